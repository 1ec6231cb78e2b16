"""What an EKF pass records: its output rows (:class:`Recorder`) and its updates' statistics per
update kind (:class:`Tally`)."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..core.rotations import dcm_to_euler, euler_error_jacobian
from ..core.solution import NavSolution
from .aids import KINDS, Measurement, tail_bound
from .layout import ATT, N_NAV, NAV
from .state import FilterState


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


class Tally:
    """Per update kind: counts, NIS, log-likelihood (optionally every update's) and the lag-1
    autocorrelation of the whitened innovations (white for a correct model)."""

    def __init__(self, keep: bool):
        self.keep = keep
        self.prev: dict[str, np.ndarray | None] = {k: None for k in KINDS}
        self.lag1 = {k: [0.0, 0.0] for k in KINDS}  # sum w_k w_(k-1), sum w_k^2
        self.n = {k: 0 for k in KINDS}
        self.rejected = {k: 0 for k in KINDS}
        self.nis_sum = {k: 0.0 for k in KINDS}
        self.dof = {k: 0 for k in KINDS}
        self.loglik = {k: 0.0 for k in KINDS}
        self.beyond = {k: 0 for k in KINDS}  # NIS beyond the chi-square tail bound
        # t, NIS per dof, log-likelihood
        self.series: dict[str, tuple[list, list, list]] = {k: ([], [], []) for k in KINDS}

    def add(self, t: float, m: Measurement, nis: float, loglik: float, used: bool, wz) -> None:
        k = m.kind
        if not used:
            self.rejected[k] += 1
            return
        prev = self.prev[k]
        if prev is not None:
            lag = self.lag1[k]
            lag[0] += float(wz @ prev)
            lag[1] += float(wz @ wz)
        self.prev[k] = wz
        self.n[k] += 1
        self.nis_sum[k] += nis
        self.dof[k] += len(m.dz)
        self.loglik[k] += loglik
        self.beyond[k] += nis > tail_bound(len(m.dz))
        if self.keep:
            for lst, v in zip(self.series[k], (t, nis / len(m.dz), loglik), strict=True):
                lst.append(v)

    def stats(self) -> dict:
        out: dict[str, Any] = {}
        for k in KINDS:
            out[f"n_{k}_updates"] = self.n[k]
            out[f"n_{k}_rejected"] = self.rejected[k]
            # Normalised innovation squared per degree of freedom: ~1 for a consistent filter.
            out[f"nis_{k}_mean"] = self.nis_sum[k] / self.dof[k] if self.dof[k] else None
            # Updates beyond the chi-square bound of tail probability TAIL_P: ~TAIL_P of them for
            # Gaussian errors; far more when the errors have heavy tails (outliers, multipath).
            out[f"n_{k}_beyond"] = self.beyond[k]
            out[f"loglik_{k}"] = self.loglik[k]
            # Whitened innovations of a correct model are white: ~0 here; a slowly varying
            # error the model misses (too little IMU noise, correlated GNSS errors) makes it > 0.
            out[f"acf1_{k}"] = (
                float(self.lag1[k][0] / self.lag1[k][1]) if self.lag1[k][1] > 0 else None
            )
            if self.keep:
                t, nis, ll = self.series[k]
                out[f"nis_{k}_t"], out[f"nis_{k}"], out[f"loglik_{k}_series"] = (
                    np.asarray(t),
                    np.asarray(nis),
                    np.asarray(ll),
                )
        return out
