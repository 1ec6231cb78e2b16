"""Absolute GNSS times (GPST, UTC, JST; GPS week and time of week; NMEA times of day) and how
they are put on the clock of a recording's IMU.

Representation
    Every absolute time is held as UNIX (POSIX) seconds: seconds since 1970-01-01 00:00:00 UTC
    without leap seconds, the clock of ROS header stamps and of most loggers. GPS time (GPST)
    runs ahead of UTC by the leap seconds inserted since 1980-01-06:
    ``unix = gpst_seconds_since_1980_01_06 + 315964800 - leap(t)``.

Leap seconds
    :data:`LEAP_SECONDS`: GPS - UTC after each insertion, from IERS Bulletin C (the table RTKLIB's
    ``utc2gpst`` uses): 1 s from 1981-07-01 ... 18 s from 2017-01-01. No leap second has been
    inserted since; a time after the next insertion (announced six months ahead) would be off by
    that second until the table is extended.

Clocks (:func:`place_on_clock`)
    A file's absolute times are used on the IMU's clock when the IMU's time stamps are
    absolute too: UNIX seconds (a bag's header stamps; also UTC), or GPS seconds since
    1980-01-06. An IMU clock that counts from some other origin (e.g. 0 at power-on) cannot
    be aligned with absolute fix times: that is an :class:`~gnssacc.core.errors.InputError`
    naming both spans, never a silent misalignment.
"""

from __future__ import annotations

import calendar
from dataclasses import dataclass
from datetime import datetime, timezone

import numpy as np

from ..core.errors import InputError

#: UNIX time of the GPS epoch 1980-01-06 00:00:00 UTC [s].
GPS_EPOCH_UNIX = 315964800.0
SECONDS_PER_WEEK = 604800.0
SECONDS_PER_DAY = 86400.0
#: (UTC date the value takes effect, GPS - UTC [s]) after each leap second (IERS Bulletin C).
LEAP_SECONDS = (
    ((1981, 7, 1), 1),
    ((1982, 7, 1), 2),
    ((1983, 7, 1), 3),
    ((1985, 7, 1), 4),
    ((1988, 1, 1), 5),
    ((1990, 1, 1), 6),
    ((1991, 1, 1), 7),
    ((1992, 7, 1), 8),
    ((1993, 7, 1), 9),
    ((1994, 7, 1), 10),
    ((1996, 1, 1), 11),
    ((1997, 7, 1), 12),
    ((1999, 1, 1), 13),
    ((2006, 1, 1), 14),
    ((2009, 1, 1), 15),
    ((2012, 7, 1), 16),
    ((2015, 7, 1), 17),
    ((2017, 1, 1), 18),
)
_LEAP_UNIX = np.array([calendar.timegm((y, m, d, 0, 0, 0)) for (y, m, d), _ in LEAP_SECONDS], float)
_LEAP_VALUE = np.array([v for _, v in LEAP_SECONDS], float)
#: IMU stamps below this are not an absolute clock (UNIX 1e8 s is 1973; GPS 1e8 s is 1983) [s].
ABSOLUTE_CLOCK_MIN_S = 1e8
#: Offset of JST (Japan Standard Time, an RTKLIB option) from UTC [s].
JST_OFFSET_S = 9 * 3600.0
TIME_SYSTEMS = ("GPST", "UTC", "JST")


def leap_seconds_at_unix(t_unix) -> np.ndarray:
    """GPS - UTC [s] in effect at UNIX times ``t_unix`` (0 before 1981-07-01)."""
    idx = np.searchsorted(_LEAP_UNIX, np.asarray(t_unix, float), side="right")
    return np.where(idx > 0, _LEAP_VALUE[np.maximum(idx - 1, 0)], 0.0)


def gps_seconds_to_unix(t_gps) -> np.ndarray:
    """GPS seconds since 1980-01-06 (GPST) -> UNIX seconds (UTC).

    The leap-second count is looked up at the UTC time, which is ``t - leap`` itself: the GPST
    time is first taken as UTC (off by at most 18 s), then corrected once more, which settles
    everywhere except within 18 s after an insertion, where the second pass does.
    """
    t_gps = np.asarray(t_gps, float)
    approx = t_gps + GPS_EPOCH_UNIX
    for _ in range(2):
        unix = t_gps + GPS_EPOCH_UNIX - leap_seconds_at_unix(approx)
        approx = unix
    return unix


def unix_to_gps_seconds(t_unix) -> np.ndarray:
    """UNIX seconds (UTC) -> GPS seconds since 1980-01-06 (GPST)."""
    t_unix = np.asarray(t_unix, float)
    return t_unix - GPS_EPOCH_UNIX + leap_seconds_at_unix(t_unix)


def week_tow_to_gps_seconds(week, tow) -> np.ndarray:
    """GPS week (counted from 1980-01-06, no roll-over) and time of week [s] -> GPS seconds."""
    return np.asarray(week, float) * SECONDS_PER_WEEK + np.asarray(tow, float)


def calendar_to_seconds(
    year: int, month: int, day: int, hour: int, minute: int, second: float
) -> float:
    """A calendar date and time of day -> seconds since 1970-01-01 of the same time scale.

    Used for UTC (giving UNIX time) and for GPST calendar dates (then seconds since 1970 on the
    GPST scale, i.e. GPS seconds + 315964800). ``second`` may hold a fraction.
    """
    whole = int(np.floor(second))
    return float(
        calendar.timegm((int(year), int(month), int(day), int(hour), int(minute), whole))
    ) + (second - whole)


def to_unix(t_scale: np.ndarray, system: str) -> np.ndarray:
    """Seconds since 1970-01-01 on ``system``'s scale (a calendar read as is) -> UNIX seconds.

    ``"UTC"``: already UNIX. ``"GPST"``: the leap seconds are removed. ``"JST"``: UTC + 9 h.
    """
    t_scale = np.asarray(t_scale, float)
    if system == "UTC":
        return t_scale
    if system == "JST":
        return t_scale - JST_OFFSET_S
    if system == "GPST":
        return gps_seconds_to_unix(t_scale - GPS_EPOCH_UNIX)
    raise ValueError(f"unknown time system {system!r}")


def iso_utc(t_unix: float) -> str:
    """A UNIX time as ``YYYY-MM-DD hh:mm:ss`` UTC (for messages)."""
    try:
        return datetime.fromtimestamp(float(t_unix), timezone.utc).strftime("%Y-%m-%d %H:%M:%S UTC")
    except (OverflowError, OSError, ValueError):
        return f"{t_unix:.3f} s"


@dataclass
class FileTimes:
    """The times of a GNSS file as read.

    Attributes
    ----------
    t : ndarray
        UNIX seconds when ``kind == "absolute"``; seconds since 00:00 UTC of an unknown day
        (made monotonic across midnights) when ``kind == "utc_time_of_day"`` (NMEA GGA without a
        date from RMC or ZDA).
    kind : {"absolute", "utc_time_of_day"}
    system : str
        The file's own time system (``GPST``, ``UTC``, ``JST``), for messages.
    """

    t: np.ndarray
    kind: str
    system: str


def _overlaps(a: np.ndarray, b: np.ndarray) -> bool:
    return bool(a[0] <= b[-1] and b[0] <= a[-1])


def place_on_clock(times: FileTimes, imu_t: np.ndarray, where: str) -> tuple[np.ndarray, str]:
    """The file's fix times on the IMU's clock [s], and which clock that is.

    Parameters
    ----------
    times : FileTimes
    imu_t : ndarray
        The IMU time stamps [s] (the run's clock).
    where : str
        The file, for errors.

    Returns
    -------
    t : ndarray
        Fix times on the IMU's clock [s].
    clock : str
        ``"unix"`` (the IMU stamps UNIX/UTC seconds) or ``"gps"`` (GPS seconds since 1980-01-06).

    Raises
    ------
    InputError
        The IMU's clock is not absolute (or is absolute but does not meet the fixes on either
        scale): one line with both spans.
    """
    imu_span = f"{imu_t[0]:.3f} .. {imu_t[-1]:.3f} s"
    if times.kind == "utc_time_of_day":
        if imu_t[0] < ABSOLUTE_CLOCK_MIN_S:
            raise InputError(
                where,
                f"its fixes carry UTC times of day but no date (no RMC or ZDA sentence), and the "
                f"IMU's time stamps ({imu_span}) are not UNIX time, so neither gives the day: add "
                f"RMC sentences, or give the fixes as gnss.csv on the IMU's clock",
            )
        return _time_of_day_on_unix(times.t, imu_t, where), "unix"
    t = times.t
    first, last = iso_utc(t[0]), iso_utc(t[-1])
    if imu_t[0] < ABSOLUTE_CLOCK_MIN_S:
        raise InputError(
            where,
            f"its fix times are absolute {times.system} ({first} .. {last}) but the IMU's time "
            f"stamps are not ({imu_span}, a clock of its own): gnssacc cannot align them; stamp the "
            f"IMU in UNIX (UTC) or GPS seconds, or give the fixes as gnss.csv on the IMU's clock",
        )
    if _overlaps(t, imu_t):
        return t.copy(), "unix"
    t_gps = unix_to_gps_seconds(t)
    if _overlaps(t_gps, imu_t):
        return t_gps, "gps"
    raise InputError(
        where,
        f"its fixes ({times.system} {first} .. {last}) do not meet the IMU's time stamps "
        f"({imu_span}: UNIX {iso_utc(imu_t[0])} .., or GPS seconds "
        f"{iso_utc(gps_seconds_to_unix(imu_t[0]))} ..) on either clock: a different recording?",
    )


def _time_of_day_on_unix(tod: np.ndarray, imu_t: np.ndarray, where: str) -> np.ndarray:
    """UTC times of day (monotonic) placed on the UNIX day of the IMU that makes them meet it."""
    day0 = np.floor(imu_t[0] / SECONDS_PER_DAY) * SECONDS_PER_DAY
    for shift in (0.0, -SECONDS_PER_DAY, SECONDS_PER_DAY):
        t = day0 + shift + tod
        if _overlaps(t, imu_t):
            return t
    raise InputError(
        where,
        f"its UTC times of day ({tod[0]:.2f} .. {tod[-1]:.2f} s after midnight) do not meet "
        f"the IMU's UNIX time stamps ({iso_utc(imu_t[0])} .. {iso_utc(imu_t[-1])}) on that "
        f"day or the next or previous",
    )
