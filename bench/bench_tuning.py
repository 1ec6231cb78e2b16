"""Time of the self-tuning (``--tune auto``) for 10-minute and 1-hour recordings, one core.

Simulated city drives (consumer IMU with vibration and scale-factor errors, 3 m white fixes at
1 Hz; and Gauss-Markov fixes, which add the second search), median of three runs each. Prints the
tuning time, the EKF passes it made, the seconds per pass and the real-time factor of a pass, and
the whole identification (stationary detection, yaw bank, tuning, model check).

    python bench/bench_tuning.py [--repeat 3] [--long 3600]
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np

from gnssacc.core.config import load_config
from gnssacc.estimators import mechanization
from gnssacc.pipeline import prepare as identify
from gnssacc.sources.sim import simulate


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--long", type=float, default=3600.0, help="length of the long run [s]")
    a = ap.parse_args()
    warnings.simplefilter("ignore")
    mechanization.warm_up()
    print(
        f"{'run':28s} {'tuning [s]':>10s} {'passes':>6s} {'s/pass':>7s} {'pass RTF':>8s} {'identify [s]':>12s}"
    )
    for duration in (600.0, a.long):
        for noise in ("white", "gm"):
            run = simulate("car-city", duration, imu_grade="consumer", noise=noise, seed=0)
            tune_s, total_s, passes = [], [], 0
            for _ in range(a.repeat):
                t0 = time.perf_counter()
                ident = identify(run, load_config(), "auto")
                total_s.append(time.perf_counter() - t0)
                tune_s.append(ident.tuning.seconds)
                passes = ident.tuning.n_evaluations
            t = float(np.median(tune_s))
            print(
                f"car-city {duration / 60:4.0f} min, {noise:5s} fixes  {t:10.1f} {passes:6d} {t / passes:7.3f} "
                f"{duration * passes / t:8.0f} {np.median(total_s):12.1f}"
            )


if __name__ == "__main__":
    main()
