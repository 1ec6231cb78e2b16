"""Self-tuning and consistency on simulated runs that behave like real IMUs (issue: trustworthy on a
user's own recording).

For each cell (scenario x IMU grade x GNSS noise) and seed, the same simulated run goes through
``gnssacc.pipeline.compare`` three times:

* ``default``: no configuration at all, ``--tune auto`` (what a new user gets);
* ``true``: the simulator's true noise parameters (``grade_config``), ``--tune none``;
* ``optimistic``: those parameters 10x too optimistic (noise densities and bias sigmas / 10),
  ``--tune none`` -- every method should then be warned about.

Printed per cell: PRMSE of ``default`` and ``true`` (mean over seeds) and their ratio, the NIS per
dof of each method under ``default``, coverage, heading flips (|yaw error| > 90 deg at any scored
epoch), and the share of methods warned about under ``optimistic``; then the tuning time.

    python bench/bench_selftune.py [--seeds 5] [--jobs 2] [--quick] [--configs default,true]
"""

from __future__ import annotations

import argparse
import json
import time
import warnings
from concurrent.futures import ProcessPoolExecutor

import numpy as np

# Imported here, before the worker processes fork, so that every run uses the same code.
from gnssacc.core.config import load_config
from gnssacc.pipeline import compare
from gnssacc.sources.sim import grade_config, simulate

METHODS = ["ekf", "smoother"]
SCENARIOS = {"car-city": 280.0, "ugv-slow": 235.0}
GRADES = ("consumer", "industrial", "tactical")
NOISES = ("white", "gm")


def _optimistic(params: dict) -> dict:
    out = dict(params)
    for k in (
        "gyro_arw_deg_rth",
        "accel_vrw_mps_rth",
        "gyro_bias_instability_deg_h",
        "accel_bias_instability_mg",
        "gyro_bias_sigma0_deg_h",
        "accel_bias_sigma0_mg",
    ):
        out[k] = float(np.asarray(out[k], float).mean()) / 10.0
    return out


def _yaw_flip(run, sol) -> bool:
    tr = run.truth
    yaw_t = np.interp(sol.t, tr.t, np.unwrap(tr.rpy[:, 2]))
    d = (sol.rpy[:, 2] - yaw_t + np.pi) % (2 * np.pi) - np.pi
    return bool(np.any(np.abs(d) > np.pi / 2))


def one(task) -> dict:
    scenario, grade, noise, seed, configs = task
    run = simulate(scenario, SCENARIOS[scenario], imu_grade=grade, noise=noise, seed=seed)
    true = grade_config(grade)
    out = {"cell": (scenario, grade, noise), "seed": seed}
    for name, cfg, tune in (
        ("default", load_config(), "auto"),
        ("true", load_config(overrides={"imu": true}), "none"),
        ("optimistic", load_config(overrides={"imu": _optimistic(true)}), "none"),
    ):
        if name not in configs:
            continue
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            metrics, sols, ident = compare(run, cfg, METHODS, tune=tune)
        res = {
            "seconds": time.perf_counter() - t0,
            "gnss": metrics["gnss_prmse_m"],
            "tune_s": ident.tuning.seconds if ident.tuning else None,
            "init": ident.init.how,
        }
        for m, sol in sols.items():
            mm, cons = metrics["methods"][m], metrics["consistency"][m]
            res[m] = {
                "prmse": mm["prmse_m"],
                "nis": cons["nis"]["pos"],
                "warned": bool(cons["warnings"]),
                "warnings": cons["warnings"],
                "acf1": cons["innovation_acf1"],
                "coverage": metrics["coverage"][m]["fraction"],
                "flip": _yaw_flip(run, sol),
            }
        out[name] = res
    return out


def summarise(results: list[dict]) -> str:
    cells: dict = {}
    for r in results:
        cells.setdefault(r["cell"], []).append(r)
    lines = []
    head = (
        f"{'scenario':9s} {'grade':10s} {'noise':5s} {'method':16s} {'PRMSE def':>9s} {'true':>6s} {'ratio':>6s} "
        f"{'NIS def':>7s} {'NIS true':>8s} {'cover':>5s} {'flips':>5s} {'warned def':>10s} {'warned@10x':>10s}"
    )
    lines += [head, "-" * len(head)]
    for (scen, grade, noise), rs in cells.items():
        for m in rs[0]["default"]:
            if not isinstance(rs[0]["default"][m], dict):
                continue
            d = np.array([r["default"][m]["prmse"] for r in rs])
            t = np.array([r["true"][m]["prmse"] if "true" in r else np.nan for r in rs])
            nis = np.mean([r["default"][m]["nis"] for r in rs])
            nis_t = np.mean([r["true"][m]["nis"] if "true" in r else np.nan for r in rs])
            cover = min(r["default"][m]["coverage"] for r in rs)
            flips = sum(r["default"][m]["flip"] for r in rs)
            warned = np.mean(
                [r["optimistic"][m]["warned"] if "optimistic" in r else np.nan for r in rs]
            )
            warned_def = np.mean([r["default"][m]["warned"] for r in rs])
            lines.append(
                f"{scen:9s} {grade:10s} {noise:5s} {m:16s} {d.mean():9.2f} {t.mean():6.2f} "
                f"{d.mean() / t.mean():6.3f} {nis:7.2f} {nis_t:8.2f} {cover:5.3f} {flips:5d} {warned_def:10.2f} "
                f"{warned:10.2f}"
            )
    tune_s = [r["default"]["tune_s"] for r in results if r["default"]["tune_s"] is not None]
    lines.append(
        f"\ntuning time per run: median {np.median(tune_s):.1f} s, max {np.max(tune_s):.1f} s "
        f"({len(tune_s)} runs of {min(SCENARIOS.values()):.0f}-{max(SCENARIOS.values()):.0f} s)"
    )
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--quick", action="store_true", help="one seed, consumer only (a smoke run)")
    ap.add_argument("--out", default=None, help="also write the per-run results as JSON")
    ap.add_argument(
        "--configs",
        default="default,true,optimistic",
        help="which of default, true, optimistic to run (default: all three; 'default' is required)",
    )
    a = ap.parse_args()
    configs = set(a.configs.split(","))
    if "default" not in configs or not configs <= {"default", "true", "optimistic"}:
        ap.error(
            f"--configs {a.configs}: a comma-separated subset of default,true,optimistic with default"
        )
    grades = ("consumer",) if a.quick else GRADES
    seeds = range(1 if a.quick else a.seeds)
    tasks = [
        (s, g, n, seed, configs)
        for s in SCENARIOS
        for g in grades
        for n in NOISES
        for seed in seeds
    ]
    t0 = time.perf_counter()
    with ProcessPoolExecutor(a.jobs) as ex:
        results = list(ex.map(one, tasks))
    print(summarise(results))
    print(
        f"{len(tasks)} runs x {len(configs)} configurations in {time.perf_counter() - t0:.0f} s with {a.jobs} processes"
    )
    if a.out:
        with open(a.out, "w") as f:
            json.dump(results, f, indent=1, default=str)


if __name__ == "__main__":
    main()
