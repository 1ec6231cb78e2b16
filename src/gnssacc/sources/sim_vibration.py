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

import copy

import numpy as np

from ..core.units import DEG
from .sim_imu_errors import gauss_markov, per_axis


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


def engine_frequency(
    speed_mid: np.ndarray,
    dt: float,
    model: dict,
    rng: np.random.Generator,
    wander_step_s: float = 0.05,
) -> np.ndarray:
    """Engine fundamental over each sample interval [Hz].

    ``min(idle + slope |v|, max) (1 + w)``: ``v`` the speed at the interval midpoints [m/s],
    ``w`` a Gauss-Markov wander (relative 1-sigma ``vib_engine_wander``, correlation time
    ``vib_engine_wander_time_s``) drawn on a ``wander_step_s`` grid and interpolated linearly.
    """
    return EngineVibration(len(speed_mid), dt, model, rng, wander_step_s, phases=False).frequency(
        speed_mid
    )


def engine_vibration(
    speed_mid: np.ndarray, dt: float, model: dict, rng: np.random.Generator
) -> dict:
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
    engine = EngineVibration(len(speed_mid), dt, model, rng)
    vib = engine.take(speed_mid)
    return {"vib_a": vib[:, :3], "vib_g": vib[:, 3:], **engine.draws}


class EngineVibration:
    """:func:`engine_vibration` of a run of ``n`` samples in consecutive chunks (:meth:`take`), bit for bit.

    The draws (the frequency wander on its coarse grid, the phases) are made at construction;
    the phase of the fundamental is carried from chunk to chunk. Parameters are those of
    :func:`engine_vibration` and :func:`engine_frequency`.

    Attributes
    ----------
    draws : dict
        ``engine_phase0``, ``engine_harmonic_phase`` (see :func:`engine_vibration`).
    """

    def __init__(
        self,
        n: int,
        dt: float,
        model: dict,
        rng: np.random.Generator,
        wander_step_s: float = 0.05,
        phases: bool = True,
    ):
        self.dt, self.model, self.k = dt, model, 0
        m = int(np.ceil(n * dt / wander_step_s)) + 1
        self._wander = gauss_markov(
            m,
            wander_step_s,
            float(model["vib_engine_wander_time_s"]),
            np.array([float(model["vib_engine_wander"])]),
            rng,
        )[:, 0]
        self._wander_t = wander_step_s * np.arange(m)
        self._rel = np.atleast_1d(np.asarray(model["vib_engine_harmonics"], float))
        if phases:
            phase0 = rng.uniform(0.0, 2.0 * np.pi)
            theta = rng.uniform(0.0, 2.0 * np.pi, size=(2, len(self._rel), 3))
            self.draws = {"engine_phase0": phase0, "engine_harmonic_phase": theta}
        self._amp = np.concatenate(
            [per_axis(model["vib_engine_accel_mps2"]), per_axis(model["vib_engine_gyro_dps"]) * DEG]
        )
        self._cycles = None  # cumulative sum of the frequencies up to the next chunk's first edge

    def frequency(self, speed_mid: np.ndarray) -> np.ndarray:
        """Engine fundamental [Hz] over the next ``len(speed_mid)`` intervals (does not advance)."""
        model, k0 = self.model, self.k
        f_nom = np.minimum(
            float(model["vib_engine_idle_hz"])
            + float(model["vib_engine_hz_per_mps"]) * np.abs(speed_mid),
            float(model["vib_engine_max_hz"]),
        )
        w_mid = np.interp(
            (np.arange(k0, k0 + len(speed_mid)) + 0.5) * self.dt, self._wander_t, self._wander
        )
        return np.maximum(f_nom * (1.0 + w_mid), 0.0)

    def take(self, speed_mid: np.ndarray) -> np.ndarray:
        """Vibration over the next ``len(speed_mid)`` intervals: accelerometers [m/s^2] in columns
        0-2, gyros [rad/s] in 3-5."""
        f = self.frequency(speed_mid)
        if self._cycles is None:
            cycles = np.concatenate([[0.0], np.cumsum(f)])
        else:
            cycles = np.cumsum(np.concatenate([[self._cycles], f]))
        self._cycles, self.k = cycles[-1], self.k + len(f)
        edges = self.draws["engine_phase0"] + 2.0 * np.pi * self.dt * cycles
        theta = self.draws["engine_harmonic_phase"]
        vib = np.zeros((len(f), 6))
        for h, r in enumerate(self._rel, start=1):
            if r != 0.0:
                vib += (r * self._amp) * harmonic_interval_mean(
                    edges, h, theta[:, h - 1].reshape(6)
                )
        return vib


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


def band_limited_interval_means(
    n: int, dt: float, band_hz, rng: np.random.Generator, channels: int = 3
) -> np.ndarray:
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
    out = np.empty((n, channels))
    for c, z in band_limited_columns(n, dt, band_hz, rng, channels):
        out[:, c] = z
    return out


def band_limited_columns(n: int, dt: float, band_hz, rng: np.random.Generator, channels: int = 3):
    """The columns of :func:`band_limited_interval_means`, one at a time: ``(c, z)``, ``z`` shape (n,).

    Bit for bit the same numbers. The spectrum's draws (real parts of every bin and channel,
    then imaginary parts) are read again from a copy of ``rng`` for each column, so only one
    column's spectrum is held at a time; ``rng`` is left where the one-pass synthesis leaves it.
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
    del f
    # Complex Gaussian bins of variance size * P * fs, real at DC and Nyquist: var(x) = sum P fs / size.
    gain = np.sqrt(0.5 * size * psd * fs)
    del psd
    start = copy.deepcopy(rng)
    for c in range(channels):
        draws = copy.deepcopy(start)
        spec = np.empty(len(gain), complex)
        for part in (spec.real, spec.imag):
            for r0 in range(0, len(gain), 1 << 14):
                r1 = min(r0 + (1 << 14), len(gain))
                part[r0:r1] = draws.standard_normal((r1 - r0, channels))[:, c]
        spec *= gain
        spec[0] = spec[0].real * np.sqrt(2.0)
        if size % 2 == 0:
            spec[-1] = spec[-1].real * np.sqrt(2.0)
        z = np.fft.irfft(spec, n=size)[:n]
        del spec
        yield c, z
    rng.bit_generator.state = draws.bit_generator.state


def road_scale(speed_mid: np.ndarray, model: dict) -> np.ndarray:
    """Road vibration RMS per interval and channel: accelerometers [m/s^2] in columns 0-2, gyros
    [rad/s] in 3-5, shape (n, 6) (``(|v| / v_ref) ** p`` times the RMS at the reference speed)."""
    gain = (np.abs(speed_mid) / float(model["vib_road_ref_speed_mps"])) ** float(
        model["vib_road_speed_exponent"]
    )
    rms = np.concatenate(
        [per_axis(model["vib_road_accel_mps2"]), per_axis(model["vib_road_gyro_dps"]) * DEG]
    )
    return gain[:, None] * rms


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
    z *= road_scale(speed_mid, model)
    return {"vib_a": z[:, :3], "vib_g": z[:, 3:]}
