"""Tuning time against the recording's length, and the accuracy of tuning on windows.

Part 1: the noise identification (``--tune auto``, default settings) of a simulated car (the
``car`` scenario, industrial IMU, 3 m white fixes at 1 Hz, seed 0) of 600, 1,200, 2,400 and
4,800 s: the time of the tuning step (median of ``--repeats``, the lengths interleaved), its EKF
passes and the ratio to 600 s (target: 2,400 s at most 1.5x 600 s). Runs longer than
:data:`gnssacc.prepare.tune_windows.WINDOWED_FROM_S` (900 s) are tuned on windows of
:data:`~gnssacc.prepare.tune_windows.SPAN_S` in all (:mod:`gnssacc.prepare.tune_windows`); the
600 s run is tuned whole, as before.

Part 2 (``--accuracy``): at 2,400 s, seeds 0 .. ``--seeds``-1, the windowed tuning (the default)
against the whole-run tuning (windows off): the tuned values, the EKF's and the smoother's PRMSE
and position NEES; the difference between the two against their spread over the seeds (hold the
accuracy, not the digits).

    python bench/bench_tuning_length.py [--repeats 3] [--lengths 600,1200,2400,4800] [--accuracy]
        [--seeds 3] [--no-timing]
"""

from __future__ import annotations

import argparse
import os
import time
import warnings

import numpy as np

os.environ.setdefault("GNSSACC_CACHE_DIR", "none")

import gnssacc  # noqa: E402
import gnssacc.prepare.tune_windows as tw  # noqa: E402
from gnssacc.core.config import load_config  # noqa: E402
from gnssacc.pipeline import prepare  # noqa: E402

LENGTHS = (600.0, 1200.0, 2400.0, 4800.0)


def tuning_time(run) -> tuple[float, int]:
    prep = prepare(run, load_config(), "auto")
    return prep.seconds["tuning_s"], prep.tuning.n_evaluations


def part1(repeats: int, lengths=LENGTHS) -> None:
    runs = {d: gnssacc.simulate("car", d, seed=0) for d in lengths}
    times: dict = {d: [] for d in lengths}
    passes: dict = {}
    for r in range(repeats):
        for d in lengths:
            s, passes[d] = tuning_time(runs[d])
            times[d].append(s)
        print(f"round {r + 1}/{repeats} done", flush=True)
    base = float(np.median(times[600.0]))
    print(
        f"\ntuning time against length (car, seed 0, median of {repeats}, load "
        f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores)"
    )
    print(f"{'length [s]':>10s} {'tuning [s]':>10s} {'passes':>7s} {'x 600 s':>8s}  windows")
    for d in lengths:
        med = float(np.median(times[d]))
        windowed = "yes" if d > tw.WINDOWED_FROM_S else "no (whole run)"
        print(f"{d:10.0f} {med:10.2f} {passes[d]:7d} {med / base:8.2f}  {windowed}")
    print(f"target: 2400 s at most 1.5x 600 s: {np.median(times[2400.0]) / base:.2f}x")


def part2(seeds: int) -> None:
    rows: dict = {"windows": [], "whole run": []}
    windowed_from = tw.WINDOWED_FROM_S
    for seed in range(seeds):
        run = gnssacc.simulate("car", 2400.0, seed=seed)
        for mode in rows:
            tw.WINDOWED_FROM_S = windowed_from if mode == "windows" else float("inf")
            t = time.perf_counter()
            res = gnssacc.process(run, methods=["ekf", "smoother"])
            m = res.metrics["methods"]
            rows[mode].append(
                {
                    "tune_s": res.prepared.seconds["tuning_s"],
                    "ekf": m["ekf"]["prmse_m"],
                    "smoother": m["smoother"]["prmse_m"],
                    "nis": m["ekf"].get("nis_pos"),
                    "nees_ekf": m["ekf"].get("nees_pos"),
                    "nees_smoother": m["smoother"].get("nees_pos"),
                    "values": res.prepared.tuning.values,
                    "all_s": time.perf_counter() - t,
                }
            )
            r = rows[mode][-1]
            print(
                f"seed {seed} {mode:9s}: tuning {r['tune_s']:.1f} s, PRMSE ekf {r['ekf']:.3f} m, "
                f"smoother {r['smoother']:.3f} m; position NEES ekf {r['nees_ekf']:.2f}, "
                f"smoother {r['nees_smoother']:.2f}",
                flush=True,
            )
    tw.WINDOWED_FROM_S = windowed_from
    print(f"\n2400 s car, seeds 0..{seeds - 1}: windowed against whole-run tuning")
    print(f"{'':10s} {'PRMSE ekf [m]':>22s} {'PRMSE smoother [m]':>22s} {'tuning [s]':>11s}")
    for mode, r in rows.items():
        e, s = [x["ekf"] for x in r], [x["smoother"] for x in r]
        print(
            f"{mode:10s} {np.mean(e):8.3f} (sd {np.std(e):5.3f}) {np.mean(s):12.3f} "
            f"(sd {np.std(s):5.3f}) {np.median([x['tune_s'] for x in r]):11.1f}"
        )
    for key in ("ekf", "smoother"):
        d = [w[key] / f[key] - 1.0 for w, f in zip(rows["windows"], rows["whole run"], strict=True)]
        print(
            f"{key}: windowed / whole-run PRMSE - 1 per seed: "
            + ", ".join(f"{100 * x:+.1f} %" for x in d)
        )
    print("tuned values per seed (windows | whole run):")
    for w, f in zip(rows["windows"], rows["whole run"], strict=True):
        print(
            "  "
            + ", ".join(
                f"{k} {v} | {f['values'].get(sec, {}).get(k)}"
                for sec, vals in w["values"].items()
                for k, v in vals.items()
            )
        )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--accuracy", action="store_true")
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--no-timing", action="store_true")
    ap.add_argument(
        "--lengths", default=",".join(f"{d:.0f}" for d in LENGTHS), help="recording lengths [s]"
    )
    a = ap.parse_args()
    warnings.simplefilter("ignore")
    if not a.no_timing:
        part1(a.repeats, tuple(float(x) for x in a.lengths.split(",")))
    if a.accuracy:
        part2(a.seeds)


if __name__ == "__main__":
    main()
