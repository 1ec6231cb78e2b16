"""A file of GNSS fixes as a run's fixes: our ``gnss.csv``, an RTKLIB ``.pos``, an NMEA log.

Used for the GNSS of a CSV run directory (``gnss.csv``, ``gnss.pos`` or ``gnss.nmea``) and for
``--gnss FILE`` (``gnss=`` in the API), which replaces any source's fixes.

Clocks
    ``gnss.csv`` times are seconds on the run's clock (as the IMU's). ``.pos`` and NMEA times
    are absolute (GPST, UTC): they are put on the IMU's clock when that is absolute too (UNIX
    or GPS seconds, e.g. a bag's header stamps), and refused otherwise
    (:func:`gnssacc.sources.gnss_time.place_on_clock`).
Sigmas and quality
    The file's covariance (sigmas and correlations) is kept per fix; a fix with no sigma gets
    ``gnss.default_sigma_m``. ``[gnss] quality`` drops fixes of the named qualities or multiplies
    their sigmas (:func:`apply_quality_policy`).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from ..core.config import DEFAULTS, RunConfig
from ..core.config_check import QUALITY_NAMES
from ..core.errors import InputError, warn_data
from ..core.recording import (
    FIX_QUALITY,
    FIX_QUALITY_NAMES,
    GnssFixes,
    RecordedRun,
    check_increasing,
)
from .common import check_degrees, read_table
from .gnss_time import ABSOLUTE_CLOCK_MIN_S, place_on_clock

POS_COLUMNS = ("t", "lat_deg", "lon_deg", "h_m")
SIGMA_COLUMNS = ("sn", "se", "sd")
CORR_COLUMNS = ("rho_ne", "rho_nd", "rho_ed")
QUALITY_COLUMN = "quality"
#: File kinds by suffix (anything else is recognised by its first line).
SUFFIXES = {".pos": "pos", ".nmea": "nmea", ".nma": "nmea", ".csv": "csv"}
#: A fix whose correlation matrix has a determinant below this is taken as uncorrelated.
MIN_CORRELATION_DET = 1e-6


def file_kind(path: Path) -> str:
    """``"pos"``, ``"nmea"`` or ``"csv"``: by suffix, else by the first non-blank line (``%``: a
    ``.pos`` header, ``$``: NMEA, anything else: CSV)."""
    kind = SUFFIXES.get(path.suffix.lower())
    if kind:
        return kind
    try:
        with open(path, "rb") as fh:
            for raw in fh:
                text = raw.strip()
                if text:
                    return (
                        "pos" if text.startswith(b"%") else "nmea" if b"$" in text[:40] else "csv"
                    )
    except OSError:
        pass
    return "csv"


def load_gnss_file(path, cfg: RunConfig, imu_t: np.ndarray) -> tuple[GnssFixes, dict]:
    """The fixes of a GNSS file on the IMU's clock, with ``[gnss] quality`` applied.

    Parameters
    ----------
    path : str or Path
        ``.csv`` (columns as ``gnss.csv``), ``.pos`` (RTKLIB) or ``.nmea``.
    cfg : RunConfig
        ``gnss.default_sigma_m``, ``gnss.quality``, ``gnss.nmea_uere_m``,
        ``gnss.nmea_vertical_factor``, ``data.max_bad_fraction``.
    imu_t : ndarray
        The IMU's time stamps [s] (the run's clock).

    Returns
    -------
    GnssFixes
    dict
        What was read: ``gnss_file``, ``gnss_format``, and for absolute times
        ``gnss_time_system`` and ``gnss_clock`` (``unix`` or ``gps``); the quality counts.
    """
    path = Path(path)
    where = str(path)
    if not path.exists():
        raise InputError(where, "GNSS file not found")
    kind = file_kind(path)
    meta: dict = {
        "gnss_file": where,
        "gnss_format": {"pos": "rtklib-pos", "nmea": "nmea", "csv": "csv"}[kind],
    }
    if kind == "csv":
        gnss = read_gnss_csv(path, cfg.default_sigma_ned, float(cfg["data"]["max_bad_fraction"]))
    else:
        gnss, times = _absolute_fixes(path, kind, cfg, meta)
        t, clock = place_on_clock(times, imu_t, where)
        meta.update(gnss_time_system=times.system, gnss_clock=clock)
        gnss = GnssFixes(
            t,
            gnss.lat,
            gnss.lon,
            gnss.h,
            gnss.sigma_ned,
            gnss.quality,
            gnss.corr_ned,
            gnss.sigma_stated,
        )
        check_increasing(gnss.t, where, "GNSS")
    gnss, counts = apply_quality_policy(gnss, cfg["gnss"]["quality"], where)
    meta.update(counts)
    return gnss, meta


def with_gnss_file(run: RecordedRun, path, cfg: RunConfig) -> RecordedRun:
    """``run`` with its fixes replaced by those of a GNSS file (``--gnss FILE``), on its IMU's clock.

    The run keeps its origin, truth, odometry and given initial state; ``meta`` records the file
    (:func:`load_gnss_file`).
    """
    gnss, meta = load_gnss_file(path, cfg, run.imu.t)
    return replace(run, gnss=gnss, meta={**run.meta, **meta}).validate()


def _absolute_fixes(path: Path, kind: str, cfg: RunConfig, meta: dict):
    """(fixes with times still absolute, FileTimes) of a .pos or NMEA file."""
    where = str(path)
    if kind == "pos":
        from .rtklib import read_pos

        pos = read_pos(path)
        if pos.meta["height_kind"] == "geodetic":
            warn_data(
                where,
                "heights are geodetic (above the geoid, RTKLIB height=geodetic), used as ellipsoidal "
                "heights: vertical scores against an ellipsoidal truth are off by the geoid undulation",
            )
        meta["gnss_file_form"] = pos.meta["form"]
        sig, corr = sigmas_and_correlations(pos.cov_ned, cfg.default_sigma_ned, where, pos.times.t)
        return GnssFixes(pos.times.t, pos.lat, pos.lon, pos.h, sig, pos.quality, corr), pos.times
    from .nmea import read_nmea

    uere = uere_by_code(cfg["gnss"]["nmea_uere_m"])
    nm = read_nmea(
        path,
        uere,
        float(cfg["gnss"]["nmea_vertical_factor"]),
        cfg.default_sigma_ned,
        float(cfg["data"]["max_bad_fraction"]),
    )
    meta["gnss_sigma_from"] = nm.meta["sigma_from"]
    if nm.meta["sigma_from"]["hdop"]:
        warn_data(
            where,
            f"{nm.meta['sigma_from']['hdop']} fix(es) without GST: sigmas assumed from HDOP x UERE "
            f"([gnss] nmea_uere_m, nmea_vertical_factor), not measured",
        )
    return GnssFixes(
        nm.times.t, nm.lat, nm.lon, nm.h, nm.sigma_ned, nm.quality, nm.corr_ned
    ), nm.times


def uere_by_code(user: dict) -> dict[int, float]:
    """``[gnss] nmea_uere_m`` (names -> metres; names not given keep their defaults) by quality code."""
    merged = {**DEFAULTS["gnss"]["nmea_uere_m"], **(user or {})}
    return {FIX_QUALITY[name]: float(v) for name, v in merged.items()}


def sigmas_and_correlations(
    cov_ned: np.ndarray, default_sigma_ned: np.ndarray, where: str, t: np.ndarray
) -> tuple[np.ndarray, np.ndarray | None]:
    """Per-fix NED sigmas [m] and correlations ``(rho_ne, rho_nd, rho_ed)`` of covariances (M, 3, 3).

    A fix with a zero (or negative) variance gets ``default_sigma_ned`` and no correlation; a fix
    whose correlations are not positive definite (the file's rounding) keeps its sigmas without
    correlations. Each repair is counted in one warning. Returns None for the correlations when
    no fix has any.
    """
    var = np.diagonal(cov_ned, axis1=1, axis2=2)
    none = np.any(var <= 0.0, axis=1)
    sig = np.sqrt(np.where(var > 0.0, var, 1.0))
    sig[none] = default_sigma_ned
    corr = np.column_stack(
        [
            cov_ned[:, 0, 1] / (sig[:, 0] * sig[:, 1]),
            cov_ned[:, 0, 2] / (sig[:, 0] * sig[:, 2]),
            cov_ned[:, 1, 2] / (sig[:, 1] * sig[:, 2]),
        ]
    )
    corr[none] = 0.0
    r_ne, r_nd, r_ed = corr.T
    det = 1.0 + 2.0 * r_ne * r_nd * r_ed - r_ne**2 - r_nd**2 - r_ed**2
    bad = (det < MIN_CORRELATION_DET) & ~none
    corr[bad] = 0.0
    if none.any():
        k = int(np.flatnonzero(none)[0])
        warn_data(
            where,
            f"{int(none.sum())} fix(es) state no standard deviation (first at {t[k]:.3f} s): "
            f"gnss.default_sigma_m used",
        )
    if bad.any():
        warn_data(
            where,
            f"{int(bad.sum())} fix(es) have correlations that are not a valid covariance (rounding): "
            f"used without correlations",
        )
    return sig, (corr if np.any(corr != 0.0) else None)


def apply_quality_policy(gnss: GnssFixes, policy: dict, where: str) -> tuple[GnssFixes, dict]:
    """``[gnss] quality``: drop the fixes of qualities marked ``"drop"``, multiply the sigmas of
    those given a number. Fixes without a quality, or a policy naming none of theirs, pass as they are.

    Returns
    -------
    GnssFixes
    dict
        ``gnss_qualities``: the count of each quality read (by name), and what was done
        (``gnss_quality_dropped``, ``gnss_quality_inflated``: counts by name).
    """
    if gnss.quality is None:
        if policy:
            warn_data(where, "the fixes state no quality: [gnss] quality has nothing to act on")
        return gnss, {}
    names = np.array([FIX_QUALITY_NAMES.get(int(q), "unknown") for q in gnss.quality])
    found = {n: int(np.sum(names == n)) for n in QUALITY_NAMES if np.any(names == n)}
    out = {"gnss_qualities": found, "gnss_quality_dropped": {}, "gnss_quality_inflated": {}}
    keep = np.ones(len(gnss), bool)
    sigma = gnss.sigma_ned.copy()
    for name, rule in (policy or {}).items():
        hit = names == name
        if not hit.any():
            continue
        if rule == "drop":
            keep &= ~hit
            out["gnss_quality_dropped"][name] = int(hit.sum())
        else:
            sigma[hit] *= float(rule)
            out["gnss_quality_inflated"][name] = int(hit.sum())
    if not keep.any():
        raise InputError(
            where,
            f"[gnss] quality drops every fix (qualities found: "
            f"{', '.join(f'{k} {v}' for k, v in found.items())})",
        )
    if not keep.all():
        warn_data(
            where,
            f"[gnss] quality dropped {int((~keep).sum())} of {len(gnss)} fixes ("
            + ", ".join(f"{k} {v}" for k, v in out["gnss_quality_dropped"].items())
            + ")",
        )
    fixes = GnssFixes(
        gnss.t, gnss.lat, gnss.lon, gnss.h, sigma, gnss.quality, gnss.corr_ned, gnss.sigma_stated
    )
    return (fixes if keep.all() else fixes.select(keep)), out


def write_gnss_file(
    path,
    gnss: GnssFixes,
    kind: str,
    *,
    truth=None,
    form: str = "llh",
    time_system: str = "GPST",
    time_format: str = "calendar",
) -> Path:
    """Write fixes held on a UNIX clock as an RTKLIB ``.pos`` (``kind="pos"``) or an NMEA log
    (``kind="nmea"``; RMC's speed and course from ``truth.v_n`` at the fix epochs when given).

    ``form``, ``time_system``, ``time_format``: of the ``.pos`` (:func:`gnssacc.sources.rtklib.write_pos`).
    The NMEA HDOP is the one that gives the fixes' horizontal sigma with the default UERE of their
    quality (GST carries the sigmas themselves).

    Raises
    ------
    InputError
        The fixes' times are not UNIX seconds (an absolute file needs an absolute clock).
    """
    path = Path(path)
    if len(gnss) and gnss.t[0] < ABSOLUTE_CLOCK_MIN_S:
        raise InputError(
            str(path),
            f"the fixes' times ({gnss.t[0]:.3f} s ..) are not UNIX seconds: a .{kind} file "
            f"holds absolute times (simulate with t_start_s set to a UNIX time)",
        )
    cov = gnss.cov_ned(np.arange(len(gnss)))
    if kind == "pos":
        from .rtklib import write_pos

        return write_pos(
            path,
            gnss.t,
            gnss.lat,
            gnss.lon,
            gnss.h,
            cov,
            gnss.quality,
            form=form,
            time_system=time_system,
            time_format=time_format,
        )
    from .nmea import write_nmea

    speed = course = None
    if truth is not None and truth.v_n is not None:
        v = np.column_stack([np.interp(gnss.t, truth.t, truth.v_n[:, i]) for i in range(3)])
        speed, course = np.hypot(v[:, 0], v[:, 1]), np.degrees(np.arctan2(v[:, 1], v[:, 0]))
    return write_nmea(
        path,
        gnss.t,
        gnss.lat,
        gnss.lon,
        gnss.h,
        gnss.sigma_ned,
        gnss.corr_ned,
        gnss.quality,
        uere_m=uere_by_code({}),
        vertical_factor=float(DEFAULTS["gnss"]["nmea_vertical_factor"]),
        speed_mps=speed,
        course_deg=course,
    )


# --- gnss.csv --------------------------------------------------------------------------------------------


def read_positions(path: Path, what: str, optional, max_bad: float) -> dict:
    """The columns of a position table (``gnss.csv``, ``truth.csv``): time order and degree ranges checked."""
    tab = read_table(path, POS_COLUMNS, optional, max_bad)
    check_increasing(tab["t"], str(path), what)
    check_degrees(tab["lat_deg"], tab["lon_deg"], tab["t"], str(path), what)
    return tab


def optional_group(tab: dict, names, where: str) -> np.ndarray | None:
    """The (rows, k) block of an all-or-none column group, or None when absent."""
    found = [c for c in names if c in tab]
    if not found:
        return None
    if len(found) != len(names):
        raise InputError(
            where,
            f"give all of the columns {', '.join(names)} or none (found only {', '.join(found)})",
        )
    return np.column_stack([tab[c] for c in names])


def read_gnss_csv(path: Path, default_sigma_ned: np.ndarray, max_bad: float) -> GnssFixes:
    """``gnss.csv``: ``t, lat_deg, lon_deg, h_m``, optional ``sn, se, sd`` [m], ``rho_ne, rho_nd,
    rho_ed`` (correlations, with the sigmas) and ``quality`` (:data:`FIX_QUALITY` code)."""
    where = str(path)
    tab = read_positions(path, "GNSS", SIGMA_COLUMNS + CORR_COLUMNS + (QUALITY_COLUMN,), max_bad)
    n = len(tab["t"])
    if n == 0:
        raise InputError(where, "no GNSS fix row at all: at least one fix is needed to initialise")
    sigma_ned = optional_group(tab, SIGMA_COLUMNS, where)
    if sigma_ned is None:
        sigma_ned = np.tile(default_sigma_ned, (n, 1))
    bad = np.flatnonzero(np.any(sigma_ned <= 0, axis=1))
    if bad.size:
        k = int(bad[0])
        raise InputError(
            where,
            f"sigmas sn, se, sd must be positive metres; not so at t = {tab['t'][k]:.6f} s "
            f"({bad.size} row(s))",
        )
    corr = optional_group(tab, CORR_COLUMNS, where)
    if corr is not None and "sn" not in tab:
        raise InputError(
            where, "correlation columns rho_ne, rho_nd, rho_ed need the sigma columns sn, se, sd"
        )
    quality = None
    if QUALITY_COLUMN in tab:
        q = tab[QUALITY_COLUMN]
        if np.any(q != np.rint(q)) or np.any((q < 0) | (q > max(FIX_QUALITY.values()))):
            raise InputError(
                where,
                f"column quality holds codes 0..{max(FIX_QUALITY.values())} "
                f"({', '.join(f'{v} {k}' for k, v in FIX_QUALITY.items())})",
            )
        quality = q.astype(int)
    return GnssFixes(
        tab["t"].copy(),
        tab["lat_deg"] * np.pi / 180.0,
        tab["lon_deg"] * np.pi / 180.0,
        tab["h_m"].copy(),
        sigma_ned,
        quality,
        None if corr is None else corr.copy(),
        sigma_stated="sn" in tab,
    )
