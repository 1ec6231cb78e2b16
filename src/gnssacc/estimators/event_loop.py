"""The EKF's event loop compiled: the stretches of a pass whose events all have compiled steps.

An EKF pass without an observer (the tuner's likelihood passes, a method's pass) spends ~20 us
of Python per epoch around numba's propagation, and a numba call from Python costs ~4 us by
itself. Aids with a compiled step say so (:meth:`gnssacc.estimators.aids.EkfAid.compiled`): the
GNSS position fix (:func:`gnssacc.estimators.aids.gnss_position.position_model`), the
non-holonomic constraint (:func:`gnssacc.estimators.aids.vehicle.vehicle_model`,
:func:`gnssacc.estimators.aids.nhc.decide_compiled`), the GNSS velocity
(:func:`gnssacc.estimators.aids.gnss_velocity.velocity_model`, when its measured axes are the same
at every epoch), the stationary updates (zero velocity, then zero rate:
:func:`gnssacc.estimators.aids.zupt.zero_rate_model`) and wheel odometry
(:func:`gnssacc.estimators.aids.odometry.odometry_model`, its sign decision
:func:`~gnssacc.estimators.aids.odometry.decide_compiled`). :func:`run_stretch` runs the events of a
pass from a given one on in one call: the propagation to each
(:func:`gnssacc.estimators.mechanization.propagate`, as
:meth:`gnssacc.estimators.mechanization.Propagator.advance` calls it), the Gauss-Markov states'
decay, each update and its feedback (:func:`gnssacc.estimators.mechanization.update_state`) and
the outputs, until an event it has no step for (another aid's epoch) or the pass's end. The EKF's
Python loop (:func:`gnssacc.estimators.ekf.run_ekf`, the reference) does that event and hands the
next ones back (:class:`CompiledLoop`).

The same numbers as the Python loop: the same kernels with the same arguments in the same order;
the updates' NIS, ``log det S`` and whitened innovations come back as arrays, which the pass's
tally takes in order as the Python loop would
(:meth:`gnssacc.estimators.ekf_record.Tally.add_update`). What the kernel computes itself it
computes as numpy does on this kind of machine: the decay's ``exp`` and the earth rate's ``cos``,
``sin`` are the C library's (numpy's own on x86-64 without AVX-512; with it, numpy's may differ
in the last bit), a fix's ``sigma^2`` is taken as numpy's scalar ``pow``
(:func:`gnssacc.estimators.aids.gnss_position.fix_noise`). The constraint's decision inputs (the
forward speed's sigma ``sqrt(h P h)``, the yaw rate) are summed in plain order where numpy's BLAS
may fuse: they only enter comparisons, which a last-bit difference decides otherwise only at an
exact tie.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..core.earth import OMEGA_IE
from .aids.gnss_position import position_model
from .aids.gnss_velocity import velocity_model
from .aids.nhc import REST, SKIPPED, TURN, decide_compiled
from .aids.odometry import APPLY
from .aids.odometry import SKIPPED as ODO_SKIPPED
from .aids.odometry import SIGN, odometry_model
from .aids.odometry import decide_compiled as odometry_decision
from .aids.vehicle import vehicle_model
from .aids.zupt import zero_rate_model
from .ekf_record import Recorder, Tally, innovation_loglik
from .layout import GNSS_ERROR, I_ATT, I_VEL, N_NAV, ODOMETRY_SCALE
from .mechanization import Propagator, propagate, update_state
from .state import FilterState

#: Event codes: the Python loop's step (an aid without a compiled step), the fix, the
#: non-holonomic constraint, an output, the GNSS velocity, a stationary epoch, wheel odometry.
PYTHON, POSITION, NHC, OUTPUT, VELOCITY, STATIONARY, ODOMETRY = 0, 1, 2, 3, 4, 5, 7
#: The updates' codes (a row of ``out``): the events' that make one update, and a stationary
#: epoch's two.
ZUPT, ZARU = 5, 6
#: The compiled steps by the name an aid gives (:meth:`gnssacc.estimators.aids.EkfAid.compiled`),
#: with their event code.
STEPS = {
    "position": POSITION,
    "nhc": NHC,
    "velocity": VELOCITY,
    "stationary": STATIONARY,
    "odometry": ODOMETRY,
}
#: The updates' kinds and degrees of freedom by code (the velocity's: its measured axes).
_KINDS = {
    POSITION: ("pos", 3),
    NHC: ("nhc", 2),
    ZUPT: ("zupt", 3),
    ZARU: ("zaru", 3),
    ODOMETRY: ("odo", 1),
}
#: Updates of a compiled stretch from which the tally takes them per kind at once (fewer: one by
#: one, cheaper than the arrays' set-up).
BATCH_FROM = 8


@njit(cache=True)
def _advance(prop, st, k, t_cur, t_to):
    """Propagate to ``t_to`` as :meth:`Propagator.advance` does, then decay the Gauss-Markov
    states over the time moved (as :func:`gnssacc.estimators.ekf.run_ekf`)."""
    t_imu, f_imu, w_imu, q_a, q_g, q_ba, q_bg, seg_i0, seg_i1, seg_qa, seg_qg = prop[:11]
    phi_order, with_cov, cov_every, Phi, with_phi, w_ie_sign, gm_tau, gm_var, q_turn = prop[11:20]
    w_turn, rest, rest_R = prop[20], prop[21], prop[22]
    pos, v_n, R_nb, b_a, b_g, P, x_e = st[:7]
    t_prev = t_cur
    k, t_cur = propagate(
        t_imu, f_imu, w_imu, k, t_cur, t_to, pos, v_n, R_nb, b_a, b_g, P, q_a, q_g, q_ba, q_bg,
        seg_i0, seg_i1, seg_qa, seg_qg, phi_order, with_cov, cov_every, Phi, with_phi, w_ie_sign,
        gm_tau, gm_var, q_turn, w_turn, rest, rest_R,
    )  # fmt: skip
    for i in range(x_e.shape[0]):
        x_e[i] *= math.exp(-(t_cur - t_prev) / gm_tau[i])
    return k, t_cur


@njit(cache=True)
def _update(st, H, R, dz, gate, out, n, code, t_e):
    """The update ``(dz, H, R)`` with its feedback, its results written to row ``n`` of ``out``."""
    pos, v_n, R_nb, b_a, b_g, P, x_e, consider = st
    nis, logdet, used, wz = update_state(P, H, R, dz, gate, consider, pos, v_n, R_nb, b_a, b_g, x_e)
    o_code, o_t, o_nis, o_logdet, o_used, o_wz = out
    o_code[n], o_t[n], o_nis[n], o_logdet[n], o_used[n] = code, t_e, nis, logdet, used
    for i in range(wz.shape[0]):
        o_wz[n, i] = wz[i]


@njit(cache=True)
def _position(fix, st, j, t_e, out, n):
    """The fix ``j`` (:meth:`gnssacc.estimators.aids.gnss_position.EkfPosition.models`)."""
    lat, lon, h, R, lever, gate, i_gm = fix
    pos, R_nb, P, x_e = st[0], st[2], st[5], st[6]
    gm = np.zeros(3)
    if i_gm >= 0:
        for r in range(3):
            gm[r] = x_e[i_gm - N_NAV + r]
    dz, H = position_model(pos, R_nb, lever, lat[j], lon[j], h[j], gm, i_gm, P.shape[0])
    _update(st, H, R[j], dz, gate, out, n, POSITION, t_e)


@njit(cache=True)
def _earth_rate(lat):
    """:func:`gnssacc.core.earth.earth_rate_n` [rad/s, NED] at ``lat`` [rad], as numpy makes it."""
    w_ie = np.empty(3)
    w_ie[0], w_ie[1], w_ie[2] = OMEGA_IE * np.cos(lat), OMEGA_IE * 0.0, OMEGA_IE * -np.sin(lat)
    return w_ie


@njit(cache=True)
def _velocity(vel, st, j, t_e, out, n):
    """The velocity ``j`` (:meth:`gnssacc.estimators.aids.gnss_velocity.EkfVelocity.models`)."""
    v, omega_b, R, rows, lever, gate = vel
    pos, v_n, R_nb, b_g, P = st[0], st[1], st[2], st[4], st[5]
    w_ie = _earth_rate(pos[0])
    dz, H = velocity_model(R_nb, v_n, b_g, omega_b[j], lever, w_ie, v[j], rows, P.shape[0])
    _update(st, H, R[j], dz, gate, out, n, VELOCITY, t_e)


@njit(cache=True)
def _stationary(zp, st, j, t_e, out, n):
    """The stationary epoch ``j``'s zero velocity, then its zero rate at the state the first left
    (:meth:`gnssacc.estimators.aids.zupt.EkfZupt.updates`)."""
    omega_mean_b, R_rate, R_zero, gate = zp
    v_n, R_nb, b_g, P = st[1], st[2], st[4], st[5]
    H = np.zeros((3, P.shape[0]))
    for r in range(3):
        H[r, I_VEL + r] = 1.0
    _update(st, H, R_zero, v_n.copy(), gate, out, n, ZUPT, t_e)
    w_ie = _earth_rate(st[0][0])
    dz, H = zero_rate_model(R_nb, b_g, omega_mean_b[j], w_ie, P.shape[0])
    _update(st, H, R_rate[j], dz, gate, out, n + 1, ZARU, t_e)


@njit(cache=True)
def _row_sigma(P, H):
    """``sqrt(h P h)`` of ``H``'s first row, summed in plain order (a decision's input)."""
    var = 0.0
    for c in range(P.shape[0]):
        hp = 0.0
        for r in range(P.shape[0]):
            hp += H[0, r] * P[r, c]
        var += hp * H[0, c]
    return math.sqrt(max(var, 0.0))


@njit(cache=True)
def _odometry(odo, st, j, t_e, out, n, skipped):
    """The odometry sample ``j`` (:meth:`gnssacc.estimators.aids.odometry.EkfOdometry.updates`);
    whether it was applied (else counted in ``skipped``: its sign contradicts the estimate's)."""
    v, sigma, omega_b, lever, R_vb, vb_rows, R, i_scale = odo
    pos, v_n, R_nb, b_g, P, x_e = st[0], st[1], st[2], st[4], st[5], st[6]
    w_ie = _earth_rate(pos[0])
    dz, H = odometry_model(
        R_nb, v_n, b_g, omega_b[j], lever, w_ie, R_vb, vb_rows, x_e[i_scale - N_NAV], i_scale,
        v[j], P.shape[0],
    )  # fmt: skip
    if odometry_decision(v[j], sigma[j], dz[0] + v[j], _row_sigma(P, H)) != APPLY:
        skipped[0] += 1
        return False
    _update(st, H, R[j], dz, 0.0, out, n, ODOMETRY, t_e)
    return True


@njit(cache=True)
def _nhc(nhc, st, j, t_e, out, n, skipped):
    """The constraint's epoch ``j`` (:meth:`gnssacc.estimators.aids.nhc.EkfNhc.updates`); whether
    it was applied (else counted in ``skipped``: at rest, turning)."""
    omega_b, rest, lever, R_vb, vb_rows, sigma_lateral, pivot_offset, R = nhc
    pos, v_n, R_nb, b_g, P = st[0], st[1], st[2], st[4], st[5]
    if rest[j]:
        skipped[0] += 1
        return False
    w_ie = _earth_rate(pos[0])
    v_b, H = vehicle_model(R_nb, v_n, b_g, omega_b[j], lever, w_ie, R_vb, vb_rows, P.shape[0])
    yaw_rate = (
        omega_b[j, 2]
        - b_g[2]
        - (R_nb[0, 2] * w_ie[0] + R_nb[1, 2] * w_ie[1] + R_nb[2, 2] * w_ie[2])
    )
    why = decide_compiled(False, v_b[0], _row_sigma(P, H), yaw_rate, sigma_lateral, pivot_offset)
    if why == TURN:
        skipped[1] += 1
        return False
    H_lv, dz = np.empty((2, H.shape[1])), np.empty(2)  # C order: update_state's own types
    for r in range(2):
        dz[r] = v_b[r + 1]
        for c in range(H.shape[1]):
            H_lv[r, c] = H[r + 1, c]
    _update(st, H_lv, R, dz, 0.0, out, n, NHC, t_e)
    return True


@njit(cache=True)
def _record(rec, i, t_e, st):
    """Output row ``i`` at ``t_e`` [s], as :meth:`gnssacc.estimators.ekf_record.Recorder.add`."""
    t, pos, v_n, R_nb, b_a, b_g, var, P_att, P_nav = rec
    P = st[5]
    t[i] = t_e
    for r in range(3):
        pos[i, r], v_n[i, r], b_a[i, r], b_g[i, r] = st[0][r], st[1][r], st[3][r], st[4][r]
        for c in range(3):
            R_nb[i, r, c] = st[2][r, c]
            P_att[i, r, c] = P[I_ATT + r, I_ATT + c]
    for r in range(N_NAV):
        var[i, r] = P[r, r]
        if P_nav.shape[0] > 0:
            for c in range(N_NAV):
                P_nav[i, r, c] = P[r, c]


@njit(cache=True)
def run_stretch(e, ev, t0, t_end, k, t_cur, prop, st, steps, out, rec, rows):
    """Run the events from ``e`` on until one whose code is :data:`PYTHON` or whose time is past
    ``t_end`` [s] (events before ``t0``, the filter's start, are passed over).

    Parameters
    ----------
    e : int
        The first event.
    ev : tuple of ndarray (E,)
        The pass's events: times [s], codes (:data:`PYTHON`, :data:`POSITION`, :data:`NHC`,
        :data:`OUTPUT`, :data:`VELOCITY`, :data:`STATIONARY`, :data:`ODOMETRY`) and the epoch
        index in their aid.
    t0, t_end : float
        The filter's start and the pass's end [s].
    k, t_cur : int, float
        The IMU sample and the time the state is at (:func:`propagate`).
    prop : tuple
        :func:`propagate`'s IMU and noise arguments (:func:`propagation`).
    st : tuple
        ``(pos, v_n, R_nb, b_a, b_g, P, x_e, consider)``, updated in place
        (:class:`gnssacc.estimators.state.FilterState`).
    steps : tuple
        The compiled aids' arrays ``(fix, nhc, velocity, stationary, odometry)``
        (:meth:`gnssacc.estimators.aids.EkfAid.compiled`; the fix's with the index of the
        Gauss-Markov fix error's first state, -1: none, after its own; the odometry's with its
        scale factor's index).
    out : tuple
        ``(code, t, nis, logdet, used, wz)`` of the updates, one row each (codes
        :data:`POSITION`, :data:`NHC`, :data:`VELOCITY`, :data:`ZUPT`, :data:`ZARU`,
        :data:`ODOMETRY`).
    rec : tuple
        The output rows' arrays (:class:`gnssacc.estimators.ekf_record.Recorder`'s ``t, pos,
        v_n, R_nb, b_a, b_g, var, P_att, P``; ``P`` empty when not kept).
    rows : ndarray (5,) of int
        The rows of ``out`` and ``rec`` written so far (the next ones to write), the
        constraint's epochs skipped at rest and turning, and the odometry's samples skipped for
        their sign; updated.

    Returns
    -------
    e, k, t_cur : int, int, float
        The event it stopped at (``E``: the end), and the state's sample and time.
    """
    ev_t, ev_code, ev_idx = ev
    fix, nhc, vel, zp, odo = steps
    while e < ev_t.shape[0]:
        t_e, code = ev_t[e], ev_code[e]
        if code == PYTHON or t_e > t_end:
            break
        if t_e >= t0:
            if t_e > t_cur:
                k, t_cur = _advance(prop, st, k, t_cur, t_e)
            if code == POSITION:
                _position(fix, st, ev_idx[e], t_e, out, rows[0])
                rows[0] += 1
            elif code == OUTPUT:
                _record(rec, rows[1], t_e, st)
                rows[1] += 1
            elif code == VELOCITY:
                _velocity(vel, st, ev_idx[e], t_e, out, rows[0])
                rows[0] += 1
            elif code == STATIONARY:
                _stationary(zp, st, ev_idx[e], t_e, out, rows[0])
                rows[0] += 2
            elif code == ODOMETRY:
                if _odometry(odo, st, ev_idx[e], t_e, out, rows[0], rows[4:]):
                    rows[0] += 1
            elif _nhc(nhc, st, ev_idx[e], t_e, out, rows[0], rows[2:]):
                rows[0] += 1
        e += 1
    return e, k, t_cur


#: The arrays of a pass without one of the compiled aids (the kernel's types all the same).
_NO_FIX = (np.zeros(0), np.zeros(0), np.zeros(0), np.zeros((0, 3, 3)), np.zeros(3), 0.0, -1)
_NO_NHC = (np.zeros((0, 3)), np.zeros(0, bool), np.zeros(3), np.eye(3), True, 0.0, 0.0, np.eye(2))
_NO_VEL: tuple = (
    np.zeros((0, 3)),
    np.zeros((0, 3)),
    np.zeros((0, 3, 3)),
    np.arange(3, dtype=np.int64),
)
_NO_VEL += (np.zeros(3), 0.0)
_NO_ZUPT = (np.zeros((0, 3)), np.zeros((0, 3, 3)), np.eye(3), 0.0)
_NO_ODO: tuple = (np.zeros(0), np.zeros(0), np.zeros((0, 3)), np.zeros(3), np.eye(3), True)
_NO_ODO += (np.zeros((0, 1, 1)), N_NAV)


def propagation(prop: Propagator) -> tuple:
    """:func:`propagate`'s arguments bound in ``prop`` (those :meth:`Propagator.advance` passes),
    in :func:`run_stretch`'s order."""
    return (
        prop.t, prop.f, prop.w, *prop.q, *prop.segments, prop.phi_order, True, prop.cov_every,
        prop.Phi, prop.with_phi, prop.w_ie_sign, prop.extra_tau, prop.extra_var, prop.q_turn,
        prop.w_turn, prop.rest, prop.rest_R,
    )  # fmt: skip


class CompiledLoop:
    """The compiled stretches of one EKF pass (:func:`run_stretch`): :meth:`of` builds it when
    some of the pass's events have compiled steps, :meth:`run` runs the events from one on and
    hands their updates to the pass's tally, their outputs to its recorder and their counts to
    its ``stats``."""

    def __init__(self, s: FilterState, prop: Propagator, events: tuple, steps: tuple, record):
        self.ev = events
        self.steps = steps  # (fix, nhc, velocity, stationary, odometry)
        self.kinds = {**_KINDS, VELOCITY: ("vel", len(steps[2][3]))}
        self.tally, self.stats, self.rec = record
        self.prop = propagation(prop)
        self.st = (s.pos, s.v_n, s.R_nb, s.b_a, s.b_g, s.P, s.x_e, int(s.consider))
        m = len(self.ev[0]) + int(np.count_nonzero(self.ev[1] == STATIONARY))  # two updates each
        self.out = (
            np.zeros(m, np.int64), np.zeros(m), np.zeros(m), np.zeros(m), np.zeros(m, bool),
            np.zeros((m, 3)),
        )  # fmt: skip
        r = self.rec
        P_nav = r.P if r.P is not None else np.zeros((0, N_NAV, N_NAV))
        self.rec_arrays = (r.t, r.pos, r.v_n, r.R_nb, r.b_a, r.b_g, r.var, r.P_att, P_nav)
        self.rows = np.zeros(5, np.int64)  # updates, outputs, skipped: at rest, turning, sign

    @classmethod
    def of(cls, setup, ev, tally: Tally, stats: dict, rec: Recorder) -> "CompiledLoop | None":
        """The compiled loop of the pass ``setup`` (:class:`gnssacc.estimators.ekf.EkfSetup`) over
        its events ``ev`` (times [s], sources: an index into ``setup.aids``, or an output; epoch
        indices), or ``None`` when none of its aids has a compiled step."""
        codes: list[int] = []
        steps = {POSITION: _NO_FIX, NHC: _NO_NHC, VELOCITY: _NO_VEL, STATIONARY: _NO_ZUPT}
        steps[ODOMETRY] = _NO_ODO
        for aid in setup.aids:
            step = aid.compiled()
            code = STEPS.get(step[0], PYTHON) if step is not None else PYTHON
            codes.append(code)
            if code == POSITION:
                steps[code] = (*step[1], int(setup.state.layout.offset(GNSS_ERROR)))
            elif code == ODOMETRY:
                steps[code] = (*step[1], int(setup.state.layout.offset(ODOMETRY_SCALE)))
            elif code != PYTHON:
                steps[code] = step[1]
        if all(c == PYTHON for c in codes):
            return None
        ev_t, ev_src, ev_idx = ev
        ev_code = np.array(codes + [OUTPUT], np.int64)[np.asarray(ev_src, np.int64)]
        events = (np.ascontiguousarray(ev_t, float), ev_code, np.asarray(ev_idx, np.int64))
        order = (POSITION, NHC, VELOCITY, STATIONARY, ODOMETRY)
        return cls(
            setup.state, setup.prop, events, tuple(steps[c] for c in order), (tally, stats, rec)
        )

    def run(self, e: int, k: int, t_cur: float, t0: float, t_end: float) -> tuple[int, int, float]:
        """Run the events from ``e`` on (:func:`run_stretch`); the event it stopped at (the
        Python loop's, or the end), and the state's IMU sample and time."""
        rows = self.rows
        n0, rows[1] = int(rows[0]), self.rec.n  # the Python loop may have recorded outputs
        e, k, t_cur = run_stretch(
            e, self.ev, t0, t_end, k, t_cur, self.prop, self.st, self.steps, self.out,
            self.rec_arrays, rows,
        )  # fmt: skip
        n, self.rec.n, rest, turn, sign = rows.tolist()
        if n > n0:
            self._tally(n0, n)
        if rest or turn or sign:
            self.stats[SKIPPED[REST]] += rest
            self.stats[SKIPPED[TURN]] += turn
            if sign:
                self.stats[ODO_SKIPPED[SIGN]] += sign
            rows[2:] = 0
        return e, k, t_cur

    def _tally(self, n0: int, n: int) -> None:
        """Rows ``n0:n`` of the updates to the tally, in order, as the Python loop adds them: one
        by one when few (a stretch between two Python events), else each kind's at once
        (:meth:`Tally.add_updates`, the same sums)."""
        code, t, nis, logdet, used, wz = (x[n0:n] for x in self.out)
        if n - n0 >= BATCH_FROM:
            for c in np.unique(code).tolist():
                kind, dof = self.kinds[c]
                mine = code == c
                self.tally.add_updates(
                    kind, dof, t[mine], nis[mine], logdet[mine], used[mine], wz[mine, :dof]
                )
            return
        rows = zip(code.tolist(), t.tolist(), nis.tolist(), logdet.tolist(), used.tolist(), wz)
        for c, t_u, nis_u, logdet_u, used_u, wz_u in rows:
            kind, dof = self.kinds[c]
            loglik = innovation_loglik(nis_u, logdet_u, dof)
            self.tally.add_update(t_u, kind, dof, nis_u, loglik, used_u, wz_u[:dof])
