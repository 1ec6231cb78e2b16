"""Time-stamp repair and gap survey of the rows read from a bag.

Bags are recorded by several processes, so messages of one topic can arrive out of order or
twice. :func:`sorted_unique` sorts them by time and drops repeated stamps (counted, warned,
recorded in ``run.meta["time_fixes"]``); :func:`find_gaps` lists long pauses for
``run.meta["gaps"]``.
"""

from __future__ import annotations

import numpy as np

from ..core.errors import warn_data
from ..core.recording import gap_indices


def sorted_unique(tab: np.ndarray, where: str, what: str, meta: dict, key: str) -> np.ndarray:
    """Sort rows by time and drop rows that repeat a time stamp (the first one is kept).

    Parameters
    ----------
    tab : ndarray, shape (N, K)
        Rows with the time [s] in column 0.
    where, what : str
        The bag and the topic, for the warnings.
    meta : dict
        Gets ``meta["time_fixes"][key]``: the counts of backward steps, exact duplicates and
        conflicting duplicates (same stamp, other data).
    key : str
        Name of the table in ``meta`` (``"imu"``, ``"gnss"``, ``"truth"``).

    Returns
    -------
    ndarray, shape (M, K)
        Strictly increasing times; a :class:`~gnssacc.core.errors.DataWarning` for each repair made.
    """
    if len(tab) == 0:
        return tab
    t = tab[:, 0]
    back = int(np.sum(np.diff(t) < 0))
    if back:
        warn_data(where, f"{what}: time went backwards {back} time(s); messages sorted by time")
        tab = tab[np.argsort(t, kind="stable")]
        t = tab[:, 0]
    same = np.flatnonzero(np.diff(t) == 0) + 1
    exact = conflicting = 0
    if same.size:
        eq = np.array([np.array_equal(tab[k], tab[k - 1], equal_nan=True) for k in same])
        exact, conflicting = int(eq.sum()), int((~eq).sum())
        keep = np.ones(len(tab), bool)
        keep[same] = False
        tab = tab[keep]
        parts = []
        if exact:
            parts.append(f"{exact} exact duplicate message(s)")
        if conflicting:
            parts.append(
                f"{conflicting} message(s) repeating a time stamp with different data (first kept)"
            )
        warn_data(where, f"{what}: dropped " + " and ".join(parts))
    meta.setdefault("time_fixes", {})[key] = {
        "backwards_steps": back,
        "exact_duplicates": exact,
        "conflicting_duplicates": conflicting,
    }
    return tab


def find_gaps(t: np.ndarray, factor: float) -> dict:
    """Pauses longer than ``factor`` times the median sample interval (the rule of
    :func:`gnssacc.core.recording.gap_indices`, with ``[quality] gap_factor`` as the IMU checks use it).

    Parameters
    ----------
    t : ndarray, shape (N,)
        Increasing times [s].
    factor : float
        Threshold as a multiple of the median interval.

    Returns
    -------
    dict
        ``nominal_dt_s`` (median interval [s]), ``count`` and the first 20 ``spans`` as
        ``[start time [s], length [s]]``; ``{"count": 0, "spans": []}`` below three samples.
    """
    if len(t) < 3:
        return {"count": 0, "spans": []}
    idx, d, med = gap_indices(t, factor)
    return {
        "nominal_dt_s": med,
        "count": int(idx.size),
        "spans": [[float(t[k]), float(d[k])] for k in idx[:20]],
    }


def subsample(t: np.ndarray, rate_hz: float) -> np.ndarray:
    """Indices of the first sample in each ``1 / rate_hz`` [s] bin counted from ``t[0]`` [s]."""
    bins = np.floor((t - t[0]) * rate_hz + 1e-9).astype(np.int64)
    return np.flatnonzero(np.r_[True, np.diff(bins) > 0])
