r"""The non-holonomic constraint: where and when it is applied.

A wheeled or tracked ground vehicle rolling on the ground does not move sideways or vertically:
at its reference point ``l_b`` (body FRD from the IMU: the rear axle centre of a car, the centre
of a skid-steer vehicle; ``[nhc] lever_arm_b_m``) the velocity in the body frame,

    v_ref^b = R_nb^T v_n + omega_eb^b x l_b,    omega_eb^b = omega_ib^b - R_nb^T omega_ie^n,

has zero lateral (y) and vertical (z) components, within ``[nhc] sigma_lateral_mps`` and
``sigma_vertical_mps`` (tyre slip, suspension travel, a residual mounting yaw or pitch times the
speed). The body frame is the IMU's after the configured mounting (``[mounting]``), so its axes
are the vehicle's. The measurement model is :func:`gnssacc.estimators.measurements.non_holonomic`
(EKF) and :func:`gnssacc.factors.nhc_factor` (smoother); both share
:func:`gnssacc.estimators.measurements.vehicle_velocity`.

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
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Decisions of :func:`decide`.
APPLY, REST, TURN = 0, 1, 2
#: How many of its own 1-sigma the filter's speed is taken wide.
K_SIGMA = 3.0
#: The ``stats`` key counting each decision not to apply the constraint.
SKIPPED = {REST: "n_nhc_skipped_rest", TURN: "n_nhc_skipped_turn"}


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


def held_samples(imu_t: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Index of the IMU sample held at each time ``t`` (sample ``k`` holds over ``(t[k-1], t[k]]``)."""
    return np.minimum(np.searchsorted(imu_t, t, side="left"), len(imu_t) - 1)


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
