"""The smoother's graph machinery: node times, the IMU preintegration, the start's prior, the
incremental fixed-lag smoother with its marginals, and the record of its estimates
(:mod:`gnssacc.estimators.smoother` runs the loop).

Bias random walks are floored at :data:`ACCEL_BIAS_RW_FLOOR` and :data:`GYRO_BIAS_RW_FLOOR` (per
second) and the start's bias sigmas at the same values: a configured zero (``[imu]
accel_bias_instability_mg`` or ``gyro_bias_instability_deg_h`` = 0, a constant bias; or a zero
``*_bias_sigma0_*``, a calibrated one) would give the bias between-factor of
``CombinedImuFactor`` or the start's prior a zero covariance, which GTSAM cannot factor. The
floors are hundreds of times below any real IMU's random walk, so they change no estimate that a
constant bias would not give.
"""

from __future__ import annotations

from collections import deque
from typing import NamedTuple

import gtsam
import numpy as np

from ..core.recording import InitialState, RecordedRun
from ..core.rotations import dcm_to_euler, euler_error_jacobian
from ..core.solution import NavSolution
from .fixed_lag import FixedLagISAM2
from .layout import (
    ATT,
    B_ACC,
    B_GYRO,
    BIASES,
    GNSS_ERROR,
    NODE_B,
    NODE_V,
    NODE_X,
    POS,
    PRIOR_BIAS,
    PRIOR_G,
    PRIOR_POSE,
    SYM_B,
    SYM_V,
    SYM_X,
    VEL,
    X_ROT,
    X_TRANS,
    NodeLayout,
    StateLayout,
)
from .mechanization import half_interval_rotations
from .settings import SmootherSettings
from .state import initial_state
from .window_marginals import NotAChain, WindowMarginals

#: Nodes closer than this are merged (a duplicate time would make a zero-length IMU factor) [s].
MIN_NODE_DT = 1e-3
#: Smallest accelerometer bias random walk the smoother uses [m/s^2/sqrt(s)] (~0.1 ug/sqrt(s)).
ACCEL_BIAS_RW_FLOOR = 1e-6
#: Smallest gyro bias random walk the smoother uses [rad/s/sqrt(s)] (~0.002 deg/h/sqrt(s)).
GYRO_BIAS_RW_FLOOR = 1e-8
#: Symbol character of the bias variables ``B(i)``: relinearised before they are marginalised
#: when far from their linearisation point (the IMU factors' first-order bias correction).
BIAS_SYMBOL = SYM_B
#: Mean rotation rates of a node interval are rounded to a geometric grid of this ratio before
#: they set its gyro noise (:meth:`ImuModel.turn_psd`; 5 %: the PSD within 2.5 %).
TURN_RATE_STEP = 1.05
#: Below this mean rotation rate [rad/s] (about the earth's rate) an interval gets no turn noise.
TURN_RATE_FLOOR = 1e-4
_LOG_TURN_STEP = np.log(TURN_RATE_STEP)


class NodeEstimate(NamedTuple):
    """One node's estimate: pose (``gtsam.Pose3``), NED velocity [m/s], IMU bias
    (``gtsam.imuBias.ConstantBias``) and its Gauss-Markov states by block name."""

    pose: gtsam.Pose3
    v_n: np.ndarray
    bias: gtsam.imuBias.ConstantBias
    markov: dict


def node_times(t0: float, t_end: float, epochs: np.ndarray, max_spacing: float) -> np.ndarray:
    """Node epochs: the start, every epoch the aids ask for in ``(t0, t_end]``, the end of the
    recording, and fill nodes in gaps longer than ``max_spacing`` [s].

    Epochs closer than :data:`MIN_NODE_DT` to the previous one are dropped.
    """
    base = np.concatenate([[t0], epochs[(epochs > t0) & (epochs <= t_end)]])
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


class ImuModel:
    """Preintegration parameters, with cached copies inflated for suspect IMU data and for the
    rotation an interval performs."""

    def __init__(self, settings: SmootherSettings, g: float, omega_ie_n: np.ndarray):
        self.settings, self.g, self.omega = settings, g, omega_ie_n
        self._cache: dict = {}
        self._turning: dict = {}  # the cache's entries without inflation, by turn PSD
        self._q_turn = float(settings.imu.gyro_turn_psd)
        self.base = self.params(np.zeros(3), np.zeros(3))  # first call fills the cache

    def turn_psd(self, rate: float) -> float:
        """The gyro PSD [rad^2/s] the constant scale-factor and cross-axis errors add at the mean
        rotation rate ``rate`` [rad/s]: ``gyro_turn_psd rate``
        (:attr:`gnssacc.estimators.settings.ImuNoise.gyro_turn_psd`), the rate rounded to a grid
        of :data:`TURN_RATE_STEP` (so that few parameter sets are made) and nothing below
        :data:`TURN_RATE_FLOOR`."""
        q = self._q_turn
        if q <= 0.0 or rate < TURN_RATE_FLOOR:
            return 0.0
        return q * float(np.exp(np.round(np.log(rate) / _LOG_TURN_STEP) * _LOG_TURN_STEP))

    def params(
        self, qa_extra: np.ndarray | None, qg_extra: np.ndarray | None, rate: float = 0.0
    ) -> gtsam.PreintegrationCombinedParams:
        """The parameters with the extra white PSDs ``qa_extra`` [(m/s^2)^2/s], ``qg_extra``
        [rad^2/s] per body axis (``None``: none) and the interval's mean rotation rate ``rate``
        [rad/s] (:meth:`turn_psd`)."""
        q_w = self.turn_psd(rate)
        if qa_extra is None and qg_extra is None and self._cache:
            if q_w == 0.0:
                return self.base
            if q_w not in self._turning:  # (most intervals: no key of arrays to make)
                self._turning[q_w] = self.params(np.zeros(3), np.zeros(3), rate)
            return self._turning[q_w]
        qa_extra = np.zeros(3) if qa_extra is None else qa_extra
        qg_extra = np.zeros(3) if qg_extra is None else qg_extra
        key = (tuple(np.round(qa_extra, 15)), tuple(np.round(qg_extra, 15)), q_w)
        if key not in self._cache:
            self._cache[key] = self._make(qa_extra, qg_extra + q_w)
        return self._cache[key]

    def _make(
        self, qa_extra: np.ndarray, qg_extra: np.ndarray
    ) -> gtsam.PreintegrationCombinedParams:
        """New parameters with the settings' noise plus ``qa_extra``, ``qg_extra``."""
        imu = self.settings.imu
        p = gtsam.PreintegrationCombinedParams.MakeSharedD(self.g)
        p.setAccelerometerCovariance(np.diag(imu.accel_psd + qa_extra))
        p.setGyroscopeCovariance(np.diag(imu.gyro_psd + qg_extra))
        p.setBiasAccCovariance(np.diag(np.maximum(imu.accel_bias_rw_psd, ACCEL_BIAS_RW_FLOOR**2)))
        p.setBiasOmegaCovariance(np.diag(np.maximum(imu.gyro_bias_rw_psd, GYRO_BIAS_RW_FLOOR**2)))
        p.setIntegrationCovariance(np.eye(3) * self.settings.integration_sigma**2)
        p.setOmegaCoriolis(self.omega)
        return p


def initial_prior(
    init: InitialState, settings: SmootherSettings, layout: StateLayout | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """The EKF's initial covariance (:func:`gnssacc.estimators.state.initial_state`, with the
    Gauss-Markov GNSS error of ``layout`` when it has it) in the smoother's variables.

    EKF errors are estimate minus truth with ``R_est = (I + [phi x]) R``; the prior factor's error
    is
    the truth's offset from the prior: rotation ``xi = -R^T phi``, translation ``tau = -R^T dp``,
    biases ``+db`` (the residual bias adds to the estimate), GNSS error ``-dx_g``.

    Returns
    -------
    cov : ndarray (12, 12) or (15, 15)
        Of (rotation, translation, accelerometer bias, gyro bias[, GNSS error]).
    c_vel : ndarray (3, 3)
        Velocity covariance (uncorrelated with the rest at the start).
    """
    s = initial_state(init, settings, layout)
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


class NodeRecord:
    """Per-node estimates and marginal covariances (one of: online, fixed-lag)."""

    def __init__(self, n: int, layout: NodeLayout):
        self.layout = layout
        self.p_n = np.full((n, 3), np.nan)
        self.R = np.full((n, 3, 3), np.nan)
        self.v_n = np.full((n, 3), np.nan)
        self.bias = np.full((n, 6), np.nan)
        self.cov_pose = np.full((n, 6, 6), np.nan)  # Pose3 tangent (body rotation, translation)
        self.cov_vel = np.full((n, 3, 3), np.nan)
        self.cov_bias = np.full((n, 6, 6), np.nan)
        self.done = np.zeros(n, bool)
        # The Gauss-Markov states, by block: estimate, covariance, cross-covariance with the pose.
        self.markov = {b.name: np.zeros((n, b.dim)) for b in layout.markov}
        self.cov_markov = {b.name: np.zeros((n, b.dim, b.dim)) for b in layout.markov}
        self.cov_x_markov = {b.name: np.zeros((n, 6, b.dim)) for b in layout.markov}

    def put(self, i: int, est: NodeEstimate, cov: np.ndarray) -> None:
        """Node ``i``'s estimate and the blocks of its joint marginal ``cov`` (the node layout)."""
        self.p_n[i] = est.pose.translation()
        self.R[i] = est.pose.rotation().matrix()
        self.v_n[i] = est.v_n
        self.bias[i] = est.bias.vector()
        self.cov_pose[i], self.cov_vel[i], self.cov_bias[i] = (
            cov[NODE_X, NODE_X],
            cov[NODE_V, NODE_V],
            cov[NODE_B, NODE_B],
        )
        for _, sl, blk in self.layout.markov_blocks():
            self.markov[blk.name][i] = est.markov[blk.name]
            self.cov_markov[blk.name][i] = cov[sl, sl]
            self.cov_x_markov[blk.name][i] = cov[NODE_X, sl]
        self.done[i] = True

    def markov_of(self, name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Block ``name``'s estimates, covariances and cross-covariances with the pose."""
        return self.markov[name], self.cov_markov[name], self.cov_x_markov[name]

    def copy_from(self, other: "NodeRecord", i: int) -> None:
        for name in ("p_n", "R", "v_n", "bias", "cov_pose", "cov_vel", "cov_bias", "done"):
            getattr(self, name)[i] = getattr(other, name)[i]
        for table in ("markov", "cov_markov", "cov_x_markov"):
            for name, arr in getattr(self, table).items():
                arr[i] = getattr(other, table)[name][i]

    def sigmas(self) -> np.ndarray:
        """1-sigma in the NavSolution layout (NED position, velocity, roll/pitch/yaw, biases)."""
        R = self.R
        # Tangent (body) -> NED: position R C R^T; the attitude error phi = -R xi has the same form.
        c_pos = R @ self.cov_pose[:, X_TRANS, X_TRANS] @ R.transpose(0, 2, 1)
        c_att = R @ self.cov_pose[:, X_ROT, X_ROT] @ R.transpose(0, 2, 1)
        roll, pitch, yaw = dcm_to_euler(R)
        J = euler_error_jacobian(roll, pitch, yaw)
        c_eul = J @ c_att @ J.transpose(0, 2, 1)

        def diag(C):
            return np.sqrt(np.maximum(np.diagonal(C, axis1=1, axis2=2), 0.0))

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


class WindowSmoother:
    """The incremental fixed-lag smoother with its marginals, over nodes of ``layout``.

    ``bandwidth``: how many nodes apart a factor reaches (1: a chain of nodes; factors on several
    nodes widen it). The window's marginals are kept by :class:`WindowMarginals` for that band; a
    wider factor makes them come from iSAM2's queries while it is in the window.
    """

    def __init__(self, settings: SmootherSettings, layout: NodeLayout, bandwidth: int = 1):
        self.lag, self.layout = settings.lag_s, layout
        self.params = gtsam.ISAM2Params()
        self.params.setFactorization(settings.factorization)
        self.threshold = settings.relinearize_threshold
        self.params.setRelinearizeThreshold(self.threshold)
        self.params.relinearizeSkip = settings.relinearize_skip
        # Reuse the slots of marginalised factors so the factor list stays bounded on long runs.
        self.params.findUnusedFactorSlots = True
        self.isam = FixedLagISAM2(self.lag, self.params, self.threshold, guard=BIAS_SYMBOL)
        self.marginals = WindowMarginals(layout.gm, bandwidth, layout.scale)

    def reset(self, robust: bool = False) -> bool:
        """A new, empty smoother; ``robust`` switches to QR factorization (returns whether it
        did)."""
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

    def estimate(self, i: int) -> NodeEstimate:
        """Node ``i``'s estimate."""
        isam = self.isam
        sym = gtsam.symbol
        markov = {
            blk.name: isam.calculateEstimateVector(sym(c, i))
            for c, _, blk in self.layout.markov_blocks()
        }
        return NodeEstimate(
            isam.calculateEstimatePose3(sym(SYM_X, i)),
            isam.calculateEstimateVector(sym(SYM_V, i)),
            isam.calculateEstimateConstantBias(sym(SYM_B, i)),
            markov,
        )

    def has_node(self, i: int) -> bool:
        """Whether node ``i`` is in the window (not marginalised, not dropped by a restart)."""
        return self.isam.getISAM2().valueExists(gtsam.symbol(SYM_X, i))

    def keys(self, i: int) -> list:
        """Keys of node ``i``, in the node layout's order."""
        return [gtsam.symbol(c, i) for c in self.layout.symbols]

    def covariances(self, nodes: list) -> np.ndarray:
        """Joint marginal covariance of each node's variables (the node layout), for ``nodes``
        (ascending); array (len(nodes), b, b).

        From :class:`gnssacc.estimators.window_marginals.WindowMarginals` (the window's linear
        system, kept in step with iSAM2), all nodes in one query; iSAM2's own queries, per node,
        while that system is not at hand (a factor wider than its band): the joint one by QR
        with GNSS-error states, else the per-key marginals and zero cross-covariances (only the
        diagonal blocks are used then).
        """
        if self.marginals.first is not None:
            try:
                return self.marginals.covariances(nodes)
            except np.linalg.LinAlgError:
                self.marginals.clear()  # rebuilt at the next update
        return np.array([self._isam_covariance(i) for i in nodes])

    def _isam_covariance(self, i: int) -> np.ndarray:
        isam = self.isam.getISAM2()
        if not self.layout.gm:
            # iSAM2's per-key marginals cost a third of its joint query (measured, smoother-accw).
            full = np.zeros((self.layout.b, self.layout.b))
            for c, sl in self.layout.blocks():
                full[sl, sl] = isam.marginalCovariance(gtsam.symbol(c, i))
            return full
        keys = self.keys(i)
        info, _ = isam.joint(keys, gtsam.EliminateQR).hessian(gtsam.Ordering(keys))
        return np.linalg.inv(info)


def insert_bias(values: gtsam.Values, key: int, bias: gtsam.imuBias.ConstantBias) -> None:
    """``values.insert(key, bias)``, naming the overload's argument: a positional call tries
    gtsam's forty-odd ``insert`` overloads in turn before the bias's, the last but two (70 us, a
    node's largest cost in Python; 30 us by name). A gtsam whose wrapper names it otherwise gets
    the positional call."""
    try:
        values.insert(key, constant_bias=bias)
    except TypeError:
        values.insert(key, bias)


def is_ill_posed(exc: Exception) -> bool:
    """Whether GTSAM's exception is its indeterminant-system error."""
    text = str(exc).lower()
    return "indeterminant" in text or "indeterminate" in text or "ill-posed" in text


def preintegrate(imu, model, bias, t_prev, t, j_start, k_end, inflation, dt_all, w_turn=None):
    """PreintegratedCombinedMeasurements over ``(t_prev, t]``; samples held over (t[k-1], t[k]].

    ``dt_all[k] = t[k] - t[k-1]``: only the first and last samples' spans are cut at the node times.
    A sample is the interval's mean specific force in the body frame at the middle of the interval
    (the convention of the EKF's mechanization and of the simulator), while GTSAM rotates it with
    the attitude at the interval's start: each sample is first turned by the half-interval rotation
    (:func:`mid_interval_force`). The gyro noise grows with the interval's mean rotation rate
    (:meth:`ImuModel.turn_psd`): the time average of ``|w_turn - b_g|``, ``w_turn`` the rotation
    the body performs per sample [rad/s] (:func:`gnssacc.estimators.mechanization.turn_rates`;
    ``None``: no such noise).
    """
    if k_end <= j_start:
        return gtsam.PreintegratedCombinedMeasurements(model.params(*inflation), bias)
    imu_t = imu.t
    dts = dt_all[j_start:k_end].tolist()
    dts[0] = min(imu_t[j_start], t) - t_prev
    if k_end - j_start > 1 and imu_t[k_end - 1] > t:
        dts[-1] = t - imu_t[k_end - 2]
    f_b, w_b = imu.f_b[j_start:k_end], imu.omega_ib_b[j_start:k_end]
    w_t = np.zeros_like(w_b) if w_turn is None else w_turn[j_start:k_end]
    if min(dts) <= 0.0:  # repeated time stamps: nothing to integrate
        keep = [k for k, dt in enumerate(dts) if dt > 0.0]
        f_b, w_b, w_t, dts = f_b[keep], w_b[keep], w_t[keep], [dts[k] for k in keep]
    dt, b_g = np.asarray(dts), bias.gyroscope()
    rate = 0.0
    if w_turn is not None and len(dts):
        w_t = w_t - b_g  # |w_t| as np.linalg.norm(w_t, axis=1) computes it, without its checks
        rate = float(np.sqrt(np.add.reduce(w_t * w_t, axis=1)) @ dt / dt.sum())
    pim = gtsam.PreintegratedCombinedMeasurements(model.params(*inflation, rate=rate), bias)
    f_b = mid_interval_force(f_b, w_b - b_g, dt)
    # map() drives the C++ calls without a Python loop body (the samples are most of the run's
    # calls).
    deque(map(pim.integrateMeasurement, f_b, w_b, dts), maxlen=0)
    return pim


def mid_interval_force(f_b: np.ndarray, omega_b: np.ndarray, dt: np.ndarray) -> np.ndarray:
    """Specific force samples [m/s^2] (body frame at each interval's middle) expressed in the body
    frame at the interval's start: ``Exp(omega dt / 2) f`` with the bias-corrected rate ``omega``
    [rad/s] held over ``dt`` [s]. Without it a vehicle turning at ``omega`` with speed ``v`` gets a
    spurious along-track acceleration ``v omega^2 dt / 2`` (5.5 mm/s^2 at 10 m/s on a 30 m circle
    at 100 Hz).

    The numbers of ``Rotation.from_rotvec(0.5 omega dt).apply(f_b)`` (scipy), at a third of its
    cost and without importing ``scipy.spatial`` (a tenth of a second): the rotations from
    :func:`gnssacc.estimators.mechanization.half_interval_rotations` (its arithmetic), applied as
    scipy applies them: by ``einsum``, and one rotation to one vector by ``matmul``."""
    R = half_interval_rotations(np.ascontiguousarray(omega_b), dt)
    if len(dt) == 1:
        return np.matmul(R, f_b[0])
    return np.einsum("ijk,ik->ij", R, f_b)


def touches(
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


def inflation_over(imu_t, k0, k1, t_a, t_b, segs):
    """Time-averaged extra PSD (accel, gyro per body axis) over ``(t_a, t_b]`` from the suspect
    segments ``segs`` (:class:`gnssacc.checks.quality.InflationSegments`)."""
    qa, qg = np.zeros(3), np.zeros(3)
    if segs.i0.size == 0 or not segs.touch(k0, k1):
        return qa, qg
    for s in np.flatnonzero((segs.i0 < k1) & (segs.i1 > k0)):
        for k in range(max(segs.i0[s], k0), min(segs.i1[s], k1)):
            lo = imu_t[k - 1] if k > 0 else imu_t[0]
            overlap = max(0.0, min(imu_t[k], t_b) - max(lo, t_a))
            qa += segs.q_accel[s] * overlap
            qg += segs.q_gyro[s] * overlap
    span = max(t_b - t_a, 1e-9)
    return qa / span, qg / span
