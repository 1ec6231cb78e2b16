"""IMU error model of the simulator: named grades, their parameters and the per-run error draws.

Each sensor triad (accelerometers [m/s^2], gyros [rad/s], body axes FRD) measures

    measured = (I + S + M) true + bias + white noise + vibration

* ``S = diag(s)``: scale-factor errors, ``M``: cross-axis errors (non-orthogonality and
  misalignment, zero diagonal, not symmetric), both drawn once per run.
* ``bias = turn-on + Gauss-Markov + drift``: a constant turn-on bias, a first-order Gauss-Markov
  bias instability, and a slow drift (a warm-up exponential plus a slow random walk), both drift
  terms zero at the first sample.
* white noise of the datasheet density (ARW / VRW), independent per sample.
* vibration: engine harmonics and broadband road vibration (:mod:`.sim_vibration`).

Grades ``perfect``, ``consumer-basic``, ``industrial-basic``, ``tactical-basic`` have white
noise, turn-on and Gauss-Markov biases only (the simulator's original grades, reproduced bit for
bit). ``consumer``, ``industrial``, ``tactical`` add every other error source.

Resulting per-sample scatter (std of measured minus true) at 100 Hz, gyro x / y / z [deg/s] and
accelerometer x / y / z [m/s^2], white noise included:

==========  ===========  ==================  ==================
grade       speed [m/s]  gyro                accelerometer
==========  ===========  ==================  ==================
consumer    0 (idle)     2.38 / 2.38 / 0.80  0.60 / 0.70 / 0.89
consumer    10           2.78 / 2.78 / 1.11  0.87 / 0.91 / 1.42
consumer    15           3.61 / 3.60 / 1.51  1.20 / 1.23 / 1.98
industrial  0 (idle)     0.30 / 0.30 / 0.11  0.08 / 0.09 / 0.11
industrial  15           0.45 / 0.45 / 0.19  0.15 / 0.15 / 0.25
tactical    0 (idle)     0.08 / 0.08 / 0.03  0.02 / 0.02 / 0.03
tactical    15           0.12 / 0.12 / 0.05  0.04 / 0.04 / 0.07
==========  ===========  ==================  ==================

For comparison, the datasheet white noise alone gives 0.10 deg/s and 0.033 m/s^2 per sample for
``consumer``: vibration dominates the scatter of a vehicle IMU by far.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np

from ..core.config import DEFAULTS
from ..core.units import DEG, MG
from ..core.errors import InputError

WHERE = "simulator"

#: Keys of an IMU grade known to the filter: ``gnssacc.core.config.DEFAULTS["imu"]`` but the
#: filter's allowances for the gyro scale-factor and cross-axis errors (``gyro_turn_error_ppm``)
#: and the accelerometer triad's (``accel_misalignment_ppm``), which the simulator draws as
#: unmodelled errors of its own (``gyro_scale_factor_ppm``, ``gyro_cross_axis_ppm``,
#: ``accel_cross_axis_ppm``: :data:`IMU_EXTRA_ERRORS`), not as a grade's filter setting.
GRADE_KEYS = tuple(
    k for k in DEFAULTS["imu"] if k not in ("gyro_turn_error_ppm", "accel_misalignment_ppm")
)


def _grade(arw, vrw, gbi, abi, g0, a0, tau=300.0) -> dict:
    return {
        "gyro_arw_deg_rth": arw,
        "accel_vrw_mps_rth": vrw,
        "gyro_bias_instability_deg_h": gbi,
        "accel_bias_instability_mg": abi,
        "bias_correlation_time_s": tau,
        "gyro_bias_sigma0_deg_h": g0,
        "accel_bias_sigma0_mg": a0,
    }


#: Filter-visible parameters of each grade, in the units of ``gnssacc.core.config.DEFAULTS["imu"]``:
#: ARW [deg/sqrt(h)], VRW [m/s/sqrt(h)], bias instability [deg/h] and [mg] (Gauss-Markov
#: sigma), correlation time [s], turn-on bias 1-sigma [deg/h] and [mg].
IMU_GRADES: dict[str, dict] = {
    "perfect": _grade(0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
    # The original grades. MEMS phone-like: turn-on gyro bias 0.5 deg/s = 1800 deg/h.
    "consumer-basic": _grade(0.6, 0.2, 30.0, 0.5, 1800.0, 30.0),
    # VN-300 class: turn-on gyro bias 0.1 deg/s = 360 deg/h.
    "industrial-basic": _grade(0.2, 0.05, 5.0, 0.04, 360.0, 5.0),
    "tactical-basic": _grade(0.05, 0.02, 0.5, 0.02, 2.0, 1.0),
    # Realistic grades; a car's consumer MEMS IMU has a turn-on gyro bias of 0.1-0.3 deg/s.
    "consumer": _grade(0.6, 0.2, 30.0, 0.5, 500.0, 30.0),
    "industrial": _grade(0.2, 0.05, 5.0, 0.04, 360.0, 5.0),
    "tactical": _grade(0.05, 0.02, 0.5, 0.02, 2.0, 1.0),
}

#: The vibration environment of a car-like vehicle (shared by every grade; the grades differ in
#: the amplitudes, i.e. in the mount and the sensor's sensitivity).
VIBRATION_ENVIRONMENT = {
    "vib_engine_harmonics": (1.0, 0.5, 0.25),  # relative amplitudes of harmonics 1, 2, 3 [-]
    "vib_engine_idle_hz": 27.0,  # fundamental at rest (engine idling) [Hz]
    "vib_engine_hz_per_mps": 2.5,  # rise of the fundamental with speed [Hz / (m/s)]
    "vib_engine_max_hz": 70.0,  # highest fundamental [Hz]
    "vib_engine_wander": 0.03,  # 1-sigma relative wander of the fundamental [-]
    "vib_engine_wander_time_s": 3.0,  # correlation time of the wander [s]
    "vib_road_band_hz": (5.0, 100.0),  # flat band of the road vibration [Hz]
    "vib_road_ref_speed_mps": 10.0,  # speed at which the road RMS applies [m/s]
    "vib_road_speed_exponent": 1.0,  # road RMS ~ (|v| / ref) ** exponent [-]
}


def _extra(sf, cross, warm_g, warm_a, warm_tau, rw_g, rw_a, eng_g, eng_a, road_g, road_a) -> dict:
    eng_g, eng_a, road_g, road_a = (
        tuple(float(x) for x in v) for v in (eng_g, eng_a, road_g, road_a)
    )
    return {
        "gyro_scale_factor_ppm": sf,
        "accel_scale_factor_ppm": sf,
        "gyro_cross_axis_ppm": cross,
        "accel_cross_axis_ppm": cross,
        "gyro_warmup_deg_h": warm_g,
        "accel_warmup_mg": warm_a,
        "warmup_time_s": warm_tau,
        "gyro_bias_rw_deg_h_rth": rw_g,
        "accel_bias_rw_mg_rth": rw_a,
        "vib_engine_gyro_dps": eng_g,
        "vib_engine_accel_mps2": eng_a,
        "vib_road_gyro_dps": road_g,
        "vib_road_accel_mps2": road_a,
        **VIBRATION_ENVIRONMENT,
    }


#: Consumer vibration amplitudes, per axis x, y, z: engine fundamental (peak) gyro [deg/s] and
#: accelerometer [m/s^2], road RMS at the reference speed, gyro [deg/s] and accelerometer [m/s^2].
_CONSUMER_VIBRATION = (
    np.array([3.6, 3.6, 1.2]),
    np.array([0.9, 1.05, 1.35]),
    np.array([3.5, 3.5, 1.5]),
    np.array([1.2, 1.2, 2.0]),
)

_NONE = _extra(0.0, 0.0, 0.0, 0.0, 300.0, 0.0, 0.0, *(np.zeros(3),) * 4)

#: Unmodelled error parameters of each grade (no filter keys):
#: scale factor and cross-axis 1-sigma [ppm] (per axis, per off-diagonal element), warm-up drift
#: amplitude 1-sigma [deg/h] / [mg] and time constant [s], bias random walk [deg/h/sqrt(h)] /
#: [mg/sqrt(h)], engine vibration amplitude of the fundamental (peak, continuous time) [deg/s] /
#: [m/s^2] per axis, road vibration continuous-time RMS at the reference speed [deg/s] / [m/s^2]
#: per axis, and the :data:`VIBRATION_ENVIRONMENT`.
IMU_EXTRA_ERRORS: dict[str, dict] = {
    "perfect": _NONE,
    "consumer-basic": _NONE,
    "industrial-basic": _NONE,
    "tactical-basic": _NONE,
    # Rigid mount in a car. Engine: 2.4 deg/s gyro x/y and 0.6-0.9 m/s^2 scatter per 100 Hz
    # sample at idle, as in a real car; road: 2.3 deg/s and 0.8-1.3 m/s^2 per sample at 10 m/s.
    "consumer": _extra(10000.0, 7000.0, 30.0, 0.5, 300.0, 10.0, 0.1, *_CONSUMER_VIBRATION),
    # Isolated mount: vibration 8 times less.
    "industrial": _extra(
        750.0, 500.0, 5.0, 0.04, 300.0, 1.0, 0.01, *(v / 8.0 for v in _CONSUMER_VIBRATION)
    ),
    # Isolated mount, less vibration-sensitive sensors: 30 times less.
    "tactical": _extra(
        100.0, 100.0, 0.5, 0.02, 600.0, 0.1, 0.005, *(v / 30.0 for v in _CONSUMER_VIBRATION)
    ),
}

#: Every key of a full error description (:func:`imu_error_model`).
MODEL_KEYS = GRADE_KEYS + tuple(_NONE)
#: The magnitudes of the unmodelled error sources: zero them (``imu_overrides``) to switch a
#: realistic grade's unmodelled errors off.
UNMODELLED_KEYS = tuple(k for k in _NONE if k not in VIBRATION_ENVIRONMENT and k != "warmup_time_s")


def _check_grade(grade: str) -> None:
    if grade not in IMU_GRADES:
        raise InputError(WHERE, f"unknown IMU grade {grade!r} (known: {', '.join(IMU_GRADES)})")


def grade_config(grade: str, overrides: dict | None = None) -> dict:
    """Filter configuration of a named grade: what a user with the IMU's datasheet would set.

    These are the true values of the errors the filter models: the white-noise densities (ARW,
    VRW) as on a datasheet, the Gauss-Markov bias instability and its correlation time, and the
    turn-on bias sigmas. Vibration, scale-factor and cross-axis errors and the slow bias drift
    (warm-up, random walk) have no filter keys: they are unmodelled errors the filter must cope
    with. In particular the vibration is not folded into the ARW / VRW, although it dominates
    the per-sample scatter (at idle about 2.4 deg/s per 100 Hz sample for ``consumer``, 24 times
    the 0.1 deg/s of its ARW); nor is the drift folded into the bias keys.
    :func:`imu_error_model` gives every parameter.

    Parameters
    ----------
    grade : str
        A key of :data:`IMU_GRADES`: ``perfect``, ``consumer``, ``industrial``, ``tactical`` or
        the original ``consumer-basic``, ``industrial-basic``, ``tactical-basic``.
    overrides : dict, optional
        Keys of ``gnssacc.core.config.DEFAULTS["imu"]`` to replace (scalar or three per-axis values).

    Returns
    -------
    dict
        The keys of ``gnssacc.core.config.DEFAULTS["imu"]``, usable as
        ``gnssacc.core.config.load_config(overrides={"imu": grade_config(grade)})``. ``"perfect"``
        gives zeros, which a filter cannot use as process noise (``load_config`` refuses them).

    Raises
    ------
    InputError
        Unknown grade, unknown override key, or a non-positive correlation time.
    """
    _check_grade(grade)
    params = dict(IMU_GRADES[grade])
    for key, value in (overrides or {}).items():
        if key not in params:
            raise InputError(
                WHERE, f"unknown IMU parameter {key!r} (known: {', '.join(GRADE_KEYS)})"
            )
        params[key] = value
    if float(params["bias_correlation_time_s"]) <= 0:
        raise InputError(WHERE, "bias_correlation_time_s must be positive")
    return params


def imu_error_model(grade: str, overrides: dict | None = None) -> dict:
    """Full error description of a named grade: :func:`grade_config` plus the unmodelled errors.

    Parameters
    ----------
    grade : str
        A key of :data:`IMU_GRADES`.
    overrides : dict, optional
        Any keys of :data:`MODEL_KEYS` to replace (per-axis keys take a scalar or three values).

    Returns
    -------
    dict
        The :func:`grade_config` keys, then (per axis = x, y, z of the body frame):
        ``gyro_scale_factor_ppm``, ``accel_scale_factor_ppm`` (1-sigma per axis [ppm]),
        ``gyro_cross_axis_ppm``, ``accel_cross_axis_ppm`` (1-sigma of each off-diagonal element,
        per row = sensing axis [ppm]), ``gyro_warmup_deg_h`` [deg/h], ``accel_warmup_mg`` [mg]
        (1-sigma amplitude of the warm-up drift ``A (1 - exp(-t / warmup_time_s))``),
        ``warmup_time_s`` [s], ``gyro_bias_rw_deg_h_rth`` [deg/h/sqrt(h)],
        ``accel_bias_rw_mg_rth`` [mg/sqrt(h)] (bias random walk), ``vib_engine_gyro_dps``
        [deg/s], ``vib_engine_accel_mps2`` [m/s^2] (peak amplitude of the engine fundamental per
        axis, continuous time, before the IMU's interval averaging), ``vib_road_gyro_dps``
        [deg/s], ``vib_road_accel_mps2`` [m/s^2] (continuous-time RMS of the road vibration per
        axis at ``vib_road_ref_speed_mps``), and the keys of :data:`VIBRATION_ENVIRONMENT`.

    Raises
    ------
    InputError
        Unknown grade or key, or an inconsistent value.
    """
    _check_grade(grade)
    extra = {k: v for k, v in (overrides or {}).items() if k not in GRADE_KEYS}
    model = {
        **grade_config(grade, {k: v for k, v in (overrides or {}).items() if k in GRADE_KEYS}),
        **IMU_EXTRA_ERRORS[grade],
    }
    for key, value in extra.items():
        if key not in model:
            raise InputError(
                WHERE, f"unknown IMU error parameter {key!r} (known: {', '.join(MODEL_KEYS)})"
            )
        model[key] = value
    lo, hi = (float(x) for x in model["vib_road_band_hz"])
    if not 0.0 <= lo < hi:
        raise InputError(
            WHERE, f"vib_road_band_hz must be (lo, hi) with 0 <= lo < hi, got {(lo, hi)}"
        )
    for key in ("warmup_time_s", "vib_engine_wander_time_s", "vib_road_ref_speed_mps"):
        if not float(model[key]) > 0:
            raise InputError(WHERE, f"{key} must be positive")
    return model


def per_axis(value) -> np.ndarray:
    """A scalar or three per-axis values as a float array of shape (3,)."""
    return np.broadcast_to(np.asarray(value, float), (3,)).copy()


def imu_sigmas_si(params: dict) -> dict:
    """Filter-visible grade parameters in SI units, per axis.

    Parameters
    ----------
    params : dict
        As returned by :func:`grade_config` (or :func:`imu_error_model`).

    Returns
    -------
    dict
        ``gyro_density`` [rad/s/sqrt(Hz)], ``accel_density`` [m/s^2/sqrt(Hz)],
        ``gyro_bi``, ``gyro_sigma0`` [rad/s], ``accel_bi``, ``accel_sigma0`` [m/s^2],
        ``tau`` [s].
    """
    return {
        "gyro_density": per_axis(params["gyro_arw_deg_rth"]) * DEG / 60.0,
        "accel_density": per_axis(params["accel_vrw_mps_rth"]) / 60.0,
        "gyro_bi": per_axis(params["gyro_bias_instability_deg_h"]) * DEG / 3600.0,
        "accel_bi": per_axis(params["accel_bias_instability_mg"]) * MG,
        "gyro_sigma0": per_axis(params["gyro_bias_sigma0_deg_h"]) * DEG / 3600.0,
        "accel_sigma0": per_axis(params["accel_bias_sigma0_mg"]) * MG,
        "tau": float(params["bias_correlation_time_s"]),
    }


def gauss_markov(n: int, dt: float, tau: float, sigma, rng: np.random.Generator) -> np.ndarray:
    """Stationary first-order Gauss-Markov sequence, one column per channel.

    ``x[k] = a x[k-1] + sqrt(1 - a^2) sigma w[k]``, ``a = exp(-dt / tau)``, ``x[0] ~ N(0, sigma^2)``.

    Parameters
    ----------
    n : int
        Number of samples.
    dt : float
        Sample interval [s].
    tau : float
        Correlation time [s].
    sigma : float or ndarray, shape (c,)
        Stationary 1-sigma per channel (any unit; the output has the same unit). A scalar gives
        three channels (the three axes).
    rng : numpy.random.Generator

    Returns
    -------
    ndarray, shape (n, 3) or (n, c)
    """
    return GaussMarkovStream(n, dt, tau, sigma, rng).take(n)


class GaussMarkovStream:
    """:func:`gauss_markov` in consecutive chunks (:meth:`take`): the same numbers, bit for bit.

    The initial value is drawn at construction, the driving noise as the chunks are taken, so
    memory does not grow with ``n``. Parameters are those of :func:`gauss_markov`.
    """

    def __init__(self, n: int, dt: float, tau: float, sigma, rng: np.random.Generator):
        sigma = per_axis(sigma) if np.ndim(sigma) == 0 else np.asarray(sigma, float).copy()
        self.n, self.rng, self.k = int(n), rng, 0
        self.a = np.exp(-dt / tau)
        self.scale = np.sqrt(1.0 - self.a * self.a) * sigma
        # Closed form per block, x[s+i] = a^i (x[s] + sum_j a^-j e_j), vectorised; the block length
        # keeps a^-i below 1e6 so the scaled cumulative sum stays accurate.
        self.block = max(1, int(np.log(1e6) * tau / dt))
        self.x0 = rng.standard_normal(len(sigma)) * sigma
        self._xs, self._p, self._off, self._cum = self.x0, np.zeros(0), 0, None

    def take(self, m: int) -> np.ndarray:
        """The next ``m`` samples, shape (m, c)."""
        out = np.empty((m, len(self.x0)))
        j = 0
        if m and self.k == 0:
            out[0], j, self.k = self.x0, 1, 1
        while j < m:
            if self._off == len(self._p):  # a new block starts at sample k - 1
                self._p = self.a ** np.arange(1, min(self.block, self.n - self.k) + 1)
                self._off, self._cum = 0, None
            q = min(m - j, len(self._p) - self._off)
            p = self._p[self._off : self._off + q, None]
            steps = self.rng.standard_normal((q, len(self.x0))) * self.scale / p
            cum = (
                np.cumsum(steps, axis=0)
                if self._cum is None
                else np.cumsum(np.concatenate([self._cum[None], steps]), axis=0)[1:]
            )
            out[j : j + q] = p * (self._xs + cum)
            self._cum, self._off, j, self.k = cum[-1], self._off + q, j + q, self.k + q
            if self._off == len(self._p):
                self._xs = out[j - 1].copy()
        return out


def skip_normals(rng: np.random.Generator, count: int, chunk: int = 1 << 16) -> None:
    """Advance ``rng`` past ``count`` standard normal draws (in chunks: small memory)."""
    for k in range(0, count, chunk):
        rng.standard_normal(min(chunk, count - k))


@dataclass
class BiasSeed:
    """What draws a run's turn-on + Gauss-Markov biases (:class:`ImuErrorStream`): enough to draw
    them again, bit for bit, instead of keeping them per sample (a few hundred bytes).

    Attributes
    ----------
    n : int
        Number of IMU samples.
    dt : float
        IMU interval [s].
    tau : float
        Gauss-Markov correlation time [s].
    sigma_a, sigma_g : ndarray
        Gauss-Markov 1-sigma, accelerometer [m/s^2] and gyro [rad/s].
    turn_on_a, turn_on_g : ndarray, shape (3,)
        Turn-on biases [m/s^2], [rad/s].
    rng_a, rng_g : numpy.random.Generator
        At the starts of the two Gauss-Markov sections of the stream; never advanced (each
        :meth:`streams` reads copies).
    """

    n: int
    dt: float
    tau: float
    sigma_a: np.ndarray
    sigma_g: np.ndarray
    turn_on_a: np.ndarray
    turn_on_g: np.ndarray
    rng_a: np.random.Generator
    rng_g: np.random.Generator

    def streams(self) -> tuple["GaussMarkovStream", "GaussMarkovStream"]:
        """Fresh Gauss-Markov streams (accelerometer, gyro) from the first sample."""
        return (
            GaussMarkovStream(self.n, self.dt, self.tau, self.sigma_a, copy.deepcopy(self.rng_a)),
            GaussMarkovStream(self.n, self.dt, self.tau, self.sigma_g, copy.deepcopy(self.rng_g)),
        )


class ImuErrorStream:
    """:func:`imu_errors` in consecutive chunks (:meth:`take`): the same numbers, bit for bit.

    The stream's four long sections (Gauss-Markov biases, then white noise, accelerometer before
    gyro, ``3 n`` normal draws each) are read side by side by four copies of ``rng`` set to
    their starts (found by drawing through them once), so memory does not grow with ``n``.
    ``rng`` is left where :func:`imu_errors` leaves it. Parameters are those of :func:`imu_errors`.

    Attributes
    ----------
    turn_on_a : ndarray, shape (3,)
        Accelerometer turn-on bias [m/s^2].
    turn_on_g : ndarray, shape (3,)
        Gyro turn-on bias [rad/s].
    """

    def __init__(self, n: int, dt: float, params: dict, rng: np.random.Generator):
        si = imu_sigmas_si(params)
        self.turn_on_a = rng.standard_normal(3) * si["accel_sigma0"]
        self.turn_on_g = rng.standard_normal(3) * si["gyro_sigma0"]
        starts = []
        for _ in range(4):
            starts.append(copy.deepcopy(rng))
            skip_normals(rng, 3 * n)
        self.bias_seed = BiasSeed(
            n,
            dt,
            si["tau"],
            si["accel_bi"],
            si["gyro_bi"],
            self.turn_on_a,
            self.turn_on_g,
            starts[0],
            starts[1],
        )
        self._gm_a, self._gm_g = self.bias_seed.streams()
        self._noise = (
            (starts[2], si["accel_density"] / np.sqrt(dt)),
            (starts[3], si["gyro_density"] / np.sqrt(dt)),
        )

    def take(self, m: int) -> dict:
        """The next ``m`` samples: ``bias_a``, ``bias_g``, ``noise_a``, ``noise_g`` of :func:`imu_errors`."""
        (rng_a, scale_a), (rng_g, scale_g) = self._noise
        return {
            "bias_a": self.turn_on_a + self._gm_a.take(m),
            "bias_g": self.turn_on_g + self._gm_g.take(m),
            "noise_a": rng_a.standard_normal((m, 3)) * scale_a,
            "noise_g": rng_g.standard_normal((m, 3)) * scale_g,
        }


def imu_errors(n: int, dt: float, params: dict, rng: np.random.Generator) -> dict:
    """Draw the filter-visible IMU errors of one run (the whole error model of the basic grades).

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
        ``noise_a`` [m/s^2], ``noise_g`` [rad/s] (white, shape (n, 3), 1-sigma density/sqrt(dt)),
        ``turn_on_a`` [m/s^2], ``turn_on_g`` [rad/s] (the turn-on biases, shape (3,)).
    """
    stream = ImuErrorStream(n, dt, params, rng)
    return {**stream.take(n), "turn_on_a": stream.turn_on_a, "turn_on_g": stream.turn_on_g}


def sensor_matrices(model: dict, rng: np.random.Generator) -> dict:
    """Draw the scale-factor and cross-axis errors of one run.

    Draw order: accelerometer scale factors (3), accelerometer cross-axis (3 x 3, diagonal
    unused), then the same for the gyros.

    Returns
    -------
    dict
        ``K_a``, ``K_g``: ``I + S + M`` (shape (3, 3), measured = K @ true); the draws
        ``accel_scale_factor``, ``gyro_scale_factor`` (shape (3,), dimensionless) and
        ``accel_cross_axis``, ``gyro_cross_axis`` (shape (3, 3), zero diagonal, dimensionless;
        row i = sensitivity of sensing axis i to the other axes).
    """
    out = {}
    for sensor in ("accel", "gyro"):
        s = rng.standard_normal(3) * per_axis(model[f"{sensor}_scale_factor_ppm"]) * 1e-6
        m = (
            rng.standard_normal((3, 3))
            * per_axis(model[f"{sensor}_cross_axis_ppm"])[:, None]
            * 1e-6
        )
        np.fill_diagonal(m, 0.0)
        out[f"{sensor}_scale_factor"], out[f"{sensor}_cross_axis"] = s, m
        out[f"K_{sensor[0]}"] = np.eye(3) + np.diag(s) + m
    return out


def bias_drift(
    t_rel: np.ndarray, model: dict, rng: np.random.Generator, rw_step_s: float = 1.0
) -> dict:
    """Draw the slow bias drift of one run: warm-up exponential plus random walk, zero at ``t_rel = 0``.

    Parameters
    ----------
    t_rel : ndarray, shape (n,)
        Sample times from the first sample [s] (sorted, starting at 0).
    model : dict
        :func:`imu_error_model`.
    rng : numpy.random.Generator
        Draw order: warm-up amplitudes (accel 3, gyro 3), then the random-walk increments.
    rw_step_s : float
        The random walk is drawn on this grid [s] and interpolated linearly (it is slow).

    Returns
    -------
    dict
        ``drift_a`` [m/s^2], ``drift_g`` [rad/s] (shape (n, 3)) and the draws
        ``accel_warmup`` [m/s^2], ``gyro_warmup`` [rad/s] (warm-up amplitudes, shape (3,)).
    """
    drift = BiasDrift(float(t_rel[-1]), model, rng, rw_step_s)
    drift_a, drift_g = drift.at(t_rel)
    return {
        "drift_a": drift_a,
        "drift_g": drift_g,
        "accel_warmup": drift.warm_a,
        "gyro_warmup": drift.warm_g,
    }


class BiasDrift:
    """The drift of :func:`bias_drift`, drawn once for a run lasting ``t_end`` [s], evaluated at any times.

    Attributes
    ----------
    warm_a : ndarray, shape (3,)
        Accelerometer warm-up amplitude [m/s^2].
    warm_g : ndarray, shape (3,)
        Gyro warm-up amplitude [rad/s].
    """

    def __init__(self, t_end: float, model: dict, rng: np.random.Generator, rw_step_s: float = 1.0):
        self.warm_a = rng.standard_normal(3) * per_axis(model["accel_warmup_mg"]) * MG
        self.warm_g = rng.standard_normal(3) * per_axis(model["gyro_warmup_deg_h"]) * DEG / 3600.0
        # Random-walk densities in SI: [mg/sqrt(h)] -> [m/s^2/sqrt(s)], [deg/h/sqrt(h)] -> [rad/s/sqrt(s)].
        k = np.concatenate(
            [
                per_axis(model["accel_bias_rw_mg_rth"]) * MG / 60.0,
                per_axis(model["gyro_bias_rw_deg_h_rth"]) * DEG / 3600.0 / 60.0,
            ]
        )
        m = int(np.ceil(t_end / rw_step_s)) + 1
        steps = rng.standard_normal((m - 1, 6)) * (k * np.sqrt(rw_step_s))
        self._walk = np.vstack([np.zeros((1, 6)), np.cumsum(steps, axis=0)])
        self._grid = rw_step_s * np.arange(m)
        self._tau = float(model["warmup_time_s"])

    def at(self, t_rel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Drift at times ``t_rel`` from the first sample [s]: accelerometers [m/s^2], gyros [rad/s], (k, 3) each."""
        rw = np.column_stack([np.interp(t_rel, self._grid, self._walk[:, i]) for i in range(6)])
        shape = -np.expm1(-t_rel / self._tau)[:, None]
        return shape * self.warm_a + rw[:, :3], shape * self.warm_g + rw[:, 3:]
