"""GTSAM iSAM2 fixed-lag smoother: the factor-graph twin of the paper's EKF.

Graph, in a local NED tangent frame at the run's origin:

* nodes (pose X, velocity V, IMU bias B) at the GNSS epochs after the start, at most one per
  ``[smoother] min_node_spacing_s`` (:func:`node_fixes`: faster fixes are folded into the node
  before them, below), plus fill nodes at most ``[smoother] max_node_spacing_s`` apart during
  GNSS outages;
* ``CombinedImuFactor`` between consecutive nodes (``PreintegratedCombinedMeasurements`` with
  gravity from the WGS-84 model at the origin and the earth rate as Coriolis), noise densities
  and bias random walks from the same configuration as the EKF, and the same data-quality
  inflation over suspect IMU spans;
* ``GPSFactor`` (``GPSFactorArm`` with a lever arm) with each fix's covariance; a fix between
  two nodes (faster fixes) is a factor on the earlier node through the IMU preintegrated up to
  the fix (:func:`gnssacc.factors.preintegrated_position_factor`), so the number of nodes, and
  the time per second of data, stay those of ``min_node_spacing_s`` whatever the fix rate;
* for ``smoother-acc``, the GNSS-acceleration factor of :mod:`gnssacc.factors` on (X_k, B_k),
  built from the same least-squares window as the EKF's update; for ``smoother-accw`` the
  window-consistent one on the poses of the window's fixes (``sum_j B_j p_ant(X_j) - a~``);
* while the vehicle stands still (``[zupt]``), a zero-velocity prior on V_k and the zero-rate
  reading (mean gyro minus the earth rate) as a prior on the gyro half of B_k, at the node
  nearest each stationary epoch of :mod:`gnssacc.estimators.zupt` (nodes are added where no GNSS epoch is
  near, e.g. a stop inside a GNSS outage);
* while the vehicle rolls (``[nhc]``), the non-holonomic constraint on (X_k, V_k, B_k) at the
  node nearest each of its epochs (:mod:`gnssacc.estimators.smoother_aids`).

Two estimates per node are reported: the *online* one (the newest node right after its
update, what a real-time user would have had) and the *fixed-lag* one (the node's value when
it leaves the lag window, or at the end), each with 1-sigma from the marginal covariances of
iSAM2's linear system (:class:`gnssacc.estimators.window_marginals.WindowMarginals`, which keeps a copy of
that system cheaper to query than iSAM2's Bayes tree) and its whitened GNSS residuals against
their expectation (:func:`residual_chi2`) as a consistency figure.

An ill-posed update (GTSAM's indeterminant-system error) never ends a run: the window is
re-initialised from the last estimate with priors from its marginal covariances, and the event
is counted in ``stats``.

Bias random walks are floored at :data:`ACCEL_BIAS_RW_FLOOR` and :data:`GYRO_BIAS_RW_FLOOR` (per
second) and the start's bias sigmas at the same values: a configured zero (``[imu]
accel_bias_instability_mg`` or ``gyro_bias_instability_deg_h`` = 0, a constant bias; or a zero
``*_bias_sigma0_*``, a calibrated one) would give the bias between-factor of
``CombinedImuFactor`` or the start's prior a zero covariance, which GTSAM cannot factor. The floors are hundreds of times below any real IMU's random walk,
so they change no estimate that a constant bias would not give.
"""

from __future__ import annotations

import time
from collections import deque

import gtsam
import numpy as np
from gtsam.symbol_shorthand import B, G, K, V, X
from scipy.spatial.transform import Rotation

from ..checks.quality import QualityReport, inflation_segments, touches_segments
from ..core.earth import earth_rate_n, normal_gravity
from ..core.progress import progress
from ..core.recording import InitialState, RecordedRun
from ..core.rotations import dcm_to_euler, euler_error_jacobian, skew
from ..core.solution import NavSolution
from ..factors import (
    gauss_markov_factor,
    gnss_accel_factor,
    gnss_position_gm_factor,
    joint_prior_factor,
    preintegrated_position_factor,
    window_accel_factor,
)
from .fixed_lag import FixedLagISAM2
from .gnss_accel import acceleration_row, measured_specific_force, window_accelerations
from .layout import (
    ATT,
    B_ACC,
    B_GYRO,
    BIASES,
    GNSS_ERROR,
    NAVSTATE_VEL,
    NODE_B,
    NODE_G,
    NODE_V,
    NODE_X,
    POS,
    PRIOR_BIAS,
    PRIOR_G,
    PRIOR_POSE,
    VEL,
    X_ROT,
    X_TRANS,
    NodeLayout,
)
from .settings import SmootherSettings
from .smoother_aids import NhcFactors, OdometryFactors
from .state import initial_state, start_of_pass
from .window_marginals import NotAChain, WindowMarginals
from .zupt import StationaryEpochs, epochs_for

#: Method id -> GNSS-acceleration factor: none, the paper's on (X_k, B_k), or the window-consistent one.
METHODS = {"smoother": None, "smoother-acc": "paper", "smoother-accw": "window"}
#: Nodes closer than this are merged (a duplicate time would make a zero-length IMU factor) [s].
MIN_NODE_DT = 1e-3
#: Smallest accelerometer bias random walk the smoother uses [m/s^2/sqrt(s)] (~0.1 ug/sqrt(s)).
ACCEL_BIAS_RW_FLOOR = 1e-6
#: Smallest gyro bias random walk the smoother uses [rad/s/sqrt(s)] (~0.002 deg/h/sqrt(s)).
GYRO_BIAS_RW_FLOOR = 1e-8
#: Symbol character of the bias variables ``B(i)``: relinearised before they are marginalised
#: when far from their linearisation point (the IMU factors' first-order bias correction).
BIAS_SYMBOL = chr(gtsam.Symbol(B(0)).chr())


def node_times(t0: float, t_end: float, gnss_t: np.ndarray, max_spacing: float) -> np.ndarray:
    """Node epochs: the start, every GNSS epoch in ``(t0, t_end]``, and fill nodes in gaps.

    Epochs closer than :data:`MIN_NODE_DT` to the previous one are dropped.
    """
    base = np.concatenate([[t0], gnss_t[(gnss_t > t0) & (gnss_t <= t_end)]])
    if base[-1] < t_end - MIN_NODE_DT:  # the last node is the end of the recording
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


def node_fixes(gnss_t: np.ndarray, min_spacing: float) -> np.ndarray:
    """Which fixes are nodes (a mask): the first, then each fix at least ``min_spacing`` [s] after
    the last one taken, less half the median fix interval (fixes at a steady rate up to
    ``1 / min_spacing`` are all taken, jitter or not; at 20 Hz every tenth for 0.5 s). The others
    are folded into the node before them; ``min_spacing <= 0``: every fix is a node."""
    keep = np.ones(len(gnss_t), bool)
    if min_spacing <= 0 or len(gnss_t) < 2:
        return keep
    step = min_spacing - 0.5 * float(np.median(np.diff(gnss_t)))
    last = -np.inf
    for k, t in enumerate(gnss_t.tolist()):
        if t - last >= step:
            last = t
        else:
            keep[k] = False
    return keep


def _folded_by_node(times: np.ndarray, gnss_t: np.ndarray, is_node_fix: np.ndarray) -> dict:
    """``{node i: [fix indices]}``: the fixes that are not nodes, strictly between nodes ``i - 1``
    and ``i`` (their factors go on node ``i - 1`` with node ``i``'s update)."""
    k = np.flatnonzero(~is_node_fix & (gnss_t > times[0]) & (gnss_t < times[-1]))
    k = k[~np.isin(gnss_t[k], times)]
    out: dict = {}
    for kk, i in zip(k.tolist(), np.searchsorted(times, gnss_t[k], side="right").tolist()):
        out.setdefault(i, []).append(kk)
    return out


class _ImuModel:
    """Preintegration parameters, with cached copies inflated for suspect IMU data."""

    def __init__(self, settings: SmootherSettings, g: float, omega_ie_n: np.ndarray):
        self.settings, self.g, self.omega = settings, g, omega_ie_n
        self._cache: dict = {}
        self.base = self.params(np.zeros(3), np.zeros(3))  # first call fills the cache

    def params(
        self, qa_extra: np.ndarray | None, qg_extra: np.ndarray | None
    ) -> gtsam.PreintegrationCombinedParams:
        if qa_extra is None and self._cache:
            return self.base
        qa_extra = np.zeros(3) if qa_extra is None else qa_extra
        qg_extra = np.zeros(3) if qg_extra is None else qg_extra
        key = (tuple(np.round(qa_extra, 15)), tuple(np.round(qg_extra, 15)))
        if key not in self._cache:
            imu = self.settings.imu
            p = gtsam.PreintegrationCombinedParams.MakeSharedD(self.g)
            p.setAccelerometerCovariance(np.diag(imu.accel_psd + qa_extra))
            p.setGyroscopeCovariance(np.diag(imu.gyro_psd + qg_extra))
            p.setBiasAccCovariance(
                np.diag(np.maximum(imu.accel_bias_rw_psd, ACCEL_BIAS_RW_FLOOR**2))
            )
            p.setBiasOmegaCovariance(
                np.diag(np.maximum(imu.gyro_bias_rw_psd, GYRO_BIAS_RW_FLOOR**2))
            )
            p.setIntegrationCovariance(np.eye(3) * self.settings.integration_sigma**2)
            p.setOmegaCoriolis(self.omega)
            self._cache[key] = p
        return self._cache[key]


def initial_prior(init: InitialState, settings: SmootherSettings) -> tuple[np.ndarray, np.ndarray]:
    """The EKF's initial covariance (:func:`gnssacc.estimators.ekf.initial_state`) in the smoother's variables.

    EKF errors are estimate minus truth with ``R_est = (I + [phi x]) R``; the prior factor's error is
    the truth's offset from the prior: rotation ``xi = -R^T phi``, translation ``tau = -R^T dp``,
    biases ``+db`` (the residual bias adds to the estimate), GNSS error ``-dx_g``.

    Returns
    -------
    cov : ndarray (12, 12) or (15, 15)
        Of (rotation, translation, accelerometer bias, gyro bias[, GNSS error]).
    c_vel : ndarray (3, 3)
        Velocity covariance (uncorrelated with the rest at the start).
    """
    s = initial_state(init, settings)
    P, layout = s.P, s.layout
    n = P.shape[0]
    R = init.R_nb
    T = np.zeros((n - 3, n))  # smoother offsets <- EKF error state (velocity dropped)
    pose = T[PRIOR_POSE]
    pose[X_ROT, ATT] = -R.T
    pose[X_TRANS, POS] = -R.T
    T[PRIOR_BIAS, BIASES] = np.eye(6)
    if layout.has(GNSS_ERROR):
        T[PRIOR_G, layout.block(GNSS_ERROR)] = -np.eye(3)
    cov = T @ P @ T.T
    cov[PRIOR_BIAS, PRIOR_BIAS] += np.diag(
        np.r_[np.full(3, ACCEL_BIAS_RW_FLOOR), np.full(3, GYRO_BIAS_RW_FLOOR)] ** 2
    )
    return cov, P[VEL, VEL]


class _Record:
    """Per-node estimates and marginal covariances (one of: online, fixed-lag)."""

    def __init__(self, n: int, gm: bool):
        self.gm = gm
        self.p_n = np.full((n, 3), np.nan)
        self.R = np.full((n, 3, 3), np.nan)
        self.v_n = np.full((n, 3), np.nan)
        self.bias = np.full((n, 6), np.nan)
        self.cov_pose = np.full(
            (n, 6, 6), np.nan
        )  # Pose3 tangent (body rotation, body translation)
        self.cov_vel = np.full((n, 3, 3), np.nan)
        self.cov_bias = np.full((n, 6, 6), np.nan)
        self.done = np.zeros(n, bool)
        self.chi2 = np.full(
            (n, 2), np.nan
        )  # whitened GNSS residual and its expectation, nodes with a fix
        # GNSS Gauss-Markov error (zeros when not modelled): estimate, its covariance and its
        # cross-covariance with the pose tangent.
        self.g = np.zeros((n, 3))
        self.cov_g = np.zeros((n, 3, 3))
        self.cov_xg = np.zeros((n, 6, 3))
        # The odometry scale factor (zeros when the run has no odometry): estimate and variance.
        self.k = np.zeros(n)
        self.var_k = np.zeros(n)

    def put(self, i: int, est, cov: np.ndarray) -> None:
        """Node ``i``'s estimate and the blocks of its joint marginal ``cov`` (X, V, B[, G][, K])."""
        pose, v_n, bias, g, k = est
        self.p_n[i] = pose.translation()
        self.R[i] = pose.rotation().matrix()
        self.v_n[i] = v_n
        self.bias[i] = bias.vector()
        self.g[i], self.k[i] = g, k
        self.cov_pose[i], self.cov_vel[i], self.cov_bias[i] = (
            cov[NODE_X, NODE_X],
            cov[NODE_V, NODE_V],
            cov[NODE_B, NODE_B],
        )
        if self.gm:
            self.cov_xg[i], self.cov_g[i] = cov[NODE_X, NODE_G], cov[NODE_G, NODE_G]
        if cov.shape[0] == NodeLayout(self.gm, True).b:  # the scale factor is the last variable
            self.var_k[i] = cov[-1, -1]
        self.done[i] = True

    def copy_from(self, other: "_Record", i: int) -> None:
        for name in (
            "p_n",
            "R",
            "v_n",
            "bias",
            "cov_pose",
            "cov_vel",
            "cov_bias",
            "done",
            "chi2",
            "g",
            "cov_g",
            "cov_xg",
            "k",
            "var_k",
        ):
            getattr(self, name)[i] = getattr(other, name)[i]

    def sigmas(self) -> np.ndarray:
        """1-sigma in the NavSolution layout (NED position, velocity, roll/pitch/yaw, biases)."""
        R = self.R
        # Tangent (body) -> NED: position R C R^T; the attitude error phi = -R xi has the same form.
        c_pos = R @ self.cov_pose[:, X_TRANS, X_TRANS] @ R.transpose(0, 2, 1)
        c_att = R @ self.cov_pose[:, X_ROT, X_ROT] @ R.transpose(0, 2, 1)
        roll, pitch, yaw = dcm_to_euler(R)
        J = euler_error_jacobian(roll, pitch, yaw)
        c_eul = J @ c_att @ J.transpose(0, 2, 1)
        diag = lambda C: np.sqrt(np.maximum(np.diagonal(C, axis1=1, axis2=2), 0.0))
        return np.concatenate(
            [diag(c_pos), diag(self.cov_vel), diag(c_eul), diag(self.cov_bias)], axis=1
        )

    def solution(
        self, run: RecordedRun, method: str, t: np.ndarray, runtime: float, stats: dict
    ) -> NavSolution:
        ok = self.done
        lat, lon, h = run.origin.to_llh(self.p_n[ok])
        rpy = np.column_stack(dcm_to_euler(self.R[ok]))
        return NavSolution(
            method,
            t[ok],
            lat,
            lon,
            h,
            self.v_n[ok],
            rpy,
            self.bias[ok, B_ACC],
            self.bias[ok, B_GYRO],
            self.sigmas()[ok],
            runtime,
            dict(stats),
        )


class _Smoother:
    """The incremental fixed-lag smoother with bookkeeping and recovery."""

    def __init__(self, settings: SmootherSettings, bandwidth: int = 1, scale: bool = False):
        """``bandwidth``: how many nodes apart a factor reaches (1: a chain of nodes; the
        window-consistent acceleration factors reach across their window of fixes). The
        window's marginals are kept by :class:`WindowMarginals` for that band; a wider factor
        makes them come from iSAM2's queries while it is in the window. ``scale``: nodes carry
        the odometry scale factor K."""
        self.lag = settings.lag_s
        self.gm = settings.gnss.gauss_markov
        self.scale = scale
        self.params = gtsam.ISAM2Params()
        self.params.setFactorization(settings.factorization)
        self.threshold = settings.relinearize_threshold
        self.params.setRelinearizeThreshold(self.threshold)
        self.params.relinearizeSkip = settings.relinearize_skip
        # Reuse the slots of marginalised factors so the factor list stays bounded on long runs.
        self.params.findUnusedFactorSlots = True
        self.isam = FixedLagISAM2(self.lag, self.params, self.threshold, guard=BIAS_SYMBOL)
        self.marginals = WindowMarginals(self.gm, bandwidth, scale)

    def reset(self, robust: bool = False) -> None:
        """A new, empty smoother; ``robust`` switches to QR factorization (returns whether it did)."""
        switched = robust and self.params.getFactorization() != "QR"
        if switched:
            self.params.setFactorization("QR")
        self.isam = FixedLagISAM2(self.lag, self.params, self.threshold, guard=BIAS_SYMBOL)
        self.marginals.clear()
        return switched

    def update(self, graph, values, stamps) -> None:
        self.isam.update(graph, values, stamps)
        try:
            self.marginals.sync(self.isam, graph)
        except NotAChain:
            self.marginals.clear()

    def estimate(self, i: int):
        """Pose, velocity, bias, GNSS error and odometry scale factor (zeros when not modelled) of
        node ``i``."""
        isam = self.isam
        g = isam.calculateEstimateVector(G(i)) if self.gm else np.zeros(3)
        k = float(isam.calculateEstimateVector(K(i))[0]) if self.scale else 0.0
        return (
            isam.calculateEstimatePose3(X(i)),
            isam.calculateEstimateVector(V(i)),
            isam.calculateEstimateConstantBias(B(i)),
            g,
            k,
        )

    def has_node(self, i: int) -> bool:
        """Whether node ``i`` is in the window (not marginalised, not dropped by a restart)."""
        return self.isam.getISAM2().valueExists(X(i))

    def keys(self, i: int) -> list:
        """Keys of node ``i``: pose, velocity, bias[, GNSS error][, odometry scale factor]."""
        return [X(i), V(i), B(i)] + ([G(i)] if self.gm else []) + ([K(i)] if self.scale else [])

    def covariances(self, nodes: list) -> np.ndarray:
        """Joint marginal covariance of each node's variables, for ``nodes`` (ascending): X_i
        (Pose3 tangent), V_i, B_i[, G_i][, K_i]; array (len(nodes), b, b), b = 15 to 19.

        From :class:`gnssacc.estimators.window_marginals.WindowMarginals` (the window's linear system, kept
        in step with iSAM2), all nodes in one query; iSAM2's own queries, per node, while that
        system is not at hand (a factor wider than its band): the joint one by QR with GNSS-error
        states, else the per-key marginals and zero cross-covariances (only the diagonal blocks
        are used then).
        """
        if self.marginals.first is not None:
            try:
                return self.marginals.covariances(nodes)
            except np.linalg.LinAlgError:
                self.marginals.clear()  # rebuilt at the next update
        return np.array([self._isam_covariance(i) for i in nodes])

    def _isam_covariance(self, i: int) -> np.ndarray:
        isam = self.isam.getISAM2()
        if not self.gm:
            # iSAM2's per-key marginals cost a third of its joint query (measured, smoother-accw).
            layout = NodeLayout(False, self.scale)
            full = np.zeros((layout.b, layout.b))
            for c, sl in layout.blocks():
                full[sl, sl] = isam.marginalCovariance(gtsam.symbol(c, i))
            return full
        keys = self.keys(i)
        info, _ = isam.joint(keys, gtsam.EliminateQR).hessian(gtsam.Ordering(keys))
        return np.linalg.inv(info)


def _is_ill_posed(exc: Exception) -> bool:
    text = str(exc).lower()
    return "indeterminant" in text or "indeterminate" in text or "ill-posed" in text


def residual_chi2(
    rec: "_Record", idx: np.ndarray, p_fix: np.ndarray, cov_fix: np.ndarray, lever_b: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    r"""Whitened squared residuals of GNSS factors at nodes ``idx`` of an estimate, and their
    expectations.

    ``r = p_fix - (t + R l + g)`` (``g`` the GNSS error, when modelled). For a consistent estimate
    that includes the fix, ``E[r^T Sigma^-1 r] = tr(Sigma^-1 C_r)`` with ``C_r = Sigma - J C J^T``
    (``C`` the joint marginal of the pose and ``g``, ``J = [-R [l x], R, I]`` on GTSAM's
    (rotation, translation) tangent and ``g``). The consistency figure is the ratio of their sums
    (:func:`run_smoother`): 1 when consistent, and never dominated by a node whose ``C_r`` is
    close to zero (the pose and GNSS-error marginals nearly cancel there).

    Parameters
    ----------
    rec : _Record
    idx : ndarray (K,) of int
        Nodes with a fix.
    p_fix : ndarray (K, 3)
        Their fixes (tangent frame) [m].
    cov_fix : ndarray (K, 3, 3)
        The fixes' white covariance [m^2] (:meth:`gnssacc.core.recording.GnssFixes.cov_ned`).
    lever_b : ndarray (3,)

    Returns
    -------
    chi2, expected : ndarray (K,)
    """
    R = rec.R[idx]
    r = p_fix - (rec.p_n[idx] + R @ lever_b + rec.g[idx])
    J = np.concatenate([-R @ skew(lever_b), R], axis=2)
    cross = J @ rec.cov_xg[idx]
    JCJ = (
        J @ rec.cov_pose[idx] @ J.transpose(0, 2, 1)
        + rec.cov_g[idx]
        + cross
        + cross.transpose(0, 2, 1)
    )
    W = np.linalg.inv(cov_fix)
    chi2 = np.einsum("ki,kij,kj->k", r, W, r)
    expected = 3.0 - np.einsum("kij,kji->k", W, JCJ)
    return chi2, np.maximum(expected, 0.0)


class _Factors:
    """Builds each kind of factor for a node: GNSS position, GNSS acceleration, stationary."""

    def __init__(
        self,
        run: RecordedRun,
        settings: SmootherSettings,
        stationary: StationaryEpochs,
        stats: dict,
        gnss_checked: np.ndarray,
    ):
        self.run, self.stats, self.st = run, stats, stationary
        self.gnss_checked = gnss_checked  # per stationary epoch: its span was vetted by the fixes
        gnss, origin = run.gnss, run.origin
        self.p_fix = origin.to_ned(gnss.lat, gnss.lon, gnss.h)
        self.fix_at = {float(t): i for i, t in enumerate(gnss.t)}
        self.lever = settings.gnss.lever_arm_b
        self.has_lever = bool(np.any(self.lever != 0))
        self.g_n = np.array([0.0, 0.0, float(normal_gravity(origin.lat0, origin.h0))])
        self.w_ie = earth_rate_n(origin.lat0)
        acc = settings.accel
        self.f_avg = acc.specific_force_avg_s
        self.acc_window = (acc.window, acc.max_gap_s, acc.sigma_override)
        self.acc = None
        self.acc_fixes: dict = {}  # fix index -> the window's fix indices, oldest first
        self.node_of: dict = {}  # fix index -> its node
        self.zupt_noise = gtsam.noiseModel.Isotropic.Sigma(3, settings.zupt.velocity_sigma_mps)
        self.zupt_var = settings.zupt.velocity_sigma_mps**2
        self.zupt_gate = settings.zupt.gate_nis
        self._noise: dict = {}
        self.gm_sigma, self.gm_tau = settings.gnss.gm_sigma, settings.gnss.gm_tau
        self.gm = bool(np.any(self.gm_sigma > 0))

    def gps(self, graph, i: int, t: float) -> int | None:
        """GPS factor on X_i if a fix is at ``t``; returns the fix index."""
        k = self.fix_at.get(float(t))
        if k is None:
            return None
        gnss = self.run.gnss
        sig = gnss.sigma_ned[k]
        cov = (
            None if gnss.corr_ned is None else gnss.cov_ned(k)
        )  # correlated axes: the full covariance
        self.stats["n_gps_factors"] += 1
        self.node_of[k] = i
        if self.gm:
            graph.add(gnss_position_gm_factor(X(i), G(i), self.p_fix[k], self.lever, sig, cov))
            return k
        key = tuple(sig) if cov is None else tuple(cov.ravel())
        noise = self._noise.get(key)
        if noise is None:  # most runs have a handful of distinct fix sigmas
            noise = self._noise[key] = (
                gtsam.noiseModel.Diagonal.Sigmas(sig)
                if cov is None
                else gtsam.noiseModel.Gaussian.Covariance(cov)
            )
        if self.has_lever:
            graph.add(gtsam.GPSFactorArm(X(i), self.p_fix[k], self.lever, noise))
        else:
            graph.add(gtsam.GPSFactor(X(i), self.p_fix[k], noise))
        return k

    def folded_gps(self, graph, i: int, k: int, pim, pose, vel, bias, interval: float) -> None:
        """Fix ``k`` (between node ``i`` and the next, ``interval`` [s] later) on node ``i``'s
        variables, through ``pim`` preintegrated from node ``i`` to the fix (and with the GNSS
        error of both nodes when modelled); ``pose, vel, bias``: node ``i``'s estimate."""
        R_f = pim.predict(gtsam.NavState(pose, vel), bias).attitude().matrix()
        keys, gm = (X(i), V(i), B(i)), None
        if self.gm:
            keys, gm = keys + (G(i), G(i + 1)), (self.gm_tau, self.gm_sigma, interval)
        graph.add(
            preintegrated_position_factor(
                keys, pim, self.p_fix[k], self.lever, self.run.gnss.cov_ned(k), R_f, gm
            )
        )
        self.stats["n_gps_folded"] += 1

    def gm_chain(self, graph, values, i: int, dt: float, g_prev: np.ndarray) -> None:
        """The GNSS error of node ``i`` and its Gauss-Markov link to node ``i - 1`` (when modelled)."""
        if self.gm:
            graph.add(gauss_markov_factor(G(i - 1), G(i), dt, self.gm_tau, self.gm_sigma))
            values.insert(G(i), np.exp(-dt / self.gm_tau) * g_prev)

    def prepare_accel(self, times: np.ndarray) -> None:
        """GNSS accelerations of every fix, all at once: the fixes before the first node and those
        at node times, in order, as :class:`gnssacc.estimators.gnss_accel.AccelWindow` would see them."""
        t_fix = self.run.gnss.t
        nodes = set(times.tolist())
        pushed = np.flatnonzero(
            (t_fix < times[0]) | np.array([t in nodes for t in t_fix.tolist()], bool)
        )
        full, a_n, var = window_accelerations(
            t_fix[pushed], self.p_fix[pushed], self.run.gnss.sigma_ned[pushed], *self.acc_window
        )
        self.acc = {int(k): (a_n[j], var[j]) for j, k in enumerate(pushed) if full[j]}
        m = self.acc_window[0]
        self.acc_fixes = {
            int(k): pushed[j - m + 1 : j + 1] for j, k in enumerate(pushed) if full[j]
        }

    def accel(self, graph, i: int, t: float, k: int, seg_i0, seg_i1) -> None:
        """GNSS-acceleration factor on (X_i, B_i) once the least-squares window is full."""
        meas = self.acc.get(k)
        if meas is None:
            return
        f_meas = measured_specific_force(self.run.imu, t, self.f_avg, seg_i0, seg_i1)
        if f_meas is None:
            self.stats["n_acc_skipped_suspect_imu"] += 1
            return
        graph.add(gnss_accel_factor(X(i), B(i), f_meas, meas[0], self.g_n, np.diag(meas[1])))
        self.stats["n_acc_factors"] += 1

    def accel_window(self, graph, k: int, in_window) -> None:
        """Window-consistent GNSS-acceleration factor on the poses of fix ``k``'s window, when its
        window is full and all of its fixes' nodes are in the smoother (``in_window(node)``)."""
        meas = self.acc.get(k)
        if meas is None:
            return
        fixes = self.acc_fixes[k]
        nodes = [self.node_of.get(int(f)) for f in fixes]
        if any(
            n is None or not in_window(n) for n in nodes
        ):  # fixes before the start, or marginalised
            self.stats["n_acc_skipped_window"] = self.stats.get("n_acc_skipped_window", 0) + 1
            return
        B_row = acceleration_row(self.run.gnss.t[fixes])
        graph.add(
            window_accel_factor([X(n) for n in nodes], B_row, meas[0], self.lever, np.diag(meas[1]))
        )
        self.stats["n_acc_factors"] += 1

    def stationary(
        self, graph, i: int, j: int, R_nb: np.ndarray, bias, v_pred: np.ndarray, c_vel: np.ndarray
    ) -> None:
        """Zero velocity on V_i and the zero-rate reading of stationary epoch ``j`` on B_i's gyro
        part, unless the velocity predicted for the node (``v_pred`` NED [m/s], covariance
        ``c_vel``) rejects standing still: its NIS against zero above ``[zupt] gate_nis``, the
        EKF's gate. Only spans the fixes have not vetted (:func:`vetted_by_fixes`: found on IMU
        evidence alone, in a GNSS outage) are gated: they may be a constant-speed cruise, and a
        zero-velocity factor there drags the whole window to a stop; the fixes have vetted the
        others, whose first epochs the gate would wrongly refuse while the estimate still carries
        the braking's last few cm/s."""
        if self.zupt_gate > 0 and not self.gnss_checked[j]:
            nis = float(v_pred @ np.linalg.solve(c_vel + self.zupt_var * np.eye(3), v_pred))
            if not nis <= self.zupt_gate:
                self.stats["n_zupt_gated"] += 1
                return
        graph.add(gtsam.PriorFactorVector(V(i), np.zeros(3), self.zupt_noise))
        # Only the gyro half is measured; the accelerometer half gets a vanishing weight.
        b_g = self.st.omega_mean_b[j] - R_nb.T @ self.w_ie
        sig = np.concatenate([np.full(3, 1e3), np.sqrt(self.st.omega_var_b[j])])
        graph.add(
            gtsam.PriorFactorConstantBias(
                B(i),
                gtsam.imuBias.ConstantBias(bias.accelerometer(), b_g),
                gtsam.noiseModel.Diagonal.Sigmas(sig),
            )
        )
        self.stats["n_zupt_factors"] += 1


def vetted_by_fixes(span, params) -> bool:
    """Whether the fixes vetted a stationary span (``span``: a
    :class:`gnssacc.prepare.stationary.StationarySpan`, ``params`` its detection's
    :class:`~gnssacc.core.stationary_params.StationaryParams`): its GNSS check ran with at least
    ``gnss_min_fixes`` (and two) fixes inside the span.

    A check made from fixes outside the span alone (a span inside a GNSS outage, checked against
    the first fixes after it) has next to no power: on a simulated UGV a 9 s cruise at 2 m/s
    inside an outage passed it with a fitted speed of 4.7 +- 4.3 m/s, and its unguarded
    zero-velocity factors drove the smoother to 20 m and 20 deg of yaw error while the EKF, whose
    gate refused them, stayed at 2 m. Such a span is gated like one found on IMU evidence alone
    (:meth:`_Factors.stationary`)."""
    return bool(span.gnss_checked) and span.gnss_n_fixes >= max(int(params.gnss_min_fixes), 2)


def _node_epochs(gnss_t: np.ndarray, stat_t: np.ndarray, interval: float) -> np.ndarray:
    """GNSS epochs plus the stationary epochs no GNSS epoch is within half an interval of."""
    if len(stat_t) == 0 or len(gnss_t) == 0:
        return np.union1d(gnss_t, stat_t)
    i = np.clip(np.searchsorted(gnss_t, stat_t), 1, len(gnss_t) - 1)
    near = np.minimum(np.abs(gnss_t[i] - stat_t), np.abs(gnss_t[i - 1] - stat_t))
    return np.union1d(gnss_t, stat_t[near > 0.5 * interval])


def _attach_stationary(times: np.ndarray, st: StationaryEpochs, interval: float) -> dict:
    """Node index for each stationary epoch (its nearest node within half an interval)."""
    out = {}
    for j, t in enumerate(st.t):
        i = int(np.clip(np.searchsorted(times, t), 1, len(times) - 1))
        i = i if abs(times[i] - t) <= abs(times[i - 1] - t) else i - 1
        if abs(times[i] - t) <= 0.5 * interval + 1e-9:
            out[i] = j
    return out


def _preintegrate(imu, model, bias, t_prev, t, j_start, k_end, inflation, dt_all):
    """PreintegratedCombinedMeasurements over ``(t_prev, t]``; samples held over (t[k-1], t[k]].

    ``dt_all[k] = t[k] - t[k-1]``: only the first and last samples' spans are cut at the node times.
    A sample is the interval's mean specific force in the body frame at the middle of the interval
    (the convention of the EKF's mechanization and of the simulator), while GTSAM rotates it with
    the attitude at the interval's start: each sample is first turned by the half-interval rotation
    (:func:`_mid_interval_force`).
    """
    pim = gtsam.PreintegratedCombinedMeasurements(model.params(*inflation), bias)
    if k_end <= j_start:
        return pim
    imu_t = imu.t
    dts = dt_all[j_start:k_end].tolist()
    dts[0] = min(imu_t[j_start], t) - t_prev
    if k_end - j_start > 1 and imu_t[k_end - 1] > t:
        dts[-1] = t - imu_t[k_end - 2]
    f_b, w_b = imu.f_b[j_start:k_end], imu.omega_ib_b[j_start:k_end]
    if min(dts) <= 0.0:  # repeated time stamps: nothing to integrate
        keep = [k for k, dt in enumerate(dts) if dt > 0.0]
        f_b, w_b, dts = f_b[keep], w_b[keep], [dts[k] for k in keep]
    f_b = _mid_interval_force(f_b, w_b - bias.gyroscope(), np.asarray(dts))
    # map() drives the C++ calls without a Python loop body (the samples are most of the run's calls).
    deque(map(pim.integrateMeasurement, f_b, w_b, dts), maxlen=0)
    return pim


def _mid_interval_force(f_b: np.ndarray, omega_b: np.ndarray, dt: np.ndarray) -> np.ndarray:
    """Specific force samples [m/s^2] (body frame at each interval's middle) expressed in the body
    frame at the interval's start: ``Exp(omega dt / 2) f`` with the bias-corrected rate ``omega``
    [rad/s] held over ``dt`` [s]. Without it a vehicle turning at ``omega`` with speed ``v`` gets a
    spurious along-track acceleration ``v omega^2 dt / 2`` (5.5 mm/s^2 at 10 m/s on a 30 m circle
    at 100 Hz)."""
    return Rotation.from_rotvec(0.5 * omega_b * dt[:, None]).apply(f_b)


def _touches(
    first: np.ndarray, last: np.ndarray, seg_i0: np.ndarray, seg_i1: np.ndarray
) -> np.ndarray:
    """Per node interval, whether samples ``[first[i-1], last[i])`` overlap a suspect segment
    (segments sorted and disjoint, :func:`gnssacc.checks.quality.inflation_segments`)."""
    out = np.zeros(len(first), bool)
    if seg_i0.size:
        j0, k1 = first[:-1], last[1:]
        s = np.searchsorted(seg_i1, j0, side="right")  # first segment ending after j0
        ok = s < len(seg_i0)
        out[1:][ok] = seg_i0[s[ok]] < k1[ok]
    return out


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
    settings : SmootherSettings or gnssacc.core.config.RunConfig
        The smoother's settings (:class:`gnssacc.estimators.settings.SmootherSettings`; a run
        configuration is reduced to them first).
    method : {"smoother", "smoother-acc", "smoother-accw"}
        Without the GNSS-acceleration factor, with the paper's, or with the window-consistent one
        (:data:`METHODS`).
    quality : QualityReport, optional
        Data-quality findings (computed when omitted).
    init : InitialState, optional
        Overrides ``run.init`` and self-initialisation (the same as the EKF's).
    stationary : gnssacc.prepare.stationary.StationaryReport, optional
        Where the vehicle stands still: zero-velocity and zero-rate factors there (``[zupt]``).
    show_progress : bool

    Returns
    -------
    dict
        ``{method: fixed-lag NavSolution, method + "-online": online NavSolution}``, one row per
        node; ``stats`` has the factor counts and ``nis_pos_mean``, the whitened GNSS residuals of
        that estimate against their expectation (:func:`residual_chi2`; 1 when consistent).
    """
    if method not in METHODS:
        raise ValueError(f"unknown smoother method {method!r}; known: {', '.join(METHODS)}")
    wall0 = time.perf_counter()
    init, quality = start_of_pass(run, settings, init, quality)
    settings = SmootherSettings.of(settings)
    run = run.with_gnss(settings.gnss.fixes(run.gnss))
    z = settings.zupt
    st = epochs_for(run, z, settings.imu.gyro_psd, stationary)
    is_node_fix = node_fixes(run.gnss.t, settings.min_node_spacing_s)
    times = node_times(
        float(init.t),
        float(run.imu.t[-1]),
        _node_epochs(run.gnss.t[is_node_fix], st.t, z.interval_s),
        settings.max_node_spacing_s,
    )
    stats = {
        "n_nodes": len(times),
        "n_gps_factors": 0,
        "n_gps_folded": 0,
        "n_acc_factors": 0,
        "n_acc_skipped_suspect_imu": 0,
        "n_zupt_factors": 0,
        "n_zupt_gated": 0,
        "n_ill_posed_recovered": 0,
        "factorization_switched_to_qr": False,
        "init": init.how,
        "t_init": float(init.t),
        "lag_s": settings.lag_s,
    }
    checked = np.array(
        [vetted_by_fixes(stationary.spans[j], stationary.params) for j in st.span], bool
    )
    loop = _Loop(
        run,
        settings,
        METHODS[method],
        quality,
        init,
        times,
        _Factors(run, settings, st, stats, checked),
        _attach_stationary(times, st, z.interval_s),
        stats,
        NhcFactors(run, settings, times, stationary, stats),
        OdometryFactors(run, settings, times, stats),
    )
    loop.folded = _folded_by_node(times, run.gnss.t, is_node_fix)
    loop.feed(method, show_progress)
    loop.score()
    loop.odo.final_stats(loop.online)
    stats["final_window_variables"] = int(loop.smoother.isam.getLinearizationPoint().size())
    stats["final_factor_slots"] = int(loop.smoother.isam.getFactors().size())
    runtime = time.perf_counter() - wall0
    out = {}
    for mid, rec in ((method, loop.fixed), (method + "-online", loop.online)):
        c = rec.chi2[np.isfinite(rec.chi2[:, 0])]
        ratio = float(c[:, 0].sum() / c[:, 1].sum()) if len(c) and c[:, 1].sum() > 0 else None
        out[mid] = rec.solution(
            run, mid, times, runtime, {**stats, "n_pos_updates": len(c), "nis_pos_mean": ratio}
        )
    return out


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
    """Feeds iSAM2 node by node and records the online and fixed-lag estimates."""

    def __init__(
        self, run, settings, use_acc, quality, init, times, factors, stationary_at, stats, nhc, odo
    ):
        self.run, self.settings, self.use_acc, self.times, self.f = (
            run,
            settings,
            use_acc,
            times,
            factors,
        )
        self.stationary_at, self.stats, self.nhc, self.odo = stationary_at, stats, nhc, odo
        self.segs = inflation_segments(run.imu, quality, settings.suspect)
        origin = run.origin
        self.model = _ImuModel(settings, float(factors.g_n[2]), earth_rate_n(origin.lat0))
        n = len(times)
        self.online, self.fixed = _Record(n, factors.gm), _Record(n, factors.gm)
        self.smoother = _Smoother(
            settings, _bandwidth(settings) if use_acc == "window" else 1, odo.active
        )
        self.fix_of = np.full(n, -1)
        self.folded: dict = {}  # node -> fixes between it and the node before (run_smoother sets it)
        self.window_start, self.oldest = 0, 0
        self._start(init)

    def priors(
        self, i, pose, vel, bias, c_pose, c_vel, c_bias, g=None, c_g=None, k=0.0, var_k=None
    ):
        graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
        graph.add(gtsam.PriorFactorPose3(X(i), pose, gtsam.noiseModel.Gaussian.Covariance(c_pose)))
        graph.add(gtsam.PriorFactorVector(V(i), vel, gtsam.noiseModel.Gaussian.Covariance(c_vel)))
        graph.add(
            gtsam.PriorFactorConstantBias(B(i), bias, gtsam.noiseModel.Gaussian.Covariance(c_bias))
        )
        values.insert(X(i), pose)
        values.insert(V(i), vel)
        values.insert(B(i), bias)
        if self.f.gm:
            graph.add(gtsam.PriorFactorVector(G(i), g, gtsam.noiseModel.Gaussian.Covariance(c_g)))
            values.insert(G(i), g)
        if self.odo.active:
            self.odo.prior(graph, values, i, k, var_k)
        return graph, values

    def _start(self, init):
        """Node 0 with the EKF's own initial covariance (:func:`initial_prior`)."""
        R0 = init.R_nb
        self.pose = gtsam.Pose3(gtsam.Rot3(R0), self.run.origin.to_ned(init.lat, init.lon, init.h))
        self.vel = np.asarray(init.v_n, float)
        self.bias = gtsam.imuBias.ConstantBias(
            np.asarray(init.b_a, float), np.asarray(init.b_g, float)
        )
        self.g, self.k = np.zeros(3), 0.0
        if self.use_acc:
            self.f.prepare_accel(self.times)
        cov, c_vel = initial_prior(init, self.settings)
        graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
        graph.add(
            joint_prior_factor(
                X(0),
                B(0),
                G(0) if self.f.gm else None,
                self.pose,
                self.bias.vector(),
                self.g if self.f.gm else None,
                cov,
            )
        )
        graph.add(
            gtsam.PriorFactorVector(V(0), self.vel, gtsam.noiseModel.Gaussian.Covariance(c_vel))
        )
        for key, value in ((X(0), self.pose), (V(0), self.vel), (B(0), self.bias)) + (
            ((G(0), self.g),) if self.f.gm else ()
        ):
            values.insert(key, value)
        if self.odo.active:
            self.odo.prior(graph, values, 0, 0.0, None)
        self._start_gate = (R0, self.vel, c_vel)
        self._node_factors(graph, 0, self.times[0])
        self.smoother.update(graph, values, [(key, self.times[0]) for key in self.smoother.keys(0)])
        self._record(0, self.times[1] if len(self.times) > 1 else np.inf)

    def _node_factors(self, graph, i, t, nav=None, pim=None):
        """GNSS, acceleration, stationary and non-holonomic factors of node ``i``; ``nav`` (``gtsam.NavState``)
        and ``pim`` are the node's prediction and preintegration (``None`` at the start), whose
        velocity and its covariance gate the stationary factors (:meth:`_Factors.stationary`)."""
        k = self.f.gps(graph, i, t)
        if k is not None:
            self.fix_of[i] = k
            if self.use_acc == "window":
                self.f.accel_window(graph, k, lambda n: n == i or self.smoother.has_node(n))
            elif self.use_acc:
                self.f.accel(graph, i, t, k, self.segs[0], self.segs[1])
        if i in self.stationary_at:
            if nav is None:  # the start: its own velocity and covariance
                R_nb, v_pred, c_vel = self._start_gate
            else:
                R_nb, v_pred, c_vel = (
                    nav.pose().rotation().matrix(),
                    nav.velocity(),
                    self._predicted_velocity_cov(i, pim),
                )
            self.f.stationary(graph, i, self.stationary_at[i], R_nb, self.bias, v_pred, c_vel)
        if nav is not None and i in self.nhc.nodes:
            self.nhc.add(
                graph,
                i,
                nav.pose().rotation().matrix(),
                nav.velocity(),
                self._predicted_velocity_cov(i, pim),
                self.bias.gyroscope(),
            )
        if nav is not None and i in self.odo.nodes:
            self.odo.add(
                graph,
                i,
                nav.pose().rotation().matrix(),
                nav.velocity(),
                self._predicted_velocity_cov(i, pim),
                self.bias.gyroscope(),
                self.k,
            )

    def _predicted_velocity_cov(self, i, pim) -> np.ndarray:
        """Covariance of node ``i``'s predicted NED velocity [m^2/s^2]: node ``i - 1``'s online
        marginal plus the preintegrated velocity noise (rotated from body ``i - 1`` into NED)."""
        R = self.online.R[i - 1]
        c_pim = np.asarray(pim.preintMeasCov())[NAVSTATE_VEL, NAVSTATE_VEL]
        return self.online.cov_vel[i - 1] + R @ c_pim @ R.T

    def _record(self, i: int, t_next: float):
        """Record node ``i``'s online estimate right after its update, and the fixed-lag estimate
        of every node that leaves the window before the next node (``t_next`` [s], ``inf`` at the
        end), whose value it is now; their covariances come from one marginal query. Returns node
        ``i``'s estimate."""
        self.oldest = max(self.oldest, self.window_start)
        leaving = []
        while self.oldest < i + 1 and self.times[self.oldest] < t_next - self.smoother.lag:
            if not (
                t_next == np.inf and self.fixed.done[self.oldest]
            ):  # at the end: not the nodes a
                leaving.append(self.oldest)  # restart already recorded
            self.oldest += 1
        nodes = leaving if leaving and leaving[-1] == i else leaving + [i]
        covs = self.smoother.covariances(nodes)
        est = self.smoother.estimate(i)
        self.online.put(i, est, covs[-1])
        for m, cov in zip(leaving, covs):
            self.fixed.put(m, est if m == i else self.smoother.estimate(m), cov)
        return est

    def score(self) -> None:
        """Whitened GNSS residuals of both estimates at every node with a fix (vectorised)."""
        for rec in (self.online, self.fixed):
            idx = np.flatnonzero((self.fix_of >= 0) & rec.done)
            k = self.fix_of[idx]
            rec.chi2[idx] = np.column_stack(
                residual_chi2(rec, idx, self.f.p_fix[k], self.run.gnss.cov_ned(k), self.f.lever)
            )

    def feed(self, method, show_progress):
        imu, times, n = self.run.imu, self.times, len(self.times)
        seg_i0, seg_i1, seg_qg, seg_qa = self.segs
        first = np.searchsorted(imu.t, times, side="right")
        last = np.minimum(np.searchsorted(imu.t, times, side="left") + 1, len(imu.t))
        touches = _touches(first, last, seg_i0, seg_i1).tolist()
        dt_all = np.diff(imu.t, prepend=imu.t[0])
        # Python scalars: the loop runs once per node and numpy scalars cost more than floats.
        times_l, first, last = (times.tolist() + [np.inf]), first.tolist(), last.tolist()
        fix_t = self.run.gnss.t
        for i in progress(range(1, n), desc=method, enable=show_progress):
            t_prev, t = times_l[i - 1], times_l[i]
            j0, k1 = first[i - 1], last[i]
            inflation = (
                _inflation_over(imu.t, j0, k1, t_prev, t, seg_i0, seg_i1, seg_qa, seg_qg)
                if touches[i]
                else (None, None)
            )
            pim = _preintegrate(imu, self.model, self.bias, t_prev, t, j0, k1, inflation, dt_all)
            nav = pim.predict(gtsam.NavState(self.pose, self.vel), self.bias)
            graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
            graph.add(gtsam.CombinedImuFactor(X(i - 1), V(i - 1), X(i), V(i), B(i - 1), B(i), pim))
            values.insert(X(i), nav.pose())
            values.insert(V(i), nav.velocity())
            values.insert(B(i), self.bias)
            if self.f.gm:
                self.f.gm_chain(graph, values, i, t - t_prev, self.g)
            if self.odo.active:
                self.odo.chain(graph, values, i, t - t_prev, self.k)
            for k in self.folded.get(i, ()):  # fixes between the nodes: on node i - 1
                t_f = float(fix_t[k])
                k_f = min(int(np.searchsorted(imu.t, t_f, side="left")) + 1, len(imu.t))
                infl = (
                    _inflation_over(imu.t, j0, k_f, t_prev, t_f, seg_i0, seg_i1, seg_qa, seg_qg)
                    if touches[i]
                    else (None, None)
                )
                self.f.folded_gps(
                    graph,
                    i - 1,
                    k,
                    _preintegrate(imu, self.model, self.bias, t_prev, t_f, j0, k_f, infl, dt_all),
                    self.pose,
                    self.vel,
                    self.bias,
                    t - t_prev,
                )
            self._node_factors(graph, i, t, nav, pim)
            try:
                self.smoother.update(graph, values, [(key, t) for key in self.smoother.keys(i)])
            except RuntimeError as exc:
                if not _is_ill_posed(exc):
                    raise
                self.stats["n_ill_posed_recovered"] += 1
                self.window_start = _reinitialise(self, i, graph, values)
            self.pose, self.vel, self.bias, self.g, self.k = self._record(i, times_l[i + 1])


def _bandwidth(settings: SmootherSettings) -> int:
    """How many nodes apart a window-consistent acceleration factor may reach: its window's m
    fixes are at most ``[accel] max_gap_s`` apart, with fill nodes at most ``[smoother]
    max_node_spacing_s`` apart between them (stationary nodes may add more: such a factor makes
    the marginals come from iSAM2 while it is in the window)."""
    per_gap = int(np.ceil(settings.accel.max_gap_s / settings.max_node_spacing_s - 1e-9))
    return (settings.accel.window - 1) * max(per_gap, 1)


def _reinitialise(loop: _Loop, i: int, graph, values) -> int:
    """Restart the window after an ill-posed update of node ``i``; return the new window start.

    The new window holds node ``i - 1`` with a prior from its online estimate and marginal
    covariance (what the failed window knew about it), node ``i`` with all of its new factors
    (IMU, GNSS, acceleration), so no measurement is lost, except a window-consistent acceleration
    factor on nodes older than ``i - 1`` (they are gone). If the smoother used Cholesky
    factorization it switches to QR, which tolerates the poor conditioning that stiff bias random
    walks cause. Nodes of the abandoned window keep their online estimate as their fixed-lag one.
    """
    online, fixed, times = loop.online, loop.fixed, loop.times
    for m in range(loop.window_start, i):
        if not fixed.done[m] and online.done[m]:
            fixed.copy_from(online, m)
    if loop.smoother.reset(robust=True):
        loop.stats["factorization_switched_to_qr"] = True
    p = i - 1
    pose = gtsam.Pose3(gtsam.Rot3(online.R[p]), online.p_n[p])
    bias = gtsam.imuBias.ConstantBias(online.bias[p, B_ACC], online.bias[p, B_GYRO])
    p_graph, p_values = loop.priors(
        p,
        pose,
        online.v_n[p],
        bias,
        online.cov_pose[p],
        online.cov_vel[p],
        online.cov_bias[p],
        online.g[p],
        online.cov_g[p] + 1e-12 * np.eye(3),
        online.k[p],
        online.var_k[p],
    )
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
