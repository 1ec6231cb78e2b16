"""Issue 31: GNSS (Doppler) velocity aiding, and the acceleration fitted to the velocities.

Simulated runs (scenario x IMU grade x GNSS noise profile, 1 Hz fixes with 3 m white or
time-correlated errors, 1 Hz Doppler velocities of 0.05 m/s white plus a small Gauss-Markov part:
:mod:`gnssacc.sources.gnss_noise`), several seeds each, every run three times on the same data:

* positions only (``--velocity off``): ``ekf``, ``smoother``;
* positions and velocities (the default): ``ekf``, ``smoother`` and the acceleration fitted to
  the velocities, the paper's form (``ekf-vacc``, ``smoother-vacc``) and the window-consistent one
  (``ekf-vaccw``, ``smoother-vaccw``);
* positions only, plus the acceleration fitted to the velocities (the four ``-vacc*`` methods);
  ``--accel off`` leaves the accelerations out (the first two passes' ``ekf`` and ``smoother``).

Prints, per cell, the median over the seeds of the whole-run PRMSE without and with velocity and
their ratio (acceptance: the EKF's at most 0.5, the smoother's at most 0.7 on white fixes; no
worse on time-correlated ones), the median position NEES and velocity NIS per dof; then the
effect of the velocity-derived acceleration on PRMSE per cell against each baseline, as the
acceleration study prints it (:func:`gnssacc.analysis.study.paired_effect`: mean paired
difference [%], 95 % bootstrap interval, sign-flip p-value).

Known noise by default (``--tune none``: the simulator's IMU parameters), the tool's default aids
(``--aids on``: the non-holonomic constraint; ``off``: the paper's setting, IMU and GNSS alone).

Usage::

    python bench/bench_velocity_aiding.py [--seeds 0-4] [--duration 300] [--imu consumer,industrial]
        [--scenario car,ugv] [--noise white,gm] [--tune none|auto] [--aids on|off] [--jobs 1]
"""

from __future__ import annotations

import argparse
import itertools
import json
import statistics
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np

import gnssacc
from gnssacc.analysis.aiding_theory import known_velocity_error
from gnssacc.analysis.metrics import truth_at
from gnssacc.analysis.montecarlo import parse_seeds
from gnssacc.analysis.study import paired_effect

#: The three passes over each run: name, velocity updates on, methods.
ACC = ("ekf-vacc", "smoother-vacc", "ekf-vaccw", "smoother-vaccw")
PASSES = (
    ("pos", False, ("ekf", "smoother")),
    ("pos+vel", True, ("ekf", "smoother") + ACC),
    ("pos+vacc", False, ACC),
)


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--seeds", default="0-4")
    p.add_argument("--duration", type=float, default=300.0)
    p.add_argument("--imu", default="consumer,industrial")
    p.add_argument("--scenario", default="car,ugv")
    p.add_argument("--noise", default="white,gm")
    p.add_argument("--tune", choices=["none", "auto"], default="none")
    p.add_argument("--aids", choices=["on", "off"], default="on")
    p.add_argument("--accel", choices=["on", "off"], default="on")
    p.add_argument("--jobs", type=int, default=1)
    p.add_argument("--rows", help="also write every run's figures to this JSON file")
    return p.parse_args(argv)


def late_prmse(res, mid: str) -> float | None:
    """PRMSE [m] over the run's second half (after the start's transient)."""
    run, sol = res.run, res.solutions.get(mid)
    tr = run.truth
    if sol is None or tr is None:
        return None
    keep = tr.t >= run.t_start + 0.5 * run.duration_s
    p_true = run.origin.to_ned(tr.lat[keep], tr.lon[keep], tr.h[keep])
    p = run.origin.to_ned(sol.lat, sol.lon, sol.h)
    p_est = np.column_stack([np.interp(tr.t[keep], sol.t, p[:, i]) for i in range(3)])
    return float(np.sqrt(np.mean(np.sum((p_est - p_true) ** 2, axis=1))))


def fix_errors(run) -> tuple[np.ndarray, np.ndarray]:
    """The fixes' times [s] and their errors against the truth, NED [m] (one row per fix inside
    the truth's span: :func:`gnssacc.analysis.metrics.truth_at`)."""
    g = run.gnss
    p_true, valid = truth_at(run, g.t)
    return g.t[valid], (run.origin.to_ned(g.lat, g.lon, g.h) - p_true)[valid]


def oracle_prmse(run, lag_s: float | None) -> float | None:
    """PRMSE [m] of an estimator that knows the velocity exactly
    (:func:`gnssacc.analysis.aiding_theory.known_velocity_error`: causal when ``lag_s`` is None,
    else a fixed-lag smoother's), scored at the truth's epochs from the first fix to the end; None
    without truth or fixes."""
    if run.truth is None or run.gnss is None or len(run.gnss.t) == 0:
        return None
    t_fix, err = fix_errors(run)
    tt = run.truth.t[run.truth.t >= t_fix[0]]
    e = known_velocity_error(t_fix, err, tt, lag_s or 0.0)
    return float(np.sqrt(np.mean(np.sum(e**2, axis=1))))


def one_run(task) -> dict:
    """Every pass of :data:`PASSES` on one simulated run: ``{(pass, method): figures}``."""
    scenario, imu, noise, seed, duration, tune, aids, accel = task
    source = f"sim:{scenario},imu={imu},duration={duration:g}"
    out = {}
    for name, vel, methods in PASSES:
        methods = methods if accel == "on" else tuple(m for m in methods if m not in ACC)
        if not methods:
            continue
        cfg = {"velocity": {"enabled": vel}}
        if aids == "off":
            cfg |= {"nhc": {"enabled": False}, "zupt": {"enabled": False}}
        res = gnssacc.process(
            source, methods=list(methods), config=cfg, tune=tune, noise=noise, seed=seed
        )
        for mid, m in res.metrics["methods"].items():
            if mid.endswith("-online") or m.get("prmse_m") is None:
                continue
            errs = m.get("errors") or {}
            nis = (res.metrics.get("consistency", {}).get(mid) or {}).get("nis", {})
            out[(name, mid)] = {
                "prmse": m["prmse_m"],
                "late": late_prmse(res, mid),
                "nees": (errs.get("nees_position") or {}).get("value"),
                "nis_vel": nis.get("vel"),
                "vel_rmse": (errs.get("velocity") or {}).get("rmse"),
            }
        if name == "pos":
            lag = float(res.prepared.cfg["smoother"]["lag_s"])
            out[("oracle", "ekf")] = {"prmse": oracle_prmse(res.run, None)}
            out[("oracle", "smoother")] = {"prmse": oracle_prmse(res.run, lag)}
    return {"cell": (scenario, imu, noise), "seed": seed, "figures": out}


def _median(rows, key, figure):
    vals = [r["figures"].get(key, {}).get(figure) for r in rows]
    vals = [v for v in vals if v is not None and np.isfinite(v)]
    return statistics.median(vals) if vals else float("nan")


def _col(rows, key, figure="prmse"):
    return np.array(
        [
            np.nan if r["figures"].get(key, {}).get(figure) is None else r["figures"][key][figure]
            for r in rows
        ]
    )


def print_tables(results: list[dict], accel: bool = True) -> None:
    cells = sorted({r["cell"] for r in results})
    print(
        "\nWhole-run PRMSE [m], median over seeds: positions only vs positions + velocities; the "
        "ratios are medians of the\nper-seed ratios (the last column: of the PRMSE over the run's "
        "second half, EKF / smoother); NEES pos and\nNIS vel per dof (1 = consistent) and the "
        "velocity RMSE [m/s] with velocities"
    )
    head = (
        f"{'scenario':8} {'imu':10} {'noise':5} {'n':>2}  {'ekf pos':>7} {'ekf +vel':>8} "
        f"{'ratio':>5}  {'smo pos':>7} {'smo +vel':>8} {'ratio':>5}  {'NEES e/s':>9} "
        f"{'NIS vel e/s':>11} {'vel RMSE':>8}  {'2nd half e/s':>12}  {'bound e/s':>9}"
    )
    print(head + "\n" + "-" * len(head))
    for cell in cells:
        rows = [r for r in results if r["cell"] == cell]
        e0, e1 = _median(rows, ("pos", "ekf"), "prmse"), _median(rows, ("pos+vel", "ekf"), "prmse")
        s0 = _median(rows, ("pos", "smoother"), "prmse")
        s1 = _median(rows, ("pos+vel", "smoother"), "prmse")
        # The ratio's median over the seeds (paired), not the ratio of the medians.
        re = np.nanmedian(_col(rows, ("pos+vel", "ekf")) / _col(rows, ("pos", "ekf")))
        rs = np.nanmedian(_col(rows, ("pos+vel", "smoother")) / _col(rows, ("pos", "smoother")))
        nees = "/".join(f"{_median(rows, ('pos+vel', m), 'nees'):.2f}" for m in ("ekf", "smoother"))
        nis = "/".join(
            f"{_median(rows, ('pos+vel', m), 'nis_vel'):.2f}" for m in ("ekf", "smoother")
        )
        vr = _median(rows, ("pos+vel", "ekf"), "vel_rmse")
        late = [
            np.nanmedian(_col(rows, ("pos+vel", m), "late") / _col(rows, ("pos", m), "late"))
            for m in ("ekf", "smoother")
        ]
        bound = [
            np.nanmedian(_col(rows, ("oracle", m)) / _col(rows, ("pos", m)))
            for m in ("ekf", "smoother")
        ]
        print(
            f"{cell[0]:8} {cell[1]:10} {cell[2]:5} {len(rows):>2}  {e0:7.2f} {e1:8.2f} {re:5.2f}  "
            f"{s0:7.2f} {s1:8.2f} {rs:5.2f}  {nees:>9} {nis:>11} {vr:8.3f}  "
            f"{late[0]:.2f}/{late[1]:.2f}  {bound[0]:9.2f}/{bound[1]:.2f}"
        )
    print(
        "bound: the least ratio any velocity-aided estimator can reach in expectation on white "
        "fixes - the PRMSE of one that\nknows the velocity exactly (the mean error of the fixes "
        "up to t, or t + the lag) over the position-only PRMSE;\nwith time-correlated fixes it "
        "is no bound (their mean error is not the best estimate)"
    )
    if not accel:
        return
    print(
        "\nVelocity-derived acceleration (-vacc: the paper's form, -vaccw: window-consistent): "
        "PRMSE effect against the same "
        "estimator without it,\nmean paired difference [%] with its 95 % bootstrap interval and "
        "sign-flip p-value"
    )
    pairs = [
        (f"{m}-{form} vs {m} ({label})", (base, m), (var, f"{m}-{form}"))
        for m in ("ekf", "smoother")
        for form in ("vacc", "vaccw")
        for label, base, var in (("pos only", "pos", "pos+vacc"), ("pos+vel", "pos+vel", "pos+vel"))
    ]
    for cell in cells:
        rows = [r for r in results if r["cell"] == cell]
        print(f"{cell[0]} {cell[1]} {cell[2]}:")
        for label, base, var in pairs:
            e = paired_effect(_col(rows, base), _col(rows, var))
            if e is None:
                print(f"  {label:38} (fewer than two seeds)")
                continue
            n, mean, lo, hi, p = e
            print(f"  {label:38} {mean:+6.1f} % [{lo:+6.1f}, {hi:+6.1f}]  p={p:.3f}  (n={n})")


def write_rows(path: str, results: list[dict], a) -> None:
    """Every run's figures as JSON rows (the study notebook reads them): one row per run, pass and
    method with the cell, seed and the settings of the bench."""
    rows = [
        {
            "scenario": r["cell"][0],
            "imu": r["cell"][1],
            "noise": r["cell"][2],
            "seed": r["seed"],
            "pass": key[0],
            "method": key[1],
            **fig,
        }
        for r in results
        for key, fig in r["figures"].items()
    ]
    meta = {"duration_s": a.duration, "tune": a.tune, "aids": a.aids, "accel": a.accel}
    with open(path, "w") as f:
        json.dump({"bench": "bench_velocity_aiding", "settings": meta, "rows": rows}, f, indent=0)


def main(argv=None) -> int:
    a = parse_args(argv)
    tasks = list(
        itertools.product(
            a.scenario.split(","),
            a.imu.split(","),
            a.noise.split(","),
            parse_seeds(a.seeds),
            [a.duration],
            [a.tune],
            [a.aids],
            [a.accel],
        )
    )
    t0 = time.perf_counter()
    if a.jobs > 1:
        with ProcessPoolExecutor(a.jobs) as ex:
            results = list(ex.map(one_run, tasks))
    else:
        results = [one_run(t) for t in tasks]
    print(
        f"{len(tasks)} runs x {len(PASSES)} passes, {time.perf_counter() - t0:.0f} s; "
        f"--tune {a.tune}, aids {a.aids}, {a.duration:g} s each, 1 Hz fixes and velocities"
    )
    print_tables(results, a.accel == "on")
    if a.rows:
        write_rows(a.rows, results, a)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
