"""NavSolution: what an estimator returns, one row per output epoch."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from .display import SIGMA_COLUMNS
from .rotations import dcm_to_euler, euler_to_dcm
from .states import ATT


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
        Roll, pitch, yaw [rad] of the body's axes, or of the vehicle's
        (:meth:`in_vehicle_axes`: what a run returns where the constraint's axes are turned).
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
    R_vb : ndarray, shape (3, 3), optional
        Set when :attr:`rpy` is the vehicle's attitude (:meth:`in_vehicle_axes`): body to vehicle
        axes; :meth:`body_rpy` gives the body's.
    attitude_floor : ndarray, shape (3,), optional
        Set by :meth:`in_vehicle_axes`: the least roll, pitch and yaw sigma it let stand [rad].
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
    R_vb: np.ndarray | None = None
    attitude_floor: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.t)

    def in_vehicle_axes(
        self, R_vb: np.ndarray | None, floor: np.ndarray | None = None
    ) -> "NavSolution":
        """This solution with :attr:`rpy` the attitude of the vehicle's axes, ``R_nv = R_nb R_vb^T``
        (``R_vb`` maps body to vehicle axes: ``[nhc] pitch_offset_deg``, ``yaw_offset_deg``;
        ``None``: the body's axes), and its attitude sigmas at least ``floor`` [rad] (roll, pitch,
        yaw): what no measurement tells of those axes
        (:func:`gnssacc.prepare.attitude_axes.attitude_axes`). Done once: a solution it made is
        returned as it is.

        The estimators integrate the accelerometers' own axes, which a constant misalignment of
        the triad (tenths of a degree on a consumer IMU) turns against the IMU's case; the
        constraint's axes, where the tuner proved them turned against the body's, are the
        vehicle's. The other sigmas, the biases and :attr:`P` stay the body's (the offsets are at
        most a few degrees: the attitude sigma of either axes is the same to first order).
        """
        if self.R_vb is not None or self.attitude_floor is not None:
            return self
        least = np.zeros(3) if floor is None else np.asarray(floor, float)
        if R_vb is None and not np.any(least > 0.0):
            return self
        sigma = self.sigma
        if np.any(least > 0.0):
            sigma = sigma.copy()
            sigma[:, ATT] = np.maximum(sigma[:, ATT], least)
        rpy = self.rpy
        if R_vb is not None:
            R_vb = np.asarray(R_vb, float)
            rpy = _turned(self.rpy, R_vb.T)
        return replace(self, rpy=rpy, sigma=sigma, R_vb=R_vb, attitude_floor=least)

    def body_rpy(self) -> np.ndarray:
        """Roll, pitch, yaw [rad] (K, 3) of the body's axes (:attr:`rpy` itself unless it is the
        vehicle's: :meth:`in_vehicle_axes`)."""
        return self.rpy if self.R_vb is None else _turned(self.rpy, self.R_vb)

    #: Column names of :attr:`sigma`.
    SIGMA_NAMES = SIGMA_COLUMNS


def _turned(rpy: np.ndarray, R_ab: np.ndarray) -> np.ndarray:
    """Roll, pitch, yaw [rad] (K, 3) of ``R_na R_ab`` for the attitudes ``R_na`` of ``rpy``."""
    if not len(rpy):
        return rpy
    R_na = np.moveaxis(euler_to_dcm(*np.asarray(rpy, float).T), -1, 0)  # (K, 3, 3)
    return np.column_stack(dcm_to_euler(R_na @ R_ab))
