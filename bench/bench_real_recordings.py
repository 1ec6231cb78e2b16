"""The shared real recordings (``../shared/data``) through ``gnssacc run DIR`` with default settings.

Each recording is written once as a CSV run directory (the documented user format) and then run
exactly as a new user would, with no configuration: ``gnssacc run DIR --out OUT --plots none``; a
closing table gives each method's PRMSE against the raw fixes', the warnings and what the input
checks applied.
Run it with the ``gnssacc`` of any installation (``--gnssacc PATH``), e.g. an older checkout, to
compare before and after. Prints each run's table and warnings, or its error.

* comma2k19 example 1: 60 s of highway driving, phone IMU (~104 Hz), u-blox fixes (10 Hz, no
  sigma: the default sigma applies), truth = comma's post-processed pose (20 Hz).
* VN-310E static logs (lckf, tckf): 32 s standing, IMU 50 Hz, fixes 5 Hz with the receiver's
  own sigmas; no truth (the antenna does not move: the velocity should stay near zero).

    python bench/bench_real_recordings.py [--data ../shared/data] [--gnssacc gnssacc]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import tempfile
from pathlib import Path

import numpy as np

from gnssacc.core.earth import LocalTangentFrame, ecef_to_llh
from gnssacc.core.recording import GnssFixes, ImuData, RecordedRun, Truth
from gnssacc.sources.csvdir import write_csv_run

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"


def ned_rotation(lat: np.ndarray, lon: np.ndarray) -> np.ndarray:
    sl, cl, so, co = np.sin(lat), np.cos(lat), np.sin(lon), np.cos(lon)
    z = np.zeros_like(lat)
    return np.stack(
        [
            np.stack([-sl * co, -sl * so, cl], -1),
            np.stack([-so, co, z], -1),
            np.stack([-cl * co, -cl * so, -sl], -1),
        ],
        -2,
    )


def comma(root: Path) -> RecordedRun:
    """comma2k19 example 1 (arrays are .npy files without extension; IMU already FRD, SI)."""
    arr = lambda rel: np.load(root / rel)  # noqa: E731
    t_imu = arr("processed_log/IMU/accelerometer/t")
    ub = arr(
        "processed_log/GNSS/live_gnss_ublox/value"
    )  # lat deg, lon deg, speed, utc ms, alt m, bearing
    t_fix = arr("processed_log/GNSS/live_gnss_ublox/t")
    sigma = np.tile([3.0, 3.0, 5.0], (len(t_fix), 1))
    fixes = GnssFixes(t_fix, np.radians(ub[:, 0]), np.radians(ub[:, 1]), ub[:, 4], sigma)
    lat, lon, h = ecef_to_llh(arr("global_pose/frame_positions"))
    v_n = np.einsum("kij,kj->ki", ned_rotation(lat, lon), arr("global_pose/frame_velocities"))
    truth = Truth(arr("global_pose/frame_times"), lat, lon, h, v_n=v_n)
    imu = ImuData(
        t_imu, arr("processed_log/IMU/accelerometer/value"), arr("processed_log/IMU/gyro/value")
    )
    return RecordedRun(
        "comma2k19-ex1",
        str(root),
        imu,
        fixes,
        LocalTangentFrame(fixes.lat[0], fixes.lon[0], fixes.h[0]),
        truth,
    )


def _vn_columns(path: Path) -> dict:
    head = path.open().readline().strip().split(",")
    data = np.genfromtxt(path, delimiter=",", skip_header=1, usecols=range(len(head)))
    return {name.strip(): data[:, i] for i, name in enumerate(head)}


def vn310(root: Path, log: str) -> RecordedRun:
    """A VN-310E static log: compensated IMU (FRD, SI) and GNSS1 fixes with their sigmas, GPS time."""
    imu, gnss = (
        _vn_columns(root / f"{log}_vn310-imu.csv"),
        _vn_columns(root / f"{log}_vn310-gnss.csv"),
    )
    t0 = imu["GpsTow [s]"][0]
    f_b = np.column_stack([imu[f"IMU::Accel::{a} [m/s^2]"] for a in "XYZ"])
    w_b = np.column_stack(
        [
            imu["IMU::AngularRate::X"],
            imu["IMU::AngularRate::Y [rad/s]"],
            imu["IMU::AngularRate::Z [rad/s]"],
        ]
    )
    sigma = np.column_stack([gnss[f"GNSS1::PosU::{a} [m]"] for a in "NED"])
    fixes = GnssFixes(
        gnss["GNSS1::Tow [ns]"] * 1e-9 - t0,
        np.radians(gnss["GNSS1::PosLla::latitude [deg]"]),
        np.radians(gnss["GNSS1::PosLla::longitude [deg]"]),
        gnss["GNSS1::PosLla::altitude [m]"],
        sigma,
    )
    return RecordedRun(
        f"vn310-{log}",
        str(root),
        ImuData(imu["GpsTow [s]"] - t0, f_b, w_b),
        fixes,
        LocalTangentFrame(fixes.lat[0], fixes.lon[0], fixes.h[0]),
    )


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
    a = ap.parse_args()
    data = Path(a.data)
    if not data.is_dir():
        raise SystemExit(f"{data}: no real recordings here (see ../shared/data/README.md)")
    runs = [
        comma(data / "comma2k19_example1"),
        vn310(data / "vn310_static", "lckf"),
        vn310(data / "vn310_static", "tckf"),
    ]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for run in runs:
            folder = write_csv_run(run, Path(tmp) / run.name)
            out = Path(tmp) / f"{run.name}-out"
            cmd = [a.gnssacc, "run", str(folder), "--out", str(out), "--plots", "none"]
            res = subprocess.run(cmd, capture_output=True, text=True)
            print(f"==== {run.name}: {' '.join(cmd[:3])} (exit {res.returncode})")
            print(res.stdout.strip())
            print(
                "\n".join(line for line in res.stderr.splitlines() if line.startswith("gnssacc:"))
            )
            rows.append(_summary_row(run.name, res.returncode, out))
    print(
        f"\n{'recording':16s} {'ekf PRMSE [m]':>16s} {'smoother [m]':>16s} {'raw [m]':>9s} {'warnings':>8s}  applied"
    )
    print("\n".join(rows))


if __name__ == "__main__":
    main()
