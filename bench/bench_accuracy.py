"""Accuracy of the EKF methods on the KITTI default over noise seeds (the paper's PRMSE), with the
default self-tuning (noise identified once per seed, shared by every method).

For each GNSS noise profile (white, gm), with and without ``--outage-every 60:20``, runs all
methods (``ekf``, ``ekf-acc``, ``smoother`` and ``smoother-acc`` with their online estimates)
over seeds and prints mean / min / max PRMSE [m], the outage-only PRMSE, the mean improvement
of each ``-acc`` method over its baseline with the number of seeds where it helped, and the raw
GNSS PRMSE for reference. The row ``ekf-acc avg2`` is ``ekf-acc`` with
``[accel] specific_force_avg_s = 2`` (specific force averaged over the 2 s fit window instead
of the paper's sample at the epoch).

Usage::

    python bench/bench_accuracy.py [--seeds 0-9] [--jobs 2] [--preset kitti] [SOURCE]
"""

from __future__ import annotations

import argparse
from concurrent.futures import ProcessPoolExecutor

import numpy as np

METHODS = (
    "ekf",
    "ekf-acc",
    "ekf-acc avg2",
    "smoother",
    "smoother-acc",
    "smoother-online",
    "smoother-acc-online",
)
BASELINE = {
    "ekf-acc": "ekf",
    "ekf-acc avg2": "ekf",
    "smoother-acc": "smoother",
    "smoother-acc-online": "smoother-online",
}


def _one(args):
    source, preset, noise, outage, seed = args
    from dataclasses import replace

    from gnssacc.analysis.metrics import gnss_score, score
    from gnssacc.core.config import load_config
    from gnssacc.pipeline import load_source, run_methods, with_outages
    from gnssacc.pipeline import prepare as identify

    cfg = load_config(preset)
    run = with_outages(load_source(source, cfg, noise=noise, seed=seed), None, outage)
    ident = identify(run, cfg)  # noise identified once; every method and variant shares it
    sols = run_methods(run, cfg, ["ekf", "ekf-acc", "smoother", "smoother-acc"], prep=ident)
    avg = replace(
        ident, cfg=ident.cfg.with_values({"accel": {"specific_force_avg_s": 2.0}}, "avg2")
    )
    sols["ekf-acc avg2"] = run_methods(run, cfg, ["ekf-acc"], prep=avg)["ekf-acc"]
    out = {"gnss": gnss_score(run).prmse_m}
    for m, s in sols.items():
        sc = score(run, s)
        out[m] = (sc.prmse_m, sc.prmse_outage_m)
    return (noise, outage, seed), out


def _stats(v):
    v = np.asarray([x for x in v if x is not None], float)
    return f"{v.mean():6.2f} {v.min():6.2f} {v.max():6.2f}" if v.size else "     -      -      -"


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("source", nargs="?", default="kitti")
    ap.add_argument("--seeds", default="0-9")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--preset", default="kitti")
    args = ap.parse_args()
    lo, hi = (int(x) for x in args.seeds.split("-"))
    seeds = range(lo, hi + 1)
    cases = [
        (args.source, args.preset, n, o, s)
        for n in ("white", "gm")
        for o in (None, "60:20")
        for s in seeds
    ]
    with ProcessPoolExecutor(args.jobs) as ex:
        results = dict(ex.map(_one, cases))
    print(f"{args.source}, preset {args.preset}, seeds {args.seeds}: PRMSE [m] mean/min/max")
    print(
        f"{'noise':6s} {'outages':8s} {'method':20s} {'PRMSE mean/min/max':>20s} {'outage-only PRMSE':>20s} "
        f"{'acc gain [%] mean (helped)':>27s}"
    )
    for noise in ("white", "gm"):
        for outage in (None, "60:20"):
            rows = [results[(noise, outage, s)] for s in seeds]
            for m in METHODS:
                gain = ""
                if m in BASELINE:
                    b = BASELINE[m]
                    g = [100 * (r[b][0] - r[m][0]) / r[b][0] for r in rows]
                    gain = f"{np.mean(g):+.2f} ({sum(x > 0 for x in g)}/{len(g)})"
                print(
                    f"{noise:6s} {outage or '-':8s} {m:20s} {_stats([r[m][0] for r in rows]):>20s} "
                    f"{_stats([r[m][1] for r in rows]):>20s} {gain:>27s}"
                )
            print(
                f"{noise:6s} {outage or '-':8s} {'gnss':20s} {_stats([r['gnss'] for r in rows]):>20s}"
            )


if __name__ == "__main__":
    main()
