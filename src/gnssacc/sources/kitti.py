"""The KITTI sequence shipped inside the gtsam wheel: gnssacc's embedded default run.

Files (read from the installed gtsam, never copied): ``gtsam/Data/KittiEquivBiasedImu.txt``
(100 Hz IMU, body forward-left-up, columns ``Time dt accelX accelY accelZ omegaX omegaY
omegaZ``) and ``gtsam/Data/KittiGps_converted.txt`` (1 Hz RTK-grade positions, local
east-north-up metres, columns ``Time,X,Y,Z``), 471 s and 3.7 km of driving.

Conversions made here:

* IMU body FLU -> FRD: ``(x, y, z) -> (x, -y, -z)`` for specific force and angular rate.
* Positions ENU -> NED: ``(N, E, D) = (Y, X, -Z)``.
* The files carry no geodetic origin. gnssacc assigns the tangent-plane origin
  :data:`ORIGIN_LLH_DEG` (49.0 N, 8.4 E, 110 m, Karlsruhe, where KITTI was recorded); it only
  sets gravity and earth rate, which vary by far less than the IMU noise over the run.

The positions are the truth; the estimators' fixes are truth plus a seeded noise profile
(:mod:`gnssacc.sources.gnss_noise`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..core.config import RunConfig
from ..core.earth import LocalTangentFrame
from ..core.errors import InputError
from ..core.recording import GnssFixes, ImuData, RecordedRun, Truth
from ..core.rotations import flu_to_frd
from .common import apply_mounting, with_noisy_fixes

#: Geodetic origin assigned to the KITTI local frame: latitude, longitude [deg], height [m].
ORIGIN_LLH_DEG = (49.0, 8.4, 110.0)
IMU_FILE = "KittiEquivBiasedImu.txt"
GPS_FILE = "KittiGps_converted.txt"


def data_dir() -> Path:
    """The ``Data`` folder of the installed gtsam package."""
    try:
        import gtsam
    except ImportError as exc:  # pragma: no cover - gtsam is a dependency
        raise InputError("kitti", f"gtsam is not importable ({exc}); reinstall gnssacc") from None
    folder = Path(gtsam.__file__).parent / "Data"
    for name in (IMU_FILE, GPS_FILE):
        if not (folder / name).is_file():
            raise InputError(str(folder / name), "missing from the installed gtsam wheel")
    return folder


def load_kitti(cfg: RunConfig, noise: str = "white", seed: int = 0) -> RecordedRun:
    """Load the KITTI sequence as a :class:`RecordedRun`.

    Parameters
    ----------
    cfg : RunConfig
        Supplies the IMU mounting / time offset (applied as for every source).
    noise : {"white", "gm", "none"}
        GNSS noise profile added to the truth positions to make the fixes.
    seed : int
        Noise seed.

    Returns
    -------
    RecordedRun
        ``name="kitti"``; truth at the 1 Hz position epochs.
    """
    folder = data_dir()
    imu_raw = np.loadtxt(folder / IMU_FILE, skiprows=1)
    gps = np.loadtxt(folder / GPS_FILE, skiprows=1, delimiter=",")
    imu = ImuData(imu_raw[:, 0], flu_to_frd(imu_raw[:, 2:5]), flu_to_frd(imu_raw[:, 5:8]))
    imu = apply_mounting(imu, cfg)

    origin = LocalTangentFrame(*np.radians(ORIGIN_LLH_DEG[:2]), ORIGIN_LLH_DEG[2])
    p_n = np.column_stack([gps[:, 2], gps[:, 1], -gps[:, 3]])
    lat, lon, h = origin.to_llh(p_n)
    truth = Truth(gps[:, 0], lat, lon, h)
    placeholder = GnssFixes(truth.t, lat, lon, h, np.full((len(lat), 3), 0.01))
    run = RecordedRun(
        name="kitti",
        where=str(folder / GPS_FILE),
        imu=imu,
        gnss=placeholder,
        origin=origin,
        truth=truth,
        meta={"source": "kitti", "origin_llh_deg": list(ORIGIN_LLH_DEG)},
    )
    return with_noisy_fixes(run, truth, noise, seed).validate()
