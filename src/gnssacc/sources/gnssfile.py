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
    GnssVelocity,
    RecordedRun,
    check_increasing,
)
from .common import check_degrees, read_table
from .gnss_time import ABSOLUTE_CLOCK_MIN_S, place_on_clock
from .gnss_vel import (
    DEFAULT_VELOCITY_SIGMA_MPS,
    speed_course,
    velocity_from_covariance,
    velocity_from_speed_course,
    velocity_on_fixes,
)

POS_COLUMNS = ("t", "lat_deg", "lon_deg", "h_m")
SIGMA_COLUMNS = ("sn", "se", "sd")
CORR_COLUMNS = ("rho_ne", "rho_nd", "rho_ed")
QUALITY_COLUMN = "quality"
#: Optional velocity columns of ``gnss.csv``: north and east (together), down (with them).
VEL_H_COLUMNS = ("vn", "ve")
VEL_D_COLUMN = "vd"
VEL_SIGMA_H_COLUMNS = ("sigma_vn", "sigma_ve")
VEL_SIGMA_D_COLUMN = "sigma_vd"
VEL_CORR_COLUMNS = ("rho_vne", "rho_vnd", "rho_ved")
#: File kinds by suffix (anything else is recognised by its first line).
SUFFIXES = {".pos": "pos", ".nmea": "nmea", ".nma": "nmea", ".csv": "csv", ".ubx": "ubx"}
#: ``meta["gnss_format"]`` of each kind.
FORMAT_NAMES = {"pos": "rtklib-pos", "nmea": "nmea", "csv": "csv", "ubx": "ubx"}
#: A fix whose correlation matrix has a determinant below this is taken as uncorrelated.
MIN_CORRELATION_DET = 1e-6


def file_kind(path: Path) -> str:
    """``"pos"``, ``"nmea"``, ``"ubx"`` or ``"csv"``: by suffix, else by the first bytes (u-blox's
    sync characters ``0xB5 0x62``: UBX) or the first non-blank line (``%``: a ``.pos`` header,
    ``$``: NMEA, anything else: CSV)."""
    kind = SUFFIXES.get(path.suffix.lower())
    if kind:
        return kind
    try:
        with open(path, "rb") as fh:
            if b"\xb5\x62" in fh.read(4096):
                return "ubx"
            fh.seek(0)
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
    """The fixes of a GNSS file on the IMU's clock (:func:`load_gnss_data` without velocities)."""
    gnss, _, meta = load_gnss_data(path, cfg, imu_t)
    return gnss, meta


def load_gnss_data(
    path, cfg: RunConfig, imu_t: np.ndarray
) -> tuple[GnssFixes, GnssVelocity | None, dict]:
    """The fixes and velocities of a GNSS file on the IMU's clock, with ``[gnss] quality`` applied.

    Parameters
    ----------
    path : str or Path
        ``.csv`` (columns as ``gnss.csv``), ``.pos`` (RTKLIB), ``.nmea`` or ``.ubx`` (u-blox).
    cfg : RunConfig
        ``gnss.default_sigma_m``, ``gnss.quality``, ``gnss.nmea_uere_m``,
        ``gnss.nmea_vertical_factor``, ``data.max_bad_fraction``.
    imu_t : ndarray
        The IMU's time stamps [s] (the run's clock).

    Returns
    -------
    GnssFixes
    GnssVelocity or None
        The file's velocities on the fixes' clock (None when it has none); those of fixes that
        the quality policy drops are dropped with them.
    dict
        What was read: ``gnss_file``, ``gnss_format``, and for absolute times
        ``gnss_time_system`` and ``gnss_clock`` (``unix`` or ``gps``); the quality counts;
        ``gnss_velocity`` (how many, and whether their sigmas are stated) when there are any.
    """
    path = Path(path)
    where = str(path)
    if not path.exists():
        raise InputError(where, "GNSS file not found")
    kind = file_kind(path)
    meta: dict = {"gnss_file": where, "gnss_format": FORMAT_NAMES[kind]}
    if kind == "csv":
        gnss, vel = read_gnss_csv_file(
            path,
            cfg.default_sigma_ned,
            float(cfg["data"]["max_bad_fraction"]),
            cfg.default_velocity_sigma,
        )
    else:
        gnss, times, vel = _absolute_fixes(path, kind, cfg, meta)
        t, clock = place_on_clock(times, imu_t, where)
        meta.update(gnss_time_system=times.system, gnss_clock=clock)
        vel = velocity_on_fixes(vel, gnss.t, t)
        gnss = replace(gnss, t=t)
        check_increasing(gnss.t, where, "GNSS")
    kept, counts = apply_quality_policy(gnss, cfg["gnss"]["quality"], where)
    meta.update(counts)
    vel = velocities_of_kept_fixes(vel, gnss.t, kept.t)
    if vel is not None:
        meta["gnss_velocity"] = {"count": len(vel), "sigma_stated": bool(vel.sigma_stated)}
    return kept, vel, meta


def velocities_of_kept_fixes(vel: GnssVelocity | None, t_all, t_kept) -> GnssVelocity | None:
    """``vel`` without the velocities tagged at a fix that was dropped (same epoch, same
    receiver solution); velocities at no fix's time stay."""
    if vel is None or len(t_all) == len(t_kept):
        return vel
    dropped = np.setdiff1d(t_all, t_kept)
    keep = ~np.isin(vel.t, dropped)
    return vel if keep.all() else (vel.select(keep) if keep.any() else None)


def with_gnss_file(run: RecordedRun, path, cfg: RunConfig) -> RecordedRun:
    """``run`` with its fixes replaced by those of a GNSS file (``--gnss FILE``), on its IMU's clock.

    The run keeps its origin, truth, odometry and given initial state; its GNSS velocities
    become the file's (none when the file has none: they belong to the receiver that made the
    fixes); ``meta`` records the file (:func:`load_gnss_data`).
    """
    gnss, vel, meta = load_gnss_data(path, cfg, run.imu.t)
    if vel is None and run.gnss_vel is not None:
        warn_data(
            str(path),
            f"the file has no GNSS velocities: the source's {len(run.gnss_vel)} velocities are "
            "dropped with its fixes (they belong to the receiver that made those)",
        )
    return replace(run, gnss=gnss, gnss_vel=vel, meta={**run.meta, **meta}).validate()


def _absolute_fixes(path: Path, kind: str, cfg: RunConfig, meta: dict):
    """(fixes with times still absolute, FileTimes, velocities on the same times or None) of a
    .pos, NMEA or UBX file."""
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
        vel = None
        if pos.vel_ned is not None:
            vel = velocity_from_covariance(
                pos.times.t, pos.vel_ned, pos.vel_cov_ned, where, cfg.default_velocity_sigma
            )
        fixes = GnssFixes(pos.times.t, pos.lat, pos.lon, pos.h, sig, pos.quality, corr)
        return fixes, pos.times, vel
    if kind == "ubx":
        from .ubx import read_ubx

        ub = read_ubx(path, float(cfg["data"]["max_bad_fraction"]))
        meta["gnss_ubx_messages"] = ub.meta["messages"]
        return ub.fixes, ub.times, ub.velocity
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
    vel = velocity_from_speed_course(
        nm.times.t, nm.speed_mps, nm.course_deg, float(cfg.default_velocity_sigma[0])
    )
    fixes = GnssFixes(nm.times.t, nm.lat, nm.lon, nm.h, nm.sigma_ned, nm.quality, nm.corr_ned)
    return fixes, nm.times, vel


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
    vel: GnssVelocity | None = None,
    form: str = "llh",
    time_system: str = "GPST",
    time_format: str = "calendar",
) -> Path:
    """Write fixes held on a UNIX clock as an RTKLIB ``.pos`` (``kind="pos"``), an NMEA log
    (``kind="nmea"``) or a u-blox UBX log (``kind="ubx"``), with their velocities when given.

    ``vel``: the GNSS velocities (:attr:`RecordedRun.gnss_vel`), written at the fixes they share
    a time with: the ``.pos`` velocity columns, NMEA RMC/VTG speed and course, UBX NAV-PVT
    ``velN/velE/velD``. Without ``vel`` the NMEA speed and course come from ``truth.v_n`` at the
    fix epochs when given (as before velocities existed), and the other formats have none.
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
    v_fix, v_cov = velocity_at_fixes(vel, gnss.t)
    if kind == "ubx":
        from .ubx import write_ubx

        return write_ubx(path, gnss, v_fix, v_cov)
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
            vel_ned=v_fix,
            vel_cov_ned=v_cov,
        )
    from .nmea import write_nmea

    speed, course = _nmea_speed_course(gnss, v_fix, truth)
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
        vtg=v_fix is not None,
    )


def _nmea_speed_course(gnss: GnssFixes, v_fix, truth):
    """NMEA's speed [m/s] and course [deg] at the fixes: of the measured velocities, else none.
    Never the truth's: the reader takes RMC's speed as a measured velocity, and a truth written
    there would aid the estimators with the answer."""
    if v_fix is not None:
        return speed_course(v_fix)
    return None, None


#: Velocities within this of a fix's time are that fix's [s] (below every format's resolution).
SAME_EPOCH_S = 1e-4


def velocity_at_fixes(vel: GnssVelocity | None, t_fix: np.ndarray):
    """(NED velocity (M, 3) [m/s], NED covariance (M, 3, 3)) at each fix from the velocity with
    the same time tag (NaN rows where none), or (None, None) without velocities. Formats that
    write a velocity per fix record use it; velocities at no fix's time are counted in a
    warning (they cannot be written)."""
    if vel is None or len(vel) == 0:
        return None, None
    t_fix = np.asarray(t_fix, float)
    j = np.clip(np.searchsorted(vel.t, t_fix), 1, len(vel.t) - 1) if len(vel.t) > 1 else None
    if j is None:
        near = np.zeros(len(t_fix), int)
    else:
        near = np.where(np.abs(vel.t[j - 1] - t_fix) <= np.abs(vel.t[j] - t_fix), j - 1, j)
    hit = np.abs(vel.t[near] - t_fix) <= SAME_EPOCH_S
    if int(hit.sum()) < len(vel):
        warn_data(
            "GNSS velocity",
            f"{len(vel) - int(hit.sum())} of {len(vel)} velocities are at no fix's time: a format "
            f"with one record per fix cannot hold them (not written)",
        )
    v = np.full((len(t_fix), 3), np.nan)
    cov = np.full((len(t_fix), 3, 3), np.nan)
    v[hit] = vel.v_ned[near[hit]]
    cov[hit] = vel.cov_ned(near[hit])
    return v, cov


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


def read_gnss_csv_file(
    path: Path,
    default_sigma_ned: np.ndarray,
    max_bad: float,
    default_velocity_sigma: np.ndarray = DEFAULT_VELOCITY_SIGMA_MPS,
) -> tuple[GnssFixes, GnssVelocity | None]:
    """``gnss.csv``'s fixes (:func:`read_gnss_csv`) and its optional velocities
    (:func:`read_gnss_csv_velocity`; ``default_velocity_sigma`` [m/s]: ``[velocity]
    default_sigma_mps``)."""
    return read_gnss_csv(path, default_sigma_ned, max_bad), read_gnss_csv_velocity(
        path, default_velocity_sigma
    )


def read_gnss_csv_velocity(
    path: Path, default_sigma_ned: np.ndarray = DEFAULT_VELOCITY_SIGMA_MPS
) -> GnssVelocity | None:
    """The optional velocity columns of ``gnss.csv``, None without them.

    ``vn, ve`` [m/s] (together), ``vd`` [m/s] (with them; without it the velocities are
    horizontal), ``sigma_vn, sigma_ve`` and ``sigma_vd`` [m/s] (for the axes given, all or none:
    without them ``default_sigma_ned``, ``[velocity] default_sigma_mps``, not stated), and
    ``rho_vne, rho_vnd, rho_ved`` (correlations, with the sigmas). A row with an empty (or
    ``nan``) velocity cell has no velocity: only the fix is used.
    """
    import warnings

    from ..core.errors import DataWarning

    where = str(path)
    names = VEL_H_COLUMNS + (VEL_D_COLUMN,) + VEL_SIGMA_H_COLUMNS + (VEL_SIGMA_D_COLUMN,)
    with warnings.catch_warnings():  # rows without a velocity are dropped here, not warned
        warnings.simplefilter("ignore", DataWarning)
        tab = read_table(path, ("t",), names + VEL_CORR_COLUMNS, 1.0)
    found = [c for c in names + VEL_CORR_COLUMNS if c in tab]
    if not found:
        return None
    if not all(c in tab for c in VEL_H_COLUMNS):
        raise InputError(
            where, f"velocity columns {', '.join(found)} need vn and ve (north and east, m/s)"
        )
    axes = list(VEL_H_COLUMNS) + ([VEL_D_COLUMN] if VEL_D_COLUMN in tab else [])
    sig_names = list(VEL_SIGMA_H_COLUMNS) + ([VEL_SIGMA_D_COLUMN] if VEL_D_COLUMN in tab else [])
    k, n = len(axes), len(tab["t"])
    if n == 0:
        return None
    v = np.full((n, 3), np.nan)
    v[:, :k] = np.column_stack([tab[c] for c in axes])
    sig = np.full((n, 3), np.nan)
    given = optional_group(tab, sig_names, where)
    if given is None and any(c in tab for c in VEL_SIGMA_H_COLUMNS + (VEL_SIGMA_D_COLUMN,)):
        raise InputError(where, f"give the velocity sigmas {', '.join(sig_names)} or none")
    sig[:, :k] = np.tile(np.asarray(default_sigma_ned)[:k], (n, 1)) if given is None else given
    corr = optional_group(tab, VEL_CORR_COLUMNS, where)
    if corr is not None and (given is None or k < 3):
        raise InputError(
            where, "velocity correlations rho_vne, rho_vnd, rho_ved need vd and the sigma columns"
        )
    if np.any(sig[:, :k] <= 0):
        raise InputError(where, "velocity sigmas must be positive m/s")
    check_increasing(tab["t"], where, "GNSS velocity")
    return GnssVelocity(
        tab["t"].copy(), v, sig, None if corr is None else corr.copy(), given is not None
    )


def velocity_columns(g: GnssFixes, vel: GnssVelocity | None) -> tuple[list, list]:
    """``gnss.csv``'s velocity column names and columns for ``vel`` at the fixes (NaN where a fix
    has none); the down column only when some velocity measures it, the sigma columns unless
    every sigma is the unstated default."""
    v, cov = velocity_at_fixes(vel, g.t)
    if v is None:
        return [], []
    sig = np.sqrt(np.diagonal(cov, axis1=1, axis2=2))
    k = 3 if np.isfinite(v[:, 2]).any() else 2
    names = list(VEL_H_COLUMNS) + ([VEL_D_COLUMN] if k == 3 else [])
    cols = [v[:, i] for i in range(k)]
    s = sig[np.isfinite(sig[:, 0]), :k]
    default = not vel.sigma_stated and np.allclose(s, DEFAULT_VELOCITY_SIGMA_MPS[:k])
    if not default:
        names += list(VEL_SIGMA_H_COLUMNS) + ([VEL_SIGMA_D_COLUMN] if k == 3 else [])
        cols += [sig[:, i] for i in range(k)]
    if vel.corr_ned is not None and k == 3 and not default:
        hit = np.isfinite(v[:, 0])
        corr = np.full((len(g.t), 3), np.nan)
        corr[hit] = 0.0
        c = cov[hit]
        s3 = sig[hit]
        corr[hit] = np.column_stack(
            [
                c[:, 0, 1] / (s3[:, 0] * s3[:, 1]),
                c[:, 0, 2] / (s3[:, 0] * s3[:, 2]),
                c[:, 1, 2] / (s3[:, 1] * s3[:, 2]),
            ]
        )
        names += list(VEL_CORR_COLUMNS)
        cols += [corr[:, i] for i in range(3)]
    return names, cols
