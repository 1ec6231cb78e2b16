"""Issue 12 study: does GNSS-derived acceleration aiding help? A paired grid over simulated runs.

The grid: IMU grade (consumer, industrial, tactical) x scenario (ugv-slow, car) x GNSS noise
(white 3 m, gm, precise 0.5 m, rtk 0.02 m) x fix rate (1, 5 Hz) x outages (none, every 60:20) x
seeds, every method on each. Each noise profile is ONE ``gnssacc batch`` campaign (``--noise`` is
a campaign setting) of ``sim:`` sources under ``--out``/noise-<profile>/; a campaign already there
with the same settings is resumed (only what is missing runs). Then:

* ``--out``/study.csv: one row per cell x method x seed with every figure of ``summary.csv``;
* per cell and variant against its baseline (``ekf`` for ``ekf-*``, ``smoother`` for
  ``smoother-*``): the mean paired difference [%] with its 95 % bootstrap interval and the
  sign-flip p-value, for PRMSE, outage PRMSE, tilt, yaw, bias errors and NEES
  (:mod:`gnssacc.analysis.study`), and which cells each variant helps or hurts on PRMSE;
* the time per task (median, with the load average), per scenario, IMU grade and fix rate, to size
  a grid for this machine.

Known noise by default (``--tune none``: the simulator's IMU parameters, and for the ``-gm``
methods the profile's Gauss-Markov model): the study asks about the aiding, not the tuning. With
``--tune none`` the ``-gm`` methods run only where the noise profile has a Gauss-Markov part
(``gm``): on white profiles they have no parameters to use.

The paper's setting by default (``--aids off``: no non-holonomic constraint, no wheel odometry,
no GNSS velocity (the simulated runs carry Doppler velocities);
the stored study was measured so): the question is what the acceleration adds to the IMU and
the fixes. ``--aids on`` runs the study with the ground-vehicle aids every method applies by
default.

Usage::

    python bench/bench_acceleration_aiding.py --out study [--seeds 0-9] [--duration 300]
        [--methods ekf,ekf-acc,...] [--imu consumer,industrial,tactical] [--scenario ugv-slow,car]
        [--noise white,gm,precise,rtk] [--gnss-hz 1,5] [--outages none,60:20] [--jobs N] [--tune none] [--aids off|on]
"""

from __future__ import annotations

import argparse
import csv
import itertools
import json
import os
import statistics
import time
from pathlib import Path

from gnssacc import pipeline
from gnssacc.analysis import study
from gnssacc.analysis.montecarlo import parse_seeds
from gnssacc.campaign.batch import open_executor, run_campaign
from gnssacc.campaign.campaign import CAMPAIGN_FILE, Campaign, Pattern, make_settings
from gnssacc.sources.gnss_noise import PROFILES

CANDIDATES = (
    "ekf",
    "ekf-acc",
    "ekf-accw",
    "ekf-gm",
    "smoother",
    "smoother-acc",
    "smoother-accw",
    "smoother-gm",
)
GM_METHODS = ("ekf-gm", "smoother-gm")
STUDY_COLUMNS = [
    *study.CELL_KEYS,
    "method",
    "seed",
    "status",
    "error",
    "prmse_m",
    "hrmse_m",
    *study.FIGURES[1:],
    "nis",
    "runtime_s",
    "task_s",
]


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--out", default="bench-out/acceleration-aiding")
    p.add_argument("--seeds", default="0-9")
    p.add_argument("--duration", type=float, default=300.0)
    p.add_argument("--methods", default=",".join(m for m in CANDIDATES if m in pipeline.METHODS))
    p.add_argument("--imu", default="consumer,industrial,tactical")
    p.add_argument("--scenario", default="ugv-slow,car")
    p.add_argument("--noise", default="white,gm,precise,rtk")
    p.add_argument("--gnss-hz", default="1,5")
    p.add_argument(
        "--outages", default="none,60:20", help="'none' and/or PERIOD:LEN (--outage-every)"
    )
    p.add_argument(
        "--jobs", type=int, default=1, help="1: this process; N: a local Dask cluster of N workers"
    )
    p.add_argument("--tune", default="none", choices=["none", "auto"])
    p.add_argument(
        "--aids",
        default="off",
        choices=["off", "on"],
        help="off: the paper's setting (no non-holonomic constraint, no odometry, no GNSS "
        "velocity)",
    )
    return p.parse_args(argv)


def aids_config(args) -> str | None:
    """A configuration file turning the ground-vehicle aids and the GNSS velocity off (``--aids
    off``), else None."""
    if args.aids == "on":
        return None
    path = Path(args.out) / "aids-off.toml"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(
        "[nhc]\nenabled = false\n\n[odometry]\nenabled = false\n\n[velocity]\nenabled = false\n"
    )
    return str(path)


def specs(args) -> dict[str, dict]:
    """``{sim: spec: its cell settings}`` of the grid (without noise and outages)."""
    out = {}
    for imu, scen, hz in itertools.product(
        args.imu.split(","), args.scenario.split(","), args.gnss_hz.split(",")
    ):
        spec = f"sim:{scen},imu={imu},gnss_hz={hz},duration={args.duration:g}"
        out[spec] = {"imu": imu, "scenario": scen, "gnss_hz": hz}
    return out


def methods_for(noise: str, methods: list[str], tune: str) -> list[str]:
    """The methods of one noise profile's campaign: the ``-gm`` ones only where they have parameters."""
    has_gm = any(PROFILES[noise]["gm_sigma"] > 0)
    return [m for m in methods if m not in GM_METHODS or has_gm or tune == "auto"]


def run_noise(args, noise: str, grid: dict) -> Path:
    """Run (or resume) the campaign of one noise profile; return its folder."""
    patterns = [Pattern() if o == "none" else Pattern(None, o) for o in args.outages.split(",")]
    methods = methods_for(noise, args.methods.split(","), args.tune)
    settings = make_settings(
        list(grid),
        methods,
        parse_seeds(args.seeds),
        patterns,
        noise=noise,
        tune=args.tune,
        plots=False,
        config=aids_config(args),
    )
    root = Path(args.out) / f"noise-{noise}"
    if (root / CAMPAIGN_FILE).exists():
        camp = Campaign.open(root)
        if camp.hash != Campaign(root, settings).hash:
            raise SystemExit(f"{root} holds a campaign with other settings; choose another --out")
    else:
        camp = Campaign.create(root, settings)
    with camp:
        run_campaign(camp, open_executor(args.jobs, None), lines=False)
    return root


def study_rows(root: Path, noise: str, grid: dict) -> list[dict]:
    """The campaign's ``summary.csv`` rows as study rows (cell settings instead of the folder name)."""
    names = {
        name: spec
        for name, spec in json.loads((root / CAMPAIGN_FILE).read_text())["settings"]["sources"]
    }
    with open(root / "summary.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    out = []
    for r in rows:
        if r["method"] == "gnss":
            continue
        cell = {"noise": noise, **grid[names[r["source"]]], "outages": r["outages"]}
        out.append({**cell, **{k: r.get(k, "") for k in STUDY_COLUMNS if k not in cell}})
    return out


def print_timing(rows: list[dict]) -> None:
    """Median task time per scenario, IMU grade and rate (each task once: its first method row)."""
    tasks: dict = {}
    for r in rows:
        key = (r["scenario"], r["imu"], r["gnss_hz"])
        tasks.setdefault(key, {}).setdefault(
            (r["noise"], r["outages"], r["seed"]), float(r["task_s"] or "nan")
        )
    print(
        f"\ntime per task (all methods, median over tasks), load average now {os.getloadavg()[0]:.2f} "
        f"on {os.cpu_count()} cores:"
    )
    runtimes: dict = {}
    for r in rows:
        if r["runtime_s"]:
            runtimes.setdefault((r["scenario"], r["imu"], r["gnss_hz"]), {}).setdefault(
                r["method"], []
            ).append(float(r["runtime_s"]))
    for key, times in sorted(tasks.items()):
        per = ", ".join(
            f"{m} {statistics.median(v):.1f}"
            for m, v in runtimes.get(key, {}).items()
            if not m.endswith("-online")
        )
        print(
            f"  {key[0]:9s} {key[1]:11s} {key[2]:>3s} Hz: {statistics.median(times.values()):6.1f} s "
            f"({len(times)} tasks; method wall times [s]: {per})"
        )


def main(argv=None) -> None:
    args = parse_args(argv)
    grid = specs(args)
    Path(args.out).mkdir(parents=True, exist_ok=True)
    print(
        f"grid: {len(grid)} runs x {len(args.outages.split(','))} outage patterns x "
        f"{len(parse_seeds(args.seeds))} seeds per noise profile; load average {os.getloadavg()[0]:.2f}"
    )
    rows = []
    for noise in args.noise.split(","):
        t0 = time.perf_counter()
        root = run_noise(args, noise, grid)
        rows += study_rows(root, noise, grid)
        print(f"noise {noise}: {root} ({time.perf_counter() - t0:.0f} s)", flush=True)
    with open(Path(args.out) / "study.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, STUDY_COLUMNS)
        w.writeheader()
        w.writerows(rows)
    eff = study.effects(rows)
    print("\n" + study.format_effects(eff))
    print("\n" + study.verdict(eff))
    print_timing(rows)
    print(f"\nstudy: {Path(args.out) / 'study.csv'} ({len(rows)} rows)")


if __name__ == "__main__":
    main()
