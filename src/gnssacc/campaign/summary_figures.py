"""The campaign's figures and ``summary.html``: what ``summary.md``'s tables say, drawn.

* ``summary_prmse.png``: a box plot of PRMSE per method over the campaign's tasks (one panel per
  outage pattern): the spread a single run hides.
* ``summary_effects.png``: a forest plot of the paired effect of each aided method over its baseline
  (``100 (baseline PRMSE - aided PRMSE) / baseline PRMSE`` per task [%], the table's ``acc gain``;
  positive = the aiding helped) with its 95 % confidence
  interval (Student t on the paired differences), per recording and over all recordings, per pattern,
  and the paired sign-flip p-value (:func:`gnssacc.analysis.montecarlo.paired_permutation_pvalue`).

Only tasks where every method succeeded and has a PRMSE (truth) are drawn.
"""

from __future__ import annotations

import html
from pathlib import Path

import numpy as np

from ..analysis.montecarlo import paired_permutation_pvalue
from ..outputs.report import BASELINES

FIGURES = ("summary_prmse.png", "summary_effects.png")


def prmse_by(records: list[dict]) -> dict:
    """``{pattern: {source: [{method: prmse_m}]}}`` of the complete tasks (every row ok, with truth)."""
    out: dict = {}
    for rec in records:
        rows = rec["rows"]
        if rec["status"] != "ok" or any(
            r["status"] != "ok" or r.get("prmse_m") is None for r in rows
        ):
            continue
        task = rec["task"]
        out.setdefault(task["outages"], {}).setdefault(task["source"], []).append(
            {r["method"]: float(r["prmse_m"]) for r in rows}
        )
    return out


def paired_effect(diff: np.ndarray) -> dict:
    """Mean of paired differences with its 95 % t interval and the sign-flip p-value."""
    from ..core.distributions import t_ppf

    n = len(diff)
    mean = float(np.mean(diff))
    half = float(t_ppf(0.975, n - 1) * np.std(diff, ddof=1) / np.sqrt(n)) if n > 1 else float("nan")
    return {
        "n": n,
        "mean": mean,
        "lo": mean - half,
        "hi": mean + half,
        "p": paired_permutation_pvalue(diff),
    }


def effects(data: dict) -> list[dict]:
    """One row per (pattern, cell, aided method): :func:`paired_effect` of the relative gain [%]."""
    rows = []
    for pattern, by_source in data.items():
        cells = list(by_source.items()) + (
            [("all recordings", [t for ts in by_source.values() for t in ts])]
            if len(by_source) > 1
            else []
        )
        for cell, tasks in cells:
            for m in tasks[0]:
                base = BASELINES.get(m)
                if base in tasks[0] and not m.endswith("-online"):
                    diff = np.array([100.0 * (t[base] - t[m]) / t[base] for t in tasks])
                    rows.append(
                        {
                            "pattern": pattern,
                            "cell": cell,
                            "method": m,
                            "baseline": base,
                            **paired_effect(diff),
                        }
                    )
    return rows


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_prmse(data: dict, path: Path) -> None:
    plt = _plt()
    fig, axes = plt.subplots(1, len(data), figsize=(max(6, 4.5 * len(data)), 4.8), squeeze=False)
    for ax, (pattern, by_source) in zip(axes[0], data.items()):
        tasks = [t for ts in by_source.values() for t in ts]
        methods = list(tasks[0])
        ax.boxplot([[t[m] for t in tasks] for m in methods], showmeans=True)
        ax.set_xticks(range(1, len(methods) + 1), methods, rotation=35, ha="right", fontsize=8)
        ax.set_ylabel("PRMSE [m]")
        ax.set_title(f"outages {pattern}: {len(tasks)} tasks", fontsize=10)
        ax.grid(alpha=0.3, axis="y")
    fig.suptitle("PRMSE per method over the campaign (box: quartiles, triangle: mean)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def plot_effects(rows: list[dict], path: Path) -> None:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(10, 1.4 + 0.38 * max(len(rows), 1)), layout="constrained")
    for k, r in enumerate(rows):
        sig = r["p"] < 0.05
        ax.plot([r["lo"], r["hi"]], [k, k], color="k" if sig else "0.55", lw=1.5)
        ax.plot(
            r["mean"],
            k,
            "o",
            color="tab:green" if r["mean"] > 0 else "tab:red",
            mfc=None if sig else "white",
            ms=7,
        )
    ax.axvline(0.0, color="k", lw=0.8)
    ax.set_yticks(
        range(len(rows)),
        [
            f"{r['method']} vs {r['baseline']} | {r['cell']} | {r['pattern']} "
            f"(n={r['n']}, p={r['p']:.3f})"
            for r in rows
        ],
        fontsize=8,
    )
    ax.invert_yaxis()
    ax.set_xlabel(
        "PRMSE gain [%] = 100 (baseline - aided) / baseline (> 0: the aiding helped), 95 % CI"
    )
    ax.set_title("Paired effect of each aiding (filled: p < 0.05, sign-flip test)")
    ax.grid(alpha=0.3, axis="x")
    fig.savefig(path, dpi=100)
    plt.close(fig)


def write_figures(root: Path, records: list[dict]) -> list[str]:
    """Write :data:`FIGURES` into ``root`` from the task records; returns the names written (none
    without a complete task with truth)."""
    data = prmse_by(records)
    if not data:
        return []
    plot_prmse(data, Path(root) / FIGURES[0])
    rows = effects(data)
    if not rows:
        return [FIGURES[0]]
    plot_effects(rows, Path(root) / FIGURES[1])
    return list(FIGURES)


def html_page(markdown: str, figures: list[str]) -> str:
    """``summary.html``: the figures first, then ``summary.md``'s text as it is."""
    imgs = "".join(f'<p><img src="{f}" alt="{f}" style="max-width:100%"></p>' for f in figures)
    return (
        f'<!doctype html><html><head><meta charset="utf-8"><title>gnssacc batch summary</title></head>'
        f'<body style="font-family:sans-serif;max-width:1100px;margin:1.5em auto"><h1>gnssacc batch: summary</h1>'
        f"{imgs}<pre>{html.escape(markdown)}</pre></body></html>\n"
    )
