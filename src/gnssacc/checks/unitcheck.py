r"""Units of the IMU data, checked against physics and the GNSS fixes (part of the input checks).

* **Time stamps** (:func:`imu_time_units`): two views must agree. An IMU for navigation samples
  at :data:`IMU_RATE_HZ` (5 Hz .. 20 kHz), and its stamps must meet the fixes' time span. Stamps
  that as seconds already overlap the fixes are seconds, whatever their rate (a slow IMU is a
  note, never another unit). Otherwise they are tried in milli-, micro- and nanoseconds; a unit
  that gives a plausible rate *and* puts the IMU on the fixes' time span (overlapping it, within
  :data:`gnssacc.checks.timeoffset.MAX_OFFSET_S`) is the finding; none: the data cannot be
  estimated as they are.
* **Accelerometer** (:func:`accel_units`): a ground vehicle's specific force is gravity plus
  accelerations that rarely exceed 0.3 g and average out, so the median norm of 0.1 s means is
  local gravity to about 1 %; scale-factor errors of even consumer MEMS are below 2 % and biases
  below 1 %. Outside +-10 % of gravity the units are wrong: 1.0 means g, 1000 milli-g (or
  cm/s^2), 32.2 ft/s^2.
* **Gyro** (:func:`gyro_units`): the IMU heading rate (about the measured gravity direction, so
  whatever the mounting) against the GNSS course rate over the run
  (:func:`gnssacc.checks.motionmatch.turn_rate_fit`): the slope is 1 for rad/s and pi/180 = 0.0175 for
  deg/s. Course and heading rates differ by side slip and the smoothing, and a gyro's scale
  factor by < 1 %: +-30 % is accepted. A slope of -1 is a mirrored pair (GNSS or IMU axes, see
  :mod:`gnssacc.checks.gnsscheck`). A slope that fits neither unit is reported only when it is precise
  (:data:`SLOPE_MAX_REL_SIGMA`) and positive: a negative one is a mirror image, which also
  changes its size (swapped latitude and longitude stretch the track by cos(lat) / cos(lon)),
  and is left to :func:`gnssacc.checks.gnsscheck.mirror_image`. deg/s needs less, since rad/s lies 57
  times away: a slope in the deg/s band that stands :data:`DEG_SLOPE_MIN_SIGMAS` sigma clear of
  zero (the gyro follows the turns) cannot come from a rad/s gyro (a slow UGV's 3-minute run
  gives a 12-16 % sigma). With too little turning, a parked vehicle's gyro reading above
  :data:`REST_RATE_MAX_RPS` (no MEMS turn-on bias comes near) points to deg/s.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..core.config import G0
from ..core.recording import ImuData, RecordedRun
from .findings import Finding
from .motionmatch import TurnFit, box_average
from .timeoffset import MAX_OFFSET_S

IMU_RATE_HZ = (5.0, 20000.0)
#: Candidate stamp units: (seconds per unit, name, divisor as written in messages).
TIME_UNITS = (
    (1e-3, "milliseconds", "1000"),
    (1e-6, "microseconds", "1e6"),
    (1e-9, "nanoseconds", "1e9"),
)
#: Longest IMU span, in spans of the fixes, that stamps taken as seconds may have (a recording
#: logs the IMU a little before and after the fixes, not for ten times as long).
SPAN_RATIO_MAX = 10.0
#: Accepted ratio of the median specific-force norm to local gravity (module notes).
GRAVITY_TOLERANCE = 0.10
#: Accepted deviation of the gyro/course slope from 1 (or from pi/180 for deg/s).
SLOPE_TOLERANCE = 0.30
#: Largest relative 1-sigma of the slope for a verdict other than deg/s.
SLOPE_MAX_REL_SIGMA = 0.15
#: A slope in the deg/s band is that verdict when it is this many sigma from zero (module notes):
#: a rad/s gyro's slope (0.7-1.3) would then lie more than a hundred sigma away.
DEG_SLOPE_MIN_SIGMAS = 4.0
#: Largest plausible mean angular rate of a parked vehicle [rad/s] (5.7 deg/s): MEMS turn-on
#: biases stay below ~2 deg/s, the earth turns at 0.004 deg/s.
REST_RATE_MAX_RPS = 0.1


def _rate_ok(dt: float) -> bool:
    # 1 % of slack: a 5 Hz IMU's median interval may be a hair over 0.2 s (clock drift, rounding).
    return dt > 0 and 0.99 * IMU_RATE_HZ[0] <= 1.0 / dt <= 1.01 * IMU_RATE_HZ[1]


def _spans_meet(a0: float, a1: float, b0: float, b1: float) -> bool:
    return a0 <= b1 + MAX_OFFSET_S and b0 <= a1 + MAX_OFFSET_S


def _overlap(a0: float, a1: float, b0: float, b1: float) -> bool:
    return a0 <= b1 and b0 <= a1


def imu_time_units(t_imu: np.ndarray, t_gnss: np.ndarray, where: str) -> Finding | None:
    """IMU stamps that are not seconds (module notes); the finding's repair rescales them.

    Parameters
    ----------
    t_imu, t_gnss : ndarray
        IMU and fix time stamps as read (the fixes' in seconds).
    where : str
        The IMU file.
    """
    dt = float(np.median(np.diff(t_imu)))
    # As seconds the IMU must meet the fixes and span about as long as they do (stamps in ms from
    # zero overlap fixes from zero too, over a thousand times their span).
    span_imu, span_gnss = float(t_imu[-1] - t_imu[0]), float(t_gnss[-1] - t_gnss[0])
    as_seconds = (
        _overlap(float(t_imu[0]), float(t_imu[-1]), float(t_gnss[0]), float(t_gnss[-1]))
        and span_imu <= SPAN_RATIO_MAX * span_gnss + 2.0 * MAX_OFFSET_S
    )
    if _rate_ok(dt):
        return None
    if as_seconds:
        rate = f"{1.0 / dt:.3g} Hz" if dt > 0 else "repeated stamps"
        return Finding(
            "time_units",
            where,
            f"the IMU samples at {rate} (median interval {dt:.6g} s), outside the "
            f"{IMU_RATE_HZ[0]:g} Hz to {IMU_RATE_HZ[1] / 1000:g} kHz of a navigation IMU; its stamps meet "
            f"the fixes as seconds, so they are taken as seconds",
            "expect poor strapdown integration" if dt > 0 and 1.0 / dt < IMU_RATE_HZ[0] else "",
            details={"median_interval": dt},
        )
    span = f"IMU time stamps step by {dt:.6g} (median) and span {t_imu[-1] - t_imu[0]:.6g}"
    found = [
        (k, name, div)
        for k, name, div in TIME_UNITS
        if _rate_ok(dt * k) and _spans_meet(t_imu[0] * k, t_imu[-1] * k, t_gnss[0], t_gnss[-1])
    ]
    if len(found) != 1:
        rate = f"{1.0 / dt:.3g} Hz" if dt > 0 else "no rate at all"
        return Finding(
            "time_units",
            where,
            f"{span}: as seconds that is {rate}, not the {IMU_RATE_HZ[0]:g} Hz to "
            f"{IMU_RATE_HZ[1] / 1000:g} kHz of an IMU, and no other unit puts the IMU on the GNSS fixes' "
            f"time span",
            "write the t column in seconds on the GNSS fixes' clock",
            impossible=True,
        )
    k, name, div = found[0]

    def repair(run: RecordedRun) -> RecordedRun:
        return _with_imu(run, ImuData(run.imu.t * k, run.imu.f_b, run.imu.omega_ib_b))

    return Finding(
        "time_units",
        where,
        f"{span} while the GNSS fixes span {t_gnss[-1] - t_gnss[0]:.1f} s: the IMU stamps are in {name} "
        f"({1.0 / (dt * k):.0f} Hz)",
        f"divide the t column by {div}",
        repair,
        f"divided the IMU time stamps by {div}",
        details={"unit": name, "scale": k, "estimable": False},
    )


def _with_imu(run: RecordedRun, imu: ImuData) -> RecordedRun:
    return replace(run, imu=imu)


def median_specific_force(imu: ImuData) -> float:
    """Median norm of the specific force's 0.1 s means (vibration averaged out) [IMU units]."""
    n = max(int((imu.t[-1] - imu.t[0]) / 0.1), 1)
    cells = box_average(imu.t, imu.f_b, float(imu.t[0]) + 0.05, 0.1, n)
    return float(np.median(np.linalg.norm(cells, axis=1)))


def accel_units(imu: ImuData, g_local: float, where: str) -> Finding | None:
    """Accelerometer units from the median specific force against gravity (module notes)."""
    med = median_specific_force(imu)
    if abs(med / g_local - 1.0) <= GRAVITY_TOLERANCE:
        return None
    head = (
        f"the accelerometer reads {med:.4g} on average (median norm of the specific force), where local "
        f"gravity is {g_local:.3f} m/s^2"
    )
    details = {"median_norm": med, "gravity_mps2": g_local}
    if abs(med - 1.0) <= GRAVITY_TOLERANCE:

        def repair(run: RecordedRun) -> RecordedRun:
            return _with_imu(run, ImuData(run.imu.t, run.imu.f_b * G0, run.imu.omega_ib_b))

        return Finding(
            "accel_units",
            where,
            f"{head}: the ax, ay, az columns are in g",
            f"multiply them by {G0}",
            repair,
            f"multiplied the specific force by {G0}",
            details=details,
        )
    for value, unit, k in (
        (1000.0, "milli-g", G0 / 1000.0),
        (100.0 * g_local, "cm/s^2", 0.01),
        (g_local / 0.3048, "ft/s^2", 0.3048),
    ):
        if abs(med / value - 1.0) <= GRAVITY_TOLERANCE:
            return Finding(
                "accel_units",
                where,
                f"{head}: the ax, ay, az columns look like {unit}",
                "convert them to m/s^2",
                _scaled_accel(k),
                f"multiplied the specific force by {k:g}",
                details=details,
            )
    return Finding(
        "accel_units",
        where,
        f"{head}: the accelerometer columns are not specific force in m/s^2; the "
        "estimates cannot be trusted",
        "convert them to m/s^2 (at rest a level IMU reads about 9.81 in total)",
        details=details,
    )


def _scaled_accel(k: float):
    """The repair multiplying the specific force by ``k``."""

    def repair(run: RecordedRun) -> RecordedRun:
        return _with_imu(run, ImuData(run.imu.t, run.imu.f_b * k, run.imu.omega_ib_b))

    return repair


def gyro_units(tf: TurnFit | None, rest_rate: float | None, where: str) -> Finding | None:
    """Gyro units from the heading-rate slope, or the rest rate without turns (module notes).

    Parameters
    ----------
    tf : TurnFit or None
    rest_rate : float or None
        Median norm of the angular rate while the GNSS shows the vehicle at rest [IMU units].
    """
    deg = np.pi / 180.0
    if tf is not None and abs(tf.k) > 0:
        k = tf.k
        precise = tf.sigma_k <= SLOPE_MAX_REL_SIGMA * abs(k)
        details = {"slope": k, "slope_sigma": tf.sigma_k}
        head = (
            f"the gyro's heading rate is {1 / k:.4g} times the GNSS course rate over "
            f"{tf.turned_deg:.0f} (IMU) degrees of turns"
        )
        if precise and abs(abs(k) - 1.0) <= SLOPE_TOLERANCE:
            return None
        if (
            abs(abs(k) / deg - 1.0) <= SLOPE_TOLERANCE
            and abs(k) >= DEG_SLOPE_MIN_SIGMAS * tf.sigma_k
        ):
            return Finding(
                "gyro_units",
                where,
                f"{head}: the gx, gy, gz columns are in deg/s",
                "multiply them by pi/180",
                _deg_to_rad,
                "multiplied the angular rate by pi/180",
                details=details,
            )
        if (
            precise and k > 0
        ):  # no unit's factor: one view (a skid-steer's or slow vehicle's course rate)
            return Finding(
                "gyro_units",
                where,
                f"{head}, a ratio of no unit (rad/s gives 1, deg/s 57.3): the course "
                "of the fixes and the gyro disagree (side slip of a skid-steer vehicle, slow fixes)",
                "nothing to do if the gyro is in rad/s",
                details=details,
            )
    if rest_rate is not None and rest_rate > REST_RATE_MAX_RPS:
        return Finding(
            "gyro_units",
            where,
            f"the gyro reads {rest_rate:.3g} (median norm) while the GNSS shows the vehicle at rest; no gyro "
            f"drifts by more than {REST_RATE_MAX_RPS} rad/s: are the gx, gy, gz columns in deg/s?",
            "multiply them by pi/180",
            _deg_to_rad,
            "multiplied the angular rate by pi/180",
            details={"rest_rate": rest_rate},
        )
    return None


def _deg_to_rad(run: RecordedRun) -> RecordedRun:
    """The repair of a gyro in deg/s."""
    return _with_imu(run, ImuData(run.imu.t, run.imu.f_b, run.imu.omega_ib_b * (np.pi / 180.0)))
