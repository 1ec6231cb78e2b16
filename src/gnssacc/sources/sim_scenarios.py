"""Scenarios of the ground-vehicle simulator: smooth speed / yaw / pitch profiles built from segments.

A :class:`Scenario` is a path in a local, flat description (speed along body x, yaw, pitch as
functions of time); :mod:`gnssacc.sources.sim` places it on the WGS-84 ellipsoid.

Conventions: body frame FRD, navigation frame NED, ``R_nb`` maps body to nav, SI units and
radians. The vehicle has no side slip: ``v_n = speed * (body x axis in n)``. The speed is signed:
a negative speed drives backwards (body x points opposite to the velocity). Roll is zero.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.errors import InputError
from ..core.units import DEG

WHERE = "simulator"

# Smooth pulses: the building block of every kinematic channel


def _step(x):
    """Quintic smoothstep S(x) on [0, 1] (C2: zero first and second derivative at both ends)."""
    return x * x * x * (10.0 - 15.0 * x + 6.0 * x * x)


def _step_d(x):
    """dS/dx."""
    return 30.0 * x * x * (1.0 - x) ** 2


def _step_int(x):
    """Integral of S from 0 to x, for x in [0, 1] (equals 1/2 at x = 1)."""
    return x**4 * (2.5 - 3.0 * x + x * x)


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


def _support(p: Pulse, t: np.ndarray):
    """Index range ``[i0, i1)`` of the samples ``t0 < t <= t0 + duration`` of pulse ``p`` (found by
    bisection, so the cost stays linear in the number of samples) and its two step arguments there."""
    te = p.t0 + p.duration
    i0, i1 = np.searchsorted(t, [p.t0, te], side="right")
    tt = t[i0:i1]
    # Rising step at t0, falling step at te - ramp; the pulse is their difference.
    x1 = np.clip((tt - p.t0) / p.ramp, 0.0, 1.0)
    x2 = np.clip((tt - (te - p.ramp)) / p.ramp, 0.0, 1.0)
    return i0, i1, tt, x1, x2


def _channel(pulses: list[Pulse], t: np.ndarray, kind: str) -> np.ndarray:
    """Sum of pulses at sorted times ``t``: ``kind`` = "value", "rate" (d/dt) or "integral"."""
    if kind == "integral":
        return _integral(pulses, t)[0]
    out = np.zeros(len(t))
    for p in pulses:
        i0, i1, _, x1, x2 = _support(p, t)
        if kind == "value":
            out[i0:i1] += p.amplitude * (_step(x1) - _step(x2))
        else:
            out[i0:i1] += p.amplitude / p.ramp * (_step_d(x1) - _step_d(x2))
    return out


def _integral(
    pulses: list[Pulse], t: np.ndarray, ended: float | None = None
) -> tuple[np.ndarray, float]:
    """Integral of the pulses from -inf to the sorted times ``t``, evaluable block by block.

    ``ended`` is the summed area of the pulses that ended before ``t[0]`` as the previous block
    returned it (``None``: the first block, summed here). The areas are summed in the same order
    whatever the blocks, so a sweep in blocks that overlap by one sample gives the one-pass
    numbers bit for bit.

    Returns
    -------
    ndarray, shape (len(t),)
        The integral (unit of the channel x s).
    float
        The summed area of the pulses that ended before ``t[-1]``: ``ended`` of the next block.
    """
    out = np.zeros(len(t))
    tail = np.zeros(len(t) + 1)
    for p in pulses:
        i0, i1, tt, x1, x2 = _support(p, t)
        te = p.t0 + p.duration
        int1 = p.ramp * _step_int(x1) + np.maximum(tt - p.t0 - p.ramp, 0.0)
        int2 = p.ramp * _step_int(x2) + np.maximum(tt - te, 0.0)
        out[i0:i1] += p.amplitude * (int1 - int2)
        tail[i1] += p.area
    if ended is not None:
        tail[0] = ended
    done = np.cumsum(tail[:-1])
    out += done
    return out, float(done[-1]) if len(t) else (ended or 0.0)


# Scenarios


@dataclass
class Kinematics:
    """Path kinematics at given times (before geodetic integration).

    Attributes
    ----------
    speed, accel : ndarray
        Signed speed along body x [m/s] (negative: reversing) and its rate [m/s^2].
    yaw, yaw_rate : ndarray
        Yaw = heading of body x [rad] (not wrapped; the course when driving forwards, the course
        + pi when reversing) and its rate [rad/s].
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
        return R_nb_batch(self.pitch, self.yaw)

    @property
    def v_n(self) -> np.ndarray:
        """NED velocity [m/s], shape (K, 3): signed speed along body x (reversing: opposite to x)."""
        cp, sp, cy, sy = np.cos(self.pitch), np.sin(self.pitch), np.cos(self.yaw), np.sin(self.yaw)
        return self.speed[:, None] * np.stack([cp * cy, cp * sy, -sp], axis=1)

    @property
    def a_n(self) -> np.ndarray:
        """Time derivative of the NED velocity components [m/s^2], shape (K, 3)."""
        cp, sp, cy, sy = np.cos(self.pitch), np.sin(self.pitch), np.cos(self.yaw), np.sin(self.yaw)
        u = np.stack([cp * cy, cp * sy, -sp], axis=1)
        du_dpitch = np.stack([-sp * cy, -sp * sy, -cp], axis=1)
        du_dyaw = np.stack([-cp * sy, cp * cy, np.zeros_like(cp)], axis=1)
        return self.accel[:, None] * u + self.speed[:, None] * (
            self.pitch_rate[:, None] * du_dpitch + self.yaw_rate[:, None] * du_dyaw
        )

    @property
    def omega_nb_b(self) -> np.ndarray:
        """Body rate w.r.t. the navigation frame, body axes [rad/s] (Z-Y-X rates, roll 0)."""
        return np.stack(
            [
                -self.yaw_rate * np.sin(self.pitch),
                self.pitch_rate,
                self.yaw_rate * np.cos(self.pitch),
            ],
            axis=1,
        )


class Scenario:
    """A ground-vehicle path built from segments, evaluated analytically at any time.

    Segments are appended in time order; every transition is a quintic smooth ramp, so
    acceleration and angular rate are continuous. Times are relative to the scenario start (0).
    The speed is signed: a negative speed drives backwards (body x opposite to the velocity), and
    every segment works while reversing.

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
        ``{"kind", "t0", "t1", "reverse", ...}`` per segment (kinds: hold, cruise, speed, turn,
        hill). ``reverse`` is True when the speed is negative somewhere in the segment (a
        reversing vehicle; the kinds keep their meaning, e.g. "cruise" backwards is straight).
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
        self._spans: dict[int, tuple] = {}  # start and end times of each pulse list, for sweeps

    def _log(self, kind: str, duration: float, reverse: bool | None = None, **info) -> "Scenario":
        info = {k: float(v) for k, v in info.items()}
        reverse = self.speed < 0.0 if reverse is None else reverse
        self.segments.append(
            {
                "kind": kind,
                "t0": self.t_end,
                "t1": self.t_end + float(duration),
                "reverse": bool(reverse),
                **info,
            }
        )
        self.t_end += float(duration)
        return self

    def cruise(self, duration_s: float) -> "Scenario":
        """Straight at the current speed for ``duration_s`` [s]: stationary at 0, backwards if negative."""
        return self._log("hold" if self.speed == 0.0 else "cruise", duration_s, speed=self.speed)

    def hold(self, duration_s: float) -> "Scenario":
        """Stand still for ``duration_s`` [s] (the speed must already be 0)."""
        if self.speed != 0.0:
            raise InputError(
                WHERE, f"{self.name}: hold() needs speed 0, the vehicle moves at {self.speed} m/s"
            )
        return self._log("hold", duration_s, speed=0.0)

    def speed_to(self, speed_mps: float, duration_s: float, ramp_s: float = 1.0) -> "Scenario":
        """Change the signed speed to ``speed_mps`` [m/s] over ``duration_s`` [s] along a straight line.

        The acceleration is a smooth trapezoid with ``ramp_s`` [s] ramps (jerk-limited). A
        negative target drives backwards; the segment is marked ``reverse`` if either end is
        negative.
        """
        ramp = min(ramp_s, duration_s / 2.0)
        accel = (speed_mps - self.speed) / (duration_s - ramp)
        self._accel.append(Pulse(self.t_end, duration_s, ramp, accel))
        info = {"speed_from": self.speed, "speed": float(speed_mps), "accel": accel}
        reverse = min(self.speed, float(speed_mps)) < 0.0
        self.speed = float(speed_mps)
        return self._log("speed", duration_s, reverse=reverse, **info)

    def turn(
        self,
        angle_deg: float,
        radius_m: float | None = None,
        rate_dps: float | None = None,
        ramp_s: float = 1.0,
    ) -> "Scenario":
        """Change the yaw by ``angle_deg`` [deg] (positive = clockwise seen from above) at constant speed.

        Give either the ``radius_m`` [m] (needs a moving vehicle; the yaw rate is |speed| / radius,
        so the path is an arc of that radius also when reversing) or the plateau yaw rate
        ``rate_dps`` [deg/s] (at speed 0 this is a turn on the spot). The yaw rate ramps up and
        down over ``ramp_s`` [s]. ``angle_deg`` is the change of the heading of body x: reversing
        with a positive angle, the vehicle's nose swings right and its path curves to the left
        (as a car steered left while backing up).
        """
        if (radius_m is None) == (rate_dps is None):
            raise InputError(
                WHERE, f"{self.name}: turn() needs exactly one of radius_m and rate_dps"
            )
        if radius_m is not None:
            if self.speed == 0.0 or not radius_m > 0:
                raise InputError(
                    WHERE,
                    f"{self.name}: a turn with a radius needs a moving vehicle and radius > 0",
                )
            rate = abs(self.speed) / radius_m
        else:
            rate = abs(rate_dps) * DEG
        angle = angle_deg * DEG
        # A turn shorter than its ramp keeps the rate and shrinks the ramp (no plateau).
        ramp = min(ramp_s, abs(angle) / rate)
        duration = abs(angle) / rate + ramp
        self._yaw_rate.append(Pulse(self.t_end, duration, ramp, np.sign(angle) * rate))
        return self._log(
            "turn", duration, angle_deg=angle_deg, yaw_rate=np.sign(angle) * rate, speed=self.speed
        )

    def hill(
        self, height_m: float, slope_deg: float = 5.0, top_s: float = 0.0, ramp_s: float = 2.0
    ) -> "Scenario":
        """Drive over a hill: climb about ``height_m`` [m] at ``slope_deg``, cruise ``top_s`` [s], descend.

        Pitch follows the slope (smooth ramps of ``ramp_s`` [s]). At constant speed the descent
        mirrors the climb exactly, so the height returns to its value before the hill. Reversing
        up a hill the nose points downhill (negative pitch).
        """
        if self.speed == 0.0:
            raise InputError(WHERE, f"{self.name}: a hill needs a moving vehicle")
        slope = abs(slope_deg) * DEG
        plateau = abs(height_m) / (abs(self.speed) * np.sin(slope))
        ramp = min(ramp_s, plateau)
        climb = plateau + ramp
        # dh/dt = speed sin(pitch): climbing backwards needs the nose down.
        sign = (np.sign(height_m) if height_m else 1.0) * np.sign(self.speed)
        t0 = self.t_end
        self._pitch.append(Pulse(t0, climb, ramp, sign * slope))
        self._pitch.append(Pulse(t0 + climb + top_s, climb, ramp, -sign * slope))
        return self._log(
            "hill", 2.0 * climb + top_s, height_m=height_m, slope_deg=slope_deg, speed=self.speed
        )

    def kinematics(self, t_rel: np.ndarray, yaw0: float) -> Kinematics:
        """Evaluate the path at sorted times ``t_rel`` [s] relative to the start; ``yaw0`` [rad]."""
        return self.kinematics_block(t_rel, yaw0)[0]

    def kinematics_block(
        self, t_rel: np.ndarray, yaw0: float, ended=None
    ) -> tuple[Kinematics, tuple]:
        """:meth:`kinematics` of one block of a sweep over sorted times, bit for bit the one-pass values.

        ``ended`` is what the previous block returned (``None`` for the first); consecutive blocks
        overlap by one sample. Returns the kinematics and the ``ended`` of the next block.
        """
        t_rel = np.atleast_1d(np.asarray(t_rel, float))
        # Within a sweep only the pulses overlapping the block count (the areas of those that
        # ended before it arrive in ``ended``): the cost per block does not grow with the run.
        accel, yaw_rate, pitch = (
            self._overlapping(p, t_rel) if ended is not None and len(t_rel) else p
            for p in (self._accel, self._yaw_rate, self._pitch)
        )
        speed_int, speed_end = _integral(accel, t_rel, None if ended is None else ended[0])
        yaw_int, yaw_end = _integral(yaw_rate, t_rel, None if ended is None else ended[1])
        speed = self.speed0 + speed_int
        # Stops end with floating-point dust of ~1e-15 m/s: make them exactly stationary.
        speed = np.where(np.abs(speed) < 1e-12, 0.0, speed)
        kin = Kinematics(
            speed=speed,
            accel=_channel(accel, t_rel, "value"),
            yaw=yaw0 + yaw_int,
            yaw_rate=_channel(yaw_rate, t_rel, "value"),
            pitch=_channel(pitch, t_rel, "value"),
            pitch_rate=_channel(pitch, t_rel, "rate"),
        )
        return kin, (speed_end, yaw_end)

    def _overlapping(self, pulses: list[Pulse], t: np.ndarray) -> list[Pulse]:
        """The pulses (in list order) that end at or after ``t[0]`` and start before ``t[-1]``."""
        spans = self._spans.get(id(pulses))
        if spans is None or len(spans[0]) != len(pulses):
            spans = (
                np.array([p.t0 for p in pulses]),
                np.array([p.t0 + p.duration for p in pulses]),
            )
            self._spans[id(pulses)] = spans
        return [pulses[i] for i in np.flatnonzero((spans[1] >= t[0]) & (spans[0] < t[-1]))]

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


def _cycle_ugv_slow(s: Scenario) -> None:
    """Slow UGV after a real recording, 235 s per cycle, at most 2.2 m/s.

    Parked 0-36 s; drives with radius turns, an on-the-spot pivot and short stops (4-6 s);
    reverses 102.7-132.7 s (30 s, 1 m/s, with a 5 m radius turn); stops at 160 s and stays
    parked 75 s.
    """
    c0 = s.t_end
    s.hold(36.0)
    s.speed_to(1.5, 3.0).cruise(8.0).turn(90.0, radius_m=4.0)
    s.speed_to(2.2, 3.0).cruise(12.0)
    s.speed_to(0.0, 3.0).hold(5.0)
    s.turn(-90.0, rate_dps=30.0).hold(3.0)  # skid-steer pivot on the spot
    s.speed_to(1.8, 3.0).turn(-60.0, radius_m=6.0).cruise(6.0)
    s.speed_to(0.0, 3.0).hold(4.0)
    t_rev = s.t_end
    s.speed_to(-1.0, 3.0).cruise(8.0).turn(45.0, radius_m=5.0)
    s.cruise(t_rev + 27.0 - s.t_end).speed_to(0.0, 3.0)  # 30 s backwards in all
    s.hold(6.0)
    s.speed_to(2.0, 3.0).cruise(4.0).turn(120.0, radius_m=5.0)
    s.cruise(c0 + 157.0 - s.t_end).speed_to(0.0, 3.0)
    s.hold(75.0)


def _cycle_rover(s: Scenario) -> None:
    """Slow rover, 367 s per cycle, 0.40-0.45 m/s: long straights with gentle turns (8-20 m radius),
    two short stops (6 s and 10 s) and a pivot on the spot. Starts and ends at rest (4 s)."""
    c0 = s.t_end
    s.hold(4.0).speed_to(0.42, 2.0).cruise(40.0).turn(60.0, radius_m=12.0).cruise(30.0)
    s.speed_to(0.45, 2.0).turn(-90.0, radius_m=8.0).cruise(45.0)
    s.speed_to(0.0, 2.0).hold(6.0).speed_to(0.40, 2.0).cruise(35.0).turn(45.0, radius_m=20.0)
    s.cruise(30.0).speed_to(0.0, 2.0).hold(10.0).turn(-120.0, rate_dps=15.0).hold(2.0)
    s.speed_to(0.43, 2.0).cruise(40.0).turn(80.0, radius_m=10.0)
    s.cruise(c0 + 361.0 - s.t_end).speed_to(0.0, 2.0)
    s.hold(c0 + 367.0 - s.t_end)


def _cycle_car_city(s: Scenario) -> None:
    """City car, 280 s per cycle, at most 15 m/s.

    Parked 0-35 s with the engine on; accelerations to 12-15 m/s, corners of 15-60 m radius,
    stops at lights of 20, 12 and 30 s (from 100.9, 180.1 and 218.0 s); a parking manoeuvre
    with 8 s backwards at up to 1.5 m/s on a 6 m radius (262.0-270.0 s); parked to 280 s.
    """
    c0 = s.t_end
    s.hold(35.0)
    s.speed_to(12.0, 8.0, ramp_s=1.5).cruise(15.0)
    s.speed_to(6.0, 4.0).turn(90.0, radius_m=15.0)
    s.speed_to(14.0, 7.0, ramp_s=1.5).cruise(20.0)
    s.speed_to(0.0, 7.0, ramp_s=1.5).hold(20.0)
    s.speed_to(10.0, 6.0, ramp_s=1.5).turn(-90.0, radius_m=40.0).cruise(12.0)
    s.speed_to(15.0, 5.0, ramp_s=1.5).cruise(15.0)
    s.speed_to(12.0, 2.0).turn(45.0, radius_m=60.0)
    s.speed_to(0.0, 7.0, ramp_s=1.5).hold(12.0)
    s.speed_to(8.0, 5.0).turn(-90.0, radius_m=25.0).cruise(10.0)
    s.speed_to(0.0, 5.0).hold(30.0)
    # Parking: pull past the space, stop, back into it (0.75 rad at 0.25 rad/s + ramp = 4 s).
    s.speed_to(3.0, 3.0).cruise(5.0).speed_to(0.0, 3.0).hold(3.0)
    s.speed_to(-1.5, 2.0).turn(np.degrees(0.75), radius_m=6.0).speed_to(0.0, 2.0)
    s.hold(c0 + 280.0 - s.t_end)


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
    "ugv-slow": (0.0, _cycle_ugv_slow),
    "car-city": (0.0, _cycle_car_city),
    "rover": (0.0, _cycle_rover),
}


def make_scenario(name: str, duration_s: float) -> Scenario:
    """A named scenario, its cycle repeated until it lasts at least ``duration_s`` [s].

    Parameters
    ----------
    name : {"static", "ugv", "car", "straight", "turns", "ugv-slow", "car-city", "rover"}
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


def reversing_spans(segments: list[dict]) -> list[tuple[float, float]]:
    """Time spans ``(t0, t1)`` [s] of consecutive segments marked ``reverse`` (e.g. ``run.sim.segments``)."""
    spans: list[tuple[float, float]] = []
    for s in segments:
        if not s.get("reverse"):
            continue
        if spans and abs(spans[-1][1] - s["t0"]) < 1e-9:
            spans[-1] = (spans[-1][0], s["t1"])
        else:
            spans.append((s["t0"], s["t1"]))
    return spans


def R_nb_batch(pitch, yaw) -> np.ndarray:
    """``Rz(yaw) @ Ry(pitch)`` for arrays, shape (K, 3, 3)."""
    cp, sp, cy, sy = np.cos(pitch), np.sin(pitch), np.cos(yaw), np.sin(yaw)
    R = np.empty((len(cp), 3, 3))
    R[:, 0, 0], R[:, 0, 1], R[:, 0, 2] = cy * cp, -sy, cy * sp
    R[:, 1, 0], R[:, 1, 1], R[:, 1, 2] = sy * cp, cy, sy * sp
    R[:, 2, 0], R[:, 2, 1], R[:, 2, 2] = -sp, 0.0, cp
    return R
