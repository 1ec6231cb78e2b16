"""The paper's 15-state error-state EKF, with the aids a run has.

Prediction runs through the numba kernel in :mod:`gnssacc.estimators.mechanization` at every IMU
sample. Updates come from one event loop over the epochs of the pass's aids
(:mod:`gnssacc.estimators.aids`) and the output epochs; every update is an aid's
:class:`gnssacc.estimators.aids.Measurement` ``(dz, H, R)`` and goes through the same Joseph-form
Kalman update (algebraically the paper's ``(I - K H) P`` for the optimal gain). Innovations are
predicted minus measured and the error state is estimate minus truth, so the closed-loop feedback
subtracts the estimated errors (paper: ``dx+ = K dz``, closed loop).

At equal times the events come in the aids' order (:attr:`gnssacc.estimators.aids.EkfAid.order`),
the outputs last; each update of an epoch is built at the state the one before it left. The
state has the navigation states and the Gauss-Markov states the aids ask for
(:class:`gnssacc.estimators.layout.StateLayout`); those decay between updates.

An *observer* (see :class:`EkfObserver`) sees every epoch and update; the observability analysis
uses it instead of a copy of this loop.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..checks.quality import QualityReport, inflation_segments
from ..core.progress import progress
from ..core.recording import InitialState, RecordedRun
from ..core.solution import NavSolution
from .aids import EKF_METHODS, EkfAid, EkfContext, Measurement, ekf_aids, ekf_counts
from . import kernels
from .ekf_record import Recorder, Tally, innovation_loglik
from .epochs import default_output_times
from .event_loop import CompiledLoop
from .layout import StateLayout
from .mechanization import Propagator, update_state
from .settings import EkfSettings
from .state import FilterState, initial_state, start_of_pass

#: Method ids and the acceleration form each applies (``None``: none).
METHODS = EKF_METHODS
#: Whether a pass without an observer runs in the compiled loop (:func:`compiled_loop_ready`):
#: ``None`` once its kernel is loaded, ``True`` always (compiling it when not), ``False`` never.
COMPILED_LOOP: bool | None = None


def kalman_update(s: FilterState, m: Measurement) -> tuple[float, float, bool, np.ndarray]:
    """Joseph-form update (``s.consider``: a Schmidt consider state, :attr:`FilterState.consider`);
    returns the NIS, the Gaussian log-likelihood of the innovation, whether it was applied (a
    positive ``m.gate`` rejects it when NIS exceeds the gate) and the whitened innovation."""
    dz = np.asarray(m.dz, float)
    nis, logdet, used, wz = update_state(
        s.P, m.H, m.R, dz, float(m.gate), s.consider, s.pos, s.v_n, s.R_nb, s.b_a, s.b_g, s.x_e
    )
    return nis, innovation_loglik(nis, logdet, len(dz)), used, wz


class EkfObserver:
    """Sees the loop: override what you need. ``kind`` is an aid's epoch kind (``"gnss"``,
    ``"stationary"``, ``"nhc"``, ``"odometry"``): the updates of one epoch come between
    :meth:`before` and :meth:`after`."""

    def start(self, setup: "EkfSetup") -> None:
        """Once, before the loop (e.g. to switch on the propagator's transition matrices)."""

    def before(self, t: float, kind: str, s: FilterState, prop: Propagator) -> None:
        """After the prediction to an update epoch, before its updates."""

    def update(self, t: float, m: Measurement, nis: float, used: bool, s: FilterState) -> None:
        """After each update (``used`` False: gated out, or evaluated only for the observer)."""

    def after(self, t: float, kind: str, s: FilterState, prop: Propagator) -> None:
        """After all updates of an epoch."""


@dataclass
class EkfSetup:
    """Everything the EKF's event loop needs, prepared once."""

    init: InitialState
    state: FilterState
    prop: Propagator
    aids: list[EkfAid]
    k: int  # IMU index of the sample holding at init.t

    @property
    def t0(self) -> float:
        return float(self.init.t)


def make_setup(
    run: RecordedRun,
    settings: EkfSettings,
    init: InitialState,
    quality: QualityReport,
    stationary=None,
    variant: str | None = None,
    observed: bool = False,
    cov_every: int = 1,
    t_stop: float | None = None,
) -> EkfSetup:
    """The pass's aids (:func:`gnssacc.estimators.aids.ekf_aids`), the state they make and its
    initial covariance, and the IMU propagator with the noise and the inflation of suspect spans
    (``stationary``: a :class:`gnssacc.prepare.stationary.StationaryReport` or ``None``); the
    aids may leave out their epochs after ``t_stop`` [s] (the pass stops there)."""
    segments = inflation_segments(run.imu, quality, settings.suspect)
    ctx = EkfContext(run, settings, init, stationary, variant, observed, segments, t_stop)
    aids = ekf_aids(ctx)
    layout = StateLayout.build(b for a in aids for b in a.states)
    imu = settings.imu
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
        layout=layout,
        q_turn=imu.gyro_turn_psd,
        rest=rest_samples(run, stationary, init),
    )
    k = int(np.searchsorted(prop.t, float(init.t), side="right"))
    return EkfSetup(init, initial_state(init, settings, layout), prop, aids, k)


def rest_samples(run: RecordedRun, stationary, init: InitialState) -> np.ndarray | None:
    """The IMU samples at which the error model is linearised about a vehicle at rest
    (:func:`gnssacc.estimators.mechanization.propagate`'s ``rest``): those inside a stationary
    span, on a run whose yaw the start found undetermined (``init.yaw_evidence``: it never turned
    or accelerated enough to tell it, so its attitude is the one it stood at); else ``None``.

    There the yaw is held as a consider state of about 100 deg, and linearised about each
    sample's specific force and the attitude of the moment, the EKF found the tilt separable from
    the horizontal accelerometer bias: a consumer IMU that never moved stated a tilt of 0.45 deg
    with a 2.6 deg error (docs/consistency.md, "A still vehicle's tilt"). Runs whose yaw is
    decided keep the samples' own specific force and attitude.
    """
    if stationary is None or not stationary.spans or init.yaw_evidence != "undetermined":
        return None
    return stationary.mask(run.imu.t)


def _events(aids: list[EkfAid], out_t: np.ndarray):
    """Event times, sources (index into ``aids``; ``len(aids)``: an output) and indices in time
    order. At equal times: by epoch kind (in the order of its first aid), then by index (the
    aids of one kind interleave epoch by epoch), then by aid; the outputs last."""
    first: dict[str, int] = {}
    for a in sorted(aids, key=lambda a: a.order):
        first.setdefault(a.epoch, a.order)
    times = [a.t for a in aids] + [out_t]
    big = max((a.order for a in aids), default=0) + 1
    group = [first[a.epoch] for a in aids] + [big]
    order = [a.order for a in aids] + [big]
    ev_t = np.concatenate(times)
    ev_src = np.concatenate([np.full(len(t), i) for i, t in enumerate(times)])
    ev_idx = np.concatenate([np.arange(len(t)) for t in times])
    ev_group = np.concatenate([np.full(len(t), g) for g, t in zip(group, times, strict=True)])
    ev_order = np.concatenate([np.full(len(t), o) for o, t in zip(order, times, strict=True)])
    idx_key = np.where(ev_src < len(aids), ev_idx, 0)
    sort = np.lexsort((ev_order, idx_key, ev_group, ev_t))
    return ev_t[sort], ev_src[sort], ev_idx[sort]


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
        The fixes' sigmas as stated (the settings' noise model applies ``[gnss] sigma_scale``).
    settings : EkfSettings or gnssacc.core.config.RunConfig
        The filter's settings (:class:`gnssacc.estimators.settings.EkfSettings`; a run
        configuration is reduced to them first).
    method : {"ekf", "ekf-acc", "ekf-accw", "ekf-vacc", "ekf-vaccw"}
        ``ekf``: position updates (the paper's baseline; with the GNSS velocity updates where the
        recording has velocities and ``[velocity] enabled``); ``ekf-acc``: position and
        GNSS-derived acceleration updates (the paper's method); ``ekf-accw``: the same with the
        window-consistent acceleration prediction; ``ekf-vacc``, ``ekf-vaccw``: the paper's and
        the window-consistent acceleration update with the acceleration fitted to the Doppler
        velocities. All of them add the other aids the run and the settings have (stationary
        updates when ``stationary`` is given and ``[zupt] enabled``, the non-holonomic
        constraint, wheel odometry).
    output_times : ndarray, optional
        Epochs [s] at which to report the state (after any update at the same time). Default:
        :func:`gnssacc.estimators.epochs.default_output_times`. Epochs before the filter starts
        are skipped.
    quality : QualityReport, optional
        Data-quality findings (:func:`gnssacc.checks.quality.check_imu` when omitted); suspect IMU
        spans get inflated process noise.
    init : InitialState, optional
        The start (what :func:`gnssacc.prepare.preparation.prepare` found, ``Prepared.init``); when
        omitted, the run's own (``run.init``), as it is. An estimator never looks for a start:
        :func:`gnssacc.prepare.passes.run_ekf` finds one for a run alone.
    stationary : gnssacc.prepare.stationary.StationaryReport, optional
        Where the vehicle stands still (zero-velocity and zero-rate updates there).
    store_P : bool
        Keep the full covariance at every output epoch.
    record_innovations : bool
        Keep every update's time, NIS per dof and log-likelihood in ``stats`` (``nis_<kind>_t``,
        ``nis_<kind>``, ``loglik_<kind>_series`` for kind in
        :data:`gnssacc.estimators.aids.KINDS`).
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
    wall0 = time.perf_counter()
    init, quality = start_of_pass(run, settings, init, quality)
    settings = EkfSettings.of(settings)
    setup = make_setup(
        run,
        settings,
        init,
        quality,
        stationary,
        METHODS[method],
        observer is not None,
        cov_every,
        t_stop,
    )
    t0, prop = setup.t0, setup.prop
    t_end = prop.t[-1] if t_stop is None else min(float(t_stop), prop.t[-1])
    out_t = default_output_times(run) if output_times is None else np.asarray(output_times, float)
    out_t = out_t[(out_t >= t0) & (out_t <= t_end)]
    ev = _events(setup.aids, out_t)
    stats = {**ekf_counts(), "init": setup.init.how, "t_init": t0}
    updates = _Updates(setup, observer, Tally(record_innovations), stats)
    loop = _EventLoop(setup, updates, Recorder(len(out_t), store_P), float(t_end), ev)
    if observer is not None:
        observer.start(setup)
    compiled = None
    if observer is None and not show_progress and compiled_loop_ready():
        compiled = CompiledLoop.of(setup, ev, updates.tally, stats, loop.rec)
    loop.run(compiled, method, show_progress)
    updates.close_unless(np.inf, None, -1)
    return loop.rec.solution(method, time.perf_counter() - wall0, updates.final_stats())


def compiled_loop_ready() -> bool:
    """Whether a pass without an observer runs its events with compiled steps in the compiled
    loop (:mod:`gnssacc.estimators.event_loop`): :data:`COMPILED_LOOP` when set, else once its
    kernel is loaded (:func:`gnssacc.estimators.kernels.loaded`; a first run's passes use the
    Python loop while it compiles in the background)."""
    return kernels.loaded("loop") if COMPILED_LOOP is None else COMPILED_LOOP


class _EventLoop:
    """The event loop of one pass in Python (the reference): :meth:`step` does one event."""

    def __init__(self, setup: EkfSetup, updates: "_Updates", rec: Recorder, t_end: float, ev):
        self.setup, self.updates, self.rec, self.t_end = setup, updates, rec, t_end
        self.s, self.prop, self.aids, self.t0 = setup.state, setup.prop, setup.aids, setup.t0
        self.ev_t, self.ev_src, self.ev_idx = (x.tolist() for x in ev)  # Python scalars
        self.k, self.t_cur = setup.k, self.t0

    def run(self, compiled: CompiledLoop | None, desc: str, show_progress: bool) -> None:
        """Every event of the pass: here (``compiled`` ``None``: the reference, with the progress
        bar ``desc`` when shown), or the stretches of events with compiled steps in the compiled
        loop and the others here."""
        n = len(self.ev_t)
        if compiled is None:
            for e in progress(range(n), desc=desc, enable=show_progress):
                if not self.step(e):
                    return
            return
        e = 0
        while e < n:
            e, self.k, self.t_cur = compiled.run(e, self.k, self.t_cur, self.t0, self.t_end)
            if e >= n or not self.step(e):
                return
            e += 1

    def step(self, e: int) -> bool:
        """Event ``e``; False when it is past the pass's end (the pass ends there)."""
        t_e, src, j, aids = self.ev_t[e], self.ev_src[e], self.ev_idx[e], self.aids
        if t_e > self.t_end:
            return False
        aid = aids[src] if src < len(aids) else None
        if aid is not None:
            aid.see(j)
        if t_e < self.t0:
            return True
        self.updates.close_unless(t_e, aid, j)
        if t_e > self.t_cur:
            t_prev, s, prop = self.t_cur, self.s, self.prop
            self.k, self.t_cur = prop.advance(s, self.k, t_prev, t_e)
            if len(s.x_e):  # the estimated Gauss-Markov states decay
                s.x_e *= np.exp(-(self.t_cur - t_prev) / prop.extra_tau)
        if aid is None:
            self.rec.add(t_e, self.s)
        else:
            self.updates.at(t_e, aid, j)
        return True


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
    """The measurement updates of one EKF pass, their tally and statistics, and the observer's
    epochs (the updates of the aids of one epoch kind at one time and index are one epoch)."""

    setup: EkfSetup
    observer: EkfObserver | None
    tally: Tally
    stats: dict
    epoch: tuple | None = None  # the observer's open epoch: (t, kind, index)

    def close_unless(self, t_e: float, aid: EkfAid | None, j: int) -> None:
        """End the observer's open epoch unless the event of ``aid`` at ``t_e`` (index ``j``)
        belongs to it."""
        obs, ep = self.observer, self.epoch
        if obs is None or ep is None:
            return
        if aid is None or ep != (t_e, aid.epoch, j):
            obs.after(ep[0], ep[1], self.setup.state, self.setup.prop)
            self.epoch = None

    def at(self, t_e: float, aid: EkfAid, j: int) -> None:
        """The updates of ``aid`` at its epoch ``j`` (time ``t_e``), each shown to the observer."""
        s, obs = self.setup.state, self.observer
        if obs is None:  # the pass alone (the tuner's, a method's): no observer to tell
            for m, apply in aid.updates(s, j, self.stats):
                if apply:
                    self.tally.add(t_e, m, *kalman_update(s, m))
            return
        if self.epoch is None:
            self.epoch = (t_e, aid.epoch, j)
            obs.before(t_e, aid.epoch, s, self.setup.prop)
        for m, apply in aid.updates(s, j, self.stats):
            if apply:
                nis, loglik, used, wz = kalman_update(s, m)
                self.tally.add(t_e, m, nis, loglik, used, wz)
            else:
                nis, used = float("nan"), False
            obs.update(t_e, m, nis, used, s)

    def final_stats(self) -> dict:
        """The pass's ``stats`` (see :func:`run_ekf`)."""
        tally, stats, s = self.tally, self.stats, self.setup.state
        stats.update(tally.stats())
        for aid in self.setup.aids:
            aid.final_stats(s, stats)
        stats["loglik"] = float(sum(tally.loglik.values()))
        return stats
