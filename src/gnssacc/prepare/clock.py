"""The clock offset the estimator finds: the IMU-to-GNSS offset that maximises the EKF's innovation
likelihood around stage 1's estimate (:mod:`gnssacc.checks.timeoffset`), and its verdict against
the stamps as given (:mod:`gnssacc.prepare.judge`).

The EKF (position and stationary updates, the configured noise) runs with the IMU shifted by
``d`` from one start, and the log-likelihood of its position innovations over a fixed set of
fixes is maximised over ``d`` (scipy's bounded ``minimize_scalar``) in a bracket of
:data:`BRACKET_SIGMAS` of stage 1's sigma around it, and the verdict compares the best offset with
the stamps as given from the same start. The start is the run's own
(:mod:`gnssacc.prepare.start`), carried by the as-given pass to where every shifted IMU has
data. A stage-1 offset beyond :data:`LARGE_SHIFT_S` is too far for one start: the run shifted by
it gets its own start (yaw bank), and the as-given run keeps its own. The offset's 1-sigma comes
from the curvature of the log-likelihood over a step that lowers it by :data:`CURVATURE_DROP` (it
is jagged on a smaller scale).

What is attainable depends on the fixes. Measured on a simulated 120 s car run (consumer IMU):
1 Hz fixes with 5 cm white noise give a 1-sigma of ~4 ms, 0.5 m white ~17 ms, 3 m white ~70 ms.

Known clock relations: stamps on an absolute clock (UNIX or GPS seconds) beside fixes on another
differ by the GPS - UTC leap seconds of their date exactly (an IMU logged in GPS time on the UNIX
epoch beside an RTKLIB ``.pos`` in GPST). Which of the two models the fixes support, the exact
relation or a free offset (one parameter more), is a choice between nested models: the free one
is taken only when its log-likelihood beats the relation's by more than the Bayesian information
criterion's penalty for one parameter, ``ln(n) / 2`` over ``n`` scored fixes (2.3 for 100
fixes, 3.1 for 500), else the exact relation (:func:`known_offsets`): with 3 m fixes the free
estimate is tens of milliseconds off (18.107 +- 0.053 s on a 2-minute car run), which a truth on
the IMU's clock would carry too.

Refuted cheaply (:func:`_refuted_at_once`): the search is a sequential test. Its first passes
score the stamps as given and stage 1's offset; when the stamps as given are the more likely by
:data:`QUICK_REFUTE_MARGIN` (the decisive gain), the log-likelihood's curvature around them (two to
eight passes over a step that lowers it by :data:`CURVATURE_DROP`, as for the unseen offset below)
places its maximum near them, and one pass there gives the verdict: refuted when the best offset
near the stamps gains less than :data:`gnssacc.prepare.judge.REFUTE_GAIN`, with the curvature's
1-sigma. Otherwise (the proposal not clearly worse, the likelihood too flat, or the maximum near
the stamps a real gain) the bounded search decides, as it did for every proposal before: on KITTI
(stage 1 proposes -0.41 s) 6 passes instead of 21, the same verdict. The passes a step needs
together (the stamps as given and the proposal, the two sides of a curvature step) run side by
side (:meth:`_Shifts.ahead`; on KITTI 5 passes in 3 rounds), the same as one after the other.

How large an offset could go unseen (:func:`unseen_offset`): the likelihood's 1-sigma at the
stamps as given, from its curvature, times the number of sigmas a decisive verdict needs
(``sqrt(2 x needed gain)``): a smaller offset is never proven, whatever the checks propose.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..checks.findings import Finding
from ..checks.timeoffset import OffsetEstimate, shifted
from ..core.config import RunConfig
from ..core.parallel import KeptWorkers, side_by_side
from ..core.recording import InitialState, RecordedRun
from ..core.states import ATT, BA, BG, POS, VEL
from ..sources.gnss_time import ABSOLUTE_CLOCK_MIN_S, gps_seconds_to_unix, leap_seconds_at_unix
from .filter_pass import FilterPass
from .judge import BURN_IN_S, LR_MIN, RATE_MIN, Innovations, Verdict, compare, innovations
from .start import StartPieces, start_pieces
from .tuning import ungated, without_aids

#: Stage 2's uncertainty is the curvature of the log-likelihood over a step that lowers it by this
#: much on average (a 2-sigma step), from a parabola through five points. On a smaller scale the
#: log-likelihood is jagged: by ~1.5 within 20 ms on a 3-minute slow-UGV run with a consumer IMU and
#: 3 m fixes, where the step a drop of 1 chose gave a sigma of 12 ms for an error of 0.2 s.
CURVATURE_DROP = 2.0
#: The bracket reaches this many of stage 1's sigmas beyond 0 and stage 1, within the bounds [s].
BRACKET_SIGMAS = 4.0
BRACKET_MIN_S, BRACKET_MAX_S = 0.5, 2.0
#: The sequential test (module notes): a proposal whose own offset the stamps as given beat by
#: this much log-likelihood is refuted from the curvature around them, without the search. The
#: decisive gain (:data:`gnssacc.prepare.judge.LR_MIN`): the proposal loses as clearly as a proven
#: correction wins.
QUICK_REFUTE_MARGIN = LR_MIN
#: A stage-1 offset beyond this gets a start of its own [s] (module notes): the as-given filter,
#: carried to where every shift has data, starts a hypothesis a second away with an attitude and
#: velocity made for the wrong IMU samples, which pulls the likelihood's maximum toward 0 (by 0.1 s
#: for a 1 s offset with 5 cm fixes); within half a second it does not.
LARGE_SHIFT_S = 0.5


def known_drop(n_fixes: int) -> float:
    """How much better than a known clock relation a free offset must explain ``n_fixes`` fixes
    to be taken instead (module notes: the information criterion's ``ln(n) / 2``)."""
    return 0.5 * float(np.log(max(n_fixes, 2)))


def known_offsets(run: RecordedRun) -> tuple[float, ...]:
    """The clock relations the run's stamps are known to be able to have [s]: +-(GPS - UTC) at
    their date when they are absolute seconds (read as UNIX and as GPS seconds), else none."""
    t0 = float(run.t_start)
    if t0 < ABSOLUTE_CLOCK_MIN_S:
        return ()
    leaps = {float(leap_seconds_at_unix(t0)), float(leap_seconds_at_unix(gps_seconds_to_unix(t0)))}
    return tuple(sorted({s * v for v in leaps if v > 0 for s in (1.0, -1.0)}))


def state_at(
    run: RecordedRun, cfg: RunConfig, pieces: StartPieces, t: float, filter_pass: FilterPass
) -> InitialState:
    """The as-given filter's state and sigmas at ``t`` [s] as a start (``pieces.init`` when ``t`` is
    its own time)."""
    init = pieces.init
    if t <= float(init.t) + 1e-9:
        return init
    sol = filter_pass(
        run,
        ungated(without_aids(cfg)),
        "ekf",
        init=init,
        quality=pieces.quality,
        output_times=np.array([t]),
        store_P=True,
        t_stop=t,  # nothing later moves the state at t: the pass ends there
    )
    sig = sol.sigma[-1]
    att = np.sqrt(np.maximum(np.diag(sol.P[-1][ATT, ATT]), 0.0)) if sol.P is not None else sig[ATT]
    return InitialState(
        t=float(sol.t[-1]),
        lat=float(sol.lat[-1]),
        lon=float(sol.lon[-1]),
        h=float(sol.h[-1]),
        v_n=sol.v_n[-1].copy(),
        rpy=sol.rpy[-1].copy(),
        sigma_pos_m=sig[POS].copy(),
        sigma_vel_mps=sig[VEL].copy(),
        sigma_att_rad=att,
        how=f"{init.how}; carried to t = {t:.2f} s",
        b_a=sol.b_a[-1].copy(),
        b_g=sol.b_g[-1].copy(),
        sigma_b_a=sig[BA].copy(),
        sigma_b_g=sig[BG].copy(),
        yaw_evidence=init.yaw_evidence,  # a yaw the run never told stays considered
    )


@dataclass
class _Shifts(KeptWorkers):
    """Innovations of the reference run shifted by ``d`` [s], from one start, cached by ``d``."""

    run: RecordedRun
    cfg: RunConfig
    pieces: StartPieces
    start: InitialState
    filter_pass: FilterPass
    t_from: float
    t_to: float

    def __post_init__(self):
        self.cache: dict = {}
        self.kept_for = self._pass  # the workers :meth:`ahead` keeps, ended with the block

    def at(self, d: float) -> Innovations | None:
        key = round(float(d), 9)
        if key not in self.cache:
            self.cache[key] = self._pass(float(d))
        return self.cache[key]

    def ahead(self, *ds: float) -> None:
        """The passes at the shifts ``ds`` [s] not made yet, side by side
        (:func:`gnssacc.core.parallel.side_by_side`: forked, each process holds the run; only the
        innovations travel; the workers kept until the ``with`` block ends), kept for :meth:`at`:
        the same as one after the other."""
        todo: dict = {}
        for d in ds:
            todo.setdefault(round(float(d), 9), float(d))  # the first of a key, as at() takes it
        todo = {k: d for k, d in todo.items() if k not in self.cache}
        if len(todo) < 2:
            return  # one pass: made where it is asked for
        made = side_by_side(self._pass, [(d,) for d in todo.values()], keep=True)
        self.cache.update(zip(todo, made, strict=True))

    def _pass(self, d: float) -> Innovations | None:
        # Without stationary updates: the spans were found on the stamps as given, and a shifted
        # IMU meets them moving (the fixes are the measure of the shift).
        return innovations(
            shifted(self.run, d),
            self.cfg,
            self.pieces,
            self.filter_pass,
            init=self.start,
            stationary=False,
        )

    def cost(self, d: float) -> float:
        """Negative log-likelihood over the fixed fix set and the GNSS velocities among them
        (``inf`` when a pass misses some fixes)."""
        inn = self.at(d)
        if inn is None:
            return float("inf")
        m = (inn.t >= self.t_from) & (inn.t <= self.t_to)
        if m.sum() != self.n_scored:
            return float("inf")
        mv = (inn.t_vel >= self.t_from) & (inn.t_vel <= self.t_to)  # GNSS velocities, if any
        return -float(inn.loglik[m].sum()) - float(inn.loglik_vel[mv].sum())

    @property
    def n_scored(self) -> int:
        g = self.run.gnss.t
        return int(np.sum((g >= self.t_from) & (g <= self.t_to)))


def _sigma(shifts: _Shifts, d: float, f0: float, half_width: float) -> float | None:
    """1-sigma of the offset from the curvature of the log-likelihood at its maximum ``d`` (module notes)."""
    h = 0.01
    while True:
        shifts.ahead(d + h, d - h)
        fp, fm = shifts.cost(d + h), shifts.cost(d - h)
        if 0.5 * (fp + fm) - f0 >= CURVATURE_DROP or h >= 0.25 * half_width:
            break
        h *= 2.0
    shifts.ahead(d - 0.5 * h, d + 0.5 * h)
    x = np.array([-h, -0.5 * h, 0.0, 0.5 * h, h])
    y = np.array([fm, shifts.cost(d - 0.5 * h), f0, shifts.cost(d + 0.5 * h), fp])
    if not np.all(np.isfinite(y)):
        return None
    curv = 2.0 * float(np.polyfit(x, y, 2)[0])
    return max(float(1.0 / np.sqrt(curv)), 0.001) if curv > 0 and np.isfinite(curv) else None


def evaluate_offset(
    run: RecordedRun, cfg: RunConfig, finding: Finding, base: StartPieces, filter_pass: FilterPass
) -> tuple[Verdict, RecordedRun, OffsetEstimate | None]:
    """The best offset near stage 1 and the verdict on it against the stamps as given (module notes).

    Returns
    -------
    verdict : Verdict
    corrected : RecordedRun
        ``run`` with the best offset added to its IMU stamps.
    estimate : OffsetEstimate or None
        The best offset (total, relative to the stamps as given) and its 1-sigma.
    """
    d1, s1 = float(finding.details["stage1_s"]), float(finding.details["stage1_sigma_s"])
    hw = float(np.clip(BRACKET_SIGMAS * s1, BRACKET_MIN_S, BRACKET_MAX_S))
    far = abs(d1) > LARGE_SHIFT_S
    centre = d1 if far else 0.0
    ref = shifted(run, centre) if far else run
    pieces = start_pieces(ref, cfg, filter_pass) if far else base
    lo, hi = (
        (-hw, hw) if far else (d1 - hw, d1 + hw)
    )  # the search; the stamps as given (0) are scored too
    t_start = max(float(pieces.init.t), ref.t_start + max(hi, 0.0) + 0.05)
    start = state_at(ref, cfg, pieces, t_start, filter_pass)
    with _Shifts(
        ref, cfg, pieces, start, filter_pass, t_start + BURN_IN_S, ref.t_end - max(-lo, 0.0) - 0.05
    ) as shifts:  # its workers, if any, end with the block
        if not far and not known_offsets(run):
            quick = _refuted_at_once(shifts, d1, hw)
            if quick is not None:  # the first passes refute the proposal: no search
                verdict, d, sigma = quick
                return (
                    verdict,
                    shifted(run, d),
                    OffsetEstimate(d, sigma, True, method="EKF likelihood"),
                )
        from scipy.optimize import minimize_scalar  # only for the search (0.2-0.5 s to import)

        res = minimize_scalar(
            shifts.cost, bounds=(lo, hi), method="bounded", options={"xatol": 0.002}
        )
        d_free, f0 = float(res.x), float(res.fun)
        d, how = _known(shifts, known_offsets(run), centre, d_free, f0, (lo, hi))
        total = centre + d
        if far:  # the stamps as given, from their own start
            verdict = compare(
                innovations(run, cfg, base, filter_pass, stationary=False),
                shifts.at(d),
                t_from=shifts.t_from,
                t_to=shifts.t_to,
            )
        else:
            verdict = compare(shifts.at(0.0), shifts.at(d), t_from=shifts.t_from, t_to=shifts.t_to)
        sigma = _sigma(shifts, d_free, f0, hw) if np.isfinite(f0) else None
        est = None if sigma is None else OffsetEstimate(total, sigma, True, method=how)
        return verdict, shifted(run, total), est


def _curvature(shifts: _Shifts, f0: float, max_step: float) -> tuple[float, float, float, float]:
    """``(h, drop, f(h), f(-h))``: the step over which the cost rises by :data:`CURVATURE_DROP` on
    average around 0 (from :data:`UNSEEN_FIRST_STEP_S`, scaled as a parabola would need, at most
    ``max_step``; at most four tries) and the costs there."""
    h, drop, fp, fm = UNSEEN_FIRST_STEP_S, 0.0, f0, f0
    for _ in range(4):
        shifts.ahead(h, -h)
        fp, fm = shifts.cost(h), shifts.cost(-h)
        drop = 0.5 * (fp + fm) - f0
        if not np.isfinite(drop) or drop >= CURVATURE_DROP or h >= max_step:
            break
        h = min(max_step, h * float(np.sqrt(1.25 * CURVATURE_DROP / max(drop, 0.02))))
    return h, drop, fp, fm


def _refuted_at_once(shifts: _Shifts, d1: float, half_width: float):
    """The sequential test of a proposal (module notes): ``(verdict, best offset, its 1-sigma)``
    when the first passes refute it, else ``None`` (the full search decides)."""
    shifts.ahead(0.0, d1)
    f0, f1 = shifts.cost(0.0), shifts.cost(d1)
    if not (np.isfinite(f0) and np.isfinite(f1)) or f1 - f0 < QUICK_REFUTE_MARGIN:
        return None
    h, drop, fp, fm = _curvature(shifts, f0, min(half_width, abs(d1)))
    if not (np.isfinite(drop) and drop >= CURVATURE_DROP):
        return None  # too flat here to place the maximum
    d = float(np.clip(0.25 * h * (fm - fp) / drop, -h, h))  # the parabola's vertex
    verdict = compare(shifts.at(0.0), shifts.at(d), t_from=shifts.t_from, t_to=shifts.t_to)
    if not verdict.refuted:
        return None
    return verdict, d, h / float(np.sqrt(2.0 * drop))


def _known(shifts: _Shifts, known, centre: float, d: float, f0: float, bounds) -> tuple:
    """``(d, method)``: the known relation (:func:`known_offsets`) the free best ``d`` cannot be
    told from, relative to ``centre``, or ``d`` itself."""
    near = [k - centre for k in known if bounds[0] <= k - centre <= bounds[1]]
    costs = [(shifts.cost(k), k) for k in near]
    cost, k = min(costs, default=(np.inf, d))
    if cost - f0 <= known_drop(shifts.n_scored):
        return k, f"EKF likelihood; the GPS - UTC leap seconds, {cost - f0:.1f} below the free best"
    return d, "EKF likelihood"


#: The largest shift the curvature at the stamps as given is measured over [s] (beyond it the
#: offset is taken as unobservable: the motion cannot show it).
UNSEEN_MAX_STEP_S = 1.0
#: ... and the first one tried [s] (about the 1-sigma of 3 m fixes on a car).
UNSEEN_FIRST_STEP_S = 0.1


def offset_sigma(
    run: RecordedRun, cfg: RunConfig, pieces: StartPieces, filter_pass: FilterPass
) -> tuple[float, float]:
    """The 1-sigma of a clock offset at the stamps as given [s] (the log-likelihood's curvature
    over a step that lowers it by :data:`CURVATURE_DROP`, at most :data:`UNSEEN_MAX_STEP_S`; ``inf``
    when even that step does not) and the minutes of fixes scored. A few EKF passes."""
    hw = UNSEEN_MAX_STEP_S
    t_start = max(float(pieces.init.t), run.t_start + hw + 0.05)
    start = state_at(run, cfg, pieces, t_start, filter_pass)
    t_to = run.t_end - hw - 0.05
    g = run.gnss.t[(run.gnss.t >= t_start + BURN_IN_S) & (run.gnss.t <= t_to)]
    minutes = float(g[-1] - g[0]) / 60.0 if len(g) > 1 else 0.0
    with _Shifts(run, cfg, pieces, start, filter_pass, t_start + BURN_IN_S, t_to) as shifts:
        shifts.ahead(0.0, UNSEEN_FIRST_STEP_S, -UNSEEN_FIRST_STEP_S)  # _curvature's first step
        f0 = shifts.cost(0.0)
        h, drop, _, _ = _curvature(shifts, f0, hw)
    if not (np.isfinite(drop) and drop >= CURVATURE_DROP):
        return float("inf"), minutes
    return h / float(np.sqrt(2.0 * drop)), minutes


def unseen_offset(sigma_s: float, minutes: float) -> float:
    """The largest clock offset no verdict would prove with the likelihood's 1-sigma ``sigma_s``
    over ``minutes`` of fixes [s]: the shift whose expected log-likelihood gain,
    ``(d / sigma)^2 / 2``, reaches the decisive gain."""
    needed = max(LR_MIN, RATE_MIN * minutes)
    return float(np.sqrt(2.0 * needed) * sigma_s)
