r"""Stationary updates: zero velocity and zero angular rate while the vehicle stands still.

Epochs
------
Within every stationary span (:mod:`gnssacc.prepare.stationary`) an epoch falls every
``[zupt] interval_s`` seconds after the span start. At each epoch the zero-rate update uses the
mean raw gyro reading over the block ``(t - interval_s, t]``; its variance per axis is learnt from
the span itself: the scatter of the span's consecutive block means (which includes engine
vibration, quantisation and whatever else the white-noise model misses), floored by the
configured white noise ``q_g / interval_s``.

Measurements
------------
``zupt``
    Zero velocity: ``dz = v_est``, ``H = [0, I, 0, 0, 0]``, 1-sigma ``[zupt] velocity_sigma_mps``.
``zaru``
    Zero angular rate: the gyro then reads the bias plus the earth rate,
    ``dz = (omega_mean - b_g_hat) - R_est^T omega_ie^n``. To first order
    ``dz = b_g - R^T [omega_ie x] phi + noise``, so ``H = [0, 0, -R^T [omega_ie x], 0, I]``.

The EKF applies both at every epoch (gated by ``[zupt] gate_nis``). The smoother puts a
zero-velocity prior on V and the zero-rate reading on the pose and the gyro half of B
(:func:`gnssacc.factors.zero_rate_factor`, the same model as the EKF's: the earth rate in body
axes needs the yaw, so neither pins the bias at a yaw it does not know) at the node nearest
each epoch (nodes are added where no fix is near, e.g. a stop inside a GNSS outage); a span the
fixes did not vet (:func:`vetted_by_fixes`) is gated there like the EKF's.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numba import njit

from ...core.earth import earth_rate_n
from ...core.recording import ImuData
from ..layout import I_ATT, I_BG, SYM_B, SYM_V, SYM_X, VEL
from ..small_linalg import matmul_into, matvec, skew_into
from .base import AidSpec, EkfAid, Measurement, SmootherAid, zero_jacobian

#: Order at equal times: after the GNSS epoch's updates.
ORDER = 4


@dataclass
class StationaryEpochs:
    """Where and with what the stationary updates happen.

    Attributes
    ----------
    t : ndarray, shape (K,)
        Epochs [s].
    omega_mean_b : ndarray, shape (K, 3)
        Mean raw gyro reading over the block ending at each epoch [rad/s, body].
    omega_var_b : ndarray, shape (K, 3)
        Variance of that mean per axis [(rad/s)^2].
    span : ndarray, shape (K,) of int
        Index of the stationary span each epoch belongs to.
    """

    t: np.ndarray
    omega_mean_b: np.ndarray
    omega_var_b: np.ndarray
    span: np.ndarray

    def __len__(self) -> int:
        return len(self.t)

    @classmethod
    def empty(cls) -> "StationaryEpochs":
        return cls(np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, int))


def _block_means(imu: ImuData, edges: np.ndarray) -> np.ndarray:
    """Mean gyro over the samples stamped in each ``(edges[j], edges[j+1]]``; NaN for an empty
    block.

    Only the samples between the first and last edge are summed (memory in the span, not the run).
    """
    lo, hi = np.searchsorted(imu.t, [edges[0], edges[-1]], side="right")
    c = np.vstack([np.zeros((1, 3)), np.cumsum(imu.omega_ib_b[lo:hi], axis=0)])
    idx = np.searchsorted(imu.t[lo:hi], edges, side="right")
    n = np.diff(idx).astype(float)
    with np.errstate(invalid="ignore", divide="ignore"):
        return (c[idx[1:]] - c[idx[:-1]]) / np.where(n > 0, n, np.nan)[:, None]


def stationary_epochs(
    imu: ImuData, spans, interval_s: float, gyro_psd: np.ndarray
) -> StationaryEpochs:
    """Epochs and gyro block means for the stationary updates.

    Parameters
    ----------
    imu : ImuData
    spans : sequence
        Stationary spans with ``t_start``, ``t_end`` [s] (e.g. ``StationaryReport.spans``).
    interval_s : float
        Spacing of the epochs and length of each gyro block [s].
    gyro_psd : ndarray, shape (3,)
        Configured white gyro noise PSD [rad^2/s]: the floor of each block mean's variance.

    Returns
    -------
    StationaryEpochs
    """
    ts, means, var, which = [], [], [], []
    floor = np.asarray(gyro_psd, float) / interval_s
    for j, sp in enumerate(spans):
        n = int(np.floor((sp.t_end - sp.t_start) / interval_s + 1e-9))
        if n < 1:
            continue
        edges = sp.t_start + interval_s * np.arange(n + 1)
        m = _block_means(imu, edges)
        ok = np.all(np.isfinite(m), axis=1)  # a block inside an IMU gap has no samples
        m, edges = m[ok], np.concatenate([[edges[0]], edges[1:][ok]])
        n = len(m)
        if n < 1:
            continue
        # Scatter of consecutive block means, half the squared difference (insensitive to a slow
        # drift).
        v = 0.5 * np.mean(np.diff(m, axis=0) ** 2, axis=0) if n >= 3 else np.full(3, np.inf)
        v = np.where(np.isfinite(v), np.maximum(v, floor), 4.0 * floor)
        ts.append(edges[1:])
        means.append(m)
        var.append(np.tile(v, (n, 1)))
        which.append(np.full(n, j))
    if not ts:
        return StationaryEpochs.empty()
    return StationaryEpochs(
        np.concatenate(ts), np.vstack(means), np.vstack(var), np.concatenate(which)
    )


def epochs_for(
    run, zupt, gyro_psd: np.ndarray, stationary, t_from: float = -np.inf, t_to: float = np.inf
) -> StationaryEpochs:
    """The stationary epochs of an estimator run: of ``stationary``'s spans (a
    :class:`gnssacc.prepare.stationary.StationaryReport`) when given and ``zupt.enabled``
    (:class:`gnssacc.estimators.settings.ZuptSettings`), else none; ``gyro_psd`` [rad^2/s] floors
    the zero-rate variance. Only the spans that reach into ``t_from`` .. ``t_to`` [s] (a pass's
    start and stop): each span's epochs are its own, so those of the pass are the same (a pass
    over a window of a long run then costs the window, not the run)."""
    if stationary is None or not zupt.enabled:
        return StationaryEpochs.empty()
    keep = [i for i, sp in enumerate(stationary.spans) if sp.t_end >= t_from and sp.t_start <= t_to]
    if len(keep) == len(stationary.spans):
        return stationary_epochs(run.imu, stationary.spans, zupt.interval_s, gyro_psd)
    ep = stationary_epochs(run.imu, [stationary.spans[i] for i in keep], zupt.interval_s, gyro_psd)
    return replace(ep, span=np.asarray(keep, int)[ep.span]) if len(ep) else ep


def zero_velocity(s, sigma_mps: float, gate: float = 0.0) -> Measurement:
    """The vehicle stands still: NED velocity zero within ``sigma_mps`` [m/s]."""
    H = zero_jacobian(s, 3)
    H[:, VEL] = np.eye(3)
    return Measurement("zupt", s.v_n.copy(), H, np.eye(3) * sigma_mps**2, gate)


@njit(cache=True)
def zero_rate_model(R_nb, b_g, omega_mean_b, w_ie_n, n):
    """``dz`` (3,) [rad/s, body] and ``H`` (3, n) of :func:`zero_rate` for the state's ``R_nb``
    and ``b_g`` [rad/s], ``n`` states; compiled (the EKF's per-update path in both of its loops),
    with numpy's arithmetic (:mod:`gnssacc.estimators.small_linalg`: ``R_nb^T`` is a transpose)."""
    Rt = R_nb.T
    w_b = matvec(Rt, w_ie_n, Rt.strides[1] < Rt.strides[0])
    dz = np.empty(3)
    for r in range(3):
        dz[r] = (omega_mean_b[r] - b_g[r]) - w_b[r]
    H = np.zeros((3, n))
    S = np.empty((3, 3))
    skew_into(w_ie_n, S)
    matmul_into(-Rt, S, H, I_ATT)
    for r in range(3):
        H[r, I_BG + r] = 1.0
    return dz, H


def zero_rate(
    s, omega_mean_b: np.ndarray, var_b: np.ndarray, w_ie_n: np.ndarray, gate: float = 0.0
) -> Measurement:
    """The vehicle stands still: the mean raw gyro reading ``omega_mean_b`` [rad/s] over a block
    (variance of that mean ``var_b`` [(rad/s)^2] per axis) is the bias plus the earth rate
    ``w_ie_n`` [rad/s, NED] (the model is :func:`zero_rate_model`)."""
    dz, H = zero_rate_model(s.R_nb, s.b_g, omega_mean_b, w_ie_n, s.P.shape[0])
    return Measurement("zaru", dz, H, np.diag(var_b), gate)


class EkfZupt(EkfAid):
    """Both updates at every stationary epoch (module notes)."""

    order, epoch = ORDER, "stationary"

    def __init__(self, ctx, epochs: StationaryEpochs):
        z = ctx.settings.zupt
        self.ep, self.t = epochs, epochs.t
        self.sigma, self.gate = z.velocity_sigma_mps, z.gate_nis

    def _zaru(self, s, j: int) -> Measurement:
        w_ie = earth_rate_n(s.pos[0])
        return zero_rate(s, self.ep.omega_mean_b[j], self.ep.omega_var_b[j], w_ie, self.gate)

    def models(self, s, j: int) -> list[Measurement]:
        return [zero_velocity(s, self.sigma, self.gate), self._zaru(s, j)]

    def updates(self, s, j: int, stats: dict):
        yield zero_velocity(s, self.sigma, self.gate), True
        yield self._zaru(s, j), True  # at the state the zero-velocity update left

    def compiled(self) -> tuple[str, tuple]:
        """``("stationary", (omega_mean_b, R_rate, R_zero, gate))``: each epoch's mean gyro
        [rad/s, body] and the zero-rate noise (K, 3, 3) [(rad/s)^2], the zero-velocity noise
        (3, 3) [m^2/s^2] and the gate, as :func:`zero_velocity` and :func:`zero_rate` take them."""
        ep = self.ep
        R_rate = np.stack([np.diag(v) for v in ep.omega_var_b]) if len(ep) else np.zeros((0, 3, 3))
        return "stationary", (
            np.ascontiguousarray(ep.omega_mean_b, float),
            np.ascontiguousarray(R_rate, float),
            np.eye(3) * self.sigma**2,
            float(self.gate),
        )


def _ekf(ctx) -> EkfZupt | None:
    t_to = np.inf if ctx.t_stop is None else float(ctx.t_stop)
    z = ctx.settings.zupt
    ep = epochs_for(ctx.run, z, ctx.settings.imu.gyro_psd, ctx.stationary, ctx.t0, t_to)
    return EkfZupt(ctx, ep) if len(ep) else None


def vetted_by_fixes(span, params) -> bool:
    """Whether the fixes vetted a stationary span (``span``: a
    :class:`gnssacc.prepare.stationary.StationarySpan`, ``params`` its detection's
    :class:`~gnssacc.core.stationary_params.StationaryParams`): its GNSS check ran with at least
    ``gnss_min_fixes`` (and two) fixes inside the span.

    A check made from fixes outside the span alone (a span inside a GNSS outage, checked against
    the first fixes after it) has next to no power; such a span is gated like one found on IMU
    evidence alone (:meth:`SmootherZupt.node`; docs/estimators.md, "Stationary spans in an
    outage")."""
    return bool(span.gnss_checked) and span.gnss_n_fixes >= max(int(params.gnss_min_fixes), 2)


def node_epochs_apart(existing: np.ndarray, epochs: np.ndarray, interval: float) -> np.ndarray:
    """The ``epochs`` no epoch of ``existing`` is within half an interval of."""
    if len(epochs) == 0 or len(existing) == 0:
        return epochs
    i = np.clip(np.searchsorted(existing, epochs), 1, len(existing) - 1)
    near = np.minimum(np.abs(existing[i] - epochs), np.abs(existing[i - 1] - epochs))
    return epochs[near > 0.5 * interval]


def attach_epochs(times: np.ndarray, epochs: np.ndarray, interval: float) -> dict:
    """Node index for each epoch (its nearest node within half an interval): ``{node: epoch}``."""
    out = {}
    for j, t in enumerate(epochs):
        i = int(np.clip(np.searchsorted(times, t), 1, len(times) - 1))
        i = i if abs(times[i] - t) <= abs(times[i - 1] - t) else i - 1
        if abs(times[i] - t) <= 0.5 * interval + 1e-9:
            out[i] = j
    return out


class SmootherZupt(SmootherAid):
    """The stationary factors of a smoother run (module notes)."""

    order = 2

    def __init__(self, ctx, epochs: StationaryEpochs):
        import gtsam

        z, st = ctx.settings.zupt, ctx.stationary
        self.stats, self.ep, self.interval_s = ctx.stats, epochs, z.interval_s
        # Per epoch: whether its span was vetted by the fixes.
        self.vetted = np.array([vetted_by_fixes(st.spans[j], st.params) for j in epochs.span], bool)
        self.noise = gtsam.noiseModel.Isotropic.Sigma(3, z.velocity_sigma_mps)
        self.var, self.gate = z.velocity_sigma_mps**2, z.gate_nis
        self.w_ie = earth_rate_n(ctx.run.origin.lat0)

    def node_epochs(self, existing: np.ndarray) -> np.ndarray:
        return node_epochs_apart(existing, self.ep.t, self.interval_s)

    def attach(self, ctx) -> None:
        self.at = attach_epochs(ctx.times, self.ep.t, self.interval_s)

    def node(self, graph, ctx, i: int, t: float, pred) -> None:
        """Zero velocity on V_i and the zero-rate reading of the node's epoch on X_i and B_i's
        gyro part, unless the velocity predicted for the node rejects standing still: its NIS
        against zero above ``[zupt] gate_nis``, the EKF's gate. Only spans the fixes have not vetted
        (:func:`vetted_by_fixes`: found on IMU evidence alone, in a GNSS outage) are gated: they
        may be a constant-speed cruise, and a zero-velocity factor there drags the whole window
        to a stop; the fixes have vetted the others, whose first epochs the gate would wrongly
        refuse while the estimate still carries the braking's last few cm/s."""
        j = self.at.get(i)
        if j is None:
            return
        import gtsam

        if self.gate > 0 and not self.vetted[j]:
            v_pred = pred.v_n
            c_vel = pred.velocity_cov()
            nis = float(v_pred @ np.linalg.solve(c_vel + self.var * np.eye(3), v_pred))
            if not nis <= self.gate:
                self.stats["n_zupt_gated"] += 1
                return
        from ...factors import zero_rate_factor

        graph.add(gtsam.PriorFactorVector(gtsam.symbol(SYM_V, i), np.zeros(3), self.noise))
        # The reading on the gyro half of B with the attitude a variable: the earth rate in body
        # axes needs the yaw, which a bias prior at the predicted yaw would pretend to know.
        graph.add(
            zero_rate_factor(
                gtsam.symbol(SYM_X, i),
                gtsam.symbol(SYM_B, i),
                self.ep.omega_mean_b[j],
                self.ep.omega_var_b[j],
                self.w_ie,
            )
        )
        self.stats["n_zupt_factors"] += 1


def _smoother(ctx) -> SmootherZupt | None:
    ep = epochs_for(ctx.run, ctx.settings.zupt, ctx.settings.imu.gyro_psd, ctx.stationary)
    return SmootherZupt(ctx, ep) if len(ep) else None


AID = AidSpec(
    name="zupt",
    kinds=("zupt", "zaru"),
    ekf=_ekf,
    smoother=_smoother,
    smoother_counts={"n_zupt_factors": 0, "n_zupt_gated": 0},
)
