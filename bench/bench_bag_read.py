"""Bag reading speed and memory: IMU/GNSS messages per second, MB/s of bag skipped, peak RSS.

Writes simulated bags padded with large dummy ``sensor_msgs/Image`` messages (the "camera"
share of a real recording) to a scratch folder on /tmp, loads each with
:func:`gnssacc.sources.rosbag.load_bag_run` in a fresh process (so the peak RSS is that of one
load), and deletes the bags afterwards. Free space is checked first and the sizes are scaled
down when short. The bags were just written, so reads are from a warm page cache.

Usage::

    python bench/bench_bag_read.py [--sizes-gb 0.25,2] [--kinds ros1-rooad,ros2-mcap,ros2-sqlite3]
                                   [--duration 600] [--repeats 3]
"""

from __future__ import annotations

import argparse
import json
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

# Peak RSS from /proc/self/status VmHWM: unlike ru_maxrss it is not inherited from the parent
# across fork+exec, so it is the high-water mark of this process alone.
CHILD = r"""
import json, sys, time, warnings
def hwm_kb():
    for line in open("/proc/self/status"):
        if line.startswith("VmHWM:"):
            return int(line.split()[1])
from gnssacc.core.config import load_config
from gnssacc.sources.rosbag import load_bag_run
import rosbags.highlevel
cfg = load_config()
base = hwm_kb()
t0 = time.perf_counter()
with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    run = load_bag_run(sys.argv[1], cfg, gnss_topic=sys.argv[2] if len(sys.argv) > 2 else None)
dt = time.perf_counter() - t0
peak = hwm_kb()
print(json.dumps({"s": dt, "n_imu": len(run.imu), "n_gnss": len(run.gnss), "rss_peak_kb": peak,
                  "rss_after_import_kb": base}))
"""


def bag_bytes(p: Path) -> int:
    return (
        p.stat().st_size
        if p.is_file()
        else sum(f.stat().st_size for f in p.rglob("*") if f.is_file())
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes-gb", default="0.25,2")
    ap.add_argument("--kinds", default="ros1-rooad,ros2-mcap,ros2-sqlite3")
    ap.add_argument(
        "--duration", type=float, default=600.0, help="simulated run length [s] (100 Hz IMU)"
    )
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--image-rate", type=float, default=10.0)
    args = ap.parse_args()
    # Turn SIGTERM into SystemExit so the scratch folder with the big bags is always removed.
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))

    from gnssacc.sources.bagwrite import write_bag
    from gnssacc.sources.sim import simulate

    sizes = [float(s) for s in args.sizes_gb.split(",")]
    kinds = [k.strip() for k in args.kinds.split(",")]
    free_gb = shutil.disk_usage("/tmp").free / 1e9
    need = max(sizes) * 1.3 + 0.5  # one bag at a time, plus slack
    if need > free_gb:
        scale = (free_gb - 0.5) / (max(sizes) * 1.3)
        sizes = [max(0.01, s * scale) for s in sizes]
        print(f"only {free_gb:.1f} GB free on /tmp: scaled the bag sizes down to {sizes} GB")
    print(
        f"/tmp free: {free_gb:.1f} GB; bag sizes {sizes} GB; kinds {kinds}; run {args.duration:.0f} s, "
        f"100 Hz IMU, 1 Hz GNSS, {args.image_rate:g} Hz images; median of {args.repeats} loads, "
        f"each in a fresh process; warm page cache"
    )
    run = simulate("car", duration_s=args.duration, imu_grade="industrial", noise="white", seed=0)
    n_img = int(np.ceil(args.duration * args.image_rate))
    rows = []
    with tempfile.TemporaryDirectory(prefix="gnssacc-bagbench-", dir="/tmp") as scratch:
        for kind in kinds:
            for size in sizes:
                img_bytes = int(size * 1e9 / n_img)
                name = {"ros1-rooad": "b.bag", "mcap": "b.mcap"}.get(kind, "b")
                path = Path(scratch) / name
                t0 = time.perf_counter()
                write_bag(
                    run,
                    path,
                    kind,
                    extra_image_topic_bytes=img_bytes,
                    image_rate_hz=args.image_rate,
                )
                t_write = time.perf_counter() - t0
                nbytes = bag_bytes(path)
                res = []
                cmd = [sys.executable, "-c", CHILD, str(path)] + (
                    ["/UBX/hpposllh"] if kind == "ros1-rooad" else []
                )
                for _ in range(args.repeats):
                    out = subprocess.run(cmd, capture_output=True, text=True, check=True)
                    res.append(json.loads(out.stdout.strip().splitlines()[-1]))
                s = float(np.median([r["s"] for r in res]))
                n_msgs = res[0]["n_imu"] + res[0]["n_gnss"]
                row = {
                    "kind": kind,
                    "bag_MB": nbytes / 1e6,
                    "write_s": t_write,
                    "load_s": s,
                    "msgs_per_s": n_msgs / s,
                    "bag_MB_per_s": nbytes / 1e6 / s,
                    "rss_peak_MB": float(np.median([r["rss_peak_kb"] for r in res])) / 1024,
                    "rss_import_MB": float(np.median([r["rss_after_import_kb"] for r in res]))
                    / 1024,
                    "n_imu": res[0]["n_imu"],
                    "n_gnss": res[0]["n_gnss"],
                }
                rows.append(row)
                print(
                    f"{kind:13s} bag {row['bag_MB']:8.0f} MB  load {s:6.2f} s  "
                    f"{row['msgs_per_s']:9.0f} IMU+GNSS msg/s  {row['bag_MB_per_s']:8.0f} MB/s of bag  "
                    f"peak RSS {row['rss_peak_MB']:6.0f} MB (after imports {row['rss_import_MB']:.0f} MB)  "
                    f"[write {t_write:.1f} s]",
                    flush=True,
                )
                if path.is_dir():
                    shutil.rmtree(path)
                else:
                    path.unlink()
    print(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
