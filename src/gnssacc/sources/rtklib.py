"""RTKLIB position solution files (``.pos``): reading, and writing (for the simulator and tests).

The format is RTKLIB's (``solution.c``: ``outsolheads``, ``outpos``, ``outecef``, ``outenu`` and
their readers; the manual's Appendix B.1 "Positioning Solution File"). Header lines start with
``%``; the last of them names the columns, its first word the time system::

    % (lat/lon/height=WGS84/ellipsoidal,Q=1:fix,2:float,3:sbas,4:dgps,5:single,6:ppp,ns=# of satellites)
    %  GPST                  latitude(deg) longitude(deg)  height(m)   Q  ns   sdn(m)   sde(m)   sdu(m)  sdne(m)  sdeu(m)  sdun(m) age(s)  ratio
    2015/06/01 00:00:00.000   47.480954411   19.056534073   181.7826   5   9   2.1245   1.9103   3.7333   0.1328   0.9211   1.1049   0.00    0.0

Fields are separated by blanks, commas or tabs (RTKLIB's ``sep`` option).

Times
    ``GPST``, ``UTC`` or ``JST`` (UTC + 9 h), as ``yyyy/mm/dd hh:mm:ss.sss`` or GPS week and time
    of week ``wwww ssssss.sss``; converted to UNIX seconds with the leap seconds of
    :mod:`gnssacc.sources.gnss_time` (any other time system is an error).
Positions
    ``latitude(deg) longitude(deg) height(m)``; ``latitude(d'") longitude(d'") height(m)``
    (degrees, minutes, seconds: three fields each, the sign on the degrees); ``x-ecef(m) y-ecef(m)
    z-ecef(m)`` (WGS84 ECEF); or ``e-baseline(m) n-baseline(m) u-baseline(m)`` from the reference
    position of the ``% ref pos :`` header line (latitude, longitude [deg] and height [m], or
    degrees-minutes-seconds). Heights must be ellipsoidal: a ``height=geodetic`` file (heights
    above the geoid) is read with a warning, a ``Tokyo`` datum refused.
Covariance
    The standard deviations ``sdn sde sdu`` (``sdx sdy sdz`` ECEF, ``sde sdn sdu`` ENU) [m] and the
    cross terms ``sdne sdeu sdun`` (``sdxy sdyz sdzx``, ``sden sdnu sdue``), each the signed square
    root of a covariance, ``c = sign(s) s^2`` (RTKLIB's ``sqvar``): rotated into the NED frame at
    the fix, then held as sigmas and correlations (:attr:`gnssacc.core.recording.GnssFixes.corr_ned`).
    A fix whose standard deviations are all zero gets ``gnss.default_sigma_m`` (counted, warned);
    correlations that rounding made inconsistent (not positive definite) are dropped (warned).
Quality
    ``Q``: 1 fix, 2 float, 3 sbas, 4 dgps, 5 single, 6 ppp (and RTKLIB's 7, dead reckoning),
    kept per fix (:data:`gnssacc.core.recording.FIX_QUALITY` uses the same numbers).

Bad input is one :class:`~gnssacc.core.errors.InputError` naming the file and line: no column
header, an unknown time system or column set, a line with the wrong number of fields or a field
that is not a number. A truncated last line (a logger stopped mid-write) is dropped with a warning.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from ..core.earth import R_en_batch, ecef_to_llh, llh_to_ecef
from ..core.errors import InputError, warn_data
from ..core.units import DEG
from .common import text_file_lines
from .gnss_time import (
    GPS_EPOCH_UNIX,
    JST_OFFSET_S,
    SECONDS_PER_WEEK,
    TIME_SYSTEMS,
    FileTimes,
    calendar_to_seconds,
    to_unix,
    unix_to_gps_seconds,
    week_tow_to_gps_seconds,
)

KIND = "an RTKLIB .pos solution file"
#: Position columns of each output form, and the covariance columns in the file's order.
FORMS = {
    "llh": (
        ("latitude(deg)", "longitude(deg)", "height(m)"),
        ("sdn(m)", "sde(m)", "sdu(m)"),
        ("sdne(m)", "sdeu(m)", "sdun(m)"),
    ),
    "dms": (
        ("latitude(d'\")", "longitude(d'\")", "height(m)"),
        ("sdn(m)", "sde(m)", "sdu(m)"),
        ("sdne(m)", "sdeu(m)", "sdun(m)"),
    ),
    "xyz": (
        ("x-ecef(m)", "y-ecef(m)", "z-ecef(m)"),
        ("sdx(m)", "sdy(m)", "sdz(m)"),
        ("sdxy(m)", "sdyz(m)", "sdzx(m)"),
    ),
    "enu": (
        ("e-baseline(m)", "n-baseline(m)", "u-baseline(m)"),
        ("sde(m)", "sdn(m)", "sdu(m)"),
        ("sden(m)", "sdnu(m)", "sdue(m)"),
    ),
}
#: Velocity columns (RTKLIB's ``outvel`` option) of each form that has them: velocity, standard
#: deviations and signed-root cross terms, in the file's order (RTKLIB writes none for ``enu``).
VEL_FORMS = {
    "llh": (
        ("vn(m/s)", "ve(m/s)", "vu(m/s)"),
        ("sdvn", "sdve", "sdvu"),
        ("sdvne", "sdveu", "sdvun"),
    ),
    "dms": (
        ("vn(m/s)", "ve(m/s)", "vu(m/s)"),
        ("sdvn", "sdve", "sdvu"),
        ("sdvne", "sdveu", "sdvun"),
    ),
    "xyz": (
        ("vx(m/s)", "vy(m/s)", "vz(m/s)"),
        ("sdvx", "sdvy", "sdvz"),
        ("sdvxy", "sdvyz", "sdvzx"),
    ),
}
#: Axis-index pairs of each cross-term column in the file's axes (ENU for llh/dms/enu, ECEF for
#: xyz): llh/dms sdne (E,N), sdeu (E,U), sdun (U,N); enu sden, sdnu, sdue; xyz sdxy, sdyz, sdzx.
CROSS_PAIRS = {
    "sdne(m)": (0, 1),
    "sdeu(m)": (0, 2),
    "sdun(m)": (2, 1),
    "sden(m)": (0, 1),
    "sdnu(m)": (1, 2),
    "sdue(m)": (2, 0),
    "sdxy(m)": (0, 1),
    "sdyz(m)": (1, 2),
    "sdzx(m)": (2, 0),
    "sdvne": (0, 1),
    "sdveu": (0, 2),
    "sdvun": (2, 1),
    "sdvxy": (0, 1),
    "sdvyz": (1, 2),
    "sdvzx": (2, 0),
}
#: NED <-> ENU axis swap (its own inverse).
T_ENU_NED = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
_SPLIT = re.compile(r"[,\s]+")


@dataclass
class PosFile:
    """What :func:`read_pos` found.

    Attributes
    ----------
    times : FileTimes
        Absolute UNIX times of the fixes.
    lat, lon : ndarray [rad]
    h : ndarray [m]
        Height as the file gives it (ellipsoidal unless ``height_kind == "geodetic"``).
    cov_ned : ndarray, shape (M, 3, 3)
        Position covariance in the NED frame at each fix [m^2] (zero where the file has none).
    quality : ndarray of int
        ``Q`` per fix (0 when the file has no ``Q`` column).
    n_sat : ndarray of int or None
        ``ns`` per fix.
    meta : dict
        ``form`` (llh, dms, xyz, enu), ``time_system``, ``time_format`` (calendar, week),
        ``height_kind``, ``header_line`` (its number), ``program``.
    vel_ned : ndarray, shape (M, 3), or None
        Velocity of the antenna along north, east, down [m/s] (``vn ve vu`` with ``vu`` negated,
        or ``vx vy vz`` rotated from ECEF), when the file has velocity columns.
    vel_cov_ned : ndarray, shape (M, 3, 3), or None
        Its NED covariance [m^2/s^2] (zero where the file states none).
    """

    times: FileTimes
    lat: np.ndarray
    lon: np.ndarray
    h: np.ndarray
    cov_ned: np.ndarray
    quality: np.ndarray
    n_sat: np.ndarray | None
    meta: dict = field(default_factory=dict)
    vel_ned: np.ndarray | None = None
    vel_cov_ned: np.ndarray | None = None


# --- reading -------------------------------------------------------------------------------------------


def read_pos(path) -> PosFile:
    """Read an RTKLIB ``.pos`` file (format in the module docstring).

    Raises
    ------
    InputError
        Naming the file and line (see the module docstring).
    """
    where = str(path)
    lines = text_file_lines(path, KIND)
    head = _Header.parse(lines, where)
    rows, numbers = _data_rows(lines, head, where)
    if not rows:
        raise InputError(where, f"no solution line after the column header (line {head.line_no})")
    cells = np.array(rows, dtype=object)
    t_scale = _times(cells[:, :2], numbers, head, where)
    values = _numbers(cells[:, 2:], numbers, where)
    col: dict = {}
    for k, name in enumerate(head.value_names):
        col.setdefault(name, k)  # a d'" column's first of three fields
    lat, lon, h, cov = _positions(values, col, head, where)
    quality = values[:, col["q"]].astype(int) if "q" in col else np.zeros(len(values), int)
    n_sat = values[:, col["ns"]].astype(int) if "ns" in col else None
    times = FileTimes(to_unix(t_scale, head.time_system), "absolute", head.time_system)
    meta = {
        "form": head.form,
        "time_system": head.time_system,
        "time_format": head.time_format,
        "height_kind": head.height_kind,
        "header_line": head.line_no,
        "program": head.program,
    }
    vel, vel_cov = _velocities(values, col, head, lat, lon, where)
    return PosFile(times, lat, lon, h, cov, quality, n_sat, meta, vel, vel_cov)


def _velocities(values: np.ndarray, col: dict, head: "_Header", lat, lon, where: str):
    """(NED velocity (M, 3) [m/s], NED covariance (M, 3, 3) [m^2/s^2]) of the rows, or
    (None, None) without velocity columns; a partial set of velocity columns is an error."""
    forms = VEL_FORMS.get(head.form)
    if forms is None:
        return None, None
    v_names, sd_names, cross_names = forms
    found = [c for c in v_names if c in col]
    if not found:
        return None, None
    if len(found) != 3:
        raise InputError(
            where,
            f"line {head.line_no}: the column header has {', '.join(found)} but not all of "
            f"{', '.join(v_names)}",
        )
    v = values[:, [col[c] for c in v_names]]
    cov = _file_covariance(values, col, sd_names, cross_names)
    R_f = R_en_batch(lat, lon)  # ECEF -> NED at the fix
    if head.form == "xyz":
        return np.einsum("kij,kj->ki", R_f, v), R_f @ cov @ R_f.transpose(0, 2, 1)
    v_ned = v[:, [0, 1, 2]] * np.array([1.0, 1.0, -1.0])  # vn ve vu -> N E D
    return v_ned, T_ENU_NED @ cov @ T_ENU_NED.T


@dataclass
class _Header:
    """The header facts: time system, columns, form, reference position."""

    line_no: int
    time_system: str
    names: list  # the column names after the time label, lower case
    value_names: list  # one name per numeric field after the time (d'" columns take three)
    form: str
    time_format: str = "calendar"
    height_kind: str = "ellipsoidal"
    ref_llh: tuple | None = None  # (lat [rad], lon [rad], h [m]) of "ref pos"
    program: str = ""

    @classmethod
    def parse(cls, lines: list[str], where: str) -> "_Header":
        n_col, col_line = None, None
        for n, line in enumerate(lines, start=1):
            text = line.strip()
            if text and not text.startswith("%"):
                break
            if any(f[0][0] in text for f in FORMS.values()):
                n_col, col_line = n, text
        if col_line is None:
            raise InputError(
                where,
                "no RTKLIB column header (a '%' line naming latitude(deg), x-ecef(m) or "
                "e-baseline(m) before the first solution line): gnssacc cannot tell the columns",
            )
        words = [w for w in _SPLIT.split(col_line.lstrip("%").strip()) if w]
        system = words[0].upper()
        if system not in TIME_SYSTEMS:
            raise InputError(
                where,
                f"line {n_col}: unknown time system {words[0]!r} in the column header (known: "
                f"{', '.join(TIME_SYSTEMS)})",
            )
        names = [w.lower() for w in words[1:]]
        form = next(k for k, f in FORMS.items() if f[0][0] in names)
        value_names = []
        for name in names:
            value_names += [name] * (
                3 if form == "dms" and name.startswith(("latitude", "longitude")) else 1
            )
        if form == "dms" and "sdue(m)" in names:  # RTKLIB labels the d'" form's sdun "sdue"
            value_names = ["sdun(m)" if v == "sdue(m)" else v for v in value_names]
        missing = [c for c in FORMS[form][0] if c not in names]
        if missing:
            raise InputError(where, f"line {n_col}: the column header lacks {', '.join(missing)}")
        head = cls(n_col, system, names, value_names, form)
        head._facts(lines[:n_col], where)
        return head

    def _facts(self, header: list[str], where: str) -> None:
        """Datum, height kind, reference position and program from the header lines above the columns."""
        for n, line in enumerate(header, start=1):
            text = line.lstrip("%").strip()
            low = text.lower()
            if low.startswith("program"):
                self.program = text.partition(":")[2].strip()
            if "lat/lon/height=" in low:
                datum_height = low.split("lat/lon/height=")[1].split(",")[0]
                if "tokyo" in datum_height:
                    raise InputError(
                        where, f"line {n}: the Tokyo datum; gnssacc needs WGS84 positions"
                    )
                if "geodetic" in datum_height:
                    self.height_kind = "geodetic"
            if low.startswith("ref pos"):
                self.ref_llh = _ref_position(text.partition(":")[2], self.form, where, n)


def _ref_position(text: str, form: str, where: str, n: int) -> tuple:
    """``% ref pos :`` as (lat [rad], lon [rad], h [m]): lat lon h [deg, m], d m s d m s h, or x y z."""
    words = [w for w in _SPLIT.split(text.strip()) if w]
    try:
        v = [float(w) for w in words]
    except ValueError:
        raise InputError(
            where, f"line {n}: cannot read the reference position {text.strip()!r}"
        ) from None
    if len(v) == 7:
        return (_dms(words[0:3]) * DEG, _dms(words[3:6]) * DEG, v[6])
    if len(v) == 3 and form == "xyz":
        lat, lon, h = ecef_to_llh(np.array(v))
        return float(lat), float(lon), float(h)
    if len(v) == 3:
        return v[0] * DEG, v[1] * DEG, v[2]
    raise InputError(
        where, f"line {n}: the reference position {text.strip()!r} is not 3 or 7 numbers"
    )


def _dms(words) -> float:
    """Degrees from ``d m s`` fields, the sign on the degrees (``-0`` counts)."""
    d, m, s = (float(w) for w in words)
    sign = -1.0 if str(words[0]).strip().startswith("-") else 1.0
    return sign * (abs(d) + m / 60.0 + s / 3600.0)


def _data_rows(lines: list[str], head: _Header, where: str) -> tuple[list, list]:
    """The solution lines' fields (two time fields first) and line numbers; a truncated last line dropped."""
    expected = 2 + len(head.value_names)
    rows, numbers = [], []
    body = [
        (n, line.strip())
        for n, line in enumerate(lines, start=1)
        if n > head.line_no and line.strip() and not line.strip().startswith("%")
    ]
    for j, (n, text) in enumerate(body):
        words = [w for w in _SPLIT.split(text) if w]
        if len(words) != expected:
            if j == len(body) - 1 and len(words) < expected:
                warn_data(
                    where,
                    f"dropped the truncated last line {n} ({len(words)} of {expected} fields)",
                )
                break
            raise InputError(
                where,
                f"line {n} has {len(words)} fields, but the column header (line {head.line_no}) "
                f"gives {expected} (time: 2, {', '.join(head.names)})",
            )
        rows.append(words)
        numbers.append(n)
    if rows:
        head.time_format = "calendar" if "/" in rows[0][0] else "week"
    return rows, numbers


def _times(cells: np.ndarray, numbers: list, head: _Header, where: str) -> np.ndarray:
    """Seconds since 1970 on the file's time scale (GPST calendar dates kept on the GPST scale)."""
    out = np.empty(len(cells))
    for k, (a, b) in enumerate(cells):
        try:
            if head.time_format == "calendar":
                y, mo, d = (int(x) for x in a.split("/"))
                hh, mm, ss = b.split(":")
                y += (2000 if y < 80 else 1900) if y < 100 else 0
                out[k] = calendar_to_seconds(y, mo, d, int(hh), int(mm), float(ss))
            else:  # RTKLIB writes UTC and JST times as the week and time of week of that scale too
                week, tow = float(a), float(b)
                if not (0 <= week <= 9999 and 0 <= tow < SECONDS_PER_WEEK):
                    raise ValueError
                out[k] = week_tow_to_gps_seconds(week, tow) + GPS_EPOCH_UNIX
        except ValueError:
            form = (
                "yyyy/mm/dd hh:mm:ss.sss"
                if head.time_format == "calendar"
                else "GPS week and time of week"
            )
            raise InputError(
                where, f"line {numbers[k]}: cannot read the time {a} {b} (expected {form})"
            ) from None
    return out


def _numbers(cells: np.ndarray, numbers: list, where: str) -> np.ndarray:
    try:
        return cells.astype(float)
    except ValueError:
        for k, row in enumerate(cells):
            for word in row:
                try:
                    float(word)
                except ValueError:
                    raise InputError(
                        where, f"line {numbers[k]}: {word[:40]!r} is not a number"
                    ) from None
        raise


def _positions(values: np.ndarray, col: dict, head: _Header, where: str):
    """(lat, lon [rad], h [m], NED covariance (M, 3, 3) [m^2]) of the rows."""
    pos_names, sd_names, cross_names = FORMS[head.form]
    if head.form in ("llh", "dms"):
        if head.form == "llh":
            lat, lon = values[:, col[pos_names[0]]] * DEG, values[:, col[pos_names[1]]] * DEG
        else:
            k_lat, k_lon = col[pos_names[0]], col[pos_names[1]]  # the first of three fields each
            lat = _dms_columns(values[:, k_lat : k_lat + 3]) * DEG
            lon = _dms_columns(values[:, k_lon : k_lon + 3]) * DEG
        h = values[:, col[pos_names[2]]].copy()
    elif head.form == "xyz":
        lat, lon, h = ecef_to_llh(values[:, [col[c] for c in pos_names]])
    else:
        if head.ref_llh is None:
            raise InputError(
                where,
                "e/n/u-baseline solutions need the '% ref pos :' header line (the base position)",
            )
        enu = values[:, [col[c] for c in pos_names]]
        R_b = R_en_batch(np.array([head.ref_llh[0]]), np.array([head.ref_llh[1]]))[0]
        r_e = llh_to_ecef(*head.ref_llh) + (enu @ T_ENU_NED.T) @ R_b
        lat, lon, h = ecef_to_llh(r_e)
    cov = _file_covariance(values, col, sd_names, cross_names)
    return lat, lon, h, _to_ned(cov, head, lat, lon)


def _dms_columns(v: np.ndarray) -> np.ndarray:
    """Degrees of (d, m, s) rows (the sign on d; a "-0" degree field is lost as a number, but RTKLIB
    prints it only with a negative minute-second part, which then carries the sign)."""
    sign = np.where((v[:, 0] < 0) | ((v[:, 0] == 0) & np.signbit(v[:, 0])), -1.0, 1.0)
    return sign * (np.abs(v[:, 0]) + v[:, 1] / 60.0 + v[:, 2] / 3600.0)


def _file_covariance(values: np.ndarray, col: dict, sd_names, cross_names) -> np.ndarray:
    """The covariance in the file's own axes (ENU for llh/dms/enu, ECEF for xyz), (M, 3, 3) [m^2];
    zero where the file has no standard deviations. Cross terms are RTKLIB's signed roots
    ``sqvar``: ``c = sign(s) s^2``, axis pairs in :data:`CROSS_PAIRS`."""
    m = len(values)
    cov = np.zeros((m, 3, 3))
    if not all(c in col for c in sd_names):
        return cov
    sd = values[:, [col[c] for c in sd_names]]
    if sd_names[0] in ("sdn(m)", "sdvn"):  # llh/dms: sdn sde sdu -> E, N, U axes
        sd = sd[:, [1, 0, 2]]
    for i in range(3):
        cov[:, i, i] = sd[:, i] ** 2
    if all(c in col for c in cross_names):
        cross = values[:, [col[c] for c in cross_names]]
        signed = np.sign(cross) * cross**2
        for j, name in enumerate(cross_names):
            a, b = CROSS_PAIRS[name]
            cov[:, a, b] = cov[:, b, a] = signed[:, j]
    return cov


def _to_ned(cov: np.ndarray, head: _Header, lat: np.ndarray, lon: np.ndarray) -> np.ndarray:
    """The file's covariance rotated into the NED frame at each fix."""
    R_f = R_en_batch(lat, lon)  # ECEF -> NED at the fix
    if head.form == "xyz":
        return R_f @ cov @ R_f.transpose(0, 2, 1)
    ned = T_ENU_NED @ cov @ T_ENU_NED.T  # ENU -> NED axes
    if head.form != "enu":
        return ned  # already at the fix
    R_b = R_en_batch(np.array([head.ref_llh[0]]), np.array([head.ref_llh[1]]))[0]
    C = R_f @ R_b.T  # NED at the base -> NED at the fix
    return C @ ned @ C.transpose(0, 2, 1)


# --- writing -------------------------------------------------------------------------------------------


def write_pos(
    path,
    t_unix: np.ndarray,
    lat: np.ndarray,
    lon: np.ndarray,
    h: np.ndarray,
    cov_ned: np.ndarray,
    quality=None,
    n_sat=None,
    *,
    form: str = "llh",
    time_system: str = "GPST",
    time_format: str = "calendar",
    ref_llh=None,
    program: str = "gnssacc",
    vel_ned=None,
    vel_cov_ned=None,
) -> Path:
    """Write fixes as an RTKLIB ``.pos`` file, in RTKLIB's own layout and precision.

    Parameters
    ----------
    path : str or Path
    t_unix : ndarray
        Fix times, UNIX seconds (UTC) [s]; written in ``time_system`` to the millisecond.
    lat, lon : ndarray [rad]
    h : ndarray [m]
        Ellipsoidal height.
    cov_ned : ndarray, shape (M, 3, 3)
        NED covariance at each fix [m^2]; rotated into the form's axes.
    quality, n_sat : array of int, optional
        ``Q`` (default 5, single) and ``ns`` (default 8).
    form : {"llh", "xyz", "enu"}
    time_system : {"GPST", "UTC", "JST"}
    time_format : {"calendar", "week"}
    ref_llh : (lat [rad], lon [rad], h [m]), optional
        The base position of the ``enu`` form (default: the first fix).
    program : str
        Written as ``% program :``.
    vel_ned : ndarray, shape (M, 3), optional
        NED velocity at each fix [m/s]: written as RTKLIB's velocity columns (``outvel``: ``vn
        ve vu`` for llh, ``vx vy vz`` ECEF for xyz; RTKLIB has none for enu) to 0.01 mm/s. A NaN
        row is written as zeros (no velocity), a NaN axis with a zero standard deviation.
    vel_cov_ned : ndarray, shape (M, 3, 3), optional
        Its NED covariance [m^2/s^2] (NaN rows and columns of unmeasured axes are written as 0).

    Returns
    -------
    Path
    """
    m = len(t_unix)
    quality = np.full(m, 5) if quality is None else np.asarray(quality, int)
    n_sat = np.full(m, 8) if n_sat is None else np.asarray(n_sat, int)
    ref = (
        (float(lat[0]), float(lon[0]), float(h[0]))
        if ref_llh is None
        else tuple(float(v) for v in ref_llh)
    )
    lines = [f"% program   : {program}"]
    if form == "enu":
        lines.append(
            f"% ref pos   :{np.degrees(ref[0]):13.9f} {np.degrees(ref[1]):14.9f} {ref[2]:10.4f}"
        )
    lines.append("%")
    what = {
        "llh": "lat/lon/height=WGS84/ellipsoidal",
        "xyz": "x/y/z-ecef=WGS84",
        "enu": "e/n/u-baseline=WGS84",
    }[form]
    lines.append(f"% ({what},Q=1:fix,2:float,3:sbas,4:dgps,5:single,6:ppp,ns=# of satellites)")
    label = f"{time_system:<{(16 if time_format == 'calendar' else 8) + 3 + 1}} "
    pos_names, sd_names, cross_names = FORMS[form]
    widths = (14, 14, 10) if form == "llh" else (14, 14, 14)
    names = (
        "".join(f"{n:>{w}} " for n, w in zip(pos_names, widths))
        + f"{'Q':>3} {'ns':>3} "
        + " ".join(f"{n:>8}" for n in sd_names + cross_names)
        + f" {'age(s)':>6} {'ratio':>6}"
    )
    vel = None
    if vel_ned is not None:
        if form not in VEL_FORMS:
            raise ValueError(f"RTKLIB writes no velocity in the {form} form")
        if form == "xyz" and np.isnan(np.asarray(vel_ned, float)).any():
            raise ValueError("a velocity without all three axes has no ECEF (xyz) form")
        v_names, vsd_names, vcross_names = VEL_FORMS[form]
        names += (
            " "
            + " ".join(f"{n:>10}" for n in v_names)
            + f" {vsd_names[0]:>9} "
            + " ".join(f"{n:>8}" for n in vsd_names[1:] + vcross_names)
        )
        vel = _velocity_values(form, lat, lon, vel_ned, vel_cov_ned)
    lines.append(f"%  {label}{names}")
    stamps = _time_strings(np.asarray(t_unix, float), time_system, time_format)
    pos, sd, cross = _form_values(form, lat, lon, h, cov_ned, ref)
    for k in range(m):
        if form == "llh":
            p = f"{pos[k, 0]:14.9f} {pos[k, 1]:14.9f} {pos[k, 2]:10.4f}"
        else:
            p = f"{pos[k, 0]:14.4f} {pos[k, 1]:14.4f} {pos[k, 2]:14.4f}"
        lines.append(
            f"{stamps[k]} {p} {quality[k]:3d} {n_sat[k]:3d} "
            + " ".join(f"{v:8.4f}" for v in (*sd[k], *cross[k]))
            + f" {0.0:6.2f} {0.0:6.1f}"
            + ("" if vel is None else _velocity_fields(*(a[k] for a in vel)))
        )
    path = Path(path)
    path.write_text("\n".join(lines) + "\n")
    return path


def _velocity_values(form: str, lat, lon, vel_ned, vel_cov_ned):
    """Velocities, standard deviations and signed-root cross terms in the form's axes and order
    (NaN velocities and covariances written as zeros: "not given")."""
    v = np.nan_to_num(np.asarray(vel_ned, float))
    m = len(v)
    cov = np.zeros((m, 3, 3)) if vel_cov_ned is None else np.nan_to_num(vel_cov_ned)
    if form == "xyz":
        R_f = R_en_batch(lat, lon)
        v_f = np.einsum("kji,kj->ki", R_f, v)  # NED -> ECEF
        cov_f = R_f.transpose(0, 2, 1) @ cov @ R_f
        order, pairs = [0, 1, 2], [(0, 1), (1, 2), (2, 0)]
    else:
        v_f = v * np.array([1.0, 1.0, -1.0])  # vn ve vu
        cov_f = T_ENU_NED @ cov @ T_ENU_NED.T  # ENU
        order, pairs = [1, 0, 2], [(0, 1), (0, 2), (2, 1)]
    sd = np.sqrt(np.maximum(np.diagonal(cov_f, axis1=1, axis2=2), 0.0))[:, order]
    cross = np.column_stack([cov_f[:, a, b] for a, b in pairs])
    return v_f, sd, np.sign(cross) * np.sqrt(np.abs(cross))


def _velocity_fields(v, sd, cross) -> str:
    """RTKLIB's velocity fields (``outpos``: ``%10.5f`` x3, ``%9.5f``, ``%8.5f`` x5)."""
    return (
        " "
        + " ".join(f"{x:10.5f}" for x in v)
        + f" {sd[0]:9.5f} "
        + " ".join(f"{x:8.5f}" for x in (*sd[1:], *cross))
    )


def _time_strings(t_unix: np.ndarray, system: str, time_format: str) -> list[str]:
    """RTKLIB's time fields: ``yyyy/mm/dd hh:mm:ss.sss`` or ``wwww ssssss.sss`` on ``system``'s scale."""
    if system == "GPST":
        t_scale = unix_to_gps_seconds(t_unix)  # GPS seconds since 1980-01-06
    elif system == "UTC":
        t_scale = t_unix - GPS_EPOCH_UNIX  # seconds since 1980-01-06, UTC scale
    else:
        t_scale = t_unix + JST_OFFSET_S - GPS_EPOCH_UNIX
    ms = np.rint(t_scale * 1000.0).astype(np.int64)  # to the millisecond, as RTKLIB's timeu = 3
    out = []
    for v in ms:
        if time_format == "week":
            week, rest = divmod(int(v), 604_800_000)
            out.append(f"{week:4d} {rest / 1000.0:10.3f}")
        else:
            sec, milli = divmod(int(v), 1000)
            d = datetime.fromtimestamp(sec + GPS_EPOCH_UNIX, timezone.utc)
            out.append(f"{d:%Y/%m/%d %H:%M:%S}.{milli:03d}")
    return out


def _form_values(form: str, lat, lon, h, cov_ned, ref):
    """Positions, standard deviations and signed-root cross terms in the form's axes and order."""
    R_f = R_en_batch(lat, lon)
    if form == "llh":
        cov = T_ENU_NED @ cov_ned @ T_ENU_NED.T  # ENU at the fix
        pos = np.column_stack([np.degrees(lat), np.degrees(lon), h])
        order, pairs = [1, 0, 2], [(0, 1), (0, 2), (2, 1)]  # sdn sde sdu; ne eu un
    elif form == "xyz":
        cov = R_f.transpose(0, 2, 1) @ cov_ned @ R_f  # ECEF
        pos = llh_to_ecef(lat, lon, h)
        order, pairs = [0, 1, 2], [(0, 1), (1, 2), (2, 0)]
    else:
        R_b = R_en_batch(np.array([ref[0]]), np.array([ref[1]]))[0]
        C = R_b @ R_f.transpose(0, 2, 1)  # NED at fix -> at base
        cov = T_ENU_NED @ (C @ cov_ned @ C.transpose(0, 2, 1)) @ T_ENU_NED.T
        pos = ((llh_to_ecef(lat, lon, h) - llh_to_ecef(*ref)) @ R_b.T) @ T_ENU_NED.T
        order, pairs = [0, 1, 2], [(0, 1), (1, 2), (2, 0)]  # sde sdn sdu; en nu ue
    sd = np.sqrt(np.maximum(np.diagonal(cov, axis1=1, axis2=2), 0.0))[:, order]
    cross = np.column_stack([cov[:, a, b] for a, b in pairs])
    return pos, sd, np.sign(cross) * np.sqrt(np.abs(cross))
