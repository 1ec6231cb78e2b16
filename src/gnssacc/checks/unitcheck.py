r"""Units of the IMU data, checked against physics and the GNSS fixes (part of the input checks).

* **Time stamps** (:func:`imu_time_units`): an IMU for navigation samples at
  :data:`IMU_RATE_HZ` (5 Hz .. 20 kHz: below, strapdown integration cannot follow a vehicle's
  turns; above, no navigation IMU outputs). Stamps whose median interval gives a rate outside it
  are tried in milli-, micro- and nanoseconds; a unit that gives a plausible rate *and* puts the
  IMU on the fixes' time span (within :data:`gnssacc.checks.timeoffset.MAX_OFFSET_S`) is the finding.
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
TIME_UNITS = ((1e-3, "milliseconds", "1000"), (1e-6, "microseconds", "1e6"), (1e-9, "nanoseconds", "1e9"))
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
    return dt > 0 and IMU_RATE_HZ[0] <= 1.0 / dt <= IMU_RATE_HZ[1]


def _spans_meet(a0: float, a1: float, b0: float, b1: float) -> bool:
    return a0 <= b1 + MAX_OFFSET_S and b0 <= a1 + MAX_OFFSET_S


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
    if _rate_ok(dt):
        return None
    span = f"IMU time stamps step by {dt:.6g} (median) and span {t_imu[-1] - t_imu[0]:.6g}"
    found = [(k, name, div) for k, name, div in TIME_UNITS
             if _rate_ok(dt * k) and _spans_meet(t_imu[0] * k, t_imu[-1] * k, t_gnss[0], t_gnss[-1])]
    if len(found) != 1:
        rate = f"{1.0 / dt:.3g} Hz" if dt > 0 else "no rate at all"
        return Finding("time_units", where, f"{span}: as seconds that is {rate}, not the {IMU_RATE_HZ[0]:g} Hz to "
                       f"{IMU_RATE_HZ[1] / 1000:g} kHz of an IMU, and no other unit puts the IMU on the GNSS fixes' "
                       f"time span", "write the t column in seconds on the GNSS fixes' clock")
    k, name, div = found[0]

    def repair(run: RecordedRun) -> RecordedRun:
        return _with_imu(run, ImuData(run.imu.t * k, run.imu.f_b, run.imu.omega_ib_b))

    return Finding("time_units", where,
                   f"{span} while the GNSS fixes span {t_gnss[-1] - t_gnss[0]:.1f} s: the IMU stamps are in {name} "
                   f"({1.0 / (dt * k):.0f} Hz)", f"divide the t column by {div}", repair,
                   f"divided the IMU time stamps by {div}", details={"unit": name, "scale": k})


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
    head = (f"the accelerometer reads {med:.4g} on average (median norm of the specific force), where local "
            f"gravity is {g_local:.3f} m/s^2")
    details = {"median_norm": med, "gravity_mps2": g_local}
    if abs(med - 1.0) <= GRAVITY_TOLERANCE:
        def repair(run: RecordedRun) -> RecordedRun:
            return _with_imu(run, ImuData(run.imu.t, run.imu.f_b * G0, run.imu.omega_ib_b))

        return Finding("accel_units", where, f"{head}: the ax, ay, az columns are in g",
                       f"multiply them by {G0}", repair, f"multiplied the specific force by {G0}", details=details)
    for value, unit in ((1000.0, "milli-g, or cm/s^2"), (g_local / 0.3048, "ft/s^2")):
        if abs(med / value - 1.0) <= GRAVITY_TOLERANCE:
            return Finding("accel_units", where, f"{head}: the ax, ay, az columns look like {unit}",
                           "convert them to m/s^2", details=details)
    return Finding("accel_units", where, f"{head}: the accelerometer columns are not specific force in m/s^2",
                   "convert them to m/s^2 (at rest a level IMU reads about 9.81 in total)", details=details)


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
        head = (f"the gyro's heading rate is {1 / k:.4g} times the GNSS course rate over "
                f"{tf.turned_deg:.0f} (IMU) degrees of turns")
        if precise and abs(abs(k) - 1.0) <= SLOPE_TOLERANCE:
            return None
        if abs(abs(k) / deg - 1.0) <= SLOPE_TOLERANCE and abs(k) >= DEG_SLOPE_MIN_SIGMAS * tf.sigma_k:
            def repair(run: RecordedRun) -> RecordedRun:
                return _with_imu(run, ImuData(run.imu.t, run.imu.f_b, run.imu.omega_ib_b * deg))

            return Finding("gyro_units", where, f"{head}: the gx, gy, gz columns are in deg/s",
                           "multiply them by pi/180", repair, "multiplied the angular rate by pi/180", details=details)
        if precise and k > 0:
            return Finding("gyro_units", where, f"{head}: the gyro columns are not angular rate in rad/s",
                           "convert them to rad/s", details=details)
    if rest_rate is not None and rest_rate > REST_RATE_MAX_RPS:
        return Finding("gyro_units", where,
                       f"the gyro reads {rest_rate:.3g} (median norm) while the GNSS shows the vehicle at rest; no gyro "
                       f"drifts by more than {REST_RATE_MAX_RPS} rad/s: are the gx, gy, gz columns in deg/s?",
                       "convert them to rad/s", details={"rest_rate": rest_rate})
    return None
