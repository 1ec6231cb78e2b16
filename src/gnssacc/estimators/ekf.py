"""The paper's 15-state error-state EKF with GNSS position and GNSS-derived acceleration updates,
plus zero-velocity / zero-angular-rate updates while the vehicle stands still, and the ground
vehicle's own aids: the non-holonomic constraint and wheel odometry.

Prediction runs through the numba kernel in :mod:`gnssacc.estimators.mechanization` at every IMU sample.
Updates come from one event loop over GNSS epochs, stationary epochs and output epochs; every
update is a :class:`gnssacc.estimators.measurements.Measurement` ``(dz, H, R)`` and goes through the same
Joseph-form Kalman update (algebraically the paper's ``(I - K H) P`` for the optimal gain).
Innovations are predicted minus measured and the error state is estimate minus truth, so the
closed-loop feedback subtracts the estimated errors (paper: ``dx+ = K dz``, closed loop).

While the vehicle rolls, the non-holonomic constraint is applied every ``[nhc] interval_s``
(:mod:`gnssacc.estimators.nhc`), and, when the recording has wheel odometry, its forward speed
with a scale-factor state (:mod:`gnssacc.estimators.odometry`; the state vector then has 16 or,
with the GNSS error states, 19 entries: :class:`FilterState`).

At a GNSS epoch the position update comes first; ``ekf-acc`` then applies the acceleration update
with ``H_a`` from :mod:`gnssacc.estimators.gnss_accel`, evaluated at the state after the position update;
``ekf-accw`` the window-consistent one (the kernel-weighted INS acceleration over the fixes'
window, ``H_w``).
An *observer* (see :class:`EkfObserver`) sees every epoch and update; the observability analysis
uses it instead of a copy of this loop.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from ..checks.quality import QualityReport, inflation_segments, touches_segments
from ..core.earth import earth_rate_n, gravity_n
from ..core.progress import progress
from ..core.recording import InitialState, RecordedRun
from ..core.rotations import dcm_to_euler, euler_error_jacobian
from ..core.solution import NavSolution
from . import measurements as meas_models
from . import nhc as nhc_rules
from . import odometry as odo_rules
from .gnss_accel import AccelWindow, measured_specific_force, window_samples
from .kalman import joseph_update
from .layout import ATT, N_NAV, NAV
from .mechanization import Propagator, apply_correction, kernel_force_integrals
from .nhc import NhcEpochs
from .nhc import epochs_for as nhc_epochs_for
from .odometry import OdometryEpochs
from .odometry import epochs_for as odometry_epochs_for
from .settings import EkfSettings, NhcSettings, OdometrySettings
from .state import FilterState, correct, initial_state, start_of_pass, state_layout
from .zupt import StationaryEpochs, epochs_for

#: The acceleration update each method applies (``None``: none; see :func:`acceleration_model`).
METHODS = {"ekf": None, "ekf-acc": "acc", "ekf-accw": "accw"}
#: Event kinds of the loop, in the order they are handled at equal times: the constraint and the
#: odometry before a GNSS epoch at the same time, so that its prior covariance holds them (as
#: :class:`gnssacc.analysis.observability.EpochCollector` sees it), and the output last.
NHC, ODOMETRY, GNSS, STATIONARY, OUTPUT = 0, 1, 2, 3, 4
#: Name of each update event kind, as the observer sees it.
EVENT_NAMES = {GNSS: "gnss", STATIONARY: "stationary", NHC: "nhc", ODOMETRY: "odometry"}
_LOG_2PI = math.log(2.0 * math.pi)


def kalman_update(
    s: FilterState, m: meas_models.Measurement
) -> tuple[float, float, bool, np.ndarray]:
    """Joseph-form update; returns the NIS, the Gaussian log-likelihood of the innovation, whether
    it was applied (a positive ``m.gate`` rejects it when NIS exceeds the gate) and the whitened
    innovation."""
    dx, nis, logdet, used, wz = joseph_update(s.P, m.H, m.R, np.asarray(m.dz, float), float(m.gate))
    if used:
        correct(s, dx)
    return nis, -0.5 * (nis + logdet + len(m.dz) * _LOG_2PI), used, wz


class EkfObserver:
    """Sees the loop: override what you need. ``kind`` is ``"gnss"`` or ``"stationary"``."""

    def start(self, setup: "EkfSetup") -> None:
        """Once, before the loop (e.g. to switch on the propagator's transition matrices)."""

    def before(self, t: float, kind: str, s: FilterState, prop: Propagator) -> None:
        """After the prediction to an update epoch, before its updates."""

    def update(
        self, t: float, m: meas_models.Measurement, nis: float, used: bool, s: FilterState
    ) -> None:
        """After each update (``used`` False: gated out, or evaluated only for the observer)."""

    def after(self, t: float, kind: str, s: FilterState, prop: Propagator) -> None:
        """After all updates of an epoch."""


class _Recorder:
    """Collects the output rows; memory grows with the outputs only. Each row keeps the attitude
    matrix and the covariance pieces it needs; Euler angles and their sigmas are computed for all
    rows at once in :meth:`solution` (per-row numpy calls cost more than the filter step)."""

    def __init__(self, n: int, store_P: bool):
        self.t = np.empty(n)
        self.pos = np.empty((n, 3))
        self.v_n = np.empty((n, 3))
        self.R_nb = np.empty((n, 3, 3))
        self.b_a = np.empty((n, 3))
        self.b_g = np.empty((n, 3))
        self.var = np.empty((n, N_NAV))
        self.P_att = np.empty((n, 3, 3))
        self.P = np.empty((n, N_NAV, N_NAV)) if store_P else None
        self.n = 0

    def add(self, t: float, s: FilterState) -> None:
        i = self.n
        self.t[i], self.pos[i], self.v_n[i], self.R_nb[i] = t, s.pos, s.v_n, s.R_nb
        self.b_a[i], self.b_g[i] = s.b_a, s.b_g
        self.var[i] = s.P.diagonal()[NAV]
        self.P_att[i] = s.P[ATT, ATT]
        if self.P is not None:
            self.P[i] = s.P[NAV, NAV]
        self.n += 1

    def solution(self, method: str, runtime_s: float, stats: dict) -> NavSolution:
        n = self.n
        rpy = np.column_stack(dcm_to_euler(self.R_nb[:n]))
        sigma = np.sqrt(np.maximum(self.var[:n], 0.0))
        J = euler_error_jacobian(rpy[:, 0], rpy[:, 1], rpy[:, 2])
        sigma[:, ATT] = np.sqrt(np.maximum(np.einsum("nij,njk,nik->ni", J, self.P_att[:n], J), 0.0))
        return NavSolution(
            method,
            self.t[:n],
            self.pos[:n, 0],
            self.pos[:n, 1],
            self.pos[:n, 2],
            self.v_n[:n],
            rpy,
            self.b_a[:n],
            self.b_g[:n],
            sigma,
            runtime_s,
            stats,
            None if self.P is None else self.P[:n],
        )


class _Tally:
    """Per update kind: counts, NIS, log-likelihood (optionally every update's) and the lag-1
    autocorrelation of the whitened innovations (white for a correct model)."""

    def __init__(self, keep: bool):
        self.keep = keep
        self.prev = {k: None for k in meas_models.KINDS}
        self.lag1 = {k: np.zeros(2) for k in meas_models.KINDS}  # sum w_k w_(k-1), sum w_k^2
        self.n = {k: 0 for k in meas_models.KINDS}
        self.rejected = {k: 0 for k in meas_models.KINDS}
        self.nis_sum = {k: 0.0 for k in meas_models.KINDS}
        self.dof = {k: 0 for k in meas_models.KINDS}
        self.loglik = {k: 0.0 for k in meas_models.KINDS}
        self.beyond = {k: 0 for k in meas_models.KINDS}  # NIS beyond the chi-square tail bound
        self.series = {k: ([], [], []) for k in meas_models.KINDS}  # t, NIS per dof, log-likelihood

    def add(
        self, t: float, m: meas_models.Measurement, nis: float, loglik: float, used: bool, wz
    ) -> None:
        k = m.kind
        if not used:
            self.rejected[k] += 1
            return
        if self.prev[k] is not None:
            self.lag1[k] += (float(wz @ self.prev[k]), float(wz @ wz))
        self.prev[k] = wz
        self.n[k] += 1
        self.nis_sum[k] += nis
        self.dof[k] += len(m.dz)
        self.loglik[k] += loglik
        self.beyond[k] += nis > meas_models.tail_bound(len(m.dz))
        if self.keep:
            for lst, v in zip(self.series[k], (t, nis / len(m.dz), loglik)):
                lst.append(v)

    def stats(self) -> dict:
        out = {}
        for k in meas_models.KINDS:
            out[f"n_{k}_updates"] = self.n[k]
            out[f"n_{k}_rejected"] = self.rejected[k]
            # Normalised innovation squared per degree of freedom: ~1 for a consistent filter.
            out[f"nis_{k}_mean"] = self.nis_sum[k] / self.dof[k] if self.dof[k] else None
            # Updates beyond the chi-square bound of tail probability TAIL_P: ~TAIL_P of them for
            # Gaussian errors; far more when the errors have heavy tails (outliers, multipath).
            out[f"n_{k}_beyond"] = self.beyond[k]
            out[f"loglik_{k}"] = self.loglik[k]
            # Whitened innovations of a correct model are white: ~0 here; a slowly varying
            # error the model misses (too little IMU noise, correlated GNSS errors) makes it > 0.
            out[f"acf1_{k}"] = (
                float(self.lag1[k][0] / self.lag1[k][1]) if self.lag1[k][1] > 0 else None
            )
            if self.keep:
                t, nis, ll = self.series[k]
                out[f"nis_{k}_t"], out[f"nis_{k}"], out[f"loglik_{k}_series"] = (
                    np.asarray(t),
                    np.asarray(nis),
                    np.asarray(ll),
                )
        return out


@dataclass
class EkfSetup:
    """Everything the EKF's event loop needs, prepared once."""

    init: InitialState
    state: FilterState
    prop: Propagator
    seg_i0: np.ndarray
    seg_i1: np.ndarray
    gate: float
    lever_b: np.ndarray
    f_avg_s: float
    p_fix_n: np.ndarray  # fixes in the run's tangent frame [m]
    window: AccelWindow
    k: int  # IMU index of the sample holding at init.t
    stationary: StationaryEpochs = field(default_factory=StationaryEpochs.empty)
    zupt_sigma: float = 0.02
    zupt_gate: float = 0.0
    nhc: NhcEpochs = field(default_factory=NhcEpochs.empty)
    nhc_settings: NhcSettings | None = None
    odometry: OdometryEpochs = field(default_factory=OdometryEpochs.empty)
    odometry_settings: OdometrySettings | None = None

    @property
    def t0(self) -> float:
        return float(self.init.t)


def prepare(
    run: RecordedRun,
    settings: EkfSettings,
    init: InitialState,
    quality: QualityReport,
    stationary=None,
    cov_every: int = 1,
) -> EkfSetup:
    """Initial state and covariance, IMU propagator with noise and inflation, acceleration window,
    stationary epochs (``stationary``: a :class:`gnssacc.prepare.stationary.StationaryReport` or ``None``)."""
    segments = inflation_segments(run.imu, quality, settings.suspect)
    imu, gnss_model, acc, z, odo = (
        settings.imu,
        settings.gnss,
        settings.accel,
        settings.zupt,
        settings.odometry,
    )
    odo_epochs = odometry_epochs_for(run, odo, float(init.t))
    with_odo = len(odo_epochs) > 0
    prop = Propagator(
        run.imu.t,
        run.imu.f_b,
        run.imu.omega_ib_b,
        imu.accel_psd,
        imu.gyro_psd,
        imu.accel_bias_rw_psd,
        imu.gyro_bias_rw_psd,
        segments,
        settings.phi_order,
        cov_every,
        layout=state_layout(settings, with_odo),
    )
    epochs = epochs_for(run, z, imu.gyro_psd, stationary)
    gnss = run.gnss
    return EkfSetup(
        init,
        initial_state(init, settings, with_odo),
        prop,
        segments.i0,
        segments.i1,
        settings.position_gate_nis,
        gnss_model.lever_arm_b,
        acc.specific_force_avg_s,
        run.origin.to_ned(gnss.lat, gnss.lon, gnss.h),
        AccelWindow(acc.window, acc.max_gap_s, acc.sigma_override),
        int(np.searchsorted(prop.t, float(init.t), side="right")),
        epochs,
        z.velocity_sigma_mps,
        z.gate_nis,
        nhc_epochs_for(run, settings.nhc, float(init.t), stationary),
        settings.nhc,
        odo_epochs,
        odo,
    )


def acceleration_model(
    run: RecordedRun, setup: EkfSetup, s: FilterState, t: float, acc, model: str = "acc"
):
    """The acceleration update at ``t`` for the window measurement ``acc``, or ``None`` when the
    specific force it needs comes from a suspect IMU span (fabricated or damaged data) or, for
    ``model="accw"``, the IMU does not cover the window.

    ``model``: ``"acc"`` the paper's (specific force at ``t``), ``"accw"`` the window-consistent
    prediction (:mod:`gnssacc.estimators.gnss_accel`)."""
    g_n = gravity_n(s.pos[0], s.pos[2])
    if model == "accw":
        win = window_samples(run.imu.t, acc.t_window)
        if win is None or touches_segments(win[0], win[1], setup.seg_i0, setup.seg_i1):
            return None
        k0, k1, h, w = win
        F_b, M, G = kernel_force_integrals(
            run.imu.f_b[k0:k1], run.imu.omega_ib_b[k0:k1], h, w, s.b_a, s.b_g
        )
        return meas_models.window_acceleration(s, acc.a_n, acc.cov, F_b, M, G, g_n)
    f_meas = measured_specific_force(run.imu, t, setup.f_avg_s, setup.seg_i0, setup.seg_i1)
    if f_meas is None:
        return None
    return meas_models.acceleration(s, acc.a_n, acc.cov, f_meas, g_n)


def default_output_times(run: RecordedRun) -> np.ndarray:
    """The GNSS epochs inside the recording, gaps filled at the GNSS interval, and the first and
    last IMU sample: the whole recording, whatever span the truth has.

    The GNSS interval is the median spacing of the fixes (1 s with a single fix); a gap (an
    outage, lost fixes, the stretches before the first and after the last fix) longer than 1.5
    intervals gets epochs spaced evenly at about that interval, so that outages have outputs too
    (at the dropped fixes' epochs, for a regular receiver).
    """
    gnss_t = run.gnss.t
    inside = gnss_t[(gnss_t > run.t_start) & (gnss_t < run.t_end)]
    base = np.concatenate([[run.t_start], inside, [run.t_end]])
    step = float(np.median(np.diff(gnss_t))) if len(gnss_t) > 1 else 1.0
    gaps = np.diff(base)
    fill = [
        base[i] + gaps[i] * np.arange(1, n) / n
        for i, n in enumerate(np.rint(gaps / step).astype(int))
        if gaps[i] > 1.5 * step
    ]
    return np.union1d(base, np.concatenate(fill) if fill else np.zeros(0))


def _events(times: dict):
    """Event times, kinds and indices in time order, from ``{kind: times}``; at equal times in
    the order of the kinds (NHC, odometry, GNSS, stationary, output)."""
    ev_t = np.concatenate(list(times.values()))
    ev_kind = np.concatenate([np.full(len(t), k) for k, t in times.items()])
    ev_idx = np.concatenate([np.arange(len(t)) for t in times.values()])
    order = np.lexsort((ev_kind, ev_t))
    return ev_t[order], ev_kind[order], ev_idx[order]


def _gnss_measurements(run, setup, s, t, i, acc, use_acc, evaluate_acc, stats):
    """The updates of a GNSS epoch, each built at the state left by the previous one (``use_acc``:
    the acceleration model applied, a value of :data:`METHODS`; the paper's is evaluated when
    only ``evaluate_acc``)."""
    gnss = run.gnss
    cov = None if gnss.corr_ned is None else gnss.cov_ned(i)  # correlated axes: the full covariance
    yield (
        meas_models.position(
            s,
            gnss.lat[i],
            gnss.lon[i],
            gnss.h[i],
            gnss.sigma_ned[i],
            setup.lever_b,
            setup.gate,
            cov,
        ),
        True,
    )
    if acc is not None and (use_acc or evaluate_acc):
        m = acceleration_model(run, setup, s, t, acc, use_acc or "acc")
        if m is None:
            stats["n_acc_skipped_suspect_imu"] += 1 if use_acc else 0
        else:
            yield m, bool(use_acc)


def _row_sigma(P: np.ndarray, h: np.ndarray) -> float:
    """1-sigma of ``h dx`` for the error covariance ``P``."""
    return math.sqrt(max(float(h @ P @ h), 0.0))


def _nhc_measurements(setup, s, j, stats):
    """The non-holonomic constraint at its epoch ``j``, unless :func:`gnssacc.estimators.nhc.decide`
    says not (counted in ``stats``)."""
    ep, nhc = setup.nhc, setup.nhc_settings
    if ep.rest[j]:  # decided without the state (nhc.decide's first test)
        stats[nhc_rules.SKIPPED[nhc_rules.REST]] += 1
        return
    w_ie = earth_rate_n(s.pos[0])
    v_b, H = meas_models.vehicle_velocity(s, ep.omega_b[j], nhc.lever_arm_b, w_ie, nhc.R_vb)
    yaw_rate = float(ep.omega_b[j, 2] - s.b_g[2] - s.R_nb[:, 2] @ w_ie)  # relative to the earth
    why = nhc_rules.decide(
        bool(ep.rest[j]),
        float(v_b[0]),
        _row_sigma(s.P, H[0]),
        yaw_rate,
        float(nhc.sigma_mps[0]),
        nhc.pivot_offset_m,
    )
    if why != nhc_rules.APPLY:
        stats[nhc_rules.SKIPPED[why]] += 1
        return
    yield meas_models.nhc_measurement(v_b, H, nhc.sigma_mps), True


def _odometry_measurements(setup, s, j, stats):
    """The wheel odometry's sample ``j``, unless its sign contradicts the filter's
    (:func:`gnssacc.estimators.odometry.decide`, counted in ``stats``)."""
    ep, odo = setup.odometry, setup.odometry_settings
    m = meas_models.odometry(
        s,
        ep.v[j],
        ep.sigma[j],
        ep.omega_b[j],
        odo.lever_arm_b,
        earth_rate_n(s.pos[0]),
        setup.nhc_settings.R_vb,
    )
    why = odo_rules.decide(
        float(ep.v[j]), float(ep.sigma[j]), float(m.dz[0] + ep.v[j]), _row_sigma(s.P, m.H[0])
    )
    if why != odo_rules.APPLY:
        stats[odo_rules.SKIPPED[why]] += 1
        return
    yield m, True


def _stationary_measurements(setup, s, j):
    st = setup.stationary
    yield meas_models.zero_velocity(s, setup.zupt_sigma, setup.zupt_gate), True
    w_ie = earth_rate_n(s.pos[0])
    yield (
        meas_models.zero_rate(s, st.omega_mean_b[j], st.omega_var_b[j], w_ie, setup.zupt_gate),
        True,
    )


def run_ekf(
    run: RecordedRun,
    settings,
    method: str = "ekf",
    *,
    output_times: np.ndarray | None = None,
    quality: QualityReport | None = None,
    init: InitialState | None = None,
    stationary=None,
    store_P: bool = False,
    record_innovations: bool = False,
    observer: EkfObserver | None = None,
    t_stop: float | None = None,
    cov_every: int = 1,
    show_progress: bool = False,
) -> NavSolution:
    """Run the EKF over a recorded run.

    Parameters
    ----------
    run : RecordedRun
    settings : EkfSettings or gnssacc.core.config.RunConfig
        The filter's settings (:class:`gnssacc.estimators.settings.EkfSettings`; a run
        configuration is reduced to them first).
    method : {"ekf", "ekf-acc", "ekf-accw"}
        ``ekf``: position updates (the paper's baseline); ``ekf-acc``: position and GNSS-derived
        acceleration updates (the paper's method); ``ekf-accw``: the same with the
        window-consistent acceleration prediction. Both add stationary updates when
        ``stationary`` is given and ``[zupt] enabled``.
    output_times : ndarray, optional
        Epochs [s] at which to report the state (after any update at the same time). Default:
        :func:`default_output_times`. Epochs before the filter starts are skipped.
    quality : QualityReport, optional
        Data-quality findings (:func:`gnssacc.checks.quality.check_imu` when omitted); suspect IMU
        spans get inflated process noise.
    init : InitialState, optional
        The start (what :func:`gnssacc.prepare.prepared.prepare` found, ``Prepared.init``); when
        omitted, the run's own (``run.init``), as it is. An estimator never looks for a start:
        :func:`gnssacc.prepare.passes.run_ekf` finds one for a run alone.
    stationary : gnssacc.prepare.stationary.StationaryReport, optional
        Where the vehicle stands still (zero-velocity and zero-rate updates there).
    store_P : bool
        Keep the full covariance at every output epoch.
    record_innovations : bool
        Keep every update's time, NIS per dof and log-likelihood in ``stats`` (``nis_<kind>_t``,
        ``nis_<kind>``, ``loglik_<kind>_series`` for kind in
        :data:`gnssacc.estimators.measurements.KINDS`).
    observer : EkfObserver, optional
        Called at every update epoch; with an observer ``ekf`` also evaluates (without applying)
        the acceleration update, for counterfactual analysis.
    t_stop : float, optional
        Stop after this time [s] (events later than it are ignored).
    cov_every : int
        Propagate the covariance every this many IMU samples (1: every sample, the default; the
        noise tuner uses more for speed).
    show_progress : bool
        Show a progress bar (only on a terminal).

    Returns
    -------
    NavSolution
        ``stats`` holds the update counts, NIS per dof and log-likelihood per update kind.
    """
    if method not in METHODS:
        raise ValueError(f"unknown EKF method {method!r}; known: {', '.join(METHODS)}")
    use_acc = METHODS[method]
    wall0 = time.perf_counter()
    init, quality = start_of_pass(run, settings, init, quality)
    settings = EkfSettings.of(settings)
    run = run.with_gnss(settings.gnss.fixes(run.gnss))
    setup = prepare(run, settings, init, quality, stationary, cov_every)
    s, prop, t0, k = setup.state, setup.prop, setup.t0, setup.k
    t_end = prop.t[-1] if t_stop is None else min(float(t_stop), prop.t[-1])
    out_t = default_output_times(run) if output_times is None else np.asarray(output_times, float)
    out_t = out_t[(out_t >= t0) & (out_t <= t_end)]
    ev_t, ev_kind, ev_idx = _events(
        {
            GNSS: run.gnss.t,
            STATIONARY: setup.stationary.t,
            NHC: setup.nhc.t,
            ODOMETRY: setup.odometry.t,
            OUTPUT: out_t,
        }
    )
    rec = _Recorder(len(out_t), store_P)
    updates = _Updates(
        run,
        setup,
        use_acc,
        observer,
        _Tally(record_innovations),
        {
            "n_acc_skipped_suspect_imu": 0,
            "init": setup.init.how,
            "t_init": t0,
            **nhc_rules.counts(),
            **odo_rules.counts(),
        },
    )
    if observer is not None:
        observer.start(setup)
    t_cur = t0
    for e in progress(range(len(ev_t)), desc=method, enable=show_progress):
        t_e, kind, i = ev_t[e], ev_kind[e], ev_idx[e]
        if t_e > t_end:
            break
        acc = (
            setup.window.push(t_e, setup.p_fix_n[i], run.gnss.sigma_ned[i])
            if kind == GNSS and (use_acc or observer is not None)
            else None
        )
        if t_e < t0:
            continue
        if t_e > t_cur:
            t_prev = t_cur
            k, t_cur = prop.advance(s, k, t_cur, t_e)
            if len(s.x_e):  # the estimated Gauss-Markov states decay
                s.x_e *= np.exp(-(t_cur - t_prev) / prop.extra_tau)
        if kind == OUTPUT:
            rec.add(t_e, s)
        else:
            updates.at(t_e, kind, i, acc)
    return rec.solution(method, time.perf_counter() - wall0, updates.final_stats())


def estimate(prep, settings: EkfSettings, method: str = "ekf", **options) -> NavSolution:
    """The EKF over a prepared recording (:class:`gnssacc.prepare.prepared.Prepared`): its run,
    start, quality report and stationary spans, with the filter's own ``settings``;
    ``options`` as for :func:`run_ekf`."""
    return run_ekf(
        prep.run,
        settings,
        method,
        init=prep.init,
        quality=prep.quality,
        stationary=prep.stationary,
        **options,
    )


@dataclass
class _Updates:
    """The measurement updates of one EKF pass, their tally and statistics."""

    run: RecordedRun
    setup: EkfSetup
    use_acc: str | None
    observer: EkfObserver | None
    tally: _Tally
    stats: dict

    def at(self, t_e: float, kind: int, i: int, acc) -> None:
        """The updates of event ``i`` of ``kind`` (GNSS epoch, stationary epoch, NHC epoch,
        odometry sample) at ``t_e`` (``acc``: the window's GNSS acceleration, if any), each shown
        to the observer."""
        setup, s, obs = self.setup, self.setup.state, self.observer
        name = EVENT_NAMES[kind]
        if obs is not None:
            obs.before(t_e, name, s, setup.prop)
        if kind == GNSS:
            models = _gnss_measurements(
                self.run, setup, s, t_e, i, acc, self.use_acc, obs is not None, self.stats
            )
        elif kind == STATIONARY:
            models = _stationary_measurements(setup, s, i)
        elif kind == NHC:
            models = _nhc_measurements(setup, s, i, self.stats)
        else:
            models = _odometry_measurements(setup, s, i, self.stats)
        for m, apply in models:
            if apply:
                nis, loglik, used, wz = kalman_update(s, m)
                self.tally.add(t_e, m, nis, loglik, used, wz)
            else:
                nis, used = float("nan"), False
            if obs is not None:
                obs.update(t_e, m, nis, used, s)
        if obs is not None:
            obs.after(t_e, name, s, setup.prop)

    def final_stats(self) -> dict:
        """The pass's ``stats`` (see :func:`run_ekf`)."""
        tally, stats = self.tally, self.stats
        stats.update(tally.stats())
        stats["n_pos_updates"], stats["n_acc_updates"] = tally.n["pos"], tally.n["acc"]
        stats["n_pos_rejected"] = tally.rejected["pos"]
        stats["accel_window_resets"] = self.setup.window.resets
        s = self.setup.state
        if s.i_scale >= 0:  # the odometry scale factor at the end, and its 1-sigma
            stats["odometry_scale"] = s.scale
            stats["odometry_scale_sigma"] = math.sqrt(s.P[s.i_scale, s.i_scale])
        stats["loglik"] = float(sum(tally.loglik.values()))
        return stats
