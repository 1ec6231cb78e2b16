"""The GNSS velocities' time-tag error the estimator finds: the shift of their time tags that
maximises the EKF's innovation likelihood (positions and velocities) near the one the view
proposes (:func:`gnssacc.checks.velcheck.time_proposal`), and its verdict against the tags as
given (:mod:`gnssacc.prepare.judge`).

Every shifted pass starts from the start the run makes with its velocities shifted by the view's
lag (the start's yaw bank uses the velocities: the tags as given can start it tenths of a degree
and metres per second off), the tags as given from theirs; all are scored over the same fixes
and velocities: :data:`gnssacc.prepare.judge.BURN_IN_S` after the later start up to
:data:`gnssacc.checks.velcheck.MAX_LAG_S` before the end. The search is
scipy's bounded ``minimize_scalar`` within :data:`SEARCH_HALF_WIDTH_S` of the view's lag (the view
puts a lag within a tenth of a second of the truth with 3 m fixes on a car; at walking pace
within a few tenths), to :data:`SEARCH_TOL_S`: about ten EKF passes.

Velocities tagged at the wrong fix (a format with one record per fix: the velocity beside the
next or the previous fix) are off by whole fix intervals, a known relation: the shift that puts
them back on the fixes' tags is taken when the free best explains the data no better than the
information criterion's penalty for one parameter (as the clock's leap seconds:
:mod:`gnssacc.prepare.clock`); the free best is a few milliseconds off, which raises the velocity
NIS of a car by a fifth.
"""

from __future__ import annotations


import numpy as np

from ..checks.findings import Finding
from ..checks.velcheck import MAX_LAG_S, shifted_velocities, with_velocities
from ..core.config import RunConfig
from ..core.recording import RecordedRun
from .filter_pass import FilterPass
from .clock import known_drop
from .judge import BURN_IN_S, Innovations, Verdict, compare, innovations
from .start import StartPieces, start_pieces

#: Half-width of the search around the view's lag [s], and its tolerance [s].
SEARCH_HALF_WIDTH_S = 0.3
SEARCH_TOL_S = 0.005
#: Velocity tags within this of a fix's are on it [s].
ON_FIX_S = 1e-3


def _shifted(run: RecordedRun, d: float) -> RecordedRun:
    """``run`` with ``d`` [s] added to its velocities' time tags."""
    return with_velocities(run, shifted_velocities(run.gnss_vel, d))


def _cost(inn: Innovations | None, d: float, t_from: float, t_to: float) -> float:
    """Negative log-likelihood of the fixes and of the velocities (by their given time tags)
    within ``[t_from, t_to]`` [s]."""
    if inn is None:
        return float("inf")
    m = (inn.t >= t_from) & (inn.t <= t_to)
    tv = inn.t_vel - d
    mv = (tv >= t_from) & (tv <= t_to)
    return -float(inn.loglik[m].sum()) - float(inn.loglik_vel[mv].sum())


def _on_the_fixes(run: RecordedRun, d: float, f: float, cost) -> float:
    """The shift that puts the velocities on the fixes' own time tags (module notes), when the
    free best shift ``d`` (cost ``f``) explains the data no better than by the information
    criterion's ``ln(n) / 2`` (:func:`gnssacc.prepare.clock.known_drop`), else ``d``."""
    t_fix, t_vel = run.gnss.t, run.gnss_vel.t
    if len(t_fix) < 2:
        return round(d, 6)
    step = float(np.median(np.diff(t_fix)))
    snap = round(d / step) * step
    k = np.clip(np.searchsorted(t_fix, t_vel + snap), 1, len(t_fix) - 1)
    near = np.minimum(np.abs(t_fix[k] - t_vel - snap), np.abs(t_fix[k - 1] - t_vel - snap))
    if snap == 0.0 or float(np.median(near)) > ON_FIX_S or abs(snap - d) > SEARCH_HALF_WIDTH_S:
        return round(d, 6)
    return round(snap, 6) if cost(snap) - f <= known_drop(len(t_vel)) else round(d, 6)


def evaluate_lag(
    run: RecordedRun, cfg: RunConfig, finding: Finding, base: StartPieces, filter_pass: FilterPass
) -> tuple[Verdict, RecordedRun, StartPieces]:
    """The best time-tag shift near the view's (module notes), the verdict on it against the tags
    as given, the run so corrected and its start (the estimators start there when it is
    applied); ``finding.details`` get ``vel_shift_s`` (the shift, added to the tags) and
    ``lag_s`` (its opposite: how late the tags were)."""
    from scipy.optimize import minimize_scalar

    d0 = float(finding.details["vel_shift_s"])
    own = start_pieces(_shifted(run, d0), cfg, filter_pass)  # the start the velocities shifted make
    t_from = max(float(base.init.t), float(own.init.t)) + BURN_IN_S
    t_to = run.t_end - MAX_LAG_S
    cache: dict = {}

    def inn(d: float) -> Innovations | None:
        key = round(float(d), 6)
        if key not in cache:
            cache[key] = innovations(_shifted(run, key), cfg, own, filter_pass)
        return cache[key]

    res = minimize_scalar(
        lambda d: _cost(inn(d), d, t_from, t_to),
        bounds=(d0 - SEARCH_HALF_WIDTH_S, d0 + SEARCH_HALF_WIDTH_S),
        method="bounded",
        options={"xatol": SEARCH_TOL_S},
    )
    d = _on_the_fixes(run, float(res.x), float(res.fun), lambda x: _cost(inn(x), x, t_from, t_to))
    given = innovations(run, cfg, base, filter_pass)  # the tags as given, from their own start
    verdict = compare(given, inn(d), t_from=t_from, t_to=t_to, vel_shift=d)
    finding.details.update(vel_shift_s=d, lag_s=-d, view_lag_s=-d0, passes=len(cache))
    late = "behind" if d < 0 else "ahead of"
    finding.problem = (
        f"the GNSS velocities' time tags run {abs(d):.3f} s {late} the fixes' (measured by the "
        f"EKF likelihood near the {-d0:+.2f} s the fixes' track shows)"
    )
    finding.repaired = f"subtracted {-d:+.3f} s from the velocities' time tags"
    corrected = _shifted(run, d)
    # the estimators start from the corrected run's own start (the view's shift made ``own``)
    pieces = own if abs(d - d0) < 1e-9 else start_pieces(corrected, cfg, filter_pass)
    return verdict, corrected, pieces
