"""NavSolution: what an estimator returns, one row per output epoch."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .display import SIGMA_COLUMNS


@dataclass
class NavSolution:
    """Per-epoch navigation estimate with 1-sigma uncertainties.

    Attributes
    ----------
    method : str
        Method id (``ekf``, ``ekf-acc``, ...).
    t : ndarray, shape (K,)
        Output epochs [s].
    lat, lon : ndarray, shape (K,)
        Geodetic latitude, longitude of the IMU / body origin [rad].
    h : ndarray, shape (K,)
        Ellipsoidal height [m].
    v_n : ndarray, shape (K, 3)
        NED velocity [m/s].
    rpy : ndarray, shape (K, 3)
        Roll, pitch, yaw [rad].
    b_a, b_g : ndarray, shape (K, 3)
        Estimated accelerometer [m/s^2] and gyro [rad/s] biases, IMU axes after mounting (body).
    sigma : ndarray, shape (K, 15)
        1-sigma of ``[pos N,E,D [m], vel N,E,D [m/s], roll, pitch, yaw [rad], b_a [m/s^2], b_g [rad/s]]``.
    runtime_s : float
        Wall time of the estimator run [s] (excluding one-off JIT compilation).
    stats : dict
        Counters and diagnostics (updates made, normalised innovation statistics, ...).
    P : ndarray, shape (K, 15, 15), optional
        Full error-state covariance per epoch, when requested.
    """

    method: str
    t: np.ndarray
    lat: np.ndarray
    lon: np.ndarray
    h: np.ndarray
    v_n: np.ndarray
    rpy: np.ndarray
    b_a: np.ndarray
    b_g: np.ndarray
    sigma: np.ndarray
    runtime_s: float = 0.0
    stats: dict = field(default_factory=dict)
    P: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.t)

    #: Column names of :attr:`sigma`.
    SIGMA_NAMES = SIGMA_COLUMNS
