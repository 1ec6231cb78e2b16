"""CSV run directory: the documented user format for recorded runs.

A run directory holds

``imu.csv`` (required)
    Columns ``t, ax, ay, az, gx, gy, gz``: time [s], specific force [m/s^2], angular rate
    [rad/s], in the IMU axes, Front-Right-Down unless the loader is told ``imu_frame="flu"``
    (Front-Left-Up; converted by negating y and z). ``[mounting]`` in the config then rotates
    the IMU axes into the body frame and shifts the IMU time stamps onto the GNSS clock.
``gnss.csv`` (required)
    Columns ``t, lat_deg, lon_deg, h_m`` and optionally ``sn, se, sd``: the 1-sigma north, east,
    down position uncertainty [m] (all three or none; without them ``gnss.default_sigma_m``).
``truth.csv`` (optional)
    Columns ``t, lat_deg, lon_deg, h_m``, optionally ``vn, ve, vd`` [m/s] and
    ``roll_deg, pitch_deg, yaw_deg`` (each group all or none). It may span less than the run:
    the outputs still cover the whole run, the scores only the truth's span (with a warning).
``init.json`` (optional)
    ``{"t", "lat_deg", "lon_deg", "h_m", "vn", "ve", "vd", "roll_deg", "pitch_deg", "yaw_deg",
    "sigma": {"pos_m", "vel_mps", "roll_pitch_deg", "yaw_deg"}}``. ``sigma`` and each of its keys
    are optional (defaults: the first fix's GNSS sigma, 0.5 m/s, 2 deg, 5 deg); ``pos_m`` and
    ``vel_mps`` take a number or N, E, D values, ``roll_pitch_deg`` a number or [roll, pitch].
    ``t`` must lie in the run: not after the last IMU sample, nor more than
    :data:`INIT_BEFORE_START_TOLERANCE_S` before the first.

In every CSV file header names are case-insensitive, column order is free, extra columns are
ignored, and lines starting with ``#`` are comments. All times are seconds; GNSS, truth and
init times are on the GNSS clock.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from ..core.config import DEG, RunConfig
from ..core.earth import LocalTangentFrame
from ..core.errors import InputError
from ..core.memory import release_free_memory
from ..core.recording import GnssFixes, ImuData, InitialState, RecordedRun, Truth, check_increasing
from ..core.rotations import flu_to_frd
from .common import apply_mounting, check_degrees, read_table

IMU_COLUMNS = ("t", "ax", "ay", "az", "gx", "gy", "gz")
POS_COLUMNS = ("t", "lat_deg", "lon_deg", "h_m")
SIGMA_COLUMNS = ("sn", "se", "sd")
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
    frame = str(imu_frame).lower()
    if frame not in IMU_FRAMES:
        raise InputError(where, f"imu_frame must be one of {', '.join(IMU_FRAMES)}, got {imu_frame!r}")
    if not root.exists():
        raise InputError(where, "run directory not found")
    if not root.is_dir():
        raise InputError(where, "not a directory: a CSV run is a directory holding imu.csv and gnss.csv")
    for name in ("imu.csv", "gnss.csv"):
        if (root / name).is_dir():
            raise InputError(str(root / name), "is a directory, expected a CSV file")
        if not (root / name).is_file():
            raise InputError(str(root / name), f"file not found: a CSV run directory needs {name}")
    max_bad = float(cfg["data"]["max_bad_fraction"])
    gnss = _read_gnss(root / "gnss.csv", cfg.default_sigma_ned, max_bad)
    imu = _read_imu(root / "imu.csv", frame, max_bad)
    # Stamps in ms/us/ns would never meet the fixes: found (and rescaled, or named) before the
    # overlap check, which could only say "different clocks?".
    if time_units is not None:
        imu = time_units(imu, gnss.t, str(root / "imu.csv"), cfg)
    imu = apply_mounting(imu, cfg)
    truth = _read_truth(root / "truth.csv", max_bad) if (root / "truth.csv").exists() else None
    init = _read_init(root / "init.json", gnss.sigma_ned[0]) if (root / "init.json").exists() else None
    if init is not None:
        check_init_time(init.t, imu.t[0], imu.t[-1], str(root / "init.json"))
    run = RecordedRun(name=root.resolve().name, where=where, imu=imu, gnss=gnss,
                      origin=LocalTangentFrame(gnss.lat[0], gnss.lon[0], gnss.h[0]),
                      truth=truth, init=init, meta={"source": "csv", "imu_frame": frame})
    release_free_memory()   # the parser's blocks
    return run.validate()


def check_init_time(t: float, t_start: float, t_end: float, where: str) -> None:
    """Raise :class:`InputError` unless the initial time lies in the run: not after its last IMU
    sample, nor more than :data:`INIT_BEFORE_START_TOLERANCE_S` before its first."""
    span = f"the run's IMU data span t = {t_start:.3f} .. {t_end:.3f} s"
    if t > t_end:
        raise InputError(where, f"time t = {t:.3f} s is after the run's end: {span}")
    if t < t_start - INIT_BEFORE_START_TOLERANCE_S:
        raise InputError(where, f"time t = {t:.3f} s is {t_start - t:.3f} s before the run's start "
                                f"(tolerance {INIT_BEFORE_START_TOLERANCE_S:g} s): {span}")


def _columns(tab: dict, names) -> np.ndarray:
    return np.column_stack([tab[c] for c in names])


def _optional_group(tab: dict, names, where: str) -> np.ndarray | None:
    """The (rows, 3) block of an all-or-none column group, or None when absent."""
    found = [c for c in names if c in tab]
    if not found:
        return None
    if len(found) != len(names):
        raise InputError(where, f"give all of the columns {', '.join(names)} or none (found only "
                                f"{', '.join(found)})")
    return _columns(tab, names)


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


def _read_positions(path: Path, what: str, optional, max_bad: float) -> dict:
    """Common part of gnss.csv and truth.csv: time order and degree ranges."""
    tab = read_table(path, POS_COLUMNS, optional, max_bad)
    check_increasing(tab["t"], str(path), what)
    check_degrees(tab["lat_deg"], tab["lon_deg"], tab["t"], str(path), what)
    return tab


def _read_gnss(path: Path, default_sigma_ned: np.ndarray, max_bad: float) -> GnssFixes:
    tab = _read_positions(path, "GNSS", SIGMA_COLUMNS, max_bad)
    n = len(tab["t"])
    if n == 0:
        raise InputError(str(path), "no GNSS fix row at all: at least one fix is needed to initialise")
    sigma_ned = _optional_group(tab, SIGMA_COLUMNS, str(path))
    if sigma_ned is None:
        sigma_ned = np.tile(default_sigma_ned, (n, 1))
    bad = np.flatnonzero(np.any(sigma_ned <= 0, axis=1))
    if bad.size:
        k = int(bad[0])
        raise InputError(str(path), f"sigmas sn, se, sd must be positive metres; not so at t = {tab['t'][k]:.6f} s "
                                    f"({bad.size} row(s))")
    return GnssFixes(tab["t"], tab["lat_deg"] * DEG, tab["lon_deg"] * DEG, tab["h_m"], sigma_ned)


def _read_truth(path: Path, max_bad: float) -> Truth:
    tab = _read_positions(path, "truth", VEL_COLUMNS + RPY_COLUMNS, max_bad)
    if len(tab["t"]) == 0:
        raise InputError(str(path), "no data rows (delete the file if there is no truth)")
    v_n = _optional_group(tab, VEL_COLUMNS, str(path))
    rpy_deg = _optional_group(tab, RPY_COLUMNS, str(path))
    return Truth(tab["t"], tab["lat_deg"] * DEG, tab["lon_deg"] * DEG, tab["h_m"], v_n,
                 None if rpy_deg is None else rpy_deg * DEG)


def _json_number(value, key: str, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise InputError(where, f"'{key}' must be a finite number, got {value!r}")
    return float(value)


def _json_vector(value, key: str, size: int, where: str) -> np.ndarray:
    """A number (same on all axes) or a list of ``size`` numbers, all positive."""
    items = value if isinstance(value, list) else [value]
    if len(items) not in (1, size):
        raise InputError(where, f"'{key}' must be a number or a list of {size} numbers, got {value!r}")
    arr = np.array([_json_number(v, key, where) for v in items])
    if np.any(arr <= 0):
        raise InputError(where, f"'{key}' must be positive, got {value!r}")
    return np.resize(arr, size)


def _check_keys(obj, allowed, required, where: str, what: str) -> None:
    if not isinstance(obj, dict):
        raise InputError(where, f"{what} must be a JSON object {{...}}")
    unknown = [k for k in obj if k not in allowed]
    if unknown:
        raise InputError(where, f"unknown key(s) {', '.join(unknown)} in {what} (known: {', '.join(allowed)})")
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
    check_degrees(np.array([v["lat_deg"]]), np.array([v["lon_deg"]]), np.array([v["t"]]), where, "initial")
    sig = doc.get("sigma", {})
    _check_keys(sig, SIGMA_KEYS, (), where, "init.json 'sigma'")
    pos = _json_vector(sig["pos_m"], "sigma.pos_m", 3, where) if "pos_m" in sig else first_fix_sigma_ned.copy()
    vel = _json_vector(sig.get("vel_mps", DEFAULT_SIGMA_VEL_MPS), "sigma.vel_mps", 3, where)
    roll_pitch = _json_vector(sig.get("roll_pitch_deg", DEFAULT_SIGMA_ROLL_PITCH_DEG),
                              "sigma.roll_pitch_deg", 2, where)
    yaw = _json_vector(sig.get("yaw_deg", DEFAULT_SIGMA_YAW_DEG), "sigma.yaw_deg", 1, where)
    return InitialState(t=v["t"], lat=v["lat_deg"] * DEG, lon=v["lon_deg"] * DEG, h=v["h_m"],
                        v_n=np.array([v["vn"], v["ve"], v["vd"]]),
                        rpy=np.array([v["roll_deg"], v["pitch_deg"], v["yaw_deg"]]) * DEG,
                        sigma_pos_m=pos, sigma_vel_mps=vel,
                        # n-frame attitude-error sigma: [roll_pitch, roll_pitch, yaw] as the
                        # level errors are taken equal to the roll/pitch sigmas.
                        sigma_att_rad=np.concatenate([roll_pitch, yaw]) * DEG,
                        how=f"given in {path.name}")


# --- writing ------------------------------------------------------------------------------------------

def _write_table(path: Path, names, columns, comment: str) -> None:
    table = np.column_stack([np.asarray(c, float) for c in columns])
    # %.17g round-trips every float64 exactly.
    np.savetxt(path, table, fmt="%.17g", delimiter=",", header=f"{comment}\n" + ",".join(names), comments="")


def write_csv_run(run: RecordedRun, path) -> Path:
    """Write a run as a CSV run directory (imu, gnss, truth and init.json when present).

    The IMU samples are written as they are held, i.e. in the body frame (FRD) on the GNSS
    clock; load the directory with an identity mounting and zero time offset to get the same
    run back. Angles are written in degrees with full float precision.

    Parameters
    ----------
    run : RecordedRun
    path : str or Path
        The directory; created if needed, existing files of the format are overwritten.

    Returns
    -------
    Path
        The directory.
    """
    root = Path(path)
    root.mkdir(parents=True, exist_ok=True)
    src = f"# gnssacc CSV run '{run.name}' written from {run.where}"
    imu = run.imu
    _write_table(root / "imu.csv", IMU_COLUMNS, [imu.t, *imu.f_b.T, *imu.omega_ib_b.T],
                 f"{src}\n# body frame FRD; t [s], specific force [m/s^2], angular rate [rad/s]")
    g = run.gnss
    _write_table(root / "gnss.csv", POS_COLUMNS + SIGMA_COLUMNS,
                 [g.t, np.degrees(g.lat), np.degrees(g.lon), g.h, *g.sigma_ned.T],
                 f"{src}\n# t [s], lat/lon [deg], h [m] ellipsoidal, 1-sigma N/E/D [m]")
    for stale in ("truth.csv", "init.json"):
        (root / stale).unlink(missing_ok=True)
    if run.truth is not None:
        _write_truth(root / "truth.csv", run.truth, src)
    if run.init is not None:
        _write_init(root / "init.json", run.init)
    return root


def _write_truth(path: Path, tr: Truth, src: str) -> None:
    names = list(POS_COLUMNS)
    cols = [tr.t, np.degrees(tr.lat), np.degrees(tr.lon), tr.h]
    if tr.v_n is not None:
        names += VEL_COLUMNS
        cols += list(np.asarray(tr.v_n).T)
    if tr.rpy is not None:
        names += RPY_COLUMNS
        cols += list(np.degrees(np.asarray(tr.rpy)).T)
    _write_table(path, names, cols, f"{src}\n# t [s], lat/lon [deg], h [m], NED velocity [m/s], "
                                    f"roll/pitch/yaw [deg]")


def _write_init(path: Path, init: InitialState) -> None:
    rpy_deg = np.degrees(init.rpy)
    att_deg = np.degrees(init.sigma_att_rad)
    doc = {"t": float(init.t), "lat_deg": float(np.degrees(init.lat)), "lon_deg": float(np.degrees(init.lon)),
           "h_m": float(init.h), "vn": float(init.v_n[0]), "ve": float(init.v_n[1]), "vd": float(init.v_n[2]),
           "roll_deg": float(rpy_deg[0]), "pitch_deg": float(rpy_deg[1]), "yaw_deg": float(rpy_deg[2]),
           "sigma": {"pos_m": [float(s) for s in init.sigma_pos_m],
                     "vel_mps": [float(s) for s in init.sigma_vel_mps],
                     "roll_pitch_deg": (float(att_deg[0]) if att_deg[0] == att_deg[1]
                                        else [float(att_deg[0]), float(att_deg[1])]),
                     "yaw_deg": float(att_deg[2])}}
    path.write_text(json.dumps(doc, indent=2) + "\n")
