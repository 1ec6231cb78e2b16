"""The smoother with its time-ordered fixed-lag smoother against GTSAM's own, on one recording.

Runs each smoother method with :class:`gnssacc.estimators.fixed_lag.FixedLagISAM2` (what ``gnssacc run``
uses) and with :class:`gnssacc.estimators.fixed_lag.GtsamFixedLag` (``gtsam.IncrementalFixedLagSmoother``),
interleaved, from the same identification, and prints per method: the median CPU seconds of the
smoother pass (CPU time: less sensitive to a shared machine than wall time), their ratio, the
variables iSAM2 re-eliminated per update, and how far the two estimates are apart (position,
sigmas relative, PRMSE where the run has truth).

    python bench/bench_fixed_lag.py [SOURCE] [--methods smoother,smoother-acc] [--repeats 3]

SOURCE is anything ``gnssacc run`` takes (default: the embedded KITTI sequence); a recording
without a configuration is self-tuned first, as ``gnssacc run`` does.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

import gnssacc.estimators.smoother as S
import gnssacc.estimators.smoother_graph as G
from gnssacc.analysis.metrics import score
from gnssacc.core.config import load_config
from gnssacc.estimators.fixed_lag import FixedLagISAM2, GtsamFixedLag
from gnssacc.pipeline import load_source
from gnssacc.pipeline import prepare as identify


def _counting(cls, count: list):
    class Counted(cls):
        def update(self, graph, values, stamps):
            super().update(graph, values, stamps)
            count[0] += self.getISAM2Result().getVariablesReeliminated()
            count[1] += 1

    return Counted


def _pass(ident, method: str, cls):
    """One smoother pass with ``cls``: solutions, CPU seconds, re-eliminated variables per update."""
    count = [0, 0]
    G.FixedLagISAM2 = _counting(cls, count)
    try:
        t0 = time.process_time()
        sols = S.run_smoother(
            ident.run,
            ident.cfg,
            method,
            quality=ident.quality,
            init=ident.init,
            stationary=ident.stationary,
        )
        return sols, time.process_time() - t0, count[0] / max(count[1], 1)
    finally:
        G.FixedLagISAM2 = FixedLagISAM2


def _apart(run, a, b) -> str:
    d_m = float(
        np.max(np.hypot((a.lat - b.lat) * 6.378e6, (a.lon - b.lon) * 6.378e6 * np.cos(a.lat)))
    )
    d_s = float(np.max(np.abs(a.sigma - b.sigma) / np.maximum(np.abs(a.sigma), 1e-300)))
    text = f"apart {d_m:.1e} m, sigma {d_s:.1e} rel"
    if run.truth is not None:
        text += f", PRMSE {score(run, a).prmse_m:.6f} / {score(run, b).prmse_m:.6f} m"
    return text


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("source", nargs="?", default="kitti")
    ap.add_argument("--methods", default="smoother,smoother-acc,smoother-accw")
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    cfg = load_config("kitti") if args.source == "kitti" else load_config()
    ident = identify(
        load_source(args.source, cfg, noise="white", seed=0)
        if args.source == "kitti"
        else load_source(args.source, cfg),
        cfg,
    )
    print(
        f"{args.source}: {ident.run.duration_s:.1f} s, {len(ident.run.gnss)} fixes; median of {args.repeats} "
        f"interleaved passes, CPU time; load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores"
    )
    print(
        f"{'method':15s} {'GTSAM [s]':>10s} {'ours [s]':>9s} {'ratio':>6s} {'re-elim/update GTSAM -> ours':>29s}"
    )
    for method in args.methods.split(","):
        cpu = {"gtsam": [], "ours": []}
        for _ in range(args.repeats):
            ref, t_ref, n_ref = _pass(ident, method, GtsamFixedLag)
            ours, t_ours, n_ours = _pass(ident, method, FixedLagISAM2)
            cpu["gtsam"].append(t_ref)
            cpu["ours"].append(t_ours)
        g, o = float(np.median(cpu["gtsam"])), float(np.median(cpu["ours"]))
        print(f"{method:15s} {g:10.2f} {o:9.2f} {o / g:6.2f} {n_ref:17.1f} -> {n_ours:.1f}")
        for key in (method, method + "-online"):
            print(f"  {key}: {_apart(ident.run, ref[key], ours[key])}")


if __name__ == "__main__":
    main()
