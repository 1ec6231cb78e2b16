r"""What GNSS-derived acceleration aiding can add, in the linear-Gaussian case.

The GNSS acceleration ``a~ = B p`` is a deterministic linear function of fixes the estimator
already uses as position measurements. Treated with its exact correlation to them it carries no
extra information; treated as independent (the paper's form) it counts the fixes twice.

Filter
------
One axis, state ``x = [p, v, a]`` (position [m], velocity [m/s], acceleration [m/s^2]) driven by
white jerk of PSD ``q`` [m^2/s^5] (the IMU's role: a random-walk acceleration), position fixes
``z_k = p_k + n_k``, ``n_k ~ N(0, R)`` white, at uniform times ``t_k = k dt``, and the paper's
least-squares acceleration of the last three fixes, ``a~_k = B [z_{k-2}, z_{k-1}, z_k]``,
``B = [1, -2, 1] / dt^2`` (:func:`gnssacc.estimators.aids.accel_model.acceleration_row`). Three filters share one
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

Factor graph
------------
A 1-D chain of epochs ``k = 0 .. n-1`` at spacing ``dt`` [s], state ``x_k = [p, v, a]`` (m, m/s,
m/s^2) with a white-jerk process (PSD ``q`` [m^2/s^5]) and a prior ``N(0, P0)`` on ``x_0``, and a
position fix ``z_k = p_k + n_k``, ``n_k ~ N(0, r^2)`` at every epoch, built from GTSAM's linear
factors (``JacobianFactor`` in a ``GaussianFactorGraph``). Three variants (:func:`fg_graph`):

``"position"``  (a) the prior, the process and the position factors;
``"paper"``     (b) (a) plus one acceleration factor per interior epoch on the window's three
                positions, ``B p - B z`` with ``Sigma_a = sum_j B_j^2 r^2`` (fixes independent, no
                correlation with the position factors);
``"joint"``     (c) the prior, the process and the fixes' joint measurement ``y = T z``,
                (on one variable holding all epochs' states, as the factor touches them all)
                ``T = [I; D]`` (``D`` the stacked ``B`` rows), with its full covariance
                ``T R T^T`` (singular: rank n of 2n - 2). It is whitened on its range: with
                ``T r = U S V^T`` (thin SVD, rank n), ``W = S^-1 U^T`` gives the factor
                ``W T H x = W y`` with unit noise, i.e. information ``H^T T^T (T R T^T)^+ T H``.
                Because ``T`` has full column rank, ``T^T (T R T^T)^+ T = R^-1``: (c) is (a).

:func:`fg_posterior` returns GTSAM's solution and the full covariance (the inverse of the
graph's own Hessian); :func:`fg_departure` measures, in closed form, how far (b) is from (a):
stated over actual error variance per state, the expected NEES per dof, and the Kullback-Leibler
divergence of (b)'s posterior from (a)'s averaged over the fixes.
"""

from __future__ import annotations

from dataclasses import dataclass

import gtsam
import numpy as np

from ..estimators.aids.accel_model import acceleration_row

#: Filter variants of :func:`kf_filter`.
KF_VARIANTS = ("position", "paper", "paper-epoch", "cloned")
_N = 8  # [p, v, a, p_{k-1}, p_{k-2}, n_k, n_{k-1}, n_{k-2}]
_PVA = slice(0, 3)  # [p, v, a]


def kf_model(dt: float, q: float) -> tuple[np.ndarray, np.ndarray]:
    """Transition ``F`` and process covariance ``Q`` (3 x 3) of ``[p, v, a]`` over ``dt`` [s] under
    white jerk of PSD ``q`` [m^2/s^5] (exact discretisation)."""
    F = np.array([[1.0, dt, 0.5 * dt * dt], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])
    Q = q * np.array(
        [
            [dt**5 / 20, dt**4 / 8, dt**3 / 6],
            [dt**4 / 8, dt**3 / 3, dt**2 / 2],
            [dt**3 / 6, dt**2 / 2, dt],
        ]
    )
    return F, Q


def kf_simulate(
    n: int, dt: float, q: float, R: float, x0: np.ndarray, P0: np.ndarray, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
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
    T[_PVA, _PVA] = F
    T[3, 0] = T[4, 3] = 1.0  # p_{k-1} <- p (before the prediction), p_{k-2} <- p_{k-1}
    T[6, 5] = T[7, 6] = 1.0  # n_{k-1} <- n_k, n_{k-2} <- n_{k-1}; n_k fresh
    x[:] = T @ x
    P[:] = T @ P @ T.T
    P[_PVA, _PVA] += Q
    P[5, 5] = R


def kf_filter(
    z: np.ndarray,
    dt: float,
    q: float,
    R: float,
    variant: str,
    x0: np.ndarray,
    P0: np.ndarray,
    accel_first: bool = False,
) -> KfResult:
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
    x[_PVA], P[_PVA, _PVA], P[5, 5] = x0, P0, R
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
            steps.insert(0 if accel_first else 1, ("acc", B @ z[k - 2 : k + 1]))
        for kind, y in steps:
            if kind == "pos":
                _update(x, P, h_pos, r_pos, y)
            else:
                out.s_acc[k] = _update(x, P, h_acc, r_acc, y)
        out.x[k], out.P[k] = x[_PVA], P[_PVA, _PVA]
    return out


def kf_monte_carlo(
    variants=KF_VARIANTS,
    runs: int = 200,
    n: int = 60,
    dt: float = 1.0,
    q: float = 1.0,
    R: float = 1.0,
    seed: int = 0,
    burn_in: int = 10,
    accel_first: bool = False,
) -> dict:
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
            acc[v]["nees"] += float(
                np.einsum("ki,ki->", e, np.linalg.solve(P, e[..., None])[..., 0])
            )
            acc[v]["stated"] += np.diagonal(P, axis1=1, axis2=2).sum(0)
            acc[v]["sq"] += (e * e).sum(0)
    m = runs * (n - burn_in)
    return {
        v: {"nees": a["nees"] / (3 * m), "stated_var": a["stated"] / m, "error_var": a["sq"] / m}
        for v, a in acc.items()
    }


def kf_departure(variant: str = "paper", **kw) -> np.ndarray:
    """Stated over actual error variance of ``variant`` per state ``[p, v, a]`` (1: consistent,
    below 1: overconfident), from :func:`kf_monte_carlo` (same keywords)."""
    r = kf_monte_carlo((variant,), **kw)[variant]
    return r["stated_var"] / r["error_var"]


# ---------------------------------------------------------------------------------------------
# Factor graph
# ---------------------------------------------------------------------------------------------
#: Variants of :func:`fg_graph`.
FG_VARIANTS = ("position", "paper", "joint")


@dataclass(frozen=True)
class FgChain:
    """A linear-Gaussian chain (see the module docstring). Arrays are per epoch state ``[p, v, a]``.

    Attributes
    ----------
    n : int
        Epochs (>= 3).
    dt : float
        Epoch spacing [s].
    q : float
        White-jerk PSD [m^2/s^5].
    r : float
        Fix 1-sigma [m].
    P0 : ndarray (3, 3)
        Prior covariance of ``x_0``.
    """

    n: int
    dt: float
    q: float
    r: float
    P0: np.ndarray

    @property
    def F(self) -> np.ndarray:
        """Transition over ``dt`` (constant acceleration)."""
        dt = self.dt
        return np.array([[1.0, dt, 0.5 * dt * dt], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])

    @property
    def Q(self) -> np.ndarray:
        """Process covariance over ``dt`` of white jerk with PSD ``q`` (exact discretisation)."""
        dt = self.dt
        return self.q * np.array(
            [
                [dt**5 / 20, dt**4 / 8, dt**3 / 6],
                [dt**4 / 8, dt**3 / 3, dt**2 / 2],
                [dt**3 / 6, dt**2 / 2, dt],
            ]
        )

    @property
    def B(self) -> np.ndarray:
        """Least-squares acceleration row of three fixes ``dt`` apart (``[1, -2, 1] / dt^2``)."""
        return acceleration_row(np.array([0.0, self.dt, 2 * self.dt]))

    def D(self) -> np.ndarray:
        """``(n - 2, n)``: the acceleration of the window ending at epoch ``k + 2`` from all fixes."""
        D = np.zeros((self.n - 2, self.n))
        for k in range(self.n - 2):
            D[k, k : k + 3] = self.B
        return D

    def prior_covariance(self) -> np.ndarray:
        """``(3n, 3n)`` joint covariance of the stacked states before any fix."""
        n, F, Q = self.n, self.F, self.Q
        Phi = [np.eye(3)]  # F^k
        for _ in range(n - 1):
            Phi.append(F @ Phi[-1])
        P = [self.P0]  # marginal covariances
        for _ in range(n - 1):
            P.append(F @ P[-1] @ F.T + Q)
        C = np.zeros((3 * n, 3 * n))
        for i in range(n):
            for j in range(i, n):
                C[3 * j : 3 * j + 3, 3 * i : 3 * i + 3] = Phi[j - i] @ P[i]  # cov(x_j, x_i)
                C[3 * i : 3 * i + 3, 3 * j : 3 * j + 3] = C[3 * j : 3 * j + 3, 3 * i : 3 * i + 3].T
        return C


_H = np.array([[1.0, 0.0, 0.0]])


def _whitener(cov: np.ndarray) -> np.ndarray:
    """``W`` with ``W^T W = cov^-1`` (GTSAM's linear factors take diagonal noise models only)."""
    return np.linalg.inv(np.linalg.cholesky(cov))


def _base_graph(m: FgChain, stacked: bool) -> gtsam.GaussianFactorGraph:
    """Prior on ``x_0`` and the process factors ``x_{k+1} - F x_k``, whitened; on per-epoch keys,
    or (``stacked``) all on key 0 holding the 3n stacked states."""
    g, unit = gtsam.GaussianFactorGraph(), gtsam.noiseModel.Unit.Create(3)
    Wp, Wq = _whitener(m.P0), _whitener(m.Q)
    if not stacked:
        g.add(gtsam.JacobianFactor(0, Wp, np.zeros(3), unit))
        for k in range(m.n - 1):
            g.add(gtsam.JacobianFactor(k, -Wq @ m.F, k + 1, Wq, np.zeros(3), unit))
        return g

    def epoch(k: int) -> slice:  # the stacked state's block of epoch k
        return slice(3 * k, 3 * k + 3)

    A = np.zeros((3, 3 * m.n))
    A[:, epoch(0)] = Wp
    g.add(gtsam.JacobianFactor(0, A, np.zeros(3), unit))
    for k in range(m.n - 1):
        A = np.zeros((3, 3 * m.n))
        A[:, epoch(k)], A[:, epoch(k + 1)] = -Wq @ m.F, Wq
        g.add(gtsam.JacobianFactor(0, A, np.zeros(3), unit))
    return g


def fg_graph(m: FgChain, z: np.ndarray, variant: str) -> gtsam.GaussianFactorGraph:
    """The chain's graph for fixes ``z`` (n,) [m]; ``variant`` one of :data:`FG_VARIANTS`."""
    if variant not in FG_VARIANTS:
        raise ValueError(f"unknown variant {variant!r}; known: {', '.join(FG_VARIANTS)}")
    z = np.asarray(z, float)
    g = _base_graph(m, stacked=variant == "joint")
    if variant == "joint":
        # One factor touches every epoch, and GTSAM's Python JacobianFactor takes at most three
        # keys: this graph holds the stacked states as one variable (key 0, dimension 3n).
        T = np.vstack([np.eye(m.n), m.D()])
        U, S, _ = np.linalg.svd(T * m.r, full_matrices=False)  # T R^(1/2), full column rank n
        W = (U / S).T  # whitening on the range of T R T^T
        Hz = np.kron(np.eye(m.n), _H)  # positions from the stacked states
        g.add(gtsam.JacobianFactor(0, W @ T @ Hz, W @ (T @ z), gtsam.noiseModel.Unit.Create(m.n)))
        return g
    fix = gtsam.noiseModel.Isotropic.Sigma(1, m.r)
    for k in range(m.n):
        g.add(gtsam.JacobianFactor(k, _H, z[k : k + 1], fix))
    if variant == "paper":
        B = m.B
        acc = gtsam.noiseModel.Isotropic.Sigma(1, m.r * float(np.sqrt(np.sum(B**2))))
        for k in range(1, m.n - 1):
            g.add(
                gtsam.JacobianFactor(
                    k - 1,
                    B[0] * _H,
                    k,
                    B[1] * _H,
                    k + 1,
                    B[2] * _H,
                    np.array([B @ z[k - 1 : k + 2]]),
                    acc,
                )
            )
    return g


def fg_posterior(m: FgChain, z: np.ndarray, variant: str) -> tuple[np.ndarray, np.ndarray]:
    """GTSAM's posterior of a variant: mean (n, 3) and full covariance (3n, 3n), epochs in order.

    The mean is ``GaussianFactorGraph.optimize``; the covariance the inverse of the graph's own
    Hessian (``GaussianFactorGraph.hessian`` in the epoch ordering), i.e. all joint marginals.
    """
    g = fg_graph(m, z, variant)
    sol = g.optimize()
    keys = [0] if variant == "joint" else list(range(m.n))
    mean = np.concatenate([sol.at(k) for k in keys]).reshape(m.n, 3)
    info, _ = g.hessian(gtsam.Ordering(keys))
    return mean, np.linalg.inv(info)


def fg_draw(m: FgChain, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A truth (n, 3) from the chain's prior and process, and its fixes (n,) [m]."""
    x = np.empty((m.n, 3))
    x[0] = rng.multivariate_normal(np.zeros(3), m.P0)
    Lq = np.linalg.cholesky(m.Q)
    for k in range(1, m.n):
        x[k] = m.F @ x[k - 1] + Lq @ rng.standard_normal(3)
    return x, x[:, 0] + m.r * rng.standard_normal(m.n)


def fg_gain(m: FgChain, variant: str) -> np.ndarray:
    """``G`` (3n, n) with the variant's posterior mean ``vec(mean) = G z`` (prior mean zero)."""
    eye = np.eye(m.n)
    return np.column_stack([fg_posterior(m, eye[i], variant)[0].ravel() for i in range(m.n)])


def fg_actual_covariance(m: FgChain, variant: str) -> np.ndarray:
    """Covariance (3n, 3n) of the variant's actual error ``G z - x`` over truth and fixes."""
    G = fg_gain(m, variant)
    Hz = np.kron(np.eye(m.n), _H)  # positions from the stacked states
    E = G @ Hz - np.eye(3 * m.n)
    return E @ m.prior_covariance() @ E.T + m.r**2 * G @ G.T


def fg_departure(
    ratios=(0.1, 0.3, 1.0, 3.0, 10.0, 100.0),
    n: int = 30,
    dt: float = 1.0,
    r: float = 3.0,
    p0_sigma=(10.0, 3.0, 1.0),
) -> list[dict]:
    """How far the paper's uncorrelated acceleration factors (b) depart from position only (a).

    Parameters
    ----------
    ratios : sequence of float
        Process over measurement: ``sqrt(q dt^3) / r`` (the jerk's velocity-level sigma over one
        interval against the fix sigma); ``q`` follows from each.
    n, dt, r : int, float [s], float [m]
        Chain length, spacing, fix 1-sigma.
    p0_sigma : sequence of 3 float
        Prior 1-sigma of ``x_0`` [m, m/s, m/s^2].

    Returns
    -------
    list of dict
        Per ratio and variant (``"position"``, ``"paper"``): ``ratio``, ``variant``,
        ``nees_per_dof`` (``tr(P^-1 C) / 3n``, C the actual error covariance), ``nees_pos_per_dof``
        (the same over the n positions' joint marginal), ``var_ratio_pva
        (stated over actual variance of p, v, a, median over the epochs), ``kl_from_position``
        (``E_z KL(N_b || N_a)`` [nats], 0 for (a)).
    """
    out = []
    for ratio in ratios:
        m = FgChain(n, dt, (ratio * r) ** 2 / dt**3, r, np.diag(np.asarray(p0_sigma, float) ** 2))
        post = {v: fg_posterior(m, np.zeros(n), v)[1] for v in ("position", "paper")}
        gain = {v: fg_gain(m, v) for v in post}
        for v, P in post.items():
            C = fg_actual_covariance(m, v)
            ratio_pva = np.median((np.diag(P) / np.diag(C)).reshape(n, 3), axis=0)
            ip = np.arange(0, 3 * n, 3)
            out.append(
                {
                    "ratio": float(ratio),
                    "variant": v,
                    "nees_per_dof": float(np.trace(np.linalg.solve(P, C)) / (3 * n)),
                    "nees_pos_per_dof": float(
                        np.trace(np.linalg.solve(P[np.ix_(ip, ip)], C[np.ix_(ip, ip)])) / n
                    ),
                    "var_ratio_pva": ratio_pva,
                    "kl_from_position": _kl(
                        m, post[v], post["position"], gain[v] - gain["position"]
                    ),
                }
            )
    return out


def _kl(m: FgChain, Pb: np.ndarray, Pa: np.ndarray, dG: np.ndarray) -> float:
    """``E_z KL(N(G_b z, Pb) || N(G_a z, Pa))`` with ``dG = G_b - G_a`` [nats]."""
    Hz = np.kron(np.eye(m.n), _H)
    Sz = Hz @ m.prior_covariance() @ Hz.T + m.r**2 * np.eye(m.n)  # covariance of the fixes
    k = Pa.shape[0]
    _, ld_a = np.linalg.slogdet(Pa)
    _, ld_b = np.linalg.slogdet(Pb)
    mean_term = np.trace(np.linalg.solve(Pa, dG @ Sz @ dG.T))
    return float(0.5 * (np.trace(np.linalg.solve(Pa, Pb)) - k + ld_a - ld_b + mean_term))


def known_velocity_error(
    t_fix: np.ndarray, err_fix: np.ndarray, t: np.ndarray, lag_s: float = 0.0
) -> np.ndarray:
    """Position error of an estimator that knows the velocity exactly: the floor of velocity aiding.

    Knowing the velocity fixes the trajectory up to one constant offset; from fixes with white
    errors of equal variance the best estimate of that offset at time ``t`` is the mean error of
    the fixes up to ``t + lag_s`` (0: a filter; the lag of a fixed-lag smoother), so no estimator
    aided by the same fixes and any velocity measurement has a smaller mean-square error in
    expectation (it knows less). With time-correlated fix errors the mean is not the best estimate
    and this is no bound.

    Parameters
    ----------
    t_fix : (n,) array
        Fix times [s], increasing.
    err_fix : (n, k) array
        The fixes' errors against the truth [m] (any frame; NED in the benches).
    t : (m,) array
        Times to evaluate [s], none before the first fix.
    lag_s : float
        How far past ``t`` the estimator may look [s].

    Returns
    -------
    (m, k) array
        The error at each of ``t`` [m].
    """
    err = np.asarray(err_fix, float)
    mean = np.cumsum(err, axis=0) / np.arange(1, len(err) + 1)[:, None]
    k = np.searchsorted(np.asarray(t_fix, float), np.asarray(t, float) + lag_s, side="right") - 1
    if np.any(k < 0):
        raise ValueError("known_velocity_error: a time before the first fix")
    return mean[k]
