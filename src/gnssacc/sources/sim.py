"""Ground-vehicle simulator: scenarios with known truth, WGS-84-consistent IMU, GNSS fixes.

The simulator produces :class:`gnssacc.run.RecordedRun` objects for tests of the estimators.

Conventions
-----------
* Body frame b is Front-Right-Down, navigation frame n is North-East-Down, ``R_nb`` maps body
  vectors into n, Euler angles are Z-Y-X roll/pitch/yaw [rad], SI units throughout.
* The vehicle has no side slip: body x points along the velocity, pitch follows the slope of
  the path, roll is zero, yaw is the course. ``v_n = R_nb @ [speed, 0, 0]``.
* The truth point (``lat, lon, h``, ``v_n``) is the IMU / body origin. GNSS fixes are of the
  antenna at ``lever_arm_b`` (body frame) from it.
* IMU sample ``k`` at time ``t[k]`` is the AVERAGE over the interval ``(t[k-1], t[k]]`` of
  length ``dt = 1 / imu_rate_hz`` (an integrating IMU, ``dv / dt`` and ``dtheta / dt``):

  - ``omega_ib_b[k] = rotvec(C_{b(k-1)}^{b(k)}) / dt`` where ``C_{b(k-1)}^{b(k)}`` is the exact
    inertial attitude increment of the body over the interval,
    ``R_nb(k-1)^T  C_{n(k-1)}^{n(k)}  R_nb(k)``, and ``C_{n(k-1)}^{n(k)}`` the rotation of the
    navigation frame w.r.t. inertial space (earth rotation plus transport) over the interval.
    A strapdown update ``R_nb(k) = exp(-[omega_in^n dt x]) R_nb(k-1) exp([omega_ib_b[k] dt x])``
    therefore reproduces the truth.
  - ``f_b[k] = R_nb(t_mid)^T (1/dt) integral of (dv_n/dt - g_n + (2 omega_ie^n + omega_en^n) x v_n) dt``
    with ``R_nb(t_mid)`` the true attitude at the interval midpoint: rotating the sample with the
    average (mid-interval) attitude reproduces the true velocity change.

  The first IMU sample is at the truth start ``t_start_s`` and averages the interval just
  before it (the trajectory is extended backwards at its initial speed and heading).
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..config import DEFAULTS, G0
from ..earth import LocalTangentFrame, OMEGA_IE, normal_gravity, radii
from ..errors import InputError
from ..gnss_noise import PROFILES, fixes_from_truth
from ..rotations import wrap_angle
from ..run import GnssFixes, ImuData, InitialState, RecordedRun, Truth

DEG = np.pi / 180.0
WHERE = "simulator"

# ---------------------------------------------------------------------------------------------
# IMU grades
# ---------------------------------------------------------------------------------------------

#: Keys of an IMU grade; identical to ``gnssacc.config.DEFAULTS["imu"]`` (same units).
GRADE_KEYS = tuple(DEFAULTS["imu"])


def _grade(arw, vrw, gbi, abi, g0, a0, tau=300.0) -> dict:
    return {"gyro_arw_deg_rth": arw, "accel_vrw_mps_rth": vrw, "gyro_bias_instability_deg_h": gbi,
            "accel_bias_instability_mg": abi, "bias_correlation_time_s": tau,
            "gyro_bias_sigma0_deg_h": g0, "accel_bias_sigma0_mg": a0}


#: Named IMU grades in the units of ``gnssacc.config.DEFAULTS["imu"]``: ARW [deg/sqrt(h)],
#: VRW [m/s/sqrt(h)], bias instability [deg/h] and [mg] (Gauss-Markov sigma), correlation time
#: [s], turn-on bias 1-sigma [deg/h] and [mg].
IMU_GRADES: dict[str, dict] = {
    "perfect": _grade(0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
    # MEMS phone-like: turn-on gyro bias 0.5 deg/s = 1800 deg/h.
    "consumer": _grade(0.6, 0.2, 30.0, 0.5, 1800.0, 30.0),
    # VN-300 class: turn-on gyro bias 0.1 deg/s = 360 deg/h.
    "industrial": _grade(0.2, 0.05, 5.0, 0.04, 360.0, 5.0),
    "tactical": _grade(0.05, 0.02, 0.5, 0.02, 2.0, 1.0),
}


def grade_config(grade: str, overrides: dict | None = None) -> dict:
    """IMU error parameters of a named grade, in configuration keys and units.

    Parameters
    ----------
    grade : {"perfect", "consumer", "industrial", "tactical"}
    overrides : dict, optional
        Keys of ``gnssacc.config.DEFAULTS["imu"]`` to replace (scalar or three per-axis values).

    Returns
    -------
    dict
        Usable as ``gnssacc.config.load_config(overrides={"imu": grade_config(grade)})`` so a
        filter is tuned to the simulated IMU. Note that ``"perfect"`` gives zeros, which a filter
        cannot use as process noise.

    Raises
    ------
    InputError
        Unknown grade or unknown override key.
    """
    if grade not in IMU_GRADES:
        raise InputError(WHERE, f"unknown IMU grade {grade!r} (known: {', '.join(IMU_GRADES)})")
    params = dict(IMU_GRADES[grade])
    for key, value in (overrides or {}).items():
        if key not in params:
            raise InputError(WHERE, f"unknown IMU parameter {key!r} (known: {', '.join(GRADE_KEYS)})")
        params[key] = value
    if float(params["bias_correlation_time_s"]) <= 0:
        raise InputError(WHERE, "bias_correlation_time_s must be positive")
    return params


def _axes(value) -> np.ndarray:
    """A scalar or three per-axis values as a float array of shape (3,)."""
    return np.broadcast_to(np.asarray(value, float), (3,)).copy()


def imu_sigmas_si(params: dict) -> dict:
    """Grade parameters in SI units, per axis.

    Parameters
    ----------
    params : dict
        As returned by :func:`grade_config`.

    Returns
    -------
    dict
        ``gyro_density`` [rad/s/sqrt(Hz)], ``accel_density`` [m/s^2/sqrt(Hz)],
        ``gyro_bi``, ``gyro_sigma0`` [rad/s], ``accel_bi``, ``accel_sigma0`` [m/s^2],
        ``tau`` [s].
    """
    mg = 1e-3 * G0
    return {
        "gyro_density": _axes(params["gyro_arw_deg_rth"]) * DEG / 60.0,
        "accel_density": _axes(params["accel_vrw_mps_rth"]) / 60.0,
        "gyro_bi": _axes(params["gyro_bias_instability_deg_h"]) * DEG / 3600.0,
        "accel_bi": _axes(params["accel_bias_instability_mg"]) * mg,
        "gyro_sigma0": _axes(params["gyro_bias_sigma0_deg_h"]) * DEG / 3600.0,
        "accel_sigma0": _axes(params["accel_bias_sigma0_mg"]) * mg,
        "tau": float(params["bias_correlation_time_s"]),
    }


def gauss_markov(n: int, dt: float, tau: float, sigma: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Stationary first-order Gauss-Markov sequence, three axes.

    ``x[k] = a x[k-1] + sqrt(1 - a^2) sigma w[k]``, ``a = exp(-dt / tau)``, ``x[0] ~ N(0, sigma^2)``.

    Parameters
    ----------
    n : int
        Number of samples.
    dt : float
        Sample interval [s].
    tau : float
        Correlation time [s].
    sigma : ndarray, shape (3,)
        Stationary 1-sigma per axis (any unit; the output has the same unit).
    rng : numpy.random.Generator

    Returns
    -------
    ndarray, shape (n, 3)
    """
    sigma = _axes(sigma)
    a = np.exp(-dt / tau)
    x = np.empty((n, 3))
    x[0] = rng.standard_normal(3) * sigma
    drive = rng.standard_normal((max(n - 1, 0), 3)) * (np.sqrt(1.0 - a * a) * sigma)
    # Closed form per block, x[s+i] = a^i (x[s] + sum_j a^-j e_j), vectorised; the block length
    # keeps a^-i below 1e6 so the scaled cumulative sum stays accurate.
    block = max(1, int(np.log(1e6) * tau / dt))
    s = 0
    while s < n - 1:
        m = min(block, n - 1 - s)
        p = a ** np.arange(1, m + 1)
        x[s + 1:s + m + 1] = p[:, None] * (x[s] + np.cumsum(drive[s:s + m] / p[:, None], axis=0))
        s += m
    return x


def imu_errors(n: int, dt: float, params: dict, rng: np.random.Generator) -> dict:
    """Draw the IMU errors of one run.

    Parameters
    ----------
    n : int
        Number of IMU samples.
    dt : float
        IMU interval [s].
    params : dict
        Grade parameters (:func:`grade_config`).
    rng : numpy.random.Generator
        Draw order is fixed (turn-on biases, Gauss-Markov biases, white noise; accelerometer
        before gyro), and every draw is made even for zero sigmas, so changing one parameter
        leaves the other error sequences unchanged.

    Returns
    -------
    dict
        ``bias_a`` [m/s^2], ``bias_g`` [rad/s] (turn-on + Gauss-Markov, shape (n, 3)),
        ``noise_a`` [m/s^2], ``noise_g`` [rad/s] (white, shape (n, 3), 1-sigma density/sqrt(dt)).
    """
    si = imu_sigmas_si(params)
    on_a = rng.standard_normal(3) * si["accel_sigma0"]
    on_g = rng.standard_normal(3) * si["gyro_sigma0"]
    gm_a = gauss_markov(n, dt, si["tau"], si["accel_bi"], rng)
    gm_g = gauss_markov(n, dt, si["tau"], si["gyro_bi"], rng)
    noise_a = rng.standard_normal((n, 3)) * (si["accel_density"] / np.sqrt(dt))
    noise_g = rng.standard_normal((n, 3)) * (si["gyro_density"] / np.sqrt(dt))
    return {"bias_a": on_a + gm_a, "bias_g": on_g + gm_g, "noise_a": noise_a, "noise_g": noise_g}


# ---------------------------------------------------------------------------------------------
# Smooth pulses: the building block of every kinematic channel
# ---------------------------------------------------------------------------------------------

def _step(x):
    """Quintic smoothstep S(x) on [0, 1] (C2: zero first and second derivative at both ends)."""
    return x * x * x * (10.0 - 15.0 * x + 6.0 * x * x)


def _step_d(x):
    """dS/dx."""
    return 30.0 * x * x * (1.0 - x) ** 2


def _step_int(x):
    """Integral of S from 0 to x, for x in [0, 1] (equals 1/2 at x = 1)."""
    return x ** 4 * (2.5 - 3.0 * x + x * x)


@dataclass(frozen=True)
class Pulse:
    """A smooth trapezoid: 0 before ``t0``, ramps to ``amplitude`` over ``ramp`` seconds, holds,
    and ramps back to 0 by ``t0 + duration``.

    Attributes
    ----------
    t0, duration, ramp : float
        Start [s], total length [s] and ramp length [s] (``ramp <= duration / 2``).
    amplitude : float
        Plateau value (unit of the channel).
    """

    t0: float
    duration: float
    ramp: float
    amplitude: float

    @property
    def area(self) -> float:
        """Integral of the pulse over all time (unit x s)."""
        return self.amplitude * (self.duration - self.ramp)


def _channel(pulses: list[Pulse], t: np.ndarray, kind: str) -> np.ndarray:
    """Sum of pulses at sorted times ``t``: ``kind`` = "value", "rate" (d/dt) or "integral".

    Each pulse is evaluated only on its support (found by bisection), so the cost stays linear in
    the number of samples for long runs with many segments.
    """
    out = np.zeros(len(t))
    tail = np.zeros(len(t) + 1)
    for p in pulses:
        te = p.t0 + p.duration
        i0, i1 = np.searchsorted(t, [p.t0, te], side="right")
        tt = t[i0:i1]
        # Rising step at t0, falling step at te - ramp; the pulse is their difference.
        x1 = np.clip((tt - p.t0) / p.ramp, 0.0, 1.0)
        x2 = np.clip((tt - (te - p.ramp)) / p.ramp, 0.0, 1.0)
        if kind == "value":
            out[i0:i1] += p.amplitude * (_step(x1) - _step(x2))
        elif kind == "rate":
            out[i0:i1] += p.amplitude / p.ramp * (_step_d(x1) - _step_d(x2))
        else:
            int1 = p.ramp * _step_int(x1) + np.maximum(tt - p.t0 - p.ramp, 0.0)
            int2 = p.ramp * _step_int(x2) + np.maximum(tt - te, 0.0)
            out[i0:i1] += p.amplitude * (int1 - int2)
            tail[i1] += p.area
    if kind == "integral":
        out += np.cumsum(tail[:-1])
    return out


# ---------------------------------------------------------------------------------------------
# Scenarios
# ---------------------------------------------------------------------------------------------

@dataclass
class Kinematics:
    """Path kinematics at given times (before geodetic integration).

    Attributes
    ----------
    speed, accel : ndarray
        Speed along the path [m/s] and its rate [m/s^2].
    yaw, yaw_rate : ndarray
        Course = yaw [rad] (not wrapped) and its rate [rad/s].
    pitch, pitch_rate : ndarray
        Path slope = pitch [rad] and its rate [rad/s].
    """

    speed: np.ndarray
    accel: np.ndarray
    yaw: np.ndarray
    yaw_rate: np.ndarray
    pitch: np.ndarray
    pitch_rate: np.ndarray

    @property
    def R_nb(self) -> np.ndarray:
        """Body-to-NED rotations, shape (K, 3, 3) (roll zero)."""
        return _R_nb_batch(self.pitch, self.yaw)

    @property
    def v_n(self) -> np.ndarray:
        """NED velocity [m/s], shape (K, 3): speed along body x."""
        cp, sp, cy, sy = np.cos(self.pitch), np.sin(self.pitch), np.cos(self.yaw), np.sin(self.yaw)
        return self.speed[:, None] * np.stack([cp * cy, cp * sy, -sp], axis=1)

    @property
    def a_n(self) -> np.ndarray:
        """Time derivative of the NED velocity components [m/s^2], shape (K, 3)."""
        cp, sp, cy, sy = np.cos(self.pitch), np.sin(self.pitch), np.cos(self.yaw), np.sin(self.yaw)
        u = np.stack([cp * cy, cp * sy, -sp], axis=1)
        du_dpitch = np.stack([-sp * cy, -sp * sy, -cp], axis=1)
        du_dyaw = np.stack([-cp * sy, cp * cy, np.zeros_like(cp)], axis=1)
        return (self.accel[:, None] * u + self.speed[:, None]
                * (self.pitch_rate[:, None] * du_dpitch + self.yaw_rate[:, None] * du_dyaw))

    @property
    def omega_nb_b(self) -> np.ndarray:
        """Body rate w.r.t. the navigation frame, body axes [rad/s] (Z-Y-X rates, roll 0)."""
        return np.stack([-self.yaw_rate * np.sin(self.pitch), self.pitch_rate,
                         self.yaw_rate * np.cos(self.pitch)], axis=1)


class Scenario:
    """A ground-vehicle path built from segments, evaluated analytically at any time.

    Segments are appended in time order; every transition is a quintic smooth ramp, so
    acceleration and angular rate are continuous. Times are relative to the scenario start (0).

    Parameters
    ----------
    name : str
    speed0 : float
        Initial speed [m/s] (the path before time 0 continues straight at this speed).

    Attributes
    ----------
    t_end : float
        End of the last segment [s].
    speed : float
        Speed at ``t_end`` [m/s].
    segments : list of dict
        ``{"kind", "t0", "t1", ...}`` per segment (kinds: hold, cruise, speed, turn, hill).
    """

    def __init__(self, name: str, speed0: float = 0.0):
        self.name = name
        self.speed0 = float(speed0)
        self.speed = float(speed0)
        self.t_end = 0.0
        self.segments: list[dict] = []
        self._accel: list[Pulse] = []
        self._yaw_rate: list[Pulse] = []
        self._pitch: list[Pulse] = []

    def _log(self, kind: str, duration: float, **info) -> "Scenario":
        info = {k: float(v) for k, v in info.items()}
        self.segments.append({"kind": kind, "t0": self.t_end, "t1": self.t_end + float(duration), **info})
        self.t_end += float(duration)
        return self

    def cruise(self, duration_s: float) -> "Scenario":
        """Straight at the current speed (stationary when the speed is 0) for ``duration_s`` [s]."""
        return self._log("hold" if self.speed == 0.0 else "cruise", duration_s, speed=self.speed)

    def hold(self, duration_s: float) -> "Scenario":
        """Stand still for ``duration_s`` [s] (the speed must already be 0)."""
        if self.speed != 0.0:
            raise InputError(WHERE, f"{self.name}: hold() needs speed 0, the vehicle moves at {self.speed} m/s")
        return self._log("hold", duration_s, speed=0.0)

    def speed_to(self, speed_mps: float, duration_s: float, ramp_s: float = 1.0) -> "Scenario":
        """Change speed to ``speed_mps`` [m/s] over ``duration_s`` [s] along a straight line.

        The acceleration is a smooth trapezoid with ``ramp_s`` [s] ramps (jerk-limited).
        """
        ramp = min(ramp_s, duration_s / 2.0)
        accel = (speed_mps - self.speed) / (duration_s - ramp)
        self._accel.append(Pulse(self.t_end, duration_s, ramp, accel))
        info = {"speed_from": self.speed, "speed": float(speed_mps), "accel": accel}
        self.speed = float(speed_mps)
        return self._log("speed", duration_s, **info)

    def turn(self, angle_deg: float, radius_m: float | None = None, rate_dps: float | None = None,
             ramp_s: float = 1.0) -> "Scenario":
        """Turn by ``angle_deg`` [deg] (positive = right, clockwise seen from above) at constant speed.

        Give either the ``radius_m`` [m] (needs a moving vehicle; the rate is speed / radius) or
        the plateau yaw rate ``rate_dps`` [deg/s] (at speed 0 this is a turn on the spot).
        The yaw rate ramps up and down over ``ramp_s`` [s].
        """
        if (radius_m is None) == (rate_dps is None):
            raise InputError(WHERE, f"{self.name}: turn() needs exactly one of radius_m and rate_dps")
        if radius_m is not None:
            if self.speed <= 0.0:
                raise InputError(WHERE, f"{self.name}: a turn with a radius needs a moving vehicle")
            rate = self.speed / radius_m
        else:
            rate = abs(rate_dps) * DEG
        angle = angle_deg * DEG
        # A turn shorter than its ramp keeps the rate and shrinks the ramp (no plateau).
        ramp = min(ramp_s, abs(angle) / rate)
        duration = abs(angle) / rate + ramp
        self._yaw_rate.append(Pulse(self.t_end, duration, ramp, np.sign(angle) * rate))
        return self._log("turn", duration, angle_deg=angle_deg, yaw_rate=np.sign(angle) * rate,
                         speed=self.speed)

    def hill(self, height_m: float, slope_deg: float = 5.0, top_s: float = 0.0,
             ramp_s: float = 2.0) -> "Scenario":
        """Drive over a hill: climb about ``height_m`` [m] at ``slope_deg``, cruise ``top_s`` [s], descend.

        Pitch follows the slope (smooth ramps of ``ramp_s`` [s]). At constant speed the descent
        mirrors the climb exactly, so the height returns to its value before the hill.
        """
        if self.speed <= 0.0:
            raise InputError(WHERE, f"{self.name}: a hill needs a moving vehicle")
        slope = abs(slope_deg) * DEG
        plateau = abs(height_m) / (self.speed * np.sin(slope))
        ramp = min(ramp_s, plateau)
        climb = plateau + ramp
        sign = np.sign(height_m) if height_m else 1.0
        t0 = self.t_end
        self._pitch.append(Pulse(t0, climb, ramp, sign * slope))
        self._pitch.append(Pulse(t0 + climb + top_s, climb, ramp, -sign * slope))
        return self._log("hill", 2.0 * climb + top_s, height_m=height_m, slope_deg=slope_deg,
                         speed=self.speed)

    def kinematics(self, t_rel: np.ndarray, yaw0: float) -> Kinematics:
        """Evaluate the path at sorted times ``t_rel`` [s] relative to the start; ``yaw0`` [rad]."""
        t_rel = np.atleast_1d(np.asarray(t_rel, float))
        speed = self.speed0 + _channel(self._accel, t_rel, "integral")
        # Stops end with floating-point dust of ~1e-15 m/s: make them exactly stationary.
        speed = np.where(np.abs(speed) < 1e-12, 0.0, speed)
        return Kinematics(
            speed=speed,
            accel=_channel(self._accel, t_rel, "value"),
            yaw=yaw0 + _channel(self._yaw_rate, t_rel, "integral"),
            yaw_rate=_channel(self._yaw_rate, t_rel, "value"),
            pitch=_channel(self._pitch, t_rel, "value"),
            pitch_rate=_channel(self._pitch, t_rel, "rate"),
        )

    def segments_until(self, t_end: float) -> list[dict]:
        """The segments that start before ``t_end`` [s] (relative), the last one clipped."""
        out = []
        for s in self.segments:
            if s["t0"] < t_end:
                out.append({**s, "t1": min(s["t1"], t_end)})
        return out


def _cycle_ugv(s: Scenario) -> None:
    """UGV: 0-3 m/s, stops, radius and on-the-spot turns, a small hill. Starts and ends at rest."""
    s.hold(8.0).speed_to(2.0, 4.0).cruise(10.0)
    s.turn(90.0, radius_m=5.0)
    s.speed_to(3.0, 3.0).cruise(6.0)
    s.hill(1.5, slope_deg=8.0, top_s=2.0)
    s.speed_to(1.0, 3.0).turn(-120.0, rate_dps=20.0).cruise(5.0)
    s.speed_to(0.0, 3.0).hold(5.0)
    s.turn(90.0, rate_dps=30.0).hold(3.0)  # skid-steer pivot on the spot
    s.speed_to(2.5, 3.0).cruise(6.0).turn(-90.0, radius_m=4.0).cruise(3.0)
    s.speed_to(0.0, 3.0)


def _cycle_car(s: Scenario) -> None:
    """Car: up to 20 m/s, turns of 15-80 m radius, hills, stops. Starts and ends at rest."""
    s.hold(10.0).speed_to(15.0, 8.0, ramp_s=1.5).cruise(10.0)
    s.turn(90.0, radius_m=60.0)
    s.speed_to(20.0, 5.0).hill(8.0, slope_deg=4.0, top_s=3.0).cruise(8.0)
    s.speed_to(8.0, 6.0, ramp_s=1.5).turn(-90.0, radius_m=20.0)
    s.speed_to(12.0, 4.0).turn(45.0, radius_m=80.0).cruise(8.0)
    s.speed_to(0.0, 6.0, ramp_s=1.5)


def _cycle_straight(s: Scenario) -> None:
    """Constant 10 m/s along a straight line."""
    s.cruise(60.0)


def _cycle_turns(s: Scenario) -> None:
    """Figure of eight at 10 m/s: a straight, a full left circle, a full right circle (30 m radius)."""
    s.cruise(10.0).turn(-360.0, radius_m=30.0).turn(360.0, radius_m=30.0)


def _cycle_static(s: Scenario) -> None:
    s.hold(600.0)


#: Scenario name -> (initial speed [m/s], one cycle appended to a Scenario).
SCENARIOS = {
    "static": (0.0, _cycle_static),
    "ugv": (0.0, _cycle_ugv),
    "car": (0.0, _cycle_car),
    "straight": (10.0, _cycle_straight),
    "turns": (10.0, _cycle_turns),
}


def make_scenario(name: str, duration_s: float) -> Scenario:
    """A named scenario, its cycle repeated until it lasts at least ``duration_s`` [s].

    Parameters
    ----------
    name : {"static", "ugv", "car", "straight", "turns"}
    duration_s : float

    Returns
    -------
    Scenario
    """
    if name not in SCENARIOS:
        raise InputError(WHERE, f"unknown scenario {name!r} (known: {', '.join(SCENARIOS)})")
    if not duration_s > 0:
        raise InputError(WHERE, f"duration_s must be positive, got {duration_s}")
    speed0, cycle = SCENARIOS[name]
    s = Scenario(name, speed0)
    while s.t_end < duration_s:
        cycle(s)
    return s


# ---------------------------------------------------------------------------------------------
# Geodetic truth trajectory
# ---------------------------------------------------------------------------------------------

def _R_nb_batch(pitch, yaw) -> np.ndarray:
    """``Rz(yaw) @ Ry(pitch)`` for arrays, shape (K, 3, 3)."""
    cp, sp, cy, sy = np.cos(pitch), np.sin(pitch), np.cos(yaw), np.sin(yaw)
    R = np.empty((len(cp), 3, 3))
    R[:, 0, 0], R[:, 0, 1], R[:, 0, 2] = cy * cp, -sy, cy * sp
    R[:, 1, 0], R[:, 1, 1], R[:, 1, 2] = sy * cp, cy, sy * sp
    R[:, 2, 0], R[:, 2, 1], R[:, 2, 2] = -sp, 0.0, cp
    return R


def _R_en_batch(lat, lon) -> np.ndarray:
    """ECEF-to-NED rotations (``gnssacc.earth.R_en``) for arrays, shape (K, 3, 3)."""
    sl, cl, so, co = np.sin(lat), np.cos(lat), np.sin(lon), np.cos(lon)
    R = np.empty((len(sl), 3, 3))
    R[:, 0, 0], R[:, 0, 1], R[:, 0, 2] = -sl * co, -sl * so, cl
    R[:, 1, 0], R[:, 1, 1], R[:, 1, 2] = -so, co, 0.0
    R[:, 2, 0], R[:, 2, 1], R[:, 2, 2] = -cl * co, -cl * so, -sl
    return R


def _rotvec_batch(R) -> np.ndarray:
    """Rotation vectors of rotations with angle < pi, shape (K, 3).

    Uses atan2(|sin|, cos) rather than arccos so that tiny angles (earth rate over 10 ms is
    7e-7 rad) keep full relative precision.
    """
    w = 0.5 * np.stack([R[:, 2, 1] - R[:, 1, 2], R[:, 0, 2] - R[:, 2, 0], R[:, 1, 0] - R[:, 0, 1]], -1)
    s = np.linalg.norm(w, axis=1)
    angle = np.arctan2(s, 0.5 * (np.trace(R, axis1=1, axis2=2) - 1.0))
    scale = np.where(s > 1e-300, angle / np.where(s > 1e-300, s, 1.0), 1.0)
    return w * scale[:, None]


def _earth_rate_batch(lat) -> np.ndarray:
    return OMEGA_IE * np.stack([np.cos(lat), np.zeros_like(lat), -np.sin(lat)], -1)


def _transport_rate_batch(lat, h, v_n) -> np.ndarray:
    R_M, R_N = radii(lat)
    return np.stack([v_n[:, 1] / (R_N + h), -v_n[:, 0] / (R_M + h), -v_n[:, 1] * np.tan(lat) / (R_N + h)], -1)


def _cumulative(rate, rate_dot, h):
    """Cumulative integral on a uniform grid of step ``h``: trapezoid with the end-derivative
    (Euler-Maclaurin) correction, fourth order; starts at 0."""
    inc = 0.5 * h * (rate[1:] + rate[:-1]) + h * h / 12.0 * (rate_dot[:-1] - rate_dot[1:])
    return np.concatenate([[0.0], np.cumsum(inc)])


def _hermite(t_grid0, h, y, ydot, t):
    """Cubic Hermite interpolation of ``y`` (with derivative ``ydot``) on a uniform grid."""
    i = np.clip(np.floor((t - t_grid0) / h).astype(int), 0, len(y) - 2)
    u = (t - (t_grid0 + i * h)) / h
    u2, u3 = u * u, u * u * u
    return ((2 * u3 - 3 * u2 + 1) * y[i] + (u3 - 2 * u2 + u) * h * ydot[i]
            + (-2 * u3 + 3 * u2) * y[i + 1] + (u3 - u2) * h * ydot[i + 1])


@dataclass
class TruthSamples:
    """True navigation state and ideal (instantaneous) inertial signals at given times.

    Attributes
    ----------
    t : ndarray, shape (K,)
        Times [s].
    lat, lon : ndarray [rad]
    h : ndarray [m]
        Geodetic position of the body (IMU) origin.
    v_n : ndarray, shape (K, 3)
        NED velocity [m/s].
    a_n : ndarray, shape (K, 3)
        Time derivative of the NED velocity components [m/s^2].
    rpy : ndarray, shape (K, 3)
        Roll, pitch, yaw [rad] (yaw wrapped to [-pi, pi)).
    R_nb : ndarray, shape (K, 3, 3)
        Body-to-NED rotations.
    f_b : ndarray, shape (K, 3)
        Instantaneous specific force, body frame [m/s^2]
        (``R_nb^T (a_n - g_n + (2 omega_ie^n + omega_en^n) x v_n)``).
    omega_ib_b : ndarray, shape (K, 3)
        Instantaneous body rate w.r.t. inertial space, body frame [rad/s]
        (``R_nb^T (omega_ie^n + omega_en^n) + omega_nb^b``).
    speed : ndarray, shape (K,)
        Speed along the path [m/s].
    """

    t: np.ndarray
    lat: np.ndarray
    lon: np.ndarray
    h: np.ndarray
    v_n: np.ndarray
    a_n: np.ndarray
    rpy: np.ndarray
    R_nb: np.ndarray
    f_b: np.ndarray
    omega_ib_b: np.ndarray
    speed: np.ndarray

    def to_truth(self) -> Truth:
        """As a :class:`gnssacc.run.Truth`."""
        return Truth(self.t.copy(), self.lat.copy(), self.lon.copy(), self.h.copy(),
                     self.v_n.copy(), self.rpy.copy())


class Trajectory:
    """A scenario placed on the WGS-84 ellipsoid, integrated on a uniform internal grid.

    The geodetic position is integrated from the analytic NED velocity with a fourth-order
    quadrature (``lat_dot = v_N / (R_M + h)``, ``lon_dot = v_E / ((R_N + h) cos lat)``,
    ``h_dot = -v_D``); velocity and attitude are analytic at any time, positions between grid
    nodes use cubic Hermite interpolation with the exact rates.

    Parameters
    ----------
    scenario : Scenario
    origin_llh : tuple of float
        Position at ``t_start`` (lat, lon [rad], h [m]).
    yaw0 : float
        Initial yaw [rad].
    t_start : float
        Absolute time of the scenario start [s].
    t_lo, t_hi : float
        Time span covered by the grid [s] (``t_lo <= t_start``).
    step : float
        Grid step [s].
    """

    def __init__(self, scenario: Scenario, origin_llh, yaw0: float, t_start: float,
                 t_lo: float, t_hi: float, step: float):
        self.scenario, self.yaw0, self.t_start = scenario, float(yaw0), float(t_start)
        self.lat0, self.lon0, self.h0 = (float(x) for x in origin_llh)
        n = int(np.ceil((t_hi - t_lo) / step - 1e-6)) + 1
        self.grid_t0, self.step = float(t_lo), float(step)
        self.t_grid = t_lo + step * np.arange(n)
        #: Path kinematics on the grid (reused by :func:`perfect_imu`).
        self.grid_kinematics = scenario.kinematics(self.t_grid - t_start, self.yaw0)
        self._integrate(self.grid_kinematics.v_n, self.grid_kinematics.a_n)

    def _integrate(self, v_n, a_n) -> None:
        i0 = int(round((self.t_start - self.grid_t0) / self.step))
        q = self.step

        def anchored(rate, rate_dot, value0):
            c = _cumulative(rate, rate_dot, q)
            return value0 + c - c[i0]

        v_N, v_E, v_D = v_n.T
        a_N, a_E, a_D = a_n.T
        h = anchored(-v_D, -a_D, self.h0)
        lat = np.full(len(h), self.lat0)
        # lat enters through the radii only; a few fixed-point passes converge to round-off.
        for _ in range(3):
            R_M, _ = radii(lat)
            lat_dot = v_N / (R_M + h)
            lat_ddot = a_N / (R_M + h) + v_N * v_D / (R_M + h) ** 2
            lat = anchored(lat_dot, lat_ddot, self.lat0)
        R_M, R_N = radii(lat)
        lat_dot = v_N / (R_M + h)
        cl = np.cos(lat)
        lon_dot = v_E / ((R_N + h) * cl)
        lon_ddot = (a_E / ((R_N + h) * cl) + v_E * v_D / ((R_N + h) ** 2 * cl)
                    + v_E * np.sin(lat) * lat_dot / ((R_N + h) * cl * cl))
        lon = anchored(lon_dot, lon_ddot, self.lon0)
        self.lat, self.lon, self.h = lat, lon, h
        self.lat_dot, self.lon_dot, self.h_dot = lat_dot, lon_dot, -v_D

    def kinematics(self, t) -> Kinematics:
        """Analytic path kinematics at absolute times ``t`` [s] (sorted)."""
        return self.scenario.kinematics(np.asarray(t, float) - self.t_start, self.yaw0)

    def position(self, t):
        """Geodetic position (lat, lon [rad], h [m]) at absolute times ``t`` [s]."""
        t = np.atleast_1d(np.asarray(t, float))
        if t.min() < self.t_grid[0] - 1e-9 or t.max() > self.t_grid[-1] + 1e-9:
            raise InputError(WHERE, f"truth requested at {t.min():.3f}..{t.max():.3f} s, outside the simulated "
                                    f"span {self.t_grid[0]:.3f}..{self.t_grid[-1]:.3f} s")
        return tuple(_hermite(self.grid_t0, self.step, y, yd, t) for y, yd in
                     ((self.lat, self.lat_dot), (self.lon, self.lon_dot), (self.h, self.h_dot)))

    def at(self, t) -> TruthSamples:
        """Full truth (state and instantaneous IMU signals) at sorted absolute times ``t`` [s]."""
        t = np.atleast_1d(np.asarray(t, float))
        lat, lon, h = self.position(t)
        kin = self.kinematics(t)
        v_n, a_n, R_nb = kin.v_n, kin.a_n, kin.R_nb
        w_ie = _earth_rate_batch(lat)
        w_en = _transport_rate_batch(lat, h, v_n)
        g_n = np.zeros((len(t), 3))
        g_n[:, 2] = normal_gravity(lat, h)
        f_n = a_n - g_n + np.cross(2.0 * w_ie + w_en, v_n)
        f_b = np.einsum("kji,kj->ki", R_nb, f_n)
        omega_ib_b = np.einsum("kji,kj->ki", R_nb, w_ie + w_en) + kin.omega_nb_b
        rpy = np.stack([np.zeros(len(t)), kin.pitch, wrap_angle(kin.yaw)], -1)
        return TruthSamples(t, lat, lon, h, v_n, a_n, rpy, R_nb, f_b, omega_ib_b, kin.speed)


def _imu_time(t_start: float, duration_s: float, rate_hz: float) -> np.ndarray:
    # k / rate (not k * dt) so that epochs of commensurate rates coincide bit for bit.
    n = int(np.floor(duration_s * rate_hz + 1e-9)) + 1
    return t_start + np.arange(n) / rate_hz


def perfect_imu(traj: Trajectory, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Error-free IMU samples averaging each interval ``(t[k-1], t[k]]`` (see the module notes).

    Parameters
    ----------
    traj : Trajectory
        Its grid must have step ``dt / 2`` and start at ``t[0] - dt``.
    t : ndarray, shape (N,)
        Uniform IMU times [s], interval ``dt``.

    Returns
    -------
    f_b : ndarray, shape (N, 3)
        Average specific force [m/s^2], body frame at mid-interval.
    omega_ib_b : ndarray, shape (N, 3)
        Inertial attitude increment over the interval as a rotation vector / dt [rad/s].
    """
    dt = 2.0 * traj.step
    kin = traj.grid_kinematics
    v_n, R_nb = kin.v_n, kin.R_nb
    lat, lon, h = traj.lat, traj.lon, traj.h
    # Interval k spans grid nodes 2k .. 2k+2 with its midpoint at 2k+1.
    a, m, b = slice(0, -2, 2), slice(1, -1, 2), slice(2, None, 2)
    # Attitude: C_{b(k-1)}^{b(k)} = R_nb(k-1)^T C_{n(k-1)}^{n(k)} R_nb(k), with the navigation-
    # frame increment C_{n(k-1)}^{n(k)} = R_en(k-1) Rz(Omega dt) R_en(k)^T (earth turns by
    # Omega dt about ECEF z while the vehicle moves over it).
    R_en = _R_en_batch(lat, lon)
    c, s = np.cos(OMEGA_IE * dt), np.sin(OMEGA_IE * dt)
    Rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    C_nn = R_en[a] @ Rz @ np.swapaxes(R_en[b], 1, 2)
    C_bb = np.swapaxes(R_nb[a], 1, 2) @ C_nn @ R_nb[b]
    omega_ib_b = _rotvec_batch(C_bb) / dt
    # Velocity: dv_n = integral(R_nb f_b) + integral(g_n - (2 w_ie + w_en) x v_n); the second,
    # smooth integral by Simpson's rule on the half-step grid.
    g_n = np.zeros_like(v_n)
    g_n[:, 2] = normal_gravity(lat, h)
    q_n = g_n - np.cross(2.0 * _earth_rate_batch(lat) + _transport_rate_batch(lat, h, v_n), v_n)
    dv_specific_n = v_n[b] - v_n[a] - dt / 6.0 * (q_n[a] + 4.0 * q_n[m] + q_n[b])
    f_b = np.einsum("kji,kj->ki", R_nb[m], dv_specific_n) / dt
    n = len(t)
    return f_b[:n], omega_ib_b[:n]


def build_trajectory(scenario: str | Scenario = "car", duration_s: float = 300.0, rate_hz: float = 100.0,
                     origin_llh_deg=(32.0, 34.8, 50.0), initial_yaw_deg: float = 30.0,
                     t_start_s: float = 0.0) -> Trajectory:
    """Place a scenario on the ellipsoid, integrated on a grid of step ``1 / (2 rate_hz)``.

    The grid spans ``[t_start_s - 1/rate_hz, t_start_s + duration_s]`` so that interval averages
    for IMU samples at ``rate_hz`` (including the first) can be formed.

    Parameters
    ----------
    scenario : str or Scenario
        A name in :data:`SCENARIOS` or a custom :class:`Scenario`.
    duration_s : float
        [s]
    rate_hz : float
        IMU rate the grid is made for [Hz].
    origin_llh_deg : (float, float, float)
        Start position: latitude, longitude [deg], ellipsoidal height [m].
    initial_yaw_deg : float
        Initial heading [deg from north, clockwise].
    t_start_s : float
        Absolute start time [s].

    Returns
    -------
    Trajectory
    """
    if not rate_hz > 0:
        raise InputError(WHERE, f"rate must be positive, got {rate_hz} Hz")
    scen = make_scenario(scenario, duration_s) if isinstance(scenario, str) else scenario
    dt = 1.0 / rate_hz
    lat, lon, h = origin_llh_deg
    return Trajectory(scen, (lat * DEG, lon * DEG, float(h)), initial_yaw_deg * DEG, t_start_s,
                      t_start_s - dt, t_start_s + duration_s, dt / 2.0)


def dense_truth(scenario: str | Scenario = "car", duration_s: float = 300.0, rate_hz: float = 100.0,
                origin_llh_deg=(32.0, 34.8, 50.0), initial_yaw_deg: float = 30.0,
                t_start_s: float = 0.0) -> TruthSamples:
    """The true trajectory sampled at ``rate_hz``, with instantaneous true ``f_b`` and ``omega_ib_b``.

    Parameters are those of :func:`build_trajectory`. Samples are at
    ``t_start_s + k / rate_hz`` for ``k = 0 .. floor(duration_s * rate_hz)``.

    Returns
    -------
    TruthSamples
        Position, NED velocity, acceleration, attitude and the instantaneous (not interval
        averaged) specific force and angular rate.
    """
    traj = build_trajectory(scenario, duration_s, rate_hz, origin_llh_deg, initial_yaw_deg, t_start_s)
    return traj.at(_imu_time(t_start_s, duration_s, rate_hz))


# ---------------------------------------------------------------------------------------------
# The recorded run
# ---------------------------------------------------------------------------------------------

def _initial_state(truth0: TruthSamples) -> InitialState:
    return InitialState(
        t=float(truth0.t[0]), lat=float(truth0.lat[0]), lon=float(truth0.lon[0]), h=float(truth0.h[0]),
        v_n=truth0.v_n[0].copy(), rpy=truth0.rpy[0].copy(),
        sigma_pos_m=np.array([1.0, 1.0, 1.5]), sigma_vel_mps=np.array([0.1, 0.1, 0.1]),
        sigma_att_rad=np.array([1.0, 1.0, 2.0]) * DEG, how="simulator truth (sigmas 1 m, 0.1 m/s, 1-2 deg)")


def simulate(scenario: str = "car", duration_s: float = 300.0, imu_grade: str = "industrial",
             imu_rate_hz: float = 100.0, gnss_rate_hz: float = 1.0, noise: str = "white", seed: int = 0,
             origin_llh_deg=(32.0, 34.8, 50.0), initial_yaw_deg: float = 30.0, lever_arm_b=(0.0, 0.0, 0.0),
             give_init: bool = False, imu_overrides: dict | None = None, truth_rate_hz: float | None = None,
             t_start_s: float = 0.0) -> RecordedRun:
    """Simulate a ground-vehicle run with known truth.

    Parameters
    ----------
    scenario : {"static", "ugv", "car", "straight", "turns"}
    duration_s : float
        Run length [s]; the IMU covers ``[t_start_s, t_start_s + duration_s]``.
    imu_grade : {"perfect", "consumer", "industrial", "tactical"}
        IMU error grade, see :data:`IMU_GRADES`.
    imu_rate_hz : float
        IMU rate [Hz]. Sample k is the average over ``(t[k-1], t[k]]``.
    gnss_rate_hz : float
        GNSS fix rate [Hz], at most the IMU rate; fixes at ``t_start_s + k / gnss_rate_hz``.
    noise : {"white", "gm", "none"}
        GNSS noise profile of :mod:`gnssacc.gnss_noise`.
    seed : int
        Seeds the IMU errors and (through an independent stream) the GNSS noise.
    origin_llh_deg : (float, float, float)
        Start latitude, longitude [deg] and ellipsoidal height [m] of the IMU.
    initial_yaw_deg : float
        Initial heading [deg].
    lever_arm_b : (float, float, float)
        GNSS antenna position relative to the IMU, body frame FRD [m]; fixes are of the antenna.
    give_init : bool
        Attach the true initial state (with 1 m / 0.1 m/s / 1-2 deg sigmas) as ``run.init``;
        otherwise the estimators self-initialise.
    imu_overrides : dict, optional
        Grade parameters to replace (keys of ``gnssacc.config.DEFAULTS["imu"]``).
    truth_rate_hz : float, optional
        Rate of ``run.truth`` [Hz]; by default the truth is at the GNSS epochs.
    t_start_s : float
        Absolute time of the first IMU sample [s].

    Returns
    -------
    RecordedRun
        ``name = "sim-<scenario>"``, ``where = "simulator(<scenario>, seed=<seed>)"``. ``meta``
        records every argument, the resolved IMU parameters (``imu_params``), the true biases per
        IMU sample ``true_bias_a`` [m/s^2] and ``true_bias_g`` [rad/s] (arrays (N, 3)), the
        scenario ``segments`` (times absolute) and the GNSS seed.
    """
    args = dict(scenario=scenario, duration_s=duration_s, imu_grade=imu_grade, imu_rate_hz=imu_rate_hz,
                gnss_rate_hz=gnss_rate_hz, noise=noise, seed=seed, origin_llh_deg=list(origin_llh_deg),
                initial_yaw_deg=initial_yaw_deg, lever_arm_b=list(lever_arm_b), give_init=give_init,
                imu_overrides=dict(imu_overrides or {}), truth_rate_hz=truth_rate_hz, t_start_s=t_start_s)
    where = f"simulator({scenario}, seed={seed})"
    params = grade_config(imu_grade, imu_overrides)
    if noise not in PROFILES:
        raise InputError(where, f"unknown GNSS noise profile {noise!r} (known: {', '.join(PROFILES)})")
    if not 0 < gnss_rate_hz <= imu_rate_hz:
        raise InputError(where, f"gnss_rate_hz must be positive and at most the IMU rate, got {gnss_rate_hz}")
    lever_b = np.asarray(lever_arm_b, float).reshape(3)

    traj = build_trajectory(scenario, duration_s, imu_rate_hz, origin_llh_deg, initial_yaw_deg, t_start_s)
    t_imu = _imu_time(t_start_s, duration_s, imu_rate_hz)
    f_b, omega_ib_b = perfect_imu(traj, t_imu)
    rng = np.random.default_rng([seed, 1])
    err = imu_errors(len(t_imu), 1.0 / imu_rate_hz, params, rng)
    imu = ImuData(t_imu, f_b + err["bias_a"] + err["noise_a"], omega_ib_b + err["bias_g"] + err["noise_g"])

    t_gnss = _imu_time(t_start_s, duration_s, gnss_rate_hz)
    truth_gnss = traj.at(t_gnss)
    truth = truth_gnss if truth_rate_hz is None else traj.at(_imu_time(t_start_s, duration_s, truth_rate_hz))
    origin = LocalTangentFrame(*(np.array(origin_llh_deg[:2], float) * DEG), float(origin_llh_deg[2]))
    gnss_seed = int(np.random.SeedSequence([seed, 2]).generate_state(1)[0])
    meta = {**args, "source": "simulator", "imu_params": params,
            "imu_sample_convention": "sample k = average over (t[k-1], t[k]]",
            "true_bias_a": err["bias_a"], "true_bias_g": err["bias_g"], "gnss_seed": gnss_seed,
            "segments": [{**s, "t0": s["t0"] + t_start_s, "t1": s["t1"] + t_start_s}
                         for s in traj.scenario.segments_until(duration_s)]}
    empty = GnssFixes(np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0), np.zeros((0, 3)))
    run = RecordedRun(name=f"sim-{scenario}", where=where, imu=imu, gnss=empty, origin=origin,
                      truth=truth.to_truth(), init=_initial_state(truth) if give_init else None, meta=meta)
    p_antenna_n = truth_gnss.R_nb @ lever_b
    fixes = fixes_from_truth(run, truth_gnss.to_truth(), noise, gnss_seed, p_antenna_n)
    return replace(run, gnss=fixes)
