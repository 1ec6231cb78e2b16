"""GTSAM iSAM2 fixed-lag smoother: the factor-graph twin of the paper's EKF.

Graph, in a local NED tangent frame at the run's origin:

* nodes (pose X, velocity V, IMU bias B, and the Gauss-Markov variables the aids ask for) at the
  start, at the epochs the pass's aids ask for (:mod:`gnssacc.estimators.aids`: the fixes, the
  stationary epochs no fix is near), at the end of the recording, and fill nodes at most
  ``[smoother] max_node_spacing_s`` apart in between (:func:`gnssacc.estimators.smoother_graph.
  node_times`);
* ``CombinedImuFactor`` between consecutive nodes (``PreintegratedCombinedMeasurements`` with
  gravity from the WGS-84 model at the origin and the earth rate as Coriolis), noise densities
  and bias random walks from the same configuration as the EKF, and the same data-quality
  inflation over suspect IMU spans; the Gauss-Markov factor between consecutive nodes'
  Gauss-Markov variables;
* the aids' factors on each node, in their order (:attr:`gnssacc.estimators.aids.SmootherAid.
  order`), after those they put on the interval before it.

Two estimates per node are reported: the *online* one (the newest node right after its
update, what a real-time user would have had) and the *fixed-lag* one (the node's value when
it leaves the lag window, or at the end), each with 1-sigma from the marginal covariances of
iSAM2's linear system (:class:`gnssacc.estimators.window_marginals.WindowMarginals`, which keeps a
copy of that system cheaper to query than iSAM2's Bayes tree), and each aid's consistency figures
for it (:meth:`gnssacc.estimators.aids.SmootherAid.score`).

An ill-posed update (GTSAM's indeterminant-system error) never ends a run: the window is
re-initialised from the last estimate with priors from its marginal covariances, and the event
is counted in ``stats``.
"""

from __future__ import annotations

import time
from dataclasses import replace
from functools import partial

import gtsam
import numpy as np

from ..checks.quality import QualityReport, inflation_segments
from ..core.earth import earth_rate_n, normal_gravity
from ..core.progress import progress
from ..core.recording import InitialState, RecordedRun
from ..core.solution import NavSolution
from ..core.states import YAW
from ..factors import gauss_markov_factor, joint_prior_factor
from .aids import (
    SMOOTHER_METHODS,
    NodePrediction,
    SmootherAid,
    SmootherContext,
    smoother_aids,
    smoother_counts,
)
from .layout import (
    B_ACC,
    B_GYRO,
    GNSS_ERROR,
    NAVSTATE_VEL,
    SYM_B,
    SYM_G,
    SYM_V,
    SYM_X,
    NodeLayout,
    StateLayout,
)
from .mechanization import turn_rates
from .settings import SmootherSettings
from .smoother_graph import (
    ImuModel,
    NodeEstimate,
    NodeRecord,
    WindowSmoother,
    inflation_over,
    initial_prior,
    insert_bias,
    is_ill_posed,
    node_times,
    preintegrate,
    touches,
)
from .state import start_of_pass

#: Method ids and the acceleration form each applies (``None``: none).
METHODS = SMOOTHER_METHODS


def run_smoother(
    run: RecordedRun,
    settings,
    method: str = "smoother",
    *,
    quality: QualityReport | None = None,
    init: InitialState | None = None,
    stationary=None,
    show_progress: bool = False,
) -> dict[str, NavSolution]:
    """Run the fixed-lag smoother.

    Parameters
    ----------
    run : RecordedRun
        The fixes' sigmas as stated (the settings' noise model applies ``[gnss] sigma_scale``).
    settings : SmootherSettings or gnssacc.core.config.RunConfig
        The smoother's settings (:class:`gnssacc.estimators.settings.SmootherSettings`; a run
        configuration is reduced to them first).
    method : {"smoother", "smoother-acc", "smoother-accw"}
        Without the GNSS-acceleration factor, with the paper's, or with the window-consistent one
        (:data:`METHODS`).
    quality : QualityReport, optional
        Data-quality findings (computed when omitted, from a run configuration).
    init : InitialState, optional
        The start (the run's own when omitted, as the EKF's).
    stationary : gnssacc.prepare.stationary.StationaryReport, optional
        Where the vehicle stands still: zero-velocity and zero-rate factors there (``[zupt]``).
    show_progress : bool

    Returns
    -------
    dict
        ``{method: fixed-lag NavSolution, method + "-online": online NavSolution}``, one row per
        node; ``stats`` has the factor counts and the aids' consistency figures of that estimate
        (``nis_pos_mean``: the whitened GNSS residuals against their expectation, 1 when
        consistent).
    """
    if method not in METHODS:
        raise ValueError(f"unknown smoother method {method!r}; known: {', '.join(METHODS)}")
    wall0 = time.perf_counter()
    init, quality = start_of_pass(run, settings, init, quality)
    settings = SmootherSettings.of(settings)
    stats = {
        "n_nodes": 0,
        **smoother_counts(),
        "n_ill_posed_recovered": 0,
        "factorization_switched_to_qr": False,
        "init": init.how,
        "t_init": float(init.t),
        "lag_s": settings.lag_s,
    }
    aids = smoother_aids(SmootherContext(run, settings, init, stationary, METHODS[method], stats))
    epochs = np.zeros(0)
    for aid in aids:
        epochs = np.union1d(epochs, aid.node_epochs(epochs))
    times = node_times(float(init.t), float(run.imu.t[-1]), epochs, settings.max_node_spacing_s)
    stats["n_nodes"] = len(times)
    loop = _Loop(run, settings, quality, init, times, aids, stats)
    loop.feed(method, show_progress)
    for aid in aids:
        aid.final_stats(loop, stats)
    stats["final_window_variables"] = int(loop.smoother.isam.getLinearizationPoint().size())
    stats["final_factor_slots"] = int(loop.smoother.isam.getFactors().size())
    runtime = time.perf_counter() - wall0
    out = {}
    for mid, rec in ((method, loop.fixed), (method + "-online", loop.online)):
        scored = {k: v for aid in aids for k, v in aid.score(loop, rec).items()}
        out[mid] = with_considered_yaw(
            rec.solution(run, mid, times, runtime, {**stats, **scored}), init
        )
    return out


def with_considered_yaw(sol: NavSolution, init: InitialState) -> NavSolution:
    """``sol`` with the yaw held as the EKF holds it when the start found the yaw undetermined
    (:func:`gnssacc.estimators.state.consider_for`): its stated yaw sigma [rad] is the marginal's
    and the start's in quadrature.

    A factor graph cannot hold a Schmidt consider state: its yaw marginal then comes from
    linearising about a specific force that is noise or the smoother's own tilt-bias error,
    turned by the yaw error (false observability, docs/consistency.md), a few degrees where the
    run never told the yaw; its estimate stays near the start's guess, whose sigma says how far
    off that may be."""
    if init.yaw_evidence != "undetermined":
        return sol
    sigma = sol.sigma.copy()
    sigma[:, YAW] = np.hypot(sigma[:, YAW], float(init.sigma_att_rad[2]))
    return replace(sol, sigma=sigma)


def estimate(
    prep, settings: SmootherSettings, method: str = "smoother", **options
) -> dict[str, NavSolution]:
    """The smoother over a prepared recording (:class:`gnssacc.prepare.prepared.Prepared`): its run,
    start, quality report and stationary spans, with the smoother's own ``settings``; ``options``
    as for :func:`run_smoother`."""
    return run_smoother(
        prep.run,
        settings,
        method,
        init=prep.init,
        quality=prep.quality,
        stationary=prep.stationary,
        **options,
    )


class _Loop:
    """Feeds iSAM2 node by node and records the online and fixed-lag estimates; what the aids see
    of the smoother (:class:`gnssacc.estimators.aids.SmootherAid`: ``times``, ``prev``,
    ``segments``, :meth:`has_node`, :meth:`preintegrate_to`, :meth:`last_online`)."""

    def __init__(self, run, settings, quality, init, times, aids: list[SmootherAid], stats):
        self.run, self.settings, self.times, self.aids, self.stats = (
            run,
            settings,
            times,
            aids,
            stats,
        )
        self.segments = inflation_segments(run.imu, quality, settings.suspect)
        origin = run.origin
        g = float(normal_gravity(origin.lat0, origin.h0))
        self.model = ImuModel(settings, g, earth_rate_n(origin.lat0))
        self.layout = NodeLayout.build(b for a in aids for b in a.states)
        n = len(times)
        self.online, self.fixed = NodeRecord(n, self.layout), NodeRecord(n, self.layout)
        bandwidth = max([a.bandwidth for a in aids] + [1])
        self.smoother = WindowSmoother(settings, self.layout, bandwidth)
        self.window_start, self.oldest = 0, 0
        for aid in aids:
            aid.attach(self)
        self._start(init)

    def has_node(self, i: int) -> bool:
        return self.smoother.has_node(i)

    def last_online(self, name: str):
        """Gauss-Markov block ``name`` of the last node with an online estimate and its covariance
        (``None, None`` when there is none)."""
        done = np.flatnonzero(self.online.done)
        if not len(done):
            return None, None
        value, cov, _ = self.online.markov_of(name)
        return value[done[-1]], cov[done[-1]]

    def priors(self, i: int, est: NodeEstimate, rec: NodeRecord, p: int):
        """Node ``i`` with priors at ``est`` and the marginal covariances of node ``p`` in ``rec``
        (a restart's)."""
        graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
        x, v, b = (gtsam.symbol(c, i) for c in (SYM_X, SYM_V, SYM_B))
        cov = gtsam.noiseModel.Gaussian.Covariance
        graph.add(gtsam.PriorFactorPose3(x, est.pose, cov(rec.cov_pose[p])))
        graph.add(gtsam.PriorFactorVector(v, est.v_n, cov(rec.cov_vel[p])))
        graph.add(gtsam.PriorFactorConstantBias(b, est.bias, cov(rec.cov_bias[p])))
        values.insert(x, est.pose)
        values.insert(v, est.v_n)
        insert_bias(values, b, est.bias)
        for c, _, blk in self.layout.markov_blocks():
            self._markov_prior(
                graph, values, c, i, blk, est.markov[blk.name], rec.cov_markov[blk.name][p]
            )
        return graph, values

    @staticmethod
    def _markov_prior(graph, values, c: str, i: int, blk, value, cov) -> None:
        """A Gauss-Markov variable of node ``i`` with a prior at ``value``: of covariance ``cov``
        (regularised) for a vector; of variance ``cov`` for a scalar, or its stationary one when
        ``cov`` is ``None`` or not positive."""
        key = gtsam.symbol(c, i)
        if blk.dim == 1:
            var = float(cov[0, 0]) if cov is not None and cov[0, 0] > 0 else None
            var = var if var is not None else float(blk.sigma[0]) ** 2
            value = np.array([float(np.asarray(value).ravel()[0])])
            graph.add(
                gtsam.PriorFactorVector(
                    key, value, gtsam.noiseModel.Isotropic.Sigma(1, np.sqrt(var))
                )
            )
        else:
            noise = gtsam.noiseModel.Gaussian.Covariance(cov + 1e-12 * np.eye(blk.dim))
            graph.add(gtsam.PriorFactorVector(key, value, noise))
        values.insert(key, value)

    def _start(self, init):
        """Node 0 with the EKF's own initial covariance (:func:`initial_prior`)."""
        R0 = init.R_nb
        markov = {b.name: np.zeros(b.dim) for b in self.layout.markov}
        self.prev = NodeEstimate(
            gtsam.Pose3(gtsam.Rot3(R0), self.run.origin.to_ned(init.lat, init.lon, init.h)),
            np.asarray(init.v_n, float),
            gtsam.imuBias.ConstantBias(np.asarray(init.b_a, float), np.asarray(init.b_g, float)),
            markov,
        )
        # The GNSS error starts tied to the pose: in the joint prior.
        joint = StateLayout.build(b for b in self.layout.markov if b.name == GNSS_ERROR)
        cov, c_vel = initial_prior(init, self.settings, joint)
        x, v, b, g = (gtsam.symbol(c, 0) for c in (SYM_X, SYM_V, SYM_B, SYM_G))
        prev = self.prev
        graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
        g0 = markov.get(GNSS_ERROR)
        graph.add(
            joint_prior_factor(
                x, b, g if g0 is not None else None, prev.pose, prev.bias.vector(), g0, cov
            )
        )
        graph.add(gtsam.PriorFactorVector(v, prev.v_n, gtsam.noiseModel.Gaussian.Covariance(c_vel)))
        values.insert(x, prev.pose)
        values.insert(v, prev.v_n)
        insert_bias(values, b, prev.bias)
        if g0 is not None:
            values.insert(g, g0)
        for c, _, blk in self.layout.markov_blocks():
            if blk.name != GNSS_ERROR:
                self._markov_prior(graph, values, c, 0, blk, markov[blk.name], None)
        pred = NodePrediction(R0, prev.v_n, prev.bias, markov, True, lambda: c_vel)
        self._node_factors(graph, 0, self.times[0], pred)
        self.smoother.update(graph, values, [(key, self.times[0]) for key in self.smoother.keys(0)])
        self._record(0, self.times[1] if len(self.times) > 1 else np.inf)

    def _node_factors(self, graph, i, t, pred: NodePrediction):
        """The aids' factors of node ``i`` (time ``t``) given its prediction."""
        for aid in self.aids:
            aid.node(graph, self, i, t, pred)

    def _predicted_velocity_cov(self, i, pim) -> np.ndarray:
        """Covariance of node ``i``'s predicted NED velocity [m^2/s^2]: node ``i - 1``'s online
        marginal plus the preintegrated velocity noise (rotated from body ``i - 1`` into NED)."""
        R = self.online.R[i - 1]
        c_pim = np.asarray(pim.preintMeasCov())[NAVSTATE_VEL, NAVSTATE_VEL]
        return self.online.cov_vel[i - 1] + R @ c_pim @ R.T

    def _record(self, i: int, t_next: float) -> NodeEstimate:
        """Record node ``i``'s online estimate right after its update, and the fixed-lag estimate
        of every node that leaves the window before the next node (``t_next`` [s], ``inf`` at the
        end), whose value it is now; their covariances come from one marginal query. Returns node
        ``i``'s estimate."""
        self.oldest = max(self.oldest, self.window_start)
        leaving = []
        while self.oldest < i + 1 and self.times[self.oldest] < t_next - self.smoother.lag:
            # At the end: not the nodes a restart already recorded.
            if not (t_next == np.inf and self.fixed.done[self.oldest]):
                leaving.append(self.oldest)
            self.oldest += 1
        nodes = leaving if leaving and leaving[-1] == i else leaving + [i]
        covs = self.smoother.covariances(nodes)
        est = self.smoother.estimate(i)
        self.online.put(i, est, covs[-1])
        for m, cov in zip(leaving, covs, strict=False):  # covs may end with node i's
            self.fixed.put(m, est if m == i else self.smoother.estimate(m), cov)
        return est

    def preintegrate_to(self, i: int, t_to: float):
        """The IMU preintegrated from node ``i - 1`` to ``t_to`` [s] (before node ``i``), from node
        ``i - 1``'s bias estimate."""
        imu = self.run.imu
        j0, t_prev = self._j0, self._t_prev
        k_to = min(int(np.searchsorted(imu.t, t_to, side="left")) + 1, len(imu.t))
        infl = (
            inflation_over(imu.t, j0, k_to, t_prev, t_to, self.segments)
            if self._touches[i]
            else (None, None)
        )
        return preintegrate(
            imu, self.model, self.prev.bias, t_prev, t_to, j0, k_to, infl, self._dt, self._w_turn
        )

    def feed(self, method, show_progress):
        imu, times, n = self.run.imu, self.times, len(self.times)
        segs = self.segments
        first = np.searchsorted(imu.t, times, side="right")
        last = np.minimum(np.searchsorted(imu.t, times, side="left") + 1, len(imu.t))
        # (preintegrate_to takes the samples up to a node as last[i] does.)
        self._touches = touches(first, last, segs.i0, segs.i1).tolist()
        self._dt = np.diff(imu.t, prepend=imu.t[0])
        self._w_turn = turn_rates(imu.t, imu.omega_ib_b)
        # Python scalars: the loop runs once per node and numpy scalars cost more than floats.
        times_l, first = (times.tolist() + [np.inf]), first.tolist()
        for i in progress(range(1, n), desc=method, enable=show_progress):
            t_prev, t = times_l[i - 1], times_l[i]
            self._j0, self._t_prev = first[i - 1], t_prev
            pim = self.preintegrate_to(i, t)
            prev = self.prev
            nav = pim.predict(gtsam.NavState(prev.pose, prev.v_n), prev.bias)
            graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
            x0, v0, b0, x1, v1, b1 = (
                gtsam.symbol(c, j) for j in (i - 1, i) for c in (SYM_X, SYM_V, SYM_B)
            )
            graph.add(gtsam.CombinedImuFactor(x0, v0, x1, v1, b0, b1, pim))
            values.insert(x1, nav.pose())
            values.insert(v1, nav.velocity())
            insert_bias(values, b1, prev.bias)
            for c, _, blk in self.layout.markov_blocks():  # Gauss-Markov link to node i - 1
                key0, key1 = gtsam.symbol(c, i - 1), gtsam.symbol(c, i)
                graph.add(gauss_markov_factor(key0, key1, t - t_prev, blk.tau_s, blk.sigma))
                values.insert(key1, np.exp(-(t - t_prev) / blk.tau_s) * prev.markov[blk.name])
            for aid in self.aids:
                aid.interval(graph, self, i)
            pred = NodePrediction(
                nav.pose().rotation().matrix(),
                nav.velocity(),
                prev.bias,
                prev.markov,
                False,
                partial(self._predicted_velocity_cov, i, pim),
            )
            self._node_factors(graph, i, t, pred)
            try:
                self.smoother.update(graph, values, [(key, t) for key in self.smoother.keys(i)])
            except RuntimeError as exc:
                if not is_ill_posed(exc):
                    raise
                self.stats["n_ill_posed_recovered"] += 1
                self.window_start = _reinitialise(self, i, graph, values)
            self.prev = self._record(i, times_l[i + 1])


def _reinitialise(loop: _Loop, i: int, graph, values) -> int:
    """Restart the window after an ill-posed update of node ``i``; return the new window start.

    The new window holds node ``i - 1`` with a prior from its online estimate and marginal
    covariance (what the failed window knew about it), node ``i`` with all of its new factors
    (IMU, the aids'), so no measurement is lost, except a factor on nodes older than ``i - 1``
    (they are gone). If the smoother used Cholesky factorization it switches to QR, which
    tolerates the poor conditioning that stiff bias random walks cause. Nodes of the abandoned
    window keep what it knew of them (:func:`_keep_window`).
    """
    online, times = loop.online, loop.times
    _keep_window(loop, i)
    if loop.smoother.reset(robust=True):
        loop.stats["factorization_switched_to_qr"] = True
    p = i - 1
    est = NodeEstimate(
        gtsam.Pose3(gtsam.Rot3(online.R[p]), online.p_n[p]),
        online.v_n[p],
        gtsam.imuBias.ConstantBias(online.bias[p, B_ACC], online.bias[p, B_GYRO]),
        {name: arr[p] for name, arr in online.markov.items()},
    )
    p_graph, p_values = loop.priors(p, est, online, p)
    p_values.insert(values)
    for j in range(graph.size()):
        if all(p_values.exists(key) for key in graph.at(j).keys()):
            p_graph.push_back(graph.at(j))
        else:
            loop.stats["n_factors_dropped_at_restart"] = (
                loop.stats.get("n_factors_dropped_at_restart", 0) + 1
            )
    stamps = [(key, times[p]) for key in loop.smoother.keys(p)] + [
        (key, times[i]) for key in loop.smoother.keys(i)
    ]
    loop.smoother.update(p_graph, p_values, stamps)
    return p


def _keep_window(loop: _Loop, i: int) -> None:
    """Record the nodes of a window abandoned at node ``i`` that have no fixed-lag estimate yet
    with the window's estimate after its last update (smoothed over the fixes up to node
    ``i - 1``: half the lag on average, where the online estimate has none); with the online
    estimate where that window cannot be read any more (the failed update left it broken)."""
    online, fixed = loop.online, loop.fixed
    nodes = [m for m in range(loop.window_start, i) if not fixed.done[m] and online.done[m]]
    if not nodes:
        return
    try:
        covs = loop.smoother.covariances(nodes)
        estimates = [loop.smoother.estimate(m) for m in nodes]
    except RuntimeError:
        covs, estimates = None, []
    for k, m in enumerate(nodes):
        if covs is not None and np.all(np.isfinite(covs[k])):
            fixed.put(m, estimates[k], covs[k])
        else:
            fixed.copy_from(online, m)
