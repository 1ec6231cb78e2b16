"""Which of the smoother's factors tell a still vehicle's tilt from its accelerometer bias.

A still IMU measures only ``g x tilt + accelerometer bias``, so no factor set should shrink the
tilt sigma much below the start's. This runs the fixed-lag smoother on a simulated run that never
moves (``--tune none``), takes the factors of its final window, linearises them at the window's
linearisation point, and prints the dense marginal sigmas (tilt, accelerometer bias, yaw) of the
oldest and newest node for subsets of the factors (docs/consistency.md, "The smoother's tilt on a
run that never moves"). With ``--yaw-sigma-deg`` the start's yaw sigma is replaced.

Usage::

    python bench/diag_static_tilt.py [--grade industrial] [--duration 8] [--seed 0]
                                     [--yaw-sigma-deg 5]
"""

from __future__ import annotations

import argparse
import os
from dataclasses import replace

import gtsam
import numpy as np

os.environ.setdefault("GNSSACC_CACHE_DIR", "none")

from gnssacc.core.config import load_config  # noqa: E402
from gnssacc.estimators import fixed_lag  # noqa: E402
from gnssacc.pipeline import load_source, prepare, run_methods  # noqa: E402

#: Factor subsets, by ``type:variables:dimension`` prefixes (the joint start prior is the 12-dim
#: custom factor on x and b).
SUBSETS = {
    "IMU factors and the start prior": ("CombinedImu", "CustomFactor:bx:12"),
    "+ GNSS positions": ("CombinedImu", "CustomFactor:bx:12", "GPS"),
    "+ zero-velocity factors": ("CombinedImu", "CustomFactor:bx:12", "PriorFactorVector"),
    "+ GNSS velocities instead": ("CombinedImu", "CustomFactor:bx:12", "CustomFactor:v:"),
    "every factor": (),
}
DIMS = {ord("x"): 6, ord("v"): 3, ord("b"): 6}


def final_window(grade: str, duration: float, seed: int, yaw_sigma_deg: float | None):
    """The smoother's last window: its factors and linearisation point."""
    cfg = load_config()
    run = load_source(f"sim:static,imu={grade},duration={duration}", cfg, seed=seed)
    prep = prepare(run, cfg, "none", ["smoother"])
    if yaw_sigma_deg is not None:
        sig = prep.init.sigma_att_rad.copy()
        sig[2] = np.radians(yaw_sigma_deg)
        prep = replace(prep, init=replace(prep.init, sigma_att_rad=sig, yaw_evidence="decided"))
    last = {}
    update = fixed_lag.FixedLagISAM2.update

    def keep(self, graph, values, stamps):
        update(self, graph, values, stamps)
        last["smoother"] = self

    fixed_lag.FixedLagISAM2.update = keep
    try:
        run_methods(prep.run, prep.cfg, ["smoother"], prep=prep)
    finally:
        fixed_lag.FixedLagISAM2.update = update
    sm = last["smoother"]
    return sm.getFactors(), sm.getLinearizationPoint()


def tag(factor) -> str:
    """``type:variables:dimension`` of a factor."""
    chars = sorted({gtsam.Symbol(k).string()[0] for k in factor.keys()})
    return f"{type(factor).__name__}:{''.join(chars)}:{factor.dim()}"


def marginal_sigmas(factors, point, keep: tuple) -> dict:
    """Dense marginal sigmas of the oldest and newest node, from the factors whose tag starts with
    one of ``keep`` (all when empty)."""
    graph = gtsam.NonlinearFactorGraph()
    for i in range(factors.size()):
        f = factors.at(i)
        if f is not None and (not keep or tag(f).startswith(keep)):
            graph.add(f)
    keys = list(point.keys())
    ordering = gtsam.Ordering()
    for k in keys:
        ordering.push_back(k)
    H, _ = graph.linearize(point).hessian(ordering)
    offset, o = {}, 0
    for k in keys:
        offset[k] = o
        o += DIMS.get(gtsam.Symbol(k).chr(), 3)
    d = 1.0 / np.sqrt(np.maximum(np.diag(H), 1e-300))
    C = np.linalg.pinv(H * d[:, None] * d[None, :]) * d[:, None] * d[None, :]
    sd = np.sqrt(np.maximum(np.diag(C), 0.0))
    xs = sorted(k for k in keys if gtsam.Symbol(k).chr() == ord("x"))
    bs = sorted(k for k in keys if gtsam.Symbol(k).chr() == ord("b"))
    out = {}
    for kx, kb in ((xs[0], bs[0]), (xs[-1], bs[-1])):
        att = np.degrees(sd[offset[kx] : offset[kx] + 3])
        acc = sd[offset[kb] : offset[kb] + 3] / 9.80665e-3
        out[gtsam.Symbol(kx).string()] = (att, acc)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--grade", default="industrial")
    ap.add_argument("--duration", type=float, default=8.0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--yaw-sigma-deg", type=float, default=None)
    a = ap.parse_args()
    factors, point = final_window(a.grade, a.duration, a.seed, a.yaw_sigma_deg)
    print(f"static {a.grade}, {a.duration:g} s, seed {a.seed}: marginal sigmas of the final window")
    print(f"{'factors':34s} {'node':5s} {'roll/pitch/yaw [deg]':24s} accel bias x/y/z [mg]")
    for name, keep in SUBSETS.items():
        for node, (att, acc) in marginal_sigmas(factors, point, keep).items():
            att_s = " / ".join(f"{v:.3g}" for v in att)
            acc_s = " / ".join(f"{v:.3g}" for v in acc)
            print(f"{name:34s} {node:5s} {att_s:24s} {acc_s}")


if __name__ == "__main__":
    main()
