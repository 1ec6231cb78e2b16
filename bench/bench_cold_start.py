"""Cold start: time to the first output of ``gnssacc run`` (default KITTI) and ``gnssacc --help``.

Each run is a fresh process. *cold*: an empty numba cache folder (``NUMBA_CACHE_DIR``), as after
``pip install .``; *warm*: the same folder again, now filled. Prints, per case, the medians over
the repeats (interleaved) of: the first line on the terminal (the compile notice when there is
one), the first result (the table's header line) and the end of the process, plus the one-off
compilation the run reports. ``--ref-src`` runs the same cases with another source tree (e.g.
``git archive <commit> src | tar -x -C /tmp/ref``) on ``PYTHONPATH``, for a before/after ratio.

Usage::

    python bench/bench_cold_start.py [--repeats 3] [--ref-src /tmp/ref/src]
"""
from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
import time

import numpy as np

RUN = ["-m", "gnssacc.cli", "run", "--no-plots", "--overwrite"]


def timed(args: list[str], env: dict) -> dict:
    """Seconds from the start to the first line, the table header and the exit of one process."""
    t0 = time.perf_counter()
    p = subprocess.Popen([sys.executable, *args], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env)
    out = {"first_line": None, "first_result": None, "jit": None}
    for line in p.stdout:
        now = time.perf_counter() - t0
        out["first_line"] = out["first_line"] or now
        if out["first_result"] is None and re.match(r"method\s+PRMSE", line):
            out["first_result"] = now
        m = re.search(r"one-off JIT compilation ([\d.]+) s", line)
        out["jit"] = float(m.group(1)) if m else out["jit"]
    if p.wait() != 0:
        raise SystemExit(f"{' '.join(args)} failed with exit code {p.returncode}")
    out["end"] = time.perf_counter() - t0
    return out


def env_for(src: str | None, cache: str) -> dict:
    env = {**os.environ, "NUMBA_CACHE_DIR": cache, "OMP_NUM_THREADS": "1"}
    if src:
        env["PYTHONPATH"] = src
    return env


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--ref-src", default=None, help="another source tree to compare with (put on PYTHONPATH)")
    args = ap.parse_args()
    trees = {"this": None} | ({"ref": args.ref_src} if args.ref_src else {})
    rows: dict[tuple, list] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(args.repeats):
            for name, src in trees.items():
                cache = tempfile.mkdtemp(dir=tmp)   # empty: as after pip install
                out_dir = os.path.join(tmp, f"out-{name}")
                for case in ("cold", "warm"):
                    rows.setdefault((name, case), []).append(timed(RUN + ["--out", out_dir], env_for(src, cache)))
                rows.setdefault((name, "--help"), []).append(timed(["-m", "gnssacc.cli", "--help"], env_for(src, cache)))
            print(f"round {r + 1}/{args.repeats} done", file=sys.stderr)
    load = os.getloadavg()
    print(f"gnssacc run (KITTI default) and --help, fresh process each, median of {args.repeats} interleaved rounds; "
          f"load average {load[0]:.1f} {load[1]:.1f} {load[2]:.1f} on {os.cpu_count()} cores")
    print(f"{'tree':5s} {'case':7s} {'first line [s]':>15s} {'first result [s]':>17s} {'exit [s]':>9s} {'JIT [s]':>8s}")
    med = {}
    for (name, case), vals in rows.items():
        m = {k: (float(np.median([v[k] for v in vals])) if all(v[k] is not None for v in vals) else float("nan"))
             for k in ("first_line", "first_result", "end", "jit")}
        med[(name, case)] = m
        print(f"{name:5s} {case:7s} {m['first_line']:15.2f} {m['first_result']:17.2f} {m['end']:9.2f} {m['jit']:8.2f}")
    if args.ref_src:
        for case in ("cold", "warm"):
            a, b = med[("ref", case)], med[("this", case)]
            print(f"{case}: first result ref/this {a['first_result'] / b['first_result']:.2f}x, "
                  f"first line ref/this {a['first_line'] / b['first_line']:.2f}x")


if __name__ == "__main__":
    main()
