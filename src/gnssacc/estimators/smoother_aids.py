"""The smoother's ground-vehicle aids: the non-holonomic constraint's factors on its nodes.

The constraint's epochs (:mod:`gnssacc.estimators.nhc`, every ``[nhc] interval_s``) are given to
the nodes nearest them, within half an interval, one epoch per node: the smoother then applies
the constraint as often as the EKF does, whatever the node rate (a 10 Hz receiver's nodes do not
get ten constraints a second). At such a node the decision of :func:`gnssacc.estimators.nhc.decide`
is taken on the node's prediction (the preintegrated state from the previous node's estimate):
its forward speed at the reference point, that speed's 1-sigma from the predicted velocity
covariance (the previous node's marginal plus the preintegration's; the attitude's share
neglected), and the bias-corrected gyro held at the node's time. Its counts go into the smoother's ``stats``:
``n_nhc_factors``, ``n_nhc_skipped_rest``, ``n_nhc_skipped_turn``.
"""
from __future__ import annotations

import math

import numpy as np
from gtsam.symbol_shorthand import B, V, X

from ..core.earth import earth_rate_n
from ..factors import nhc_factor
from . import nhc as nhc_rules
from .settings import SmootherSettings


def nearest_nodes(times: np.ndarray, epochs: np.ndarray, interval_s: float) -> np.ndarray:
    """The nodes given an epoch each: every epoch's nearest node within half ``interval_s`` [s],
    each node once, the start node (index 0, which has no prediction) left out."""
    if len(epochs) == 0 or len(times) < 2:
        return np.zeros(0, int)
    i = np.clip(np.searchsorted(times, epochs), 1, len(times) - 1)
    i = np.where(np.abs(times[i - 1] - epochs) < np.abs(times[i] - epochs), i - 1, i)
    near = np.abs(times[i] - epochs) <= 0.5 * interval_s + 1e-9
    return np.unique(i[near & (i > 0)])


class NhcFactors:
    """Builds the non-holonomic factors of a smoother run (module docstring).

    Parameters
    ----------
    run : RecordedRun
    settings : SmootherSettings
    times : ndarray
        The node times [s].
    stationary : gnssacc.prepare.stationary.StationaryReport or None
    stats : dict
        The run's statistics (the counts are added to it).
    """

    def __init__(self, run, settings: SmootherSettings, times: np.ndarray, stationary, stats: dict):
        self.cfg, self.stats = settings.nhc, stats
        stats.update(n_nhc_factors=0, **nhc_rules.counts())
        nodes = np.zeros(0, int)
        if self.cfg.enabled:
            epochs = nhc_rules.nhc_epochs(run.imu, float(times[0]), float(times[-1]), self.cfg.interval_s)
            nodes = nearest_nodes(times, epochs.t, self.cfg.interval_s)
        self.nodes = set(nodes.tolist())
        node_t = times[nodes]
        self.rest = dict(zip(nodes.tolist(), (stationary.mask(node_t) if stationary is not None
                                              else np.zeros(len(nodes), bool)).tolist()))
        self.omega_b = dict(zip(nodes.tolist(), np.asarray(run.imu.omega_ib_b)[nhc_rules.held_samples(run.imu.t, node_t)]))
        self.w_ie = earth_rate_n(run.origin.lat0)

    def add(self, graph, i: int, R_nb: np.ndarray, v_n: np.ndarray, c_vel: np.ndarray, b_g: np.ndarray) -> None:
        """The constraint on node ``i`` when it has an epoch and :func:`gnssacc.estimators.nhc.decide`
        applies it: ``R_nb``, ``v_n`` [m/s, NED], ``c_vel`` [m^2/s^2] the node's predicted attitude,
        velocity and velocity covariance, ``b_g`` [rad/s] the gyro bias it was predicted with."""
        if i not in self.nodes:
            return
        cfg, omega = self.cfg, self.omega_b[i]
        w_b = omega - b_g - R_nb.T @ self.w_ie
        v_b = cfg.R_vb @ (R_nb.T @ v_n + np.cross(w_b, cfg.lever_arm_b))
        fwd = R_nb @ cfg.R_vb[0]     # the vehicle's forward axis, NED
        why = nhc_rules.decide(self.rest[i], float(v_b[0]), math.sqrt(max(float(fwd @ c_vel @ fwd), 0.0)),
                               float(w_b[2]), float(cfg.sigma_mps[0]), cfg.pivot_offset_m)
        if why != nhc_rules.APPLY:
            self.stats[nhc_rules.SKIPPED[why]] += 1
            return
        graph.add(nhc_factor(X(i), V(i), B(i), omega, cfg.lever_arm_b, self.w_ie, cfg.sigma_mps, cfg.R_vb))
        self.stats["n_nhc_factors"] += 1
