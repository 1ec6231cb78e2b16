"""The shared real recordings (``../shared/data``) through ``gnssacc run`` with default settings.

Each recording is run exactly as a new user would, with no configuration, through its reader
(``gnssacc run SEGMENT_FOLDER``, ``gnssacc run LOG-imu.csv``: :mod:`gnssacc.sources.comma2k19`,
:mod:`gnssacc.sources.vectornav`); a closing table gives each method's PRMSE against the raw
fixes', the warnings and what the input checks applied.

* comma2k19 example 1: 60 s of highway driving, phone IMU (~104 Hz), u-blox fixes (10 Hz, no
  sigma stated), CAN speed (wheel odometry), u-blox speed and bearing (GNSS velocity), truth =
  comma's post-processed pose (20 Hz; its caveat: comma's own optimiser, camera frame).
* VN-310E static logs (lckf, tckf): 32 s standing, IMU 50 Hz, fixes 5 Hz with the receiver's
  own sigmas and NED velocities; no truth (the unit's INS solution is not one).

``--no-odometry`` (``[odometry] enabled = false``) and ``--no-velocity`` (``--velocity off``
where the gnssacc run has it; an older one reads no velocity anyway) leave those streams out.
``--via-csv`` loads each recording with the readers in this process and writes it as a CSV run
directory first (the fixes' sigmas then become stated ones, as this bench did before its readers
existed: with ``--no-odometry --no-velocity`` it reproduces that bench's figures), which also
lets an older installation (``--gnssacc PATH``) run it. Prints each run's table and warnings, or
its error.

    python bench/bench_real_recordings.py [--data ../shared/data] [--gnssacc gnssacc]
        [--no-odometry] [--no-velocity] [--via-csv]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import tempfile
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np

from gnssacc.core.config import load_config
from gnssacc.core.earth import R_en_batch
from gnssacc.core.errors import DataWarning
from gnssacc.core.recording import RecordedRun
from gnssacc.sources.comma2k19 import load_comma2k19
from gnssacc.sources.csvdir import write_csv_run
from gnssacc.sources.vectornav import load_vectornav

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"


def comma(root: Path) -> RecordedRun:
    """comma2k19 example 1 as the other benches have always held it (their figures rest on it):
    through the reader, without odometry and velocity, the default fix sigma taken as stated
    (the caveat warning of its reference is left to ``gnssacc run``)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        run = load_comma2k19(root, load_config(), odometry=False, velocity=False)
    return replace(run, name="comma2k19-ex1", gnss=replace(run.gnss, sigma_stated=True))


def vn310(root: Path, log: str) -> RecordedRun:
    """A VN-310E static log (``lckf``, ``tckf``) through the reader, without velocity."""
    return replace(
        load_vectornav(root / f"{log}_vn310-imu.csv", velocity=False), name=f"vn310-{log}"
    )


def ned_rotation(lat: np.ndarray, lon: np.ndarray) -> np.ndarray:
    """ECEF -> NED rotations at (lat, lon) [rad], shape (K, 3, 3)."""
    return R_en_batch(lat, lon)


def recordings(data: Path) -> list[tuple[str, Path]]:
    """(name, what ``gnssacc run`` is given) of each shared recording."""
    vn = data / "vn310_static"
    return [
        ("comma2k19-ex1", data / "comma2k19_example1"),
        ("vn310-lckf", vn / "lckf_vn310-imu.csv"),
        ("vn310-tckf", vn / "tckf_vn310-imu.csv"),
    ]


def as_csv_run(name: str, src: Path, folder: Path, odometry: bool, velocity: bool) -> Path:
    """A recording read by its reader and written as a CSV run directory."""
    if src.is_dir():
        run = load_comma2k19(src, load_config(), odometry=odometry, velocity=velocity)
    else:
        run = load_vectornav(src, velocity=velocity)
    run.name = name
    return write_csv_run(run, folder)


def run_options(gnssacc: str, no_odometry: bool, no_velocity: bool, tmp: Path) -> list[str]:
    """The ``gnssacc run`` options that leave the odometry and the velocities out."""
    opts = []
    if no_odometry:
        cfg = tmp / "no-odometry.toml"
        cfg.write_text("[odometry]\nenabled = false\n")
        opts += ["--config", str(cfg)]
    if no_velocity:
        helptext = subprocess.run([gnssacc, "run", "--help"], capture_output=True, text=True)
        if "--velocity" in helptext.stdout:
            opts += ["--velocity", "off"]
        else:
            print(f"({gnssacc} run has no --velocity: it reads no GNSS velocity anyway)")
    return opts


def _summary_row(name: str, code: int, out: Path) -> str:
    """One line of the closing table: each method's PRMSE against the raw fixes', or the refusal."""
    if code != 0:
        return f"{name:16s} exit {code} (refused or failed)"
    m = json.loads((out / "metrics.json").read_text())
    raw = m.get("gnss_prmse_m")
    cells = []
    for mid in ("ekf", "smoother"):
        v = m["methods"].get(mid, {}).get("prmse_m")
        cells.append("-" if v is None else f"{v:.2f}" + (f" ({v / raw:.2f}x)" if raw else ""))
    warned = sum(len(c["warnings"]) for c in m.get("consistency", {}).values())
    applied = [
        f["check"] for f in m.get("input_checks", []) if f["action"] in ("repaired", "applied")
    ]
    raw_s = f"{raw:.2f}" if raw else "no truth"
    return f"{name:16s} {cells[0]:>16s} {cells[1]:>16s} {raw_s:>9s} {warned:8d}  {', '.join(applied) or '-'}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=str(DATA))
    ap.add_argument(
        "--gnssacc", default="gnssacc", help="the gnssacc command to run (e.g. an older install)"
    )
    ap.add_argument("--no-odometry", action="store_true", help="leave the wheel odometry out")
    ap.add_argument("--no-velocity", action="store_true", help="leave the GNSS velocities out")
    ap.add_argument(
        "--via-csv", action="store_true", help="read in-process, run a CSV run directory"
    )
    a = ap.parse_args()
    data = Path(a.data)
    if not data.is_dir():
        raise SystemExit(f"{data}: no real recordings here (see ../shared/data/README.md)")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        opts = run_options(a.gnssacc, a.no_odometry, a.no_velocity, Path(tmp))
        for name, src in recordings(data):
            if a.via_csv:
                odo, vel = not a.no_odometry, not a.no_velocity
                src = as_csv_run(name, src, Path(tmp) / name, odo, vel)
            out = Path(tmp) / f"{name}-out"
            cmd = [a.gnssacc, "run", str(src), "--out", str(out), "--plots", "none", *opts]
            res = subprocess.run(cmd, capture_output=True, text=True)
            print(f"==== {name}: {' '.join(cmd)} (exit {res.returncode})")
            print(res.stdout.strip())
            print(
                "\n".join(line for line in res.stderr.splitlines() if line.startswith("gnssacc:"))
            )
            rows.append(_summary_row(name, res.returncode, out))
    print(
        f"\n{'recording':16s} {'ekf PRMSE [m]':>16s} {'smoother [m]':>16s} {'raw [m]':>9s} "
        f"{'warnings':>8s}  applied"
    )
    print("\n".join(rows))


if __name__ == "__main__":
    main()
