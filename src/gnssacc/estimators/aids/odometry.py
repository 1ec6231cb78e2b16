r"""Wheel odometry as a measurement: which samples are used and when one is refused.

The drive controller reports the forward speed of the odometry's reference point ``l_b``
(``[odometry] lever_arm_b_m``, body FRD from the IMU: a car's rear axle centre) along the vehicle
x axis, read through the wheel radius, so with a scale-factor error ``k``::

    v~ = (1 + k) v_x + noise,    v_x = (R_nb^T v_n + omega_eb^b x l_b)_x

(:func:`odometry`: ``dz = (1 + k_est) v_x - v~``, ``H = [(1 + k_est) H_x, ..., v_x]``, ``H_x`` the
first row of :func:`gnssacc.estimators.aids.vehicle.vehicle_velocity`'s Jacobian and ``v_x`` in
the scale state's column; :func:`gnssacc.factors.odometry_factor`). ``k`` is a state of the
estimators (``odometry_scale``, :mod:`gnssacc.estimators.layout`), a first-order Gauss-Markov
process of 1-sigma ``[odometry] scale_sigma`` and correlation time ``scale_tau_s`` (tyre
pressure, wear and load change slowly);
the speed's 1-sigma is ``[odometry] speed_sigma_mps`` (identified by the noise tuner), or a
sample's own stated sigma when larger.

At most one sample per ``[odometry] interval_s`` is used (the first of each interval: samples
are not averaged, since the speed changes within an interval). A sample is refused when its
sign contradicts the estimator's: the estimator's forward speed and the odometry's both differ
from zero by more than three of their 1-sigma and have opposite signs (an odometry that reports
an unsigned speed while the vehicle reverses, or a reversed wheel-encoder sign); counted as
``n_odo_skipped_sign``. A speed near zero is used as it is: at standstill the odometry's zero is
a measurement like any other.

The smoother uses the sample nearest each node within half the odometry's interval (``[odometry]
interval_s``, at least the samples' own spacing), one per node, as a factor on the node's pose,
velocity, bias and its scale factor ``K_i``. The scale factor is a variable of every node, linked
node to node by the same Gauss-Markov model, so the window stays a chain of nodes. Counts:
``n_odo_factors``, ``n_odo_skipped_sign``; the scale factor at the end (the EKF's, the last
node's online estimate) and its 1-sigma: ``odometry_scale``, ``odometry_scale_sigma``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from ...core.earth import earth_rate_n
from ...core.rotations import cross3
from ..layout import ODOMETRY_SCALE, SYM_B, SYM_K, SYM_V, SYM_X, MarkovBlock
from .base import AidSpec, EkfAid, Measurement, SmootherAid, nearest, nearest_nodes, row_sigma
from .vehicle import K_SIGMA, held_samples, vehicle_axes, vehicle_model

#: Decisions of :func:`decide`.
APPLY, SIGN = 0, 1
#: The ``stats`` key counting each decision not to use a sample.
SKIPPED = {SIGN: "n_odo_skipped_sign"}
#: Order at equal times: after the constraint, before a GNSS epoch.
ORDER = 1


def counts() -> dict:
    """Zero counts of the decisions not to use a sample (``stats`` keys)."""
    return dict.fromkeys(SKIPPED.values(), 0)


@dataclass
class OdometryEpochs:
    """The odometry samples an estimator uses.

    Attributes
    ----------
    t : ndarray (K,)
        Sample times [s].
    v : ndarray (K,)
        Forward speed read [m/s].
    sigma : ndarray (K,)
        Its 1-sigma [m/s].
    omega_b : ndarray (K, 3)
        Raw gyro reading held at each sample [rad/s, body].
    """

    t: np.ndarray
    v: np.ndarray
    sigma: np.ndarray
    omega_b: np.ndarray

    def __len__(self) -> int:
        return len(self.t)

    @classmethod
    def empty(cls) -> "OdometryEpochs":
        return cls(np.zeros(0), np.zeros(0), np.zeros(0), np.zeros((0, 3)))


def odometry_epochs(
    imu, odo, t0: float, t_end: float, interval_s: float, sigma_mps: float
) -> OdometryEpochs:
    """The samples of ``odo`` (:class:`gnssacc.core.recording.WheelOdometry`) in ``(t0, t_end]``
    [s],
    at most one per ``interval_s`` [s], with the 1-sigma ``max(sigma_mps, stated)`` [m/s] and
    the gyro reading held at each (``imu``: :class:`gnssacc.core.recording.ImuData`)."""
    t = np.asarray(odo.t, float)
    keep = np.flatnonzero((t > t0) & (t <= t_end) & np.isfinite(odo.v_forward))
    if interval_s > 0 and len(keep):
        _, first = np.unique(np.floor((t[keep] - t0) / interval_s), return_index=True)
        keep = keep[first]
    stated = getattr(odo, "sigma_v", None)
    sigma = np.full(len(keep), float(sigma_mps))
    if stated is not None:
        sigma = np.maximum(sigma, np.nan_to_num(np.asarray(stated, float)[keep]))
    return OdometryEpochs(
        t[keep],
        np.asarray(odo.v_forward, float)[keep],
        sigma,
        np.asarray(imu.omega_ib_b)[held_samples(imu.t, t[keep])],
    )


def epochs_for(run, odometry, t0: float) -> OdometryEpochs:
    """The odometry samples of an estimator run from ``t0`` [s] (``odometry``:
    :class:`gnssacc.estimators.settings.OdometrySettings`); none when it is off or the run has no
    odometry."""
    odo = getattr(run, "odometry", None)
    if odo is None or not odometry.enabled or len(odo.t) == 0:
        return OdometryEpochs.empty()
    return odometry_epochs(
        run.imu, odo, t0, run.t_end, odometry.interval_s, odometry.speed_sigma_mps
    )


def decide(v_odo: float, sigma_odo: float, v_pred: float, sigma_pred: float) -> int:
    """:data:`SIGN` when the odometry's speed ``v_odo`` (1-sigma ``sigma_odo``) and the estimator's
    prediction of it ``v_pred`` (1-sigma ``sigma_pred``) [m/s] are both clearly non-zero and of
    opposite signs, else :data:`APPLY`."""
    if (
        v_odo * v_pred < 0
        and abs(v_odo) > K_SIGMA * sigma_odo
        and abs(v_pred) > K_SIGMA * sigma_pred
    ):
        return SIGN
    return APPLY


#: :func:`decide` compiled (the EKF's compiled event loop).
decide_compiled = njit(cache=True)(decide)


def scale_states(settings) -> tuple[MarkovBlock, ...]:
    """The scale-factor state of ``settings`` (either estimator's)."""
    o = settings.odometry
    return (MarkovBlock(ODOMETRY_SCALE, np.array([o.scale_tau_s]), np.array([o.scale_sigma])),)


@njit(cache=True)
def odometry_model(
    R_nb, v_n, b_g, omega_meas_b, lever_b, w_ie_n, R_vb, vb_rows, scale, i_scale, v_odo, n
):
    """``dz`` (1,) [m/s] and ``H`` (1, n) of :func:`odometry` for the state's ``R_nb``, ``v_n``
    [m/s, NED], ``b_g`` [rad/s], its scale-factor error ``scale`` (state ``i_scale``) and ``n``
    states; ``R_vb``, ``vb_rows`` as :func:`gnssacc.estimators.aids.vehicle.vehicle_model` takes
    them. Compiled (the EKF's per-update path in both of its loops), with numpy's arithmetic."""
    v_b, H = vehicle_model(R_nb, v_n, b_g, omega_meas_b, lever_b, w_ie_n, R_vb, vb_rows, n)
    k = 1.0 + scale
    H_x = np.empty((1, n))
    for c in range(n):
        H_x[0, c] = H[0, c] * k
    H_x[0, i_scale] = v_b[0]
    dz = np.empty(1)
    dz[0] = k * v_b[0] - v_odo
    return dz, H_x


def odometry(
    s,
    v_odo: float,
    sigma_mps: float,
    omega_meas_b: np.ndarray,
    lever_b: np.ndarray,
    w_ie_n: np.ndarray,
    R_vb: np.ndarray | None = None,
) -> Measurement:
    """Wheel odometry's forward speed ``v_odo`` [m/s] (1-sigma ``sigma_mps``) of the point
    ``lever_b`` [m, body] along the vehicle's x axis (``R_vb``: body to vehicle axes), read with
    the scale factor of the state's ``odometry_scale`` (module notes; the model is
    :func:`odometry_model`)."""
    R, rows = vehicle_axes(R_vb)
    dz, H_x = odometry_model(
        s.R_nb, s.v_n, s.b_g, omega_meas_b, lever_b, w_ie_n, R, rows, s.scale, s.i_scale,
        float(v_odo), s.P.shape[0],
    )  # fmt: skip
    return Measurement("odo", dz, H_x, np.array([[sigma_mps**2]]))


class EkfOdometry(EkfAid):
    """The samples in use, unless :func:`decide` refuses one (counted in ``stats``)."""

    order, epoch = ORDER, "odometry"

    def __init__(self, ctx, epochs: OdometryEpochs):
        self.ep, self.t = epochs, epochs.t
        self.cfg, self.R_vb = ctx.settings.odometry, ctx.settings.nhc.R_vb
        self.states = scale_states(ctx.settings)

    def models(self, s, j: int) -> list[Measurement]:
        ep = self.ep
        w_ie = earth_rate_n(s.pos[0])
        return [
            odometry(s, ep.v[j], ep.sigma[j], ep.omega_b[j], self.cfg.lever_arm_b, w_ie, self.R_vb)
        ]

    def updates(self, s, j: int, stats: dict):
        ep = self.ep
        (m,) = self.models(s, j)
        why = decide(
            float(ep.v[j]), float(ep.sigma[j]), float(m.dz[0] + ep.v[j]), row_sigma(s.P, m.H[0])
        )
        if why != APPLY:
            stats[SKIPPED[why]] += 1
            return
        yield m, True

    def compiled(self) -> tuple[str, tuple]:
        """``("odometry", (v, sigma, omega_b, lever, R_vb, vb_rows, R))``: the samples' speeds and
        1-sigmas [m/s], the gyro held at each [rad/s], the reference point [m, body], the
        vehicle's axes (:func:`gnssacc.estimators.aids.vehicle.vehicle_axes`) and each sample's
        noise (K, 1, 1) [m^2/s^2] as :func:`odometry` takes it."""
        ep = self.ep
        return "odometry", (
            np.ascontiguousarray(ep.v, float),
            np.ascontiguousarray(ep.sigma, float),
            np.ascontiguousarray(ep.omega_b, float),
            np.ascontiguousarray(self.cfg.lever_arm_b, float),
            *vehicle_axes(self.R_vb),
            np.array([[[x**2]] for x in np.asarray(ep.sigma, float)]).reshape(-1, 1, 1),
        )

    def final_stats(self, s, stats: dict) -> None:
        """The scale factor at the end, and its 1-sigma."""
        stats["odometry_scale"] = s.scale
        stats["odometry_scale_sigma"] = math.sqrt(s.P[s.i_scale, s.i_scale])


def _ekf(ctx) -> EkfOdometry | None:
    ep = epochs_for(ctx.run, ctx.settings.odometry, ctx.t0)
    return EkfOdometry(ctx, ep) if len(ep) else None


class SmootherOdometry(SmootherAid):
    """The odometry's factors and the nodes' scale factors (module notes)."""

    order = 4

    def __init__(self, ctx, epochs: OdometryEpochs):
        self.run, self.ep, self.stats = ctx.run, epochs, ctx.stats
        self.cfg = ctx.settings.odometry
        self.R_vb, self.forward_b = ctx.settings.nhc.R_vb, ctx.settings.nhc.forward_b
        self.states = scale_states(ctx.settings)
        self.w_ie = earth_rate_n(ctx.run.origin.lat0)
        ctx.stats.update(n_odo_factors=0, **counts())

    def attach(self, ctx) -> None:
        times, ep, run = ctx.times, self.ep, self.run
        spacing = float(np.median(np.diff(ep.t))) if len(ep) > 1 else self.cfg.interval_s
        reach = max(self.cfg.interval_s, spacing)
        nodes = nearest_nodes(times, ep.t, reach)
        self.sample = dict(zip(nodes.tolist(), nearest(ep.t, times[nodes]).tolist(), strict=True))
        omega = np.asarray(run.imu.omega_ib_b)[held_samples(run.imu.t, times[nodes])]
        self.omega_b = dict(zip(nodes.tolist(), omega, strict=True))

    def node(self, graph, ctx, i: int, t: float, pred) -> None:
        """The odometry factor of node ``i`` unless its sample's sign contradicts the node's
        prediction (with the scale factor it was predicted with)."""
        if pred.start or i not in self.sample:
            return
        import gtsam

        from ...factors import odometry_factor

        j, cfg, omega, R_nb = self.sample[i], self.cfg, self.omega_b[i], pred.R_nb
        k = float(pred.markov[ODOMETRY_SCALE][0])
        c_vel = pred.velocity_cov()
        w_b = omega - pred.bias.gyroscope() - R_nb.T @ self.w_ie
        fwd = R_nb @ self.forward_b  # the vehicle's forward axis, NED
        v_x = float(fwd @ pred.v_n + self.forward_b @ cross3(w_b, cfg.lever_arm_b))
        sigma_pred = (1.0 + k) * math.sqrt(max(float(fwd @ c_vel @ fwd), 0.0))
        why = decide(float(self.ep.v[j]), float(self.ep.sigma[j]), (1.0 + k) * v_x, sigma_pred)
        if why != APPLY:
            self.stats[SKIPPED[why]] += 1
            return
        graph.add(
            odometry_factor(
                *(gtsam.symbol(c, i) for c in (SYM_X, SYM_V, SYM_B, SYM_K)),
                float(self.ep.v[j]),
                omega,
                cfg.lever_arm_b,
                self.w_ie,
                float(self.ep.sigma[j]),
                self.R_vb,
            )
        )
        self.stats["n_odo_factors"] += 1

    def final_stats(self, ctx, stats: dict) -> None:
        """The scale factor of the last node with an online estimate and its 1-sigma."""
        k, var = ctx.last_online(ODOMETRY_SCALE)
        if k is not None:
            stats["odometry_scale"] = float(k[0])
            stats["odometry_scale_sigma"] = float(np.sqrt(max(var[0, 0], 0.0)))


def _smoother(ctx) -> SmootherOdometry | None:
    ep = epochs_for(ctx.run, ctx.settings.odometry, float(ctx.init.t))
    return SmootherOdometry(ctx, ep) if len(ep) else None


def _in_use(run, cfg) -> bool:
    odo = getattr(run, "odometry", None)
    return odo is not None and len(odo.t) > 0


AID = AidSpec(
    name="odometry",
    kinds=("odo",),
    ekf=_ekf,
    smoother=_smoother,
    counts=counts(),
    noise_keys=(("odometry", "speed_sigma_mps"),),
    stage="vehicle",
    enabled_key=("odometry", "enabled"),
    inflated_keys=(("odometry", "speed_sigma_mps"),),
    in_use=_in_use,
)
