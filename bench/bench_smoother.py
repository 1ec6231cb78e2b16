"""Smoother speed and memory.

Speed (KITTI default, one core, median of --repeats runs): wall time and real-time factor of
``smoother``, ``smoother-acc`` and ``smoother-accw`` (acceleration factors and per-node marginal
covariances included), next to a *plain* gtsam baseline timed in the same process:
IncrementalFixedLagSmoother with CombinedImuFactor + GPSFactor, the same lag, 1 Hz nodes, no marginals. The ratio to the plain
script is the machine-independent figure; the real-time factor is what a user sees.

Memory: peak resident memory of fresh processes running ``smoother-acc`` on simulated car runs
of 600 s and 6000 s (10x longer), above the process's memory just before the smoother starts
(gtsam allocations are not visible to tracemalloc, hence RSS).

``--high-rate`` instead times the smoothers on fast fixes: simulated slow-UGV runs of 360 s with
10 Hz and 20 Hz fixes (industrial IMU), and the real recordings of ``../shared/data`` (comma2k19:
60 s, 10 Hz; VN-310 static: 32 s, 5 Hz), with the default node layout (fixes folded into nodes
at most ``[smoother] min_node_spacing_s`` apart) and with a node per fix (``min_node_spacing_s =
0``, the layout before): wall time, real-time factor, nodes, PRMSE against the truth, and the
largest difference between the two at their common nodes in units of the node-per-fix sigma.

Usage::

    python bench/bench_smoother.py [--repeats 5] [--breakdown]
    python bench/bench_smoother.py --high-rate [--repeats 3]
"""

from __future__ import annotations

import argparse
import contextlib
import json
import subprocess
import sys
import time

import numpy as np


def plain_fixed_lag(run, cfg, init) -> float:
    """The plain reference: what a short gtsam script does, with our data and IMU noise."""
    import gtsam
    from gtsam.symbol_shorthand import B, V, X

    from gnssacc.core.earth import normal_gravity

    t0 = time.perf_counter()
    p = gtsam.PreintegrationCombinedParams.MakeSharedD(
        float(normal_gravity(run.origin.lat0, run.origin.h0))
    )
    p.setAccelerometerCovariance(np.diag(cfg.accel_psd))
    p.setGyroscopeCovariance(np.diag(cfg.gyro_psd))
    p.setBiasAccCovariance(np.diag(cfg.accel_bias_rw_psd))
    p.setBiasOmegaCovariance(np.diag(cfg.gyro_bias_rw_psd))
    p.setIntegrationCovariance(1e-8 * np.eye(3))
    params = gtsam.ISAM2Params()
    params.setFactorization("QR")
    sm = gtsam.IncrementalFixedLagSmoother(float(cfg["smoother"]["lag_s"]), params)
    p_fix = run.origin.to_ned(run.gnss.lat, run.gnss.lon, run.gnss.h)
    pose = gtsam.Pose3(gtsam.Rot3(init.R_nb), run.origin.to_ned(init.lat, init.lon, init.h))
    vel, bias = np.asarray(init.v_n, float), gtsam.imuBias.ConstantBias()
    g, v = gtsam.NonlinearFactorGraph(), gtsam.Values()
    g.add(gtsam.PriorFactorPose3(X(0), pose, gtsam.noiseModel.Isotropic.Sigma(6, 1.0)))
    g.add(gtsam.PriorFactorVector(V(0), vel, gtsam.noiseModel.Isotropic.Sigma(3, 1.0)))
    g.add(gtsam.PriorFactorConstantBias(B(0), bias, gtsam.noiseModel.Isotropic.Sigma(6, 0.1)))
    for k, val in ((X(0), pose), (V(0), vel), (B(0), bias)):
        v.insert(k, val)
    ts = gtsam.FixedLagSmootherKeyTimestampMap()
    for k in (X(0), V(0), B(0)):
        ts.insert((k, init.t))
    sm.update(g, v, ts)
    imu, j, t_prev = run.imu, int(np.searchsorted(run.imu.t, init.t, side="right")), init.t
    for n, i in enumerate(np.flatnonzero(run.gnss.t > init.t), start=1):
        t = run.gnss.t[i]
        pim = gtsam.PreintegratedCombinedMeasurements(p, bias)
        while j < len(imu.t) and imu.t[j] <= t:
            pim.integrateMeasurement(
                imu.f_b[j], imu.omega_ib_b[j], imu.t[j] - max(imu.t[j - 1], t_prev)
            )
            j += 1
        nav = pim.predict(gtsam.NavState(pose, vel), bias)
        g, v, ts = (
            gtsam.NonlinearFactorGraph(),
            gtsam.Values(),
            gtsam.FixedLagSmootherKeyTimestampMap(),
        )
        g.add(gtsam.CombinedImuFactor(X(n - 1), V(n - 1), X(n), V(n), B(n - 1), B(n), pim))
        g.add(
            gtsam.GPSFactor(X(n), p_fix[i], gtsam.noiseModel.Diagonal.Sigmas(run.gnss.sigma_ned[i]))
        )
        for k, val in ((X(n), nav.pose()), (V(n), nav.velocity()), (B(n), bias)):
            v.insert(k, val)
        for k in (X(n), V(n), B(n)):
            ts.insert((k, t))
        sm.update(g, v, ts)
        pose, vel, bias = (
            sm.calculateEstimatePose3(X(n)),
            sm.calculateEstimateVector(V(n)),
            sm.calculateEstimateConstantBias(B(n)),
        )
        t_prev = t
    return time.perf_counter() - t0


@contextlib.contextmanager
def _without_marginals():
    """The smoother with its per-node marginal upkeep switched off (identity covariances): what
    the sigmas cost, by difference. For this bench only; the estimates are unchanged."""
    from gnssacc.estimators import window_marginals as W

    sync, covs = W.WindowMarginals.sync, W.WindowMarginals.covariances

    def no_sync(self, isam, new_factors):
        self.first = 0

    W.WindowMarginals.sync = no_sync
    W.WindowMarginals.covariances = lambda self, nodes: np.tile(np.eye(self.b), (len(nodes), 1, 1))
    try:
        yield
    finally:
        W.WindowMarginals.sync, W.WindowMarginals.covariances = sync, covs


def _high_rate_runs():
    """(name, run, config) of the fast-fix cases: simulated, then the real recordings if present."""
    from pathlib import Path

    from gnssacc.core.config import load_config
    from gnssacc.sources.sim import grade_config, simulate

    cfg = load_config(overrides={"imu": grade_config("industrial")})
    for rate in (10.0, 20.0):
        yield (
            f"sim ugv-slow 360 s, {rate:.0f} Hz fixes",
            simulate("ugv-slow", 360.0, gnss_rate_hz=rate, seed=0),
            cfg,
        )
    data = Path(__file__).resolve().parents[2] / "shared" / "data"
    if data.is_dir():
        sys.path.insert(0, str(Path(__file__).resolve().parent))
        from bench_real_recordings import comma, vn310

        yield "comma2k19 60 s, 10 Hz fixes", comma(data / "comma2k19_example1"), load_config()
        yield "VN-310 static 32 s, 5 Hz fixes", vn310(data / "vn310_static", "lckf"), load_config()


def high_rate(repeats: int) -> None:
    from dataclasses import replace

    from gnssacc import pipeline
    from gnssacc.analysis.metrics import score
    from gnssacc.estimators.kernels import ready
    from gnssacc.estimators.settings import SmootherSettings
    from gnssacc.estimators.smoother import estimate

    ready(["smoother", "smoother-acc"])
    print(
        f"Fast fixes: smoother wall time (median of {repeats}; a node per fix: one run), one core"
    )
    print(
        f"{'case':34s} {'method':13s} {'layout':14s} {'wall [s]':>9s} {'x real time':>12s} {'nodes':>6s} "
        f"{'PRMSE [m]':>10s} {'max |diff|/sigma':>17s}"
    )
    for name, run, cfg in _high_rate_runs():
        prep = pipeline.prepare(run, cfg, "auto", ["smoother"])
        base = SmootherSettings.from_config(prep.cfg)
        for method in ("smoother", "smoother-acc"):
            sols, walls = {}, {}
            for layout, spacing, n in (
                ("folded", base.min_node_spacing_s, repeats),
                ("node per fix", 0.0, 1),
            ):
                w = []
                for _ in range(n):
                    t0 = time.perf_counter()
                    sols[layout] = estimate(
                        prep, replace(base, min_node_spacing_s=spacing), method
                    )[method]
                    w.append(time.perf_counter() - t0)
                walls[layout] = float(np.median(w))
            a, b = sols["folded"], sols["node per fix"]
            _, ia, ib = np.intersect1d(a.t, b.t, return_indices=True)
            o = prep.run.origin
            d = np.hstack(
                [
                    o.to_ned(a.lat[ia], a.lon[ia], a.h[ia])
                    - o.to_ned(b.lat[ib], b.lon[ib], b.h[ib]),
                    a.v_n[ia] - b.v_n[ib],
                    (a.rpy[ia] - b.rpy[ib] + np.pi) % (2 * np.pi) - np.pi,
                    a.b_a[ia] - b.b_a[ib],
                    a.b_g[ia] - b.b_g[ib],
                ]
            )
            worst = float(np.max(np.abs(d) / b.sigma[ib]))
            for layout, sol in sols.items():
                prmse = score(prep.run, sol).prmse_m if prep.run.truth is not None else float("nan")
                print(
                    f"{name:34s} {method:13s} {layout:14s} {walls[layout]:9.2f} "
                    f"{run.duration_s / walls[layout]:12.0f} {sol.stats['n_nodes']:6d} {prmse:10.3f} "
                    f"{worst if layout == 'folded' else float('nan'):17.2f}"
                )


def _rss_mib() -> float:
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * 4096 / 2**20


def _memory_child(duration: float) -> None:
    import threading

    from gnssacc.checks.quality import check_imu
    from gnssacc.core.config import load_config
    from gnssacc.prepare.passes import run_smoother
    from gnssacc.sources.sim import grade_config, simulate

    cfg = load_config(overrides={"imu": grade_config("industrial")})
    run = simulate("car", duration_s=duration, imu_grade="industrial", seed=0)
    q = check_imu(run.imu, cfg)
    run_smoother(
        simulate("car", duration_s=30.0, imu_grade="industrial", seed=0), cfg, "smoother-acc"
    )  # warm
    # Poll RSS while the smoother runs (the simulator's own peak before it must not count).
    before, peak, done = _rss_mib(), [0.0], threading.Event()

    def poll():
        while not done.is_set():
            peak[0] = max(peak[0], _rss_mib())
            done.wait(0.005)

    th = threading.Thread(target=poll)
    th.start()
    sols = run_smoother(run, cfg, "smoother-acc", quality=q)
    done.set()
    th.join()
    peak[0] = max(peak[0], _rss_mib())
    st = sols["smoother-acc"].stats
    print(
        json.dumps(
            {
                "nodes": st["n_nodes"],
                "rss_before_mib": before,
                "peak_mib": peak[0],
                "vars": st["final_window_variables"],
                "slots": st["final_factor_slots"],
            }
        )
    )


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--memory-child", type=float, default=None, help=argparse.SUPPRESS)
    ap.add_argument(
        "--breakdown",
        action="store_true",
        help="also time each smoother with the marginal upkeep switched off (where the time goes)",
    )
    ap.add_argument(
        "--high-rate", action="store_true", help="fast fixes: folded nodes against a node per fix"
    )
    args = ap.parse_args()
    if args.memory_child is not None:
        _memory_child(args.memory_child)
        return
    if args.high_rate:
        high_rate(args.repeats)
        return

    from gnssacc.core.config import load_config
    from gnssacc.prepare.passes import run_smoother
    from gnssacc.pipeline import load_source
    from gnssacc.pipeline import prepare as identify

    cfg = load_config("kitti")
    ident = identify(
        load_source("kitti", cfg, noise="white", seed=0), cfg
    )  # the start and noise `run` uses
    run, cfg, init = ident.run, ident.cfg, ident.init
    kw = dict(quality=ident.quality, init=init, stationary=ident.stationary)
    run_smoother(run, cfg, "smoother", **kw)  # warm-up (imports, caches)
    smoothers = ("smoother", "smoother-acc", "smoother-accw")
    walls = {"plain gtsam script": [], **{m: [] for m in smoothers}}
    if args.breakdown:
        walls.update({f"{m} (no sigmas)": [] for m in smoothers})
    for _ in range(args.repeats):  # interleaved, so slow phases of the machine hit all alike
        walls["plain gtsam script"].append(plain_fixed_lag(run, cfg, init))
        for m in smoothers:
            t0 = time.perf_counter()
            run_smoother(run, cfg, m, **kw)
            walls[m].append(time.perf_counter() - t0)
            if args.breakdown:
                with _without_marginals():
                    t0 = time.perf_counter()
                    run_smoother(run, cfg, m, **kw)
                    walls[f"{m} (no sigmas)"].append(time.perf_counter() - t0)
    plain = float(np.median(walls["plain gtsam script"]))
    print(
        f"KITTI {run.duration_s:.1f} s, {len(run.gnss)} nodes; median of {args.repeats} interleaved runs, one core"
    )
    print(
        f"{'method':26s} {'wall [s]':>9s} {'min [s]':>8s} {'real-time factor':>17s} {'x plain script':>15s}"
    )
    for m, w in walls.items():
        med = float(np.median(w))
        print(f"{m:26s} {med:9.3f} {min(w):8.3f} {run.duration_s / med:17.0f} {med / plain:15.2f}")
    base = float(np.median(walls["smoother"]))
    for m in smoothers[1:]:
        print(
            f"{m} / smoother: {float(np.median(walls[m])) / base:.2f} (median wall over median wall)"
        )

    print("\nMemory (fresh process per run, peak RSS above the RSS before the smoother starts):")
    print(
        f"{'run length [s]':>15s} {'nodes':>7s} {'peak growth [MiB]':>18s} {'variables held':>15s} "
        f"{'factor slots':>13s}"
    )
    rows = []
    for duration in (600.0, 6000.0):
        out = subprocess.run(
            [sys.executable, __file__, "--memory-child", str(duration)],
            capture_output=True,
            text=True,
            check=True,
        )
        d = json.loads(out.stdout.strip().splitlines()[-1])
        growth = d["peak_mib"] - d["rss_before_mib"]
        rows.append((duration, d["nodes"], growth))
        print(f"{duration:15.0f} {d['nodes']:7d} {growth:18.1f} {d['vars']:15d} {d['slots']:13d}")
    (d0, n0, g0), (d1, n1, g1) = rows
    print(
        f"10x longer run: {g1 - g0:+.1f} MiB peak resident memory ({(g1 - g0) * 2**20 / (n1 - n0):.0f} bytes per "
        f"extra node; the stored output is 1.6 kB per node, partly served from memory freed by the simulator)"
    )


if __name__ == "__main__":
    main()
