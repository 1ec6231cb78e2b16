"""CSV run directory: the documented user format for recorded runs.

A run directory holds

``imu.csv`` (required)
    Columns ``t, ax, ay, az, gx, gy, gz``: time [s], specific force [m/s^2], angular rate
    [rad/s], in the IMU axes, Front-Right-Down unless the loader is told ``imu_frame="flu"``
    (Front-Left-Up; converted by negating y and z). ``[mounting]`` in the config then rotates
    the IMU axes into the body frame and shifts the IMU time stamps onto the GNSS clock.
``gnss.csv``, or ``gnss.pos``, ``gnss.nmea`` or ``gnss.ubx`` (exactly one of them)
    ``gnss.csv``: columns ``t, lat_deg, lon_deg, h_m`` and optionally ``sn, se, sd``: the 1-sigma
    north, east, down position uncertainty [m] (all three or none; without them
    ``gnss.default_sigma_m``), ``rho_ne, rho_nd, rho_ed``: the correlations of those errors
    (with the sigmas), and ``quality``: the fix quality code (1 fix, 2 float, 3 sbas, 4 dgps,
    5 single, 6 ppp, 7 estimated, 0 unknown); optionally the GNSS velocity ``vn, ve[, vd]``
    [m/s] with ``sigma_vn, sigma_ve[, sigma_vd]`` and ``rho_vne, rho_vnd, rho_ved``
    (:func:`gnssacc.sources.gnssfile.read_gnss_csv_velocity`). ``gnss.pos``: an RTKLIB solution
    file (:mod:`gnssacc.sources.rtklib`); ``gnss.nmea``: an NMEA 0183 log
    (:mod:`gnssacc.sources.nmea`); ``gnss.ubx``: a u-blox UBX log (:mod:`gnssacc.sources.ubx`):
    their times are absolute (GPST, UTC), so ``imu.csv`` must then be stamped in UNIX (UTC) or GPS
    seconds (:mod:`gnssacc.sources.gnssfile`). Their velocities become ``run.gnss_vel``.
``odom.csv`` (optional)
    Wheel odometry: columns ``t, v_forward`` and optionally ``yaw_rate``, ``sigma_v``,
    ``sigma_yaw_rate``: time [s] on the IMU's clock (shifted with it by ``[mounting]
    imu_time_offset_s``), the vehicle's forward speed [m/s] (negative reversing), its turn rate
    about the vehicle's down axis [rad/s] (positive turning right, clockwise seen from above:
    the negative of ROS's ``angular.z``), and their per-sample 1-sigma.
``truth.csv`` (optional)
    Columns ``t, lat_deg, lon_deg, h_m``, optionally ``vn, ve, vd`` [m/s] and
    ``roll_deg, pitch_deg, yaw_deg`` (each group all or none); time [s] on the IMU's clock (a
    logger stamps it beside the IMU: it is shifted with the IMU by ``[mounting]
    imu_time_offset_s`` and by a measured offset). It may span less than the run: the outputs
    still cover the whole run, the scores only the truth's span (with a warning). A truth that
    disagrees with the fixes is not scored (:mod:`gnssacc.checks.truthcheck`).
``true_bias.csv`` (optional, written by ``gnssacc sim``)
    A simulated run's true IMU biases, one row per IMU sample: columns ``t, bax, bay, baz, bgx,
    bgy, bgz`` (time [s] on the IMU's clock, accelerometer bias [m/s^2], gyro bias [rad/s], IMU
    axes); read back as ``run.sim`` (:mod:`gnssacc.sources.true_bias_file`) for the bias figures.
``init.json`` (optional)
    ``{"t", "lat_deg", "lon_deg", "h_m", "vn", "ve", "vd", "roll_deg", "pitch_deg", "yaw_deg",
    "sigma": {"pos_m", "vel_mps", "roll_pitch_deg", "yaw_deg"}}``. ``sigma`` and each of its keys
    are optional (defaults: the first fix's GNSS sigma, 0.5 m/s, 2 deg, 5 deg); ``pos_m`` and
    ``vel_mps`` take a number or N, E, D values, ``roll_pitch_deg`` a number or [roll, pitch].
    ``t`` must lie in the run: not after the last IMU sample, nor more than
    :data:`INIT_BEFORE_START_TOLERANCE_S` before the first.

In every CSV file header names are case-insensitive, column order is free, extra columns are
ignored, and lines starting with ``#`` are comments. All times are seconds; GNSS and init
times are on the GNSS clock, IMU, odometry and truth times on the IMU's.
"""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np

from ..core.config import DEG, RunConfig
from ..core.earth import LocalTangentFrame
from ..core.errors import InputError
from ..core.memory import release_free_memory
from ..core.recording import (
    ImuData,
    InitialState,
    RecordedRun,
    Truth,
    WheelOdometry,
    check_increasing,
)
from ..core.rotations import flu_to_frd
from .common import apply_mounting, check_degrees, configured_time_offset_s, read_table
from .true_bias_file import FILE as BIAS_FILE
from .true_bias_file import read_true_bias, write_true_bias
from .gnssfile import (
    CORR_COLUMNS,
    POS_COLUMNS,
    QUALITY_COLUMN,
    SIGMA_COLUMNS,
    apply_quality_policy,
    load_gnss_data,
    optional_group,
    read_gnss_csv_file,
    read_positions,
    velocities_of_kept_fixes,
    velocity_columns,
    write_gnss_file,
)

IMU_COLUMNS = ("t", "ax", "ay", "az", "gx", "gy", "gz")
GNSS_FILES = ("gnss.csv", "gnss.pos", "gnss.nmea", "gnss.ubx")
ODOM_COLUMNS = ("t", "v_forward")
ODOM_OPTIONAL = ("yaw_rate", "sigma_v", "sigma_yaw_rate")
VEL_COLUMNS = ("vn", "ve", "vd")
RPY_COLUMNS = ("roll_deg", "pitch_deg", "yaw_deg")
INIT_KEYS = ("t", "lat_deg", "lon_deg", "h_m", "vn", "ve", "vd", "roll_deg", "pitch_deg", "yaw_deg")
SIGMA_KEYS = ("pos_m", "vel_mps", "roll_pitch_deg", "yaw_deg")
#: init.json sigma defaults (the position default is the first fix's GNSS sigma).
DEFAULT_SIGMA_VEL_MPS = 0.5
DEFAULT_SIGMA_ROLL_PITCH_DEG = 2.0
DEFAULT_SIGMA_YAW_DEG = 5.0
IMU_FRAMES = ("frd", "flu")
#: How far before the first IMU sample init.json's time may be (a state taken at the first fix) [s].
INIT_BEFORE_START_TOLERANCE_S = 1.0


# --- reading ------------------------------------------------------------------------------------------


def load_csv_run(path, cfg: RunConfig, imu_frame: str = "frd", time_units=None) -> RecordedRun:
    """Load a CSV run directory (format in the module docstring).

    Parameters
    ----------
    path : str or Path
        The run directory.
    cfg : RunConfig
        Uses ``[mounting]``, ``gnss.default_sigma_m`` and ``data.max_bad_fraction``.
    imu_frame : {"frd", "flu"}
        Axes convention of ``imu.csv``; FLU samples are converted to FRD (y -> -y, z -> -z)
        before the mounting rotation is applied.
    time_units : callable, optional
        ``time_units(imu, t_gnss, where, cfg) -> ImuData``: IMU stamps in other units than
        seconds found (and rescaled, or named in an error) before the configured time offset is
        added and before the IMU and the fixes are compared (the input checks'
        :func:`gnssacc.checks.plausibility.fix_imu_time_units`, handed in by the pipeline: a
        source only reads). Omitted: the stamps are taken as seconds.

    Returns
    -------
    RecordedRun
        Validated; ``name`` is the directory name, ``where`` the directory path, ``origin`` the
        tangent plane at the first GNSS fix.

    Raises
    ------
    InputError
        Naming the file and the problem (missing file or column, non-numeric cell, time not
        increasing, no GNSS fix, degrees out of range, too many NaN rows, bad init.json ...).
    """
    root = Path(path)
    where = str(root)
    frame = _checked_directory(root, imu_frame)
    gnss_file = _gnss_file(root)
    max_bad = float(cfg["data"]["max_bad_fraction"])
    imu = _read_imu(root / "imu.csv", frame, max_bad)
    imu_unshifted_t = imu.t
    meta = {"source": "csv", "imu_frame": frame}
    imu, gnss, gnss_vel = _imu_and_fixes(root, gnss_file, imu, cfg, max_bad, meta, time_units)
    offset_s = configured_time_offset_s(cfg)  # what puts the IMU's clock on the fixes'
    truth = (
        _shifted_truth(_read_truth(root / "truth.csv", max_bad), offset_s)
        if (root / "truth.csv").exists()
        else None
    )
    init = (
        _read_init(root / "init.json", gnss.sigma_ned[0]) if (root / "init.json").exists() else None
    )
    if init is not None:
        check_init_time(init.t, imu.t[0], imu.t[-1], str(root / "init.json"))
    odometry = None
    if (root / "odom.csv").exists():
        odometry = read_odometry_csv(root / "odom.csv", max_bad).shifted(offset_s)
    sim = None
    if (root / BIAS_FILE).exists():  # before the IMU's clock is shifted: the file is on it
        sim = read_true_bias(root / BIAS_FILE, imu_unshifted_t, max_bad)
    run = RecordedRun(
        name=root.resolve().name,
        where=where,
        imu=imu,
        gnss=gnss,
        origin=LocalTangentFrame(gnss.lat[0], gnss.lon[0], gnss.h[0]),
        truth=truth,
        init=init,
        meta=meta,
        odometry=odometry,
        truth_on_imu_clock=True,
        gnss_vel=gnss_vel,
        sim=sim,
    )
    release_free_memory()  # the parser's blocks
    return run.validate()


def _checked_directory(root: Path, imu_frame: str) -> str:
    """The IMU axes (``"frd"`` or ``"flu"``) once ``root`` is known to be a directory holding an
    ``imu.csv`` file; an :class:`InputError` naming the option or file otherwise."""
    where = str(root)
    frame = str(imu_frame).lower()
    if frame not in IMU_FRAMES:
        raise InputError(
            where, f"imu_frame must be one of {', '.join(IMU_FRAMES)}, got {imu_frame!r}"
        )
    if not root.exists():
        raise InputError(where, "run directory not found")
    if not root.is_dir():
        raise InputError(
            where, "not a directory: a CSV run is a directory holding imu.csv and gnss.csv"
        )
    if (root / "imu.csv").is_dir():
        raise InputError(str(root / "imu.csv"), "is a directory, expected a CSV file")
    if not (root / "imu.csv").is_file():
        raise InputError(str(root / "imu.csv"), "file not found: a CSV run directory needs imu.csv")
    return frame


def _imu_and_fixes(
    root: Path,
    gnss_file: Path,
    imu: ImuData,
    cfg: RunConfig,
    max_bad: float,
    meta: dict,
    time_units,
):
    """(IMU in body axes, fixes, velocities or None) of a run directory: the fixes of its one GNSS
    file ``gnss_file``, IMU stamps in other units than seconds found by ``time_units``
    (``gnss.csv``: relative times) and the ``[mounting]`` applied; absolute fix times put on the
    IMU's clock."""
    if gnss_file.name == "gnss.csv":
        read_fixes, gnss_vel = read_gnss_csv_file(
            gnss_file, cfg.default_sigma_ned, max_bad, cfg.default_velocity_sigma
        )
        gnss, _ = apply_quality_policy(read_fixes, cfg["gnss"]["quality"], str(gnss_file))
        gnss_vel = velocities_of_kept_fixes(gnss_vel, read_fixes.t, gnss.t)
        # Stamps in ms/us/ns would never meet the fixes: found (and rescaled, or named) before the
        # overlap check, which could only say "different clocks?".
        if time_units is not None:
            imu = _rescaled(imu, time_units(imu, gnss.t, str(root / "imu.csv"), cfg), root, meta)
        imu = apply_mounting(imu, cfg)
    else:  # absolute fix times are put on the IMU's clock, which must be absolute too
        imu = apply_mounting(imu, cfg)
        gnss, gnss_vel, read = load_gnss_data(gnss_file, cfg, imu.t)
        meta.update(read)
    return imu, gnss, gnss_vel


def _rescaled(imu: ImuData, scaled: ImuData, root: Path, meta: dict) -> ImuData:
    """``scaled``; when it is not ``imu`` (stamps not in seconds, rescaled as they were read), the
    repair recorded in ``meta["repaired_on_load"]`` as an input check's finding would say it."""
    if scaled is not imu:
        k = float(np.median(np.diff(imu.t)) / np.median(np.diff(scaled.t)))
        meta["repaired_on_load"] = [
            {
                "check": "time_units",
                "where": str(root / "imu.csv"),
                "problem": "the IMU stamps are not seconds: as given the IMU never meets the fixes",
                "fix": f"divide the t column by {k:.6g}",
                "correction": f"divided the IMU time stamps by {k:.6g}",
                "action": "repaired",
                "details": {"evidence": "one unit alone puts the IMU on the fixes' time span"},
            }
        ]
    return scaled


def _gnss_file(root: Path) -> Path:
    """The one GNSS file of a run directory (:data:`GNSS_FILES`)."""
    found = [root / n for n in GNSS_FILES if (root / n).exists()]
    if not found:
        raise InputError(
            str(root / "gnss.csv"),
            "file not found: a CSV run directory needs gnss.csv (or gnss.pos, "
            "an RTKLIB solution, or gnss.nmea, an NMEA log)",
        )
    if len(found) > 1:
        raise InputError(
            str(root),
            f"holds {' and '.join(p.name for p in found)}: keep one GNSS file (or choose "
            f"with --gnss FILE)",
        )
    if found[0].is_dir():
        raise InputError(str(found[0]), "is a directory, expected a file of GNSS fixes")
    return found[0]


def read_odometry_csv(path: Path, max_bad: float) -> WheelOdometry:
    """``odom.csv`` (module docstring) -> :class:`WheelOdometry` on the IMU's clock as written."""
    where = str(path)
    tab = read_table(path, ODOM_COLUMNS, ODOM_OPTIONAL, max_bad)
    if len(tab["t"]) < 2:
        raise InputError(where, f"{len(tab['t'])} data row(s): need at least two odometry samples")
    check_increasing(tab["t"], where, "odometry")

    def column(name):
        return tab[name].copy() if name in tab else None

    for name in ("sigma_v", "sigma_yaw_rate"):
        if name in tab and np.any(tab[name] <= 0):
            k = int(np.flatnonzero(tab[name] <= 0)[0])
            raise InputError(where, f"{name} must be positive; not so at t = {tab['t'][k]:.6f} s")
    if "sigma_yaw_rate" in tab and "yaw_rate" not in tab:
        raise InputError(where, "sigma_yaw_rate needs the yaw_rate column")
    return WheelOdometry(
        tab["t"].copy(),
        tab["v_forward"].copy(),
        column("yaw_rate"),
        column("sigma_v"),
        column("sigma_yaw_rate"),
        frame=path.name,
    )


def check_init_time(t: float, t_start: float, t_end: float, where: str) -> None:
    """Raise :class:`InputError` unless the initial time lies in the run: not after its last IMU
    sample, nor more than :data:`INIT_BEFORE_START_TOLERANCE_S` before its first."""
    span = f"the run's IMU data span t = {t_start:.3f} .. {t_end:.3f} s"
    if t > t_end:
        raise InputError(where, f"time t = {t:.3f} s is after the run's end: {span}")
    if t < t_start - INIT_BEFORE_START_TOLERANCE_S:
        raise InputError(
            where,
            f"time t = {t:.3f} s is {t_start - t:.3f} s before the run's start "
            f"(tolerance {INIT_BEFORE_START_TOLERANCE_S:g} s): {span}",
        )


def _columns(tab: dict, names) -> np.ndarray:
    return np.column_stack([tab[c] for c in names])


def _read_imu(path: Path, frame: str, max_bad: float) -> ImuData:
    """imu.csv -> ImuData in FRD-labelled IMU axes on the IMU clock (mounting not yet applied)."""
    tab = read_table(path, IMU_COLUMNS, (), max_bad)
    if len(tab["t"]) < 2:
        raise InputError(str(path), f"{len(tab['t'])} data row(s): need at least two IMU samples")
    check_increasing(tab["t"], str(path), "IMU")
    f_imu = _columns(tab, IMU_COLUMNS[1:4])
    omega_imu = _columns(tab, IMU_COLUMNS[4:7])
    if frame == "flu":
        f_imu, omega_imu = flu_to_frd(f_imu), flu_to_frd(omega_imu)
    # A copy of the time column: a view would keep the whole parsed table alive with the run.
    return ImuData(tab["t"].copy(), f_imu, omega_imu)


def _shifted_truth(truth: Truth, offset_s: float) -> Truth:
    """The truth with ``offset_s`` [s] added to its stamps (it is on the IMU's clock)."""
    return replace(truth, t=truth.t + offset_s) if offset_s else truth


def _read_truth(path: Path, max_bad: float) -> Truth:
    tab = read_positions(path, "truth", VEL_COLUMNS + RPY_COLUMNS, max_bad)
    if len(tab["t"]) == 0:
        raise InputError(str(path), "no data rows (delete the file if there is no truth)")
    v_n = optional_group(tab, VEL_COLUMNS, str(path))
    rpy_deg = optional_group(tab, RPY_COLUMNS, str(path))
    return Truth(
        tab["t"],
        tab["lat_deg"] * DEG,
        tab["lon_deg"] * DEG,
        tab["h_m"],
        v_n,
        None if rpy_deg is None else rpy_deg * DEG,
    )


def _json_number(value, key: str, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise InputError(where, f"'{key}' must be a finite number, got {value!r}")
    return float(value)


def _json_vector(value, key: str, size: int, where: str) -> np.ndarray:
    """A number (same on all axes) or a list of ``size`` numbers, all positive."""
    items = value if isinstance(value, list) else [value]
    if len(items) not in (1, size):
        raise InputError(
            where, f"'{key}' must be a number or a list of {size} numbers, got {value!r}"
        )
    arr = np.array([_json_number(v, key, where) for v in items])
    if np.any(arr <= 0):
        raise InputError(where, f"'{key}' must be positive, got {value!r}")
    return np.resize(arr, size)


def _check_keys(obj, allowed, required, where: str, what: str) -> None:
    if not isinstance(obj, dict):
        raise InputError(where, f"{what} must be a JSON object {{...}}")
    unknown = [k for k in obj if k not in allowed]
    if unknown:
        raise InputError(
            where, f"unknown key(s) {', '.join(unknown)} in {what} (known: {', '.join(allowed)})"
        )
    missing = [k for k in required if k not in obj]
    if missing:
        raise InputError(where, f"missing key(s) {', '.join(missing)} in {what}")


def _read_init(path: Path, first_fix_sigma_ned: np.ndarray) -> InitialState:
    where = str(path)
    try:
        doc = json.loads(path.read_text(encoding="utf-8-sig"))
    except json.JSONDecodeError as exc:
        raise InputError(where, f"not valid JSON: {exc.msg} at line {exc.lineno}") from None
    except UnicodeDecodeError:
        raise InputError(where, "not a UTF-8 text file") from None
    _check_keys(doc, INIT_KEYS + ("sigma",), INIT_KEYS, where, "init.json")
    v = {k: _json_number(doc[k], k, where) for k in INIT_KEYS}
    check_degrees(
        np.array([v["lat_deg"]]), np.array([v["lon_deg"]]), np.array([v["t"]]), where, "initial"
    )
    sig = doc.get("sigma", {})
    _check_keys(sig, SIGMA_KEYS, (), where, "init.json 'sigma'")
    pos = (
        _json_vector(sig["pos_m"], "sigma.pos_m", 3, where)
        if "pos_m" in sig
        else first_fix_sigma_ned.copy()
    )
    vel = _json_vector(sig.get("vel_mps", DEFAULT_SIGMA_VEL_MPS), "sigma.vel_mps", 3, where)
    roll_pitch = _json_vector(
        sig.get("roll_pitch_deg", DEFAULT_SIGMA_ROLL_PITCH_DEG), "sigma.roll_pitch_deg", 2, where
    )
    yaw = _json_vector(sig.get("yaw_deg", DEFAULT_SIGMA_YAW_DEG), "sigma.yaw_deg", 1, where)
    return InitialState(
        t=v["t"],
        lat=v["lat_deg"] * DEG,
        lon=v["lon_deg"] * DEG,
        h=v["h_m"],
        v_n=np.array([v["vn"], v["ve"], v["vd"]]),
        rpy=np.array([v["roll_deg"], v["pitch_deg"], v["yaw_deg"]]) * DEG,
        sigma_pos_m=pos,
        sigma_vel_mps=vel,
        # n-frame attitude-error sigma: [roll_pitch, roll_pitch, yaw] as the
        # level errors are taken equal to the roll/pitch sigmas.
        sigma_att_rad=np.concatenate([roll_pitch, yaw]) * DEG,
        how=f"given in {path.name}",
    )


# --- writing ------------------------------------------------------------------------------------------


def _write_table(path: Path, names, columns, comment: str) -> None:
    table = np.column_stack([np.asarray(c, float) for c in columns])
    # %.17g round-trips every float64 exactly.
    np.savetxt(
        path,
        table,
        fmt="%.17g",
        delimiter=",",
        header=f"{comment}\n" + ",".join(names),
        comments="",
    )


def write_csv_run(run: RecordedRun, path, gnss_format: str = "csv") -> Path:
    """Write a run as a CSV run directory (imu, gnss, truth, odom.csv and init.json when present).

    The IMU samples are written as they are held, i.e. in the body frame (FRD) on the GNSS
    clock; load the directory with an identity mounting and zero time offset to get the same
    run back. Angles are written in degrees with full float precision.

    Parameters
    ----------
    run : RecordedRun
    path : str or Path
        The directory; created if needed, existing files of the format are overwritten.
    gnss_format : {"csv", "pos", "nmea", "ubx"}
        The fixes (and ``run.gnss_vel``) as ``gnss.csv`` (full precision), or as ``gnss.pos``
        (RTKLIB, GPST), ``gnss.nmea`` (NMEA 0183) or ``gnss.ubx`` (u-blox NAV-PVT) in those
        formats' precision; the latter three need the run's times in UNIX seconds.

    Returns
    -------
    Path
        The directory.
    """
    root = Path(path)
    root.mkdir(parents=True, exist_ok=True)
    src = f"# gnssacc CSV run '{run.name}' written from {run.where}"
    imu = run.imu
    _write_table(
        root / "imu.csv",
        IMU_COLUMNS,
        [imu.t, *imu.f_b.T, *imu.omega_ib_b.T],
        f"{src}\n# body frame FRD; t [s], specific force [m/s^2], angular rate [rad/s]",
    )
    for stale in ("truth.csv", "init.json", "odom.csv", BIAS_FILE) + GNSS_FILES:
        (root / stale).unlink(missing_ok=True)
    if gnss_format == "csv":
        write_gnss_csv(root / "gnss.csv", run.gnss, src, vel=run.gnss_vel)
    else:
        write_gnss_file(
            root / f"gnss.{gnss_format}",
            run.gnss,
            gnss_format,
            truth=run.truth,
            vel=run.gnss_vel,
        )
    if run.odometry is not None:
        write_odometry_csv(root / "odom.csv", run.odometry, src)
    if run.truth is not None:
        _write_truth(root / "truth.csv", run.truth, src)
    if run.init is not None:
        _write_init(root / "init.json", run.init)
    if run.sim is not None and run.sim.bias is not None and len(run.sim.bias) == len(imu.t):
        write_true_bias(root / BIAS_FILE, imu.t, run.sim.bias, src)
    return root


def write_gnss_csv(path: Path, g, src: str = "# gnssacc GNSS fixes", vel=None) -> None:
    """Fixes as ``gnss.csv`` (with the correlations and quality codes when they have them, and
    the velocities ``vel`` at the fixes with the same time tag:
    :func:`gnssacc.sources.gnssfile.velocity_columns`)."""
    names = list(POS_COLUMNS + SIGMA_COLUMNS)
    cols = [g.t, np.degrees(g.lat), np.degrees(g.lon), g.h, *g.sigma_ned.T]
    if g.corr_ned is not None:
        names += CORR_COLUMNS
        cols += list(np.asarray(g.corr_ned).T)
    if g.quality is not None:
        names.append(QUALITY_COLUMN)
        cols.append(g.quality)
    v_names, v_cols = velocity_columns(g, vel)
    _write_table(
        path,
        names + v_names,
        cols + v_cols,
        f"{src}\n# t [s], lat/lon [deg], h [m] ellipsoidal, 1-sigma N/E/D [m], "
        f"correlations, quality code (1 fix .. 5 single)"
        + (", NED velocity and its 1-sigma [m/s] (nan: none at that fix)" if v_names else ""),
    )


def write_odometry_csv(
    path: Path, odo: WheelOdometry, src: str = "# gnssacc wheel odometry"
) -> None:
    """Wheel odometry as ``odom.csv`` (the columns it has)."""
    names, cols = list(ODOM_COLUMNS), [odo.t, odo.v_forward]
    for name in ODOM_OPTIONAL:
        if getattr(odo, name) is not None:
            names.append(name)
            cols.append(getattr(odo, name))
    _write_table(
        path,
        names,
        cols,
        f"{src}\n# t [s] on the IMU clock, forward speed [m/s], yaw rate about the "
        f"vehicle's down axis [rad/s] (positive turning right), 1-sigmas",
    )


def _write_truth(path: Path, tr: Truth, src: str) -> None:
    names = list(POS_COLUMNS)
    cols = [tr.t, np.degrees(tr.lat), np.degrees(tr.lon), tr.h]
    if tr.v_n is not None:
        names += VEL_COLUMNS
        cols += list(np.asarray(tr.v_n).T)
    if tr.rpy is not None:
        names += RPY_COLUMNS
        cols += list(np.degrees(np.asarray(tr.rpy)).T)
    _write_table(
        path,
        names,
        cols,
        f"{src}\n# t [s], lat/lon [deg], h [m], NED velocity [m/s], roll/pitch/yaw [deg]",
    )


def _write_init(path: Path, init: InitialState) -> None:
    rpy_deg = np.degrees(init.rpy)
    att_deg = np.degrees(init.sigma_att_rad)
    doc = {
        "t": float(init.t),
        "lat_deg": float(np.degrees(init.lat)),
        "lon_deg": float(np.degrees(init.lon)),
        "h_m": float(init.h),
        "vn": float(init.v_n[0]),
        "ve": float(init.v_n[1]),
        "vd": float(init.v_n[2]),
        "roll_deg": float(rpy_deg[0]),
        "pitch_deg": float(rpy_deg[1]),
        "yaw_deg": float(rpy_deg[2]),
        "sigma": {
            "pos_m": [float(s) for s in init.sigma_pos_m],
            "vel_mps": [float(s) for s in init.sigma_vel_mps],
            "roll_pitch_deg": (
                float(att_deg[0])
                if att_deg[0] == att_deg[1]
                else [float(att_deg[0]), float(att_deg[1])]
            ),
            "yaw_deg": float(att_deg[2]),
        },
    }
    path.write_text(json.dumps(doc, indent=2) + "\n")
