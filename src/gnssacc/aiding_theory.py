r"""Exact linear-Gaussian references for GNSS-acceleration aiding: does ``a~`` add information?

Filter
------
One axis, state ``x = [p, v, a]`` (position [m], velocity [m/s], acceleration [m/s^2]) driven by
white jerk of PSD ``q`` [m^2/s^5] (the IMU's role: a random-walk acceleration), position fixes
``z_k = p_k + n_k``, ``n_k ~ N(0, R)`` white, at uniform times ``t_k = k dt``, and the paper's
least-squares acceleration of the last three fixes, ``a~_k = B [z_{k-2}, z_{k-1}, z_k]``,
``B = [1, -2, 1] / dt^2`` (:func:`gnssacc.gnss_accel.acceleration_row`). Three filters share one
8-state layout ``[p, v, a, p_{k-1}, p_{k-2}, n_k, n_{k-1}, n_{k-2}]``: before each epoch the
position is cloned (stochastic cloning, ``p_{k-1} <- p``) and the noise slots shift, the newest
drawn from its prior ``N(0, R)``. Window-consistent: ``a~`` is predicted from the clones,
``B [p_{k-2}, p_{k-1}, p_k]``, not from the acceleration at ``t_k``.

``position``
    Position updates only (``H = e_p``, noise ``R``).
``paper``
    Position updates and the acceleration with ``Sigma_a = sum_j B_j^2 R`` as an independent
    measurement (the correlation with the position updates built from the same fixes ignored);
    ``paper-epoch`` compares it with the acceleration state at ``t_k`` (the paper's literal model,
    which adds the window model error).
``cloned``
    Exact: the fix noises are states, the position update is ``z_k = p_k + n_k`` and the
    acceleration ``a~_k = sum_j B_j (p_j + n_j)``, both without further noise. The acceleration is
    then a deterministic function of what the position updates already conditioned on: its
    innovation variance is zero (to rounding) and it leaves the estimate unchanged, so
    ``cloned`` reproduces ``position`` exactly (applied first, it carries the information the
    position update would have, which then carries none). ``paper`` counts the fix noise twice
    and is overconfident; :func:`kf_departure` measures by how much.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .gnss_accel import acceleration_row

#: Filter variants of :func:`kf_filter`.
KF_VARIANTS = ("position", "paper", "paper-epoch", "cloned")
_N = 8  # [p, v, a, p_{k-1}, p_{k-2}, n_k, n_{k-1}, n_{k-2}]


def kf_model(dt: float, q: float) -> tuple[np.ndarray, np.ndarray]:
    """Transition ``F`` and process covariance ``Q`` (3 x 3) of ``[p, v, a]`` over ``dt`` [s] under
    white jerk of PSD ``q`` [m^2/s^5] (exact discretisation)."""
    F = np.array([[1.0, dt, 0.5 * dt * dt], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])
    Q = q * np.array([[dt**5 / 20, dt**4 / 8, dt**3 / 6], [dt**4 / 8, dt**3 / 3, dt**2 / 2],
                      [dt**3 / 6, dt**2 / 2, dt]])
    return F, Q


def kf_simulate(n: int, dt: float, q: float, R: float, x0: np.ndarray, P0: np.ndarray,
                rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """True states ``(n, 3)`` (the first drawn from ``N(x0, P0)``) and fixes ``(n,)`` [m]."""
    F, Q = kf_model(dt, q)
    L, LQ = np.linalg.cholesky(P0), np.linalg.cholesky(Q)
    x = np.empty((n, 3))
    x[0] = x0 + L @ rng.standard_normal(3)
    for k in range(1, n):
        x[k] = F @ x[k - 1] + LQ @ rng.standard_normal(3)
    return x, x[:, 0] + np.sqrt(R) * rng.standard_normal(n)


@dataclass
class KfResult:
    """Output of :func:`kf_filter` after each epoch's updates.

    Attributes
    ----------
    x : ndarray (n, 3)
        Estimated ``[p, v, a]``.
    P : ndarray (n, 3, 3)
        Their covariance.
    s_acc : ndarray (n,)
        Innovation variance of the acceleration update [m^2/s^4] (NaN: none at that epoch).
    """

    x: np.ndarray
    P: np.ndarray
    s_acc: np.ndarray


def _update(x, P, H, r, y, rel_tol=1e-10):
    """Scalar Kalman update in place; returns the innovation variance. One the state already
    predicts exactly (``S`` zero to rounding, as for a fix the state has conditioned on) is skipped."""
    PH = P @ H
    S = float(H @ PH) + r
    if S <= rel_tol * (float(np.abs(H) @ np.sqrt(np.abs(np.diag(P)))) ** 2 + r):
        return S
    K = PH / S
    x += K * (y - H @ x)
    P -= np.outer(K, PH)
    P[:] = 0.5 * (P + P.T)
    return S


def _shift(x, P, F, Q, R):
    """Clone the position and shift the noise slots (newest from its prior), then predict ``dt``."""
    T = np.zeros((_N, _N))
    T[:3, :3] = F
    T[3, 0] = T[4, 3] = 1.0         # p_{k-1} <- p (before the prediction), p_{k-2} <- p_{k-1}
    T[6, 5] = T[7, 6] = 1.0         # n_{k-1} <- n_k, n_{k-2} <- n_{k-1}; n_k fresh
    x[:] = T @ x
    P[:] = T @ P @ T.T
    P[:3, :3] += Q
    P[5, 5] = R


def kf_filter(z: np.ndarray, dt: float, q: float, R: float, variant: str, x0: np.ndarray, P0: np.ndarray,
              accel_first: bool = False) -> KfResult:
    """Run one of :data:`KF_VARIANTS` over fixes ``z`` [m] at interval ``dt`` [s].

    Parameters
    ----------
    z : ndarray (n,)
    dt, q, R : float
        Fix interval [s], jerk PSD [m^2/s^5], fix variance [m^2].
    variant : str
        See the module docstring.
    x0, P0 : ndarray (3,), (3, 3)
        Prior of ``[p, v, a]`` at the first fix.
    accel_first : bool
        Apply the acceleration update before the position update at each epoch.
    """
    if variant not in KF_VARIANTS:
        raise ValueError(f"unknown variant {variant!r}; known: {', '.join(KF_VARIANTS)}")
    F, Q = kf_model(dt, q)
    B = acceleration_row(dt * np.arange(3.0))
    exact = variant == "cloned"
    x, P = np.zeros(_N), np.zeros((_N, _N))
    x[:3], P[:3, :3], P[5, 5] = x0, P0, R
    h_pos = np.zeros(_N)
    h_pos[0] = 1.0
    h_pos[5] = 1.0 if exact else 0.0
    h_acc = np.zeros(_N)
    if variant == "paper-epoch":
        h_acc[2] = 1.0
    else:
        h_acc[[4, 3, 0]] = B
        if exact:
            h_acc[[7, 6, 5]] = B
    r_pos, r_acc = (0.0, 0.0) if exact else (R, float(B @ B) * R)
    n = len(z)
    out = KfResult(np.empty((n, 3)), np.empty((n, 3, 3)), np.full(n, np.nan))
    for k in range(n):
        if k > 0:
            _shift(x, P, F, Q, R)
        steps = [("pos", z[k])]
        if variant != "position" and k >= 2:
            steps.insert(0 if accel_first else 1, ("acc", B @ z[k - 2:k + 1]))
        for kind, y in steps:
            if kind == "pos":
                _update(x, P, h_pos, r_pos, y)
            else:
                out.s_acc[k] = _update(x, P, h_acc, r_acc, y)
        out.x[k], out.P[k] = x[:3], P[:3, :3]
    return out


def kf_monte_carlo(variants=KF_VARIANTS, runs: int = 200, n: int = 60, dt: float = 1.0, q: float = 1.0,
                   R: float = 1.0, seed: int = 0, burn_in: int = 10, accel_first: bool = False) -> dict:
    """Each variant on the same ``runs`` simulated runs of ``n`` fixes (prior ``N(0, P0)``,
    ``P0 = diag(R, 1, 1)``); scored on the epochs from ``burn_in`` on.

    Returns
    -------
    dict
        Per variant: ``nees`` (mean NEES per dof of ``[p, v, a]``; 1 for a consistent filter),
        ``stated_var`` (3,) the mean covariance diagonal and ``error_var`` (3,) the mean squared
        error [m^2, m^2/s^2, m^2/s^4].
    """
    rng = np.random.default_rng(seed)
    x0, P0 = np.zeros(3), np.diag([R, 1.0, 1.0])
    acc = {v: {"nees": 0.0, "stated": np.zeros(3), "sq": np.zeros(3)} for v in variants}
    for _ in range(runs):
        truth, z = kf_simulate(n, dt, q, R, x0, P0, rng)
        for v in variants:
            res = kf_filter(z, dt, q, R, v, x0, P0, accel_first)
            e = (res.x - truth)[burn_in:]
            P = res.P[burn_in:]
            acc[v]["nees"] += float(np.einsum("ki,ki->", e, np.linalg.solve(P, e[..., None])[..., 0]))
            acc[v]["stated"] += np.diagonal(P, axis1=1, axis2=2).sum(0)
            acc[v]["sq"] += (e * e).sum(0)
    m = runs * (n - burn_in)
    return {v: {"nees": a["nees"] / (3 * m), "stated_var": a["stated"] / m, "error_var": a["sq"] / m}
            for v, a in acc.items()}


def kf_departure(variant: str = "paper", **kw) -> np.ndarray:
    """Stated over actual error variance of ``variant`` per state ``[p, v, a]`` (1: consistent,
    below 1: overconfident), from :func:`kf_monte_carlo` (same keywords)."""
    r = kf_monte_carlo((variant,), **kw)[variant]
    return r["stated_var"] / r["error_var"]
