"""The gyro turn allowance from the recording's own gyro noise (``[imu] gyro_turn_error_ppm =
"auto"``, the default).

Both estimators cover the gyros' constant scale-factor and cross-axis errors, which the 15-state
model does not carry, with noise that grows with the angle turned
(:attr:`gnssacc.core.config.RunConfig.gyro_turn_psd`). The fixes' likelihood cannot tell its size
(:mod:`gnssacc.prepare.tuning`), and a recording does not state its IMU's grade, but its
stationary spans show how noisy its gyros are: the white-noise density measured at rest
(:func:`gnssacc.prepare.stationary.noise_from_stationary`, spans of 10 s or more; on a run without
one, the spans of :data:`SHORT_REST_S` or more: :func:`rest_allowance`). Datasheets tie the two
loosely (:data:`ANCHORS`), which makes a prior: explicit values, a preset's included, are used as
given. A run without such a span keeps :data:`gnssacc.core.config.FALLBACK_TURN_ERROR_PPM`:
the density the tuner identifies in motion is no measurement of the gyros' white noise, as it
trades against the very errors the allowance covers (on a simulated industrial car, true 0.2
deg/sqrt(h) and 0.198 at rest on the same grade's city drive, the tuner gave 0.033; on a consumer
phone IMU, comma2k19, 0.14 or 0.42 depending on the lever arm configured).
"""

from __future__ import annotations

import numpy as np

from ..core.config import FALLBACK_TURN_ERROR_PPM, RunConfig
from .stationary import noise_from_stationary

#: Datasheet anchors, ``(gyro white-noise density [deg/sqrt(h)], 1-sigma gyro scale-factor and
#: cross-axis error [ppm])`` by grade: tactical (fibre-optic and high-end MEMS of the KVH 1750 /
#: Honeywell HG1700 class: ARW 0.01-0.1 deg/sqrt(h), scale factor and misalignment 100-500 ppm);
#: industrial MEMS (Analog Devices ADIS1647x, Xsens MTi, VectorNav VN-100/300: 0.1-0.4
#: deg/sqrt(h), 0.1-0.5 %); consumer MEMS (Bosch BMI088 / BMI270, InvenSense ICM-20948 /
#: ICM-42688: 0.2-0.9 deg/sqrt(h) and several deg/h of bias instability, sensitivity tolerance
#: and cross-axis sensitivity +-1-2 %). The densities overlap between grades, so the relation is
#: loose: a prior for runs whose configuration does not say, not a measurement. The same pairs
#: are the packaged presets' (``tactical``, ``industrial``; ``consumer`` at its datasheet density).
ANCHORS = ((0.05, 150.0), (0.2, 1000.0), (0.6, 10000.0))


#: Datasheet anchors of the accelerometers' turn-on bias, ``(gyro white-noise density
#: [deg/sqrt(h)], 1-sigma accelerometer turn-on bias [mg])`` by grade, the packaged presets'
#: values: tactical (HG1700 class: ~1 mg), industrial MEMS (ADIS1647x, VN-100/300: a few mg),
#: consumer MEMS (BMI088, ICM-42688 zero-g offsets of +-20-50 mg). As loose as :data:`ANCHORS`:
#: the prior of a run that cannot measure it (:func:`accel_turn_on_mg`).
TURN_ON_ANCHORS = ((0.05, 1.0), (0.2, 5.0), (0.6, 40.0))


def _by_class(arw_deg_rth: float, anchors) -> float:
    """``anchors``' second value at this gyro density: linear in log-log between them, held at
    the end anchors' beyond them."""
    x, y = np.log(np.array(anchors)).T
    return float(np.exp(np.interp(np.log(arw_deg_rth), x, y)))


def accel_turn_on_mg(arw_deg_rth: float) -> float:
    """The accelerometer turn-on bias 1-sigma [mg] an IMU whose gyros have this white noise
    [deg/sqrt(h)] typically has (:data:`TURN_ON_ANCHORS`, as :func:`turn_error_ppm`); NaN for a
    density that is not a positive finite number."""
    if not (np.isfinite(arw_deg_rth) and arw_deg_rth > 0.0):
        return float("nan")
    return _by_class(arw_deg_rth, TURN_ON_ANCHORS)


def turn_error_ppm(arw_deg_rth: float) -> float:
    """The gyro scale-factor and cross-axis error a gyro of this white noise typically has.

    Interpolated linearly in log(density) - log(ppm) between :data:`ANCHORS` and held at the
    end anchors' values beyond them (smooth and increasing in between, no steps).

    Parameters
    ----------
    arw_deg_rth : float
        The gyros' white-noise density (angle random walk) [deg/sqrt(h)].

    Returns
    -------
    float
        1-sigma error [ppm]; :data:`gnssacc.core.config.FALLBACK_TURN_ERROR_PPM` for a density
        that is not a positive finite number.
    """
    if not (np.isfinite(arw_deg_rth) and arw_deg_rth > 0.0):
        return FALLBACK_TURN_ERROR_PPM
    return _by_class(arw_deg_rth, ANCHORS)


def gyro_density_deg_rth(values) -> float:
    """One white-noise density of the three gyros [deg/sqrt(h)]: the geometric mean of the finite
    positive per-axis values ``values`` [deg/sqrt(h)], NaN when there is none."""
    v = np.atleast_1d(np.asarray(values, float))
    v = v[np.isfinite(v) & (v > 0.0)]
    return float(np.exp(np.mean(np.log(v)))) if v.size else float("nan")


def resolved(cfg: RunConfig, arw_deg_rth: float, what: str) -> RunConfig:
    """``cfg`` with an ``"auto"`` turn allowance set from the gyro noise, else ``cfg`` itself.

    Parameters
    ----------
    cfg : RunConfig
    arw_deg_rth : float
        The recording's gyro white-noise density [deg/sqrt(h)] (:func:`gyro_density_deg_rth`);
        NaN: nothing is set (the estimators use the fallback of
        :attr:`gnssacc.core.config.RunConfig.gyro_turn_psd`).
    what : str
        Where the density came from, recorded as the value's source (e.g. ``"at rest"``).

    Returns
    -------
    RunConfig
    """
    if cfg["imu"]["gyro_turn_error_ppm"] != "auto" or not np.isfinite(arw_deg_rth):
        return cfg
    ppm = round(turn_error_ppm(arw_deg_rth), 1)
    source = f"turn allowance from the gyro noise {what} ({arw_deg_rth:.3g} deg/sqrt(h))"
    return cfg.with_values({"imu": {"gyro_turn_error_ppm": ppm}}, source)


#: rad/s/sqrt(Hz) = rad/sqrt(s) -> deg/sqrt(h).
RAD_RTS_TO_DEG_RTH = float(np.degrees(1.0) * 60.0)


#: Shortest stationary span [s] whose gyro noise sets the allowance on a run without a span of
#: 10 s (the tuner's starting values need those: their bias instability and the accelerometers'
#: vibration leaks; the allowance needs only the gyros' white density, as a loose prior). The
#: Allan deviation is read up to a quarter of a span: 1 s here, past the vibration lines a
#: 100 Hz IMU removes. Short spans read the density low by up to 15 % on strong idle vibration
#: (:func:`gnssacc.prepare.stationary.noise_from_stationary`), the allowance 30 % (the anchors'
#: log-log slope is about 2), against a factor of 10 between the fallback and a consumer gyro's.
#: Stops at lights or a UGV's pauses of 5-10 s: simulated consumer and industrial UGVs (spans of
#: 4.3-7.9 s) read 0.573 and 0.197 deg/sqrt(h), truth 0.6 and 0.2.
SHORT_REST_S = 4.0


def rest_allowance(cfg: RunConfig, imu, stationary, noise) -> RunConfig:
    """``cfg`` with an ``"auto"`` turn allowance from the gyros' white-noise density measured at
    rest: ``noise``'s (:class:`gnssacc.prepare.stationary.StationaryNoise` of the spans of 10 s or
    more) when it has a span, else that of the spans of :data:`SHORT_REST_S` or more in
    ``stationary`` (:class:`gnssacc.prepare.stationary.StationaryReport` of ``imu``); ``cfg``
    unchanged without either (the fallback applies), or when the value is not ``"auto"``."""
    if cfg["imu"]["gyro_turn_error_ppm"] != "auto":
        return cfg
    what = "at rest"
    if noise is None or not noise.n_spans:
        if stationary is None or not stationary.spans:
            return cfg
        noise = noise_from_stationary(imu, stationary, min_span_s=SHORT_REST_S)
        if not noise.n_spans:
            return cfg
        what = f"at rest ({noise.n_spans} spans of {SHORT_REST_S:g}-10 s, {noise.total_s:.0f} s)"
    return resolved(cfg, rest_density_deg_rth(noise), what)


def rest_density_deg_rth(noise) -> float:
    """The gyros' white-noise density measured at rest [deg/sqrt(h)] (:func:`gyro_density_deg_rth`
    of ``noise``'s, a :class:`gnssacc.prepare.stationary.StationaryNoise`): the IMU's class for
    the priors of this module; NaN without a span."""
    if noise is None or not noise.n_spans:
        return float("nan")
    return gyro_density_deg_rth(np.asarray(noise.gyro_density, float) * RAD_RTS_TO_DEG_RTH)
