r"""The GNSS fixes checked against physics and against the IMU (part of the input checks).

* **Time stamps** (:func:`gnss_time_units`): navigation receivers give a fix every 5 ms (200 Hz)
  to every few seconds; a median interval outside :data:`FIX_INTERVAL_S` means the stamps are
  not seconds (1 Hz fixes stamped in ms are 1000 "s" apart).
* **Number of fixes** (:func:`fix_count`): the start needs a position, a velocity and an
  acceleration: at least :data:`MIN_FIXES` fixes inside the IMU's time span.
* **Heights** (:func:`heights`): roads run from -430 m (Dead Sea) to 5.8 km, and the geoid is
  within +-110 m of the ellipsoid: a median height outside :data:`HEIGHT_RANGE_M` is in other
  units (mm, feet over a high plateau) or another field.
* **Radians** (:func:`latlon_radians`): latitude and longitude in radians, read as degrees, put
  every fix within 1.57 deg of latitude and 3.14 deg of longitude of (0, 0): the open sea of the
  Gulf of Guinea, with no road. The IMU decides: the fixes' accelerations are then 57.3 times
  smaller than those the IMU measures (:class:`gnssacc.checks.motionmatch.HorizontalFit`), within the
  :data:`SCALE_RANGE` a track in degrees must meet (a UGV that reverses for a sixth of its run
  shows 0.6-0.75 of the true ratio: its velocity frame turns by 180 deg, the IMU's axes do not).
* **Mirror image** (:func:`mirror_image`): swapped latitude and longitude, or a lost hemisphere
  sign, mirror the track: the fixes then turn left where the gyro turns right, and their
  acceleration fits the accelerometer's only as a mirror image. Both IMU sensors must disagree
  with the fixes (when only one does, the IMU's own axes disagree in handedness). For the gyro
  this is a question of sign alone (:data:`SIGN_SIGMAS`), not of the slope's size: swapping
  latitude and longitude also stretches the track by cos(lat) / cos(lon) across its axes, which
  with a slow vehicle's already low slope (0.8-0.9) takes it out of any band around -1.
* **Scale** (:func:`gnss_scale`): otherwise the fixes' accelerations must match the IMU's within
  :data:`SCALE_RANGE` (the ratio's noise, attitude and slope effects stay within 20-30 %).
* **Initial state** (:func:`init_position`): a given start (``init.json``) must lie near the
  fix at its time.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..core.earth import LocalTangentFrame
from ..core.recording import RecordedRun
from .findings import Finding
from .motionmatch import HorizontalFit, LateralFit, TurnFit

FIX_INTERVAL_S = (0.005, 60.0)
MIN_FIXES = 3
HEIGHT_RANGE_M = (-1000.0, 10000.0)
RAD_PER_DEG = np.pi / 180.0
#: A horizontal fit decides only with a correlation of at least MIN_RHO (the better model) and,
#: for a mirror verdict, MIRROR_MARGIN between the two models (clean runs: 0.7-0.95 against 0.1).
MIN_RHO = 0.5
MIRROR_MARGIN = 0.3
#: Accepted ratio of the IMU's to the fixes' horizontal acceleration.
SCALE_RANGE = (0.5, 2.0)
#: The gyro turns with (or against) the fixes when the heading-rate slope is this many sigma above
#: (below) zero: clean runs give 3-5 sigma on a slow UGV's two minutes, 7-9 on three, 16-25 on a car's.
SIGN_SIGMAS = 3.0


def gnss_time_units(t: np.ndarray, where: str) -> Finding | None:
    """Fix stamps whose median interval is no receiver's (module notes)."""
    if len(t) < 2:
        return None
    dt = float(np.median(np.diff(t)))
    if FIX_INTERVAL_S[0] <= dt <= FIX_INTERVAL_S[1]:
        return None
    hint = " (milliseconds?)" if dt > FIX_INTERVAL_S[1] else ""
    return Finding(
        "time_units",
        where,
        f"GNSS fixes are {dt:.6g} s apart (median): no receiver gives fixes "
        f"{'that rarely' if dt > 1 else 'that often'}; the t column is not in seconds{hint}",
        "write the t column in seconds",
        details={"median_interval": dt},
        impossible=True,
    )


def fix_count(t_gnss: np.ndarray, t0: float, t1: float, where: str) -> Finding | None:
    """Fewer than :data:`MIN_FIXES` fixes within the IMU span ``[t0, t1]`` [s]."""
    n = int(np.sum((t_gnss >= t0) & (t_gnss <= t1)))
    if n >= MIN_FIXES:
        return None
    return Finding(
        "fix_count",
        where,
        f"{n} GNSS fix(es) within the IMU data's time span ({t0:.3f} .. {t1:.3f} s; "
        f"{len(t_gnss)} in the file): at least {MIN_FIXES} are needed to start (a position, a velocity "
        f"and an acceleration), and checking the units, clocks and mounting needs a minute of fixes",
        "record or export more fixes",
        details={"n_fixes": n},
        impossible=True,
    )


#: Height units a median outside the road range may be in: (metres per unit, name).
HEIGHT_UNITS = ((1e-3, "millimetres"), (1e-2, "centimetres"), (0.3048, "feet"))
#: Where a reinterpreted median height must land [m]: on a road (the Dead Sea's -430 m to the
#: 5.8 km of the highest pass, the geoid within 110 m of the ellipsoid), stricter than the range
#: that leaves heights as given alone (a geocentric radius in millimetres would be 6.4 km).
ROAD_HEIGHT_M = (-600.0, 6000.0)


def heights(h: np.ndarray, where: str, declined=frozenset()) -> Finding | None:
    """A median height outside :data:`HEIGHT_RANGE_M` (module notes): a proposal for the first unit
    of :data:`HEIGHT_UNITS` that brings it into the range and was not judged before
    (``declined``: the keys of the proposals settled); none left: no ground vehicle drives there,
    the data cannot be estimated as they are."""
    med = float(np.median(h))
    if HEIGHT_RANGE_M[0] <= med <= HEIGHT_RANGE_M[1]:
        return None
    head = (
        f"the fixes' heights are around {med:.6g} m, outside the {HEIGHT_RANGE_M[0]:g} .. {HEIGHT_RANGE_M[1]:g} m "
        f"of any road"
    )
    for k, name in HEIGHT_UNITS:
        if ROAD_HEIGHT_M[0] <= med * k <= ROAD_HEIGHT_M[1]:
            f = Finding(
                "heights",
                where,
                f"{head}: the h_m column is in {name}",
                "convert the h_m column to metres",
                _scaled_heights(k),
                f"multiplied the heights by {k:g}",
                details={"median_height_m": med, "log_jacobian_per_fix": float(np.log(k))},
            )
            if f.key not in declined:
                return f
    return Finding(
        "heights",
        where,
        f"{head}: the h_m column is in other units or is not an ellipsoidal height",
        "write ellipsoidal heights in metres",
        details={"median_height_m": med},
        impossible=True,
    )


def _scaled_heights(k: float):
    """The proposal: heights times ``k`` (metres per unit)."""

    def repair(run: RecordedRun) -> RecordedRun:
        g = replace(run.gnss, h=run.gnss.h * k)
        return replace(run, gnss=g, origin=LocalTangentFrame(g.lat[0], g.lon[0], g.h[0]))

    return repair


def in_radian_box(lat: np.ndarray, lon: np.ndarray) -> bool:
    """Whether every (lat, lon) [rad], read as degrees, would be a radian value: |lat| <= pi/2 deg
    and |lon| <= pi deg (module notes)."""
    return bool(
        np.all(np.abs(lat) <= 0.5 * np.pi * RAD_PER_DEG)
        and np.all(np.abs(lon) <= np.pi * RAD_PER_DEG)
    )


def _radians_to_degrees(run: RecordedRun) -> RecordedRun:
    """The repair: latitude/longitude values (held as degrees) were radians."""
    k = 1.0 / RAD_PER_DEG
    g = replace(run.gnss, lat=run.gnss.lat * k, lon=run.gnss.lon * k)
    out = replace(run, gnss=g, origin=LocalTangentFrame(g.lat[0], g.lon[0], g.h[0]))
    if run.truth is not None and in_radian_box(run.truth.lat, run.truth.lon):
        out = replace(out, truth=replace(run.truth, lat=run.truth.lat * k, lon=run.truth.lon * k))
    if run.init is not None and in_radian_box(np.array([run.init.lat]), np.array([run.init.lon])):
        out = replace(out, init=replace(run.init, lat=run.init.lat * k, lon=run.init.lon * k))
    return out


def latlon_radians(run: RecordedRun, fit: HorizontalFit | None, where: str) -> Finding | None:
    """Latitude/longitude in radians (module notes): repairable when the IMU confirms the scale."""
    g = run.gnss
    if not in_radian_box(g.lat, g.lon):
        return None
    decided = fit is not None and max(fit.rho_direct, fit.rho_mirror) >= MIN_RHO
    head = (
        f"every fix lies within 1.6 deg of latitude and 3.2 deg of longitude of (0, 0), in the open sea, "
        f"(first fix {np.degrees(g.lat[0]):.6f}, {np.degrees(g.lon[0]):.6f})"
    )
    if decided and SCALE_RANGE[0] <= fit.scale <= SCALE_RANGE[1]:
        return None  # the IMU agrees with the track as it is: a real place
    fix = "multiply the lat_deg and lon_deg columns by 180/pi"
    # Positions read as radians are 180/pi times further apart: the log-Jacobian of reading
    # latitude and longitude so, per fix (the estimator compares likelihoods of metres).
    details = {
        "accel_ratio": fit.scale if fit is not None else None,
        "log_jacobian_per_fix": 2.0 * np.log(1.0 / RAD_PER_DEG),
    }
    why = (
        f" and the IMU measures {fit.scale:.3g} times the track's accelerations" if decided else ""
    )
    return Finding(
        "latlon",
        where,
        f"{head}{why}: the lat_deg and lon_deg columns look like radians",
        fix + ' (if the recording really is from there, set [checks] skip = "latlon")',
        _radians_to_degrees,
        "multiplied latitude and longitude by 180/pi",
        details=details,
    )


def _slope_side(tf: TurnFit | None) -> int:
    """+1 gyro turns with the course rate, -1 against it (mirrored), 0 undecided: the sign of the
    slope, when it stands :data:`SIGN_SIGMAS` clear of zero (its size is the gyro units' check)."""
    if tf is None or not tf.sigma_k > 0:
        return 0
    z = tf.k / tf.sigma_k
    return 1 if z >= SIGN_SIGMAS else (-1 if z <= -SIGN_SIGMAS else 0)


def _fit_side(fit: HorizontalFit | None) -> int:
    """+1 accelerometer agrees with the fixes, -1 only as a mirror image, 0 undecided."""
    if fit is None or max(fit.rho_direct, fit.rho_mirror) < MIN_RHO:
        return 0
    d = fit.rho_direct - fit.rho_mirror
    return 1 if d >= MIRROR_MARGIN else (-1 if d <= -MIRROR_MARGIN else 0)


def _swapped(run: RecordedRun) -> RecordedRun:
    """The proposal for a mirrored track: latitude and longitude swapped back."""
    g = replace(run.gnss, lat=run.gnss.lon, lon=run.gnss.lat)
    return replace(run, gnss=g, origin=LocalTangentFrame(g.lat[0], g.lon[0], g.h[0]))


def mirror_image(
    fit: HorizontalFit | None,
    tf: TurnFit | None,
    lf: LateralFit | None,
    gnss_where: str,
    imu_where: str,
    lat: np.ndarray | None = None,
    lon: np.ndarray | None = None,
) -> Finding | None:
    """The track mirrored against both IMU sensors (a proposal: latitude and longitude swapped back,
    which the estimator judges; swapped and sign-lost coordinates look alike, so a confirmed one is
    refused naming both, never guessed), or the IMU's sensors against each other (a note).
    ``lat``, ``lon``:
    the fixes' [rad], for the log-Jacobian of swapping them (east is ``cos(lat)`` per degree)."""
    acc, gyr = _fit_side(fit), _slope_side(tf)
    if acc == -1 and gyr == -1:
        jac = (
            float(np.mean(np.log(np.abs(np.cos(lon)) / np.maximum(np.abs(np.cos(lat)), 1e-12))))
            if lat is not None and lon is not None
            else 0.0
        )
        return Finding(
            "latlon",
            gnss_where,
            "the fixes' track is the mirror image of the motion the IMU measured (it turns left where the "
            "gyro turns right, and its accelerations match the accelerometer's only mirrored): latitude "
            "and longitude are swapped, or one of them has lost its sign (hemisphere)",
            "check the lat_deg and lon_deg columns",
            _swapped,
            "swapped latitude and longitude",
            details={
                "slope": tf.k,
                "rho_direct": fit.rho_direct,
                "rho_mirror": fit.rho_mirror,
                "log_jacobian_per_fix": jac,
            },
            alternatives=(
                "a lost sign of the latitude (hemisphere)",
                "a lost sign of the longitude",
            ),
        )
    if acc * gyr == -1:
        return Finding(
            "mounting",
            imu_where,
            "the gyro and the accelerometer disagree on the direction of the turns (one of them turns with "
            "the fixes, the other against them): one IMU axis has the wrong sign in one of the two sensors",
            "check the signs of the ax, ay, az and gx, gy, gz columns (both must be right-handed, the same axes)",
            details={"slope": tf.k, "rho_direct": fit.rho_direct, "rho_mirror": fit.rho_mirror},
            impossible=True,
        )  # no frame makes both sensors right: nothing to estimate
    return None


def gnss_scale(fit: HorizontalFit | None, where: str) -> Finding | None:
    """The fixes' accelerations against the IMU's, outside :data:`SCALE_RANGE` (module notes)."""
    if fit is None or max(fit.rho_direct, fit.rho_mirror) < MIN_RHO:
        return None
    if SCALE_RANGE[0] <= fit.scale <= SCALE_RANGE[1]:
        return None
    return Finding(
        "latlon",
        where,
        f"the IMU measures {fit.scale:.3g} times the accelerations of the fixes' track: "
        f"the fixes' positions are not in degrees and metres",
        "check the units of lat_deg, lon_deg",
        details={"accel_ratio": fit.scale},
    )


def init_position(run: RecordedRun, where: str) -> Finding | None:
    """A given start more than 100 m (+ 50 m/s for the time to the nearest fix, + 10 fix sigmas:
    a ground vehicle and a fix's error) from the fix nearest to it in time."""
    init, g = run.init, run.gnss
    if init is None or len(g) == 0:
        return None
    k = int(np.argmin(np.abs(g.t - init.t)))
    dt = abs(float(g.t[k]) - float(init.t))
    p = run.origin.to_ned(
        np.array([init.lat, g.lat[k]]), np.array([init.lon, g.lon[k]]), np.array([init.h, g.h[k]])
    )
    d = float(np.linalg.norm(p[0] - p[1]))
    tol = 100.0 + 50.0 * dt + 10.0 * float(np.max(g.sigma_ned[k]))
    if d <= tol:
        return None
    return Finding(
        "init_position",
        where,
        f"the initial position is {d / 1000:.4g} km from the GNSS fix {dt:.2f} s "
        f"from it (at most {tol:.0f} m is plausible): the two disagree in their coordinates",
        "check lat_deg, lon_deg, h_m and t of the initial state against the fixes",
        lambda r: replace(r, init=None),
        "started from the fixes instead of the given initial state",
        details={"distance_m": d},
    )
