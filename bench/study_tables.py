"""The tables (docs/science.md) of the acceleration-aiding study, from its stored rows.

Per GNSS quality and fix rate, for each variant against its baseline: the mean over the cells of
the paired change [%] of a figure, and in how many cells it is significantly better / worse
(:func:`gnssacc.analysis.study.classify`: false-discovery rate 5 % over the variant's cells); then the
median position NEES per dof of every method.

    python bench/study_tables.py [notebooks/data/acceleration_aiding/*.csv.gz]
"""

from __future__ import annotations

import glob
import sys

import numpy as np

from gnssacc.analysis import study

VARIANTS = ("ekf-acc", "ekf-accw", "ekf-gm", "smoother-acc", "smoother-accw", "smoother-gm")
METHODS = (
    "ekf",
    "ekf-acc",
    "ekf-accw",
    "ekf-gm",
    "smoother",
    "smoother-acc",
    "smoother-accw",
    "smoother-gm",
)
GRID = [(noise, hz) for noise in ("white", "gm", "precise", "rtk") for hz in ("1", "5")]
FIGURES = ("prmse_m", "prmse_outage_m", "tilt_rms_deg", "yaw_rms_deg", "bias_a_rms_mg")


def change_table(eff: list, figure: str) -> str:
    """Markdown: per (noise, rate) row and variant, ``mean% (better/worse of n)``."""
    groups = study.classify(eff, figure)
    lines = [
        f"{figure}: mean over cells of the paired change [%] (cells better / worse at FDR 5 %)",
        "| GNSS | rate | " + " | ".join(VARIANTS) + " |",
        "|---|---|" + "---|" * len(VARIANTS),
    ]
    for noise, hz in GRID:
        cells = []
        for v in VARIANTS:
            mine = {
                k: [e for e, _ in es if e.cell[0] == noise and e.cell[3] == hz]
                for k, es in groups.get(v, {}).items()
            }
            n = sum(len(es) for es in mine.values())
            mean = np.mean([e.mean_pct for es in mine.values() for e in es]) if n else None
            cells.append(
                "–" if not n else f"{mean:+.1f} ({len(mine['helps'])}/{len(mine['hurts'])} of {n})"
            )
        lines.append(f"| {noise} | {hz} Hz | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def nees_table(rows: list) -> str:
    """Markdown: median position NEES per dof per (noise, rate) and method."""
    nees: dict = {}
    for r in rows:
        if r["status"] == "ok" and r.get("nees_pos"):
            nees.setdefault((r["noise"], r["gnss_hz"], r["method"]), []).append(
                float(r["nees_pos"])
            )
    lines = ["| GNSS | rate | " + " | ".join(METHODS) + " |", "|---|---|" + "---|" * len(METHODS)]
    for noise, hz in GRID:
        lines.append(
            f"| {noise} | {hz} Hz | "
            + " | ".join(
                f"{np.median(nees[(noise, hz, m)]):.2f}" if (noise, hz, m) in nees else "–"
                for m in METHODS
            )
            + " |"
        )
    return "\n".join(lines)


def main() -> None:
    paths = sys.argv[1:] or sorted(glob.glob("notebooks/data/acceleration_aiding/*.csv.gz"))
    rows = study.read_rows(*paths)
    eff = study.effects(rows)
    for figure in FIGURES:
        print(change_table(eff, figure) + "\n")
    print("median position NEES per dof\n" + nees_table(rows))


if __name__ == "__main__":
    main()
