"""The true IMU biases of a simulated run, drawn again from the run's random streams when asked.

A run's true biases (turn-on + Gauss-Markov + drift, :mod:`.sim_imu_errors`) are six floats per
IMU sample, as much as the IMU's own specific force and rate; they are only read to score the
estimated biases at the solution epochs. :class:`TrueBias` keeps what draws them (the streams'
starts, the turn-on biases and the drift, a few hundred bytes plus the drift's one-second walk)
and draws them again, block by block, bit for bit the numbers the simulator added to the IMU.
"""

from __future__ import annotations

from typing import Iterator

import numpy as np

from . import sim_path
from .sim_imu_errors import BiasDrift, BiasSeed


class TrueBias:
    """The accelerometer [m/s^2] and gyro [rad/s] bias in effect at each IMU sample, body axes.

    Parameters
    ----------
    t : ndarray, shape (n,)
        The IMU sample times [s] (the run's own array: no copy).
    seed : BiasSeed
        The turn-on and Gauss-Markov biases' draws (:attr:`ImuErrorStream.bias_seed`).
    drift : BiasDrift or None
        The slow drift (None: zero).
    """

    def __init__(self, t: np.ndarray, seed: BiasSeed, drift: BiasDrift | None):
        if len(t) != seed.n:
            raise ValueError(f"{len(t)} sample times for {seed.n} biases")
        self.t, self.seed, self.drift = t, seed, drift

    def __len__(self) -> int:
        return self.seed.n

    @property
    def nbytes(self) -> int:
        """Bytes of the arrays it holds beyond the run's sample times (the draws, the drift's walk)."""
        held = [
            *vars(self.seed).values(),
            *(vars(self.drift).values() if self.drift is not None else ()),
        ]
        return sum(v.nbytes for v in held if isinstance(v, np.ndarray))

    def with_drift(
        self, bias_a: np.ndarray, bias_g: np.ndarray, rows
    ) -> tuple[np.ndarray, np.ndarray]:
        """The turn-on + Gauss-Markov biases of samples ``rows`` (a slice or indices) plus the
        drift: the one sum the simulator's sweep, :meth:`blocks` and :meth:`at` make, so their
        numbers agree bit for bit (each term is per sample)."""
        if self.drift is None:
            return bias_a, bias_g
        drift_a, drift_g = self.drift.at(self.t[rows] - self.t[0])
        return bias_a + drift_a, bias_g + drift_g

    def blocks(self, size: int | None = None) -> Iterator[tuple[int, int, np.ndarray, np.ndarray]]:
        """``(k0, k1, bias_a, bias_g)`` for consecutive blocks of ``size`` samples ``k0 .. k1-1``
        ((m, 3) each; default :data:`gnssacc.sources.sim_path.IMU_BLOCK`)."""
        size = sim_path.IMU_BLOCK if size is None else int(size)
        gm_a, gm_g = self.seed.streams()
        s = self.seed
        for k0 in range(0, s.n, size):
            k1 = min(k0 + size, s.n)
            yield (k0, k1) + self.with_drift(
                s.turn_on_a + gm_a.take(k1 - k0), s.turn_on_g + gm_g.take(k1 - k0), slice(k0, k1)
            )

    def samples(self) -> tuple[np.ndarray, np.ndarray]:
        """Every sample's biases: accelerometer [m/s^2] and gyro [rad/s], shape (n, 3) each (drawn on each call)."""
        out_a, out_g = np.empty((self.seed.n, 3)), np.empty((self.seed.n, 3))
        for k0, k1, b_a, b_g in self.blocks():
            out_a[k0:k1], out_g[k0:k1] = b_a, b_g
        return out_a, out_g

    def at(
        self, t: np.ndarray, t_samples: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """The biases interpolated linearly at times ``t`` [s], held constant outside the samples.

        Equal bit for bit to ``np.interp(t, t_samples, samples()[.][:, i])`` per axis, with
        memory in the number of epochs, not of samples: only the samples bracketing an epoch
        are kept as the blocks pass (``np.interp`` reads nothing else).

        Parameters
        ----------
        t : ndarray, shape (K,)
            Query times [s].
        t_samples : ndarray, shape (n,), optional
            The samples' times [s] (default: :attr:`t`; a caller whose IMU clock was shifted
            passes its own).

        Returns
        -------
        bias_a, bias_g : ndarray, shape (K, 3)
        """
        t = np.asarray(t, float)
        t_samples = self.t if t_samples is None else np.asarray(t_samples, float)
        n = self.seed.n
        j = np.clip(np.searchsorted(t_samples, t, side="right") - 1, 0, n - 1)
        need = np.unique(np.concatenate([j, np.minimum(j + 1, n - 1)]))
        b_a, b_g = np.empty((len(need), 3)), np.empty((len(need), 3))
        gm_a, gm_g = self.seed.streams()
        for k0 in range(0, n, sim_path.IMU_BLOCK):  # the Gauss-Markov recursion passes every sample
            k1 = min(k0 + sim_path.IMU_BLOCK, n)
            lo, hi = np.searchsorted(need, (k0, k1))
            b_a[lo:hi], b_g[lo:hi] = (
                gm_a.take(k1 - k0)[need[lo:hi] - k0],
                gm_g.take(k1 - k0)[need[lo:hi] - k0],
            )
        b_a, b_g = self.with_drift(
            self.seed.turn_on_a + b_a, self.seed.turn_on_g + b_g, need
        )  # the drift: only there
        tn = t_samples[need]
        return tuple(
            np.column_stack([np.interp(t, tn, b[:, i]) for i in range(3)])
            if len(t)
            else np.zeros((0, 3))
            for b in (b_a, b_g)
        )
