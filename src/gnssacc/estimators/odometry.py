r"""Wheel odometry as a measurement: which samples are used and when one is refused.

The drive controller reports the forward speed of the odometry's reference point ``l_b``
(``[odometry] lever_arm_b_m``, body FRD from the IMU: a car's rear axle centre) along the vehicle
x axis, read through the wheel radius, so with a scale-factor error ``k``::

    v~ = (1 + k) v_x + noise,    v_x = (R_nb^T v_n + omega_eb^b x l_b)_x

(:func:`gnssacc.estimators.measurements.odometry`, :func:`gnssacc.factors.odometry_factor`). ``k``
is a state of the estimators, a first-order Gauss-Markov process of 1-sigma ``[odometry]
scale_sigma`` and correlation time ``scale_tau_s`` (tyre pressure, wear and load change slowly);
the speed's 1-sigma is ``[odometry] speed_sigma_mps`` (identified by the noise tuner), or a
sample's own stated sigma when larger.

At most one sample per ``[odometry] interval_s`` is used (the first of each interval: samples
are not averaged, since the speed changes within an interval). A sample is refused when its
sign contradicts the estimator's: the estimator's forward speed and the odometry's both differ
from zero by more than three of their 1-sigma and have opposite signs (an odometry that reports
an unsigned speed while the vehicle reverses, or a reversed wheel-encoder sign); counted as
``n_odo_skipped_sign``. A speed near zero is used as it is: at standstill the odometry's zero is
a measurement like any other.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .nhc import K_SIGMA, held_samples

#: Decisions of :func:`decide`.
APPLY, SIGN = 0, 1
#: The ``stats`` key counting each decision not to use a sample.
SKIPPED = {SIGN: "n_odo_skipped_sign"}


def counts() -> dict:
    """Zero counts of the decisions not to use a sample (``stats`` keys)."""
    return dict.fromkeys(SKIPPED.values(), 0)


@dataclass
class OdometryEpochs:
    """The odometry samples an estimator uses.

    Attributes
    ----------
    t : ndarray (K,)
        Sample times [s].
    v : ndarray (K,)
        Forward speed read [m/s].
    sigma : ndarray (K,)
        Its 1-sigma [m/s].
    omega_b : ndarray (K, 3)
        Raw gyro reading held at each sample [rad/s, body].
    """

    t: np.ndarray
    v: np.ndarray
    sigma: np.ndarray
    omega_b: np.ndarray

    def __len__(self) -> int:
        return len(self.t)

    @classmethod
    def empty(cls) -> "OdometryEpochs":
        return cls(np.zeros(0), np.zeros(0), np.zeros(0), np.zeros((0, 3)))


def odometry_epochs(
    imu, odo, t0: float, t_end: float, interval_s: float, sigma_mps: float
) -> OdometryEpochs:
    """The samples of ``odo`` (:class:`gnssacc.core.recording.WheelOdometry`) in ``(t0, t_end]`` [s],
    at most one per ``interval_s`` [s], with the 1-sigma ``max(sigma_mps, stated)`` [m/s] and
    the gyro reading held at each (``imu``: :class:`gnssacc.core.recording.ImuData`)."""
    t = np.asarray(odo.t, float)
    keep = np.flatnonzero((t > t0) & (t <= t_end) & np.isfinite(odo.v_forward))
    if interval_s > 0 and len(keep):
        _, first = np.unique(np.floor((t[keep] - t0) / interval_s), return_index=True)
        keep = keep[first]
    stated = getattr(odo, "sigma_v", None)
    sigma = np.full(len(keep), float(sigma_mps))
    if stated is not None:
        sigma = np.maximum(sigma, np.nan_to_num(np.asarray(stated, float)[keep]))
    return OdometryEpochs(
        t[keep],
        np.asarray(odo.v_forward, float)[keep],
        sigma,
        np.asarray(imu.omega_ib_b)[held_samples(imu.t, t[keep])],
    )


def epochs_for(run, odometry, t0: float) -> OdometryEpochs:
    """The odometry samples of an estimator run from ``t0`` [s] (``odometry``:
    :class:`gnssacc.estimators.settings.OdometrySettings`); none when it is off or the run has no
    odometry."""
    odo = getattr(run, "odometry", None)
    if odo is None or not odometry.enabled or len(odo.t) == 0:
        return OdometryEpochs.empty()
    return odometry_epochs(
        run.imu, odo, t0, run.t_end, odometry.interval_s, odometry.speed_sigma_mps
    )


def decide(v_odo: float, sigma_odo: float, v_pred: float, sigma_pred: float) -> int:
    """:data:`SIGN` when the odometry's speed ``v_odo`` (1-sigma ``sigma_odo``) and the estimator's
    prediction of it ``v_pred`` (1-sigma ``sigma_pred``) [m/s] are both clearly non-zero and of
    opposite signs, else :data:`APPLY`."""
    if (
        v_odo * v_pred < 0
        and abs(v_odo) > K_SIGMA * sigma_odo
        and abs(v_pred) > K_SIGMA * sigma_pred
    ):
        return SIGN
    return APPLY
