"""The Kalman measurement update as a compiled kernel (the EKF's and the tuner's hot path).

Joseph form, ``P <- (I - K H) P (I - K H)^T + K R K^T`` with the optimal gain
``K = P H^T S^-1``, ``S = H P H^T + R`` (algebraically the paper's ``(I - K H) P``, numerically
safer). ``S`` is factored by Cholesky, which gives its inverse and ``log det S`` for the
innovation log-likelihood.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def _cholesky_inverse(S):
    """Inverse, log-determinant and inverse Cholesky factor of a small SPD matrix; ``ok`` False if
    not positive definite."""
    m = S.shape[0]
    L = np.zeros((m, m))
    for j in range(m):
        d = S[j, j]
        for k in range(j):
            d -= L[j, k] * L[j, k]
        if d <= 0.0:
            return np.zeros((m, m)), 0.0, np.zeros((m, m)), False
        L[j, j] = math.sqrt(d)
        for i in range(j + 1, m):
            v = S[i, j]
            for k in range(j):
                v -= L[i, k] * L[j, k]
            L[i, j] = v / L[j, j]
    Linv = np.zeros((m, m))
    for i in range(m):
        Linv[i, i] = 1.0 / L[i, i]
        for j in range(i):
            v = 0.0
            for k in range(j, i):
                v -= L[i, k] * Linv[k, j]
            Linv[i, j] = v / L[i, i]
    inv = np.zeros((m, m))
    logdet = 0.0
    for i in range(m):
        logdet += 2.0 * math.log(L[i, i])
        for j in range(m):
            v = 0.0
            for k in range(max(i, j), m):
                v += Linv[k, i] * Linv[k, j]
            inv[i, j] = v
    return inv, logdet, Linv, True


@njit(cache=True)
def _innovation_cov(P, H, R):
    """``P H^T`` (n x m) and the symmetrised innovation covariance ``S = H P H^T + R``."""
    n, m = P.shape[0], H.shape[0]
    PHt = np.zeros((n, m))
    for i in range(n):
        for j in range(m):
            v = 0.0
            for k in range(n):
                v += P[i, k] * H[j, k]
            PHt[i, j] = v
    S = R.copy()
    for i in range(m):
        for j in range(m):
            v = 0.0
            for k in range(n):
                v += H[i, k] * PHt[k, j]
            S[i, j] += v
    for i in range(m):  # symmetrise (loops: array expressions cost seconds of compilation)
        for j in range(i + 1, m):
            S[i, j] = S[j, i] = 0.5 * (S[i, j] + S[j, i])
    return PHt, S


@njit(cache=True)
def _gain(PHt, S_inv, dz):
    """``K = P H^T S^-1`` and ``dx = K dz`` (explicit loops: numba's @ goes through BLAS, slower
    at this size)."""
    n, m = PHt.shape
    K = np.zeros((n, m))
    dx = np.zeros(n)
    for i in range(n):
        for j in range(m):
            v = 0.0
            for k in range(m):
                v += PHt[i, k] * S_inv[k, j]
            K[i, j] = v
        for j in range(m):
            dx[i] += K[i, j] * dz[j]
    return K, dx


@njit(cache=True)
def _joseph(P, K, H, R):
    """``P <- A P A^T + K R K^T`` with ``A = I - K H``, in place, kept exactly symmetric."""
    n, m = P.shape[0], H.shape[0]
    A = np.zeros((n, n))
    for i in range(n):
        A[i, i] = 1.0
        for j in range(n):
            for k in range(m):
                A[i, j] -= K[i, k] * H[k, j]
    AP = np.zeros((n, n))
    for i in range(n):
        for k in range(n):
            a = A[i, k]
            if a != 0.0:
                for j in range(n):
                    AP[i, j] += a * P[k, j]
    KR = np.zeros((n, m))
    for i in range(n):
        for j in range(m):
            for k in range(m):
                KR[i, j] += K[i, k] * R[k, j]
    for i in range(n):
        for j in range(i, n):
            v = 0.0
            for k in range(n):
                v += AP[i, k] * A[j, k]
            for k in range(m):
                v += KR[i, k] * K[j, k]
            P[i, j] = v
            P[j, i] = v


@njit(cache=True)
def joseph_update(P, H, R, dz, gate, consider=-1):
    """Kalman update of ``P`` (n x n, in place) with ``H`` (m x n), ``R`` (m x m), innovation
    ``dz``; state ``consider`` (``>= 0``) is a Schmidt consider state: its row of the gain is zero,
    so the update neither moves its estimate nor shrinks its variance, while its uncertainty and
    correlations still weigh on the others (the Joseph form holds for any gain).

    Returns
    -------
    dx : ndarray (n,)
        The estimated error (zero when rejected).
    nis : float
        Normalised innovation squared ``dz^T S^-1 dz``.
    logdet : float
        ``log det S``.
    used : bool
        False when ``gate > 0`` and ``nis > gate``, or when ``S`` is not positive definite.
    wz : ndarray (m,)
        The whitened innovation ``L^-1 dz`` (``S = L L^T``), for whiteness tests.
    """
    n, m = P.shape[0], H.shape[0]
    PHt, S = _innovation_cov(P, H, R)
    S_inv, logdet, Linv, ok = _cholesky_inverse(S)
    wz = np.zeros(m)
    if not ok:
        return np.zeros(n), np.inf, 0.0, False, wz
    for i in range(m):
        for k in range(i + 1):
            wz[i] += Linv[i, k] * dz[k]
    nis = 0.0
    for i in range(m):
        for j in range(m):
            nis += dz[i] * S_inv[i, j] * dz[j]
    if gate > 0.0 and nis > gate:
        return np.zeros(n), nis, logdet, False, wz
    K, dx = _gain(PHt, S_inv, dz)
    if consider >= 0:
        for j in range(m):
            K[consider, j] = 0.0
        dx[consider] = 0.0
    _joseph(P, K, H, R)
    return dx, nis, logdet, True, wz
