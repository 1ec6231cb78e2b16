"""What a recording says about its gyros' grade: the gyro white-noise density at rest and the
tuner's identified gyro ARW and bias instability, per recording (issue 33, the turn allowance).

Per case: the rest density [deg/sqrt(h)] per gyro axis and their geometric mean, the stationary
seconds it came from, the rest bias-instability floor [deg/h] where seen, and the tuned
``gyro_arw_deg_rth`` / ``gyro_bias_instability_deg_h`` and ``gyro_turn_error_ppm`` in use, with
where it came from (the rest spans it was read on, or the configuration).

    python bench/diag_gyro_grade.py [--only NAME] [--seed 0]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np

import gnssacc

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_consistency import cases, merged  # noqa: E402

RAD_S_RTHZ_TO_DEG_RTH = np.degrees(1.0) * 60.0  # rad/s/sqrt(Hz) -> deg/sqrt(h)


def gyro_grade(case, seed: int) -> str:
    """One line of figures for a case's seed."""
    with tempfile.TemporaryDirectory() as tmp:
        if callable(case.source):
            source, options, _ = case.source(seed, Path(tmp))
            config = merged(case.options.get("config", {}), options.get("config", {}))
            options = {**case.options, **options, **({"config": config} if config else {})}
        else:
            source, options = case.source, {**case.options, "seed": seed}
        res = gnssacc.process(source, methods=["ekf"], **options)
    prep = res.prepared
    rest = prep.rest_noise
    dens = rest.gyro_density * RAD_S_RTHZ_TO_DEG_RTH if rest is not None else np.full(3, np.nan)
    bi = [] if rest is None else rest.bias_instability[3:]
    bi_s = "/".join("-" if b is None else f"{np.degrees(b) * 3600:.1f}" for b in bi) or "-"
    imu = prep.cfg["imu"]
    gm = float(np.exp(np.nanmean(np.log(dens)))) if np.isfinite(dens).any() else float("nan")
    return (
        f"{case.name:34s} rest {'/'.join(f'{d:.3f}' for d in dens)} (gm {gm:.3f}) "
        f"{rest.total_s if rest else 0:.0f} s bi {bi_s} | tuned arw {imu['gyro_arw_deg_rth']} "
        f"bi {imu['gyro_bias_instability_deg_h']} turn {imu['gyro_turn_error_ppm']} "
        f"({prep.cfg.origin.get(('imu', 'gyro_turn_error_ppm'), 'default')})"
    )


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--only", default="", help="the cases whose name contains this")
    p.add_argument("--seed", type=int, default=0)
    a = p.parse_args(argv)
    warnings.simplefilter("ignore")
    for case in cases(True, 1):
        if a.only and a.only not in case.name:
            continue
        try:
            print(gyro_grade(case, a.seed), flush=True)
        except Exception as exc:  # a refusal is a result
            print(f"{case.name:34s} error {type(exc).__name__}: {str(exc)[:100]}", flush=True)


if __name__ == "__main__":
    main()
