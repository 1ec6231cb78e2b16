"""Noise identification whose cost does not grow with the recording: the tuner's likelihood on a
bounded, representative part of a long run, confirmed over the whole of it.

The tuner (:mod:`gnssacc.prepare.tuning`) maximises the innovation likelihood of ~90 EKF passes;
over the whole run each pass costs its length, so a one-hour drive spent most of a minute before
its first estimate. A run longer than :data:`WINDOWED_FROM_S` is instead identified on windows
that together span :data:`SPAN_S` of IMU data, whatever the run's length:

- the first :data:`FIRST_S` from the tuner's start, as the whole-run pass begins (the turn-on
  biases are learnt there: their sigmas are the start's);
- :data:`N_LATER` later windows, one per stratum of the rest of the run (equal parts in time),
  each placed within its stratum where its share of rest (the stationary spans) and of turning
  (yaw rate above :data:`TURN_RATE_DEG_S`) is closest to the stratum's own: the motion, rests and
  turns of the run keep their weight. Each starts :data:`LEAD_S` before its scored part from the
  state and the full covariance (correlations kept: a start with the sigmas alone makes the first
  innovations look larger than they are, and the search answers with more process noise) of one
  reference pass over the whole run with the search's starting noise (every aid in use, the
  covariance propagated as in the tuner's passes); the updates of the lead are not scored (the
  covariance settles to the trial noise there).

Each trial point is one pass per window (:class:`WindowedPass`, a
:class:`~gnssacc.prepare.filter_pass.FilterPass` whose statistics add the windows' scored updates),
so the search itself is unchanged. A window's pass reads only its span of the run
(:func:`reads`, :meth:`RecordedRun.between <gnssacc.core.recording.RecordedRun.between>`): its
setup (the fixes' noise, the aids' epochs, the event list, the tally) then costs the window, not
the run, with the same numbers to rounding. The windows' log-likelihoods are added as a **stratified
estimate of the whole run's**: each later window's counts the length of its stratum over its
scored seconds (:attr:`Window.weight`), the first window's once. Added as they are, the first
window (where the filter converges from the start) would weigh 40 % of the objective instead of
the tenth of a 2,400 s run it is, and the search would answer that transient with more process
noise; weighted, the objective estimates the one the whole-run tuner maximises, and the
likelihood-ratio tests of its later steps (the Gauss-Markov fixes, the vehicle's axes) are made
on the scale of the whole run. The windows of a trial point are shared among the usable cores
(:func:`gnssacc.core.parallel.usable_jobs`, forked workers: the same numbers as in one process).

**The slow terms over the whole run.** Windows of a minute or two cannot tell a slow IMU error
from white noise. On a 2,400 s simulated car (seed 0, the other values the whole run's) the whole
run's log-likelihood falls by 14 and 11 from its peak at a quarter and at four times its tuned
accelerometer bias instability; the windows' (weighted to the whole run's scale) rises by 0.3 at
the quarter and falls by 3 at four times: they hardly tell it (the search left it 1.5-1.9x above
the whole run's on three seeds of four), and the gyros' bias instability came out 0.4-0.8x the
whole run's on all four. So each parameter of :data:`REFINED` is refined over the whole run, in
turn, from the windows' value: four passes at :data:`REFINE_OFFSETS` (side by side), the value at
the vertex of the parabola through their objective (the tuner's: likelihood plus prior, within
its bounds; :func:`gnssacc.prepare.tuning.refined_whole`). On those runs the whole run's
objective at the windows' gyro value was 30-100 worse than at the refined one. The
accelerometer's white noise is left as the windows give it (up to 6x the whole run's): the whole
run's likelihood hardly tells it either (within 2 over a decade and a half around the windows'
value, its prior holding it), and refined the same way it moved the PRMSE by 0.5 % at most, for
four passes more than the time target has room for.

Then one more pass over the whole run, with the tuned noise, confirms it against the reference
pass (the starting noise): the tuned noise must explain the whole run at least as well as the
starting noise (log-likelihood gain >= 0), else the run is tuned over its whole length as before
(:func:`tuned_on_windows` returns ``None``). The NIS the tuner reports is the whole run's.

**The budget.** :data:`SPAN_S` is set by what a noise estimate needs, not by any recording: the
scored part (480 s: the first window and four of 60 s after their leads) holds ~1,400 components
of 1 Hz fixes, a standard error of ~2 % on the fixes' sigma (``1 / sqrt(2 N)``); the first window
is a few times the ~100 s over which metre-level fixes resolve a vehicle IMU's turn-on biases,
and each later window is one car manoeuvre long (a turn, a stop and the speed changes around
it). What the windows cannot give is the whole run's precision: their estimate scatters as a
600 s recording's does (``bench/bench_tuning_length.py --accuracy`` shows that scatter beside the
whole run's). A run up to :data:`WINDOWED_FROM_S` long is tuned over its whole length exactly as
before (the windows and the ten whole-run passes would save little there).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, replace

import numpy as np

from ..core.parallel import usable_jobs
from ..core.recording import InitialState, RecordedRun
from ..core.states import ATT, BA, BG, NAV, POS, VEL
from .filter_pass import FilterPass
from .tuning import run_white_stats, starting_config, ungated

#: IMU seconds each trial pass covers on a windowed run [s].
SPAN_S = 600.0
#: A run longer than this is tuned on windows [s]: one and a half budgets. A trial point on
#: windows costs :data:`SPAN_S` of IMU (and the windows' starts), and the windowed tuning ten
#: whole-run passes more (the reference, the slow terms' eight, the confirming one): with ~80
#: trial points the whole run costs no more below ~700 s, and up to 900 s the saving (a fifth
#: at most) would be small against a change of method.
WINDOWED_FROM_S = 900.0
#: The first window, from the tuner's start [s].
FIRST_S = 240.0
#: Later windows (one per stratum of the rest of the run) and the unscored lead of each [s].
N_LATER = 4
LEAD_S = 30.0
#: Yaw rate above which the vehicle counts as turning, for the placement of the windows [deg/s].
TURN_RATE_DEG_S = 3.0
#: Steps at which the placements within a stratum are compared [s].
PLACEMENT_STEP_S = 10.0
#: The parameters refined over the whole run after the search on windows, in turn (module
#: notes): the slow terms, the accelerometer's and the gyros' bias instability, which windows of
#: a minute or two cannot tell from white noise.
REFINED = (("imu", "accel_bias_instability_mg"), ("imu", "gyro_bias_instability_deg_h"))
#: Where each is evaluated over the whole run, from the windows' value [decades].
REFINE_OFFSETS = (-0.75, -0.25, 0.25, 0.75)


#: Seconds of data a window's pass reads on each side of its span, at least [s] (its history:
#: the acceleration fit's last fixes, :func:`reads`).
MARGIN_S = 5.0


@dataclass(frozen=True)
class Window:
    """One window: the pass runs from ``start`` (``None``: the tuner's own) over ``t_from`` ..
    ``t_to`` and scores the updates from ``t_scored`` [s]; its log-likelihood counts ``weight``
    times (the seconds of the run it stands for over its scored seconds). ``reads``: the span
    of the run its pass reads (:func:`reads`; ``None``: the whole run)."""

    t_from: float
    t_scored: float
    t_to: float
    start: InitialState | None = None
    weight: float = 1.0
    reads: tuple[float, float] | None = None


def reads(run: RecordedRun, w: Window, cfg, stationary, quality) -> tuple[float, float]:
    """The span ``(t_a, t_b)`` [s] of ``run`` that ``w``'s pass reads: the same numbers from
    :meth:`RecordedRun.between <gnssacc.core.recording.RecordedRun.between>` as from the whole
    run, at the cost of the span. :data:`MARGIN_S` beyond the window, the ``[accel] window``
    fixes and velocities before it (what the acceleration fit holds when the pass starts), and
    whole every stationary span (its gyro blocks and their scatter) and every suspect IMU span
    with its ``[quality] suspect_local_window_s`` (its inflation's local sigma) that an end
    would cut."""
    a, b = w.t_from - MARGIN_S, w.t_to + MARGIN_S
    held = int(cfg["accel"]["window"]) + 1
    for stream in (run.gnss, run.gnss_vel):
        if stream is not None and len(stream.t):
            j = int(np.searchsorted(stream.t, w.t_from, side="left")) - held
            a = min(a, float(stream.t[j]) if j >= 0 else -np.inf)
    spans = [(s.t_start, s.t_end) for s in (stationary.spans if stationary is not None else [])]
    if quality is not None:
        lw = float(cfg["quality"]["suspect_local_window_s"])
        spans += [(s.t_start - lw, s.t_end + lw) for s in quality.spans]
    moved = True
    while moved:  # a span reaching past an end widens it, which may reach another span
        moved = False
        for s0, s1 in spans:
            if s0 < a <= s1 or s0 <= b < s1:
                a, b, moved = min(a, s0), max(b, s1), True
    return max(a, run.t_start), min(b, run.t_end)


def _shares(run: RecordedRun, stationary, t: np.ndarray) -> np.ndarray:
    """Per second ``t``: at rest (0/1) and turning (0/1)."""
    rest = stationary.mask(t).astype(float) if stationary is not None else np.zeros(len(t))
    wz = np.interp(t, run.imu.t, np.abs(run.imu.omega_ib_b[:, 2]))
    return np.column_stack([rest, (wz > np.radians(TURN_RATE_DEG_S)).astype(float)])


def placements(run: RecordedRun, stationary, t0: float) -> list[tuple[float, float]]:
    """The later windows' spans ``(t_from, t_to)`` (module notes), from ``t0`` (the end of the first
    window) to the end of the run."""
    length = (SPAN_S - FIRST_S) / N_LATER
    edges = np.linspace(t0, float(run.t_end), N_LATER + 1)
    out = []
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        if b - a <= length:
            out.append((float(a), float(b)))
            continue
        sec = np.arange(a, b, 1.0)
        sh = _shares(run, stationary, sec)
        target = sh.mean(axis=0)
        cands = np.arange(a, b - length + 1e-9, PLACEMENT_STEP_S)
        miss = [
            np.abs(sh[(sec >= c) & (sec < c + length)].mean(axis=0) - target).sum() for c in cands
        ]
        # Ties (a uniform stratum): the candidate nearest the stratum's middle.
        mid = 0.5 * (a + b - length)
        best = min(range(len(cands)), key=lambda i: (round(miss[i], 6), abs(cands[i] - mid)))
        out.append((float(cands[best]), float(cands[best] + length)))
    return out


def states_at(
    run, cfg, init, quality, times, filter_pass: FilterPass, stationary=None, method: str = "ekf"
) -> tuple[list[InitialState], dict]:
    """The filter's state and covariance at ``times`` [s], each as a start, and the statistics of
    the pass that gave them: one ungated pass of ``method`` from ``init`` with ``cfg`` (its noise,
    its aids), the covariance propagated as the tuner's passes propagate it."""
    sol = filter_pass(
        run,
        ungated(cfg),
        method,
        init=init,
        stationary=stationary,
        quality=quality,
        output_times=np.asarray(times, float),
        store_P=True,
        cov_every=int(cfg["tune"]["cov_every"]),
    )
    out = []
    for k in range(len(sol.t)):
        sig = sol.sigma[k]
        att = (
            np.sqrt(np.maximum(np.diag(sol.P[k][ATT, ATT]), 0.0)) if sol.P is not None else sig[ATT]
        )
        out.append(
            InitialState(
                t=float(sol.t[k]),
                lat=float(sol.lat[k]),
                lon=float(sol.lon[k]),
                h=float(sol.h[k]),
                v_n=sol.v_n[k].copy(),
                rpy=sol.rpy[k].copy(),
                sigma_pos_m=sig[POS].copy(),
                sigma_vel_mps=sig[VEL].copy(),
                sigma_att_rad=att,
                how=f"{init.how}; carried to t = {float(sol.t[k]):.2f} s",
                b_a=sol.b_a[k].copy(),
                b_g=sol.b_g[k].copy(),
                sigma_b_a=sig[BA].copy(),
                sigma_b_g=sig[BG].copy(),
                yaw_evidence=init.yaw_evidence,  # a yaw the run never told stays considered
                cov=None if sol.P is None else np.array(sol.P[k][NAV, NAV]),
            )
        )
    return out, sol.stats


def windows(
    run: RecordedRun, cfg, init, quality, stationary, filter_pass, noise=None
) -> list[Window]:
    """The windows of a long run (module notes); empty when the run is tuned whole. ``noise``
    (:class:`~gnssacc.prepare.stationary.StationaryNoise`, optional): the densities measured at
    rest, with which the reference pass runs (the search's start)."""
    return windows_and_reference(run, cfg, init, quality, stationary, filter_pass, noise)[0]


def windows_and_reference(
    run: RecordedRun, cfg, init, quality, stationary, filter_pass, noise=None, method: str = "ekf"
) -> tuple[list[Window], dict]:
    """:func:`windows`, and the statistics of the reference pass over the whole run (``method``,
    the search's starting noise, every aid ``cfg`` has: the whole run's likelihood before the
    tuning, :func:`tuned_on_windows`); ``([], {})`` when the run is tuned whole."""
    t0 = float(init.t)
    if run.t_end - t0 <= WINDOWED_FROM_S:
        return [], {}
    first = Window(t0, t0, t0 + FIRST_S)
    spans = placements(run, stationary, first.t_to)
    ref = starting_config(run, cfg, noise)
    times = [a for a, _ in spans]
    starts, before = states_at(run, ref, init, quality, times, filter_pass, stationary, method)
    stratum = (float(run.t_end) - first.t_to) / N_LATER  # each later window stands for one
    later = []
    for s, (_, b) in zip(starts, spans, strict=False):
        scored = min(s.t + LEAD_S, b)
        later.append(Window(s.t, scored, b, s, stratum / max(b - scored, 1e-9)))
    wins = [first] + later
    return [replace(w, reads=reads(run, w, cfg, stationary, quality)) for w in wins], before


def _scored(stats: dict, t_scored: float) -> dict:
    """A window's statistics with only the updates from ``t_scored`` counted (from its series)."""
    out = {}
    for key in [k for k in stats if k.startswith("nis_") and k.endswith("_t")]:
        kind = key[len("nis_") : -len("_t")]
        t = np.asarray(stats[key], float)
        keep = t >= t_scored
        ll, nis = np.asarray(stats[f"loglik_{kind}_series"]), np.asarray(stats[f"nis_{kind}"])
        out[f"loglik_{kind}"] = float(ll[keep].sum())
        out[f"n_{kind}_updates"] = int(keep.sum())
        out[f"nis_{kind}_mean"] = float(nis[keep].mean()) if keep.any() else None
        out[f"acf1_{kind}"] = stats.get(f"acf1_{kind}")
    return out


def merged(parts: list[dict], weights=None) -> dict:
    """The windows' statistics as one pass's over the run they stand for: the log-likelihoods
    added, each times its window's weight (default 1: a stratified estimate of the whole run's),
    the counts added as they are (the updates scored), the mean NIS and the lag-1 autocorrelation
    weighted by the updates times the weights."""
    out: dict = {}
    wts = np.ones(len(parts)) if weights is None else np.asarray(weights, float)
    kinds = {k[len("n_") : -len("_updates")] for p in parts for k in p if k.endswith("_updates")}
    for kind in kinds:
        n = np.array([p.get(f"n_{kind}_updates", 0) for p in parts], float)
        out[f"n_{kind}_updates"] = int(n.sum())
        out[f"loglik_{kind}"] = float(
            sum(p.get(f"loglik_{kind}", 0.0) * w for p, w in zip(parts, wts, strict=True))
        )
        for stat in (f"nis_{kind}_mean", f"acf1_{kind}"):
            vals = [(p.get(stat), w) for p, w in zip(parts, n * wts, strict=True) if w > 0]
            vals = [(v, w) for v, w in vals if v is not None]
            wsum = sum(w for _, w in vals)
            out[stat] = float(sum(v * w for v, w in vals) / wsum) if wsum > 0 else None
    out["loglik"] = float(sum(v for k, v in out.items() if k.startswith("loglik_")))
    return out


class WindowedPass:
    """A :class:`~gnssacc.prepare.filter_pass.FilterPass` over :class:`Window` s: one pass of
    ``filter_pass`` per window, statistics merged (:func:`merged`); the first window starts where
    the caller says (``init``), the others from their own starts. Only statistics are returned
    (``output_times`` must be empty), on a solution of the first window.

    With ``jobs`` > 1 the windows are shared among that many processes (this one and workers
    forked on the first call, which hold the recording as this process does; the windows of a
    share are every ``jobs``-th): the same passes, merged in the same order, so the same numbers
    as in one process. A worker that fails is replaced by this process (its windows run here).
    A process forked from this one (the tuner's trial points side by side) runs all the windows
    itself: it must not share the workers' pipes with this process. :meth:`close` ends the
    workers.
    """

    def __init__(self, wins: list[Window], filter_pass: FilterPass, jobs: int = 1):
        self.wins, self.filter_pass, self.passes = wins, filter_pass, 0
        self.jobs = max(1, min(int(jobs), len(wins)))
        self.workers: list | None = None
        self.owner = os.getpid()  # only the process that made it talks to its workers
        self.parts: dict = {}  # window -> (run, quality, the span of the run, of the report)

    def _window(self, k: int, run, cfg, method, init, kw) -> tuple[dict, object]:
        w = self.wins[k]
        start = init if w.start is None else w.start
        lead = w.t_scored > w.t_from  # a lead not scored: the series tell what is
        run, kw = self._part(k, run, kw)
        sol = self.filter_pass(
            run, cfg, method, init=start, t_stop=w.t_to, **kw, record_innovations=lead
        )
        return (_scored(sol.stats, w.t_scored) if lead else sol.stats), sol

    def _part(self, k: int, run, kw: dict) -> tuple[RecordedRun, dict]:
        """Window ``k``'s span of ``run`` and of the quality report in ``kw`` (made once per run
        and report: the turn rates and inflation kept per run are then found again)."""
        w = self.wins[k]
        if w.reads is None:
            return run, kw
        quality = kw.get("quality")
        have = self.parts.get(k)
        if have is None or have[0] is not run or have[1] is not quality:
            sub = run.between(*w.reads) if have is None or have[0] is not run else have[2]
            i0, i1 = run.imu_range(*w.reads)
            part = None if quality is None else quality.between(i0, i1)
            have = self.parts[k] = (run, quality, sub, part)
        return have[2], {**kw, "quality": have[3]}

    def _share(self, j: int) -> list[int]:
        return list(range(j, len(self.wins), self.jobs))

    def __call__(self, run, cfg, method="ekf", *, init=None, **kw):
        parts: dict = {}
        asked = self._ask(run, (cfg, method, init, kw))
        first = None
        for k in self._share(0) if asked else range(len(self.wins)):
            parts[k], sol = self._window(k, run, cfg, method, init, kw)
            first = sol if k == 0 else first
        for j, conn in asked:
            try:
                got = conn.recv()
            except (EOFError, OSError):  # the worker died: no workers more
                self.close()
                got = {}
            if "failed" in got:  # a pass that raises: raised here, as in one process
                got = {}
            parts.update(got)
            for k in [k for k in self._share(j) if k not in parts]:
                parts[k], _ = self._window(k, run, cfg, method, init, kw)
        self.passes += 1
        return replace(
            first,
            stats=merged(
                [parts[k] for k in range(len(self.wins))],
                [w.weight for w in self.wins],
            ),
        )

    def _ask(self, run, job) -> list:
        """Send ``job`` to the workers (started on the first call); ``[(share, connection)]``."""
        if self.jobs < 2 or os.getpid() != self.owner:
            # A process forked from the owner (the tuner evaluating trial points side by side,
            # gnssacc.core.parallel) holds the owner's pipes: used from both, the workers' answers
            # would go to either. It runs every window itself.
            return []
        if self.workers is None:
            self._start(run)
        asked = []
        for j, (conn, _) in enumerate(self.workers or [], start=1):
            try:
                conn.send(job)
                asked.append((j, conn))
            except (OSError, ValueError):
                self.close()
                return []
        return asked

    def _start(self, run) -> None:
        import multiprocessing
        import sys

        ctx = multiprocessing.get_context("fork")
        sys.stdout.flush()  # a child must not write this process's buffers again
        sys.stderr.flush()
        self.workers = []
        for j in range(1, self.jobs):
            mine, theirs = ctx.Pipe()
            p = ctx.Process(target=self._serve, args=(theirs, j, run), daemon=True)
            p.start()
            theirs.close()
            self.workers.append((mine, p))

    def _serve(self, conn, j: int, run) -> None:
        """A worker: the windows of share ``j`` for each job received, until told to stop (or
        interrupted: quietly, the parent says what happened)."""
        try:
            while (job := conn.recv()) is not None:
                cfg, method, init, kw = job
                try:
                    got = {
                        k: self._window(k, run, cfg, method, init, kw)[0] for k in self._share(j)
                    }
                except Exception:  # noqa: BLE001 (the parent runs these windows and raises)
                    got = {"failed": True}
                conn.send(got)
        except BaseException:  # noqa: BLE001 (EOF, Ctrl-C: the worker just ends)
            return

    def close(self) -> None:
        """End the workers (the windows then run in this process)."""
        for conn, p in self.workers or []:
            try:
                conn.send(None)
            except (OSError, ValueError):
                pass
            p.join(timeout=5.0)
            if p.is_alive():
                p.terminate()
        self.workers, self.jobs = None, 1


def tuned_on_windows(run, cfg, stationary, quality, init, noise, *, filter_pass: FilterPass):
    """:func:`gnssacc.prepare.tuning.tune` on the windows of a long run, confirmed over the whole
    run (module notes): ``(cfg, result)`` as :func:`~gnssacc.prepare.tuning.tune` gives them, the
    result's NIS and log-likelihoods those of the whole run with the configured and the tuned noise
    (every aid in use) and ``from_stationary["windows"]`` what was done; ``None`` when the run is
    tuned whole (short, or the tuned noise not confirmed)."""
    import time

    from .tuning import aids, tune

    t0 = time.perf_counter()
    method = "ekf-acc" if cfg["tune"]["likelihood"] == "position+accel" else "ekf"
    wins, before = windows_and_reference(
        run, cfg, init, quality, stationary, filter_pass, noise, method
    )
    if not wins:
        return None
    windowed = WindowedPass(wins, filter_pass, usable_jobs())
    try:
        cfg_t, result = tune(run, cfg, stationary, quality, init, noise, filter_pass=windowed)
    finally:
        windowed.close()
    cfg_t, result, refined = _refined(
        run, cfg, cfg_t, result, stationary, quality, init, filter_pass
    )
    kinds = ("pos", "zaru") + aids(run, cfg_t)[1]
    kinds += ("acc",) if method == "ekf-acc" else ()
    scale = float(cfg_t["gnss"]["sigma_scale"]) / float(cfg["gnss"]["sigma_scale"])
    tuned_init = replace(init, sigma_pos_m=init.sigma_pos_m * scale)
    after = run_white_stats(
        run, cfg_t, stationary, quality, tuned_init, filter_pass=filter_pass, method=method
    )
    gain = sum(after[f"loglik_{k}"] - before[f"loglik_{k}"] for k in kinds)
    info = dict(result.from_stationary)
    info["windows"] = {
        "spans_s": [[w.t_from - run.t_start, w.t_to - run.t_start] for w in wins],
        "scored_from_s": [w.t_scored - run.t_start for w in wins],
        "imu_seconds_per_pass": float(sum(w.t_to - w.t_from for w in wins)),
        "run_seconds": float(run.duration_s),
        "whole_run_loglik_gain": float(gain),
        "confirmed": bool(gain >= 0.0),
        "refined_over_whole_run": refined,
    }
    if gain < 0.0:  # the windows' noise explains the whole run worse than the starting noise
        return None
    result = replace(
        result,
        from_stationary=info,
        nis_before=before.get("nis_pos_mean"),
        nis_after=after.get("nis_pos_mean"),
        loglik_before=float(sum(before[f"loglik_{k}"] for k in kinds)),
        loglik_after=float(sum(after[f"loglik_{k}"] for k in kinds)),
        n_evaluations=result.n_evaluations + 2,  # the reference (the start's) and the tuned one
        seconds=time.perf_counter() - t0,
    )
    return cfg_t, result


def _refined(run, cfg, cfg_t, result, stationary, quality, init, filter_pass):
    """``(cfg_t, result)`` with each free parameter of :data:`REFINED` refined over the whole run
    (:func:`gnssacc.prepare.tuning.refined_whole`, from the windows' value), and what was done per
    parameter (``section.key`` -> the windows' value, the refined one and the profile)."""
    from .tuning import refined_whole

    done: dict = {}
    values = {sec: dict(vals) for sec, vals in result.values.items()}
    n = 0
    for sec, key in REFINED:
        name = f"{sec}.{key}"
        if key not in values.get(sec, {}) or np.size(cfg_t[sec][key]) != 1:
            continue  # set by the user, not identified on this run, or per axis
        got, passes, profile = refined_whole(
            run,
            cfg_t,
            (sec, key),
            float(np.asarray(result.start.get(name, cfg_t[sec][key])).ravel()[0]),
            REFINE_OFFSETS,
            stationary,
            quality,
            init,
            init_scale=float(cfg["gnss"]["sigma_scale"]),
            filter_pass=filter_pass,
            at_rest=result.from_stationary,
        )
        n += passes
        done[name] = {"windows": float(cfg_t[sec][key]), "refined": got, **profile}
        values[sec][key] = float(f"{got:.4g}")
        cfg_t = cfg_t.with_values({sec: {key: values[sec][key]}}, "tuned")
    return cfg_t, replace(result, values=values, n_evaluations=result.n_evaluations + n), done
