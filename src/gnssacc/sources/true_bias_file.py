"""``true_bias.csv`` of a CSV run directory: a simulated run's true IMU biases, kept with its data.

Columns ``t, bax, bay, baz, bgx, bgy, bgz``: time [s] on the IMU's clock (one row per IMU
sample), the accelerometer bias [m/s^2] and the gyro bias [rad/s] in effect at that sample, IMU
axes (FRD; the body axes of a simulated run). ``gnssacc sim`` writes it; reading the directory
back gives ``run.sim`` a :class:`TabulatedBias` at the IMU's samples, so that the bias figures
and errors of a simulated folder compare with the truth as those of the run in memory do.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..core.recording import SimTruth
from .common import read_table

#: The file's name in a run directory.
FILE = "true_bias.csv"
#: Its columns.
COLUMNS = ("t", "bax", "bay", "baz", "bgx", "bgy", "bgz")


class TabulatedBias:
    """True biases held per sample (the interface of
    :class:`gnssacc.sources.sim_true_bias.TrueBias`).

    Parameters
    ----------
    t : ndarray, shape (n,)
        Sample times [s].
    b_a, b_g : ndarray, shape (n, 3)
        Accelerometer [m/s^2] and gyro [rad/s] biases.
    """

    def __init__(self, t: np.ndarray, b_a: np.ndarray, b_g: np.ndarray):
        self.t, self.b_a, self.b_g = np.asarray(t, float), np.asarray(b_a), np.asarray(b_g)

    def __len__(self) -> int:
        return len(self.t)

    def samples(self) -> tuple[np.ndarray, np.ndarray]:
        """Every sample's biases, shape (n, 3) each."""
        return self.b_a, self.b_g

    def at(self, t: np.ndarray, t_samples: np.ndarray | None = None):
        """The biases interpolated linearly at times ``t`` [s] (``t_samples``: the samples' times
        on the caller's clock, default :attr:`t`)."""
        ts = self.t if t_samples is None else np.asarray(t_samples, float)
        t = np.asarray(t, float)
        return tuple(
            np.column_stack([np.interp(t, ts, b[:, i]) for i in range(3)])
            for b in (self.b_a, self.b_g)
        )


def write_true_bias(path: Path, t: np.ndarray, bias, src: str) -> None:
    """Write ``bias`` (``samples()`` per IMU sample at times ``t`` [s]) as ``true_bias.csv``."""
    b_a, b_g = bias.samples()
    table = np.column_stack([np.asarray(t, float), b_a, b_g])
    np.savetxt(
        path,
        table,
        fmt="%.17g",
        delimiter=",",
        header=f"{src}\n# t [s] IMU clock, true accelerometer bias [m/s^2], true gyro bias "
        f"[rad/s], IMU axes FRD\n" + ",".join(COLUMNS),
        comments="",
    )


def read_true_bias(path: Path, imu_t: np.ndarray, max_bad: float) -> SimTruth | None:
    """``true_bias.csv`` as the ``run.sim`` of a run read from a directory (biases only: no
    scenario log, no error draws), per IMU sample: rows at other times (IMU rows dropped for NaN,
    a file from another rate) are interpolated to the IMU's times. ``None``, with a warning, when
    the file does not span the IMU's samples (it belongs to another run)."""
    from ..core.errors import warn_data

    tab = read_table(path, COLUMNS, (), max_bad)
    t = tab["t"]
    if len(t) < 2 or t[0] > imu_t[0] + 1e-6 or t[-1] < imu_t[-1] - 1e-6 or np.any(np.diff(t) <= 0):
        warn_data(
            str(path),
            f"its {len(t)} rows do not span the IMU's samples ({imu_t[0]:g} .. {imu_t[-1]:g} s) "
            "in increasing time: the true biases are not used",
        )
        return None
    b_a = np.column_stack([np.interp(imu_t, t, tab[c]) for c in COLUMNS[1:4]])
    b_g = np.column_stack([np.interp(imu_t, t, tab[c]) for c in COLUMNS[4:7]])
    return SimTruth(TabulatedBias(imu_t, b_a, b_g), [], {}, {}, {})
