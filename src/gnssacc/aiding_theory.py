r"""What GNSS-derived acceleration aiding can add, in the linear-Gaussian case.

The GNSS acceleration ``a~ = B p`` is a deterministic linear function of fixes the estimator
already uses as position measurements. Treated with its exact correlation to them it carries no
extra information; treated as independent (the paper's form) it counts the fixes twice.

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

from .gnss_accel import acceleration_row

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
        return self.q * np.array([[dt**5 / 20, dt**4 / 8, dt**3 / 6], [dt**4 / 8, dt**3 / 3, dt**2 / 2],
                                  [dt**3 / 6, dt**2 / 2, dt]])

    @property
    def B(self) -> np.ndarray:
        """Least-squares acceleration row of three fixes ``dt`` apart (``[1, -2, 1] / dt^2``)."""
        return acceleration_row(np.array([0.0, self.dt, 2 * self.dt]))

    def D(self) -> np.ndarray:
        """``(n - 2, n)``: the acceleration of the window ending at epoch ``k + 2`` from all fixes."""
        D = np.zeros((self.n - 2, self.n))
        for k in range(self.n - 2):
            D[k, k:k + 3] = self.B
        return D

    def prior_covariance(self) -> np.ndarray:
        """``(3n, 3n)`` joint covariance of the stacked states before any fix."""
        n, F, Q = self.n, self.F, self.Q
        Phi = [np.eye(3)]                                  # F^k
        for _ in range(n - 1):
            Phi.append(F @ Phi[-1])
        P = [self.P0]                                      # marginal covariances
        for _ in range(n - 1):
            P.append(F @ P[-1] @ F.T + Q)
        C = np.zeros((3 * n, 3 * n))
        for i in range(n):
            for j in range(i, n):
                C[3 * j:3 * j + 3, 3 * i:3 * i + 3] = Phi[j - i] @ P[i]   # cov(x_j, x_i)
                C[3 * i:3 * i + 3, 3 * j:3 * j + 3] = C[3 * j:3 * j + 3, 3 * i:3 * i + 3].T
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
    A = np.zeros((3, 3 * m.n))
    A[:, 0:3] = Wp
    g.add(gtsam.JacobianFactor(0, A, np.zeros(3), unit))
    for k in range(m.n - 1):
        A = np.zeros((3, 3 * m.n))
        A[:, 3 * k:3 * k + 3], A[:, 3 * k + 3:3 * k + 6] = -Wq @ m.F, Wq
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
        U, S, _ = np.linalg.svd(T * m.r, full_matrices=False)   # T R^(1/2), full column rank n
        W = (U / S).T                                           # whitening on the range of T R T^T
        Hz = np.kron(np.eye(m.n), _H)                           # positions from the stacked states
        g.add(gtsam.JacobianFactor(0, W @ T @ Hz, W @ (T @ z), gtsam.noiseModel.Unit.Create(m.n)))
        return g
    fix = gtsam.noiseModel.Isotropic.Sigma(1, m.r)
    for k in range(m.n):
        g.add(gtsam.JacobianFactor(k, _H, z[k:k + 1], fix))
    if variant == "paper":
        B = m.B
        acc = gtsam.noiseModel.Isotropic.Sigma(1, m.r * float(np.sqrt(np.sum(B**2))))
        for k in range(1, m.n - 1):
            g.add(gtsam.JacobianFactor(k - 1, B[0] * _H, k, B[1] * _H, k + 1, B[2] * _H,
                                       np.array([B @ z[k - 1:k + 2]]), acc))
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
    Hz = np.kron(np.eye(m.n), _H)                       # positions from the stacked states
    E = G @ Hz - np.eye(3 * m.n)
    return E @ m.prior_covariance() @ E.T + m.r**2 * G @ G.T


def fg_departure(ratios=(0.1, 0.3, 1.0, 3.0, 10.0, 100.0), n: int = 30, dt: float = 1.0, r: float = 3.0,
                 p0_sigma=(10.0, 3.0, 1.0)) -> list[dict]:
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
            out.append({"ratio": float(ratio), "variant": v,
                        "nees_per_dof": float(np.trace(np.linalg.solve(P, C)) / (3 * n)),
                        "nees_pos_per_dof": float(np.trace(np.linalg.solve(P[np.ix_(ip, ip)], C[np.ix_(ip, ip)])) / n),
                        "var_ratio_pva": ratio_pva, "kl_from_position": _kl(m, post[v], post["position"],
                                                                           gain[v] - gain["position"])})
    return out


def _kl(m: FgChain, Pb: np.ndarray, Pa: np.ndarray, dG: np.ndarray) -> float:
    """``E_z KL(N(G_b z, Pb) || N(G_a z, Pa))`` with ``dG = G_b - G_a`` [nats]."""
    Hz = np.kron(np.eye(m.n), _H)
    Sz = Hz @ m.prior_covariance() @ Hz.T + m.r**2 * np.eye(m.n)   # covariance of the fixes
    k = Pa.shape[0]
    _, ld_a = np.linalg.slogdet(Pa)
    _, ld_b = np.linalg.slogdet(Pb)
    mean_term = np.trace(np.linalg.solve(Pa, dG @ Sz @ dG.T))
    return float(0.5 * (np.trace(np.linalg.solve(Pa, Pb)) - k + ld_a - ld_b + mean_term))
