"""VectorNav CSV exports (an ``X-imu.csv`` / ``X-gnss.csv`` pair): ``gnssacc run X-imu.csv``.

The layout is the one the INSTINCT toolkit writes for a VectorNav VN-310 (column names
``GROUP::Field::Axis [unit]``, one header line; rows may carry extra unnamed cells, e.g.
satellite lists, which are ignored):

``X-imu.csv``
    ``GpsWeek`` (modulo 1024, with ``GpsCycle``) and ``GpsTow [s]``; the compensated specific
    force ``IMU::Accel::X/Y/Z [m/s^2]`` and angular rate ``IMU::AngularRate::X/Y/Z [rad/s]``
    (else the uncompensated ``IMU::UncompAccel`` / ``IMU::UncompGyro``), body axes FRD (the
    VectorNav's own frame).
``X-gnss.csv``
    GNSS receiver 1: ``GNSS1::Tow [ns]``, ``GNSS1::Week``, ``GNSS1::Fix`` (0 no fix, 1 time only:
    dropped; 2 2-D -> unknown, 3 3-D -> single, 4 SBAS -> sbas, 7 RTK float, 8 RTK fixed),
    ``GNSS1::PosLla`` [deg, deg, m ellipsoidal], ``GNSS1::PosU::N/E/D [m]`` (1-sigma, stated),
    ``GNSS1::VelNed::N/E/D [m/s]`` with ``GNSS1::VelU [m/s]`` as the sigma of each axis: the
    GNSS velocity (none when the export lacks those columns). The unit's own INS solution (``INS::*``, ``Att::*``) is in the file too: it
    is the unit's filter output, a reference never a truth, and is not read as one.
Times
    Seconds of GPS time from the first IMU sample (``(week - week0) * 604800 + tow - tow0``), the
    same clock for the IMU and the fixes.

Detected by its layout: a file named ``*-imu.csv`` or ``*-gnss.csv`` whose header names
``IMU::`` or ``GNSS1::`` columns and whose partner file exists, or a directory holding exactly
one such pair (several: an error naming them).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..core.earth import LocalTangentFrame
from ..core.errors import InputError, warn_data
from ..core.recording import FIX_QUALITY, GnssFixes, GnssVelocity, ImuData, RecordedRun

WEEK_S = 604800.0
#: GNSS1::Fix -> quality code (None: dropped).
FIX_QUALITY_VN = {
    0: None,
    1: None,
    2: FIX_QUALITY["unknown"],
    3: FIX_QUALITY["single"],
    4: FIX_QUALITY["sbas"],
    5: FIX_QUALITY["unknown"],
    6: FIX_QUALITY["unknown"],
    7: FIX_QUALITY["float"],
    8: FIX_QUALITY["fix"],
}
SUFFIXES = ("-imu.csv", "-gnss.csv")


def _header(path: Path) -> list[str]:
    try:
        with open(path, encoding="utf-8-sig", errors="replace") as fh:
            return [c.strip() for c in fh.readline().strip().split(",")]
    except OSError:
        return []


def _is_vn(path: Path) -> bool:
    return any(c.startswith(("IMU::", "GNSS1::")) for c in _header(path))


def vectornav_pair(path: Path) -> tuple[Path, Path] | None:
    """``(imu.csv, gnss.csv)`` of a VectorNav export named by one of its files or by a folder
    holding one pair; None when ``path`` is not one (module docstring).

    Raises
    ------
    InputError
        A folder holding several pairs, or one file of a pair without its partner.
    """
    path = Path(path)
    if path.is_dir():
        pairs = [
            (p, p.with_name(p.name[: -len(SUFFIXES[0])] + SUFFIXES[1]))
            for p in sorted(path.glob("*" + SUFFIXES[0]))
        ]
        pairs = [(a, b) for a, b in pairs if b.exists() and _is_vn(a)]
        if len(pairs) > 1:
            names = ", ".join(a.name for a, _ in pairs)
            raise InputError(
                str(path), f"holds {len(pairs)} VectorNav exports ({names}): run one of them"
            )
        return pairs[0] if pairs else None
    name = path.name
    for own, other in (SUFFIXES, SUFFIXES[::-1]):
        if name.endswith(own) and _is_vn(path):
            partner = path.with_name(name[: -len(own)] + other)
            if not partner.exists():
                raise InputError(str(path), f"a VectorNav export needs its partner {partner.name}")
            return (path, partner) if own == SUFFIXES[0] else (partner, path)
    return None


def _columns(path: Path, wanted: dict) -> dict:
    """``{key: column}`` of the columns named (``key -> name or tuple of alternative names``,
    matched without the ``[unit]``); rows cut to the header's width; non-numeric cells refused."""
    head = _header(path)
    bare = [c.split(" [")[0].strip() for c in head]
    idx = {}
    for key, names in wanted.items():
        for name in (names,) if isinstance(names, str) else names:
            if name in bare:
                idx[key] = bare.index(name)
                break
        else:
            alt = names if isinstance(names, str) else " or ".join(names)
            raise InputError(str(path), f"no column {alt}: not a VectorNav export gnssacc reads")
    try:
        data = np.genfromtxt(
            path, delimiter=",", skip_header=1, usecols=sorted(set(idx.values())), ndmin=2
        )
    except ValueError as err:
        raise InputError(str(path), f"cannot read the table: {str(err).splitlines()[0]}") from None
    pos = {c: k for k, c in enumerate(sorted(set(idx.values())))}
    return {key: data[:, pos[c]] for key, c in idx.items()}


def load_vectornav(path, *, velocity: bool = True) -> RecordedRun:
    """Load a VectorNav CSV export (module docstring) named by either file or its folder.

    Parameters
    ----------
    path : str or Path
    velocity : bool
        Read ``GNSS1::VelNed`` as the GNSS velocity.

    Returns
    -------
    RecordedRun
        Validated; no truth (the unit's INS solution is not one).
    """
    pair = vectornav_pair(Path(path))
    if pair is None:
        raise InputError(str(path), "not a VectorNav export (X-imu.csv with X-gnss.csv)")
    imu_path, gnss_path = pair
    imu, t0 = _imu(imu_path)
    gnss, vel = _gnss(gnss_path, t0, velocity)
    stem = imu_path.name[: -len(SUFFIXES[0])]
    run = RecordedRun(
        name=stem,
        where=str(imu_path),
        imu=imu,
        gnss=gnss,
        origin=LocalTangentFrame(gnss.lat[0], gnss.lon[0], gnss.h[0]),
        meta={"source": "vectornav", "gnss_file": str(gnss_path)},
        gnss_vel=vel,
    )
    return run.validate()


def _imu(path: Path) -> tuple[ImuData, tuple[float, float]]:
    """The IMU samples on seconds from the first one, and that first (week, tow)."""
    names = {"week": "GpsWeek", "cycle": "GpsCycle", "tow": "GpsTow"}
    try:
        c = _columns(path, {**names, **{f"a{a}": f"IMU::Accel::{a}" for a in "XYZ"}})
        c.update(_columns(path, {f"w{a}": f"IMU::AngularRate::{a}" for a in "XYZ"}))
    except InputError:  # no compensated samples: the uncompensated ones
        c = _columns(path, {**names, **{f"a{a}": f"IMU::UncompAccel::{a}" for a in "XYZ"}})
        c.update(_columns(path, {f"w{a}": f"IMU::UncompGyro::{a}" for a in "XYZ"}))
        warn_data(str(path), "no compensated IMU columns: the uncompensated ones used")
    good = np.all(np.isfinite(np.column_stack(list(c.values()))), axis=1)
    c = {k: v[good] for k, v in c.items()}
    week = c["cycle"] * 1024 + c["week"]
    t0 = (float(week[0]), float(c["tow"][0]))
    t = (week - t0[0]) * WEEK_S + (c["tow"] - t0[1])
    f_b = np.column_stack([c[f"a{a}"] for a in "XYZ"])
    w_b = np.column_stack([c[f"w{a}"] for a in "XYZ"])
    return ImuData(t, f_b, w_b), t0


def _gnss(path: Path, t0: tuple, velocity: bool):
    """Fixes (and velocities) on the IMU's seconds, fixes without a position fix dropped."""
    want = {"tow": "GNSS1::Tow", "week": "GNSS1::Week", "fix": "GNSS1::Fix"}
    want.update(lat="GNSS1::PosLla::latitude", lon="GNSS1::PosLla::longitude")
    want.update(h="GNSS1::PosLla::altitude")
    want.update({f"s{a}": f"GNSS1::PosU::{a}" for a in "NED"})
    c = _columns(path, want)
    if velocity:
        vel_cols = {f"v{a}": f"GNSS1::VelNed::{a}" for a in "NED"}
        try:
            c.update(_columns(path, {**vel_cols, "su": "GNSS1::VelU"}))
        except InputError:  # an export without the velocity: fixes only
            velocity = False
    q = np.array([FIX_QUALITY_VN.get(int(f), None) if np.isfinite(f) else None for f in c["fix"]])
    keep = np.array([x is not None for x in q]) & np.isfinite(c["lat"]) & np.isfinite(c["tow"])
    if not keep.any():
        raise InputError(str(path), "no GNSS1 row with a position fix (GNSS1::Fix >= 2)")
    if not keep.all():
        warn_data(str(path), f"dropped {int((~keep).sum())} GNSS1 row(s) without a position fix")
    c = {k: v[keep] for k, v in c.items()}
    t = (c["week"] - t0[0]) * WEEK_S + (c["tow"] * 1e-9 - t0[1])
    sig = np.column_stack([c[f"s{a}"] for a in "NED"])
    fixes = GnssFixes(
        t, np.radians(c["lat"]), np.radians(c["lon"]), c["h"], sig, q[keep].astype(int)
    )
    vel = None
    if velocity:
        v = np.column_stack([c[f"v{a}"] for a in "NED"])
        s = np.repeat(c["su"][:, None], 3, axis=1)
        ok = np.all(np.isfinite(v), axis=1) & (c["su"] > 0)
        if ok.any():
            vel = GnssVelocity(t[ok], v[ok], s[ok], None, sigma_stated=True)
    return fixes, vel
