"""Cold start: time to the first output of ``gnssacc run`` (default KITTI) and ``gnssacc --help``.

Each run is a fresh process. *cold*: an empty numba cache folder (``NUMBA_CACHE_DIR``), as after
an install that compiled nothing; *warm*: the same folder again, now filled. Prints, per case, the
medians over the repeats (interleaved) of: the first line on the terminal (the compile notice when
there is one), the first result (the table's header line) and the end of the process, plus the
one-off compilation the run reports. ``--ref-src`` runs the same cases with another source tree
(e.g. ``git archive <commit> src | tar -x -C /tmp/ref``) on ``PYTHONPATH``, for a before/after ratio.

``--fresh-venv`` measures what a new user meets instead: a new virtual environment, ``pip install``
of this repository (timed; packages come from pip's cache or the registry; ``setup.py`` compiles
the kernels into the wheel), then ``gnssacc run`` from that environment, the kernels cached where a
user's are (the installed package's ``__pycache__``). Cases, interleaved: *first* (the package's
``__pycache__`` put back as the install left it: the first run after ``pip install``), *warm* (the
same again), and *no-kernels* (every cached kernel deleted: a first run when the install could not
compile them, e.g. a wheel from another machine). ``--install-only`` times the install with and
without the kernels (``GNSSACC_BUILD_KERNELS=0``) instead.

Usage::

    python bench/bench_cold_start.py [--repeats 3] [--ref-src /tmp/ref/src]
    python bench/bench_cold_start.py --fresh-venv [--repeats 3] [--plots]
    python bench/bench_cold_start.py --fresh-venv --install-only [--repeats 2]
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]

RUN = ["-m", "gnssacc.cli", "run", "--no-plots", "--overwrite"]


def timed(args: list[str], env: dict, python: str = sys.executable) -> dict:
    """Seconds from the start to the first line, the table header and the exit of one process."""
    t0 = time.perf_counter()
    p = subprocess.Popen(
        [python, *args], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env
    )
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


def fresh_venv(tmp: str, env: dict | None = None) -> tuple[str, float]:
    """A new virtual environment with a fresh copy of this repository installed (as a user's clone:
    no build folder, no cached kernels); its python and the seconds taken by venv and install."""
    import shutil

    src = os.path.join(tmp, "src")
    shutil.copytree(
        REPO,
        src,
        ignore=shutil.ignore_patterns(".git", "build", "*.egg-info", "__pycache__", "*.pyc"),
    )
    t0 = time.perf_counter()
    venv = os.path.join(tmp, "venv")
    subprocess.run([sys.executable, "-m", "venv", venv], check=True)
    python = os.path.join(venv, "bin", "python")
    subprocess.run([python, "-m", "pip", "install", "-q", src], check=True, env=env)
    return python, time.perf_counter() - t0


def kernel_files(python: str, env: dict) -> list[Path]:
    """The installed package's cached kernels (numba's index and data files)."""
    out = subprocess.run(
        [python, "-c", "from gnssacc.core import jit; print(jit.cache_folder())"],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    folder = Path(out.stdout.strip())
    return [f for pattern in ("**/*.nbi", "**/*.nbc") for f in folder.glob(pattern)]


def restore_kernels(python: str, env: dict, installed: dict[Path, bytes]) -> None:
    """Put the cached kernels back as ``installed`` holds them (empty: delete them all)."""
    for f in kernel_files(python, env):
        f.unlink()
    for f, data in installed.items():
        f.write_bytes(data)


def median_row(vals: list[dict]) -> dict:
    return {
        k: float(np.median([v[k] if v[k] is not None else np.nan for v in vals]))
        for k in ("first_line", "first_result", "end", "jit")
    }


def main_fresh_venv(repeats: int, plots: bool) -> None:
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "PYTHONPATH")}
    env["OMP_NUM_THREADS"] = "1"
    rows: dict[str, list] = {}
    run = RUN if not plots else [a for a in RUN if a != "--no-plots"]
    with tempfile.TemporaryDirectory() as tmp:
        python, install_s = fresh_venv(tmp, env)
        installed = {f: f.read_bytes() for f in kernel_files(python, env)}
        out_dir = os.path.join(tmp, "out")
        for r in range(repeats):
            restore_kernels(python, env, installed)
            rows.setdefault("first", []).append(timed(run + ["--out", out_dir], env, python))
            rows.setdefault("warm", []).append(timed(run + ["--out", out_dir], env, python))
            restore_kernels(python, env, {})
            rows.setdefault("no-kernels", []).append(timed(run + ["--out", out_dir], env, python))
            print(f"round {r + 1}/{repeats} done", file=sys.stderr)
    load = os.getloadavg()
    print(
        f"fresh virtual environment: pip install {REPO} took {install_s:.1f} s ({len(installed)} kernel cache "
        f"files installed); then gnssacc run (KITTI default{', with plots' if plots else ', --no-plots'}), "
        f"median of {repeats}; load average {load[0]:.1f} {load[1]:.1f} {load[2]:.1f} on {os.cpu_count()} cores"
    )
    print(
        f"{'case':11s} {'first line [s]':>15s} {'first result [s]':>17s} {'exit [s]':>9s} {'JIT [s]':>8s}"
    )
    med = {case: median_row(vals) for case, vals in rows.items()}
    for case, m in med.items():
        print(
            f"{case:11s} {m['first_line']:15.2f} {m['first_result']:17.2f} {m['end']:9.2f} {m['jit']:8.2f}"
        )
    for case in ("first", "no-kernels"):
        print(
            f"{case} / warm: exit {med[case]['end'] / med['warm']['end']:.2f}x, "
            f"first result {med[case]['first_result'] / med['warm']['first_result']:.2f}x"
        )


def main_install_only(repeats: int) -> None:
    """``pip install`` into a fresh environment, with and without the kernels compiled (interleaved)."""
    base = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "PYTHONPATH")}
    times: dict[str, list] = {}
    for r in range(repeats):
        for case, extra in (("with kernels", {}), ("without", {"GNSSACC_BUILD_KERNELS": "0"})):
            with tempfile.TemporaryDirectory() as tmp:
                times.setdefault(case, []).append(fresh_venv(tmp, {**base, **extra})[1])
        print(f"round {r + 1}/{repeats} done", file=sys.stderr)
    load = os.getloadavg()
    print(
        f"python -m venv + pip install {REPO}, median of {repeats}; load average {load[0]:.1f} {load[1]:.1f} "
        f"{load[2]:.1f} on {os.cpu_count()} cores"
    )
    for case, vals in times.items():
        print(f"{case:13s} {np.median(vals):6.1f} s  ({', '.join(f'{v:.1f}' for v in vals)})")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument(
        "--ref-src", default=None, help="another source tree to compare with (put on PYTHONPATH)"
    )
    ap.add_argument(
        "--fresh-venv", action="store_true", help="install into a new virtual environment first"
    )
    ap.add_argument(
        "--install-only", action="store_true", help="with --fresh-venv: time pip install alone"
    )
    ap.add_argument("--plots", action="store_true", help="with --fresh-venv: draw the figures too")
    args = ap.parse_args()
    if args.fresh_venv and args.install_only:
        return main_install_only(args.repeats)
    if args.fresh_venv:
        return main_fresh_venv(args.repeats, args.plots)
    trees = {"this": None} | ({"ref": args.ref_src} if args.ref_src else {})
    rows: dict[tuple, list] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(args.repeats):
            for name, src in trees.items():
                cache = tempfile.mkdtemp(dir=tmp)  # empty: as after pip install
                out_dir = os.path.join(tmp, f"out-{name}")
                for case in ("cold", "warm"):
                    rows.setdefault((name, case), []).append(
                        timed(RUN + ["--out", out_dir], env_for(src, cache))
                    )
                rows.setdefault((name, "--help"), []).append(
                    timed(["-m", "gnssacc.cli", "--help"], env_for(src, cache))
                )
            print(f"round {r + 1}/{args.repeats} done", file=sys.stderr)
    load = os.getloadavg()
    print(
        f"gnssacc run (KITTI default) and --help, fresh process each, median of {args.repeats} interleaved rounds; "
        f"load average {load[0]:.1f} {load[1]:.1f} {load[2]:.1f} on {os.cpu_count()} cores"
    )
    print(
        f"{'tree':5s} {'case':7s} {'first line [s]':>15s} {'first result [s]':>17s} {'exit [s]':>9s} {'JIT [s]':>8s}"
    )
    med = {}
    for (name, case), vals in rows.items():
        m = {
            k: (
                float(np.median([v[k] for v in vals]))
                if all(v[k] is not None for v in vals)
                else float("nan")
            )
            for k in ("first_line", "first_result", "end", "jit")
        }
        med[(name, case)] = m
        print(
            f"{name:5s} {case:7s} {m['first_line']:15.2f} {m['first_result']:17.2f} {m['end']:9.2f} {m['jit']:8.2f}"
        )
    if args.ref_src:
        for case in ("cold", "warm"):
            a, b = med[("ref", case)], med[("this", case)]
            print(
                f"{case}: first result ref/this {a['first_result'] / b['first_result']:.2f}x, "
                f"first line ref/this {a['first_line'] / b['first_line']:.2f}x"
            )


if __name__ == "__main__":
    main()
