"""The truth against the fixes, as the input checks' corrections left both: a truth that disagrees
with them beyond what their sigmas allow is reported and not scored.

A recording's truth is scored against only when it is of the same place and clock as the fixes:
its positions at the fix epochs must lie within what the fixes' sigmas allow (those the recording
states; the configured default where it states none: :func:`fix_sigmas`), over every fix and
over the fixes taken while moving (:func:`gnssacc.sources.truth_check.agreement`; a truth on
another clock is off by its speed times the clock error, so a moving run shows a clock error as
a position error, and a parked one shows a position offset alone). A bag's truth candidates were
checked so when the bag was read; after a clock offset was applied to the IMU (and to whatever
shares its clock: a CSV run's truth, docs/formats.md) every source's truth is checked again here.

A truth that fails is dropped from the run, with a warning that says how far it is from the fixes
and, when a shift of its time stamps within :data:`MAX_SHIFT_S` makes it agree, by how much: a
user then knows whether to look at its clock or at its coordinates. The run is still estimated;
its table has no accuracy figures.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from ..core.config import RunConfig
from ..core.errors import warn_data
from ..core.recording import RecordedRun
from ..sources.truth_check import MAX_SIGMA_RATIO, MIN_FIXES, Agreement, agreement
from .findings import Finding

#: Shifts of the truth's time stamps searched for one that makes it agree [s].
MAX_SHIFT_S = 60.0
#: Steps of that search [s]: coarse over the whole range, then fine about the best coarse one.
COARSE_STEP_S, FINE_STEP_S = 0.25, 0.01


def _where(run: RecordedRun) -> str:
    """The truth's file: ``truth.csv`` of a CSV run directory, else the run's source."""
    if run.meta.get("source") == "csv":
        return str(Path(run.where) / "truth.csv")
    topic = (run.meta.get("topics") or {}).get("truth")
    return f"{run.where} (truth {topic})" if topic else f"{run.where} (truth)"


def fix_sigmas(run: RecordedRun, cfg: RunConfig) -> np.ndarray:
    """The fix sigmas the truth is judged by (N, E, D per fix [m]): those the recording states;
    where it states none, ``gnss.default_sigma_m``, the configured assumption for such fixes (a
    scatter measured from the fixes is their white part only: a receiver's own filter leaves
    errors that wander by tens of times more, which a truth must not be held against)."""
    g = run.gnss
    if g.sigma_stated and run.meta.get("fix_sigmas") is None:
        return g.sigma_ned
    return np.maximum(g.sigma_ned, cfg.default_sigma_ned)


class _Comparison:
    """The run's truth and fixes in NED about its origin, compared at any shift of the truth's
    stamps (made once: the shift search compares hundreds of times)."""

    def __init__(self, run: RecordedRun, cfg: RunConfig):
        tr, g, o = run.truth, run.gnss, run.origin
        self.t_truth, self.p_truth = tr.t, o.to_ned(tr.lat, tr.lon, tr.h)
        self.t_fix, self.p_fix, self.sigma = g.t, o.to_ned(g.lat, g.lon, g.h), fix_sigmas(run, cfg)
        self.lever_m = float(np.linalg.norm(cfg.lever_arm_b))

    def at(self, shift_s: float = 0.0) -> Agreement:
        """The truth, its stamps shifted by ``shift_s`` [s], against the fixes."""
        return agreement(
            self.t_truth + shift_s, self.p_truth, self.t_fix, self.p_fix, self.sigma, self.lever_m
        )

    def worst(self, shift_s: float) -> float:
        a = self.at(shift_s)
        return a.worst_ratio if a.n >= MIN_FIXES else np.inf

    def agreeing_shift(self) -> float | None:
        """The shift of the truth's stamps within +-:data:`MAX_SHIFT_S` that brings it closest to
        the fixes, when it makes it agree (module notes), else ``None`` [s]."""
        coarse = np.arange(-MAX_SHIFT_S, MAX_SHIFT_S + 1e-9, COARSE_STEP_S)
        best = float(coarse[int(np.argmin([self.worst(dt) for dt in coarse]))])
        fine = best + np.arange(-COARSE_STEP_S, COARSE_STEP_S + 1e-9, FINE_STEP_S)
        ratios = [self.worst(dt) for dt in fine]
        k = int(np.argmin(ratios))
        return float(fine[k]) if ratios[k] <= MAX_SIGMA_RATIO else None


def checked_truth(run: RecordedRun, cfg: RunConfig) -> tuple[RecordedRun, Finding | None]:
    """The run, without its truth when the truth disagrees with the fixes (module notes), and the
    finding that says so (warned of), or ``None`` when it agrees or cannot be compared."""
    if run.truth is None or len(run.truth.t) < 2:
        return run, None
    comparison = _Comparison(run, cfg)
    a = comparison.at()
    if a.ok or a.n < MIN_FIXES:
        return run, None
    shift = comparison.agreeing_shift()
    n, e, d = (float(v) for v in a.mean_ned_m)
    offset = f"on average {n:+.1f} m north, {e:+.1f} m east, {d:+.1f} m down of them"
    why = (
        f"it agrees with them when its time stamps are shifted by {shift:+.2f} s: another clock"
        if shift is not None and abs(shift) >= FINE_STEP_S
        else f"no shift of its time stamps within {MAX_SHIFT_S:g} s makes it agree: another place "
        f"or frame"
    )
    finding = Finding(
        "truth",
        _where(run),
        f"the truth disagrees with the GNSS fixes ({a.describe()}; {offset}); {why}; not scored "
        f"as the truth",
        "check the truth's clock and coordinates (a CSV run's truth.csv is on the IMU's clock)",
        action="not scored",
        details={
            "n_fixes": a.n,
            "rms_m": a.rms_m,
            "ratio": a.ratio,
            "ratio_moving": a.ratio_moving if np.isfinite(a.ratio_moving) else None,
            "mean_ned_m": [n, e, d],
            "agreeing_shift_s": shift,
        },
    )
    warn_data(finding.where, f"{finding.problem}; {finding.fix}")
    return replace(run, truth=None), finding
