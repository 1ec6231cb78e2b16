"""The paper's least-squares GNSS acceleration: a quadratic fitted to the last ``m`` fixes, its
acceleration ``a~ = B p`` and covariance (Versano & Klein, the design matrix ``A`` and the row
``B``), and its velocity form: the slope of a line fitted to the last ``m`` Doppler velocities
(:func:`velocity_accelerations`).

One implementation, used wherever a GNSS-derived acceleration is needed: the start's levelling
(:mod:`gnssacc.prepare.initialise`), the EKF's acceleration update and the smoother's factor
(:mod:`gnssacc.estimators.aids.accel_model`, :mod:`gnssacc.factors`), and the aiding theory
(:mod:`gnssacc.analysis.aiding_theory`).
"""

from __future__ import annotations

import numpy as np


def design_matrix(t: np.ndarray) -> np.ndarray:
    """Design matrix ``A`` (m x 3) for fix times ``t`` [s], referenced to ``t[0]``."""
    dt = np.asarray(t, float) - float(t[0])
    return np.column_stack([np.ones_like(dt), dt, 0.5 * dt * dt])


def acceleration_row(t: np.ndarray) -> np.ndarray:
    """Row ``B`` (m,) such that the least-squares acceleration is ``B @ p`` [1/s^2].

    Parameters
    ----------
    t : ndarray, shape (m,)
        Fix times [s], m >= 3, at least three distinct; need not be uniform.

    Notes
    -----
    ``B = e_3^T (A^T A)^{-1} A^T``. The 3x3 normal matrix is built from power sums of the time
    offsets, scaled to O(1) by the window length for conditioning, and inverted by cofactors:
    scalar arithmetic, because this runs at every GNSS epoch and numpy's per-call overhead
    dominates for such small arrays.
    """
    t = [float(x) for x in t]
    scale = max(t[-1] - t[0], 1e-9)
    u = [(x - t[0]) / scale for x in t]
    q = [0.5 * x * x for x in u]
    s0, s1, s2 = float(len(u)), sum(u), sum(qq for qq in q)
    s11, s12, s22 = (
        sum(x * x for x in u),
        sum(x * qq for x, qq in zip(u, q)),
        sum(qq * qq for qq in q),
    )
    # N = [[s0, s1, s2], [s1, s11, s12], [s2, s12, s22]]; third row of N^-1 by cofactors.
    c20 = s1 * s12 - s11 * s2
    c21 = -(s0 * s12 - s1 * s2)
    c22 = s0 * s11 - s1 * s1
    det = s0 * (s11 * s22 - s12 * s12) - s1 * (s1 * s22 - s12 * s2) + s2 * c20
    if abs(det) < 1e-12 * max(1.0, s0) ** 3:
        raise ValueError("acceleration window needs at least three distinct fix times")
    return np.array([(c20 + c21 * x + c22 * qq) / det for x, qq in zip(u, q)]) / scale**2


def ls_acceleration(
    t: np.ndarray, p_n: np.ndarray, sigma_ned: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares acceleration of a window of fixes and its covariance.

    Parameters
    ----------
    t : ndarray, shape (m,)
        Fix times [s].
    p_n : ndarray, shape (m, 3)
        Fix positions in a local NED tangent frame [m].
    sigma_ned : ndarray, shape (m, 3)
        1-sigma of each fix along N, E, D [m].

    Returns
    -------
    a_n : ndarray, shape (3,)
        Acceleration in NED [m/s^2].
    cov : ndarray, shape (3, 3)
        Its covariance, ``sum_j B_j^2 diag(sigma_j^2)`` [m^2/s^4].
    """
    B = acceleration_row(t)
    a_n = B @ np.asarray(p_n, float)
    cov = np.diag((B[:, None] ** 2 * np.asarray(sigma_ned, float) ** 2).sum(axis=0))
    return a_n, cov


def full_window_ends(t: np.ndarray, m: int, max_gap_s: float) -> np.ndarray:
    """Indices ``j`` of the samples that complete a full window ``j - m + 1 .. j`` of times ``t``
    [s]: one in which no interval exceeds ``max_gap_s`` [s] (a window is cleared at a gap)."""
    bad = np.concatenate([[0], np.cumsum(np.diff(t) > max_gap_s)])  # gaps before sample j
    j = np.arange(m - 1, len(t))
    return j[bad[j] == bad[j - m + 1]]


def window_accelerations(
    t: np.ndarray,
    p_n: np.ndarray,
    sigma_ned: np.ndarray,
    m: int,
    max_gap_s: float,
    sigma_override: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What :class:`AccelWindow` returns for each of a sequence of fixes pushed in order, at once.

    The window of fix ``j`` is fixes ``j - m + 1 .. j``; it is full when none of its intervals
    exceeds ``max_gap_s`` (the buffer is cleared at such a gap). Same formula as
    :func:`acceleration_row` and :func:`ls_acceleration`, vectorised over the windows.

    Parameters
    ----------
    t : ndarray (M,)
        Fix times [s], increasing.
    p_n, sigma_ned : ndarray (M, 3)
        Positions in a local NED frame and their 1-sigma [m].
    m : int
        Window length (>= 3).
    max_gap_s : float
    sigma_override : ndarray (3,), optional
        Fixed 1-sigma [m/s^2] replacing the propagated covariance.

    Returns
    -------
    full : ndarray (M,) of bool
        Whether fix ``j`` completes a window (a measurement).
    a_n : ndarray (M, 3)
        Accelerations [m/s^2, NED] (NaN where not full).
    var : ndarray (M, 3)
        Their variances (diagonal covariance) [m^2/s^4].
    """
    t = np.asarray(t, float)
    M = len(t)
    full = np.zeros(M, bool)
    a_n, var = np.full((M, 3), np.nan), np.full((M, 3), np.nan)
    if M < m:
        return full, a_n, var
    j = full_window_ends(t, m, max_gap_s)
    full[j] = True
    idx = j[:, None] + np.arange(1 - m, 1)  # (K, m) fix indices per window
    T = t[idx]
    scale = np.maximum(T[:, -1] - T[:, 0], 1e-9)
    u = (T - T[:, :1]) / scale[:, None]
    q = 0.5 * u * u
    s0, s1, s2 = float(m), u.sum(1), q.sum(1)
    s11, s12, s22 = (u * u).sum(1), (u * q).sum(1), (q * q).sum(1)
    c20, c21, c22 = s1 * s12 - s11 * s2, -(s0 * s12 - s1 * s2), s0 * s11 - s1 * s1
    det = s0 * (s11 * s22 - s12 * s12) - s1 * (s1 * s22 - s12 * s2) + s2 * c20
    if np.any(np.abs(det) < 1e-12 * max(1.0, s0) ** 3):
        raise ValueError("acceleration window needs at least three distinct fix times")
    Bw = (c20[:, None] + c21[:, None] * u + c22[:, None] * q) / det[:, None] / scale[:, None] ** 2
    a_n[j] = np.einsum("km,kmc->kc", Bw, np.asarray(p_n, float)[idx])
    var[j] = (Bw[:, :, None] ** 2 * np.asarray(sigma_ned, float)[idx] ** 2).sum(1)
    if sigma_override is not None:
        var[j] = np.asarray(sigma_override, float) ** 2
    return full, a_n, var


def velocity_accelerations(
    t: np.ndarray, v_n: np.ndarray, sigma_ned: np.ndarray, m: int, max_gap_s: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The least-squares acceleration of the last ``m`` GNSS (Doppler) velocities, for each of a
    sequence of velocities in order: the slope of a straight line fitted to each window, as
    :func:`window_accelerations` fits a quadratic to the positions (the same window and gap rule).

    Per axis ``a~ = sum_j C_j v_j`` with ``C_j = (t_j - mean t) / sum_i (t_i - mean t)^2`` [1/s]
    (for three uniform velocities ``(v_2 - v_0) / (2 dt)``) and, for independent velocities,
    ``var = sum_j C_j^2 sigma_j^2``.

    Parameters
    ----------
    t : ndarray (M,)
        Velocity times [s], increasing.
    v_n, sigma_ned : ndarray (M, 3)
        Velocities [m/s, NED] and their 1-sigma; NaN on an axis not measured.
    m : int
        Window length (>= 2).
    max_gap_s : float

    Returns
    -------
    full : ndarray (M,) of bool
        Whether velocity ``j`` completes a window.
    a_n, var : ndarray (M, 3)
        Accelerations [m/s^2, NED] and their variances [m^2/s^4]; NaN where not full and on an
        axis some velocity of the window does not measure.
    """
    t = np.asarray(t, float)
    M = len(t)
    full = np.zeros(M, bool)
    a_n, var = np.full((M, 3), np.nan), np.full((M, 3), np.nan)
    if M < m:
        return full, a_n, var
    j = full_window_ends(t, m, max_gap_s)
    full[j] = True
    idx = j[:, None] + np.arange(1 - m, 1)
    u = t[idx] - t[idx].mean(axis=1, keepdims=True)
    C = u / (u * u).sum(axis=1, keepdims=True)
    a_n[j] = np.einsum("km,kmc->kc", C, np.asarray(v_n, float)[idx])
    var[j] = (C[:, :, None] ** 2 * np.asarray(sigma_ned, float)[idx] ** 2).sum(1)
    return full, a_n, var
