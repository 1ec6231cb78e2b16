"""Rotation helpers: skew matrices, rotation vectors, roll/pitch/yaw.

Convention: ``R_nb`` maps body-frame vectors into the navigation frame, ``v_n = R_nb @ v_b``.
Euler angles are roll, pitch, yaw [rad] in the aerospace Z-Y-X sequence:
``R_nb = Rz(yaw) @ Ry(pitch) @ Rx(roll)``.
"""

from __future__ import annotations

import numpy as np


def skew(v):
    """Skew-symmetric matrix ``[v x]`` with ``skew(a) @ b == cross(a, b)``."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def cross3(a, b) -> np.ndarray:
    """``a x b`` for two 3-vectors (``np.cross`` costs ten times more at this size, in the
    estimators' per-update paths)."""
    return np.array(
        [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
    )


def rotvec_to_dcm(phi):
    """Rotation matrix of a rotation vector [rad] (Rodrigues' formula, exact)."""
    phi = np.asarray(phi, float)
    angle = np.linalg.norm(phi)
    K = skew(phi)
    if angle < 1e-8:
        return np.eye(3) + K + 0.5 * K @ K
    return np.eye(3) + np.sin(angle) / angle * K + (1.0 - np.cos(angle)) / angle**2 * K @ K


def dcm_to_rotvec(R):
    """Rotation vector [rad] of a rotation matrix (inverse of :func:`rotvec_to_dcm`)."""
    R = np.asarray(R, float)
    c = np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0)
    angle = np.arccos(c)
    w = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    if angle < 1e-6:
        return 0.5 * w
    if np.pi - angle < 1e-6:
        # Near pi the antisymmetric part vanishes: use the symmetric part instead.
        axis = np.sqrt(np.maximum((np.diag(R) + 1.0) / 2.0, 0.0))
        k = int(np.argmax(axis))
        for j in range(3):
            if j != k:
                axis[j] = (R[k, j] + R[j, k]) / (4.0 * axis[k])
        return angle * axis / np.linalg.norm(axis)
    return angle / (2.0 * np.sin(angle)) * w


def euler_to_dcm(roll, pitch, yaw):
    """``R_nb`` from roll, pitch, yaw [rad] (Z-Y-X sequence)."""
    cr, sr = np.cos(roll), np.sin(roll)
    cp, sp = np.cos(pitch), np.sin(pitch)
    cy, sy = np.cos(yaw), np.sin(yaw)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def dcm_to_euler(R_nb):
    """Roll, pitch, yaw [rad] of ``R_nb``; works on one matrix or a stack ``(..., 3, 3)``."""
    R_nb = np.asarray(R_nb, float)
    roll = np.arctan2(R_nb[..., 2, 1], R_nb[..., 2, 2])
    pitch = -np.arcsin(np.clip(R_nb[..., 2, 0], -1.0, 1.0))
    yaw = np.arctan2(R_nb[..., 1, 0], R_nb[..., 0, 0])
    return roll, pitch, yaw


def euler_error_jacobian(roll, pitch, yaw):
    """Map a navigation-frame attitude error to roll/pitch/yaw errors.

    With the filter's convention ``R_nb_est = (I + [phi x]) R_nb_true`` the Euler-angle errors
    are ``d_euler = J @ phi``, ``J = E^-1`` with ``E = [Rz Ry e_x, Rz e_y, e_z]`` (the matrix
    that maps Z-Y-X Euler-angle rates to an angular rate resolved in n).

    Works on scalars or arrays of angles (one matrix per element).

    Returns
    -------
    ndarray, shape (..., 3, 3)
        Rows: roll, pitch, yaw errors [rad] per component of ``phi`` [rad].
    """
    cy, sy = np.cos(yaw), np.sin(yaw)
    cp, sp = np.cos(pitch), np.sin(pitch)
    if np.ndim(cy) == 0:
        return np.linalg.inv(np.array([[cy * cp, -sy, 0.0], [sy * cp, cy, 0.0], [-sp, 0.0, 1.0]]))
    E = np.zeros(np.shape(cy) + (3, 3))
    E[..., 0, 0], E[..., 0, 1] = cy * cp, -sy
    E[..., 1, 0], E[..., 1, 1] = sy * cp, cy
    E[..., 2, 0], E[..., 2, 2] = -sp, 1.0
    return np.linalg.inv(E)


#: FRD <-> FLU body axes (a 180 deg roll; its own inverse): ``v_flu = FLU_FRD @ v_frd``.
FLU_FRD = np.diag([1.0, -1.0, -1.0])
#: NED <-> ENU world axes (swap N/E, flip the vertical; its own inverse): ``v_enu = ENU_NED @ v_ned``.
ENU_NED = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])


def flu_to_frd(v_flu: np.ndarray) -> np.ndarray:
    """Vectors ``(..., 3)`` from FLU to FRD body axes (ROS REP-103 to ours)."""
    return np.asarray(v_flu, float) * np.array([1.0, -1.0, -1.0])


def ros_to_R_nb(R_enu_flu: np.ndarray) -> np.ndarray:
    """``R_nb`` (FRD body to NED) from a ROS orientation (FLU body to ENU)."""
    return ENU_NED @ R_enu_flu @ FLU_FRD


def R_nb_to_ros(R_nb: np.ndarray) -> np.ndarray:
    """ROS orientation (FLU body to ENU) of ``R_nb`` (FRD body to NED)."""
    return ENU_NED @ R_nb @ FLU_FRD


def dcm_to_quaternion(R: np.ndarray) -> np.ndarray:
    """Unit quaternion ``(qx, qy, qz, qw)`` of a rotation matrix (Shepperd's method), ``qw >= 0``."""
    R = np.asarray(R, float)
    tr = np.trace(R)
    if tr > 0:
        s = 2.0 * np.sqrt(tr + 1.0)
        q = np.array(
            [(R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s, 0.25 * s]
        )
    else:
        i = int(np.argmax(np.diag(R)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * np.sqrt(1.0 + R[i, i] - R[j, j] - R[k, k])
        q = np.empty(4)
        q[i] = 0.25 * s
        q[j] = (R[j, i] + R[i, j]) / s
        q[k] = (R[k, i] + R[i, k]) / s
        q[3] = (R[k, j] - R[j, k]) / s
    q /= np.linalg.norm(q)
    return q if q[3] >= 0 else -q


def quaternion_to_dcm(x: float, y: float, z: float, w: float) -> np.ndarray:
    """Rotation matrix of a quaternion ``(x, y, z, w)`` (normalised first)."""
    n = np.sqrt(x * x + y * y + z * z + w * w)
    x, y, z, w = x / n, y / n, z / n, w / n
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def wrap_angle(a):
    """Wrap angles [rad] into [-pi, pi)."""
    return (np.asarray(a) + np.pi) % (2.0 * np.pi) - np.pi
