"""The whole ``gnssacc run`` on KITTI against the plain GTSAM script doing the core of the same job.

Fresh processes, interleaved rounds (so that a slow phase of the machine hits every case alike),
warm numba cache and bytecode (:func:`child_env`): the plain script (``bench/plain_gtsam_kitti.py``: load, fixed-lag smoother,
print; with and without per-node sigmas), the default ``gnssacc run`` (four methods, input
checks, noise tuning, files and figures), ``gnssacc run --methods ekf,smoother,smoother-acc
--no-plots`` and the rerun ``--methods ekf,smoother --no-plots``. Prints per case the median
wall time of the whole process (start to exit), the time to the table, and the ratio to the
plain script.

The gnssacc cases prepare afresh (``--retune``) but for the rerun, which reuses the preparation
kept by the others (``$GNSSACC_CACHE_DIR``, a folder of the bench's own). Then the acceptance of
issue 35 (each against the plain script).

The floor of any gnssacc run (:data:`FLOOR`, interleaved likewise): imports, the ekf and smoother
kernels loaded from the cache, the KITTI files read; nothing estimated.

``--breakdown`` adds one instrumented run per gnssacc case: where the time goes, from the start
of the process (interpreter and imports, data, each preparation stage, the methods, scoring,
table, files, figures, exit).

Usage::

    python bench/bench_whole_run.py [--repeats 5] [--breakdown]
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
#: The gnssacc cases: prepared afresh (``--retune``), and a rerun reusing the kept preparation.
RUNS = {
    "default run": ["run", "--overwrite", "--retune"],
    "ekf,smoother,smoother-acc --no-plots": [
        "run",
        "--overwrite",
        "--retune",
        "--methods",
        "ekf,smoother,smoother-acc",
        "--no-plots",
    ],
    "rerun ekf,smoother --no-plots (kept)": [
        "run",
        "--overwrite",
        "--methods",
        "ekf,smoother",
        "--no-plots",
    ],
}
#: The issue's acceptance (issue 35): ``(case, "table" or "end", most x plain)``.
TARGETS = (
    ("default run", "table", 4.0),
    ("default run", "end", 6.0),
    ("ekf,smoother,smoother-acc --no-plots", "end", 4.0),
    ("rerun ekf,smoother --no-plots (kept)", "end", 2.5),
)
PLAIN = {"plain gtsam script": [], "plain gtsam script + sigmas": ["--sigmas"]}
#: The floor of any ``gnssacc run`` of ``ekf,smoother`` on KITTI: a process that imports gnssacc,
#: loads the compiled kernels those methods need and reads the KITTI files, and estimates nothing.
FLOOR = (
    "from gnssacc import cli, pipeline\n"
    "from gnssacc.estimators import kernels\n"
    "for g in kernels.groups_for(['ekf', 'smoother']):\n"
    "    kernels.compile_group(g)\n"
    "pipeline.load('kitti')\n"
)


def child_env() -> dict:
    """The cases' environment: one BLAS thread, and Python's bytecode kept as a default Python
    and ``pip install`` keep it (a shell with ``PYTHONDONTWRITEBYTECODE`` set would make every
    gnssacc process compile its ~90 modules again, ~0.3 s that an installed gnssacc does not pay;
    the warm-up run writes the bytecode of an editable install)."""
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    return env


def timed(cmd: list[str]) -> dict:
    """Seconds to the table's header line (gnssacc) and to the exit of one process."""
    t0 = time.perf_counter()
    p = subprocess.Popen(
        cmd,
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
        env=child_env(),
    )
    table = None
    for line in p.stdout:
        if table is None and re.match(r"method\s+PRMSE", line):
            table = time.perf_counter() - t0
    if p.wait() != 0:
        raise SystemExit(f"{' '.join(cmd)} failed with exit code {p.returncode}")
    return {"table": table, "end": time.perf_counter() - t0}


#: An instrumented ``gnssacc run``: times the stages from the process start and prints them.
BREAKDOWN_CHILD = r"""
import json, os, sys, time
t_start = time.perf_counter()
marks = []
def mark(name):
    marks.append((name, time.perf_counter() - t_start))
import gnssacc.cli as cli
mark("imports (cli)")
import gnssacc.api as api, gnssacc.pipeline as pipeline

def wrap(mod, name, label):
    real = getattr(mod, name)
    def inner(*a, **k):
        mark(label + " start")
        out = real(*a, **k)
        mark(label + " end")
        return out
    setattr(mod, name, inner)

wrap(api, "load", "data")
wrap(pipeline, "prepare", "preparation")
wrap(pipeline, "run_methods", "methods")
wrap(pipeline, "compare", "compare")
wrap(cli, "_print_summary", "table")
wrap(api, "write_result", "files")
wrap(pipeline, "draw_figures", "figures")
code = cli.main(sys.argv[1:])
mark("main returned")
print(json.dumps(marks), file=sys.stderr, flush=True)
sys.stdout.flush()
os._exit(code)
"""


def breakdown(name: str, args: list[str], out_dir: str) -> None:
    t0 = time.perf_counter()
    p = subprocess.run(
        [sys.executable, "-c", BREAKDOWN_CHILD, *args, "--out", out_dir],
        capture_output=True,
        text=True,
        env=child_env(),
    )
    end = time.perf_counter() - t0
    marks = dict(json.loads(p.stderr.strip().splitlines()[-1]))
    metrics = json.loads((Path(out_dir) / "metrics.json").read_text())
    prep = metrics["identify_s"]
    rows = [("interpreter, imports, arguments", marks["data start"])]
    rows.append(("data (KITTI files)", marks["data end"] - marks["data start"]))
    rows.append(("imports until the preparation", marks["preparation start"] - marks["data end"]))
    for key in (
        "cache_load_s",
        "input_checks_s",
        "quality_and_stationary_s",
        "initialisation_s",
        "tuning_s",
        "model_check_s",
    ):
        if key in prep:
            rows.append((f"  preparation: {key.removesuffix('_s').replace('_', ' ')}", prep[key]))
    rows.append(("preparation (all)", marks["preparation end"] - marks["preparation start"]))
    rows.append(("model check, kernels wait", marks["methods start"] - marks["preparation end"]))
    for m, v in metrics["methods"].items():
        if not m.endswith("-online") and v.get("runtime_s") is not None:
            rows.append((f"  method {m}", v["runtime_s"]))
    rows.append(("methods (all)", marks["methods end"] - marks["methods start"]))
    rows.append(("scoring, consistency", marks["compare end"] - marks["methods end"]))
    rows.append(("until the table is printed", marks["table end"] - marks["compare end"]))
    figures = marks.get("figures end", 0) - marks.get("figures start", 0)
    rows.append(("files (without figures)", marks["files end"] - marks["files start"] - figures))
    rows.append(("figures", figures))
    rows.append(("exit", end - marks["main returned"]))
    print(
        f"\n{name}: where the time goes (one instrumented run, whole process {end:.2f} s; "
        f"the table at {marks['table end']:.2f} s)"
    )
    for label, sec in rows:
        print(f"  {label:40s} {sec:6.2f} s")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--breakdown", action="store_true")
    args = ap.parse_args()
    rows: dict[str, list] = {}
    load0 = os.getloadavg()
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "out")
        os.environ["GNSSACC_CACHE_DIR"] = os.path.join(tmp, "prepared")  # the bench's own
        timed(
            [sys.executable, "-m", "gnssacc.cli", *RUNS["default run"], "--out", out]
        )  # a warm cache
        for r in range(args.repeats):
            for name, extra in PLAIN.items():
                rows.setdefault(name, []).append(
                    timed([sys.executable, str(HERE / "plain_gtsam_kitti.py"), *extra])
                )
            for name, extra in RUNS.items():
                rows.setdefault(name, []).append(
                    timed([sys.executable, "-m", "gnssacc.cli", *extra, "--out", out])
                )
            rows.setdefault("floor: imports, kernels, data", []).append(
                timed([sys.executable, "-c", FLOOR])
            )
            print(f"round {r + 1}/{args.repeats} done", file=sys.stderr)
        load1 = os.getloadavg()
        print(
            f"KITTI, fresh process each, median of {args.repeats} interleaved rounds; load average "
            f"{load0[0]:.1f} at the start, {load1[0]:.1f} at the end, on {os.cpu_count()} cores; "
            "bytecode kept (PYTHONDONTWRITEBYTECODE of this shell not passed on)"
        )
        plain = {n: float(np.median([v["end"] for v in rows[n]])) for n in PLAIN}
        print(
            f"{'case':40s} {'exit [s]':>9s} {'table [s]':>10s} {'x plain':>8s} {'x plain+sigmas':>15s}"
        )
        for name, vals in rows.items():
            end = float(np.median([v["end"] for v in vals]))
            table = (
                np.median([v["table"] for v in vals])
                if vals[0]["table"] is not None
                else float("nan")
            )
            print(
                f"{name:40s} {end:9.2f} {table:10.2f} {end / plain['plain gtsam script']:8.2f} "
                f"{end / plain['plain gtsam script + sigmas']:15.2f}"
            )
        print("\nacceptance (issue 35), x the plain gtsam script:")
        for name, when, most in TARGETS:
            x = float(np.median([v[when] for v in rows[name]])) / plain["plain gtsam script"]
            verdict = "ok" if x <= most else "NOT MET"
            print(f"  {name:40s} {when:5s} {x:5.2f}x (target <= {most:g}x) {verdict}")
        if args.breakdown:
            for name, extra in RUNS.items():
                breakdown(name, extra, out)


if __name__ == "__main__":
    main()
