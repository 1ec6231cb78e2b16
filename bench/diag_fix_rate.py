"""At what fix rate does the noise identification see the fixes' slow wander? (issue 33)

A diagnostic, not a product. A receiver that filters its high-rate fixes (20 Hz, stating no
sigma) has errors that wander for tens of seconds with almost no scatter from one fix to the
next (the simulator's ``filtered`` profile: Gauss-Markov 0.6 / 0.6 / 1.0 m, tau 30 s, plus 2-3 cm
white). Tuned on all its fixes, the one-step likelihood prefers a short correlation time (the
IMU's unmodelled errors look like a fast wander) and both estimators come out overconfident.
Here each seed of the slow consumer-IMU rover is tuned on its fixes as given and on the same
fixes decimated (every ``k``-th), and each configuration found is then run with ``--tune none``
on all the fixes: the Gauss-Markov sigma and time found, PRMSE and position NEES of ``ekf`` and
``smoother`` against the truth, and the raw fixes' PRMSE. Fixes without a sigma get their scatter
about local quadratics as their sigma (a decimated track scatters more), and ``gnss.sigma_scale``
is relative to it: the transfer keeps the white part's metres (the scale times the decimated
fixes' sigma over the scale's base on all the fixes).

    python bench/diag_fix_rate.py [--seeds 0,1,2] [--every 1,5] [--duration 367]
"""

from __future__ import annotations

import argparse
import os
import warnings
from dataclasses import replace

import numpy as np

import gnssacc

SECTIONS = ("imu", "gnss", "nhc", "zupt")


def rover(seed: int, duration_s: float):
    """The slow rover with 20 Hz receiver-filtered fixes that state no sigma."""
    run = gnssacc.simulate(
        "rover", duration_s, imu_grade="consumer", gnss_rate_hz=20.0, noise="filtered", seed=seed
    )
    sigma = np.tile([3.0, 3.0, 5.0], (len(run.gnss), 1))
    return run.with_gnss(replace(run.gnss, sigma_ned=sigma, sigma_stated=False))


def read_sigma(prepared) -> float:
    """The median horizontal 1-sigma [m] the fixes were read with (their scatter, unstated)."""
    return float(np.median(prepared.run.gnss.sigma_ned[:, :2]))


def row(run, every: int, base_m: float) -> str:
    """Tune on every ``every``-th fix; score that configuration on all the fixes, whose sigma as
    read is ``base_m`` [m]."""
    mask = np.zeros(len(run.gnss.t), bool)
    mask[::every] = True
    prep = gnssacc.process(run.with_gnss(run.gnss.select(mask)), methods=["ekf"]).prepared
    tuned = prep.cfg
    config = {s: dict(tuned[s]) for s in SECTIONS}
    config["gnss"]["sigma_scale"] = float(tuned["gnss"]["sigma_scale"]) * read_sigma(prep) / base_m
    res = gnssacc.process(run, methods=["ekf", "smoother"], config=config, tune="none")
    m = res.metrics["methods"]
    gm = np.atleast_1d(np.asarray(tuned["gnss"]["gm_sigma_m"], float))
    found = f"{gm[0]:.2f} / {gm[-1]:.2f} m, {float(tuned['gnss']['gm_tau_s']):5.1f} s"
    scores = "  ".join(
        f"{m[k]['prmse_m']:6.3f} {m[k]['nees_pos']:5.2f}" for k in ("ekf", "smoother")
    )
    return f"{20.0 / every:6.1f} Hz  {found:24s} {scores}  {res.metrics['gnss_prmse_m']:6.3f}"


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--seeds", default="0,1,2")
    p.add_argument("--every", default="1,5", help="tune on every k-th fix, for each k")
    p.add_argument("--duration", type=float, default=367.0)
    a = p.parse_args(argv)
    os.environ.setdefault("GNSSACC_CACHE_DIR", "none")  # every tuning made afresh
    warnings.simplefilter("ignore")  # the table carries the figures; the runs' own lines are long
    print("simulated: Gauss-Markov 0.60 / 1.00 m (N/E / D), 30.0 s, white 0.02 / 0.03 m")
    print(
        f"{'seed':>4s} {'tuned at':>9s}  {'Gauss-Markov found':24s} ekf PRMSE NEES"
        f"  smoother PRMSE NEES  raw PRMSE"
    )
    for seed in (int(s) for s in a.seeds.split(",")):
        run = rover(seed, a.duration)
        base_m = read_sigma(gnssacc.process(run, methods=["ekf"], tune="none").prepared)
        for every in (int(k) for k in a.every.split(",")):
            print(f"{seed:4d} {row(run, every, base_m)}", flush=True)


if __name__ == "__main__":
    main()
