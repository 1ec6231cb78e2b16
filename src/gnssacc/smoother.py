"""GTSAM iSAM2 fixed-lag smoother: the factor-graph twin of the paper's EKF.

Graph, in a local NED tangent frame at the run's origin:

* nodes (pose X, velocity V, IMU bias B) at every GNSS epoch after the start, plus fill nodes
  at most ``[smoother] max_node_spacing_s`` apart during GNSS outages;
* ``CombinedImuFactor`` between consecutive nodes (``PreintegratedCombinedMeasurements`` with
  gravity from the WGS-84 model at the origin and the earth rate as Coriolis), noise densities
  and bias random walks from the same configuration as the EKF, and the same data-quality
  inflation over suspect IMU spans;
* ``GPSFactor`` (``GPSFactorArm`` with a lever arm) with each fix's covariance;
* for ``smoother-acc``, the GNSS-acceleration factor of :mod:`gnssacc.factors` on (X_k, B_k),
  built from the same least-squares window as the EKF's update.

Two estimates per node are reported: the *online* one (the newest node right after its
update, what a real-time user would have had) and the *fixed-lag* one (the node's value when
it leaves the lag window, or at the end), each with 1-sigma from iSAM2's marginal covariances.

An ill-posed update (GTSAM's indeterminant-system error) never ends a run: the window is
re-initialised from the last estimate with priors from its marginal covariances, and the event
is counted in ``stats``.
"""
from __future__ import annotations

import time

import gtsam
import numpy as np
from gtsam.symbol_shorthand import B, V, X

from .config import RunConfig
from .earth import earth_rate_n, normal_gravity
from .factors import gnss_accel_factor
from .gnss_accel import AccelWindow, measured_specific_force
from .initialise import initial_sigmas, initialise
from .progress import progress
from .quality import QualityReport, check_imu, inflation_segments, touches_segments
from .rotations import dcm_to_euler, euler_error_jacobian
from .run import InitialState, RecordedRun
from .solution import NavSolution

METHODS = {"smoother": False, "smoother-acc": True}
#: Nodes closer than this are merged (a duplicate time would make a zero-length IMU factor) [s].
MIN_NODE_DT = 1e-3


def node_times(t0: float, t_end: float, gnss_t: np.ndarray, max_spacing: float) -> np.ndarray:
    """Node epochs: the start, every GNSS epoch in ``(t0, t_end]``, and fill nodes in gaps.

    Epochs closer than :data:`MIN_NODE_DT` to the previous one are dropped.
    """
    base = np.concatenate([[t0], gnss_t[(gnss_t > t0) & (gnss_t <= t_end)]])
    if base[-1] < t_end - MIN_NODE_DT and t_end - base[-1] > max_spacing:
        base = np.append(base, t_end)
    out = [base[0]]
    for t in base[1:]:
        gap = t - out[-1]
        if gap < MIN_NODE_DT:
            continue
        n_fill = int(np.ceil(gap / max_spacing - 1e-9)) - 1
        out.extend(out[-1] + gap * np.arange(1, n_fill + 1) / (n_fill + 1))
        out.append(t)
    return np.asarray(out)


class _ImuModel:
    """Preintegration parameters, with cached copies inflated for suspect IMU data."""

    def __init__(self, cfg: RunConfig, g: float, omega_ie_n: np.ndarray):
        self.cfg, self.g, self.omega = cfg, g, omega_ie_n
        self._cache: dict = {}
        self.base = self.params(np.zeros(3), np.zeros(3))  # first call fills the cache

    def params(self, qa_extra: np.ndarray | None, qg_extra: np.ndarray | None) -> gtsam.PreintegrationCombinedParams:
        if qa_extra is None and self._cache:
            return self.base
        qa_extra = np.zeros(3) if qa_extra is None else qa_extra
        qg_extra = np.zeros(3) if qg_extra is None else qg_extra
        key = (tuple(np.round(qa_extra, 15)), tuple(np.round(qg_extra, 15)))
        if key not in self._cache:
            cfg = self.cfg
            p = gtsam.PreintegrationCombinedParams.MakeSharedD(self.g)
            p.setAccelerometerCovariance(np.diag(cfg.accel_psd + qa_extra))
            p.setGyroscopeCovariance(np.diag(cfg.gyro_psd + qg_extra))
            p.setBiasAccCovariance(np.diag(cfg.accel_bias_rw_psd))
            p.setBiasOmegaCovariance(np.diag(cfg.gyro_bias_rw_psd))
            p.setIntegrationCovariance(np.eye(3) * float(cfg["smoother"]["integration_sigma"]) ** 2)
            p.setOmegaCoriolis(self.omega)
            self._cache[key] = p
        return self._cache[key]


def _pose_covariance_body(R_nb: np.ndarray, sig_att_n: np.ndarray, sig_pos_n: np.ndarray) -> np.ndarray:
    """Pose3 tangent covariance (body rotation, body translation) from NED sigmas."""
    C = np.zeros((6, 6))
    C[0:3, 0:3] = R_nb.T @ np.diag(sig_att_n**2) @ R_nb
    C[3:6, 3:6] = R_nb.T @ np.diag(sig_pos_n**2) @ R_nb
    return C


class _Record:
    """Per-node estimates and marginal covariances (one of: online, fixed-lag)."""

    def __init__(self, n: int):
        self.p_n = np.full((n, 3), np.nan)
        self.R = np.full((n, 3, 3), np.nan)
        self.v_n = np.full((n, 3), np.nan)
        self.bias = np.full((n, 6), np.nan)
        self.cov_pose = np.full((n, 6, 6), np.nan)   # Pose3 tangent (body rotation, body translation)
        self.cov_vel = np.full((n, 3, 3), np.nan)
        self.cov_bias = np.full((n, 6, 6), np.nan)
        self.done = np.zeros(n, bool)

    def put(self, i: int, pose: gtsam.Pose3, v_n, bias: gtsam.imuBias.ConstantBias, covs) -> None:
        self.p_n[i] = pose.translation()
        self.R[i] = pose.rotation().matrix()
        self.v_n[i] = v_n
        self.bias[i] = bias.vector()
        self.cov_pose[i], self.cov_vel[i], self.cov_bias[i] = covs
        self.done[i] = True

    def copy_from(self, other: "_Record", i: int) -> None:
        for name in ("p_n", "R", "v_n", "bias", "cov_pose", "cov_vel", "cov_bias", "done"):
            getattr(self, name)[i] = getattr(other, name)[i]

    def sigmas(self) -> np.ndarray:
        """1-sigma in the NavSolution layout (NED position, velocity, roll/pitch/yaw, biases)."""
        R = self.R
        # Tangent (body) -> NED: position R C R^T; the attitude error phi = -R xi has the same form.
        c_pos = R @ self.cov_pose[:, 3:6, 3:6] @ R.transpose(0, 2, 1)
        c_att = R @ self.cov_pose[:, 0:3, 0:3] @ R.transpose(0, 2, 1)
        roll, pitch, yaw = dcm_to_euler(R)
        J = np.array([euler_error_jacobian(r, p, y) for r, p, y in zip(roll, pitch, yaw)]).reshape(-1, 3, 3)
        c_eul = J @ c_att @ J.transpose(0, 2, 1)
        diag = lambda C: np.sqrt(np.maximum(np.diagonal(C, axis1=1, axis2=2), 0.0))
        return np.concatenate([diag(c_pos), diag(self.cov_vel), diag(c_eul), diag(self.cov_bias)], axis=1)

    def solution(self, run: RecordedRun, method: str, t: np.ndarray, runtime: float, stats: dict) -> NavSolution:
        ok = self.done
        lat, lon, h = run.origin.to_llh(self.p_n[ok])
        rpy = np.column_stack(dcm_to_euler(self.R[ok]))
        return NavSolution(method, t[ok], lat, lon, h, self.v_n[ok], rpy, self.bias[ok, 0:3], self.bias[ok, 3:6],
                           self.sigmas()[ok], runtime, dict(stats))


class _Smoother:
    """The incremental fixed-lag smoother with bookkeeping and recovery."""

    def __init__(self, cfg: RunConfig):
        sm = cfg["smoother"]
        self.lag = float(sm["lag_s"])
        self.params = gtsam.ISAM2Params()
        self.params.setFactorization(str(sm["factorization"]).upper())
        self.params.setRelinearizeThreshold(float(sm["relinearize_threshold"]))
        self.params.relinearizeSkip = int(sm["relinearize_skip"])
        # Reuse the slots of marginalised factors so the factor list stays bounded on long runs.
        self.params.findUnusedFactorSlots = True
        self.isam = gtsam.IncrementalFixedLagSmoother(self.lag, self.params)

    def reset(self, robust: bool = False) -> None:
        """A new, empty smoother; ``robust`` switches to QR factorization (returns whether it did)."""
        switched = robust and self.params.getFactorization() != "QR"
        if switched:
            self.params.setFactorization("QR")
        self.isam = gtsam.IncrementalFixedLagSmoother(self.lag, self.params)
        return switched

    def update(self, graph, values, stamps) -> None:
        ts = gtsam.FixedLagSmootherKeyTimestampMap()
        for key, t in stamps:
            ts.insert((key, t))
        self.isam.update(graph, values, ts)

    def estimate(self, i: int):
        isam = self.isam
        return (isam.calculateEstimatePose3(X(i)), isam.calculateEstimateVector(V(i)),
                isam.calculateEstimateConstantBias(B(i)))

    def covariances(self, i: int, joint: bool = False):
        """Marginal covariances of X_i (6x6, tangent), V_i (3x3) and B_i (6x6).

        ``joint=True`` asks iSAM2 for the three at once, which is cheaper for old nodes deep in
        the Bayes tree; single queries are cheaper for the newest node near the root.
        """
        isam = self.isam
        if joint:
            full = isam.getISAM2().jointMarginalCovariance([X(i), V(i), B(i)]).fullMatrix()
            return full[0:6, 0:6], full[6:9, 6:9], full[9:15, 9:15]
        return isam.marginalCovariance(X(i)), isam.marginalCovariance(V(i)), isam.marginalCovariance(B(i))


def _is_ill_posed(exc: Exception) -> bool:
    text = str(exc).lower()
    return "indeterminant" in text or "indeterminate" in text or "ill-posed" in text


def run_smoother(run: RecordedRun, cfg: RunConfig, method: str = "smoother", *,
                 quality: QualityReport | None = None, init: InitialState | None = None,
                 show_progress: bool = False) -> dict[str, NavSolution]:
    """Run the fixed-lag smoother.

    Parameters
    ----------
    run : RecordedRun
    cfg : RunConfig
    method : {"smoother", "smoother-acc"}
        Without / with the GNSS-acceleration factor.
    quality : QualityReport, optional
        Data-quality findings (computed when omitted).
    init : InitialState, optional
        Overrides ``run.init`` and self-initialisation (same initialiser as the EKF).
    show_progress : bool

    Returns
    -------
    dict
        ``{method: fixed-lag NavSolution, method + "-online": online NavSolution}``, one row per
        node.
    """
    if method not in METHODS:
        raise ValueError(f"unknown smoother method {method!r}; known: {', '.join(METHODS)}")
    use_acc = METHODS[method]
    wall0 = time.perf_counter()
    init = init or run.init or initialise(run, cfg)
    quality = quality or check_imu(run.imu, cfg)
    seg_i0, seg_i1, seg_qg, seg_qa = inflation_segments(run.imu, quality, cfg)
    imu, gnss, origin = run.imu, run.gnss, run.origin

    g = float(normal_gravity(origin.lat0, origin.h0))
    g_n = np.array([0.0, 0.0, g])
    model = _ImuModel(cfg, g, earth_rate_n(origin.lat0))
    lever = cfg.lever_arm_b
    f_avg = float(cfg["accel"]["specific_force_avg_s"])
    p_fix = origin.to_ned(gnss.lat, gnss.lon, gnss.h)
    fix_at = {float(t): i for i, t in enumerate(gnss.t)}
    times = node_times(float(init.t), float(imu.t[-1]), gnss.t, float(cfg["smoother"]["max_node_spacing_s"]))
    n = len(times)
    online, fixed = _Record(n), _Record(n)
    stats = {"n_nodes": n, "n_gps_factors": 0, "n_acc_factors": 0, "n_acc_skipped_suspect_imu": 0,
             "n_ill_posed_recovered": 0, "factorization_switched_to_qr": False, "init": init.how, "t_init": float(init.t), "lag_s": float(cfg["smoother"]["lag_s"])}

    sig_p, sig_v, sig_att = initial_sigmas(init, cfg)
    R0 = init.R_nb
    pose = gtsam.Pose3(gtsam.Rot3(R0), origin.to_ned(init.lat, init.lon, init.h))
    vel = np.asarray(init.v_n, float)
    bias = gtsam.imuBias.ConstantBias()
    bias_sig0 = np.concatenate([cfg.accel_bias_sigma0, cfg.gyro_bias_sigma0])
    smoother = _Smoother(cfg)

    def priors(i, pose, vel, bias, c_pose, c_vel, c_bias):
        graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
        graph.add(gtsam.PriorFactorPose3(X(i), pose, gtsam.noiseModel.Gaussian.Covariance(c_pose)))
        graph.add(gtsam.PriorFactorVector(V(i), vel, gtsam.noiseModel.Gaussian.Covariance(c_vel)))
        graph.add(gtsam.PriorFactorConstantBias(B(i), bias, gtsam.noiseModel.Gaussian.Covariance(c_bias)))
        values.insert(X(i), pose)
        values.insert(V(i), vel)
        values.insert(B(i), bias)
        return graph, values

    has_lever = bool(np.any(lever != 0))
    noise_cache: dict = {}

    def measurement_factors(graph, i, t):
        k = fix_at.get(float(t))
        if k is None:
            return None
        sig = tuple(gnss.sigma_ned[k])
        noise = noise_cache.get(sig)
        if noise is None:  # most runs have a handful of distinct fix sigmas
            noise = noise_cache[sig] = gtsam.noiseModel.Diagonal.Sigmas(gnss.sigma_ned[k])
        if has_lever:
            graph.add(gtsam.GPSFactorArm(X(i), p_fix[k], lever, noise))
        else:
            graph.add(gtsam.GPSFactor(X(i), p_fix[k], noise))
        stats["n_gps_factors"] += 1
        return k

    window = AccelWindow(int(cfg["accel"]["window"]), float(cfg["accel"]["max_gap_s"]), cfg.accel_sigma_override)
    for k in np.flatnonzero(gnss.t <= times[0]):
        window.push(gnss.t[k], p_fix[k], gnss.sigma_ned[k])

    graph, values = priors(0, pose, vel, bias, _pose_covariance_body(R0, sig_att, sig_p), np.diag(sig_v**2),
                           np.diag(bias_sig0**2))
    measurement_factors(graph, 0, times[0])
    smoother.update(graph, values, [(X(0), times[0]), (V(0), times[0]), (B(0), times[0])])
    online.put(0, pose, vel, bias, smoother.covariances(0))
    window_start = 0  # first node still in the current smoother (after a re-initialisation)
    oldest = 0        # oldest node whose fixed-lag estimate is not recorded yet

    imu_t, imu_f, imu_w = imu.t, imu.f_b, imu.omega_ib_b
    # Samples of each node interval: (t_prev, t] is covered by samples [first[i], last[i]).
    first = np.searchsorted(imu.t, times, side="right")
    last = np.minimum(np.searchsorted(imu.t, times, side="left") + 1, len(imu.t))
    suspect = (np.zeros(n, bool) if seg_i0.size == 0 else
               np.array([touches_segments(first[i - 1], last[i], seg_i0, seg_i1) if i else False for i in range(n)]))
    for i in progress(range(1, n), desc=method, enable=show_progress):
        t_prev, t = times[i - 1], times[i]
        # Preintegrate the IMU over (t_prev, t], samples held over (t[k-1], t[k]].
        j_start, k_end = int(first[i - 1]), int(last[i])
        if suspect[i]:
            qa_x, qg_x = _inflation_over(imu.t, j_start, k_end, t_prev, t, seg_i0, seg_i1, seg_qa, seg_qg)
        else:
            qa_x = qg_x = None
        pim = gtsam.PreintegratedCombinedMeasurements(model.params(qa_x, qg_x), bias)
        # Interval pieces: each sample's (t[k-1], t[k]] clipped to (t_prev, t].
        edges = np.clip(imu_t[j_start:k_end], t_prev, t)
        dts = np.diff(edges, prepend=t_prev)
        integrate = pim.integrateMeasurement
        for f_b, w_b, dt in zip(imu_f[j_start:k_end], imu_w[j_start:k_end], dts.tolist()):
            if dt > 0.0:
                integrate(f_b, w_b, dt)

        nav = pim.predict(gtsam.NavState(pose, vel), bias)
        graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
        graph.add(gtsam.CombinedImuFactor(X(i - 1), V(i - 1), X(i), V(i), B(i - 1), B(i), pim))
        values.insert(X(i), nav.pose())
        values.insert(V(i), nav.velocity())
        values.insert(B(i), bias)
        k = measurement_factors(graph, i, t)
        if use_acc and k is not None:
            meas = window.push(t, p_fix[k], gnss.sigma_ned[k])
            if meas is not None:
                f_meas = measured_specific_force(imu, t, f_avg, seg_i0, seg_i1)
                if f_meas is None:
                    stats["n_acc_skipped_suspect_imu"] += 1
                else:
                    graph.add(gnss_accel_factor(X(i), B(i), f_meas, meas.a_n, g_n, meas.cov))
                    stats["n_acc_factors"] += 1

        # Nodes about to leave the window: their fixed-lag estimate is the value they have now.
        oldest = max(oldest, window_start)
        while oldest < i and times[oldest] < t - smoother.lag:
            fixed.put(oldest, *smoother.estimate(oldest), smoother.covariances(oldest, joint=True))
            oldest += 1
        stamps = [(X(i), t), (V(i), t), (B(i), t)]
        try:
            smoother.update(graph, values, stamps)
        except RuntimeError as exc:
            if not _is_ill_posed(exc):
                raise
            stats["n_ill_posed_recovered"] += 1
            window_start = _reinitialise(smoother, i, times, online, fixed, window_start, graph, values, priors, stats)
        pose, vel, bias = smoother.estimate(i)
        online.put(i, pose, vel, bias, smoother.covariances(i))

    for m in range(window_start, n):
        if not fixed.done[m]:
            fixed.put(m, *smoother.estimate(m), smoother.covariances(m, joint=True))
    # What the smoother holds at the end: bounded by the lag, whatever the run length.
    stats["final_window_variables"] = int(smoother.isam.getLinearizationPoint().size())
    stats["final_factor_slots"] = int(smoother.isam.getFactors().size())
    runtime = time.perf_counter() - wall0
    return {method: fixed.solution(run, method, times, runtime, stats),
            method + "-online": online.solution(run, method + "-online", times, runtime, stats)}


def _reinitialise(smoother, i, times, online, fixed, window_start, graph, values, priors, stats) -> int:
    """Restart the window after an ill-posed update of node ``i``; return the new window start.

    The new window holds node ``i - 1`` with a prior from its online estimate and marginal
    covariance (what the failed window knew about it), node ``i`` with all of its new factors
    (IMU, GNSS, acceleration), so no measurement is lost. If the smoother used Cholesky
    factorization it switches to QR, which tolerates the poor conditioning that stiff bias random
    walks cause. Nodes of the abandoned window keep their online estimate as their fixed-lag one.
    """
    for m in range(window_start, i):
        if not fixed.done[m] and online.done[m]:
            fixed.copy_from(online, m)
    if smoother.reset(robust=True):
        stats["factorization_switched_to_qr"] = True
    p = i - 1
    pose = gtsam.Pose3(gtsam.Rot3(online.R[p]), online.p_n[p])
    bias = gtsam.imuBias.ConstantBias(online.bias[p, 0:3], online.bias[p, 3:6])
    p_graph, p_values = priors(p, pose, online.v_n[p], bias, online.cov_pose[p], online.cov_vel[p],
                               online.cov_bias[p])
    p_graph.push_back(graph)
    p_values.insert(values)
    stamps = [(key(p), times[p]) for key in (X, V, B)] + [(key(i), times[i]) for key in (X, V, B)]
    smoother.update(p_graph, p_values, stamps)
    return p


def _inflation_over(imu_t, k0, k1, t_a, t_b, seg_i0, seg_i1, seg_qa, seg_qg):
    """Time-averaged extra PSD (accel, gyro per body axis) over ``(t_a, t_b]`` from suspect segments."""
    qa, qg = np.zeros(3), np.zeros(3)
    if seg_i0.size == 0 or not touches_segments(k0, k1, seg_i0, seg_i1):
        return qa, qg
    for s in np.flatnonzero((seg_i0 < k1) & (seg_i1 > k0)):
        for k in range(max(seg_i0[s], k0), min(seg_i1[s], k1)):
            lo = imu_t[k - 1] if k > 0 else imu_t[0]
            overlap = max(0.0, min(imu_t[k], t_b) - max(lo, t_a))
            qa += seg_qa[s] * overlap
            qg += seg_qg[s] * overlap
    span = max(t_b - t_a, 1e-9)
    return qa / span, qg / span
