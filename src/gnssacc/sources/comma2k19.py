"""comma2k19 segment folders (``processed_log/`` and ``global_pose/``): ``gnssacc run SEGMENT``.

The comma2k19 dataset (github.com/commaai/comma2k19, MIT) holds 33 hours of highway driving as
one-minute segments; each segment folder holds numpy arrays saved without an extension
(``np.load``), every stream a ``t`` (device boot seconds) and a ``value`` array:

``processed_log/IMU/accelerometer``, ``processed_log/IMU/gyro``
    Phone IMU, ~100 Hz, axes forward-right-down (FRD), specific force [m/s^2] and the
    bias-corrected angular rate [rad/s] (Android's). The gyro is put on the accelerometer's
    stamps (linear interpolation) when they differ.
``processed_log/GNSS/live_gnss_ublox``
    u-blox fixes, 10 Hz: ``[lat deg, lon deg, speed m/s, UTC ms, altitude m (ellipsoidal),
    bearing deg]``. The fixes state no sigma: ``gnss.default_sigma_m`` stands in (not stated: the
    preparation identifies the noise from the fixes' own scatter). Speed and bearing are the
    horizontal GNSS velocity (:func:`gnssacc.sources.gnss_vel.velocity_from_speed_course`:
    default sigma, no course below 1 m/s). Times are the log's (boot seconds at reception: the
    receiver's latency is in them).
``processed_log/CAN/speed``
    The car's speed from CAN [m/s] as wheel odometry (forward speed, no yaw rate), on the IMU's
    clock.
``global_pose/``
    ``frame_times``, ``frame_positions`` (ECEF [m]), ``frame_velocities`` (ECEF [m/s]),
    ``frame_orientations`` (quaternion ECEF <- camera), 20 Hz: the reference. CAVEAT
    (:data:`REFERENCE_CAVEAT`): it is comma's own post-processed optimiser output (a tightly
    coupled INS/GNSS/vision solution using these same fixes, not an independent RTK/INS
    system), and it is the position of the camera, about 1.5 m from the antenna (the lever arm is
    not given). Taken as the run's truth with that caveat stated (``Truth.caveat``, one warning):
    its errors, about a metre, are of the order of what it scores.

Detected by its layout: a directory holding ``processed_log/IMU/accelerometer``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..core.config import RunConfig
from ..core.earth import LocalTangentFrame, R_en_batch, ecef_to_llh
from ..core.errors import InputError, warn_data
from ..core.recording import GnssFixes, ImuData, RecordedRun, Truth, WheelOdometry
from .gnss_vel import velocity_from_speed_course

#: The reference's caveat, stated wherever it is used as a truth.
REFERENCE_CAVEAT = (
    "comma2k19's global_pose is comma's own optimiser output (it fuses these fixes), in the "
    "camera frame about 1.5 m from the antenna: a reference, not an independent truth"
)
IMU_DIR = Path("processed_log/IMU")
UBLOX_DIR = Path("processed_log/GNSS/live_gnss_ublox")
CAN_SPEED_DIR = Path("processed_log/CAN/speed")
POSE_DIR = Path("global_pose")


def is_comma2k19(path: Path) -> bool:
    """Whether ``path`` is a comma2k19 segment folder (module docstring)."""
    return path.is_dir() and (path / IMU_DIR / "accelerometer").is_dir()


def _array(root: Path, rel, what: str) -> np.ndarray:
    p = root / rel
    if not p.exists():
        raise InputError(str(p), f"missing: a comma2k19 segment needs {what}")
    try:
        return np.asarray(np.load(p, allow_pickle=False), float)
    except (ValueError, OSError) as err:
        raise InputError(str(p), f"not a numpy array file ({what}): {err}") from None


def _stream(root: Path, rel: Path, what: str, cols: int) -> tuple[np.ndarray, np.ndarray]:
    """(t, value (N, cols)) of a ``processed_log`` stream, checked."""
    t = _array(root, rel / "t", what)
    v = _array(root, rel / "value", what).reshape(len(t), -1)
    if v.shape[1] < cols:
        raise InputError(
            str(root / rel / "value"), f"{what}: {v.shape[1]} columns, expected {cols}"
        )
    good = np.isfinite(t) & np.all(np.isfinite(v[:, :cols]), axis=1)
    order = np.argsort(t[good], kind="stable")
    t, v = t[good][order], v[good][order]
    keep = np.r_[True, np.diff(t) > 0]
    return t[keep], v[keep]


def load_comma2k19(
    path, cfg: RunConfig, *, odometry: bool = True, velocity: bool = True
) -> RecordedRun:
    """Load a comma2k19 segment folder (module docstring).

    Parameters
    ----------
    path : str or Path
        The segment folder (holding ``processed_log/`` and ``global_pose/``).
    cfg : RunConfig
        ``gnss.default_sigma_m`` (the fixes state none).
    odometry, velocity : bool
        Read the CAN speed as wheel odometry, and the u-blox speed and bearing as GNSS
        velocities.

    Returns
    -------
    RecordedRun
        Validated; truth = ``global_pose`` with :data:`REFERENCE_CAVEAT` (None without it).
    """
    root = Path(path)
    t_a, f_b = _stream(root, IMU_DIR / "accelerometer", "the accelerometer", 3)
    t_g, w_b = _stream(root, IMU_DIR / "gyro", "the gyro", 3)
    if len(t_g) != len(t_a) or np.any(t_g != t_a):
        w_b = np.column_stack([np.interp(t_a, t_g, w_b[:, i]) for i in range(3)])
    imu = ImuData(t_a, f_b[:, :3], w_b[:, :3])
    t_fix, ub = _stream(root, UBLOX_DIR, "the u-blox fixes (live_gnss_ublox)", 6)
    sigma = np.tile(cfg.default_sigma_ned, (len(t_fix), 1))
    gnss = GnssFixes(
        t_fix, np.radians(ub[:, 0]), np.radians(ub[:, 1]), ub[:, 4], sigma, sigma_stated=False
    )
    vel = (
        velocity_from_speed_course(t_fix, ub[:, 2], ub[:, 5], float(cfg.default_velocity_sigma[0]))
        if velocity
        else None
    )
    odo = None
    if odometry and (root / CAN_SPEED_DIR).exists():
        t_o, v_o = _stream(root, CAN_SPEED_DIR, "the CAN speed", 1)
        odo = WheelOdometry(t_o, v_o[:, 0].copy(), frame="CAN speed")
    truth = _reference(root) if (root / POSE_DIR).is_dir() else None
    if truth is not None:
        warn_data(str(root), f"truth: {REFERENCE_CAVEAT}")
    run = RecordedRun(
        name=root.resolve().name,
        where=str(root),
        imu=imu,
        gnss=gnss,
        origin=LocalTangentFrame(gnss.lat[0], gnss.lon[0], gnss.h[0]),
        truth=truth,
        meta={"source": "comma2k19", "truth_caveat": REFERENCE_CAVEAT if truth else None},
        odometry=odo,
        gnss_vel=vel,
    )
    return run.validate()


def _reference(root: Path) -> Truth:
    """``global_pose`` as a :class:`Truth` (geodetic position, NED velocity) with its caveat."""
    t = _array(root, POSE_DIR / "frame_times", "the reference times")
    r_e = _array(root, POSE_DIR / "frame_positions", "the reference positions").reshape(-1, 3)
    v_e = _array(root, POSE_DIR / "frame_velocities", "the reference velocities").reshape(-1, 3)
    if not (len(t) == len(r_e) == len(v_e)):
        raise InputError(
            str(root / POSE_DIR), "frame_times, positions, velocities differ in length"
        )
    lat, lon, h = ecef_to_llh(r_e)
    v_n = np.einsum("kij,kj->ki", R_en_batch(lat, lon), v_e)
    return Truth(t, lat, lon, h, v_n=v_n, caveat=REFERENCE_CAVEAT)
