"""NMEA 0183 GNSS logs: reading GGA (with RMC or ZDA for the date, GST for the sigmas), and writing
(for the simulator and tests).

Sentences (any talker: ``GP``, ``GN``, ``GL``, ``GA``, ``GB``, ``BD`` ...; others are ignored)
    ``GGA``: UTC time of day, latitude and longitude (``ddmm.mmmm``, hemisphere letters), fix
    quality, number of satellites, HDOP, altitude above mean sea level and the geoid separation:
    the ellipsoidal height is ``altitude + separation``.
    ``RMC`` / ``ZDA``: the UTC date that puts GGA's time of day on a calendar day (the one with the
    same time of day, else the nearest one before, across midnight); RMC's speed over ground
    [knots -> m/s] and course [deg] (status ``A`` only) are kept beside the fixes
    (``NmeaFile.speed_mps``, ``course_deg``) and become the horizontal GNSS velocity
    (:func:`gnssacc.sources.gnss_vel.velocity_from_speed_course`: a documented default sigma, and
    below a stated speed no course).
    ``VTG``: course over ground (true) and speed (knots, else km/h), used at the epochs RMC gives
    none. VTG has no time of its own: it belongs to the epoch of the time-tagged sentence (RMC,
    GGA, GST, ZDA) before it, or, when the file's first VTG comes before any of them (a receiver
    that leads each epoch with VTG), to the one after it. A VTG of mode ``N`` (not valid) is
    ignored.
    ``GST``: per-axis 1-sigma of latitude, longitude and altitude [m] and the error ellipse
    (semi-major, semi-minor, orientation from true north): preferred over HDOP; the ellipse gives
    the north-east correlation.
Sigmas without GST (a stated assumption, not a measurement)
    ``sigma_n = sigma_e = HDOP * UERE / sqrt(2)`` (HDOP scales the user-equivalent range error,
    UERE, into the horizontal RMS error, shared by two axes) and
    ``sigma_d = vertical_factor * HDOP * UERE`` (VDOP taken as ``vertical_factor`` times HDOP).
    UERE depends on the fix quality (``[gnss] nmea_uere_m``, defaults in
    :data:`gnssacc.core.config.DEFAULTS`); a fix without HDOP gets ``gnss.default_sigma_m``.
Fix quality (GGA field 6) -> :data:`gnssacc.core.recording.FIX_QUALITY`
    0 invalid (dropped), 1 GPS/SPS -> single, 2 DGPS -> dgps, 3 PPS -> single, 4 RTK fixed -> fix,
    5 RTK float -> float, 6 estimated (dead reckoning) -> estimated, 7 manual input (dropped, not
    a measurement), 8 simulation -> unknown.
Checks
    Every sentence's checksum (``*hh``, the XOR of the characters between ``$`` and ``*``) is
    verified; sentences that fail it, have none, have too few fields or unreadable numbers, and
    lines that are not sentences, are counted and skipped with one warning line, or, above
    ``data.max_bad_fraction`` of the lines, refused with an :class:`~gnssacc.core.errors.InputError`
    naming the first bad line.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from ..core.errors import InputError, warn_data
from ..core.recording import FIX_QUALITY
from .common import text_file_lines
from .gnss_time import SECONDS_PER_DAY, FileTimes, calendar_to_seconds

KIND = "an NMEA 0183 log"
KNOT_MPS = 1852.0 / 3600.0
#: GGA fix quality -> gnssacc quality code; None: the fix is dropped.
GGA_QUALITY = {
    0: None,
    1: FIX_QUALITY["single"],
    2: FIX_QUALITY["dgps"],
    3: FIX_QUALITY["single"],
    4: FIX_QUALITY["fix"],
    5: FIX_QUALITY["float"],
    6: FIX_QUALITY["estimated"],
    7: None,
    8: FIX_QUALITY["unknown"],
}
#: gnssacc quality code -> GGA fix quality (for writing).
QUALITY_GGA = {
    FIX_QUALITY["single"]: 1,
    FIX_QUALITY["dgps"]: 2,
    FIX_QUALITY["sbas"]: 2,
    FIX_QUALITY["fix"]: 4,
    FIX_QUALITY["float"]: 5,
    FIX_QUALITY["estimated"]: 6,
    FIX_QUALITY["ppp"]: 5,
    FIX_QUALITY["unknown"]: 1,
}
#: Fields after the address that a sentence must have to be read.
MIN_FIELDS = {"GGA": 11, "RMC": 9, "ZDA": 4, "GST": 8, "VTG": 7}
#: Dates further than this from a GGA's time of day are a day away [s].
HALF_DAY_S = 43200.0


@dataclass
class NmeaFile:
    """What :func:`read_nmea` found, one entry per GGA fix kept.

    Attributes
    ----------
    times : FileTimes
        UNIX seconds (``absolute``, UTC) or UTC times of day (``utc_time_of_day``: no date).
    lat, lon : ndarray [rad]
    h : ndarray [m]
        Ellipsoidal height (altitude + geoid separation).
    sigma_ned : ndarray, shape (M, 3) [m]
    corr_ned : ndarray, shape (M, 3), or None
        ``(rho_ne, 0, 0)`` from GST's error ellipse, None without any.
    quality : ndarray of int
        :data:`gnssacc.core.recording.FIX_QUALITY` codes.
    n_sat : ndarray of int
    hdop : ndarray
        NaN where absent.
    speed_mps, course_deg : ndarray
        RMC's speed over ground [m/s] and course [deg] at the fix's epoch, NaN without an RMC.
    meta : dict
        Counts: ``sentences``, ``bad`` (by reason), ``first_bad_line``, ``dropped_quality``
        (by GGA quality), ``sigma_from`` (gst, hdop, default).
    """

    times: FileTimes
    lat: np.ndarray
    lon: np.ndarray
    h: np.ndarray
    sigma_ned: np.ndarray
    corr_ned: np.ndarray | None
    quality: np.ndarray
    n_sat: np.ndarray
    hdop: np.ndarray
    speed_mps: np.ndarray
    course_deg: np.ndarray
    meta: dict = field(default_factory=dict)


# --- sentences -----------------------------------------------------------------------------------------


def checksum(body: str) -> int:
    """The NMEA checksum of the text between ``$`` and ``*``: the XOR of its bytes."""
    out = 0
    for ch in body.encode("ascii", "replace"):
        out ^= ch
    return out


class BadSentence(ValueError):
    """A line that is not a usable sentence; its text is the reason (a short phrase)."""


def split_sentence(line: str) -> tuple[str, list[str]] | None:
    """``(type, fields)`` of a sentence (type e.g. ``GGA``, talker dropped), None for a sentence
    gnssacc does not read (proprietary, other types).

    Raises
    ------
    BadSentence
        Not a sentence, no checksum, a wrong checksum.
    """
    start = line.find("$")
    if start < 0:
        raise BadSentence("not a sentence")
    text = line[start + 1 :].strip()
    body, star, given = text.partition("*")
    if not star:
        raise BadSentence("no checksum")
    try:
        if int(given[:2], 16) != checksum(body) or len(given.strip()) != 2:
            raise BadSentence("bad checksum")
    except ValueError:
        raise BadSentence("bad checksum") from None
    words = body.split(",")
    address = words[0]
    if address.startswith("P") or len(address) != 5:
        return None
    kind = address[2:]
    if kind not in MIN_FIELDS:
        return None
    if len(words) - 1 < MIN_FIELDS[kind]:
        raise BadSentence("too few fields")
    return kind, words[1:]


def _number(text: str, what: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise BadSentence(f"unreadable {what}") from None


def _time_of_day(text: str) -> float:
    """``hhmmss.ss`` -> seconds after midnight."""
    if len(text) < 6:
        raise BadSentence("unreadable time")
    hh, mm, ss = _number(text[0:2], "time"), _number(text[2:4], "time"), _number(text[4:], "time")
    if not (0 <= hh < 24 and 0 <= mm < 60 and 0 <= ss < 61):
        raise BadSentence("unreadable time")
    return hh * 3600.0 + mm * 60.0 + ss


def _angle(value: str, hemi: str, width: int) -> float:
    """``ddmm.mmmm`` (``dddmm.mmmm`` for longitude, ``width`` degree digits) + N/S/E/W -> degrees."""
    if hemi not in ("N", "S", "E", "W") or len(value) < width + 2:
        raise BadSentence("unreadable position")
    deg = _number(value[:width], "position") + _number(value[width:], "position") / 60.0
    return -deg if hemi in ("S", "W") else deg


def _midnight(day: str, month: str, year: str) -> float:
    """UNIX time of 00:00 UTC of a date; two-digit years are 1980-2079 (as RTKLIB reads them)."""
    y = int(_number(year, "date"))
    if y < 100:
        y += 2000 if y < 80 else 1900
    try:
        return calendar_to_seconds(
            y, int(_number(month, "date")), int(_number(day, "date")), 0, 0, 0.0
        )
    except (ValueError, OverflowError):
        raise BadSentence("unreadable date") from None


@dataclass
class _Gga:
    index: int
    line: int
    tod: float
    lat: float
    lon: float
    q: int
    n_sat: int
    hdop: float
    h: float


def _gga(f: list[str], index: int, line: int) -> _Gga | None:
    """A GGA fix (None when it has no position: quality 0 with empty fields)."""
    q = int(_number(f[5], "fix quality")) if f[5] else 0
    if q == 0 and not f[1]:
        return _Gga(
            index,
            line,
            _time_of_day(f[0]) if f[0] else np.nan,
            np.nan,
            np.nan,
            0,
            0,
            np.nan,
            np.nan,
        )
    tod = _time_of_day(f[0])
    lat, lon = _angle(f[1], f[2], 2), _angle(f[3], f[4], 3)
    alt, sep = _number(f[8], "altitude"), (_number(f[10], "geoid separation") if f[10] else 0.0)
    hdop = _number(f[7], "HDOP") if f[7] else np.nan
    n_sat = int(_number(f[6], "satellite count")) if f[6] else 0
    return _Gga(index, line, tod, lat, lon, q, n_sat, hdop, alt + sep)


# --- reading -------------------------------------------------------------------------------------------


def read_nmea(
    path,
    uere_m: dict,
    vertical_factor: float,
    default_sigma_ned: np.ndarray,
    max_bad_fraction: float,
) -> NmeaFile:
    """Read an NMEA 0183 log (format and rules in the module docstring).

    Parameters
    ----------
    path : str or Path
    uere_m : dict
        Quality code (:data:`gnssacc.core.recording.FIX_QUALITY`) -> UERE [m] for HDOP sigmas.
    vertical_factor : float
        VDOP / HDOP assumed for the vertical sigma.
    default_sigma_ned : ndarray, shape (3,)
        Sigmas [m] of a fix with neither GST nor HDOP.
    max_bad_fraction : float
        Largest fraction of bad lines tolerated (``data.max_bad_fraction``).

    Raises
    ------
    InputError
        Not text (with the line), too many bad sentences (the first named), no GGA fix.
    """
    where = str(path)
    lines = text_file_lines(path, KIND)
    fixes, dates, gst, rmc, counts = _scan(lines, where, max_bad_fraction)
    kept = [g for g in fixes if g.q in GGA_QUALITY and GGA_QUALITY[g.q] is not None]
    dropped = {}
    for g in fixes:
        if g not in kept:
            dropped[g.q] = dropped.get(g.q, 0) + 1
    if not kept:
        raise InputError(
            where,
            f"no GGA sentence with a valid fix ({len(fixes)} GGA sentence(s), "
            f"{counts['sentences']} sentence(s) read)",
        )
    times = _dated(kept, dates, where)
    sig, corr, sigma_from = _sigmas(kept, gst, uere_m, vertical_factor, default_sigma_ned)
    sc = [rmc.get(round(g.tod * 100), (np.nan, np.nan)) for g in kept]
    speed = np.array([x[0] for x in sc])
    course = np.array([x[1] for x in sc])
    meta = {
        **counts,
        "dropped_quality": {str(k): v for k, v in dropped.items()},
        "sigma_from": sigma_from,
    }
    return NmeaFile(
        times,
        np.radians([g.lat for g in kept]),
        np.radians([g.lon for g in kept]),
        np.array([g.h for g in kept]),
        sig,
        corr,
        np.array([GGA_QUALITY[g.q] for g in kept], int),
        np.array([g.n_sat for g in kept], int),
        np.array([g.hdop for g in kept]),
        speed,
        course,
        meta,
    )


def _scan(lines: list[str], where: str, max_bad_fraction: float):
    """Every sentence read: GGA fixes, dates (index, time of day, midnight), GST and the speed and
    course (RMC's, else VTG's) by time of day [centiseconds], and the counts; bad lines counted,
    warned or refused."""
    fixes, dates, gst, rmc = [], [], {}, {}
    tagged: list = []  # (line index, time of day) of every time-tagged sentence
    vtgs: list = []  # (line index, (speed, course))
    bad: dict[str, int] = {}
    first_bad = None
    n_lines = 0
    for n, line in enumerate(lines, start=1):
        if not line.strip():
            continue
        n_lines += 1
        try:
            parsed = split_sentence(line)
            if parsed is None:
                continue
            kind, f = parsed
            if kind == "VTG":
                _vtg(f, n_lines, vtgs)
                continue
            if kind == "GGA":
                fixes.append(_gga(f, n_lines, n))
            elif kind in ("RMC", "ZDA"):
                _date_sentence(kind, f, n_lines, dates, rmc)
            else:
                _gst(f, gst)
            if f[0]:
                tagged.append((n_lines, _time_of_day(f[0])))
        except BadSentence as err:
            reason = str(err)
            bad[reason] = bad.get(reason, 0) + 1
            first_bad = first_bad or (n, reason)
    n_bad = sum(bad.values())
    counts = {
        "sentences": n_lines,
        "bad": bad,
        "first_bad_line": first_bad[0] if first_bad else None,
    }
    for key, value in _vtg_epochs(vtgs, tagged).items():  # where RMC gives no speed
        if not np.isfinite(rmc.get(key, (np.nan,))[0]):
            rmc[key] = value
    if n_bad:
        listing = ", ".join(f"{v} {k}" for k, v in sorted(bad.items()))
        text = (
            f"{n_bad} of {n_lines} line(s) are not usable sentences ({listing}); first at line {first_bad[0]} "
            f"({first_bad[1]})"
        )
        if n_bad > max_bad_fraction * n_lines:
            raise InputError(
                where,
                f"{text}: more than the allowed {100 * max_bad_fraction:.1f}% "
                f"(data.max_bad_fraction)",
            )
        warn_data(where, f"skipped {text}")
    return fixes, dates, gst, rmc, counts


def _date_sentence(kind: str, f: list[str], index: int, dates: list, rmc: dict) -> None:
    """An RMC or ZDA: its date (if any) and, for RMC, speed and course by time of day."""
    if kind == "RMC":
        if not f[0] or not f[8]:
            return
        tod = _time_of_day(f[0])
        d = f[8]
        if len(d) != 6:
            raise BadSentence("unreadable date")
        dates.append((index, tod, _midnight(d[0:2], d[2:4], d[4:6])))
        if f[1] == "A":  # V: void, no valid navigation (its speed and course are not used)
            speed = _number(f[6], "speed") * KNOT_MPS if f[6] else np.nan
            course = _number(f[7], "course") if f[7] else np.nan
            rmc[round(tod * 100)] = (speed, course)
    elif f[0] and f[1] and f[2] and f[3]:
        dates.append((index, _time_of_day(f[0]), _midnight(f[1], f[2], f[3])))


def _vtg(f: list[str], index: int, vtgs: list) -> None:
    """A VTG: (index, (speed [m/s], course [deg])); none when its mode is N (not valid)."""
    if len(f) > 8 and f[8][:1] == "N":
        return
    course = _number(f[0], "course") if f[0] else np.nan
    if f[4]:
        speed = _number(f[4], "speed") * KNOT_MPS
    elif f[6]:
        speed = _number(f[6], "speed") / 3.6
    else:
        return
    vtgs.append((index, (speed, course)))


def _vtg_epochs(vtgs: list, tagged: list) -> dict:
    """VTG (speed, course) by time of day [centiseconds]: each at the time-tagged sentence before
    it, or after it when the file's first VTG precedes every time-tagged sentence."""
    if not vtgs or not tagged:
        return {}
    idx = np.array([i for i, _ in tagged])
    tod = np.array([t for _, t in tagged])
    leads = vtgs[0][0] < idx[0]
    out = {}
    for i, value in vtgs:
        j = int(np.searchsorted(idx, i)) if leads else int(np.searchsorted(idx, i)) - 1
        if 0 <= j < len(idx):
            out[round(tod[j] * 100)] = value
    return out


def _gst(f: list[str], gst: dict) -> None:
    """A GST: ``(semi-major, semi-minor, orientation [deg], sd lat, sd lon, sd alt)`` by time of day."""
    if not f[0]:
        return
    vals = tuple(_number(v, "GST value") if v else np.nan for v in f[2:8])
    gst[round(_time_of_day(f[0]) * 100)] = vals


def _dated(kept: list[_Gga], dates: list, where: str) -> FileTimes:
    """UNIX times of the fixes from the dates nearest them; UTC times of day without any date."""
    tod = np.array([g.tod for g in kept])
    if not dates:
        jumps = np.r_[0.0, np.cumsum(np.where(np.diff(tod) < -HALF_DAY_S, SECONDS_PER_DAY, 0.0))]
        return FileTimes(tod + jumps, "utc_time_of_day", "UTC")
    d_index = np.array([d[0] for d in dates])
    d_tod = np.array([d[1] for d in dates])
    d_mid = np.array([d[2] for d in dates])
    same = {}
    for j, (_, t, _m) in enumerate(dates):
        same.setdefault(round(t * 100), []).append(j)
    out = np.empty(len(kept))
    for k, g in enumerate(kept):
        cands = same.get(round(g.tod * 100), [])
        near = [j for j in cands if abs(d_index[j] - g.index) <= 10]
        if near:
            j = min(near, key=lambda j: abs(d_index[j] - g.index))
            out[k] = d_mid[j] + g.tod
            continue
        before = np.flatnonzero(d_index < g.index)
        j = int(before[-1]) if before.size else int(np.argmin(d_index))
        day = d_mid[j] + (
            SECONDS_PER_DAY
            if g.tod < d_tod[j] - HALF_DAY_S
            else -SECONDS_PER_DAY
            if g.tod > d_tod[j] + HALF_DAY_S
            else 0.0
        )
        out[k] = day + g.tod
    return FileTimes(out, "absolute", "UTC")


def _sigmas(
    kept: list[_Gga], gst: dict, uere_m: dict, vertical_factor: float, default_sigma_ned: np.ndarray
):
    """NED sigmas [m] (GST, else HDOP x UERE, else the default), the NE correlation of GST's
    ellipse (None when no fix has one) and the counts of each source."""
    m = len(kept)
    sig = np.empty((m, 3))
    corr = np.zeros((m, 3))
    used = {"gst": 0, "hdop": 0, "default": 0}
    for k, g in enumerate(kept):
        e = gst.get(round(g.tod * 100))
        if e is not None and np.all(np.isfinite(e[3:6])) and np.all(np.asarray(e[3:6]) > 0):
            sig[k] = e[3:6]
            corr[k, 0] = _ellipse_correlation(e, sig[k])
            used["gst"] += 1
        elif np.isfinite(g.hdop) and g.hdop > 0:
            uere = float(uere_m[GGA_QUALITY[g.q]])
            sig[k] = [g.hdop * uere / np.sqrt(2.0)] * 2 + [vertical_factor * g.hdop * uere]
            used["hdop"] += 1
        else:
            sig[k] = default_sigma_ned
            used["default"] += 1
    return sig, (corr if np.any(corr != 0) else None), used


def _ellipse_correlation(e: tuple, sig_ned: np.ndarray) -> float:
    """North-east correlation of GST's error ellipse (semi-major ``a``, semi-minor ``b`` [m], the
    major axis ``theta`` [deg] clockwise from true north): ``C_ne = (a^2 - b^2) sin(theta) cos(theta)``
    over the per-axis sigmas; 0 when the ellipse is absent or inconsistent with them."""
    a, b, theta = e[0], e[1], e[2]
    if not (np.isfinite(a) and np.isfinite(b) and np.isfinite(theta)) or a <= 0 or b < 0:
        return 0.0
    th = np.radians(theta)
    rho = (a * a - b * b) * np.sin(th) * np.cos(th) / (sig_ned[0] * sig_ned[1])
    return float(rho) if abs(rho) < 0.999 else 0.0


# --- writing -------------------------------------------------------------------------------------------


def _sentence(body: str) -> str:
    return f"${body}*{checksum(body):02X}"


def _dm(deg: float, width: int, pos: str, neg: str) -> tuple[str, str]:
    """Degrees -> (``ddmm.mmmmmmm`` with ``width`` degree digits, hemisphere letter)."""
    a = abs(deg)
    d = int(a)
    minutes = (a - d) * 60.0
    if round(minutes, 7) >= 60.0:
        d, minutes = d + 1, 0.0
    return f"{d:0{width}d}{minutes:010.7f}", (neg if deg < 0 else pos)


def write_nmea(
    path,
    t_unix: np.ndarray,
    lat: np.ndarray,
    lon: np.ndarray,
    h: np.ndarray,
    sigma_ned: np.ndarray,
    corr_ned=None,
    quality=None,
    n_sat=None,
    *,
    uere_m: dict,
    vertical_factor: float,
    speed_mps=None,
    course_deg=None,
    geoid_sep_m: float = 0.0,
    gst: bool = True,
    rmc: bool = True,
    vtg: bool = False,
    talker: str = "GP",
) -> Path:
    """Write fixes as NMEA 0183: per epoch RMC (date, speed, course), VTG (when asked), GGA and GST.

    Parameters
    ----------
    t_unix : ndarray
        UNIX (UTC) times [s]; written to the hundredth of a second.
    lat, lon : ndarray [rad]
    h : ndarray [m]
        Ellipsoidal heights; GGA gets ``h - geoid_sep_m`` as altitude and ``geoid_sep_m``.
    sigma_ned : ndarray, shape (M, 3) [m]
        Written in GST (and as the HDOP that gives the same horizontal sigma with ``uere_m``).
    corr_ned : ndarray, shape (M, 3), optional
        Only ``rho_ne`` can be written (GST's ellipse).
    quality, n_sat : array of int, optional
        :data:`~gnssacc.core.recording.FIX_QUALITY` codes (default single) and satellite counts (8).
    uere_m, vertical_factor
        As for :func:`read_nmea`: HDOP = sqrt(2) sigma_h / UERE(quality).
    speed_mps, course_deg : ndarray, optional
        RMC's speed over ground [m/s] and course [deg] (empty fields without).
    gst, rmc, vtg : bool
        Write GST, RMC and VTG sentences (VTG after RMC, at the epochs with a speed).
    talker : str
    """
    m = len(t_unix)
    quality = np.full(m, FIX_QUALITY["single"]) if quality is None else np.asarray(quality, int)
    n_sat = np.full(m, 8) if n_sat is None else np.asarray(n_sat, int)
    out = []
    for k in range(m):
        cs = int(np.rint(float(t_unix[k]) * 100.0))
        sec, centi = divmod(cs, 100)
        d = datetime.fromtimestamp(sec, timezone.utc)
        hms = f"{d:%H%M%S}.{centi:02d}"
        la, ns_ = _dm(np.degrees(lat[k]), 2, "N", "S")
        lo, ew = _dm(np.degrees(lon[k]), 3, "E", "W")
        s = sigma_ned[k]
        s_h = np.sqrt((s[0] ** 2 + s[1] ** 2) / 2.0)
        hdop = np.sqrt(2.0) * s_h / float(uere_m[int(quality[k])])
        if rmc:
            sp = (
                f"{speed_mps[k] / KNOT_MPS:.3f}"
                if speed_mps is not None and np.isfinite(speed_mps[k])
                else ""
            )
            co = (
                f"{course_deg[k] % 360.0:.2f}"
                if course_deg is not None and np.isfinite(course_deg[k])
                else ""
            )
            out.append(
                _sentence(f"{talker}RMC,{hms},A,{la},{ns_},{lo},{ew},{sp},{co},{d:%d%m%y},,,A")
            )
        if vtg and speed_mps is not None and np.isfinite(speed_mps[k]):
            co = f"{course_deg[k] % 360.0:.2f}" if np.isfinite(course_deg[k]) else ""
            kn, kmh = speed_mps[k] / KNOT_MPS, speed_mps[k] * 3.6
            out.append(_sentence(f"{talker}VTG,{co},T,,M,{kn:.3f},N,{kmh:.3f},K,A"))
        out.append(
            _sentence(
                f"{talker}GGA,{hms},{la},{ns_},{lo},{ew},{QUALITY_GGA[int(quality[k])]},{n_sat[k]:02d},"
                f"{hdop:.2f},{h[k] - geoid_sep_m:.4f},M,{geoid_sep_m:.4f},M,,"
            )
        )
        if gst:
            rho = 0.0 if corr_ned is None else float(corr_ned[k][0])
            a, b, theta = _ellipse(s[0], s[1], rho)
            rms = float(np.sqrt(s[0] ** 2 + s[1] ** 2))
            out.append(
                _sentence(
                    f"{talker}GST,{hms},{rms:.4f},{a:.4f},{b:.4f},{theta:.2f},{s[0]:.4f},{s[1]:.4f},"
                    f"{s[2]:.4f}"
                )
            )
    path = Path(path)
    path.write_text("\r\n".join(out) + "\r\n")
    return path


def _ellipse(s_n: float, s_e: float, rho: float) -> tuple[float, float, float]:
    """(semi-major, semi-minor [m], orientation of the major axis [deg from north, 0..180])."""
    C = np.array([[s_n * s_n, rho * s_n * s_e], [rho * s_n * s_e, s_e * s_e]])
    w, v = np.linalg.eigh(C)
    major = v[:, 1]
    theta = np.degrees(np.arctan2(major[1], major[0])) % 180.0
    return float(np.sqrt(max(w[1], 0.0))), float(np.sqrt(max(w[0], 0.0))), float(theta)
