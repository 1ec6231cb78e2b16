"""The epochs an estimate is reported at when the caller names none."""

from __future__ import annotations

import numpy as np

from ..core.recording import RecordedRun


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
