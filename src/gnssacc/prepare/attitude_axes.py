"""Whose axes a run's attitude is of, and the least attitude sigma no measurement can beat
(``metrics.json`` ``attitude_axes``).

The estimators integrate the accelerometer triad's own axes: gravity and the fixes' accelerations
align the attitude with the axes the accelerometers sense along. A triad's cross-axis errors
(non-orthogonality and misalignment, ``f_meas = (I + M) f``, each off-diagonal element of ``M``
about ``[imu] accel_misalignment_ppm`` 1-sigma: tenths of a degree on a consumer IMU) turn those
axes against the IMU's case, and so against the vehicle, by the antisymmetric part of ``M``: a
rotation of ``(M_zy - M_yz) / 2``, ``(M_xz - M_zx) / 2``, ``(M_yx - M_xy) / 2`` about x, y, z,
each of 1-sigma ``accel_misalignment_ppm / sqrt(2)`` for independent elements. No measurement of
the 15-state model separates that rotation from the attitude, so no attitude sigma of the case's
(or the vehicle's) axes can be below it: it is the reported sigma's floor, on every axis the tuner
did not measure. A floor, not a term added in quadrature: the tuned noise covers some of what the
model leaves out already, and the estimator's sigma then holds part of it.

* Where the tuner searched the constraint's axes against the body's (``[nhc]
  pitch_offset_deg``, ``yaw_offset_deg`` set by ``tuned``), those angles were measured against
  the triad's axes: where it proved one (its likelihood-ratio test), the attitude is the
  vehicle's (:meth:`gnssacc.core.solution.NavSolution.in_vehicle_axes`). The measurement has a
  resolution (:func:`likelihood_sigma`), and a test that keeps an angle only on decisive evidence
  leaves at zero angles of up to about four of it: the axis's floor is how far the angle in use
  may be from the vehicle's (:func:`offset_floor`: a kept angle's resolution; for one left at
  zero, the triad's turn as the IMU's class allows it, updated by the likelihood). A
  sideways-mounted consumer IMU whose pitch test found -0.34 deg at 3.1 sigma, not decisive, and
  kept zero stated a pitch sigma of 0.15 deg with an error of +0.34 (pitch NEES 3.5 / 4.4).
* The roll against the vehicle's axes is in no measurement (the constraint's lateral and vertical
  velocities are both zero whatever it is). Where the tuner found the other two angles, they
  measure this IMU's triad; with the three angles alike a priori, their root mean square
  ``sqrt((p^2 + y^2) / 2)`` is the roll's scale given the two. The roll's floor is the larger of
  that and the triad's rotation.
* Every other axis (all three without the constraint or its tuning; where a user set the angles,
  those are the case's, not the triad's) has the triad's rotation as its floor.

**A vehicle that never moved enough to tell its yaw** (the start's ``yaw_evidence``
``"undetermined"``) never separated its tilt from the horizontal accelerometer biases either: the
fixes and the stationary updates measure ``g phi - R_nb b_a`` alone, which turning or accelerating
would have split. The roll and pitch then cannot be known better than the biases' prior allows,
``atan(sigma_b_a / g)`` per axis (the body's y bias tilts the roll, its x bias the pitch; the
start's bias sigmas, else ``[imu] accel_bias_sigma0_mg``): the EKF's covariance holds that
(linearised at rest, :func:`gnssacc.estimators.ekf.rest_samples`); the fixed-lag smoother's
marginals, relinearised as the unobservable yaw wanders, claimed a third of it (a simulated
consumer vehicle at rest: roll sigma 0.38 deg against 1.15 deg, its error 1.5 deg; roll NEES
15). It is every solution's roll and pitch floor on such a run (``level_deg``).
"""

from __future__ import annotations

import math

import numpy as np

from ..core.config import FALLBACK_TURN_ERROR_PPM, RunConfig
from ..core.units import G0

#: The axes of :attr:`gnssacc.core.solution.NavSolution.rpy`, in order.
AXES = ("roll", "pitch", "yaw")


def misalignment_ppm(cfg: RunConfig) -> tuple[float, str]:
    """The accelerometer triad's cross-axis 1-sigma [ppm] and where it came from: ``[imu]
    accel_misalignment_ppm``, or with ``"auto"`` the gyro turn allowance's value (the same IMU's
    class: :mod:`gnssacc.prepare.turn_allowance`), its fallback where that is still ``"auto"``."""
    value = cfg["imu"]["accel_misalignment_ppm"]
    if value != "auto":
        return float(value), cfg.origin.get(("imu", "accel_misalignment_ppm"), "defaults")
    turn = cfg["imu"]["gyro_turn_error_ppm"]
    if turn == "auto":
        return FALLBACK_TURN_ERROR_PPM, "the fallback turn allowance"
    return float(turn), "the gyro turn allowance"


def level_floor(cfg: RunConfig, init) -> dict | None:
    """The roll and pitch no measurement of a run that never showed its yaw can beat [deg]
    (module notes): ``{"roll", "pitch"}`` from the horizontal accelerometer biases' sigma
    (``init.sigma_b_a``, else ``[imu] accel_bias_sigma0_mg``) and that sigma ``bias_mg`` (x, y);
    ``None`` when ``init`` (an :class:`~gnssacc.core.recording.InitialState`) is missing or its
    yaw was told."""
    if init is None or getattr(init, "yaw_evidence", "") != "undetermined":
        return None
    sigma = cfg.accel_bias_sigma0 if init.sigma_b_a is None else np.asarray(init.sigma_b_a, float)
    tilt = np.degrees(np.arctan(sigma[:2] / G0))
    return {
        "roll": float(tilt[1]),
        "pitch": float(tilt[0]),
        "bias_mg": [float(x) for x in sigma[:2] / G0 * 1e3],
    }


#: How far beyond the found angle the likelihood is read when zero is within a sigma of it [deg].
PROBE_DEG = 0.5


def needs_probe(found_deg: float, drop: float) -> bool:
    """Whether :func:`likelihood_sigma` reads the likelihood at :func:`probe_at`: zero is within a
    sigma of the found angle (``drop``, its log-likelihood below the found one's, under 0.5)."""
    return drop < 0.5 or found_deg == 0.0


def probe_at(found_deg: float) -> float:
    """Where :func:`likelihood_sigma` reads the likelihood beyond the found angle, away from zero
    [deg]."""
    return found_deg + math.copysign(PROBE_DEG, found_deg or 1.0)


def likelihood_sigma(loglik, found_deg: float) -> float:
    """How well the likelihood resolves one angle of the vehicle's axes: its 1-sigma [deg] from
    the curvature of the log-likelihood along the angle, by the secant between the found angle
    and zero (where the tuner's test already read it) or, where zero is within a sigma of it,
    between the found angle and :func:`probe_at`; ``inf`` where the likelihood is flat.

    Parameters
    ----------
    loglik : callable
        ``loglik(angle_deg)``: the log-likelihood with this angle at ``angle_deg``, the others as
        found.
    found_deg : float
        The angle the search found (the likelihood's maximum along it) [deg].
    """
    best = loglik(found_deg)
    drop, dist = best - loglik(0.0), abs(found_deg)
    if needs_probe(found_deg, drop):
        dist = PROBE_DEG
        drop = best - loglik(probe_at(found_deg))
    return dist / math.sqrt(2.0 * drop) if drop > 0.0 else math.inf


def offset_floor(found_deg: float, sigma_deg: float | None, kept: bool, triad_deg: float) -> float:
    """How far an angle of the vehicle's axes in use may be from the vehicle's [deg], 1-sigma.

    A kept angle (its test decisive: the data overrule any prior) is off by what the likelihood
    resolves, ``sigma_deg``. A dropped one is zero, and the angle is what the IMU's class allows,
    ``N(0, triad_deg^2)`` (the triad's turn; the mounting is applied), updated by the likelihood
    ``N(found_deg, sigma_deg^2)``: zero is off by the root mean square ``hypot(mean, sd)`` of that
    posterior (no more than the triad, nearly the found angle where the likelihood is sharp).
    ``sigma_deg`` ``None``: a flat likelihood (a kept angle is then off by the root mean square of
    the prior about it).
    """
    flat = sigma_deg is None or not math.isfinite(sigma_deg)
    if kept and not flat:
        return float(sigma_deg)
    used = found_deg if kept else 0.0
    if triad_deg <= 0.0:  # a calibrated triad: the vehicle's axes are the case's
        return abs(used)
    info = 0.0 if flat else 1.0 / sigma_deg**2
    var = 1.0 / (1.0 / triad_deg**2 + info)
    return math.hypot(used - found_deg * info * var, math.sqrt(var))


def attitude_axes(cfg: RunConfig, init=None, tuned_axes: dict | None = None) -> dict:
    """Whose axes the solutions' attitude is of and the least sigma of each of its angles.

    Parameters
    ----------
    cfg : RunConfig
        The run's configuration (tuned).
    init : InitialState, optional
        The run's start: on a run whose yaw it left undetermined, roll and pitch have the level
        floor too (:func:`level_floor`).
    tuned_axes : dict, optional
        The tuner's record of the angles it searched (``TuneResult.from_stationary``
        ``vehicle_axes``: ``{key: {"found_deg", "sigma_deg", "kept"}}``, :func:`likelihood_sigma`):
        each such angle's floor (:func:`offset_floor`).

    Returns
    -------
    dict
        ``axes`` (``"vehicle"`` where ``[nhc]`` turns the constraint's axes against the body's,
        else ``"body"``), ``pitch_offset_deg``, ``yaw_offset_deg`` [deg], ``set_by`` (who set the
        nonzero angles: ``tuned``, a file, ``overrides``), ``misalignment_ppm`` with its
        ``misalignment_from``, ``triad_deg`` (the triad's rotation per axis, 1-sigma [deg]),
        ``level_deg`` (:func:`level_floor`, or ``None``) and ``sigma_floor_deg`` ``{roll, pitch,
        yaw}`` [deg] (the module docstring); ``resolution_deg`` ``{pitch, yaw}``, the floors of
        the angles the tuner searched (:func:`offset_floor`; an axis not searched is absent).
    """
    keys = ("pitch_offset_deg", "yaw_offset_deg")
    angles = {k: float(cfg["nhc"][k]) for k in keys}
    origin = {k: cfg.origin.get(("nhc", k), "defaults") for k in keys}
    ppm, source = misalignment_ppm(cfg)
    triad = math.degrees(ppm * 1e-6) / math.sqrt(2.0)
    measured = {k: origin[k] == "tuned" for k in keys}  # searched, kept or not
    resolution = {
        k.split("_")[0]: offset_floor(**tuned_axes[k], triad_deg=triad)
        for k in keys
        if measured[k] and tuned_axes and k in tuned_axes
    }
    floor = {
        "roll": triad,
        "pitch": resolution.get("pitch", 0.0) if measured["pitch_offset_deg"] else triad,
        "yaw": resolution.get("yaw", 0.0) if measured["yaw_offset_deg"] else triad,
    }
    if any(measured[k] and angles[k] for k in keys):
        floor["roll"] = max(triad, math.sqrt((angles[keys[0]] ** 2 + angles[keys[1]] ** 2) / 2))
    level = level_floor(cfg, init)
    if level is not None:
        floor["roll"] = max(floor["roll"], level["roll"])
        floor["pitch"] = max(floor["pitch"], level["pitch"])
    return {
        "axes": "vehicle" if any(angles.values()) else "body",
        **angles,
        "set_by": sorted({origin[k] for k in keys if angles[k]}),
        "misalignment_ppm": ppm,
        "misalignment_from": source,
        "triad_deg": triad,
        "level_deg": level,
        "resolution_deg": resolution,
        "sigma_floor_deg": floor,
    }
