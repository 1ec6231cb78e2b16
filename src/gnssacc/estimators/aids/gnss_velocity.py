r"""GNSS velocity: the receiver's Doppler velocity of the antenna, in the EKF and the smoother.

Measurement
-----------
The receiver measures the antenna's velocity relative to the earth (NED), not the IMU's. With the
lever arm ``l_b`` (``[gnss] lever_arm_b_m``), the bias-corrected gyro ``w = omega~ - b_g`` (the
raw sample held at the velocity's time) and the earth rate ``omega_ie^n``:

    v_ant = v_n + R_nb (w x l_b) - omega_ie^n x (R_nb l_b)

(Groves' loosely coupled lever-arm term; the transport rate's share, below 1e-5 m/s, is left
out). Under the error convention of :mod:`gnssacc.estimators.aids.base` (``R_est = (I + [phi x])
R``, bias-corrected rate ``w + db_g``) the EKF's innovation ``dz = v_ant,est - v~`` has

    H = [0, I, -[(R (w x l)) x] + [omega_ie x][(R l) x], 0, -R [l x]]

(blocks dp, dv, phi, b_a, b_g). Only the axes the source measures are used (NMEA speed and course:
north and east), with their stated (or default) covariance times ``[velocity] sigma_scale``;
gated by ``[velocity] gate_nis``. Update kind ``vel``: its NIS is reported beside the position's.

Smoother
--------
A velocity at a node's time is :func:`gnssacc.factors.gnss_velocity_factor` on the node's (X, V,
B); one between nodes (faster fixes, folded like them: :mod:`.gnss_position`) is
:func:`gnssacc.factors.preintegrated_velocity_factor` on the earlier node, through the IMU
preintegrated up to it. The velocities add no nodes: those at no node time and between no two
nodes (before the start) are left out. Consistency: the whitened residuals of each estimate to
its nodes' velocities over their expectation (as the positions', ``nis_vel_mean``).

The velocities are independent of the fixes' noise (Doppler against pseudorange), so they are
separate measurements; ``[velocity] enabled = false`` (``--velocity off``) leaves them out.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ...core.earth import earth_rate_n
from ..layout import B_GYRO, I_ATT, I_BG, I_VEL, N_NAV, SYM_B, SYM_V, SYM_X
from ..small_linalg import matmul_into, matvec, skew_into
from .base import AidSpec, EkfAid, Measurement, SmootherAid
from .gnss_position import folded_by_node
from .vehicle import held_samples

#: Order at equal times: after the fixes' epoch (its position and acceleration updates).
ORDER = 3


@njit(cache=True)
def velocity_model(R_nb, v_n, b_g, omega_meas_b, lever_b, w_ie_n, v_meas, rows, n):
    """``dz`` (m,) [m/s, NED] and ``H`` (m, n) of the velocity update on the measured axes
    ``rows`` (m,) of ``v_meas`` [m/s, NED], for the state's ``R_nb``, ``v_n`` [m/s], ``b_g``
    [rad/s] and ``n`` states; ``omega_meas_b`` the raw gyro [rad/s], ``lever_b`` [m, body],
    ``w_ie_n`` [rad/s, NED]: the antenna's velocity ``v_ant`` and its Jacobians (module notes).
    Compiled (the EKF's per-update path in both of its loops, the smoother's residuals), with
    numpy's arithmetic (:mod:`gnssacc.estimators.small_linalg`)."""
    v = v_n.copy()
    d_phi, d_bg = np.zeros((3, 3)), np.zeros((3, 3))
    if lever_b[0] != 0.0 or lever_b[1] != 0.0 or lever_b[2] != 0.0:
        c_rows = R_nb.strides[1] < R_nb.strides[0]
        w = omega_meas_b - b_g
        c = np.empty(3)  # w x l
        c[0], c[1], c[2] = (
            w[1] * lever_b[2] - w[2] * lever_b[1],
            w[2] * lever_b[0] - w[0] * lever_b[2],
            w[0] * lever_b[1] - w[1] * lever_b[0],
        )
        l_n, a_n = matvec(R_nb, lever_b, c_rows), matvec(R_nb, c, c_rows)
        v[0] = (v_n[0] + a_n[0]) - (w_ie_n[1] * l_n[2] - w_ie_n[2] * l_n[1])
        v[1] = (v_n[1] + a_n[1]) - (w_ie_n[2] * l_n[0] - w_ie_n[0] * l_n[2])
        v[2] = (v_n[2] + a_n[2]) - (w_ie_n[0] * l_n[1] - w_ie_n[1] * l_n[0])
        S_w, S_l, S_a = np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3))
        skew_into(w_ie_n, S_w)
        skew_into(l_n, S_l)
        skew_into(a_n, S_a)
        matmul_into(S_w, S_l, d_phi, 0)
        d_phi -= S_a  # -[a x] + [w_ie x][l x], each element one rounding as numpy adds
        skew_into(lever_b, S_l)
        matmul_into(-R_nb, S_l, d_bg, 0)
    m = rows.shape[0]
    dz, H = np.empty(m), np.zeros((m, n))
    for i in range(m):
        r = rows[i]
        dz[i] = v[r] - v_meas[r]
        H[i, I_VEL + r] = 1.0
        for j in range(3):
            H[i, I_ATT + j] = d_phi[r, j]
            H[i, I_BG + j] = d_bg[r, j]
    return dz, H


def velocity(
    s,
    v_meas: np.ndarray,
    cov: np.ndarray,
    axes: np.ndarray,
    omega_meas_b: np.ndarray,
    lever_b: np.ndarray,
    w_ie_n: np.ndarray,
    gate: float = 0.0,
) -> Measurement:
    """The velocity update on the measured ``axes`` (boolean (3,)) of ``v_meas`` [m/s, NED] with
    covariance ``cov`` [m^2/s^2] (3 x 3; rows and columns of the measured axes used);
    ``omega_meas_b`` the raw gyro [rad/s] (the state's bias is removed here; the model is
    :func:`velocity_model`)."""
    rows = np.flatnonzero(axes).astype(np.int64)
    dz, H = velocity_model(
        s.R_nb, s.v_n, s.b_g, omega_meas_b, lever_b, w_ie_n, v_meas, rows, s.P.shape[0]
    )
    return Measurement("vel", dz, H, cov[np.ix_(axes, axes)], gate)


class VelocityEpochs:
    """The velocities an estimator uses: those with a measured axis, with the raw gyro held at
    each (``vel``: :class:`gnssacc.core.recording.GnssVelocity`, its sigmas scaled)."""

    def __init__(self, run, vel):
        axes = vel.measured()
        keep = np.flatnonzero(axes.any(axis=1))
        self.vel = vel.select(keep)
        self.t = self.vel.t
        self.axes = axes[keep]
        self.omega_b = np.asarray(run.imu.omega_ib_b)[held_samples(run.imu.t, self.t)]
        self.v = np.nan_to_num(self.vel.v_ned)

    def __len__(self) -> int:
        return len(self.t)

    def cov(self, k: int) -> np.ndarray:
        """Covariance of velocity ``k`` [m^2/s^2], NaN rows and columns of unmeasured axes
        zeroed (they are never used)."""
        return np.nan_to_num(self.vel.cov_ned(k))


def epochs_for(run, settings) -> VelocityEpochs | None:
    """The velocities of a pass (``settings``: either estimator's), or ``None`` when they are off
    or the run has none."""
    vel = settings.velocity.velocities(getattr(run, "gnss_vel", None))
    if vel is None:
        return None
    ep = VelocityEpochs(run, vel)
    return ep if len(ep) else None


class EkfVelocity(EkfAid):
    """The velocity update at every velocity epoch (module notes)."""

    order, epoch = ORDER, "gnss_vel"

    def __init__(self, ctx, ep: VelocityEpochs):
        self.ep, self.t = ep, ep.t
        self.lever = ctx.settings.gnss.lever_arm_b
        self.gate = ctx.settings.velocity.gate_nis

    def models(self, s, j: int) -> list[Measurement]:
        ep = self.ep
        w_ie = earth_rate_n(s.pos[0])
        return [
            velocity(s, ep.v[j], ep.cov(j), ep.axes[j], ep.omega_b[j], self.lever, w_ie, self.gate)
        ]

    def compiled(self) -> tuple[str, tuple] | None:
        """``("velocity", (v, omega_b, R, rows, lever, gate))``: the velocities [m/s, NED], the raw
        gyro held at each [rad/s], their noise covariances on the measured axes (K, m, m)
        [m^2/s^2] as :func:`velocity` takes them, the measured axes (m,), the lever arm [m, body]
        and the gate; ``None`` when the measured axes change from one velocity to another (the
        Python loop's then)."""
        ep = self.ep
        if len(ep) == 0 or not (ep.axes == ep.axes[0]).all():
            return None
        rows = np.flatnonzero(ep.axes[0])
        R = np.nan_to_num(ep.vel.cov_ned(np.arange(len(ep))))[:, rows][:, :, rows]  # as cov(k)
        return "velocity", (
            np.ascontiguousarray(ep.v, float),
            np.ascontiguousarray(ep.omega_b, float),
            np.ascontiguousarray(R, float),
            rows.astype(np.int64),
            np.ascontiguousarray(self.lever, float),
            float(self.gate),
        )


def _ekf(ctx) -> EkfVelocity | None:
    ep = epochs_for(ctx.run, ctx.settings)
    return None if ep is None else EkfVelocity(ctx, ep)


def residual_chi2(rec, idx: np.ndarray, ep: VelocityEpochs, k: np.ndarray, lever_b, w_ie_n, b_g):
    r"""Whitened squared residuals of the velocity factors at nodes ``idx`` of an estimate (their
    velocities ``k``) and their expectations, as :func:`.gnss_position.residual_chi2` for the
    fixes: ``E[r^T W r] = m - tr(W J C J^T)`` with ``C`` the marginal of the node's velocity
    (``rec.cov_vel``) and ``J = I`` (the lever-arm term's share of the pose and bias marginals is
    left out: centimetres per second at most against the velocity's own)."""
    out = []
    for i, kk in zip(idx.tolist(), k.tolist(), strict=True):
        axes = ep.axes[kk]
        rows = np.flatnonzero(axes).astype(np.int64)
        r, _ = velocity_model(
            rec.R[i], rec.v_n[i], np.ascontiguousarray(b_g[i]), ep.omega_b[kk], lever_b, w_ie_n,
            ep.v[kk], rows, N_NAV,
        )  # fmt: skip
        C = ep.cov(kk)[np.ix_(axes, axes)]
        W = np.linalg.inv(C)
        JCJ = rec.cov_vel[i][np.ix_(axes, axes)]
        out.append((float(r @ W @ r), max(float(axes.sum() - np.trace(W @ JCJ)), 0.0)))
    return np.array(out).reshape(-1, 2)


class SmootherVelocity(SmootherAid):
    """The velocities' factors on the smoother's nodes (module notes)."""

    order = 2

    def __init__(self, ctx, ep: VelocityEpochs):
        self.ep, self.stats = ep, ctx.stats
        self.lever = ctx.settings.gnss.lever_arm_b
        self.w_ie = earth_rate_n(ctx.run.origin.lat0)
        self.at_t = {float(t): k for k, t in enumerate(ep.t)}

    def attach(self, ctx) -> None:
        times = ctx.times
        on_node = np.isin(self.ep.t, times)
        self.folded = folded_by_node(times, self.ep.t, on_node)
        self.vel_of = np.full(len(times), -1)

    def interval(self, graph, ctx, i: int) -> None:
        """The velocities between node ``i - 1`` and node ``i`` on node ``i - 1``'s variables,
        through the IMU preintegrated from node ``i - 1`` to each."""
        import gtsam

        from ...factors import preintegrated_velocity_factor

        ep = self.ep
        for k in self.folded.get(i, ()):
            pim = ctx.preintegrate_to(i, float(ep.t[k]))
            prev = ctx.prev
            R_f = pim.predict(gtsam.NavState(prev.pose, prev.v_n), prev.bias).attitude().matrix()
            keys = tuple(gtsam.symbol(c, i - 1) for c in (SYM_X, SYM_V, SYM_B))
            graph.add(
                preintegrated_velocity_factor(
                    keys, pim, ep.v[k], ep.axes[k], ep.omega_b[k], self.lever, self.w_ie,
                    ep.cov(k), R_f,
                )
            )  # fmt: skip
            self.stats["n_vel_folded"] += 1

    def node(self, graph, ctx, i: int, t: float, pred) -> None:
        """The velocity factor on node ``i`` when a velocity is at its time ``t``."""
        k = self.at_t.get(float(t))
        if k is None:
            return
        import gtsam

        from ...factors import gnss_velocity_factor

        ep = self.ep
        keys = tuple(gtsam.symbol(c, i) for c in (SYM_X, SYM_V, SYM_B))
        graph.add(
            gnss_velocity_factor(
                keys, ep.v[k], ep.axes[k], ep.omega_b[k], self.lever, self.w_ie, ep.cov(k)
            )
        )
        self.vel_of[i] = k
        self.stats["n_vel_factors"] += 1

    def score(self, ctx, rec) -> dict:
        """``nis_vel_mean``: the estimate's whitened residuals to its nodes' velocities over their
        expectation (:func:`residual_chi2`; 1 when consistent), and ``n_vel_updates``."""
        idx = np.flatnonzero((self.vel_of >= 0) & rec.done)
        c = residual_chi2(
            rec, idx, self.ep, self.vel_of[idx], self.lever, self.w_ie, rec.bias[:, B_GYRO]
        )
        c = c[np.isfinite(c[:, 0])]
        ratio = float(c[:, 0].sum() / c[:, 1].sum()) if len(c) and c[:, 1].sum() > 0 else None
        return {"n_vel_updates": len(c), "nis_vel_mean": ratio}


def _smoother(ctx) -> SmootherVelocity | None:
    ep = epochs_for(ctx.run, ctx.settings)
    return None if ep is None else SmootherVelocity(ctx, ep)


def _in_use(run, cfg) -> bool:
    vel = getattr(run, "gnss_vel", None)
    return vel is not None and bool(vel.measured().any())


AID = AidSpec(
    name="gnss_velocity",
    kinds=("vel",),
    ekf=_ekf,
    smoother=_smoother,
    smoother_counts={"n_vel_factors": 0, "n_vel_folded": 0},
    noise_keys=(("velocity", "sigma_scale"),),
    stage="imu",
    enabled_key=("velocity", "enabled"),
    in_use=_in_use,
)
