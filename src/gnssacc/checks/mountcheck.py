r"""How the IMU is mounted, from the data: the ``[mounting] imu_to_body_rpy_deg`` that fits them.

The body frame is Front-Right-Down; ``f_body = R_bi f_imu`` with ``R_bi = R(roll, pitch, yaw)``.

* **Down** (roll and pitch of the IMU axes): a ground vehicle is level on average, so the run's
  mean specific force points up in the body; its direction in IMU axes is the body's down axis
  (:func:`gnssacc.checks.motionmatch.level_imu`).
* **Forward** (yaw of the IMU axes): a vehicle moves along its body x axis, so in turns its
  centripetal acceleration, GNSS speed times IMU heading rate, lies along the body's right axis:
  regressing it on the levelled horizontal specific force finds that axis among the IMU's
  (:func:`gnssacc.checks.motionmatch.lateral_fit`; the along-track acceleration drops out, and only the
  GNSS speed is used, which is precise even at walking pace). Without enough turning the yaw is
  undetermined and the IMU x axis (or y, if x is near vertical) is taken as the forward one.

IMUs are mounted on purpose along the vehicle's axes, so an estimate within
:data:`SNAP_TOLERANCE_DEG` of one of the 24 right-angle orientations is taken to be that
orientation: the rest is the road's average grade, the vehicle's sitting attitude and the
estimate's noise, and must not trigger anything.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import permutations, product

import numpy as np

from ..core.rotations import dcm_to_euler
from .motionmatch import LateralFit, LevelledImu

#: An estimate this close to a right-angle orientation is taken as that orientation [deg]: a few
#: degrees of average road grade and sitting attitude, plus the yaw estimate's noise (~6 deg on a
#: 2-minute car run, ~15 deg on a slow UGV) stay below it.
SNAP_TOLERANCE_DEG = 20.0
#: An oblique (not right-angle) mounting is reported when it is turned more than this from the
#: body axes [deg]: beyond the plausible few degrees of a careful installation by a wide margin.
OBLIQUE_MIN_DEG = 30.0
#: The yaw is determined when its 1-sigma (from the regression residuals, which also hold the
#: unmodelled along-track accelerations: conservative) is below this [deg], and the specific
#: force along the forward axis found follows the GNSS along-track acceleration.
MAX_YAW_SIGMA_DEG = 20.0


def right_angle_orientations() -> np.ndarray:
    """The 24 rotations whose rows are signed IMU axes, shape (24, 3, 3)."""
    out = []
    for perm in permutations(range(3)):
        for signs in product((1.0, -1.0), repeat=3):
            R = np.zeros((3, 3))
            R[range(3), perm] = signs
            if np.linalg.det(R) > 0:
                out.append(R)
    return np.array(out)


def rotation_angle_deg(R: np.ndarray) -> float:
    """Angle of a rotation matrix [deg]."""
    return float(np.degrees(np.arccos(np.clip(0.5 * (np.trace(R) - 1.0), -1.0, 1.0))))


@dataclass
class MountEstimate:
    """The mounting the data show, relative to the IMU axes as loaded.

    Attributes
    ----------
    R_bi : ndarray, shape (3, 3)
        IMU axes (as loaded) to body axes: the right-angle orientation when ``snapped``, else the
        estimate itself.
    R_est : ndarray, shape (3, 3)
        The estimate (rows: body forward, right, down in IMU axes).
    tilt_deg : float
        Angle between the IMU's down axis (as loaded) and the body's [deg].
    yaw_determined : bool
    yaw_sigma_deg : float
        1-sigma of the forward direction (inf when undetermined) [deg].
    snapped : bool
        Within :data:`SNAP_TOLERANCE_DEG` of a right-angle orientation.
    """

    R_bi: np.ndarray
    R_est: np.ndarray
    tilt_deg: float
    yaw_determined: bool
    yaw_sigma_deg: float
    snapped: bool

    @property
    def rpy_deg(self) -> np.ndarray:
        """Roll, pitch, yaw of ``R_bi`` [deg]."""
        return np.degrees(np.array(dcm_to_euler(self.R_bi)))

    @property
    def is_identity(self) -> bool:
        return rotation_angle_deg(self.R_bi) < 1e-6 if self.snapped else False

    @property
    def implausible(self) -> bool:
        """A right-angle orientation other than the identity, or an oblique one turned more than
        :data:`OBLIQUE_MIN_DEG` from the body axes."""
        if self.snapped:
            return rotation_angle_deg(self.R_bi) > 1.0
        return rotation_angle_deg(self.R_est) > OBLIQUE_MIN_DEG


def estimate_mounting(lev: LevelledImu, fit: LateralFit | None) -> MountEstimate:
    """The mounting from the levelled IMU and (for the yaw) the lateral fit (module notes).

    Parameters
    ----------
    lev : LevelledImu
    fit : LateralFit or None
        At the measured clock offset; ``None`` (or a weak fit, or one whose forward axis does not
        follow the along-track acceleration) leaves the yaw undetermined.
    """
    d = lev.down
    sigma = float(np.degrees(fit.sigma_yaw)) if fit is not None else float("inf")
    yaw_ok = fit is not None and sigma <= MAX_YAW_SIGMA_DEG and fit.along_rho > 0
    if yaw_ok:
        u = np.cos(fit.yaw) * lev.e1 + np.sin(fit.yaw) * lev.e2
    else:
        axis = np.eye(3)[0] if abs(d[0]) < 0.9 else np.eye(3)[1]
        u = axis - (axis @ d) * d
        u /= np.linalg.norm(u)
    R_est = np.vstack([u, np.cross(d, u), d])
    tilt = float(np.degrees(np.arccos(np.clip(d[2], -1.0, 1.0))))
    cands = right_angle_orientations()
    angles = np.array([rotation_angle_deg(R_est @ C.T) for C in cands])
    j = int(np.argmin(angles))
    snapped = bool(angles[j] <= SNAP_TOLERANCE_DEG)
    return MountEstimate(
        cands[j] if snapped else R_est,
        R_est,
        tilt,
        bool(yaw_ok),
        sigma if yaw_ok else float("inf"),
        snapped,
    )
