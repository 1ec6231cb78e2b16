"""Model error of the GNSS-acceleration predictions: the paper's one-epoch ``R_nb f + g`` versus
the window-consistent (Peano-kernel) prediction of ``ekf-accw``.

On noise-free fixes and a perfect IMU, ``a~ - a_pred(truth)`` is the model error alone; with a
realistic IMU the IMU's noise over the window adds to it. Prints the RMS of ``|a~ - a_pred|``
[m/s^2] per scenario, fix rate and IMU grade, and the ratio window / paper. Deterministic (no
timings): one simulated run per row, seed 0.

Usage::

    python bench/bench_accel_models.py [--duration 300]
"""

from __future__ import annotations

import argparse

import numpy as np

from gnssacc.estimators.aids.accel_model import model_errors
from gnssacc.sources.sim import simulate


def rms(e: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum(e * e, axis=1))))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--duration", type=float, default=300.0)
    args = ap.parse_args()
    print(
        f"{'scenario':10s} {'fix [Hz]':>8s} {'IMU':>10s} {'windows':>8s} {'paper [m/s^2]':>14s} "
        f"{'window [m/s^2]':>15s} {'window/paper':>13s}"
    )
    for scenario in ("car", "car-city", "ugv-slow"):
        for rate in (1.0, 5.0):
            for grade in ("perfect", "industrial"):
                run = simulate(
                    scenario,
                    args.duration,
                    imu_grade=grade,
                    gnss_rate_hz=rate,
                    noise="none",
                    seed=0,
                )
                _, paper, window = model_errors(run)
                print(
                    f"{scenario:10s} {rate:8.0f} {grade:>10s} {len(paper):8d} {rms(paper):14.4f} "
                    f"{rms(window):15.4f} {rms(window) / rms(paper):13.4f}"
                )


if __name__ == "__main__":
    main()
