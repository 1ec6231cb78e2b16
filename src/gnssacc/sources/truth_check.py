r"""Whether a recorded trajectory may serve as the truth: it must be geo-referenced and agree with
the GNSS fixes, as given, within what their sigmas allow.

A recording's reference trajectory (an RTK receiver, a survey-grade INS) and a drive
controller's wheel odometry look alike in a bag (``nav_msgs/Odometry`` both), but odometry lives in
a local frame (REP-105's ``odom``: starting at the power-on pose, drifting) and scoring against it
would be scoring against another estimate. So a candidate is the truth only when

1. its frame is not a local odometry frame (:func:`is_local_frame`), and
2. its positions, read in the geo frame as given (no alignment of any kind: a rotated or
   shifted frame disagrees), agree with the fixes: the fixes' normalised distances from it,
   ``q_k = sum_i (d_ki / s_ki)^2`` over N, E, D with ``s_ki^2 = sigma_ki^2 + |l|^2`` (the
   fix sigma and the antenna lever arm, the truth being of the vehicle, the fixes of the
   antenna), have a median ``m`` with ``sqrt(m / m_3) <=`` :data:`MAX_SIGMA_RATIO`, ``m_3``
   being the median of the chi-square distribution with 3 degrees of freedom (2.366): the
   ratio is about 1 for a truth much better than the fixes and honest fix sigmas. The same ratio
   over the fixes taken while the candidate moves faster than :data:`MOVING_MPS` must meet the
   bound too: a truth on another clock is off by its speed times the clock error, which a run
   parked for more than half its length would hide from a median over every fix.

:data:`MAX_SIGMA_RATIO` = 3 allows fix sigmas three times optimistic, as receivers' often are
(the noise tuner's ``gnss.sigma_scale`` finds factors of that order); the median keeps a few
outlying fixes from deciding.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Largest robust normalised distance (in fix sigmas) of a truth from the fixes.
MAX_SIGMA_RATIO = 3.0
#: Median of the chi-square distribution with 3 degrees of freedom.
CHI2_3_MEDIAN = 2.365973884375338
#: Fewest fixes inside the candidate's span needed to judge it.
MIN_FIXES = 5
#: Longest gap between two candidate samples a fix may be interpolated across [s].
MAX_GAP_S = 2.0
#: A candidate moves faster than this at a fix (its own positions' finite differences) [m/s].
MOVING_MPS = 1.0
#: Frame ids of local odometry frames (REP-105), compared without a leading "/" and in lower case.
LOCAL_FRAMES = ("odom",)


def is_local_frame(frame_id: str) -> bool:
    """Whether ``frame_id`` names a local odometry frame: ``odom`` or ending in ``odom``
    (``wheel_odom``, ``base_odom``) or ``odom_combined`` (REP-105's continuous, drifting frame)."""
    f = frame_id.strip().lstrip("/").lower()
    return any(
        f == name or f.endswith("_" + name) or f.endswith("/" + name) or f.startswith(name + "_")
        for name in LOCAL_FRAMES
    )


@dataclass
class Agreement:
    """How a candidate truth compares with the fixes.

    Attributes
    ----------
    n : int
        Fixes compared (inside the candidate's span, away from its gaps).
    rms_m : float
        RMS 3-D distance of the fixes from the candidate [m].
    ratio : float
        ``sqrt(median(q) / m_3)``: the robust normalised distance in fix sigmas (NaN with no fix).
    ok : bool
        At least :data:`MIN_FIXES` fixes, ``ratio <= MAX_SIGMA_RATIO`` and the same of the moving
        fixes (:attr:`ratio_moving`).
    ratio_moving : float
        ``ratio`` over the fixes where the candidate moves (NaN with fewer than :data:`MIN_FIXES`).
    mean_ned_m : ndarray, shape (3,) or None
        Mean of the candidate's position minus the fix's, N, E, D [m].
    """

    n: int
    rms_m: float
    ratio: float
    ok: bool
    ratio_moving: float = float("nan")
    mean_ned_m: np.ndarray | None = None

    @property
    def worst_ratio(self) -> float:
        """The larger of :attr:`ratio` and :attr:`ratio_moving` (the one the bound is on)."""
        return float(np.nanmax([self.ratio, self.ratio_moving]))

    def describe(self) -> str:
        if self.n < MIN_FIXES:
            return f"only {self.n} fix(es) inside its span to compare (need {MIN_FIXES})"
        moving = (
            f", {self.ratio_moving:.1f} while moving"
            if np.isfinite(self.ratio_moving) and self.ratio_moving > self.ratio
            else ""
        )
        return (
            f"{self.rms_m:.2f} m RMS from the fixes, {self.ratio:.1f} fix sigmas{moving} "
            f"(median-based; a truth is within {MAX_SIGMA_RATIO:g})"
        )


def agreement(
    t_truth: np.ndarray,
    p_truth_n: np.ndarray,
    t_fix: np.ndarray,
    p_fix_n: np.ndarray,
    sigma_ned: np.ndarray,
    lever_m: float = 0.0,
) -> Agreement:
    """Compare a candidate trajectory with the fixes (module notes).

    Parameters
    ----------
    t_truth : ndarray, shape (K,)
        Candidate times [s], increasing.
    p_truth_n : ndarray, shape (K, 3)
        Candidate positions, NED about a common origin [m].
    t_fix : ndarray, shape (M,)
        Fix times [s] (same clock).
    p_fix_n : ndarray, shape (M, 3)
        Fix positions, NED about the same origin [m].
    sigma_ned : ndarray, shape (M, 3)
        Fix 1-sigma [m].
    lever_m : float
        Length of the antenna lever arm [m].

    Returns
    -------
    Agreement
    """
    if len(t_truth) < 2:
        return Agreement(0, float("nan"), float("nan"), False)
    j = np.searchsorted(t_truth, t_fix)
    inside = (j > 0) & (j < len(t_truth))
    jj = np.clip(j, 1, len(t_truth) - 1)
    inside &= (t_truth[jj] - t_truth[jj - 1]) <= MAX_GAP_S
    inside |= np.isin(t_fix, t_truth)
    n = int(inside.sum())
    if n == 0:
        return Agreement(0, float("nan"), float("nan"), False)
    t_in = t_fix[inside]
    p = np.column_stack([np.interp(t_in, t_truth, p_truth_n[:, i]) for i in range(3)])
    d = p - p_fix_n[inside]
    s2 = sigma_ned[inside] ** 2 + lever_m**2
    q = np.sum(d**2 / s2, axis=1)
    ratio = float(np.sqrt(np.median(q) / CHI2_3_MEDIAN))
    speed = np.linalg.norm(np.gradient(p_truth_n[:, :2], t_truth, axis=0), axis=1)
    moving = np.interp(t_in, t_truth, speed) > MOVING_MPS
    ratio_moving = (
        float(np.sqrt(np.median(q[moving]) / CHI2_3_MEDIAN))
        if moving.sum() >= MIN_FIXES
        else float("nan")
    )
    rms = float(np.sqrt(np.mean(np.sum(d**2, axis=1))))
    ok = n >= MIN_FIXES and ratio <= MAX_SIGMA_RATIO and not ratio_moving > MAX_SIGMA_RATIO
    return Agreement(n, rms, ratio, ok, ratio_moving, d.mean(axis=0))
