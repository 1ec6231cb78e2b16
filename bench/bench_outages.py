"""Navigation through GNSS outages: the ground-vehicle aids (non-holonomic constraint, wheel
odometry) against IMU-only bridging.

For each case (KITTI with seed 13, simulated cars and UGVs with consumer and industrial IMUs)
and each variant, runs ``ekf`` and ``smoother`` through :func:`gnssacc.process` with
``--outage-every 60:20`` (20 s without GNSS at the end of every minute) and prints the PRMSE
over the run and inside the outages [m], then the PRMSE of the same run without outages (GNSS
up throughout: what the aids must not spoil), with the raw fixes' PRMSE.

Variants (``--variants``):

``before``
    No non-holonomic constraint, no wheel odometry: IMU-only bridging (``[nhc] enabled = false``,
    ``[odometry] enabled = false``).
``nhc``
    The non-holonomic constraint (the default settings).
``odo``
    The constraint and the wheel odometry (simulated runs only, with ``odom_hz=10``: the
    simulator's odometry with its scale error and slip).
``today``
    The configuration as it is, nothing overridden: for the code before the aids existed (run
    this script with that code on the path to get the "today" table).

Usage::

    python bench/bench_outages.py [--variants before,nhc,odo] [--seeds 0-2] [--cases kitti,car-consumer,...]
        [--methods ekf,smoother] [--json out.json]

Sim figures are the median over the seeds (each seed draws the IMU errors, the GNSS noise and the
odometry errors); KITTI always uses seed 13. One process, one run at a time (the figures are
accuracies, not timings).
"""

from __future__ import annotations

import argparse
import json
import warnings

import numpy as np

OUTAGES = "60:20"
#: Case name -> (source, seeds or None for the --seeds).
CASES = {
    "kitti": ("kitti", (13,)),
    "car-consumer": ("sim:car,imu=consumer,duration=300", None),
    "car-industrial": ("sim:car,imu=industrial,duration=300", None),
    "ugv-consumer": ("sim:ugv,imu=consumer,duration=300", None),
    "ugv-industrial": ("sim:ugv,imu=industrial,duration=300", None),
}
VARIANTS = {
    "today": None,
    "before": {"nhc": {"enabled": False}, "odometry": {"enabled": False}},
    "nhc": {"nhc": {"enabled": True}, "odometry": {"enabled": False}},
    "odo": {"nhc": {"enabled": True}, "odometry": {"enabled": True}},
}
#: Simulated odometry rate of the ``odo`` variant [Hz].
ODOM_HZ = 10


def _process(source: str, seed: int, variant: str, methods: list, outages: str | None):
    import gnssacc

    with warnings.catch_warnings():
        warnings.simplefilter(
            "ignore"
        )  # data warnings are per run; the figures are what counts here
        return gnssacc.process(
            source, methods=methods, config=VARIANTS[variant], seed=seed, outage_every=outages
        )


def _prmse(res, m: str, key: str) -> float:
    s = res.metrics["methods"].get(m, {})
    return s[key] if s.get("status", "ok") == "ok" and s.get(key) is not None else np.nan


def one(source: str, seed: int, variant: str, methods: list) -> dict:
    """``{method: (overall, outage, without outages) PRMSE}`` and the raw fixes' PRMSE of one run."""
    if variant == "odo":
        if not source.startswith("sim:"):
            return {}
        source = f"{source},odom_hz={ODOM_HZ}"
    res = _process(source, seed, variant, methods, OUTAGES)
    up = _process(source, seed, variant, methods, None)
    out = {}
    for m in methods:
        out[m] = (
            _prmse(res, m, "prmse_m"),
            _prmse(res, m, "prmse_outage_m"),
            _prmse(up, m, "prmse_m"),
        )
        stats = res.metrics["methods"].get(m, {}).get("stats", {})
        for key in (
            "n_nhc_updates",
            "n_nhc_factors",
            "n_odo_updates",
            "n_odo_factors",
            "odometry_scale",
        ):
            if key in stats:
                out[f"{m}:{key}"] = stats[key]
    out["gnss"] = (res.metrics["gnss_prmse_m"], np.nan, np.nan)
    return out


def _cell(v) -> str:
    return "    -" if v is None or not np.isfinite(v) else f"{v:5.2f}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--variants", default="before,nhc,odo")
    ap.add_argument("--cases", default=",".join(CASES))
    ap.add_argument("--seeds", default="0-2", help="sim seeds, e.g. 0-2 or 0,5 (KITTI: 13)")
    ap.add_argument("--methods", default="ekf,smoother")
    ap.add_argument("--json", default=None, help="also write every figure to this JSON file")
    a = ap.parse_args()
    from gnssacc.argcheck import seeds as parse_seeds

    seeds = parse_seeds(a.seeds)
    methods = a.methods.split(",")
    variants = a.variants.split(",")
    results: dict = {}
    print(
        f"outages every {OUTAGES} (period:length s); PRMSE [m] overall / in outages, and without outages; "
        f"sim cases: median over seeds {a.seeds}"
    )
    head = (
        f"{'case':16s} {'variant':7s} "
        + " ".join(f"{m + ' all/out/none':>21s}" for m in methods)
        + "   fixes"
    )
    print(head)
    print("-" * len(head))
    for case in a.cases.split(","):
        source, case_seeds = CASES[case]
        for variant in variants:
            rows = [one(source, s, variant, methods) for s in (case_seeds or seeds)]
            rows = [r for r in rows if r]
            if not rows:
                continue
            results.setdefault(case, {})[variant] = rows
            with warnings.catch_warnings():
                warnings.simplefilter(
                    "ignore", RuntimeWarning
                )  # all-NaN columns (the fixes in outages)
                med = {
                    m: np.nanmedian(np.array([r[m] for r in rows], float), axis=0)
                    for m in methods + ["gnss"]
                }
            cells = " ".join(
                f"{_cell(med[m][0])} {_cell(med[m][1])} {_cell(med[m][2])}   " for m in methods
            )
            print(f"{case:16s} {variant:7s} {cells} {_cell(med['gnss'][0])}", flush=True)
    if a.json:
        with open(a.json, "w") as fh:
            json.dump(
                results,
                fh,
                indent=1,
                default=lambda o: None if isinstance(o, float) and np.isnan(o) else o,
            )


if __name__ == "__main__":
    main()
