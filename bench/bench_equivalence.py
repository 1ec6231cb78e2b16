"""Same results before and after a refactor: the same runs with two gnssacc installations.

Runs each case with ``--before`` and ``--after`` (two ``gnssacc`` executables, e.g. a frozen
checkout's venv and the working tree's), then compares, per case, the printed table (the timing
columns masked) and every figure of ``metrics.json`` (timing fields excepted), and prints both
tables and the largest relative difference.

Cases (``--cases``, comma-separated; default all that can run):

* ``kitti``: ``gnssacc run --no-plots`` (the KITTI sequence in the gtsam wheel, default methods);
* ``ugv``: a simulated UGV with wheel odometry (``gnssacc sim --scenario ugv --grade consumer
  --odom-rate 10 --duration 300 --seed 1``, made once with ``--before``) with outages
  (``--outage-every 60:20``);
* ``comma``: a CSV run directory (``--comma DIR``, e.g. the comma2k19 example as a CSV run);
* ``kitti-all``, ``ugv-all``: the same with every acceleration form and the ``-gm`` methods
  (``--methods`` :data:`ALL_METHODS`).

Exit status 1 when a table differs or a figure differs by more than ``--rtol`` (default 1e-9).

Usage::

    python bench/bench_equivalence.py --before /path/venv/bin/gnssacc --after gnssacc \\
        --comma /path/commadir [--cases kitti,ugv] [--work DIR] [--reuse-before]
"""

from __future__ import annotations

import argparse
import json
import math
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ALL_METHODS = "ekf,ekf-acc,ekf-accw,smoother,smoother-acc,smoother-accw,ekf-gm,smoother-gm"
#: metrics.json keys that are wall-clock measurements (compared for presence only).
TIMING_KEYS = {"runtime_s", "realtime_factor", "jit_compile_s", "identify_s", "seconds"}
#: Table columns that are wall-clock measurements.
TIMING_COLUMNS = ("wall [s]", "real-time x")
SIM = "sim --scenario ugv --grade consumer --odom-rate 10 --duration 300 --seed 1".split()


def cases(args, work: Path) -> dict[str, list[str]]:
    """``{case: gnssacc arguments before --out}``."""
    ugv = work / "simugv"
    out = {
        "kitti": ["run"],
        "ugv": ["run", str(ugv), "--outage-every", "60:20"],
        "kitti-all": ["run", "--methods", ALL_METHODS],
        "ugv-all": ["run", str(ugv), "--outage-every", "60:20", "--methods", ALL_METHODS],
    }
    if args.comma:
        out["comma"] = ["run", str(args.comma)]
    return out


def run_case(exe: str, argv: list[str], out: Path) -> str:
    """Run one case into ``out`` and return its printed output (stdout)."""
    if out.exists():
        shutil.rmtree(out)
    cmd = [exe, *argv, "--out", str(out), "--no-plots"]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed ({proc.returncode}):\n{proc.stderr[-2000:]}")
    return proc.stdout


def masked_table(text: str, out: str = "") -> list[str]:
    """The printed lines with the wall-clock figures masked: the table's timing columns (their
    place found from its header), ``done in .. s``, the tuner's and the JIT's seconds, and the
    output folder's path (``out``)."""
    lines = [
        line.replace(out, "OUT") if out else line
        for line in text.splitlines()
        if line.strip() and not line.startswith(("gnssacc: first run", "(one-off JIT", "results: "))
    ]
    head = next((i for i, line in enumerate(lines) if line.startswith("method ")), None)
    cut = None
    if head is not None:
        cut = min(lines[head].index(c) - 2 for c in TIMING_COLUMNS if c in lines[head])
    masked = []
    for i, line in enumerate(lines):
        if cut is not None and i >= head and line[:1].isalnum() and " " in line[:cut]:
            line = line[:cut].rstrip() if not line.startswith(("PRMSE", "NEES", "NIS")) else line
        line = re.sub(r"done in [0-9.]+ s", "done in # s", line)
        line = re.sub(r"passes, [0-9.]+ s\)", "passes, # s)", line)
        masked.append(line)
    return masked


def flatten(x, path: str = "") -> dict:
    """``{path: leaf}`` of a JSON document."""
    if isinstance(x, dict):
        out = {}
        for k, v in x.items():
            out.update(flatten(v, f"{path}/{k}"))
        return out
    if isinstance(x, list):
        out = {}
        for i, v in enumerate(x):
            out.update(flatten(v, f"{path}[{i}]"))
        return out
    return {path: x}


def is_timing(path: str) -> bool:
    return any(part.split("[")[0] in TIMING_KEYS for part in path.split("/"))


def compare_metrics(a: dict, b: dict) -> tuple[float, str, list[str]]:
    """Largest relative difference of the numbers, where, and the other differences."""
    fa, fb = flatten(a), flatten(b)
    worst, where, other = 0.0, "", []
    for key in sorted(set(fa) | set(fb)):
        if key not in fa or key not in fb:
            other.append(f"{key}: only {'after' if key in fb else 'before'}")
            continue
        if is_timing(key):
            continue
        x, y = fa[key], fb[key]
        if key.endswith("/where") and Path(str(x)).name == Path(str(y)).name:
            continue  # a file of the installation (KITTI in the gtsam wheel): its folder differs
        if isinstance(x, (int, float)) and isinstance(y, (int, float)) and not isinstance(x, bool):
            if math.isnan(x) and math.isnan(y):
                continue
            d = abs(x - y) / max(abs(x), abs(y), 1e-300) if x != y else 0.0
            if d > worst:
                worst, where = d, key
        elif x != y:
            other.append(f"{key}: {str(x)[:80]!r} -> {str(y)[:80]!r}")
    return worst, where, other


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--before", required=True, help="gnssacc executable of the reference")
    ap.add_argument("--after", default="gnssacc", help="gnssacc executable under test")
    ap.add_argument("--comma", type=Path, help="a CSV run directory (the comma2k19 example)")
    ap.add_argument("--cases", help="comma-separated subset of the cases")
    ap.add_argument("--work", type=Path, help="working folder (default: a temporary one)")
    ap.add_argument(
        "--reuse-before", action="store_true", help="keep the reference's results from --work"
    )
    ap.add_argument("--rtol", type=float, default=1e-9)
    args = ap.parse_args()
    work = args.work or Path(tempfile.mkdtemp(prefix="equivalence_"))
    work.mkdir(parents=True, exist_ok=True)
    all_cases = cases(args, work)
    chosen = args.cases.split(",") if args.cases else list(all_cases)
    if any(c.startswith("ugv") for c in chosen) and not (work / "simugv" / "imu.csv").exists():
        subprocess.run([args.before, *SIM, str(work / "simugv")], check=True, capture_output=True)
    failed = False
    for name in chosen:
        argv = all_cases[name]
        texts = {}
        for side, exe in (("before", args.before), ("after", args.after)):
            out = work / f"{name}-{side}"
            saved = work / f"{name}-{side}.txt"
            if side == "before" and args.reuse_before and saved.exists():
                texts[side] = saved.read_text()
                continue
            texts[side] = run_case(exe, argv, out)
            saved.write_text(texts[side])
        print(f"=== {name}: gnssacc {' '.join(argv)} --no-plots")
        for side in ("before", "after"):
            table = (work / f"{name}-{side}" / "table.txt").read_text()
            print(f"--- {side}\n{table.rstrip()}")
        tables_same = masked_table(
            (work / f"{name}-before" / "table.txt").read_text()
        ) == masked_table((work / f"{name}-after" / "table.txt").read_text())
        printed = {
            side: masked_table(texts[side], str(work / f"{name}-{side}"))
            for side in ("before", "after")
        }
        printed_same = printed["before"] == printed["after"]
        worst, where, other = compare_metrics(
            json.loads((work / f"{name}-before" / "metrics.json").read_text()),
            json.loads((work / f"{name}-after" / "metrics.json").read_text()),
        )
        ok = tables_same and printed_same and worst <= args.rtol and not other
        failed |= not ok
        print(
            f"--- {name}: table {'identical' if tables_same else 'DIFFERS'} (timing columns "
            f"masked), printed output {'identical' if printed_same else 'DIFFERS'}; largest "
            f"relative difference in metrics.json {worst:.3g}{f' at {where}' if where else ''}"
            f"; {len(other)} other differences -> {'OK' if ok else 'FAIL'}"
        )
        for line in other[:20]:
            print(f"    {line}")
        if not printed_same:
            for x, y in zip(printed["before"], printed["after"], strict=False):
                if x != y:
                    print(f"    before: {x}\n    after:  {y}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
