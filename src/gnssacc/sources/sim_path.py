"""The simulator's truth: a scenario's path on the WGS-84 ellipsoid and its error-free IMU.

The conventions (frames, the integrating IMU's sample convention) are those of
:mod:`gnssacc.sources.sim`. The path is integrated on a uniform internal grid at twice the IMU
rate, swept in blocks of nodes: nothing of the size of the run is kept, and every number is the
same, bit for bit, as in one pass over the whole grid (the cumulative sums carry from block to
block; :func:`perfect_imu` and :meth:`Trajectory.position` read each block as it passes).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Iterator

import numpy as np

from ..core.earth import OMEGA_IE, R_en_batch, normal_gravity, radii
from ..core.errors import InputError
from ..core.recording import Truth
from ..core.rotations import wrap_angle
from ..core.units import DEG
from .sim_scenarios import Kinematics, Scenario, make_scenario

WHERE = "simulator"

#: IMU samples per block of the sweep (twice as many grid nodes; memory ~1 kB per sample in a block).
IMU_BLOCK = 8192


def _rotvec_batch(R) -> np.ndarray:
    """Rotation vectors of rotations with angle < pi, shape (K, 3).

    Uses atan2(|sin|, cos) rather than arccos so that tiny angles (earth rate over 10 ms is
    7e-7 rad) keep full relative precision.
    """
    w = 0.5 * np.stack(
        [R[:, 2, 1] - R[:, 1, 2], R[:, 0, 2] - R[:, 2, 0], R[:, 1, 0] - R[:, 0, 1]], -1
    )
    s = np.linalg.norm(w, axis=1)
    angle = np.arctan2(s, 0.5 * (np.trace(R, axis1=1, axis2=2) - 1.0))
    scale = np.where(s > 1e-300, angle / np.where(s > 1e-300, s, 1.0), 1.0)
    return w * scale[:, None]


def _earth_rate_batch(lat) -> np.ndarray:
    return OMEGA_IE * np.stack([np.cos(lat), np.zeros_like(lat), -np.sin(lat)], -1)


def _transport_rate_batch(lat, h, v_n) -> np.ndarray:
    R_M, R_N = radii(lat)
    return np.stack(
        [v_n[:, 1] / (R_N + h), -v_n[:, 0] / (R_M + h), -v_n[:, 1] * np.tan(lat) / (R_N + h)], -1
    )


def _cumulative(rate, rate_dot, h, start=None):
    """Cumulative integral on a uniform grid of step ``h``: trapezoid with the end-derivative
    (Euler-Maclaurin) correction, fourth order; from 0, or continuing a sweep from ``start``
    (the value at the block's first node, carried from the previous block)."""
    inc = 0.5 * h * (rate[1:] + rate[:-1]) + h * h / 12.0 * (rate_dot[:-1] - rate_dot[1:])
    if start is None:
        return np.concatenate([[0.0], np.cumsum(inc)])
    return np.cumsum(np.concatenate([[start], inc]))


def _hermite(u, h, y0, ydot0, y1, ydot1):
    """Cubic Hermite interpolation at ``u`` in [0, 1] between nodes 0 and 1, ``h`` apart."""
    u2, u3 = u * u, u * u * u
    return (
        (2 * u3 - 3 * u2 + 1) * y0
        + (u3 - 2 * u2 + u) * h * ydot0
        + (-2 * u3 + 3 * u2) * y1
        + (u3 - u2) * h * ydot1
    )


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
        """As a :class:`gnssacc.core.recording.Truth`."""
        return Truth(
            self.t.copy(),
            self.lat.copy(),
            self.lon.copy(),
            self.h.copy(),
            self.v_n.copy(),
            self.rpy.copy(),
        )


@dataclass
class GridBlock:
    """The path on grid nodes ``g0 .. g0 + len(t) - 1`` of a :class:`Trajectory` (one block of a sweep).

    Attributes
    ----------
    g0 : int
        Index of the block's first node in the whole grid.
    t : ndarray, shape (K,)
        Node times [s].
    kin : Kinematics
        Path kinematics at the nodes.
    v_n : ndarray, shape (K, 3)
        NED velocity [m/s].
    lat, lon, h, lat_dot, lon_dot, h_dot : ndarray, shape (K,)
        Geodetic position [rad, rad, m] and its rates [rad/s, rad/s, m/s].
    """

    g0: int
    t: np.ndarray
    kin: Kinematics
    v_n: np.ndarray
    lat: np.ndarray
    lon: np.ndarray
    h: np.ndarray
    lat_dot: np.ndarray
    lon_dot: np.ndarray
    h_dot: np.ndarray


class Trajectory:
    """A scenario placed on the WGS-84 ellipsoid, integrated on a uniform internal grid.

    The geodetic position is integrated from the analytic NED velocity with a fourth-order
    quadrature (``lat_dot = v_N / (R_M + h)``, ``lon_dot = v_E / ((R_N + h) cos lat)``,
    ``h_dot = -v_D``); velocity and attitude are analytic at any time, positions between grid
    nodes use cubic Hermite interpolation with the exact rates. The grid is not stored: each
    use sweeps it in blocks (:meth:`blocks`), so memory does not grow with the run.

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

    def __init__(
        self,
        scenario: Scenario,
        origin_llh,
        yaw0: float,
        t_start: float,
        t_lo: float,
        t_hi: float,
        step: float,
    ):
        self.scenario, self.yaw0, self.t_start = scenario, float(yaw0), float(t_start)
        self.lat0, self.lon0, self.h0 = (float(x) for x in origin_llh)
        #: Number of grid nodes; node j is at ``grid_t0 + step * j`` [s].
        self.n_grid = int(np.ceil((t_hi - t_lo) / step - 1e-6)) + 1
        self.grid_t0, self.step = float(t_lo), float(step)
        # The node of t_start, where the integrals are anchored to the origin.
        self.i0 = int(round((self.t_start - self.grid_t0) / self.step))

    def blocks(self, samples: int | None = None) -> Iterator[GridBlock]:
        """Sweep the grid in blocks of ``2 samples`` node intervals (default :data:`IMU_BLOCK`), each
        overlapping the next by one node. The first block reaches at least one node past
        ``t_start`` (the integrals' anchor); the last one takes the rest when it would hold fewer
        than two IMU samples.
        """
        samples = IMU_BLOCK if samples is None else int(samples)
        g0, ended, carry = 0, None, None
        first_end = max(2 * samples, self.i0 + 1 + (self.i0 + 1) % 2)
        while True:
            g1 = first_end if g0 == 0 else g0 + 2 * samples
            # No block of a single IMU sample: numpy multiplies one row by a matrix in another way
            # (gemv, not gemm), one ulp apart from the one-pass product of the sensor matrices.
            g1 = self.n_grid - 1 if g1 > self.n_grid - 5 else g1
            t = self.grid_t0 + self.step * np.arange(g0, g1 + 1)
            kin, ended = self.scenario.kinematics_block(t - self.t_start, self.yaw0, ended)
            v_n = kin.v_n
            position, carry = self._integrate(v_n, kin.a_n, carry)
            yield GridBlock(g0, t, kin, v_n, *position)
            if g1 == self.n_grid - 1:
                return
            g0 = g1

    def _integrate(self, v_n, a_n, carry):
        """Geodetic position and rates on one block; ``carry``: the cumulative integrals at its first
        node and their values at ``t_start`` (``None`` for the first block). Returns them for the next."""
        first, nxt = carry is None, {}

        def anchored(name, rate, rate_dot, value0):
            c = _cumulative(rate, rate_dot, self.step, None if first else carry[name][0])
            anchor = c[self.i0] if first else carry[name][1]
            nxt[name] = (c[-1], anchor)
            return value0 + c - anchor

        v_N, v_E, v_D = v_n.T
        a_N, a_E, a_D = a_n.T
        h = anchored("h", -v_D, -a_D, self.h0)
        lat = np.full(len(h), self.lat0)
        # lat enters through the radii only; a few fixed-point passes converge to round-off.
        for p in range(3):
            R_M, _ = radii(lat)
            lat_dot = v_N / (R_M + h)
            lat_ddot = a_N / (R_M + h) + v_N * v_D / (R_M + h) ** 2
            lat = anchored(f"lat{p}", lat_dot, lat_ddot, self.lat0)
        R_M, R_N = radii(lat)
        lat_dot = v_N / (R_M + h)
        cl = np.cos(lat)
        lon_dot = v_E / ((R_N + h) * cl)
        lon_ddot = (
            a_E / ((R_N + h) * cl)
            + v_E * v_D / ((R_N + h) ** 2 * cl)
            + v_E * np.sin(lat) * lat_dot / ((R_N + h) * cl * cl)
        )
        lon = anchored("lon", lon_dot, lon_ddot, self.lon0)
        return (lat, lon, h, lat_dot, lon_dot, -v_D), nxt

    def sweep(self, queries=(), on_block: Callable[[GridBlock], None] | None = None) -> list[tuple]:
        """Sweep the grid once: call ``on_block`` on every block, interpolate the positions at the query times.

        Parameters
        ----------
        queries : sequence of ndarray
            Absolute times [s] within the grid's span, any order.
        on_block : callable, optional
            Called with each :class:`GridBlock` in time order. Without it the sweep stops after
            the last block a query needs.

        Returns
        -------
        list of (lat, lon, h)
            Per query array: geodetic positions [rad, rad, m].
        """
        plans, out = [], []
        for t in queries:
            t = np.atleast_1d(np.asarray(t, float))
            self._check_span(t)
            i = np.clip(np.floor((t - self.grid_t0) / self.step).astype(int), 0, self.n_grid - 2)
            u = (t - (self.grid_t0 + i * self.step)) / self.step
            order = np.argsort(i, kind="stable")
            plans.append((i[order], u[order], order))
            out.append(np.empty((3, len(t))))
        last = max((p[0][-1] for p in plans if len(p[0])), default=-1)
        for block in self.blocks():
            if on_block is not None:
                on_block(block)
            g1 = block.g0 + len(block.t) - 1
            for (i, u, order), res in zip(plans, out):
                a, b = np.searchsorted(i, [block.g0, g1])  # node pairs (i, i + 1) inside the block
                j = i[a:b] - block.g0
                for row, (y, yd) in enumerate(
                    ((block.lat, block.lat_dot), (block.lon, block.lon_dot), (block.h, block.h_dot))
                ):
                    res[row, order[a:b]] = _hermite(
                        u[a:b], self.step, y[j], yd[j], y[j + 1], yd[j + 1]
                    )
            if on_block is None and g1 > last:
                break
        return [tuple(r) for r in out]

    def _check_span(self, t) -> None:
        t_last = self.grid_t0 + self.step * float(self.n_grid - 1)
        if t.min() < self.grid_t0 - 1e-9 or t.max() > t_last + 1e-9:
            raise InputError(
                WHERE,
                f"truth requested at {t.min():.3f}..{t.max():.3f} s, outside the simulated "
                f"span {self.grid_t0:.3f}..{t_last:.3f} s",
            )

    def kinematics(self, t) -> Kinematics:
        """Analytic path kinematics at absolute times ``t`` [s] (sorted)."""
        return self.scenario.kinematics(np.asarray(t, float) - self.t_start, self.yaw0)

    def position(self, t):
        """Geodetic position (lat, lon [rad], h [m]) at absolute times ``t`` [s] (one sweep)."""
        return self.sweep([t])[0]

    def at(self, t, position=None) -> TruthSamples:
        """Full truth (state and instantaneous IMU signals) at sorted absolute times ``t`` [s].

        ``position``: the (lat, lon, h) at ``t`` when already known (from a :meth:`sweep`).
        """
        t = np.atleast_1d(np.asarray(t, float))
        lat, lon, h = self.position(t) if position is None else position
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


def sample_times(t_start: float, duration_s: float, rate_hz: float) -> np.ndarray:
    """Sample times ``t_start + k / rate_hz`` [s], ``k = 0 .. floor(duration_s * rate_hz)``."""
    # k / rate (not k * dt) so that epochs of commensurate rates coincide bit for bit.
    n = int(np.floor(duration_s * rate_hz + 1e-9)) + 1
    return t_start + np.arange(n) / rate_hz


def sweep_imu(traj: Trajectory, n: int, on_samples: Callable, queries=()) -> list[tuple]:
    """One sweep of ``traj``: the error-free IMU of samples ``0 .. n-1`` block by block, and positions.

    Parameters
    ----------
    traj : Trajectory
        Its grid must have step ``dt / 2`` and start at ``t[0] - dt`` (:func:`build_trajectory`).
    n : int
        Number of IMU samples.
    on_samples : callable
        ``on_samples(k0, k1, f_b, omega_ib_b, speed_mid)`` for samples ``k0 .. k1-1`` in order:
        see :func:`perfect_imu`; ``speed_mid`` is the signed speed at each interval's midpoint [m/s].
    queries : sequence of ndarray
        Times [s] of :meth:`Trajectory.sweep`.

    Returns
    -------
    list of (lat, lon, h)
        The positions at the query times (:meth:`Trajectory.sweep`).
    """
    done = [0]

    def on_block(block: GridBlock) -> None:
        k0, k1 = block.g0 // 2, min((block.g0 + len(block.t) - 1) // 2, n)
        if k1 > k0:
            f_b, omega_ib_b = _perfect_imu_block(block, 2 * (k1 - k0) + 1, 2.0 * traj.step)
            on_samples(k0, k1, f_b, omega_ib_b, block.kin.speed[1 : 2 * (k1 - k0) : 2])
            done[0] = k1

    positions = traj.sweep(queries, on_block)
    if done[0] != n:
        raise InputError(WHERE, f"the trajectory's grid covers {done[0]} of {n} IMU samples")
    return positions


def perfect_imu(traj: Trajectory, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Error-free IMU samples averaging each interval ``(t[k-1], t[k]]`` (see :mod:`gnssacc.sources.sim`).

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

    def keep(k0, k1, f, w, _speed_mid):
        f_b[k0:k1], omega_ib_b[k0:k1] = f, w

    sweep_imu(traj, n, keep)
    return f_b, omega_ib_b


def _perfect_imu_block(block: GridBlock, m: int, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """:func:`perfect_imu` of the intervals within the block's first ``m`` nodes (``m`` odd)."""
    v_n, R_nb = block.v_n[:m], block.kin.R_nb[:m]
    lat, lon, h = block.lat[:m], block.lon[:m], block.h[:m]
    # Interval k spans grid nodes 2k .. 2k+2 with its midpoint at 2k+1.
    a, mid, b = slice(0, -2, 2), slice(1, -1, 2), slice(2, None, 2)
    # Attitude: C_{b(k-1)}^{b(k)} = R_nb(k-1)^T C_{n(k-1)}^{n(k)} R_nb(k), with the navigation-
    # frame increment C_{n(k-1)}^{n(k)} = R_en(k-1) Rz(Omega dt) R_en(k)^T (earth turns by
    # Omega dt about ECEF z while the vehicle moves over it).
    R_en = R_en_batch(lat, lon)
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
    dv_specific_n = v_n[b] - v_n[a] - dt / 6.0 * (q_n[a] + 4.0 * q_n[mid] + q_n[b])
    f_b = np.einsum("kji,kj->ki", R_nb[mid], dv_specific_n) / dt
    return f_b, omega_ib_b


def build_trajectory(
    scenario: str | Scenario = "car",
    duration_s: float = 300.0,
    rate_hz: float = 100.0,
    origin_llh_deg=(32.0, 34.8, 50.0),
    initial_yaw_deg: float = 30.0,
    t_start_s: float = 0.0,
) -> Trajectory:
    """Place a scenario on the ellipsoid, integrated on a grid of step ``1 / (2 rate_hz)``.

    The grid spans ``[t_start_s - 1/rate_hz, t_start_s + duration_s]`` so that interval averages
    for IMU samples at ``rate_hz`` (including the first) can be formed.

    Parameters
    ----------
    scenario : str or Scenario
        A name in :data:`gnssacc.sources.sim_scenarios.SCENARIOS` or a custom :class:`Scenario`.
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
    return Trajectory(
        scen,
        (lat * DEG, lon * DEG, float(h)),
        initial_yaw_deg * DEG,
        t_start_s,
        t_start_s - dt,
        t_start_s + duration_s,
        dt / 2.0,
    )


def dense_truth(
    scenario: str | Scenario = "car",
    duration_s: float = 300.0,
    rate_hz: float = 100.0,
    origin_llh_deg=(32.0, 34.8, 50.0),
    initial_yaw_deg: float = 30.0,
    t_start_s: float = 0.0,
) -> TruthSamples:
    """The true trajectory sampled at ``rate_hz``, with instantaneous true ``f_b`` and ``omega_ib_b``.

    Parameters are those of :func:`build_trajectory`. Samples are at
    ``t_start_s + k / rate_hz`` for ``k = 0 .. floor(duration_s * rate_hz)``.

    Returns
    -------
    TruthSamples
        Position, NED velocity, acceleration, attitude and the instantaneous (not interval
        averaged) specific force and angular rate.
    """
    traj = build_trajectory(
        scenario, duration_s, rate_hz, origin_llh_deg, initial_yaw_deg, t_start_s
    )
    return traj.at(sample_times(t_start_s, duration_s, rate_hz))
