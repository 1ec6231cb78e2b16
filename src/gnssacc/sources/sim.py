"""Ground-vehicle simulator: scenarios with known truth, WGS-84-consistent IMU, GNSS fixes.

The simulator produces :class:`gnssacc.recording.RecordedRun` objects for tests of the estimators.
Its parts: :mod:`.sim_scenarios` (speed / yaw / pitch profiles), this module (the path on the
ellipsoid, the error-free IMU, the run), :mod:`.sim_imu_errors` (grades and IMU errors) and
:mod:`.sim_vibration` (engine and road vibration). Their public names are re-exported here.

Conventions
-----------
* Body frame b is Front-Right-Down, navigation frame n is North-East-Down, ``R_nb`` maps body
  vectors into n, Euler angles are Z-Y-X roll/pitch/yaw [rad], SI units throughout.
* The vehicle has no side slip: body x points along the velocity (against it when reversing,
  at negative speed), pitch follows the slope of the path, roll is zero, yaw is the heading of
  body x. ``v_n = R_nb @ [speed, 0, 0]`` with a signed speed.
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
* The measured IMU adds the errors of the grade to these averages, per sensor triad
  ``(I + S + M) true + bias + white noise + vibration`` (:mod:`.sim_imu_errors`); the vibration
  is itself averaged over each interval (:mod:`.sim_vibration`).
"""
from __future__ import annotations

from dataclasses import dataclass, fields, replace

import numpy as np

from ..earth import LocalTangentFrame, OMEGA_IE, normal_gravity, radii
from ..errors import InputError
from ..gnss_noise import PROFILES, fixes_from_truth
from ..memory import release_free_memory
from ..rotations import wrap_angle
from ..recording import GnssFixes, ImuData, InitialState, RecordedRun, SimTruth, Truth
from .sim_imu_errors import (GRADE_KEYS, IMU_EXTRA_ERRORS, IMU_GRADES, MODEL_KEYS,  # noqa: F401 (re-exported)
                             UNMODELLED_KEYS, VIBRATION_ENVIRONMENT, per_axis, bias_drift, gauss_markov,
                             grade_config, imu_error_model, imu_errors, imu_sigmas_si, sensor_matrices)
from .sim_scenarios import (SCENARIOS, Kinematics, Pulse, Scenario, R_nb_batch,  # noqa: F401 (re-exported)
                            make_scenario, reversing_spans)
from .sim_vibration import engine_vibration, road_vibration

DEG = np.pi / 180.0
WHERE = "simulator"

# ---------------------------------------------------------------------------------------------
# Geodetic truth trajectory
# ---------------------------------------------------------------------------------------------


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
        """As a :class:`gnssacc.recording.Truth`."""
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
    n = len(t)
    f_b, omega_ib_b = np.empty((n, 3)), np.empty((n, 3))
    # In blocks of samples: the per-interval temporaries (rotation stacks) stay small whatever
    # the run length; every sample's arithmetic is the same as in one pass.
    for k0 in range(0, n, IMU_BLOCK):
        k1 = min(k0 + IMU_BLOCK, n)
        f_b[k0:k1], omega_ib_b[k0:k1] = _perfect_imu_block(traj, 2 * k0, 2 * k1 + 1)
    return f_b, omega_ib_b


#: IMU samples per block of :func:`perfect_imu` (memory ~1 kB per sample in a block).
IMU_BLOCK = 50_000


def _perfect_imu_block(traj: Trajectory, g0: int, g1: int) -> tuple[np.ndarray, np.ndarray]:
    """:func:`perfect_imu` of the intervals within grid nodes ``[g0, g1)`` (``g0`` even)."""
    dt = 2.0 * traj.step
    full = traj.grid_kinematics   # its v_n and R_nb are computed on access: take the block first
    kin = Kinematics(*(getattr(full, f.name)[g0:g1] for f in fields(Kinematics)))
    v_n, R_nb = kin.v_n, kin.R_nb
    lat, lon, h = traj.lat[g0:g1], traj.lon[g0:g1], traj.h[g0:g1]
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
    return f_b, omega_ib_b


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


def _nonzero(model: dict, *keys: str) -> bool:
    return any(np.any(np.asarray(model[k], float) != 0.0) for k in keys)


def unmodelled_errors(model: dict, t: np.ndarray, dt: float, speed_mid: np.ndarray, seed: int) -> dict:
    """Draw the errors a filter does not model: scale factor and cross-axis, bias drift, vibration.

    Each source draws from its own stream ``numpy.random.default_rng([seed, 3, i])`` (i = 0
    sensor matrices, 1 drift, 2 engine vibration, 3 road vibration), independent of the stream
    ``[seed, 1]`` of :func:`imu_errors`, so adding or changing one source leaves the others and
    the basic errors unchanged. A source whose magnitudes are all zero is skipped.

    Parameters
    ----------
    model : dict
        :func:`imu_error_model`.
    t : ndarray, shape (n,)
        IMU times [s].
    dt : float
        IMU interval [s].
    speed_mid : ndarray, shape (n,)
        Signed speed at the midpoint of each sample interval [m/s].
    seed : int

    Returns
    -------
    dict
        ``K_a``, ``K_g`` (3 x 3 or None for the identity), ``drift_a`` [m/s^2], ``drift_g``
        [rad/s], ``vib_a`` [m/s^2], ``vib_g`` [rad/s] (shape (n, 3) or None for zero) and
        ``draws``: the per-run constants (see :func:`sensor_matrices`, :func:`bias_drift`,
        :func:`gnssacc.sources.sim_vibration.engine_vibration`; zeros for skipped sources).
    """
    out = dict.fromkeys(("K_a", "K_g", "drift_a", "drift_g", "vib_a", "vib_g"))
    draws = {"accel_scale_factor": np.zeros(3), "gyro_scale_factor": np.zeros(3),
             "accel_cross_axis": np.zeros((3, 3)), "gyro_cross_axis": np.zeros((3, 3)),
             "accel_warmup": np.zeros(3), "gyro_warmup": np.zeros(3)}
    stream = [np.random.default_rng([seed, 3, i]) for i in range(4)]
    if _nonzero(model, "accel_scale_factor_ppm", "gyro_scale_factor_ppm", "accel_cross_axis_ppm",
                "gyro_cross_axis_ppm"):
        m = sensor_matrices(model, stream[0])
        out["K_a"], out["K_g"] = m.pop("K_a"), m.pop("K_g")
        draws.update(m)
    if _nonzero(model, "accel_warmup_mg", "gyro_warmup_deg_h", "accel_bias_rw_mg_rth", "gyro_bias_rw_deg_h_rth"):
        d = bias_drift(t - t[0], model, stream[1])
        out["drift_a"], out["drift_g"] = d.pop("drift_a"), d.pop("drift_g")
        draws.update(d)
    vib = []
    if _nonzero(model, "vib_engine_accel_mps2", "vib_engine_gyro_dps") and _nonzero(model, "vib_engine_harmonics"):
        e = engine_vibration(speed_mid, dt, model, stream[2])
        vib.append((e.pop("vib_a"), e.pop("vib_g")))
        draws.update(e)
    if _nonzero(model, "vib_road_accel_mps2", "vib_road_gyro_dps"):
        r = road_vibration(speed_mid, dt, model, stream[3])
        vib.append((r["vib_a"], r["vib_g"]))
    if vib:
        out["vib_a"], out["vib_g"] = sum(v[0] for v in vib), sum(v[1] for v in vib)
    out["draws"] = draws
    return out


def _measure(true: np.ndarray, K, bias: np.ndarray, noise: np.ndarray, vib) -> np.ndarray:
    """``K true + bias + noise + vib`` (the basic grades' ``true + bias + noise``, bit for bit)."""
    out = (true if K is None else true @ K.T) + bias + noise
    if vib is not None:
        out += vib
    return out


def simulate_imu(traj: Trajectory, t: np.ndarray, model: dict, seed: int) -> tuple[ImuData, dict]:
    """The measured IMU of a run: perfect interval averages plus every error of ``model``.

    Parameters
    ----------
    traj : Trajectory
        As from :func:`build_trajectory` for the IMU rate.
    t : ndarray, shape (n,)
        IMU times [s].
    model : dict
        :func:`imu_error_model`.
    seed : int
        The filter-visible errors (:func:`imu_errors`) draw from ``default_rng([seed, 1])`` as
        they always have; the others as in :func:`unmodelled_errors`.

    Returns
    -------
    ImuData
    dict
        ``true_bias_a`` [m/s^2], ``true_bias_g`` [rad/s] (turn-on + Gauss-Markov + drift per
        sample, shape (n, 3)) and ``imu_error_draws`` (per-run constants: ``accel_turn_on_bias``
        [m/s^2], ``gyro_turn_on_bias`` [rad/s] and those of :func:`unmodelled_errors`).
    """
    dt = 2.0 * traj.step
    f_b, omega_ib_b = perfect_imu(traj, t)
    err = imu_errors(len(t), dt, model, np.random.default_rng([seed, 1]))
    extra = unmodelled_errors(model, t, dt, traj.grid_kinematics.speed[1::2][:len(t)], seed)
    bias_a = err["bias_a"] if extra["drift_a"] is None else err["bias_a"] + extra["drift_a"]
    bias_g = err["bias_g"] if extra["drift_g"] is None else err["bias_g"] + extra["drift_g"]
    imu = ImuData(t, _measure(f_b, extra["K_a"], bias_a, err["noise_a"], extra["vib_a"]),
                  _measure(omega_ib_b, extra["K_g"], bias_g, err["noise_g"], extra["vib_g"]))
    draws = {"accel_turn_on_bias": err["turn_on_a"], "gyro_turn_on_bias": err["turn_on_g"], **extra["draws"]}
    return imu, {"true_bias_a": bias_a, "true_bias_g": bias_g, "imu_error_draws": draws}


def simulate(scenario: str | Scenario = "car", duration_s: float = 300.0, imu_grade: str = "industrial",
             imu_rate_hz: float = 100.0, gnss_rate_hz: float = 1.0, noise: str = "white", seed: int = 0,
             origin_llh_deg=(32.0, 34.8, 50.0), initial_yaw_deg: float = 30.0, lever_arm_b=(0.0, 0.0, 0.0),
             give_init: bool = False, imu_overrides: dict | None = None, truth_rate_hz: float | None = None,
             t_start_s: float = 0.0) -> RecordedRun:
    """Simulate a ground-vehicle run with known truth.

    Parameters
    ----------
    scenario : str or Scenario
        A name in :data:`SCENARIOS` ("static", "ugv", "car", "straight", "turns", "ugv-slow",
        "car-city") or a custom :class:`Scenario`.
    duration_s : float
        Run length [s]; the IMU covers ``[t_start_s, t_start_s + duration_s]``.
    imu_grade : str
        IMU error grade, a key of :data:`IMU_GRADES`: "perfect", the realistic "consumer",
        "industrial", "tactical" (with vibration, scale-factor, cross-axis and drift errors), or
        the original "consumer-basic", "industrial-basic", "tactical-basic". See
        :func:`imu_error_model`.
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
        Error parameters to replace: keys of ``gnssacc.config.DEFAULTS["imu"]`` or any other key
        of :func:`imu_error_model` (e.g. ``{"vib_road_gyro_dps": 0.0}``).
    truth_rate_hz : float, optional
        Rate of ``run.truth`` [Hz]; by default the truth is at the GNSS epochs.
    t_start_s : float
        Absolute time of the first IMU sample [s].

    Returns
    -------
    RecordedRun
        ``name = "sim-<scenario>"``, ``where = "simulator(<scenario>, seed=<seed>)"``. ``meta``
        records every argument and the GNSS seed; ``sim`` (:class:`gnssacc.recording.SimTruth`) the
        filter-visible IMU parameters (``imu_params``, as :func:`grade_config`), the full error
        description (``imu_error_model``), the per-run error draws (``imu_error_draws``, small
        arrays), the true biases per IMU sample ``true_bias_a`` [m/s^2] and ``true_bias_g``
        [rad/s] (arrays (N, 3)) and the scenario ``segments`` (times absolute; ``reverse`` marks
        reversing).
    """
    args = dict(scenario=scenario, duration_s=duration_s, imu_grade=imu_grade, imu_rate_hz=imu_rate_hz,
                gnss_rate_hz=gnss_rate_hz, noise=noise, seed=seed, origin_llh_deg=list(origin_llh_deg),
                initial_yaw_deg=initial_yaw_deg, lever_arm_b=list(lever_arm_b), give_init=give_init,
                imu_overrides=dict(imu_overrides or {}), truth_rate_hz=truth_rate_hz, t_start_s=t_start_s)
    name = scenario if isinstance(scenario, str) else scenario.name
    args["scenario"] = name
    where = f"simulator({name}, seed={seed})"
    model = imu_error_model(imu_grade, imu_overrides)
    if noise not in PROFILES:
        raise InputError(where, f"unknown GNSS noise profile {noise!r} (known: {', '.join(PROFILES)})")
    if not 0 < gnss_rate_hz <= imu_rate_hz:
        raise InputError(where, f"gnss_rate_hz must be positive and at most the IMU rate, got {gnss_rate_hz}")
    lever_b = np.asarray(lever_arm_b, float).reshape(3)

    traj = build_trajectory(scenario, duration_s, imu_rate_hz, origin_llh_deg, initial_yaw_deg, t_start_s)
    release_free_memory()   # the integration's temporaries, before the IMU's
    imu, imu_info = simulate_imu(traj, _imu_time(t_start_s, duration_s, imu_rate_hz), model, seed)
    release_free_memory()

    t_gnss = _imu_time(t_start_s, duration_s, gnss_rate_hz)
    truth_gnss = traj.at(t_gnss)
    truth = truth_gnss if truth_rate_hz is None else traj.at(_imu_time(t_start_s, duration_s, truth_rate_hz))
    origin = LocalTangentFrame(*(np.array(origin_llh_deg[:2], float) * DEG), float(origin_llh_deg[2]))
    gnss_seed = int(np.random.SeedSequence([seed, 2]).generate_state(1)[0])
    meta = {**args, "source": "simulator", "imu_sample_convention": "sample k = average over (t[k-1], t[k]]",
            "gnss_seed": gnss_seed}
    truths = _sim_truth(traj, imu_info, model, duration_s, t_start_s)
    empty = GnssFixes(np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0), np.zeros((0, 3)))
    run = RecordedRun(name=f"sim-{name}", where=where, imu=imu, gnss=empty, origin=origin,
                      truth=truth.to_truth(), init=_initial_state(truth) if give_init else None, sim=truths, meta=meta)
    p_antenna_n = truth_gnss.R_nb @ lever_b
    fixes = fixes_from_truth(run, truth_gnss.to_truth(), noise, gnss_seed, p_antenna_n)
    return replace(run, gnss=fixes)


def _sim_truth(traj: Trajectory, imu_info: dict, model: dict, duration_s: float, t_start_s: float) -> SimTruth:
    """The run's :class:`SimTruth`: true biases and draws (:func:`simulate_imu`), the scenario log
    with absolute times, the grade's filter-visible parameters and the full error model."""
    segments = [{**s, "t0": s["t0"] + t_start_s, "t1": s["t1"] + t_start_s} for s in traj.scenario.segments_until(duration_s)]
    return SimTruth(imu_info["true_bias_a"], imu_info["true_bias_g"], segments, imu_info["imu_error_draws"],
                    {k: model[k] for k in GRADE_KEYS}, model)
