"""Vehicle vibration seen by the simulated IMU: engine harmonics and broadband road vibration.

Vibration is applied as sensor error, additive on the accelerometers [m/s^2] and the gyros
[rad/s] per body axis; the tiny real body motion it implies (millimetres, hundredths of a
degree) is not put into the truth. The simulated IMU integrates: sample k is the mean over
``(t[k-1], t[k]]``, and so is its vibration error.

* Engine: harmonics ``h = 1, 2, ...`` of a fundamental ``f(t) = min(idle + slope |v|, max)
  (1 + w(t))``, ``v`` the speed and ``w`` a slow Gauss-Markov wander; the engine idles while the
  vehicle stands. The phase is piecewise linear (``f`` held over each sample interval), so the
  interval mean of ``sin(h phi + theta)`` is exact in closed form,
  ``sin(h phi_mid + theta) sinc(h f dt)``. Harmonics near multiples of the IMU rate alias to
  low frequencies, attenuated by the sinc as in a real integrating IMU.
* Road: Gaussian noise with a flat two-sided PSD on ``lo <= |f| <= hi`` and a given
  continuous-time RMS, scaled by ``(|v| / v_ref) ** p``. Its interval means form a stationary
  sequence with PSD ``P(f) = sum_m S(f + m fs) sinc^2((f + m fs) dt)`` (a boxcar of length dt,
  then sampling at fs = 1/dt, with aliasing); it is synthesised directly at the IMU rate by FFT,
  which gives exactly the second-order statistics of the interval means without a finer
  internal rate. The speed is taken at each interval's midpoint (it changes slowly over dt).
"""
from __future__ import annotations

import numpy as np

from .sim_imu_errors import DEG, per_axis, gauss_markov


def harmonic_interval_mean(phase_edges: np.ndarray, order: int, offset=0.0) -> np.ndarray:
    """Mean of ``sin(order phi(t) + offset)`` over each interval, ``phi`` linear within it.

    Parameters
    ----------
    phase_edges : ndarray, shape (n + 1,)
        Phase of the fundamental at the interval edges [rad].
    order : int
        Harmonic number.
    offset : float or ndarray, shape (c,)
        Phase offsets [rad]; an array gives one column per offset.

    Returns
    -------
    ndarray, shape (n,) or (n, c)
        Exact interval means, ``sin(order phi_mid + offset) sinc(order dphi / 2)``.
    """
    a, b = order * phase_edges[:-1], order * phase_edges[1:]
    mid = 0.5 * (a + b)
    atten = np.sinc((b - a) / (2.0 * np.pi))  # sin(x) / x at x = (b - a) / 2
    s, c = atten * np.sin(mid), atten * np.cos(mid)
    off = np.asarray(offset, float)
    if off.ndim == 0:
        return s * np.cos(off) + c * np.sin(off)
    return s[:, None] * np.cos(off) + c[:, None] * np.sin(off)


def engine_frequency(speed_mid: np.ndarray, dt: float, model: dict, rng: np.random.Generator,
                     wander_step_s: float = 0.05) -> np.ndarray:
    """Engine fundamental over each sample interval [Hz].

    ``min(idle + slope |v|, max) (1 + w)``: ``v`` the speed at the interval midpoints [m/s],
    ``w`` a Gauss-Markov wander (relative 1-sigma ``vib_engine_wander``, correlation time
    ``vib_engine_wander_time_s``) drawn on a ``wander_step_s`` grid and interpolated linearly.
    """
    n = len(speed_mid)
    f_nom = np.minimum(float(model["vib_engine_idle_hz"]) + float(model["vib_engine_hz_per_mps"])
                       * np.abs(speed_mid), float(model["vib_engine_max_hz"]))
    m = int(np.ceil(n * dt / wander_step_s)) + 1
    w = gauss_markov(m, wander_step_s, float(model["vib_engine_wander_time_s"]),
                     np.array([float(model["vib_engine_wander"])]), rng)[:, 0]
    w_mid = np.interp((np.arange(n) + 0.5) * dt, wander_step_s * np.arange(m), w)
    return np.maximum(f_nom * (1.0 + w_mid), 0.0)


def engine_vibration(speed_mid: np.ndarray, dt: float, model: dict, rng: np.random.Generator) -> dict:
    """Interval means of the engine vibration of one run.

    Parameters
    ----------
    speed_mid : ndarray, shape (n,)
        Speed at the midpoint of each sample interval [m/s] (sign ignored).
    dt : float
        IMU interval [s].
    model : dict
        :func:`gnssacc.sources.sim_imu_errors.imu_error_model`.
    rng : numpy.random.Generator
        Draw order: frequency wander, start phase, harmonic phases (accel then gyro).

    Returns
    -------
    dict
        ``vib_a`` [m/s^2], ``vib_g`` [rad/s] (shape (n, 3)), and the draws
        ``engine_phase0`` [rad] (fundamental phase at ``t[0] - dt``),
        ``engine_harmonic_phase`` [rad] (shape (2, H, 3): accel/gyro, harmonic, axis).
    """
    f = engine_frequency(speed_mid, dt, model, rng)
    rel = np.atleast_1d(np.asarray(model["vib_engine_harmonics"], float))
    phase0 = rng.uniform(0.0, 2.0 * np.pi)
    theta = rng.uniform(0.0, 2.0 * np.pi, size=(2, len(rel), 3))
    edges = phase0 + 2.0 * np.pi * dt * np.concatenate([[0.0], np.cumsum(f)])
    amp = np.concatenate([per_axis(model["vib_engine_accel_mps2"]), per_axis(model["vib_engine_gyro_dps"]) * DEG])
    vib = np.zeros((len(f), 6))
    for h, r in enumerate(rel, start=1):
        if r != 0.0:
            vib += (r * amp) * harmonic_interval_mean(edges, h, theta[:, h - 1].reshape(6))
    return {"vib_a": vib[:, :3], "vib_g": vib[:, 3:], "engine_phase0": phase0, "engine_harmonic_phase": theta}


def _fast_len(n: int) -> int:
    """Smallest 2^a 3^b 5^c >= n (fast FFT length)."""
    best = 1 << max(0, (n - 1).bit_length())
    p5 = 1
    while p5 < best:
        p35 = p5
        while p35 < best:
            q = -(-n // p35)
            best = min(best, (1 << max(0, (q - 1).bit_length())) * p35)
            p35 *= 3
        p5 *= 5
    return best


def band_limited_interval_means(n: int, dt: float, band_hz, rng: np.random.Generator,
                                channels: int = 3) -> np.ndarray:
    """Interval means of unit-RMS band-limited Gaussian noise, sampled every ``dt``.

    The continuous process has a flat two-sided PSD ``S = 1 / (2 (hi - lo))`` on
    ``lo <= |f| <= hi`` (variance 1). Sample k is its mean over ``(t[k-1], t[k]]``; the sequence
    is synthesised by FFT (circular, length padded to a fast size and cut) with the PSD of the
    interval means, ``sum_m S(f + m/dt) sinc^2((f + m/dt) dt)``.

    Parameters
    ----------
    n : int
        Number of samples.
    dt : float
        Sample interval [s].
    band_hz : (float, float)
        ``(lo, hi)`` [Hz].
    rng : numpy.random.Generator
    channels : int
        Independent columns.

    Returns
    -------
    ndarray, shape (n, channels)
        Dimensionless (unit continuous-time RMS); variance ``integral of S sinc^2(f dt) df`` < 1.
    """
    lo, hi = (float(x) for x in band_hz)
    size = _fast_len(max(n, 2))
    fs = 1.0 / dt
    f = np.arange(size // 2 + 1) * (fs / size)
    psd = np.zeros(len(f))
    for m in range(-int(np.ceil(hi / fs)) - 1, int(np.ceil(hi / fs)) + 2):
        fm = np.abs(f + m * fs)
        psd += ((fm >= lo) & (fm <= hi)) * np.sinc(fm * dt) ** 2
    psd /= 2.0 * (hi - lo)
    # Complex Gaussian bins of variance size * P * fs, real at DC and Nyquist: var(x) = sum P fs / size.
    spec = rng.standard_normal((len(f), channels)) + 1j * rng.standard_normal((len(f), channels))
    spec *= np.sqrt(0.5 * size * psd * fs)[:, None]
    spec[0] = spec[0].real * np.sqrt(2.0)
    if size % 2 == 0:
        spec[-1] = spec[-1].real * np.sqrt(2.0)
    return np.fft.irfft(spec, n=size, axis=0)[:n]


def road_vibration(speed_mid: np.ndarray, dt: float, model: dict, rng: np.random.Generator) -> dict:
    """Interval means of the broadband road vibration of one run.

    The continuous-time RMS per axis is ``vib_road_*`` at ``vib_road_ref_speed_mps`` and scales
    as ``(|v| / v_ref) ** vib_road_speed_exponent`` with the speed at each interval's midpoint
    ``speed_mid`` [m/s]; zero at standstill for a positive exponent.

    Returns
    -------
    dict
        ``vib_a`` [m/s^2], ``vib_g`` [rad/s] (shape (n, 3)).
    """
    z = band_limited_interval_means(len(speed_mid), dt, model["vib_road_band_hz"], rng, channels=6)
    gain = (np.abs(speed_mid) / float(model["vib_road_ref_speed_mps"])) ** float(model["vib_road_speed_exponent"])
    rms = np.concatenate([per_axis(model["vib_road_accel_mps2"]), per_axis(model["vib_road_gyro_dps"]) * DEG])
    z *= gain[:, None] * rms
    return {"vib_a": z[:, :3], "vib_g": z[:, 3:]}
