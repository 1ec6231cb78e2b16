"""Filter against fixed-lag smoother on simulated runs, paired over seeds.

For each case (scenario, IMU grade, GNSS noise profile, duration) and seed, simulates a run,
processes it with ``ekf``, ``smoother`` (and, with ``--acc``, ``ekf-acc``, ``smoother-acc``)
through :func:`gnssacc.process` (the noise identified once per run, shared by every method),
and scores position [m], velocity [m/s], tilt and yaw [deg] RMS errors against the truth over
the output epochs after the first 10 s. Prints, per case and pair (smoother fixed-lag and online
against its filter), the mean and median paired difference, the mean relative change, on how
many seeds the smoother was better, and two-sided p-values of a sign test and a paired t-test.

Usage::

    python bench/bench_filter_vs_smoother.py [--seeds 0-9] [--tune auto|none] [--acc]
        [--case ugv,industrial,white,180 ...]

Defaults: the cases ugv/car x industrial/consumer x white/gm, 180 s, seeds 0-9, ``--tune auto``.
One process, one run at a time (the figures are accuracies, not timings).
"""

from __future__ import annotations

import argparse
import itertools
import warnings

import numpy as np
from scipy import stats

#: Smoother estimate -> the filter it is compared with.
PAIRS = {
    "smoother": "ekf",
    "smoother-online": "ekf",
    "smoother-acc": "ekf-acc",
    "smoother-acc-online": "ekf-acc",
}
FIGURES = ("pos", "vel", "tilt", "yaw")


def _rms(e: np.ndarray) -> float:
    ok = np.all(np.isfinite(e), axis=1)
    return float(np.sqrt(np.mean(np.sum(e[ok] ** 2, axis=1))))


def errors_of_run(
    scenario: str, grade: str, noise: str, duration: float, seed: int, methods: list, tune: str
) -> dict:
    """Per method: position [m], velocity [m/s], tilt and yaw [deg] RMS errors (after 10 s)."""
    import gnssacc
    from gnssacc.analysis.observability import state_errors

    run = gnssacc.simulate(scenario, duration, imu_grade=grade, noise=noise, seed=seed)
    with warnings.catch_warnings():
        warnings.simplefilter(
            "ignore"
        )  # data warnings are per run; the figures are what counts here
        res = gnssacc.process(run, methods=methods, tune=tune)
    out = {}
    for m, sol in res.solutions.items():
        e = state_errors(res.run, sol)[sol.t >= sol.t[0] + 10.0]
        out[m] = {
            "pos": _rms(e[:, 0:3]),
            "vel": _rms(e[:, 3:6]),
            "tilt": float(np.degrees(_rms(e[:, 6:8]))),
            "yaw": float(np.degrees(_rms(e[:, 8:9]))),
        }
    return out


def paired_lines(rows: list) -> list:
    """Table lines of the paired comparisons of ``rows`` (one dict of :func:`errors_of_run` per seed)."""
    lines = []
    for a, b in PAIRS.items():
        if a not in rows[0] or b not in rows[0]:
            continue
        for fig in FIGURES:
            xa = np.array([r[a][fig] for r in rows])
            xb = np.array([r[b][fig] for r in rows])
            d = xa - xb
            n_better = int(np.sum(d < 0))
            sign_p = stats.binomtest(n_better, len(d)).pvalue if np.any(d != 0) else 1.0
            t_p = stats.ttest_rel(xa, xb).pvalue if len(d) > 1 and np.any(d != 0) else float("nan")
            lines.append(
                f"  {a:20s} {b:8s} {fig:4s} {xa.mean():8.3f} {xb.mean():8.3f} {d.mean():+8.3f} "
                f"{np.median(d):+8.3f} {100 * d.mean() / xb.mean():+7.1f} {n_better:3d}/{len(d):<3d} "
                f"{sign_p:7.3g} {t_p:7.3g}"
            )
    return lines


def _seeds(text: str) -> list:
    if "-" in text:
        lo, hi = text.split("-")
        return list(range(int(lo), int(hi) + 1))
    return [int(s) for s in text.split(",")]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0-9")
    ap.add_argument("--tune", default="auto", choices=("auto", "none"))
    ap.add_argument("--acc", action="store_true", help="also ekf-acc against smoother-acc")
    ap.add_argument("--case", action="append", help="scenario,grade,noise,duration_s (repeatable)")
    args = ap.parse_args()
    cases = (
        [c.split(",") for c in args.case]
        if args.case
        else [
            [s, g, n, "180"]
            for s, g, n in itertools.product(
                ("ugv", "car"), ("industrial", "consumer"), ("white", "gm")
            )
        ]
    )
    methods = ["ekf", "smoother"] + (["ekf-acc", "smoother-acc"] if args.acc else [])
    print(
        "columns: smoother, filter, figure, mean of each [m, m/s, deg], mean and median paired difference,"
        " mean change [%], seeds where the smoother is better, sign-test p, paired t-test p"
    )
    for scenario, grade, noise, duration in cases:
        rows = [
            errors_of_run(scenario, grade, noise, float(duration), s, methods, args.tune)
            for s in _seeds(args.seeds)
        ]
        print(f"{scenario} {grade} {noise} {duration} s, tune {args.tune}, {len(rows)} seeds")
        print("\n".join(paired_lines(rows)), flush=True)


if __name__ == "__main__":
    main()
