"""The smoother's ground-vehicle aids: the non-holonomic constraint's and the wheel odometry's
factors on its nodes.

The constraint's epochs (:mod:`gnssacc.estimators.nhc`, every ``[nhc] interval_s``) are given to
the nodes nearest them, within half an interval, one epoch per node: the smoother then applies
the constraint as often as the EKF does, whatever the node rate (a 10 Hz receiver's nodes do not
get ten constraints a second). At such a node the decision of :func:`gnssacc.estimators.nhc.decide`
is taken on the node's prediction (the preintegrated state from the previous node's estimate):
its forward speed at the reference point, that speed's 1-sigma from the predicted velocity
covariance (the previous node's marginal plus the preintegration's; the attitude's share
neglected), and the bias-corrected gyro held at the node's time. Its counts go into the smoother's ``stats``:
``n_nhc_factors``, ``n_nhc_skipped_rest``, ``n_nhc_skipped_turn``.

Wheel odometry (:mod:`gnssacc.estimators.odometry`) is used the same way: the sample nearest
each node within half the odometry's interval (``[odometry] interval_s``, at least the samples'
own spacing), one per node, as :func:`gnssacc.factors.odometry_factor` on the node's pose,
velocity, bias and its scale factor ``K_i``. The scale factor is a variable of every node,
linked node to node by the first-order Gauss-Markov factor of ``[odometry] scale_sigma`` and
``scale_tau_s`` (:func:`gnssacc.factors.gauss_markov_factor`; the EKF's state of the same model),
so the window stays a chain of nodes. A sample whose sign contradicts the node's prediction is
refused (:func:`gnssacc.estimators.odometry.decide`). Counts: ``n_odo_factors``,
``n_odo_skipped_sign``; the scale factor at the last node and its 1-sigma: ``odometry_scale``,
``odometry_scale_sigma``.
"""

from __future__ import annotations

import math

import gtsam
import numpy as np
from gtsam.symbol_shorthand import B, K, V, X

from ..core.earth import earth_rate_n
from ..core.rotations import cross3
from ..factors import gauss_markov_factor, nhc_factor, odometry_factor
from . import nhc as nhc_rules
from . import odometry as odo_rules
from .settings import SmootherSettings


def _nearest(t: np.ndarray, at: np.ndarray) -> np.ndarray:
    """Index of the entry of sorted ``t`` nearest each time of ``at``."""
    i = np.clip(np.searchsorted(t, at), 1, len(t) - 1) if len(t) > 1 else np.zeros(len(at), int)
    return np.where((i > 0) & (np.abs(t[i - 1] - at) < np.abs(t[i] - at)), i - 1, i)


def nearest_nodes(times: np.ndarray, epochs: np.ndarray, interval_s: float) -> np.ndarray:
    """The nodes given an epoch each: every epoch's nearest node within half ``interval_s`` [s],
    each node once, the start node (index 0, which has no prediction) left out."""
    if len(epochs) == 0 or len(times) < 2:
        return np.zeros(0, int)
    i = _nearest(times, epochs)
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
            epochs = nhc_rules.nhc_epochs(
                run.imu, float(times[0]), float(times[-1]), self.cfg.interval_s
            )
            nodes = nearest_nodes(times, epochs.t, self.cfg.interval_s)
        self.nodes = set(nodes.tolist())
        node_t = times[nodes]
        self.rest = dict(
            zip(
                nodes.tolist(),
                (
                    stationary.mask(node_t)
                    if stationary is not None
                    else np.zeros(len(nodes), bool)
                ).tolist(),
            )
        )
        self.omega_b = dict(
            zip(
                nodes.tolist(),
                np.asarray(run.imu.omega_ib_b)[nhc_rules.held_samples(run.imu.t, node_t)],
            )
        )
        self.w_ie = earth_rate_n(run.origin.lat0)

    def add(
        self, graph, i: int, R_nb: np.ndarray, v_n: np.ndarray, c_vel: np.ndarray, b_g: np.ndarray
    ) -> None:
        """The constraint on node ``i`` when it has an epoch and :func:`gnssacc.estimators.nhc.decide`
        applies it: ``R_nb``, ``v_n`` [m/s, NED], ``c_vel`` [m^2/s^2] the node's predicted attitude,
        velocity and velocity covariance, ``b_g`` [rad/s] the gyro bias it was predicted with."""
        if i not in self.nodes:
            return
        cfg, omega = self.cfg, self.omega_b[i]
        w_b = omega - b_g - R_nb.T @ self.w_ie
        v_b = R_nb.T @ v_n + cross3(w_b, cfg.lever_arm_b)
        v_b = v_b if cfg.R_vb is None else cfg.R_vb @ v_b
        fwd = R_nb @ cfg.forward_b  # the vehicle's forward axis, NED
        why = nhc_rules.decide(
            self.rest[i],
            float(v_b[0]),
            math.sqrt(max(float(fwd @ c_vel @ fwd), 0.0)),
            float(w_b[2]),
            float(cfg.sigma_mps[0]),
            cfg.pivot_offset_m,
        )
        if why != nhc_rules.APPLY:
            self.stats[nhc_rules.SKIPPED[why]] += 1
            return
        graph.add(
            nhc_factor(X(i), V(i), B(i), omega, cfg.lever_arm_b, self.w_ie, cfg.sigma_mps, cfg.R_vb)
        )
        self.stats["n_nhc_factors"] += 1


class OdometryFactors:
    """Builds the wheel odometry's factors and scale-factor variables of a smoother run (module
    docstring). ``active`` is False without odometry (or with ``[odometry] enabled = false``):
    the nodes then carry no scale factor.

    Parameters
    ----------
    run : RecordedRun
    settings : SmootherSettings
    times : ndarray
        The node times [s].
    stats : dict
        The run's statistics (the counts are added to it).
    """

    def __init__(self, run, settings: SmootherSettings, times: np.ndarray, stats: dict):
        self.cfg, self.stats = settings.odometry, stats
        self.R_vb, self.forward_b = settings.nhc.R_vb, settings.nhc.forward_b
        ep = odo_rules.epochs_for(run, self.cfg, float(times[0]))
        self.active = len(ep) > 0
        self.nodes: set = set()
        if not self.active:
            return
        stats.update(n_odo_factors=0, **odo_rules.counts())
        spacing = float(np.median(np.diff(ep.t))) if len(ep) > 1 else self.cfg.interval_s
        reach = max(self.cfg.interval_s, spacing)
        nodes = nearest_nodes(times, ep.t, reach)
        self.sample = dict(zip(nodes.tolist(), _nearest(ep.t, times[nodes]).tolist()))
        self.nodes = set(self.sample)
        self.ep = ep
        self.omega_b = dict(
            zip(
                nodes.tolist(),
                np.asarray(run.imu.omega_ib_b)[nhc_rules.held_samples(run.imu.t, times[nodes])],
            )
        )
        self.w_ie = earth_rate_n(run.origin.lat0)
        self.tau, self.sigma = np.array([self.cfg.scale_tau_s]), np.array([self.cfg.scale_sigma])

    def prior(self, graph, values, i: int, k: float, var_k: float | None) -> None:
        """The scale factor of node ``i`` with a prior at ``k`` of variance ``var_k`` (``None`` or
        not positive: the start's, ``[odometry] scale_sigma`` squared)."""
        var = var_k if var_k is not None and var_k > 0 else float(self.sigma[0]) ** 2
        graph.add(
            gtsam.PriorFactorVector(
                K(i), np.array([k]), gtsam.noiseModel.Isotropic.Sigma(1, np.sqrt(var))
            )
        )
        values.insert(K(i), np.array([k]))

    def chain(self, graph, values, i: int, dt: float, k_prev: float) -> None:
        """Node ``i``'s scale factor, predicted from node ``i - 1``'s ``k_prev`` over ``dt`` [s]."""
        graph.add(gauss_markov_factor(K(i - 1), K(i), dt, self.tau, self.sigma))
        values.insert(K(i), np.exp(-dt / self.tau) * k_prev)

    def add(
        self,
        graph,
        i: int,
        R_nb: np.ndarray,
        v_n: np.ndarray,
        c_vel: np.ndarray,
        b_g: np.ndarray,
        k: float,
    ) -> None:
        """The odometry factor of node ``i`` unless its sample's sign contradicts the node's
        prediction (``R_nb``, ``v_n`` [m/s, NED], ``c_vel`` [m^2/s^2], ``b_g`` [rad/s], the scale
        factor ``k`` it was predicted with)."""
        j, cfg, omega = self.sample[i], self.cfg, self.omega_b[i]
        w_b = omega - b_g - R_nb.T @ self.w_ie
        fwd = R_nb @ self.forward_b  # the vehicle's forward axis, NED
        v_x = float(fwd @ v_n + self.forward_b @ cross3(w_b, cfg.lever_arm_b))
        sigma_pred = (1.0 + k) * math.sqrt(max(float(fwd @ c_vel @ fwd), 0.0))
        why = odo_rules.decide(
            float(self.ep.v[j]), float(self.ep.sigma[j]), (1.0 + k) * v_x, sigma_pred
        )
        if why != odo_rules.APPLY:
            self.stats[odo_rules.SKIPPED[why]] += 1
            return
        graph.add(
            odometry_factor(
                X(i),
                V(i),
                B(i),
                K(i),
                float(self.ep.v[j]),
                omega,
                cfg.lever_arm_b,
                self.w_ie,
                float(self.ep.sigma[j]),
                self.R_vb,
            )
        )
        self.stats["n_odo_factors"] += 1

    def final_stats(self, online) -> None:
        """The scale factor of the last node with an online estimate (``online``: the smoother's
        record) and its 1-sigma, into ``stats``."""
        if not self.active:
            return
        done = np.flatnonzero(online.done)
        if len(done):
            self.stats["odometry_scale"] = float(online.k[done[-1]])
            self.stats["odometry_scale_sigma"] = float(np.sqrt(max(online.var_k[done[-1]], 0.0)))
