"""Two ``bench_consistency.py --json`` files side by side: one method's figures per case.

Per case: PRMSE [m], position NEES and attitude NEES (median over the seeds), before -> after,
and the PRMSE change [%]; at the end the median change and its range over the cases.

    python bench/compare_consistency.py BEFORE.json AFTER.json [--method smoother]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np


def medians(seeds: list, method: str) -> dict:
    """The median over seeds of a case's PRMSE, position and attitude NEES (NaN where absent)."""
    rows = [s[method] for s in seeds if s.get(method)]
    return {
        key: float(np.median([np.nan if r[key] is None else r[key] for r in rows]))
        for key in ("prmse", "nees_pos", "nees_att")
    }


def pair(b: dict, c: dict, key: str) -> str:
    """``before->after`` of one figure, ``-`` where the case has none."""
    return f"{b[key]:.2f}->{c[key]:.2f}" if np.isfinite(b[key]) else "-"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("before")
    ap.add_argument("after")
    ap.add_argument("--method", default="smoother")
    a = ap.parse_args()
    before, after = (json.loads(Path(f).read_text()) for f in (a.before, a.after))
    changes = []
    print(f"{'case':36s} {'PRMSE [m]':>14s} {'change':>7s} {'NEES pos':>12s} {'NEES att':>14s}")
    for case in before:
        if case not in after:
            continue
        b, c = medians(before[case], a.method), medians(after[case], a.method)
        pct = 100 * (c["prmse"] / b["prmse"] - 1) if b["prmse"] > 0 else np.nan
        if np.isfinite(pct):
            changes.append(pct)
        change = f"{pct:+.1f}%" if np.isfinite(pct) else "-"
        print(
            f"{case:36s} {pair(b, c, 'prmse'):>14s} {change:>7s} {pair(b, c, 'nees_pos'):>12s} "
            f"{pair(b, c, 'nees_att'):>14s}"
        )
    if changes:
        print(
            f"PRMSE change over {len(changes)} cases: median {np.median(changes):+.1f} %, "
            f"range {min(changes):+.1f} .. {max(changes):+.1f} %"
        )


if __name__ == "__main__":
    main()
