"""The fixed-lag smoother's window: accuracy, consistency and time against ``[smoother] lag_s``.

Per recording and lag: the smoother's PRMSE [m], its position NEES per dof (and attitude NEES
where the truth has attitude), and its own wall time [s] (the median of ``--repeats`` runs, one by
default: indicative; the preparation is shared through the preparation cache, so every lag starts
from the same tuned noise). Default settings otherwise (``gnssacc.process``, method ``smoother``).

    python bench/diag_smoother_lag.py [--lags 10,20] [--runs kitti@0 sim:car,imu=tactical@0 ...]

Besides ``source@seed``, ``--runs`` takes ``comma2k19`` (``../shared/data``'s example 1 against
comma's pose, skipped where absent) and ``bench/bench_hard_traits.py``'s ``rover`` (20 Hz fixes
without sigmas) and ``sideways`` (the sideways-IMU bag, scored against its simulated truth).
"""

from __future__ import annotations

import argparse
import os
import tempfile
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
from bench_hard_traits import rover_run, write_sideways_bag

import gnssacc

RUNS = [f"kitti@{s}" for s in range(5)] + [
    "sim:car-city,imu=industrial,duration=300@0",
    "sim:ugv-slow,imu=consumer,duration=300@0",
    "sim:car,imu=tactical,duration=300@0",
    "sim:ugv,imu=industrial,duration=300@0",
    "comma2k19",
    "rover",
    "sideways",
]
COMMA = Path(__file__).resolve().parents[2] / "shared" / "data" / "comma2k19_example1"


def recording(spec: str, folder: str):
    """(what ``gnssacc.process`` is given, seed) for one ``--runs`` entry."""
    if spec == "comma2k19":
        return str(COMMA), 0
    if spec == "rover":
        return rover_run(), 0
    if spec == "sideways":
        run, bag = write_sideways_bag(Path(folder))
        return replace(gnssacc.load(str(bag)), truth=run.truth), 0
    source, _, seed = spec.rpartition("@")
    return source, int(seed)


def cell(source, seed: int, lag: float, repeats: int) -> str:
    """One recording's figures at one lag (the wall time: the median of ``repeats`` runs)."""
    walls = []
    for _ in range(repeats):
        res = gnssacc.process(
            source, methods=["smoother"], seed=seed, config={"smoother": {"lag_s": lag}}
        )
        walls.append(res.solutions["smoother"].runtime_s)
    m = res.metrics["methods"]["smoother"]
    errors = m.get("errors") or {}
    pos = (errors.get("nees_position") or {}).get("value")
    att = (errors.get("nees_attitude") or {}).get("value")
    att_s = "" if att is None else f" att {att:.2f}"
    return (
        f"lag {lag:g} s: {m['prmse_m']:.3f} m NEES {pos:.2f}{att_s} wall {np.median(walls):.2f} s"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--lags", default="10,20", help="lags to compare [s], comma-separated")
    ap.add_argument("--runs", nargs="*", default=RUNS, help="source@seed")
    ap.add_argument("--repeats", type=int, default=1, help="runs per cell (median wall time)")
    args = ap.parse_args()
    lags = [float(x) for x in args.lags.split(",")]
    warnings.simplefilter("ignore")
    with tempfile.TemporaryDirectory() as cache:
        os.environ.setdefault("GNSSACC_CACHE_DIR", cache)  # one preparation per recording
        for spec in args.runs:
            if spec == "comma2k19" and not COMMA.is_dir():
                print(f"{spec:45s} skipped: {COMMA} absent", flush=True)
                continue
            source, seed = recording(spec, cache)
            cells = " | ".join(cell(source, seed, lag, args.repeats) for lag in lags)
            print(f"{spec:45s} {cells}", flush=True)


if __name__ == "__main__":
    main()
