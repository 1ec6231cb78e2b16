"""The fixed-lag smoother's window: accuracy, consistency and time against ``[smoother] lag_s``.

Per recording and lag: the smoother's PRMSE [m], its position NEES per dof (and attitude NEES
where the truth has attitude), and its own wall time [s] (one run each: indicative; the
preparation is shared through the preparation cache, so every lag starts from the same tuned
noise). Default settings otherwise (``gnssacc.process``, method ``smoother``).

    python bench/diag_smoother_lag.py [--lags 10,20] [--runs kitti@0 sim:car,imu=tactical@0 ...]
"""

from __future__ import annotations

import argparse
import os
import tempfile
import warnings

import gnssacc

RUNS = [f"kitti@{s}" for s in range(5)] + [
    "sim:car-city,imu=industrial,duration=300@0",
    "sim:ugv-slow,imu=consumer,duration=300@0",
    "sim:car,imu=tactical,duration=300@0",
    "sim:ugv,imu=industrial,duration=300@0",
]


def cell(spec: str, lag: float) -> str:
    """One recording's figures at one lag."""
    source, _, seed = spec.rpartition("@")
    res = gnssacc.process(
        source, methods=["smoother"], seed=int(seed), config={"smoother": {"lag_s": lag}}
    )
    m = res.metrics["methods"]["smoother"]
    errors = m.get("errors") or {}
    pos = (errors.get("nees_position") or {}).get("value")
    att = (errors.get("nees_attitude") or {}).get("value")
    att_s = "" if att is None else f" att {att:.2f}"
    return (
        f"lag {lag:g} s: {m['prmse_m']:.3f} m NEES {pos:.2f}{att_s} "
        f"wall {res.solutions['smoother'].runtime_s:.2f} s"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--lags", default="10,20", help="lags to compare [s], comma-separated")
    ap.add_argument("--runs", nargs="*", default=RUNS, help="source@seed")
    args = ap.parse_args()
    lags = [float(x) for x in args.lags.split(",")]
    warnings.simplefilter("ignore")
    with tempfile.TemporaryDirectory() as cache:
        os.environ.setdefault("GNSSACC_CACHE_DIR", cache)  # one preparation per recording
        for spec in args.runs:
            print(f"{spec:45s} " + " | ".join(cell(spec, lag) for lag in lags), flush=True)


if __name__ == "__main__":
    main()
