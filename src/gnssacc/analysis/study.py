"""Paired analysis of an aiding study: each variant against its baseline, cell by cell.

A study is a table of rows (``study.csv``, written by ``bench/bench_acceleration_aiding.py``), one
per cell x method x seed, where a **cell** is one combination of the grid's settings (IMU grade,
scenario, GNSS noise and rate, outage pattern: :data:`CELL_KEYS`) and the seed draws the IMU
errors and the GNSS noise. Within a cell, a variant (``ekf-acc``, ``ekf-gm``, ...) and its
baseline (``ekf``, :func:`baseline_of`) ran on the very same data per seed, so the comparison is
paired: per seed the relative difference ``d = 100 (variant - baseline) / baseline`` [%] of a
figure (negative = smaller error), then over the seeds its mean, a 95 % percentile-bootstrap
interval of that mean and the exact or Monte-Carlo sign-flip p-value
(:func:`gnssacc.analysis.montecarlo.paired_permutation_pvalue`).

Works on plain rows (``csv.DictReader``), no pandas needed::

    from gnssacc.analysis import study
    rows = study.read_rows("study.csv")
    eff = study.effects(rows)
    print(study.format_effects(eff))
    print(study.verdict(eff))
"""

from __future__ import annotations

import csv
import gzip
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.stats import false_discovery_control

from .metrics import BASELINES
from .montecarlo import paired_permutation_pvalue

#: The settings that make a cell of the grid.
CELL_KEYS = ("noise", "imu", "scenario", "gnss_hz", "outages")
#: The figures compared (errors: smaller is better; ``nees_*``: 1 is consistent).
FIGURES = (
    "prmse_m",
    "prmse_outage_m",
    "tilt_rms_deg",
    "yaw_rms_deg",
    "bias_a_rms_mg",
    "bias_g_rms_deg_h",
    "nees_pos",
    "nees_att",
)
#: The error figures, for :func:`verdict`.
ERRORS = FIGURES[:6]


def baseline_of(method: str) -> str | None:
    """The baseline a method is compared with: :data:`gnssacc.analysis.metrics.BASELINES`, else ``ekf`` for
    ``ekf-*``, ``smoother-online`` for ``smoother-*-online``, ``smoother`` for ``smoother-*``;
    ``None`` for a baseline itself (and the raw fixes)."""
    if method in BASELINES:
        return BASELINES[method]
    if method.startswith("ekf-"):
        return "ekf"
    if method.startswith("smoother-") and method != "smoother-online":
        return "smoother-online" if method.endswith("-online") else "smoother"
    return None


def read_rows(*paths) -> list[dict]:
    """The rows of one or more ``study.csv`` files (``.csv.gz`` too), strings (empty cells ``""``).

    Studies run in parts (e.g. another method set on the same cells and seeds) are read together;
    a row repeated by several parts (a baseline run in each: the same simulated data, the same
    figures) is kept once, by its cell, method and seed.
    """
    out: dict = {}
    for path in paths:
        path = Path(path)
        opener = gzip.open if path.suffix == ".gz" else open
        with opener(path, "rt", newline="") as fh:
            for r in csv.DictReader(fh):
                out.setdefault((*(r[k] for k in CELL_KEYS), r["method"], r["seed"]), r)
    return list(out.values())


def bootstrap_ci(
    d: np.ndarray, n_boot: int = 10_000, level: float = 0.95, seed: int = 0
) -> tuple[float, float]:
    """Percentile-bootstrap interval of the mean of ``d`` (resampling its entries with replacement)."""
    d = np.asarray(d, float)
    rng = np.random.default_rng(seed)
    means = d[rng.integers(0, len(d), size=(n_boot, len(d)))].mean(axis=1)
    a = (1.0 - level) / 2.0
    return float(np.quantile(means, a)), float(np.quantile(means, 1.0 - a))


@dataclass
class Effect:
    """A variant against its baseline on one figure in one cell.

    Attributes
    ----------
    cell : tuple
        The values of :data:`CELL_KEYS`.
    variant, baseline, figure : str
    n : int
        Seeds with both values.
    baseline_mean, variant_mean : float
        Means over those seeds [the figure's unit].
    mean_pct : float
        Mean paired relative difference [%] (negative: the variant's figure is smaller).
    ci_low, ci_high : float
        95 % bootstrap interval of ``mean_pct`` [%].
    p : float
        Two-sided sign-flip p-value of ``mean_pct`` being zero.
    """

    cell: tuple
    variant: str
    baseline: str
    figure: str
    n: int
    baseline_mean: float
    variant_mean: float
    mean_pct: float
    ci_low: float
    ci_high: float
    p: float


def paired_effect(base: np.ndarray, var: np.ndarray, n_boot: int = 10_000) -> tuple | None:
    """``(n, mean_pct, ci_low, ci_high, p)`` of paired values (see :class:`Effect`); pairs with a
    missing or non-positive baseline are left out; ``None`` when fewer than two pairs remain."""
    base, var = np.asarray(base, float), np.asarray(var, float)
    ok = np.isfinite(base) & np.isfinite(var) & (base > 0)
    if ok.sum() < 2:
        return None
    d = 100.0 * (var[ok] - base[ok]) / base[ok]
    lo, hi = bootstrap_ci(d, n_boot)
    return int(ok.sum()), float(d.mean()), lo, hi, paired_permutation_pvalue(d)


def _value(row: dict, figure: str) -> float:
    text = row.get(figure, "")
    return float(text) if text not in ("", None) else np.nan


def effects(rows: list[dict], figures=FIGURES, n_boot: int = 10_000) -> list[Effect]:
    """Every variant against its baseline, per cell and figure (rows with ``status`` ``ok``)."""
    table: dict = {}
    for r in rows:
        if r.get("status", "ok") == "ok":
            table.setdefault(tuple(r[k] for k in CELL_KEYS), {}).setdefault(r["method"], {})[
                r["seed"]
            ] = r
    out = []
    for cell, by_method in table.items():
        for variant, runs in by_method.items():
            base = baseline_of(variant)
            if base not in by_method:
                continue
            seeds = sorted(set(runs) & set(by_method[base]), key=int)
            for fig in figures:
                b = np.array([_value(by_method[base][s], fig) for s in seeds])
                v = np.array([_value(runs[s], fig) for s in seeds])
                e = paired_effect(b, v, n_boot)
                if e is not None:
                    ok = np.isfinite(b) & np.isfinite(v) & (b > 0)
                    out.append(
                        Effect(
                            cell,
                            variant,
                            base,
                            fig,
                            e[0],
                            float(b[ok].mean()),
                            float(v[ok].mean()),
                            *e[1:],
                        )
                    )
    return out


def format_effects(eff: list[Effect], figures=FIGURES) -> str:
    """A text table: per cell and variant, each error figure's ``mean% [low, high] p`` and each
    NEES as ``baseline mean > variant mean`` (its distance from 1 matters, not its size)."""
    lines = [
        " | ".join(CELL_KEYS) + " | variant (n seeds) | " + " | ".join(figures),
        "(errors: mean paired difference to the baseline [%], 95 % bootstrap CI, sign-flip p; "
        "NEES per dof: baseline > variant means)",
    ]
    rows: dict = {}
    for e in eff:
        rows.setdefault((e.cell, e.variant, e.n), {})[e.figure] = e
    for (cell, variant, n), by_fig in sorted(rows.items()):
        cells = [_cell(by_fig[f]) if f in by_fig else "-" for f in figures]
        lines.append(" | ".join(cell) + f" | {variant} ({n}) | " + " | ".join(cells))
    return "\n".join(lines)


def _cell(e: Effect) -> str:
    if e.figure.startswith("nees"):
        return f"{e.baseline_mean:.2f} > {e.variant_mean:.2f}"
    return f"{e.mean_pct:+.1f} [{e.ci_low:+.1f},{e.ci_high:+.1f}] p={e.p:.3f}"


def classify(
    eff: list[Effect], figure: str = "prmse_m", alpha: float = 0.05
) -> dict[str, dict[str, list]]:
    """Per variant, its cells on ``figure`` as ``{"helps", "hurts", "same"}``: lists of ``(Effect,
    q)``. Significant means at false-discovery rate ``alpha`` over that variant's cells
    (Benjamini-Hochberg q-value below ``alpha``: a grid of a hundred cells would otherwise show
    about five "effects" at p < 0.05 by chance alone), with the bootstrap interval on one side of
    zero."""
    by: dict = {}
    for variant in sorted({e.variant for e in eff if e.figure == figure}):
        mine = [e for e in eff if e.figure == figure and e.variant == variant]
        q = false_discovery_control([e.p for e in mine], method="bh")
        kinds = {"helps": [], "hurts": [], "same": []}
        for e, qe in zip(mine, q):
            sig = qe < alpha
            kinds[
                "helps" if sig and e.ci_high < 0 else "hurts" if sig and e.ci_low > 0 else "same"
            ].append((e, qe))
        by[variant] = kinds
    return by


def verdict(eff: list[Effect], figure: str = "prmse_m", alpha: float = 0.05) -> str:
    """Which cells each variant helps or hurts on ``figure`` (:func:`classify`), as text."""
    lines = []
    for variant, kinds in classify(eff, figure, alpha).items():
        total = sum(len(v) for v in kinds.values())
        base = next(e.baseline for v in kinds.values() for e, _ in v)
        lines.append(
            f"{variant} vs {base} on {figure}: helps in {len(kinds['helps'])}, hurts in "
            f"{len(kinds['hurts'])}, no significant change in {len(kinds['same'])} of {total} cells "
            f"(false-discovery rate {alpha:g})"
        )
        for kind in ("helps", "hurts"):
            for e, qe in kinds[kind]:
                lines.append(
                    f"  {kind}: {'/'.join(e.cell)}: {e.mean_pct:+.1f} % [{e.ci_low:+.1f}, {e.ci_high:+.1f}] "
                    f"p={e.p:.4f} q={qe:.4f}"
                )
    return "\n".join(lines)
