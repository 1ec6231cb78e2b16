r"""Simulated wheel odometry: the forward speed and yaw rate a drive controller reports, with a
per-run scale-factor error, white noise and wheel slip.

Model (per sample ``k``, true signed speed ``v`` along body x [m/s], its rate ``a`` [m/s^2],
true turn rate ``w`` about the body down axis [rad/s], ``g`` the standard gravity)::

    v_odo = (1 + s) (1 + a / (C g)) v + e_turn + n_v
    w_odo = (1 + s) chi w + n_w

``s``
    Scale-factor error of the wheel radius (tyre pressure, wear, load), drawn once per run from
    N(0, :data:`SCALE_SIGMA`^2): what an estimator's scale-factor state should find.
``1 + a / (C g)``
    Longitudinal slip: a driven wheel turns faster than the ground passes under it while
    accelerating and slower while braking, by a slip ratio about ``a / (C g)`` with the
    normalised longitudinal tyre stiffness ``C`` (:data:`SLIP_STIFFNESS`; 2 % at 0.3 g).
``chi``, ``e_turn``
    Skid-steer vehicles (tracked or wheeled UGVs, ``kind="skid"``) turn by dragging their wheels
    sideways: the yaw rate from the wheel-speed difference over-reads by the track's
    instantaneous-centre-of-rotation factor ``chi`` (drawn per run, U(:data:`SKID_CHI`)), and the
    forward speed (the mean of both sides) gets a slip error ``e_turn`` that grows with the wheel
    speeds of the turn, ``|w| B / 2`` (B the track width, :data:`SKID_TRACK_M`): a Gauss-Markov
    error of 1-sigma :data:`SKID_TURN_SLIP` times that speed, correlated over
    :data:`SKID_SLIP_TAU_S`. Largest in turns on the spot. Cars (``kind="car"``) have ``chi = 1``
    (a differential's wheel speeds give the rear axle's turn rate) and no ``e_turn``.
``n_v``, ``n_w``
    White noise, 1-sigma :data:`NOISE_V_MPS` and :data:`NOISE_W_RADPS` (encoder quantisation),
    which the samples also state as their sigmas.

Every draw comes from the stream ``numpy.random.default_rng([seed, 4])``, independent of the IMU
errors' and the GNSS noise's, so asking for odometry leaves the rest of a run unchanged.
"""

from __future__ import annotations

import numpy as np

from ..core.recording import WheelOdometry

STANDARD_GRAVITY = 9.80665
#: 1-sigma of the per-run wheel-radius scale factor error (dimensionless).
SCALE_SIGMA = 0.01
#: Normalised longitudinal tyre stiffness (slip ratio = a / (C g)).
SLIP_STIFFNESS = 15.0
#: Range of the skid-steer yaw over-read factor (instantaneous centres of rotation outside the tracks).
SKID_CHI = (1.3, 1.9)
#: Skid-steer track width [m].
SKID_TRACK_M = 0.6
#: 1-sigma of the skid-steer turn slip as a fraction of the turn's wheel speed |w| B / 2.
SKID_TURN_SLIP = 0.3
#: Correlation time of the skid-steer turn slip [s].
SKID_SLIP_TAU_S = 0.5
#: White noise of the forward speed [m/s] and of the yaw rate [rad/s].
NOISE_V_MPS = 0.02
NOISE_W_RADPS = 0.005
#: Vehicle kinds: skid steer for the UGV scenarios, a car otherwise.
SKID_SCENARIOS = ("ugv", "ugv-slow")
KINDS = ("car", "skid")


def odometry_kind(scenario_name: str) -> str:
    """``"skid"`` for the UGV scenarios, ``"car"`` for the others."""
    return "skid" if scenario_name in SKID_SCENARIOS else "car"


def simulate_odometry(
    t: np.ndarray,
    speed: np.ndarray,
    accel: np.ndarray,
    yaw_rate_b: np.ndarray,
    kind: str,
    seed: int,
) -> tuple[WheelOdometry, dict]:
    """Wheel odometry at times ``t`` from the true kinematics there (model in the module docstring).

    Parameters
    ----------
    t : ndarray, shape (K,)
        Sample times [s].
    speed, accel : ndarray, shape (K,)
        True signed speed along body x [m/s] and its rate [m/s^2].
    yaw_rate_b : ndarray, shape (K,)
        True turn rate about the body down axis [rad/s] (relative to the ground).
    kind : {"car", "skid"}
    seed : int

    Returns
    -------
    WheelOdometry
        With constant stated sigmas (the white noise's), ``frame`` naming the simulator.
    dict
        The per-run draws and model constants: ``scale_factor`` (``s``), ``yaw_factor``
        (``(1 + s) chi``), ``chi``, ``kind``, ``slip_stiffness``, ``noise_v_mps``, ``noise_w_radps``.
    """
    if kind not in KINDS:
        raise ValueError(f"unknown odometry kind {kind!r} (known: {', '.join(KINDS)})")
    rng = np.random.default_rng([seed, 4])
    s = float(rng.normal(0.0, SCALE_SIGMA))
    chi = float(rng.uniform(*SKID_CHI)) if kind == "skid" else 1.0
    n = len(t)
    v = (1.0 + s) * (1.0 + accel / (SLIP_STIFFNESS * STANDARD_GRAVITY)) * speed
    if kind == "skid":
        v = v + SKID_TURN_SLIP * np.abs(yaw_rate_b) * SKID_TRACK_M / 2.0 * _gauss_markov(
            t, SKID_SLIP_TAU_S, rng
        )
    v = v + rng.normal(0.0, NOISE_V_MPS, n)
    w = (1.0 + s) * chi * yaw_rate_b + rng.normal(0.0, NOISE_W_RADPS, n)
    odo = WheelOdometry(
        np.asarray(t, float).copy(),
        v,
        w,
        np.full(n, NOISE_V_MPS),
        np.full(n, NOISE_W_RADPS),
        frame=f"simulator ({kind})",
    )
    draws = {
        "kind": kind,
        "scale_factor": s,
        "chi": chi,
        "yaw_factor": (1.0 + s) * chi,
        "slip_stiffness": SLIP_STIFFNESS,
        "noise_v_mps": NOISE_V_MPS,
        "noise_w_radps": NOISE_W_RADPS,
    }
    return odo, draws


def _gauss_markov(t: np.ndarray, tau_s: float, rng: np.random.Generator) -> np.ndarray:
    """A unit-variance first-order Gauss-Markov sequence at times ``t`` (exact discretisation)."""
    out = np.empty(len(t))
    drive = rng.standard_normal(len(t))
    a = np.exp(-np.diff(t, prepend=t[0]) / tau_s)
    x = drive[0]
    for k in range(len(t)):
        x = a[k] * x + np.sqrt(1.0 - a[k] * a[k]) * drive[k] if k else x
        out[k] = x
    return out
