r"""The non-holonomic constraint: where and when it is applied.

A wheeled or tracked ground vehicle rolling on the ground does not move sideways or vertically:
at its reference point ``l_b`` (body FRD from the IMU: the rear axle centre of a car, the centre
of a skid-steer vehicle; ``[nhc] lever_arm_b_m``) the velocity in the body frame,

    v_ref^b = R_nb^T v_n + omega_eb^b x l_b,    omega_eb^b = omega_ib^b - R_nb^T omega_ie^n,

has zero lateral (y) and vertical (z) components, within ``[nhc] sigma_lateral_mps`` and
``sigma_vertical_mps`` (tyre slip, suspension travel, a residual mounting yaw or pitch times the
speed). The body frame is the IMU's after the configured mounting (``[mounting]``), so its axes
are the vehicle's. The measurement model is :func:`non_holonomic` (EKF: ``dz = [v_y, v_z]`` of
:func:`gnssacc.estimators.aids.vehicle.vehicle_velocity`, ``H`` its rows 2 and 3) and
:func:`gnssacc.factors.nhc_factor` on (X, V, B) (smoother).

When it is applied
------------------
Epochs fall every ``[nhc] interval_s`` from the start. At each, :func:`decide` says, from the data:

* **at rest** (skipped): the epoch lies in a stationary span of the prepared recording
  (:mod:`gnssacc.prepare.stationary`); the zero-velocity updates hold the vehicle there, and a
  vehicle at rest says nothing of its heading through its velocity.
* **turning on the spot** (skipped): a skid-steer vehicle pivots about a centre whose place
  along the vehicle is not known (it moves with the load on the tracks); a centre ``d`` from
  the reference point moves that point sideways at ``|omega_z| d``. With ``d`` up to
  ``[nhc] pivot_offset_m``, the constraint is skipped when that side slip exceeds both the
  lateral slip the constraint allows, ``sigma_lateral`` (one sigma, not three: a turn's slip
  keeps its sign for the whole turn, so it is a bias, not noise that averages out), and the
  speed the vehicle demonstrably rolls at, ``max(|v_x| - 3 sigma_vx, 0)`` (the filter's
  forward speed less three of its own 1-sigma, so that a drifting filter in an outage cannot
  make a pivot look like a drive). So a slow yaw (``|omega_z| d`` within ``sigma_lateral``) is
  always constrained, and so is a turn rolled faster than the pivot would move the reference
  point: a car's corner at speed rolls, a pivot at standstill does not.
* otherwise it is **applied**, backwards as forwards: the constraint says nothing of the sign
  of the forward speed, so reversing needs no test of its own; the passage through zero speed
  with a yaw rate is caught by the turn test (the speed's lower bound is zero there).

The yaw rate is the bias-corrected gyro's z (body down) at the epoch, the IMU sample held there.
The counts of each decision are in the estimators' ``stats`` (``n_nhc_updates`` or
``n_nhc_factors``, ``n_nhc_skipped_rest``, ``n_nhc_skipped_turn``).

The smoother
------------
The constraint's epochs are given to the nodes nearest them, within half an interval, one epoch
per node: the smoother then applies the constraint as often as the EKF does, whatever the node
rate (a 10 Hz receiver's nodes do not get ten constraints a second). At such a node the decision
is taken on the node's prediction (the preintegrated state from the previous node's estimate):
its forward speed at the reference point, that speed's 1-sigma from the predicted velocity
covariance (the previous node's marginal plus the preintegration's; the attitude's share
neglected), and the bias-corrected gyro held at the node's time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from ...core.earth import earth_rate_n
from ...core.rotations import cross3
from ..layout import SYM_B, SYM_V, SYM_X
from .base import AidSpec, EkfAid, Measurement, SmootherAid, nearest_nodes, row_sigma
from .vehicle import K_SIGMA, held_samples, vehicle_axes, vehicle_velocity

#: Decisions of :func:`decide`.
APPLY, REST, TURN = 0, 1, 2
#: The ``stats`` key counting each decision not to apply the constraint.
SKIPPED = {REST: "n_nhc_skipped_rest", TURN: "n_nhc_skipped_turn"}
#: Order at equal times: first (a GNSS epoch's prior holds it).
ORDER = 0


def counts() -> dict:
    """Zero counts of the decisions not to apply the constraint (``stats`` keys)."""
    return dict.fromkeys(SKIPPED.values(), 0)


@dataclass
class NhcEpochs:
    """The constraint's epochs of a run.

    Attributes
    ----------
    t : ndarray (K,)
        Epochs [s].
    omega_b : ndarray (K, 3)
        Raw gyro reading held at each epoch [rad/s, body].
    rest : ndarray (K,) of bool
        Whether the epoch lies in a stationary span.
    """

    t: np.ndarray
    omega_b: np.ndarray
    rest: np.ndarray

    def __len__(self) -> int:
        return len(self.t)

    @classmethod
    def empty(cls) -> "NhcEpochs":
        return cls(np.zeros(0), np.zeros((0, 3)), np.zeros(0, bool))


def nhc_epochs(imu, t0: float, t_end: float, interval_s: float, stationary=None) -> NhcEpochs:
    """Epochs every ``interval_s`` [s] after ``t0`` up to ``t_end`` [s], their gyro readings
    (``imu``: :class:`gnssacc.core.recording.ImuData`) and whether each lies in a stationary span
    of ``stationary`` (a :class:`gnssacc.prepare.stationary.StationaryReport` or ``None``)."""
    n = int(np.floor((t_end - t0) / interval_s + 1e-9))
    if n < 1:
        return NhcEpochs.empty()
    t = t0 + interval_s * np.arange(1, n + 1)
    rest = stationary.mask(t) if stationary is not None else np.zeros(n, bool)
    return NhcEpochs(t, np.asarray(imu.omega_ib_b)[held_samples(imu.t, t)], rest)


def epochs_for(run, nhc, t0: float, stationary) -> NhcEpochs:
    """The constraint's epochs of an estimator run from ``t0`` [s] (``nhc``:
    :class:`gnssacc.estimators.settings.NhcSettings`); none when it is off."""
    if not nhc.enabled:
        return NhcEpochs.empty()
    return nhc_epochs(run.imu, t0, run.t_end, nhc.interval_s, stationary)


def decide(
    rest: bool,
    v_x: float,
    sigma_vx: float,
    yaw_rate: float,
    sigma_lateral: float,
    pivot_offset_m: float,
) -> int:
    """Whether the constraint applies at an epoch (see the module docstring).

    Parameters
    ----------
    rest : bool
        The epoch lies in a stationary span.
    v_x : float
        The estimator's forward speed at the reference point [m/s].
    sigma_vx : float
        Its 1-sigma [m/s].
    yaw_rate : float
        Bias-corrected gyro z (body down) [rad/s].
    sigma_lateral : float
        The constraint's lateral 1-sigma [m/s].
    pivot_offset_m : float
        How far along the vehicle a turn's centre on the spot may lie [m].

    Returns
    -------
    int
        :data:`APPLY`, :data:`REST` or :data:`TURN`.
    """
    if rest:
        return REST
    slip = abs(yaw_rate) * pivot_offset_m
    rolling = max(abs(v_x) - K_SIGMA * sigma_vx, 0.0)
    if slip > sigma_lateral and slip > rolling:
        return TURN
    return APPLY


#: :func:`decide` compiled, for the EKF's compiled event loop (Python calls the function itself).
decide_compiled = njit(cache=True)(decide)


def nhc_measurement(
    v_b: np.ndarray, H_v: np.ndarray, sigma_mps: np.ndarray, R: np.ndarray | None = None
) -> Measurement:
    """:func:`non_holonomic` from the vehicle velocity ``v_b`` and its Jacobian ``H_v`` of
    :func:`gnssacc.estimators.aids.vehicle.vehicle_velocity` (for a caller that looked at the
    forward speed first); ``R``: ``diag(sigma_mps^2)`` when the caller made it once."""
    if R is None:
        R = np.diag(np.asarray(sigma_mps, float) ** 2)
    return Measurement("nhc", v_b[1:3], H_v[1:3], R)


def non_holonomic(
    s,
    omega_meas_b: np.ndarray,
    lever_b: np.ndarray,
    w_ie_n: np.ndarray,
    sigma_mps: np.ndarray,
    R_vb: np.ndarray | None = None,
) -> Measurement:
    """Zero lateral and vertical velocity at the vehicle's reference point ``lever_b`` [m, body],
    in the vehicle's axes (``R_vb``), 1-sigma ``sigma_mps`` [m/s] (lateral, vertical);
    ``omega_meas_b`` the raw gyro [rad/s] at the epoch, ``w_ie_n`` the earth rate [rad/s, NED]."""
    return nhc_measurement(*vehicle_velocity(s, omega_meas_b, lever_b, w_ie_n, R_vb), sigma_mps)


class EkfNhc(EkfAid):
    """The constraint at its epochs, unless :func:`decide` says not (counted in ``stats``)."""

    order, epoch = ORDER, "nhc"

    def __init__(self, ctx, epochs: NhcEpochs):
        self.ep, self.t, self.cfg = epochs, epochs.t, ctx.settings.nhc
        self.R = np.diag(np.asarray(self.cfg.sigma_mps, float) ** 2)  # one for every update

    def models(self, s, j: int) -> list[Measurement]:
        cfg = self.cfg
        w_ie = earth_rate_n(s.pos[0])
        return [
            non_holonomic(s, self.ep.omega_b[j], cfg.lever_arm_b, w_ie, cfg.sigma_mps, cfg.R_vb)
        ]

    def updates(self, s, j: int, stats: dict):
        ep, nhc = self.ep, self.cfg
        if ep.rest[j]:  # decided without the state (decide's first test)
            stats[SKIPPED[REST]] += 1
            return
        w_ie = earth_rate_n(s.pos[0])
        v_b, H = vehicle_velocity(s, ep.omega_b[j], nhc.lever_arm_b, w_ie, nhc.R_vb)
        yaw_rate = float(ep.omega_b[j, 2] - s.b_g[2] - s.R_nb[:, 2] @ w_ie)  # relative to the earth
        why = decide(
            bool(ep.rest[j]),
            float(v_b[0]),
            row_sigma(s.P, H[0]),
            yaw_rate,
            float(nhc.sigma_mps[0]),
            nhc.pivot_offset_m,
        )
        if why != APPLY:
            stats[SKIPPED[why]] += 1
            return
        yield nhc_measurement(v_b, H, nhc.sigma_mps, self.R), True

    def compiled(self) -> tuple[str, tuple]:
        """``("nhc", (omega_b, rest, lever, R_vb, vb_rows, sigma_lateral, pivot_offset, R))``:
        the epochs' gyro readings [rad/s] and rest flags, the reference point [m, body], the
        vehicle's axes (:func:`gnssacc.estimators.aids.vehicle.vehicle_axes`), the lateral sigma
        [m/s], the pivot offset [m] and the constraint's noise covariance [m^2/s^2]."""
        cfg, ep = self.cfg, self.ep
        return "nhc", (
            np.ascontiguousarray(ep.omega_b, float),
            np.ascontiguousarray(ep.rest, bool),
            np.ascontiguousarray(cfg.lever_arm_b, float),
            *vehicle_axes(cfg.R_vb),
            float(cfg.sigma_mps[0]),
            float(cfg.pivot_offset_m),
            np.ascontiguousarray(self.R, float),
        )


def _ekf(ctx) -> EkfNhc | None:
    ep = epochs_for(ctx.run, ctx.settings.nhc, ctx.t0, ctx.stationary)
    return EkfNhc(ctx, ep) if len(ep) else None


class SmootherNhc(SmootherAid):
    """The constraint's factors on the nodes nearest its epochs (module notes)."""

    order = 3

    def __init__(self, ctx):
        self.ctx_run, self.stationary = ctx.run, ctx.stationary
        self.cfg, self.stats = ctx.settings.nhc, ctx.stats
        self.w_ie = earth_rate_n(ctx.run.origin.lat0)

    def attach(self, ctx) -> None:
        run, times = self.ctx_run, ctx.times
        epochs = nhc_epochs(run.imu, float(times[0]), float(times[-1]), self.cfg.interval_s)
        nodes = nearest_nodes(times, epochs.t, self.cfg.interval_s)
        node_t = times[nodes]
        st = self.stationary
        rest = st.mask(node_t) if st is not None else np.zeros(len(nodes), bool)
        self.rest = dict(zip(nodes.tolist(), rest.tolist(), strict=True))
        omega = np.asarray(run.imu.omega_ib_b)[held_samples(run.imu.t, node_t)]
        self.omega_b = dict(zip(nodes.tolist(), omega, strict=True))

    def node(self, graph, ctx, i: int, t: float, pred) -> None:
        """The constraint on node ``i`` when it has an epoch and :func:`decide` applies it, on the
        node's predicted attitude, velocity and velocity covariance and the gyro bias it was
        predicted with."""
        if pred.start or i not in self.omega_b:
            return
        import gtsam

        from ...factors import nhc_factor

        cfg, omega, R_nb = self.cfg, self.omega_b[i], pred.R_nb
        c_vel = pred.velocity_cov()
        w_b = omega - pred.bias.gyroscope() - R_nb.T @ self.w_ie
        v_b = R_nb.T @ pred.v_n + cross3(w_b, cfg.lever_arm_b)
        v_b = v_b if cfg.R_vb is None else cfg.R_vb @ v_b
        fwd = R_nb @ cfg.forward_b  # the vehicle's forward axis, NED
        why = decide(
            self.rest[i],
            float(v_b[0]),
            math.sqrt(max(float(fwd @ c_vel @ fwd), 0.0)),
            float(w_b[2]),
            float(cfg.sigma_mps[0]),
            cfg.pivot_offset_m,
        )
        if why != APPLY:
            self.stats[SKIPPED[why]] += 1
            return
        keys = (gtsam.symbol(c, i) for c in (SYM_X, SYM_V, SYM_B))
        graph.add(nhc_factor(*keys, omega, cfg.lever_arm_b, self.w_ie, cfg.sigma_mps, cfg.R_vb))
        self.stats["n_nhc_factors"] += 1


def _smoother(ctx) -> SmootherNhc | None:
    return SmootherNhc(ctx) if ctx.settings.nhc.enabled else None


SIGMAS = (("nhc", "sigma_lateral_mps"), ("nhc", "sigma_vertical_mps"))
#: The vehicle's axes relative to the body's, searched additively (steps of 1.5 deg).
OFFSETS = {("nhc", "pitch_offset_deg"): 1.5, ("nhc", "yaw_offset_deg"): 1.5}

AID = AidSpec(
    name="nhc",
    kinds=("nhc",),
    ekf=_ekf,
    smoother=_smoother,
    counts=counts(),
    smoother_counts={"n_nhc_factors": 0, **counts()},
    noise_keys=SIGMAS + tuple(OFFSETS),
    stage="vehicle",
    enabled_key=("nhc", "enabled"),
    floored_keys=SIGMAS,
    floor_key=("zupt", "velocity_sigma_mps"),
    inflated_keys=SIGMAS,
    additive_keys=OFFSETS,
)
