"""Stationary updates: the epochs at which the estimators apply zero-velocity and zero-angular-rate
updates, and the gyro block means those updates compare with.

Within every stationary span (:mod:`gnssacc.prepare.stationary`) an epoch falls every
``[zupt] interval_s`` seconds after the span start. At each epoch the zero-rate update uses the
mean raw gyro reading over the block ``(t - interval_s, t]``; its variance per axis is learnt from
the span itself: the scatter of the span's consecutive block means (which includes engine
vibration, quantisation and whatever else the white-noise model misses), floored by the
configured white noise ``q_g / interval_s``. Both the EKF and the smoother take their stationary
epochs from here.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.recording import ImuData


@dataclass
class StationaryEpochs:
    """Where and with what the stationary updates happen.

    Attributes
    ----------
    t : ndarray, shape (K,)
        Epochs [s].
    omega_mean_b : ndarray, shape (K, 3)
        Mean raw gyro reading over the block ending at each epoch [rad/s, body].
    omega_var_b : ndarray, shape (K, 3)
        Variance of that mean per axis [(rad/s)^2].
    span : ndarray, shape (K,) of int
        Index of the stationary span each epoch belongs to.
    """

    t: np.ndarray
    omega_mean_b: np.ndarray
    omega_var_b: np.ndarray
    span: np.ndarray

    def __len__(self) -> int:
        return len(self.t)

    @classmethod
    def empty(cls) -> "StationaryEpochs":
        return cls(np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, int))


def _block_means(imu: ImuData, edges: np.ndarray) -> np.ndarray:
    """Mean gyro over the samples stamped in each ``(edges[j], edges[j+1]]``; NaN for an empty block.

    Only the samples between the first and last edge are summed (memory in the span, not the run).
    """
    lo, hi = np.searchsorted(imu.t, [edges[0], edges[-1]], side="right")
    c = np.vstack([np.zeros((1, 3)), np.cumsum(imu.omega_ib_b[lo:hi], axis=0)])
    idx = np.searchsorted(imu.t[lo:hi], edges, side="right")
    n = np.diff(idx).astype(float)
    with np.errstate(invalid="ignore", divide="ignore"):
        return (c[idx[1:]] - c[idx[:-1]]) / np.where(n > 0, n, np.nan)[:, None]


def stationary_epochs(
    imu: ImuData, spans, interval_s: float, gyro_psd: np.ndarray
) -> StationaryEpochs:
    """Epochs and gyro block means for the stationary updates.

    Parameters
    ----------
    imu : ImuData
    spans : sequence
        Stationary spans with ``t_start``, ``t_end`` [s] (e.g. ``StationaryReport.spans``).
    interval_s : float
        Spacing of the epochs and length of each gyro block [s].
    gyro_psd : ndarray, shape (3,)
        Configured white gyro noise PSD [rad^2/s]: the floor of each block mean's variance.

    Returns
    -------
    StationaryEpochs
    """
    ts, means, var, which = [], [], [], []
    floor = np.asarray(gyro_psd, float) / interval_s
    for j, sp in enumerate(spans):
        n = int(np.floor((sp.t_end - sp.t_start) / interval_s + 1e-9))
        if n < 1:
            continue
        edges = sp.t_start + interval_s * np.arange(n + 1)
        m = _block_means(imu, edges)
        ok = np.all(np.isfinite(m), axis=1)  # a block inside an IMU gap has no samples
        m, edges = m[ok], np.concatenate([[edges[0]], edges[1:][ok]])
        n = len(m)
        if n < 1:
            continue
        # Scatter of consecutive block means, half the squared difference (insensitive to a slow drift).
        v = 0.5 * np.mean(np.diff(m, axis=0) ** 2, axis=0) if n >= 3 else np.full(3, np.inf)
        v = np.where(np.isfinite(v), np.maximum(v, floor), 4.0 * floor)
        ts.append(edges[1:])
        means.append(m)
        var.append(np.tile(v, (n, 1)))
        which.append(np.full(n, j))
    if not ts:
        return StationaryEpochs.empty()
    return StationaryEpochs(
        np.concatenate(ts), np.vstack(means), np.vstack(var), np.concatenate(which)
    )


def epochs_for(run, zupt, gyro_psd: np.ndarray, stationary) -> StationaryEpochs:
    """The stationary epochs of an estimator run: of ``stationary``'s spans (a
    :class:`gnssacc.prepare.stationary.StationaryReport`) when given and ``zupt.enabled``
    (:class:`gnssacc.estimators.settings.ZuptSettings`), else none; ``gyro_psd`` [rad^2/s] floors
    the zero-rate variance."""
    if stationary is None or not zupt.enabled:
        return StationaryEpochs.empty()
    return stationary_epochs(run.imu, stationary.spans, zupt.interval_s, gyro_psd)
