"""Fix errors the default white model does not describe: outliers, and Gauss-Markov errors whose
time constant is not the 60 s the tuner starts from (and the simulator uses by default).

* ``outliers``: simulated ``car-city`` 280 s and ``ugv-slow`` 235 s (industrial IMU, 3 m white
  fixes), each clean and with a fraction of the fixes moved (:func:`gnssacc.sources.gnss_noise.add_outliers`),
  default settings and with ``[ekf] position_gate_nis``. Printed per run: PRMSE of the raw fixes,
  ``ekf``, ``smoother`` and ``smoother-online``; position NIS and NEES; how many methods got the
  heavy-tail warning.
* ``gm-tau``: Gauss-Markov fixes (2.5/2.5/4 m, white 0.5/0.5/0.8 m) with time constant ``--tau``,
  default settings against the true noise model (``--tune none``). Printed per run: the tuned tau,
  Gauss-Markov sigma and white sigma, PRMSE of both configurations, NEES and NIS.

    python bench/bench_gnss_errors.py outliers [--fraction 0.03] [--sigma 20] [--gate 16.27] [--seeds 0,1]
    python bench/bench_gnss_errors.py gm-tau [--tau 10,300] [--seeds 0,1,2]

Accuracies, not timings: one process, one run at a time.
"""

from __future__ import annotations

import argparse
import warnings

import numpy as np

import gnssacc.sources.gnss_noise as gn
from gnssacc.core.config import load_config
from gnssacc.pipeline import compare
from gnssacc.sources.sim import grade_config, simulate

RUNS = (("car-city", 280.0), ("ugv-slow", 235.0))
METHODS = ["ekf", "smoother"]


def _compare(run, cfg, tune="auto"):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return compare(run, cfg, METHODS, tune=tune)


def _figures(metrics) -> str:
    m, c = metrics["methods"], metrics["consistency"]
    warned = sum(any("carry outliers" in w for w in c[k]["warnings"]) for k in c)
    return (
        f"gnss {metrics['gnss_prmse_m']:5.2f}  ekf {m['ekf']['prmse_m']:5.2f}  smoother {m['smoother']['prmse_m']:5.2f}"
        f"  online {m['smoother-online']['prmse_m']:5.2f} m | NIS ekf {c['ekf']['nis']['pos']:.2f} smoother "
        f"{c['smoother']['nis']['pos']:.2f} | NEES ekf {m['ekf']['nees_pos']:.2f} smoother "
        f"{m['smoother']['nees_pos']:.2f} | outlier warning {warned}/{len(c)}"
    )


def outliers(a) -> None:
    gated = load_config(overrides={"ekf": {"position_gate_nis": a.gate}})
    for (scen, dur), seed in ((r, s) for r in RUNS for s in a.seeds):
        clean = simulate(scen, dur, imu_grade="industrial", noise="white", seed=seed)
        run, moved = gn.add_outliers(clean, a.fraction, a.sigma, seed=seed + 100)
        print(
            f"{scen} seed {seed}: {moved.sum()} of {len(moved)} fixes moved by N(0, {a.sigma:g} m)"
        )
        print(f"  clean            {_figures(_compare(clean, load_config())[0])}")
        print(f"  outliers         {_figures(_compare(run, load_config())[0])}")
        print(f"  outliers, gate   {_figures(_compare(run, gated)[0])}", flush=True)


def gm_tau(a) -> None:
    base = dict(gn.PROFILES["gm"])
    white = float(np.mean(base["white_sigma"][:2])) / float(
        np.hypot(base["gm_sigma"][0], base["white_sigma"][0])
    )
    try:
        for tau in a.tau:
            gn.PROFILES["gm"] = dict(base, tau_s=tau)
            true = load_config(
                overrides={
                    "imu": grade_config("industrial"),
                    "gnss": {
                        "gm_sigma_m": base["gm_sigma"].tolist(),
                        "gm_tau_s": tau,
                        "sigma_scale": white,
                    },
                }
            )
            for (scen, dur), seed in ((r, s) for r in RUNS for s in a.seeds):
                run = simulate(scen, dur, imu_grade="industrial", noise="gm", seed=seed)
                m, _, ident = _compare(run, load_config())
                mt, _, _ = _compare(run, true, tune="none")
                g = ident.tuning.values.get("gnss", {})
                sig = run.gnss.sigma_ned[0, 0]
                print(
                    f"tau {tau:5.0f} s {scen:8s} seed {seed}: tuned tau {np.mean(g.get('gm_tau_s', np.nan)):6.1f} s, "
                    f"GM sigma {np.round(g.get('gm_sigma_m', [np.nan]), 2)}, white {g.get('sigma_scale', np.nan) * sig:.2f} m"
                    f" | ekf {m['methods']['ekf']['prmse_m']:.2f} (true model {mt['methods']['ekf']['prmse_m']:.2f}),"
                    f" smoother {m['methods']['smoother']['prmse_m']:.2f} ({mt['methods']['smoother']['prmse_m']:.2f}) m"
                    f" | NEES {m['methods']['ekf']['nees_pos']:.2f}/{m['methods']['smoother']['nees_pos']:.2f}"
                    f" NIS {m['consistency']['ekf']['nis']['pos']:.2f}/{m['consistency']['smoother']['nis']['pos']:.2f}",
                    flush=True,
                )
    finally:
        gn.PROFILES["gm"] = base


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="what", required=True)
    o = sub.add_parser("outliers")
    o.add_argument("--fraction", type=float, default=0.03)
    o.add_argument("--sigma", type=float, default=20.0, help="spread of an outlier per axis [m]")
    o.add_argument(
        "--gate", type=float, default=16.27, help="[ekf] position_gate_nis of the gated row"
    )
    o.add_argument("--seeds", default="0,1")
    t = sub.add_parser("gm-tau")
    t.add_argument("--tau", default="10,300", help="true Gauss-Markov time constants [s]")
    t.add_argument("--seeds", default="0,1,2")
    a = ap.parse_args()
    a.seeds = [int(s) for s in a.seeds.split(",")]
    if a.what == "outliers":
        outliers(a)
    else:
        a.tau = [float(x) for x in a.tau.split(",")]
        gm_tau(a)


if __name__ == "__main__":
    main()
