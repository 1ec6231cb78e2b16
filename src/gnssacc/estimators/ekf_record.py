"""What an EKF pass records: its output rows (:class:`Recorder`) and its updates' statistics per
update kind (:class:`Tally`)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..core.rotations import dcm_to_euler, euler_error_jacobian
from ..core.solution import NavSolution
from .aids import KINDS, Measurement, tail_bound
from .layout import ATT, N_NAV, NAV
from .state import FilterState


_LOG_2PI = math.log(2.0 * math.pi)


def innovation_loglik(nis: float, logdet: float, dof: int) -> float:
    """The Gaussian log-likelihood of an innovation of ``dof`` degrees of freedom from its NIS and
    ``log det S`` (:func:`gnssacc.estimators.kalman.joseph_update`)."""
    return -0.5 * (nis + logdet + dof * _LOG_2PI)


def _added(total: float, values: np.ndarray) -> float:
    """``total`` plus ``values`` one after the other (a running sum's order: ``np.sum`` adds
    pairwise, which differs in the last bits)."""
    return float(np.add.accumulate(np.concatenate(([total], values)))[-1])


class Recorder:
    """Collects the output rows; memory grows with the outputs only. Each row keeps the attitude
    matrix and the covariance pieces it needs; Euler angles and their sigmas are computed for all
    rows at once in :meth:`solution` (per-row numpy calls cost more than the filter step)."""

    def __init__(self, n: int, store_P: bool):
        self.t = np.empty(n)
        self.pos = np.empty((n, 3))
        self.v_n = np.empty((n, 3))
        self.R_nb = np.empty((n, 3, 3))
        self.b_a = np.empty((n, 3))
        self.b_g = np.empty((n, 3))
        self.var = np.empty((n, N_NAV))
        self.P_att = np.empty((n, 3, 3))
        self.P = np.empty((n, N_NAV, N_NAV)) if store_P else None
        self.n = 0

    def add(self, t: float, s: FilterState) -> None:
        i = self.n
        self.t[i], self.pos[i], self.v_n[i], self.R_nb[i] = t, s.pos, s.v_n, s.R_nb
        self.b_a[i], self.b_g[i] = s.b_a, s.b_g
        self.var[i] = s.P.diagonal()[NAV]
        self.P_att[i] = s.P[ATT, ATT]
        if self.P is not None:
            self.P[i] = s.P[NAV, NAV]
        self.n += 1

    def solution(self, method: str, runtime_s: float, stats: dict) -> NavSolution:
        n = self.n
        rpy = np.column_stack(dcm_to_euler(self.R_nb[:n]))
        sigma = np.sqrt(np.maximum(self.var[:n], 0.0))
        J = euler_error_jacobian(rpy[:, 0], rpy[:, 1], rpy[:, 2])
        sigma[:, ATT] = np.sqrt(np.maximum(np.einsum("nij,njk,nik->ni", J, self.P_att[:n], J), 0.0))
        return NavSolution(
            method,
            self.t[:n],
            self.pos[:n, 0],
            self.pos[:n, 1],
            self.pos[:n, 2],
            self.v_n[:n],
            rpy,
            self.b_a[:n],
            self.b_g[:n],
            sigma,
            runtime_s,
            stats,
            None if self.P is None else self.P[:n],
        )


class _KindTally:
    """The running figures of one update kind (:class:`Tally`)."""

    __slots__ = ("n", "rejected", "nis_sum", "dof", "loglik", "beyond", "lag", "prev", "series")

    def __init__(self):
        self.n = self.rejected = self.dof = self.beyond = 0
        self.nis_sum = self.loglik = 0.0
        self.lag = [0.0, 0.0]  # sum w_k w_(k-1), sum w_k^2
        # The last whitened innovation per number of axes: a velocity's measured axes may change
        # from one update to the next, and the lag-1 sums pair updates with as many axes.
        self.prev: dict[int, np.ndarray] = {}
        self.series: tuple[list, list, list] = ([], [], [])  # t, NIS per dof, log-likelihood


class Tally:
    """Per update kind: counts, NIS, log-likelihood (optionally every update's) and the lag-1
    autocorrelation of the whitened innovations (white for a correct model)."""

    def __init__(self, keep: bool):
        self.keep = keep
        self.kinds = {k: _KindTally() for k in KINDS}

    @property
    def loglik(self) -> dict[str, float]:
        """The log-likelihood per update kind."""
        return {k: v.loglik for k, v in self.kinds.items()}

    def add(self, t: float, m: Measurement, nis: float, loglik: float, used: bool, wz) -> None:
        """The update ``m`` at ``t`` [s]: its NIS, log-likelihood, whether it was applied and its
        whitened innovation (:func:`gnssacc.estimators.ekf.kalman_update`)."""
        self.add_update(t, m.kind, len(m.dz), nis, loglik, used, wz)

    def add_update(
        self, t: float, kind: str, dof: int, nis: float, loglik: float, used: bool, wz
    ) -> None:
        """:meth:`add` for an update of ``kind`` with ``dof`` degrees of freedom."""
        k = self.kinds[kind]
        if not used:
            k.rejected += 1
            return
        prev = k.prev.get(len(wz))
        if prev is not None:
            lag = k.lag
            lag[0] += float((wz * prev).sum())  # as add_updates sums (a BLAS dot may fuse)
            lag[1] += float((wz * wz).sum())
        k.prev[len(wz)] = wz
        k.n += 1
        k.nis_sum += nis
        k.dof += dof
        k.loglik += loglik
        k.beyond += nis > tail_bound(dof)
        if self.keep:
            for lst, v in zip(k.series, (t, nis / dof, loglik), strict=True):
                lst.append(v)

    def add_updates(self, kind: str, dof: int, t, nis, logdet, used, wz) -> None:
        """:meth:`add_update` for consecutive updates of one ``kind`` (arrays in time order: ``t``
        [s], NIS, ``log det S``, applied or not, whitened innovations (m, ``dof``)), their
        log-likelihoods (:func:`innovation_loglik`) computed here: the same sums, added in the
        same order (a pass's compiled stretch hands over hundreds at once)."""
        k = self.kinds[kind]
        used = np.asarray(used, bool)
        k.rejected += int(used.size - np.count_nonzero(used))
        t, nis, logdet, wz = t[used], nis[used], logdet[used], wz[used]
        if nis.size == 0:
            return
        loglik = -0.5 * (nis + logdet + dof * _LOG_2PI)
        prev = k.prev.get(wz.shape[1])
        w = wz if prev is None else np.vstack([prev[None, :], wz])
        if len(w) > 1:
            k.lag[0] = _added(k.lag[0], (w[1:] * w[:-1]).sum(axis=1))
            k.lag[1] = _added(k.lag[1], (w[1:] * w[1:]).sum(axis=1))
        k.prev[wz.shape[1]] = wz[-1]
        k.n += nis.size
        k.nis_sum = _added(k.nis_sum, nis)
        k.dof += dof * nis.size
        k.loglik = _added(k.loglik, loglik)
        k.beyond += int(np.count_nonzero(nis > tail_bound(dof)))
        if self.keep:
            for lst, v in zip(k.series, (t, nis / dof, loglik), strict=True):
                lst.extend(v.tolist())

    def stats(self) -> dict:
        out: dict[str, Any] = {}
        for name, k in self.kinds.items():
            out[f"n_{name}_updates"] = k.n
            out[f"n_{name}_rejected"] = k.rejected
            # Normalised innovation squared per degree of freedom: ~1 for a consistent filter.
            out[f"nis_{name}_mean"] = k.nis_sum / k.dof if k.dof else None
            # Updates beyond the chi-square bound of tail probability TAIL_P: ~TAIL_P of them for
            # Gaussian errors; far more when the errors have heavy tails (outliers, multipath).
            out[f"n_{name}_beyond"] = k.beyond
            out[f"loglik_{name}"] = k.loglik
            # Whitened innovations of a correct model are white: ~0 here; a slowly varying
            # error the model misses (too little IMU noise, correlated GNSS errors) makes it > 0.
            out[f"acf1_{name}"] = float(k.lag[0] / k.lag[1]) if k.lag[1] > 0 else None
            if self.keep:
                t, nis, ll = k.series
                out[f"nis_{name}_t"], out[f"nis_{name}"], out[f"loglik_{name}_series"] = (
                    np.asarray(t),
                    np.asarray(nis),
                    np.asarray(ll),
                )
        return out
