"""u-blox UBX logs (``.ubx``): NAV-PVT fixes and Doppler velocities, read and written with
``pyubx2``.

Messages
    ``NAV-PVT`` (any other message, NMEA or RTCM interleaved in the log, is skipped). Per epoch:
    ``lat``, ``lon`` [deg] and ``height`` (above the ellipsoid) [mm] -> the fix; ``hAcc`` and
    ``vAcc`` [mm] -> the north and east sigma (``hAcc`` each, as the ROS u-blox driver reads it)
    and the down sigma; ``velN``, ``velE``, ``velD`` [mm/s] -> the NED velocity with ``sAcc``
    [mm/s] as the sigma of each axis (a fix with ``sAcc`` 0 has no velocity).
Time
    ``iTOW`` [ms] is the epoch's GPS time of week; its week comes from the message's UTC date
    (``validDate``, ``validTime``): the GPS week whose ``iTOW`` lies nearest that UTC time. Held
    as UNIX seconds (GPST converted with :mod:`gnssacc.sources.gnss_time`'s leap seconds, as
    ``.pos`` GPST), to the millisecond. An epoch without a valid date is dropped (counted).
Quality
    ``fixType`` 0 (no fix) and 5 (time only), ``gnssFixOK`` 0 (outside the receiver's masks) and
    ``invalidLlh`` are dropped (counted, one warning); ``carrSoln`` 2 -> fix, 1 -> float, else
    ``diffSoln`` -> dgps, else 3-D and GNSS + dead reckoning -> single, 2-D -> unknown, dead
    reckoning only -> estimated (:data:`gnssacc.core.recording.FIX_QUALITY`).
Checks
    Messages that fail their checksum or cannot be parsed are counted and skipped with one
    warning, or refused above ``data.max_bad_fraction`` of the messages; a log without a NAV-PVT
    is an :class:`~gnssacc.core.errors.InputError` naming the messages it holds.
"""

from __future__ import annotations

import calendar
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from ..core.errors import InputError, warn_data
from ..core.recording import FIX_QUALITY, GnssFixes, GnssVelocity
from .gnss_time import (
    SECONDS_PER_WEEK,
    FileTimes,
    gps_seconds_to_unix,
    unix_to_gps_seconds,
)

KIND = "a u-blox UBX log"
#: fixType -> quality code (None: dropped); carrSoln and diffSoln refine 3-D fixes.
FIX_TYPE_QUALITY = {
    0: None,
    1: FIX_QUALITY["estimated"],
    2: FIX_QUALITY["unknown"],
    3: FIX_QUALITY["single"],
    4: FIX_QUALITY["single"],
    5: None,
}


@dataclass
class UbxFile:
    """What :func:`read_ubx` found.

    Attributes
    ----------
    times : FileTimes
        UNIX seconds of the kept epochs (``absolute``, GPST).
    fixes : GnssFixes
        The fixes on those times (``sigma_stated`` True).
    velocity : GnssVelocity or None
        The NED velocities on the same times (those with ``sAcc`` > 0).
    meta : dict
        ``messages`` (count by identity), ``bad`` (unreadable messages), ``dropped`` (by reason).
    """

    times: FileTimes
    fixes: GnssFixes
    velocity: GnssVelocity | None
    meta: dict = field(default_factory=dict)


def read_ubx(path, max_bad_fraction: float = 0.01) -> UbxFile:
    """Read a u-blox UBX log (rules in the module docstring).

    Raises
    ------
    InputError
        Not readable, too many bad messages, no NAV-PVT, no usable epoch.
    """
    from pyubx2 import ERR_LOG, UBX_PROTOCOL, UBXReader

    where = str(path)
    bad: list = []
    counts: dict = {}
    rows = []
    try:
        with open(path, "rb") as stream:
            reader = UBXReader(
                stream, protfilter=UBX_PROTOCOL, quitonerror=ERR_LOG, errorhandler=bad.append
            )
            for _raw, msg in reader:
                if msg is None:
                    continue
                counts[msg.identity] = counts.get(msg.identity, 0) + 1
                if msg.identity == "NAV-PVT":
                    rows.append(msg)
    except OSError as exc:
        raise InputError(where, f"cannot read the file: {exc.strerror}") from None
    n_msg = sum(counts.values()) + len(bad)
    if bad:
        text = f"{len(bad)} of {n_msg} UBX message(s) unreadable (first: {str(bad[0])[:60]})"
        if len(bad) > max_bad_fraction * n_msg:
            raise InputError(
                where,
                f"{text}: more than the allowed {100 * max_bad_fraction:.1f}% "
                f"(data.max_bad_fraction); is it a UBX log?",
            )
        warn_data(where, f"skipped {text}")
    if not rows:
        held = ", ".join(f"{k} {v}" for k, v in sorted(counts.items())) or "no UBX message"
        raise InputError(where, f"no NAV-PVT message ({held}): gnssacc reads NAV-PVT epochs")
    return _epochs(rows, where, {"messages": counts, "bad": len(bad)})


def _epochs(rows: list, where: str, meta: dict) -> UbxFile:
    """The kept NAV-PVT epochs as fixes and velocities."""
    dropped: dict = {}
    keep = []
    for m in rows:
        reason = _drop_reason(m)
        if reason:
            dropped[reason] = dropped.get(reason, 0) + 1
        else:
            keep.append(m)
    meta["dropped"] = dropped
    if dropped:
        listing = ", ".join(f"{v} {k}" for k, v in sorted(dropped.items()))
        warn_data(
            where, f"dropped {sum(dropped.values())} of {len(rows)} NAV-PVT epochs ({listing})"
        )
    if not keep:
        raise InputError(where, f"no NAV-PVT epoch with a valid fix ({len(rows)} read)")
    t = _unix_times(keep)
    order = np.argsort(t, kind="stable")
    keep, t = [keep[i] for i in order], t[order]
    a = {k: np.array([getattr(m, k) for m in keep], float) for k in _FIELDS}
    quality = np.array([_quality(m) for m in keep], int)
    sig = np.column_stack([a["hAcc"], a["hAcc"], a["vAcc"]]) * 1e-3
    fixes = GnssFixes(
        t, np.radians(a["lat"]), np.radians(a["lon"]), a["height"] * 1e-3, sig, quality
    )
    has_v = a["sAcc"] > 0
    vel = None
    if has_v.any():
        v = np.column_stack([a["velN"], a["velE"], a["velD"]])[has_v] * 1e-3
        s = np.repeat(a["sAcc"][has_v, None] * 1e-3, 3, axis=1)
        vel = GnssVelocity(t[has_v], v, s, None, sigma_stated=True)
    return UbxFile(FileTimes(t, "absolute", "GPST"), fixes, vel, meta)


_FIELDS = ("lat", "lon", "height", "hAcc", "vAcc", "velN", "velE", "velD", "sAcc")


def _drop_reason(m) -> str:
    """Why a NAV-PVT epoch is not used ("" when it is)."""
    if FIX_TYPE_QUALITY.get(int(m.fixType)) is None:
        return "no fix" if int(m.fixType) == 0 else f"fixType {int(m.fixType)}"
    if not int(m.gnssFixOk):
        return "gnssFixOK 0"
    if int(getattr(m, "invalidLlh", 0)):
        return "invalidLlh"
    if not (int(m.validDate) and int(m.validTime)):
        return "no valid UTC date"
    if m.hAcc <= 0 or m.vAcc <= 0:
        return "no accuracy estimate"
    return ""


def _quality(m) -> int:
    carr = int(m.carrSoln)
    if carr == 2:
        return FIX_QUALITY["fix"]
    if carr == 1:
        return FIX_QUALITY["float"]
    q = FIX_TYPE_QUALITY[int(m.fixType)]
    return FIX_QUALITY["dgps"] if int(m.diffSoln) and q == FIX_QUALITY["single"] else q


def _unix_times(rows: list) -> np.ndarray:
    """UNIX seconds of the epochs: ``iTOW`` in the GPS week nearest the UTC date's."""
    utc = np.array(
        [
            calendar.timegm((m.year, m.month, m.day, m.hour, m.min, 0)) + m.second + m.nano * 1e-9
            for m in rows
        ]
    )
    tow = np.array([m.iTOW for m in rows], float) * 1e-3
    week = np.rint((unix_to_gps_seconds(utc) - tow) / SECONDS_PER_WEEK)
    return gps_seconds_to_unix(week * SECONDS_PER_WEEK + tow)


# --- writing ---------------------------------------------------------------------------------


#: Quality code -> (fixType, diffSoln, carrSoln) written.
QUALITY_PVT = {
    FIX_QUALITY["fix"]: (3, 1, 2),
    FIX_QUALITY["float"]: (3, 1, 1),
    FIX_QUALITY["dgps"]: (3, 1, 0),
    FIX_QUALITY["sbas"]: (3, 1, 0),
    FIX_QUALITY["ppp"]: (3, 1, 0),
    FIX_QUALITY["single"]: (3, 0, 0),
    FIX_QUALITY["estimated"]: (1, 0, 0),
    FIX_QUALITY["unknown"]: (2, 0, 0),
}


def _pvt_message(gnss: GnssFixes, k: int, quality: int, v_ned: np.ndarray, s_acc: float):
    """The NAV-PVT message of fix ``k`` (UBX units: ms, 1e-7 deg, mm, mm/s)."""
    from pyubx2 import GET, UBXMessage

    ms = int(np.rint(float(unix_to_gps_seconds(gnss.t[k])) * 1e3))
    utc = float(gps_seconds_to_unix(ms * 1e-3))
    sec = int(np.floor(utc))
    d = datetime.fromtimestamp(sec, timezone.utc)
    fix_type, diff, carr = QUALITY_PVT[quality]
    mm = lambda x: int(np.rint(x * 1e3))  # noqa: E731
    return UBXMessage(
        "NAV",
        "NAV-PVT",
        GET,
        iTOW=ms % int(SECONDS_PER_WEEK * 1000),
        year=d.year,
        month=d.month,
        day=d.day,
        hour=d.hour,
        min=d.minute,
        second=d.second,
        validDate=1,
        validTime=1,
        fullyResolved=1,
        tAcc=20,
        nano=int(np.rint((utc - sec) * 1e9)),
        fixType=fix_type,
        gnssFixOk=1,
        diffSoln=diff,
        carrSoln=carr,
        numSV=12,
        lon=float(np.degrees(gnss.lon[k])),
        lat=float(np.degrees(gnss.lat[k])),
        height=mm(gnss.h[k]),
        hMSL=mm(gnss.h[k]),
        hAcc=mm(max(gnss.sigma_ned[k, 0], gnss.sigma_ned[k, 1])),
        vAcc=mm(gnss.sigma_ned[k, 2]),
        velN=mm(v_ned[0]),
        velE=mm(v_ned[1]),
        velD=mm(v_ned[2]),
        gSpeed=mm(np.hypot(v_ned[0], v_ned[1])),
        headMot=float(np.degrees(np.arctan2(v_ned[1], v_ned[0])) % 360.0),
        sAcc=mm(s_acc),
        headAcc=180.0,
        pDOP=1.5,
    )


def write_ubx(path, gnss: GnssFixes, vel_ned=None, vel_cov_ned=None) -> Path:
    """Write fixes held on a UNIX clock as a UBX log of NAV-PVT messages (``pyubx2``).

    Parameters
    ----------
    path : str or Path
    gnss : GnssFixes
        Times UNIX seconds (written as ``iTOW`` [ms] and the UTC fields), positions to 1e-7 deg
        and 1 mm; ``hAcc`` the larger of the north and east sigmas, ``vAcc`` the down sigma [mm].
        Correlations cannot be written.
    vel_ned : ndarray, shape (M, 3), optional
        NED velocity at each fix [m/s] (NaN rows: none, written with ``sAcc`` 0), to 1 mm/s.
    vel_cov_ned : ndarray, shape (M, 3, 3), optional
        Its covariance: ``sAcc`` is the largest axis sigma.

    Raises
    ------
    ValueError
        A velocity with an unmeasured axis (NAV-PVT always has three).
    """
    m = len(gnss)
    quality = np.full(m, FIX_QUALITY["single"]) if gnss.quality is None else gnss.quality
    v = np.full((m, 3), np.nan) if vel_ned is None else np.asarray(vel_ned, float)
    has_v = np.all(np.isfinite(v), axis=1)
    if np.any(np.isfinite(v).any(axis=1) & ~has_v):
        raise ValueError(
            "a UBX NAV-PVT velocity has three axes: a horizontal-only one cannot be written"
        )
    s_acc = np.zeros(m)
    if vel_cov_ned is not None:
        sd = np.sqrt(np.diagonal(np.nan_to_num(vel_cov_ned), axis1=1, axis2=2))
        s_acc = np.where(has_v, sd.max(axis=1), 0.0)
    out = bytearray()
    for k in range(m):
        vk = np.where(has_v[k], v[k], 0.0)
        out += _pvt_message(gnss, k, int(quality[k]), vk, float(s_acc[k])).serialize()
    path = Path(path)
    path.write_bytes(bytes(out))
    return path
