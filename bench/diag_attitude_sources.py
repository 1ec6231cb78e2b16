"""Which of the simulator's unmodelled IMU errors makes the attitude overconfident (issue 33).

A diagnostic, not a product: the same simulated run (scenario, grade, seed) with one group of
the simulator's unmodelled error sources switched off at a time (``imu_overrides``), then all
off, then only one group on; per variant the EKF's and the smoother's attitude NEES per dof
(pooled, roll / pitch / yaw), the position NEES and the PRMSE.

Groups (keys of :func:`gnssacc.sources.sim_imu_errors.imu_error_model`):

* ``gyro-sf``: gyro scale factors; ``gyro-cross``: gyro cross-axis (misalignment);
* ``accel-sf-cross``: accelerometer scale factors and cross-axis (``accel-sf``, ``accel-cross``:
  one of them);
* ``drift``: the warm-up and random-walk bias drift (gyro and accelerometer);
* ``vibration``: engine and road vibration (gyro and accelerometer).

    python bench/diag_attitude_sources.py [--scenario car-city] [--grade consumer] [--seed 0]
        [--tune auto|none] [--nhc on|off] [--variants base,-gyro-cross,...] [--config k=v ...]
"""

from __future__ import annotations

import argparse
import json
import time
import warnings
from dataclasses import replace

import numpy as np

import gnssacc
from gnssacc.sources.sim import dense_truth_rate, simulate

GROUPS = {
    "gyro-sf": ("gyro_scale_factor_ppm",),
    "gyro-cross": ("gyro_cross_axis_ppm",),
    "accel-sf-cross": ("accel_scale_factor_ppm", "accel_cross_axis_ppm"),
    "accel-sf": ("accel_scale_factor_ppm",),
    "accel-cross": ("accel_cross_axis_ppm",),
    "drift": (
        "gyro_warmup_deg_h",
        "accel_warmup_mg",
        "gyro_bias_rw_deg_h_rth",
        "accel_bias_rw_mg_rth",
    ),
    "vibration": (
        "vib_engine_gyro_dps",
        "vib_engine_accel_mps2",
        "vib_road_gyro_dps",
        "vib_road_accel_mps2",
    ),
}


#: The groups that partition the sources (``none`` and ``+GROUP`` use these).
MAIN_GROUPS = ("gyro-sf", "gyro-cross", "accel-sf-cross", "drift", "vibration")


def overrides(variant: str) -> dict:
    """``base`` (all on), ``none`` (all off), ``-GROUP`` (one off) or ``+GROUP`` (only one on)."""
    if variant == "base":
        off = ()
    elif variant == "none":
        off = MAIN_GROUPS
    elif variant.startswith("-"):
        off = (variant[1:],)
    else:  # every main group off but the keys of the one named (a sub-group too: +accel-cross)
        keep = set(GROUPS[variant[1:]])
        return {k: 0.0 for g in MAIN_GROUPS for k in GROUPS[g] if k not in keep}
    return {k: 0.0 for g in off for k in GROUPS[g]}


def figures(res, mid: str) -> dict:
    e = res.metrics["methods"][mid].get("errors") or {}
    att, pos = e.get("nees_attitude"), e.get("nees_position")
    sig = np.degrees(np.asarray(res.solutions[mid].sigma)[:, 6:9])
    return {
        "sigma_deg": np.round(np.nanmedian(sig, axis=0), 4).tolist(),  # median stated sigma
        "prmse": res.metrics["methods"][mid].get("prmse_m"),
        "pos": pos["value"] if pos else None,
        "att": att["value"] if att else None,
        **({a: att["per_axis"][a]["value"] for a in ("roll", "pitch", "yaw")} if att else {}),
    }


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--scenario", default="car-city")
    p.add_argument("--grade", default="consumer")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--duration", type=float, default=300.0)
    p.add_argument("--tune", default="auto")
    p.add_argument("--nhc", default="on")
    p.add_argument("--variants", default="base,none," + ",".join("-" + g for g in MAIN_GROUPS))
    p.add_argument("--ppm", type=float, default=None, help="[imu] gyro_turn_error_ppm")
    p.add_argument("--json", help="append each variant's figures (one JSON line) to this file")
    a = p.parse_args(argv)
    warnings.simplefilter("ignore")
    config: dict = {}
    if a.nhc == "off":
        config["nhc"] = {"enabled": False}
    if a.ppm is not None:
        config["imu"] = {"gyro_turn_error_ppm": a.ppm}
    rate = dense_truth_rate(100.0)
    print(f"{a.scenario} {a.grade} seed {a.seed} tune {a.tune} nhc {a.nhc} ppm {a.ppm}")
    for variant in a.variants.split(","):
        t0 = time.perf_counter()
        run = simulate(
            a.scenario,
            duration_s=a.duration,
            imu_grade=a.grade,
            seed=a.seed,
            velocity=True,
            truth_rate_hz=rate,
            imu_overrides=overrides(variant),
        )
        run = replace(run, meta={**run.meta, "source_spec": "sim:"})
        res = gnssacc.process(run, methods=["ekf", "smoother"], config=config, tune=a.tune)
        row = {m: figures(res, m) for m in ("ekf", "smoother")}
        cells = "  ".join(
            f"{m} prmse {r['prmse']:.2f} pos {r['pos']:.2f} att {r['att']:.2f} "
            f"({r['roll']:.1f}/{r['pitch']:.1f}/{r['yaw']:.1f}) "
            f"sig {'/'.join(f'{x:.3f}' for x in r['sigma_deg'])}"
            for m, r in row.items()
        )
        print(f"{variant:16s} {cells}  [{time.perf_counter() - t0:.0f} s]", flush=True)
        if a.json:
            with open(a.json, "a") as f:
                tuned = res.prepared.tuning.values if res.prepared.tuning else None
                rec = {"variant": variant, **vars(a), **row, "tuned": tuned}
                f.write(json.dumps(rec) + "\n")


if __name__ == "__main__":
    main()
