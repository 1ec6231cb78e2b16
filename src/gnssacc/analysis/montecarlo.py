"""Statistics of a Monte-Carlo comparison over GNSS noise seeds (``gnssacc bench``, and the
tables of ``gnssacc batch``'s ``summary.md``); the runs themselves are :mod:`gnssacc.campaign.batch` tasks.

Each seed draws a new GNSS noise realisation on the same recorded run; every method runs on it.
The table reports mean, standard deviation, min and max PRMSE per method, and for each ``-acc``
method the mean paired improvement over its baseline with a paired significance test.

Significance: an exact two-sided sign-flip permutation test of the mean paired difference
(baseline minus aided PRMSE) — under the null hypothesis "aiding changes nothing" each paired
difference is symmetric about zero, so all 2^n sign patterns are equally likely (Fisher's
randomisation test; see Good, *Permutation, Parametric and Bootstrap Tests of Hypotheses*,
2005, ch. 3). Exact for n <= 20 seeds, 200,000 random sign patterns above that. It assumes no
normality, which PRMSE differences over a handful of seeds rarely justify.
"""

from __future__ import annotations

from collections import Counter

import numpy as np

from ..core.config_check import MAX_SEED
from ..core.display import text_table
from .metrics import BASELINES

#: Most sign patterns evaluated at once by :func:`paired_permutation_pvalue` (bounds its memory:
#: a block holds this many patterns times the number of pairs, as 8-byte integers).
SIGN_BLOCK_ENTRIES = 1 << 22


def paired_permutation_pvalue(diff: np.ndarray, n_random: int = 200_000, seed: int = 0) -> float:
    """Two-sided p-value of the mean of paired differences ``diff`` being zero (sign-flip test).

    The sign patterns are evaluated in blocks of at most :data:`SIGN_BLOCK_ENTRIES` entries, so
    a campaign's pooled test over thousands of pairs needs tens of MB, not GB; the random
    patterns are drawn block after block from one generator, the same stream as in one draw.
    """
    d = np.asarray(diff, float)
    d = d[np.isfinite(d)]
    n = d.size
    if n == 0 or np.all(d == 0):
        return 1.0
    observed = abs(d.mean())
    total = 2**n if n <= 20 else n_random
    rng = None if n <= 20 else np.random.default_rng(seed)
    step = max(SIGN_BLOCK_ENTRIES // n, 1)
    hits = 0
    for start in range(0, total, step):
        if rng is None:
            index = np.arange(start, min(start + step, total))
            signs = ((index[:, None] >> np.arange(n)) & 1) * 2 - 1
        else:
            signs = rng.choice([-1, 1], size=(min(step, total - start), n))
        hits += int(np.sum(np.abs(signs @ d) / n >= observed - 1e-12))
    return hits / total


#: Most seeds one bench runs.
MAX_SEEDS = 1000


def parse_seeds(text: str) -> list[int]:
    """Seeds from ``"0-19"``, ``"3"`` or ``"1,4,7"``.

    Raises
    ------
    ValueError
        Saying what is wrong: unreadable part, empty range, a seed twice or out of
        ``0..MAX_SEED``, no seed, more than :data:`MAX_SEEDS` seeds.
    """
    out: list[int] = []
    for part in (p.strip() for p in str(text).split(",")):
        if not part:
            continue
        a, sep, b = part.partition("-")
        try:
            lo = int(a)
            hi = int(b) if sep else lo
        except ValueError:
            raise ValueError(f"cannot read {part!r}") from None
        if hi < lo:
            raise ValueError(f"{part!r} is an empty range")
        if hi > MAX_SEED:
            raise ValueError(f"seed {hi} is larger than {MAX_SEED}")
        if len(out) + hi - lo + 1 > MAX_SEEDS:
            raise ValueError(f"more than {MAX_SEEDS} seeds")
        out.extend(range(lo, hi + 1))
    if not out:
        raise ValueError("no seeds")
    twice = sorted(s for s, n in Counter(out).items() if n > 1)
    if twice:
        raise ValueError(f"seed {twice[0]} is given twice")
    return out


def summarise(results: dict) -> dict:
    """Per method: mean / std / min / max PRMSE, outage PRMSE mean, and paired stats of ``-acc``."""
    seeds = sorted(results)
    methods = list(results[seeds[0]])
    table = {}
    for m in methods:
        v = np.array([results[s][m][0] for s in seeds], float)
        o = np.array(
            [np.nan if results[s][m][1] is None else results[s][m][1] for s in seeds], float
        )
        row = {
            "n": len(v),
            "mean": float(np.mean(v)),
            "std": float(np.std(v, ddof=1)) if len(v) > 1 else 0.0,
            "min": float(np.min(v)),
            "max": float(np.max(v)),
            "outage_mean": None if np.all(np.isnan(o)) else float(np.nanmean(o)),
        }
        base = BASELINES.get(m)
        if base in methods:
            b = np.array([results[s][base][0] for s in seeds], float)
            diff = b - v
            row.update(
                {
                    "baseline": base,
                    "improvement_pct_mean": float(np.mean(100 * diff / b)),
                    "helped": int(np.sum(diff > 0)),
                    "p_value": paired_permutation_pvalue(diff),
                }
            )
        table[m] = row
    return table


def format_summary(table: dict, title: str) -> str:
    """The paper-style table: baseline, with acc, improvement %, spread and significance."""
    head = [
        "method",
        "PRMSE mean [m]",
        "std",
        "min",
        "max",
        "outage PRMSE",
        "acc gain [%]",
        "helped",
        "p (paired)",
    ]
    rows = []
    for m, r in table.items():
        acc = "improvement_pct_mean" in r
        rows.append(
            [
                m,
                f"{r['mean']:.3f}",
                f"{r['std']:.3f}",
                f"{r['min']:.3f}",
                f"{r['max']:.3f}",
                "-" if r["outage_mean"] is None else f"{r['outage_mean']:.2f}",
                f"{r['improvement_pct_mean']:+.2f}" if acc else "-",
                f"{r['helped']}/{r['n']}" if acc else "-",
                f"{r['p_value']:.3f}" if acc else "-",
            ]
        )
    return "\n".join([title] + text_table(head, rows))
