"""The filter-smoother consistency test (McReynolds') on the smoother's position, and whether it
could calibrate the smoother's stated sigmas (docs/consistency.md, "The smoother's position NEES
on KITTI").

For a linear Gaussian model that is right, the online (filtered) and the smoothed estimates of an
epoch differ by ``d = x_f - x_s`` with covariance ``P_f - P_s`` (the smoothed error is orthogonal
to the difference), so ``kappa = mean(d_i^2 / (P_f,ii - P_s,ii))`` is 1 and needs no truth. Two
parts:

* ``--toy``: a scalar random walk seen through white noise, a Kalman filter and an RTS smoother
  whose model is right, has the process noise too small or too large, or has the likelihood's
  white noise fitted to a correlated process noise: kappa, the filter's and the smoother's NEES,
  and the smoother's NEES with its sigma calibrated as ``P_f - kappa (P_f - P_s)``.
* the same on ``gnssacc.process`` runs (default settings, ``ekf`` and ``smoother``): kappa of the
  fixed-lag smoother against its online estimate (position, N/E/D pooled; the last window's
  nodes, whose two estimates are the same, left out), with its effective count and the
  likelihood-ratio statistic of kappa = 1, and the position NEES of the smoother, of the same
  sigma calibrated, of the online estimate, and the smoother's per axis.

    python bench/diag_filter_smoother.py [--toy] [--runs kitti@0 kitti@1 sim:car,imu=tactical@0]
"""

from __future__ import annotations

import argparse
import warnings

import numpy as np

import gnssacc
from gnssacc.analysis.errorstats import effective_count
from gnssacc.analysis.observability import state_errors


def kalman_rts(z: np.ndarray, q: float, r: float):
    """A scalar random walk's Kalman filter and RTS smoother: filtered and smoothed estimates and
    variances, and the filter's innovation log-likelihood."""
    n = len(z)
    xf, pf, xp, pp = (np.zeros(n) for _ in range(4))
    m, p, loglik = 0.0, 100.0, 0.0
    for k in range(n):
        p += q if k else 0.0
        xp[k], pp[k] = m, p
        s, nu = p + r, z[k] - m
        loglik += -0.5 * (nu * nu / s + np.log(s)) if k > 10 else 0.0
        m, p = m + p / s * nu, p * (1 - p / s)
        xf[k], pf[k] = m, p
    xs, ps = xf.copy(), pf.copy()
    for k in range(n - 2, -1, -1):
        c = pf[k] / pp[k + 1]
        xs[k] = xf[k] + c * (xs[k + 1] - xp[k + 1])
        ps[k] = pf[k] + c * c * (ps[k + 1] - pp[k + 1])
    return xf, pf, xs, ps, loglik


def toy_row(name: str, x: np.ndarray, z: np.ndarray, q: float) -> None:
    xf, pf, xs, ps, _ = kalman_rts(z, q, 1.0)
    k = slice(10, -1)  # the start's transient; the last epoch has P_f = P_s
    d, dp = (xf - xs)[k], (pf - ps)[k]
    kappa = float(np.mean(d * d / dp))
    es, ef = (xs - x)[k], (xf - x)[k]
    cal = pf[k] - kappa * dp
    cal_nees = f"{np.mean(es**2 / cal):.2f}" if np.all(cal > 0) else "negative"
    print(
        f"{name:42s} kappa {kappa:5.2f}  NEES filter {np.mean(ef**2 / pf[k]):.2f}  smoother "
        f"{np.mean(es**2 / ps[k]):.2f}  calibrated {cal_nees}"
    )


def toy(n: int = 20000, seed: int = 0) -> None:
    rng = np.random.default_rng(seed)
    print("scalar random walk, q = 0.1, r = 1, 20000 epochs")
    x = np.cumsum(rng.normal(0.0, np.sqrt(0.1), n))
    z = x + rng.normal(0.0, 1.0, n)
    for q in (0.1, 0.03, 0.3):
        toy_row(f"white process noise, model q = {q}", x, z, q)
    for rho in (0.5, 0.8):
        e = rng.normal(0.0, np.sqrt(0.1 * (1 - rho**2)), n)
        w = np.zeros(n)
        for i in range(1, n):
            w[i] = rho * w[i - 1] + e[i]
        x = np.cumsum(w)
        z = x + rng.normal(0.0, 1.0, n)
        grid = np.geomspace(0.01, 3.0, 25)
        q = grid[int(np.argmax([kalman_rts(z, g, 1.0)[4] for g in grid]))]
        toy_row(f"AR(1) {rho} process noise, ML white q = {q:.2f}", x, z, q)


def run_row(spec: str) -> None:
    source, _, seed = spec.rpartition("@") if "@" in spec else (spec, "", "0")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = gnssacc.process(source, methods=["ekf", "smoother"], seed=int(seed))
    on, sm = res.solutions["smoother-online"], res.solutions["smoother"]
    eo, es = state_errors(res.run, on)[:, 0:3], state_errors(res.run, sm)[:, 0:3]
    so, ss = np.asarray(on.sigma)[:, 0:3], np.asarray(sm.sigma)[:, 0:3]
    d, dp = eo - es, so**2 - ss**2
    ok = np.isfinite(d).all(1) & (dp > 0).all(1)
    kappa = float(np.mean(d[ok] ** 2 / dp[ok]))
    terms = 3 * effective_count(d[ok] / np.sqrt(dp[ok]))
    lr = terms * (kappa - 1 - np.log(kappa))
    cal = so[ok] ** 2 - kappa * dp[ok]
    nees_cal = np.mean(es[ok] ** 2 / cal)
    axes = "/".join(f"{v:.2f}" for v in np.mean((es[ok] / ss[ok]) ** 2, axis=0))
    print(
        f"{spec:40s} kappa {kappa:.2f} ({terms:.0f} terms, 2 log LR {lr:5.1f})  position NEES "
        f"smoother {np.mean((es[ok] / ss[ok]) ** 2):.2f} calibrated {nees_cal:.2f}"
        f"  online {np.mean((eo[ok] / so[ok]) ** 2):.2f}  smoother N/E/D {axes}",
        flush=True,
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--toy", action="store_true", help="the scalar random walk only")
    ap.add_argument(
        "--runs",
        nargs="*",
        default=[f"kitti@{s}" for s in range(5)]
        + ["sim:car-city,imu=industrial,duration=300@0", "sim:car,imu=tactical,duration=300@0"],
    )
    args = ap.parse_args()
    toy()
    if not args.toy:
        print()
        for spec in args.runs:
            run_row(spec)


if __name__ == "__main__":
    main()
