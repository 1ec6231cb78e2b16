r"""GNSS-derived acceleration (the paper's method): its two forms in the EKF and the smoother.

The measurement is the least-squares acceleration of the last ``[accel] window`` fixes (the
window restarts after a gap longer than ``[accel] max_gap_s``), valid at the newest fix, with
the propagated covariance of the fixes' noise (or ``[accel] sigma_override``); the model, its
Jacobians and the window are :mod:`gnssacc.estimators.aids.accel_model`. Two forms of the INS
prediction it is compared with (:data:`FORMS`, one vocabulary for both estimators and the method
ids):

``paper`` (``ekf-acc``, ``smoother-acc``)
    The paper's: ``R_nb f + g`` with the specific force measured at the newest fix (averaged over
    ``[accel] specific_force_avg_s``); ``H_a = [0, 0, -[(R f) x], R, 0]``. Smoother: the
    factor of :func:`gnssacc.factors.gnss_accel_factor` on (X_k, B_k).
``window`` (``ekf-accw``, ``smoother-accw``)
    Window-consistent: the kernel-weighted INS acceleration over the fixes' window,
    ``H_w = [0, 0, -[(R F) x], R M, R G]``. Smoother: the factor of
    :func:`gnssacc.factors.window_accel_factor` on the poses of the window's fixes
    (``sum_j B_j p_ant(X_j) - a~``), which widens the smoother's band of nodes.

``velocity`` (``ekf-vacc``, ``smoother-vacc``)
    The paper's form (the same ``H_a`` and factor) with the acceleration fitted by least squares
    to the last ``[accel] window`` Doppler velocities instead of the fixes (the slope of a line,
    :func:`gnssacc.core.gnss_fit.velocity_accelerations`; the same gap rule), on the axes the
    velocities measure, updated at each velocity's epoch; ``[accel] sigma_override`` is for the
    position forms and is not used. It needs the recording's velocities (``[velocity] enabled``
    or not: with ``--velocity off`` the acceleration is used without the velocity updates). As
    for the positions, consecutive accelerations share all but one velocity, and each shares its
    velocities with the velocity updates: every one is treated as an independent measurement
    (the same velocity noise counted more than once; the fitted slope is also the acceleration at
    the window's middle, compared with the specific force at its newest epoch as in the paper).
``velocity-window`` (``ekf-vaccw``, ``smoother-vaccw``)
    The same acceleration against the window-consistent prediction: the INS acceleration weighted
    by the slope's kernel, with the antenna's lever-arm term and the Coriolis term
    (:mod:`gnssacc.estimators.aids.velocity_window`). Smoother: the slope of the window's node
    antenna velocities (:func:`gnssacc.factors.velocity_window_accel_factor`), which widens the
    smoother's band of nodes as the ``window`` form does.

The window is fed with every fix, those before the estimator starts too. An update whose specific
force comes from a suspect IMU span (fabricated or damaged data) is skipped
(``n_acc_skipped_suspect_imu``). The EKF evaluates the paper's form without applying it when an
observer watches a pass without acceleration (the observability analysis' counterfactual).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ...core.earth import earth_rate_n, gravity_n, normal_gravity
from ...core.errors import InputError
from ...core.gnss_fit import velocity_accelerations
from ..layout import ATT, BA, BG, SYM_B, SYM_V, SYM_X
from ..mechanization import kernel_force_integrals
from .accel_model import (
    AccelMeasurement,
    AccelWindow,
    H_a_blocks,
    H_w_blocks,
    acceleration_row,
    measured_specific_force,
    predicted_acceleration,
    window_accelerations,
    window_samples,
)
from .base import AidSpec, EkfAid, Measurement, SmootherAid, zero_jacobian
from .gnss_velocity import VelocityEpochs
from .velocity_window import (
    lever_term,
    slope_coefficients,
    slope_weights,
    velocity_window_acceleration,
)

#: The forms of the INS prediction, by the suffix of their method ids (``ekf-acc``, ...).
FORMS = {"acc": "paper", "accw": "window", "vacc": "velocity", "vaccw": "velocity-window"}
#: The suffix of each form's method ids.
VARIANT_SUFFIX = {form: suffix for suffix, form in FORMS.items()}
#: The forms fitted to the Doppler velocities.
VELOCITY_FORMS = ("velocity", "velocity-window")
#: Order at equal times: right after the GNSS position update of the same fix.
ORDER = 3


def acceleration(
    s, a_n: np.ndarray, cov: np.ndarray, f_meas_b: np.ndarray, g_n: np.ndarray
) -> Measurement:
    """GNSS-derived acceleration ``a_n`` [m/s^2] (covariance ``cov``) against the INS prediction
    from the measured specific force ``f_meas_b`` [m/s^2, body] and gravity ``g_n`` (the
    ``paper`` form)."""
    f_b = f_meas_b - s.b_a
    a_pred = predicted_acceleration(s.R_nb, f_b, g_n)
    d_phi, d_ba = H_a_blocks(s.R_nb, f_b)
    H = zero_jacobian(s, 3)
    H[:, ATT] = d_phi
    H[:, BA] = d_ba
    return Measurement("acc", a_pred - a_n, H, cov)


def window_acceleration(
    s,
    a_n: np.ndarray,
    cov: np.ndarray,
    F_b: np.ndarray,
    M: np.ndarray,
    G: np.ndarray,
    g_n: np.ndarray,
) -> Measurement:
    """GNSS-derived acceleration ``a_n`` [m/s^2] (covariance ``cov``) against the window-consistent
    INS prediction ``R_nb F_b + g_n``, ``F_b, M, G`` the kernel integrals of
    :func:`gnssacc.estimators.mechanization.kernel_force_integrals` at the state's biases (body
    frame at the update epoch; the ``window`` form)."""
    d_phi, d_ba, d_bg = H_w_blocks(s.R_nb, F_b, M, G)
    H = zero_jacobian(s, 3)
    H[:, ATT] = d_phi
    H[:, BA] = d_ba
    H[:, BG] = d_bg
    return Measurement("acc", predicted_acceleration(s.R_nb, F_b, g_n) - a_n, H, cov)


def doppler_velocities(run, settings, method: str) -> VelocityEpochs:
    """The velocities the ``velocity`` form fits (the run's, their sigmas times ``[velocity]
    sigma_scale``, whether or not the velocity updates are on).

    Raises
    ------
    InputError
        The recording has no velocities.
    """
    vel = replace(settings.velocity, enabled=True).velocities(getattr(run, "gnss_vel", None))
    ep = None if vel is None else VelocityEpochs(run, vel)
    if ep is None or not len(ep):
        raise InputError(
            run.where, f"{method} fits the acceleration to GNSS velocities: this recording has none"
        )
    return ep


def doppler_accelerations(ep: VelocityEpochs, acc) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`gnssacc.core.gnss_fit.velocity_accelerations` of the velocities ``ep`` with the
    ``[accel]`` window and gap (``acc``: :class:`gnssacc.estimators.settings.AccelSettings`)."""
    v = np.where(ep.axes, ep.vel.v_ned, np.nan)
    return velocity_accelerations(ep.t, v, ep.vel.sigma_ned, acc.window, acc.max_gap_s)


class EkfAccel(EkfAid):
    """The acceleration update at every fix (every velocity, for the ``velocity`` form) whose
    window is full (module notes)."""

    order, epoch = ORDER, "gnss"

    def __init__(self, ctx):
        run, acc = ctx.run, ctx.settings.accel
        self.apply = ctx.variant is not None
        self.form = ctx.variant or "paper"
        self.imu, self.f_avg_s, self.segments = run.imu, acc.specific_force_avg_s, ctx.segments
        self.current = None  # the window's acceleration at the last fix seen
        if self.form in VELOCITY_FORMS:
            ep = doppler_velocities(run, ctx.settings, f"ekf-{VARIANT_SUFFIX[self.form]}")
            self.t, self.epoch, self.vel_window = ep.t, "gnss_vel", doppler_accelerations(ep, acc)
            self.vel, self.m, self.lever = ep, acc.window, ctx.settings.gnss.lever_arm_b
            self.window = AccelWindow(acc.window, acc.max_gap_s)  # counts no resets here
            return
        fixes = ctx.settings.gnss.fixes(run.gnss)
        self.t, self.sigma = fixes.t, fixes.sigma_ned
        self.p_fix = run.origin.to_ned(fixes.lat, fixes.lon, fixes.h)
        self.window = AccelWindow(acc.window, acc.max_gap_s, acc.sigma_override)

    def see(self, j: int) -> None:
        if self.form not in VELOCITY_FORMS:
            self.current = self.window.push(self.t[j], self.p_fix[j], self.sigma[j])
            return
        full, a_n, var = self.vel_window
        axes = np.isfinite(a_n[j])
        if not full[j] or not axes.any():
            self.current = None
            return
        cov = np.diag(np.where(axes, var[j], 1.0))
        t_win = self.t[j - self.m + 1 : j + 1]
        self.current = AccelMeasurement(float(self.t[j]), np.nan_to_num(a_n[j]), cov, t_win, axes)
        self.current_j = j

    def _velocity_window(self, s, acc, g_n) -> Measurement | None:
        """The ``velocity-window`` form's update (:mod:`.velocity_window`), or ``None`` when the
        IMU does not cover the window or a suspect span touches it."""
        win = window_samples(self.imu.t, acc.t_window, slope_weights)
        if win is None or self.segments.touch(win[0], win[1]):
            return None
        k0, k1, h, w = win
        imu = self.imu
        F_b, M, G = kernel_force_integrals(
            imu.f_b[k0:k1], imu.omega_ib_b[k0:k1], h, w, s.b_a, s.b_g
        )
        lever = None
        if self.lever.any():
            j = self.current_j
            om = self.vel.omega_b[j - self.m + 1 : j + 1]
            lever = lever_term(imu.t, imu.omega_ib_b, acc.t_window, om, self.lever, s.b_g)
        w_ie = earth_rate_n(s.pos[0])
        return velocity_window_acceleration(s, acc.a_n, acc.cov, F_b, M, G, g_n, w_ie, lever)

    def model(self, s, t: float) -> Measurement | None:
        """The update for the window's acceleration at ``t`` [s], or ``None`` when the specific
        force it needs comes from a suspect IMU span or, for the ``window`` form, the IMU does
        not cover the window."""
        acc = self.current
        assert acc is not None  # a full window (models and updates ask only then)
        g_n = gravity_n(s.pos[0], s.pos[2])
        if self.form == "window":
            win = window_samples(self.imu.t, acc.t_window)
            if win is None or self.segments.touch(win[0], win[1]):
                return None
            k0, k1, h, w = win
            F_b, M, G = kernel_force_integrals(
                self.imu.f_b[k0:k1], self.imu.omega_ib_b[k0:k1], h, w, s.b_a, s.b_g
            )
            return window_acceleration(s, acc.a_n, acc.cov, F_b, M, G, g_n)
        if self.form == "velocity-window":
            m = self._velocity_window(s, acc, g_n)
        else:
            seg = self.segments
            f_meas = measured_specific_force(self.imu, t, self.f_avg_s, seg.i0, seg.i1)
            if f_meas is None:
                return None
            m = acceleration(s, acc.a_n, acc.cov, f_meas, g_n)
        if m is None or acc.axes is None or acc.axes.all():
            return m
        ax = acc.axes
        return Measurement(m.kind, m.dz[ax], m.H[ax], m.R[np.ix_(ax, ax)], m.gate)

    def models(self, s, j: int) -> list[Measurement]:
        m = None if self.current is None else self.model(s, float(self.t[j]))
        return [] if m is None else [m]

    def updates(self, s, j: int, stats: dict):
        if self.current is None:
            return
        m = self.model(s, float(self.t[j]))
        if m is None:
            stats["n_acc_skipped_suspect_imu"] += 1 if self.apply else 0
            return
        yield m, self.apply

    def final_stats(self, s, stats: dict) -> None:
        stats["accel_window_resets"] = self.window.resets


def _ekf(ctx) -> EkfAccel | None:
    """The aid when the method applies a form, or an observer watches (the paper's, evaluated)."""
    return EkfAccel(ctx) if ctx.variant is not None or ctx.observed else None


def bandwidth(settings) -> int:
    """How many nodes apart a window-consistent acceleration factor may reach: its window's m
    fixes are at most ``[accel] max_gap_s`` apart, with fill nodes at most ``[smoother]
    max_node_spacing_s`` apart between them (stationary nodes may add more: such a factor makes
    the marginals come from iSAM2 while it is in the window)."""
    per_gap = int(np.ceil(settings.accel.max_gap_s / settings.max_node_spacing_s - 1e-9))
    return (settings.accel.window - 1) * max(per_gap, 1)


class SmootherAccel(SmootherAid):
    """The acceleration factors of a smoother run (module notes)."""

    order = 1

    def __init__(self, ctx):
        run, settings = ctx.run, ctx.settings
        self.stats, self.form, self.imu = ctx.stats, ctx.variant, run.imu
        self.fixes = settings.gnss.fixes(run.gnss)
        self.p_fix = run.origin.to_ned(self.fixes.lat, self.fixes.lon, self.fixes.h)
        self.fix_at = {float(t): i for i, t in enumerate(self.fixes.t)}
        self.lever = settings.gnss.lever_arm_b
        origin = run.origin
        self.g_n = np.array([0.0, 0.0, float(normal_gravity(origin.lat0, origin.h0))])
        acc = settings.accel
        self.f_avg = acc.specific_force_avg_s
        self.acc_window = (acc.window, acc.max_gap_s, acc.sigma_override)
        windowed = self.form in ("window", "velocity-window")
        self.bandwidth = bandwidth(settings) if windowed else 1
        self.accel = acc
        if self.form in VELOCITY_FORMS:
            self.vel = doppler_velocities(run, settings, f"smoother-{VARIANT_SUFFIX[self.form]}")
            self.w_ie = earth_rate_n(origin.lat0)

    def _attach_velocity(self, ctx) -> None:
        """The ``velocity`` form: the accelerations of the velocities before the first node and at
        node times, in order (as the position forms take the fixes), by velocity index."""
        ep, times = self.vel, ctx.times
        at_node = np.isin(ep.t, times)
        pushed = np.flatnonzero((ep.t < times[0]) | at_node)
        sub = ep.vel.select(pushed)
        v = np.where(ep.axes[pushed], sub.v_ned, np.nan)
        acc = self.accel
        full, a_n, var = velocity_accelerations(
            ep.t[pushed], v, sub.sigma_ned, acc.window, acc.max_gap_s
        )
        self.acc: dict[int, tuple] = {
            int(k): (np.nan_to_num(a_n[j]), np.where(np.isfinite(a_n[j]), var[j], 1.0),
                     np.isfinite(a_n[j]))
            for j, k in enumerate(pushed.tolist())
            if full[j] and np.isfinite(a_n[j]).any()
        }  # fmt: skip
        self.at_t = {float(t): k for k, t in enumerate(ep.t.tolist())}
        m = acc.window
        self.acc_vels = {
            int(k): pushed[j - m + 1 : j + 1] for j, k in enumerate(pushed.tolist()) if full[j]
        }
        self.node_of = {self.at_t[t]: i for i, t in enumerate(times.tolist()) if t in self.at_t}

    def attach(self, ctx) -> None:
        """The accelerations of every fix, all at once: the fixes before the first node and those
        at node times, in order, as :class:`gnssacc.estimators.aids.accel_model.AccelWindow` would
        see them; and the node of each fix at a node time."""
        if self.form in VELOCITY_FORMS:
            self._attach_velocity(ctx)
            return
        times = ctx.times
        t_fix = self.fixes.t
        nodes = set(times.tolist())
        pushed = np.flatnonzero(
            (t_fix < times[0]) | np.array([t in nodes for t in t_fix.tolist()], bool)
        )
        full, a_n, var = window_accelerations(
            t_fix[pushed], self.p_fix[pushed], self.fixes.sigma_ned[pushed], *self.acc_window
        )
        self.acc = {int(k): (a_n[j], var[j]) for j, k in enumerate(pushed) if full[j]}
        m = self.acc_window[0]
        self.acc_fixes = {
            int(k): pushed[j - m + 1 : j + 1] for j, k in enumerate(pushed) if full[j]
        }
        self.node_of = {self.fix_at[t]: i for i, t in enumerate(times.tolist()) if t in self.fix_at}

    def node(self, graph, ctx, i: int, t: float, pred) -> None:
        if self.form in VELOCITY_FORMS:
            k = self.at_t.get(float(t))
            if k is None:
                return
            if self.form == "velocity":
                self._paper(graph, i, t, k, ctx.segments)
            else:
                self._velocity_window_factor(graph, k, lambda n: n == i or ctx.has_node(n))
            return
        k = self.fix_at.get(float(t))
        if k is None:
            return
        if self.form == "window":
            self._window(graph, k, lambda n: n == i or ctx.has_node(n))
        else:
            self._paper(graph, i, t, k, ctx.segments)

    def _paper(self, graph, i: int, t: float, k: int, segments) -> None:
        """The paper's factor on (X_i, B_i) once the least-squares window is full."""
        import gtsam

        from ...factors import gnss_accel_factor

        meas = self.acc.get(k)
        if meas is None:
            return
        f_meas = measured_specific_force(self.imu, t, self.f_avg, segments.i0, segments.i1)
        if f_meas is None:
            self.stats["n_acc_skipped_suspect_imu"] += 1
            return
        graph.add(
            gnss_accel_factor(
                gtsam.symbol(SYM_X, i),
                gtsam.symbol(SYM_B, i),
                f_meas,
                meas[0],
                self.g_n,
                np.diag(meas[1]),
                meas[2] if len(meas) > 2 else None,
            )
        )
        self.stats["n_acc_factors"] += 1

    def _window(self, graph, k: int, in_window) -> None:
        """The window-consistent factor on the poses of fix ``k``'s window, when its window is
        full and all of its fixes' nodes are in the smoother (``in_window(node)``)."""
        import gtsam

        from ...factors import window_accel_factor

        meas = self.acc.get(k)
        if meas is None:
            return
        fixes = self.acc_fixes[k]
        nodes = [self.node_of.get(int(f)) for f in fixes]
        if any(n is None or not in_window(n) for n in nodes):  # before the start, or marginalised
            self.stats["n_acc_skipped_window"] = self.stats.get("n_acc_skipped_window", 0) + 1
            return
        B_row = acceleration_row(self.fixes.t[fixes])
        graph.add(
            window_accel_factor(
                [gtsam.symbol(SYM_X, n) for n in nodes if n is not None],
                B_row,
                meas[0],
                self.lever,
                np.diag(meas[1]),
            )
        )
        self.stats["n_acc_factors"] += 1

    def _velocity_window_factor(self, graph, k: int, in_window) -> None:
        """The ``velocity-window`` factor: the slope of the antenna velocities of the nodes of
        velocity ``k``'s window (:func:`gnssacc.factors.velocity_window_accel_factor`), when its
        window is full and all of its nodes are in the smoother."""
        import gtsam

        from ...factors import velocity_window_accel_factor

        meas = self.acc.get(k)
        if meas is None:
            return
        vels = self.acc_vels[k]
        nodes = [self.node_of.get(int(v)) for v in vels]
        if any(n is None or not in_window(n) for n in nodes):
            self.stats["n_acc_skipped_window"] = self.stats.get("n_acc_skipped_window", 0) + 1
            return
        keys = [tuple(gtsam.symbol(c, int(n or 0)) for c in (SYM_X, SYM_V, SYM_B)) for n in nodes]
        graph.add(
            velocity_window_accel_factor(
                keys,
                slope_coefficients(self.vel.t[vels]),
                meas[0],
                meas[2],
                self.vel.omega_b[vels],
                self.lever,
                self.w_ie,
                np.diag(meas[1]),
            )
        )
        self.stats["n_acc_factors"] += 1


def _smoother(ctx) -> SmootherAccel | None:
    return SmootherAccel(ctx) if ctx.variant is not None else None


AID = AidSpec(
    name="gnss_accel",
    kinds=("acc",),
    ekf=_ekf,
    smoother=_smoother,
    counts={"n_acc_skipped_suspect_imu": 0, "accel_window_resets": 0},
    smoother_counts={"n_acc_factors": 0, "n_acc_skipped_suspect_imu": 0},
)
