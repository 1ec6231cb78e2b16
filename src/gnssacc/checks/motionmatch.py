r"""The motion the IMU measured against the motion the GNSS fixes show, before any attitude is known.

The input checks (:mod:`gnssacc.checks.plausibility`) compare the two before any estimator runs, so they
may rely on nothing an estimator would provide: no attitude, no mounting, no time offset, no
trusted units. Everything here is invariant to how the IMU is turned about the vertical.

IMU side (:func:`level_imu`)
    The mean specific force of a ground-vehicle run is gravity: the vehicle is level on average
    and its mean acceleration over a run is tiny (it ends about as fast as it starts). Its
    direction gives the IMU's "down" axis ``d`` (in IMU axes) whatever the mounting. The specific
    force across ``d`` is the horizontal specific force (acceleration plus the tilt of the
    moment, e.g. road grade), resolved on a basis ``e1``, ``e2 = d x e1``; the rate about ``d`` is
    the heading rate. Both are box-averaged onto a uniform grid (an IMU sample holds over its
    interval, so averaging never aliases vibration into the result).
GNSS side (:func:`gnss_kinematics`)
    Weighted quadratic fits of the horizontal fix positions over windows of ``W`` seconds give a
    velocity and an acceleration per window centre. A least-squares quadratic's acceleration is
    the true acceleration averaged with the biweight kernel ``(1 - s^2)^2`` over the window
    (integrate the fit's weights by parts twice), so the IMU's horizontal specific force averaged
    with the same kernel is directly comparable, up to a rotation about the vertical (the heading)
    and the tilt part. The fits average in a fixed (north-east) frame, so the IMU side is averaged
    in a fixed frame too (:func:`smooth_horizontal`: turned by the heading the gyro integrates,
    averaged, turned back): a slow vehicle's window of half a minute holds whole turns, and an
    average over the IMU's own turning axes would mix the accelerations before and after them.
    That frame needs a gyro in rad/s of the accelerometer's handedness, which the input checks
    establish only later: they use whichever of the two frames matches the fixes better.
Velocity frame (:func:`velocity_frame`)
    The GNSS acceleration resolved along and across the GNSS velocity, ``a_t + i a_n`` as a
    complex number (``a_n`` positive to the right of travel), is, for a vehicle that moves along
    its body x axis, the body-frame horizontal acceleration: the levelled IMU reads the same up to
    one constant complex factor ``c`` (:func:`complex_fit`): ``arg c`` is the mounting yaw, ``|c|``
    the ratio of the IMU's to the GNSS's acceleration scale (1 when both are right), and a better
    fit with the complex conjugate means that one of them is a mirror image of the other.

The window ``W`` is chosen per recording (:func:`choose_window`): the shortest one over which the
IMU's smoothed dynamics stand well above the GNSS acceleration noise, which follows from the
fixes' own scatter about short local fits (:func:`fix_scatter`), not from their stated sigmas.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Finest grid for the IMU signals [s]: the comparisons smooth over 2 s or more, so a 10 ms grid
#: loses nothing and bounds the memory of kHz IMUs.
MIN_STEP_S = 0.01
#: Candidate GNSS smoothing windows [s] (:func:`choose_window`).
WINDOWS_S = (2.0, 3.0, 4.0, 6.0, 8.0, 12.0, 16.0, 24.0, 32.0)
#: Signal-to-noise power ratio :func:`choose_window` asks for: the smoothed IMU horizontal
#: specific force against the GNSS acceleration noise. At 10 a perfect match correlates at 0.95.
TARGET_SNR = 10.0
#: Fewest fixes in a fit window (a quadratic has three parameters; two more give a check).
MIN_FIXES = 5
#: Fewest independent windows (centres x spacing / window) a regression of two parameters over
#: window centres needs to state a sigma from its residuals: one degree of freedom left for their
#: scatter. With fewer, neighbouring centres share most of their fixes and the residuals
#: understate the error (a 40 s run with 5-s outages every 20 s, 1.4 windows, gave "+-3 deg" for
#: a yaw 50 deg off). Beyond it the residual sigma is conservative rather than optimistic: the
#: residuals also hold the unmodelled along-track accelerations (a 180 s slow-UGV run with 3.9
#: windows states +-14 deg for a yaw 0.2 deg off).
MIN_INDEPENDENT_WINDOWS = 3.0


@dataclass
class LevelledImu:
    """IMU signals about the mean gravity direction, on a uniform grid (IMU clock).

    Attributes
    ----------
    t0, step : float
        Time of the first grid point [s] and grid step [s].
    down : ndarray, shape (3,)
        Unit vector of gravity ("down") in IMU axes, from the run's mean specific force.
    e1, e2 : ndarray, shape (3,)
        Horizontal basis in IMU axes, ``e2 = down x e1`` (so ``(e1, e2, down)`` is right-handed).
    f_h : ndarray, shape (n, 2)
        Horizontal specific force along ``e1``, ``e2`` [m/s^2] (IMU units if they are wrong).
    omega_v : ndarray, shape (n,)
        Angular rate about ``down`` [rad/s] (IMU units): the heading rate, positive turning right.
    f_mean_norm : float
        Norm of the run's mean specific force [m/s^2] (IMU units).
    ground_frame : bool
        Whether :func:`smooth_horizontal` averages in a frame fixed on the ground (turned by the
        heading the gyro integrates), or in the IMU axes (for a gyro whose heading rate cannot
        turn that frame: not in rad/s, or of the other handedness than the accelerometer).
    """

    t0: float
    step: float
    down: np.ndarray
    e1: np.ndarray
    e2: np.ndarray
    f_h: np.ndarray
    omega_v: np.ndarray
    f_mean_norm: float
    ground_frame: bool = True

    @property
    def t(self) -> np.ndarray:
        return self.t0 + self.step * np.arange(len(self.omega_v))

    @property
    def t_end(self) -> float:
        return self.t0 + self.step * (len(self.omega_v) - 1)


#: Samples (and grid cells) per block of :class:`BoxGrid`'s work: a long run's temporaries stay
#: a few MiB, beside the two run-long arrays it keeps (cell edges and running integral).
BOX_BLOCK = 1 << 16


class BoxGrid:
    """Box averages of channels sampled at times ``t`` over a uniform grid, one channel at a time.

    Sample ``k`` holds over ``(t[k-1], t[k]]`` (the first over one interval before ``t[0]``);
    cell ``j`` is ``[t0 + (j - 1/2) step, t0 + (j + 1/2) step]``, ``j = 0 .. n-1``. The running
    integral and the interpolation at the cell edges go block by block, so a channel costs two
    float64 per sample (edges and integral, shared by the channels) plus bounded blocks; the
    arithmetic is that of the whole-array computation, element by element.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Sample times [s], increasing, N >= 2.
    t0, step : float
        Grid [s].
    n : int
        Number of grid cells.
    """

    def __init__(self, t: np.ndarray, t0: float, step: float, n: int):
        self.t, self.t0, self.step, self.n = np.asarray(t, float), float(t0), float(step), int(n)
        t = self.t
        self.dt0 = t[0] - (
            t[0] - (t[1] - t[0])
        )  # the first sample's interval, as np.diff(prepend=) gives it
        self.edges = np.empty(len(t) + 1)
        self.edges[0] = t[0] - self.dt0
        self.edges[1:] = t
        self.cum = np.zeros(len(t) + 1)

    def _integrate(self, x: np.ndarray) -> None:
        """``cum[1:] = cumsum(x * dt)`` block by block (the carry added as the next term, so the
        sums are the sequential ones of a whole-array cumsum)."""
        t, cum, N = self.t, self.cum, len(self.t)
        for a in range(0, N, BOX_BLOCK):
            b = min(a + BOX_BLOCK, N)
            seg = cum[a + 1 : b + 1]
            if a == 0:
                seg[0] = self.dt0
                np.subtract(t[1:b], t[: b - 1], out=seg[1:])
            else:
                np.subtract(t[a:b], t[a - 1 : b - 1], out=seg)
            seg *= x[a:b]
            if a > 0:
                seg[0] += cum[a]
            np.cumsum(seg, out=seg)

    def average(self, x: np.ndarray, out: np.ndarray) -> np.ndarray:
        """Fills ``out`` (n,) with the cell averages of one channel ``x`` (N,) and returns it."""
        self._integrate(x)
        lo_t, hi_t = self.edges[0], self.edges[-1]
        for a in range(0, self.n, BOX_BLOCK):
            b = min(a + BOX_BLOCK, self.n)
            g = self.t0 + self.step * (np.arange(a, b + 1) - 0.5)
            np.clip(g, lo_t, hi_t, out=g)
            width = np.maximum(np.diff(g), 1e-12)
            out[a:b] = np.diff(np.interp(g, self.edges, self.cum)) / width
        return out


def box_average(t: np.ndarray, x: np.ndarray, t0: float, step: float, n: int) -> np.ndarray:
    """Averages of samples ``x`` (sample k holds over ``(t[k-1], t[k]]``) over grid cells
    ``[t0 + (j - 1/2) step, t0 + (j + 1/2) step]``, ``j = 0 .. n-1`` (:class:`BoxGrid`).

    Parameters
    ----------
    t : ndarray, shape (N,)
        Sample times [s], increasing.
    x : ndarray, shape (N, k)
    t0, step : float
        Grid [s].
    n : int
        Number of grid cells.

    Returns
    -------
    ndarray, shape (n, k)
    """
    grid = BoxGrid(t, t0, step, n)
    out = np.empty((n, x.shape[1]))
    for i in range(x.shape[1]):  # one channel at a time: a long run's temporaries stay one column
        grid.average(x[:, i], out[:, i])
    return out


def _horizontal_basis(down: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    axis = np.eye(3)[int(np.argmin(np.abs(down)))]
    e1 = axis - (axis @ down) * down
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(down, e1)


def level_imu(imu, step: float | None = None) -> LevelledImu:
    """Horizontal specific force and heading rate of an IMU record on a uniform grid.

    Parameters
    ----------
    imu : gnssacc.core.recording.ImuData
        Samples in any axes (time [s]; units as recorded).
    step : float, optional
        Grid step [s]; default the median sample interval, at least :data:`MIN_STEP_S`.

    Returns
    -------
    LevelledImu
    """
    t = np.asarray(imu.t, float)
    step = float(step or max(float(np.median(np.diff(t))), MIN_STEP_S))
    dt = np.diff(t, prepend=t[0] - (t[1] - t[0]))
    f_mean = dt @ imu.f_b / dt.sum()
    del dt
    norm = float(np.linalg.norm(f_mean))
    down = -f_mean / norm if norm > 0 else np.array([0.0, 0.0, 1.0])
    e1, e2 = _horizontal_basis(down)
    n = max(int(np.floor((t[-1] - t[0]) / step)) + 1, 1)
    grid = BoxGrid(t, float(t[0]), step, n)
    f_h, omega_v = np.empty((n, 2)), np.empty(n)
    # one projection at a time (each one column of the run), averaged into its output column
    grid.average(imu.f_b @ e1, f_h[:, 0])
    grid.average(imu.f_b @ e2, f_h[:, 1])
    grid.average(imu.omega_ib_b @ down, omega_v)
    return LevelledImu(float(t[0]), step, down, e1, e2, f_h, omega_v, norm)


def _kernel(step: float, window_s: float, kernel: str) -> np.ndarray:
    """The weights of :func:`smooth`'s kernel over its ``2 half + 1`` grid points."""
    half = max(int(round(0.5 * window_s / step)), 1)
    s = np.arange(-half, half + 1) / (half + 1.0)
    return {"biweight": (1 - s * s) ** 2, "epanechnikov": 1 - s * s, "box": np.ones_like(s)}[kernel]


def smooth(x: np.ndarray, step: float, window_s: float, kernel: str = "biweight") -> np.ndarray:
    """Kernel average of a uniformly sampled signal over ``window_s`` centred on each sample.

    ``kernel``: ``"biweight"`` ``(1 - s^2)^2`` (what a least-squares quadratic's acceleration
    sees), ``"epanechnikov"`` ``1 - s^2`` (its velocity), or ``"box"``. Samples within half a
    window of either end are averaged over the part of the kernel that exists.
    """
    k = _kernel(step, window_s, kernel)
    x2 = x.reshape(len(x), -1)
    out = np.empty(x2.shape, np.result_type(x2, float))
    for a, b, lo, hi in _blocks(len(x), len(k) // 2):  # the normalisation shared by the channels
        den = _weights(k, a, b, lo, hi)
        for i in range(x2.shape[1]):
            out[a:b, i] = _convolve_block(x2[lo:hi, i], k, a - lo, b - lo) / den
    return out.reshape(x.shape)


#: Samples convolved per FFT in :func:`smooth`: a long run's grid is smoothed in blocks (each with
#: the kernel's half width of neighbours), so the FFT's work arrays stay a few MiB.
SMOOTH_BLOCK = 1 << 16


def _good_size(n: int, primes: tuple[int, ...]) -> int:
    """The smallest length at least ``n`` whose prime factors are 2 and ``primes`` (odd): the
    lengths pocketfft transforms fastest, as ``scipy.fft.next_fast_len`` picks them (3, 5 for a
    real transform; 3, 5, 7, 11 for a complex one)."""
    odd = [1]
    for p in primes:  # every product of the odd primes below 2 n
        more = []
        for q in odd:
            while q < 2 * n:
                more.append(q)
                q *= p
        odd = more
    return min(q << max(0, (-(-n // q) - 1).bit_length()) for q in odd)


def _convolve_full(x: np.ndarray, k: np.ndarray) -> np.ndarray:
    """The full linear convolution of ``x`` (real or complex) with a real kernel ``k``, by FFT.

    What ``scipy.signal.fftconvolve(x, k, "full")`` does, with numpy's FFT (the same pocketfft
    and transform lengths as ``scipy.fft``'s, the same numbers): ``scipy.signal`` costs a run
    0.4-0.8 s of imports (it loads ``scipy.stats``), ``scipy.fft`` 0.3 s, ``numpy.fft`` nothing.
    """
    n = len(x) + len(k) - 1
    if np.iscomplexobj(x):
        size = _good_size(n, (3, 5, 7, 11))
        return np.fft.ifft(np.fft.fft(x, size) * np.fft.fft(k, size))[:n]
    size = _good_size(n, (3, 5))
    return np.fft.irfft(np.fft.rfft(x, size) * np.fft.rfft(k, size), size)[:n]


def _blocks(n: int, half: int):
    """``(a, b, lo, hi)`` per block of outputs ``a .. b-1`` of :func:`_convolve_same` with a kernel
    of half width ``half``: ``lo .. hi-1`` are the samples that reach them."""
    for a in range(0, n, SMOOTH_BLOCK):
        b = min(a + SMOOTH_BLOCK, n)
        yield a, b, max(a - half, 0), min(b + half, n)


def _convolve_block(x: np.ndarray, k: np.ndarray, a: int, b: int) -> np.ndarray:
    """Outputs ``a .. b-1`` of the "same" convolution of the samples ``x`` with an odd kernel ``k``."""
    half = len(k) // 2
    return _convolve_full(x, k)[a + half : b + half]  # full[j] is output j - half


def _weights(k: np.ndarray, a: int, b: int, lo: int, hi: int) -> np.ndarray:
    """The kernel weight within the record at outputs ``a .. b-1`` (block ``lo .. hi-1``), at least 1e-12."""
    return np.maximum(_convolve_block(np.ones(hi - lo), k, a - lo, b - lo), 1e-12)


def _convolve_same(x: np.ndarray, k: np.ndarray) -> np.ndarray:
    """``scipy.signal.fftconvolve(x, k, "same")`` for an odd-length kernel, block by block."""
    out = np.empty(len(x), np.result_type(x, k))
    for a, b, lo, hi in _blocks(len(x), len(k) // 2):
        out[a:b] = _convolve_block(x[lo:hi], k, a - lo, b - lo)
    return out


def smooth_horizontal(lev: LevelledImu, window_s: float) -> np.ndarray:
    """The levelled horizontal specific force averaged like the GNSS fits average the acceleration:
    in a frame fixed on the ground, then resolved in the IMU axes of each grid point (module notes).

    The frame is the IMU's turned back by the heading the gyro integrates about ``down`` (a gyro
    bias turns it by a few degrees over a window, which the average does not notice); with
    ``lev.ground_frame`` false, the IMU axes themselves. Block by block (:func:`smooth`'s
    blocks): besides the output, one float64 per grid point (the integrated heading).

    Parameters
    ----------
    lev : LevelledImu
    window_s : float
        Kernel width [s] (biweight, :func:`smooth`).

    Returns
    -------
    ndarray, shape (n, 2)
        Along ``e1``, ``e2`` [m/s^2] (IMU units).
    """
    if not lev.ground_frame:
        return smooth(lev.f_h, lev.step, window_s)
    k = _kernel(lev.step, window_s, "biweight")
    heading = np.cumsum(lev.omega_v)
    out = np.empty((len(heading), 2))
    for a, b, lo, hi in _blocks(len(heading), len(k) // 2):
        turn = heading[lo:hi] * (1j * lev.step)
        np.exp(turn, out=turn)
        z = lev.f_h[lo:hi, 1] * 1j
        z += lev.f_h[lo:hi, 0]
        z *= turn
        f = _convolve_block(z, k, a - lo, b - lo) / _weights(k, a, b, lo, hi)
        f /= turn[a - lo : b - lo]
        out[a:b, 0], out[a:b, 1] = f.real, f.imag
    return out


def at_times(t0: float, step: float, x: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Linear interpolation of a grid signal ``x`` (n,) or (n, k) at times ``t`` [s]."""
    u = (np.asarray(t, float) - t0) / step
    j = np.clip(np.floor(u).astype(int), 0, len(x) - 2)
    w = np.clip(u - j, 0.0, 1.0)
    if x.ndim == 1:
        return (1 - w) * x[j] + w * x[j + 1]
    return (1 - w)[:, None] * x[j] + w[:, None] * x[j + 1]


# --- GNSS side ---------------------------------------------------------------------------------


@dataclass
class GnssKinematics:
    """Smoothed horizontal kinematics of the fixes at window centres (GNSS clock).

    Attributes
    ----------
    t : ndarray, shape (n,)
        Window centres [s] (only those with a well-posed fit).
    v, a : ndarray, shape (n, 2)
        North and east velocity [m/s] and acceleration [m/s^2] (in the fixes' units if wrong).
    sigma_v, sigma_a : ndarray, shape (n,)
        Their 1-sigma per axis, from the fixes' scatter.
    window_s : float
        Fit window [s].
    scatter_m : float
        1-sigma scatter of a fix of median stated sigma about short local fits [m].
    snr : float
        Power of the acceleration signal over that of its noise (mean square minus the noise's,
        divided by the noise's): below ~1 the fixes show no accelerations at all.
    """

    t: np.ndarray
    v: np.ndarray
    a: np.ndarray
    sigma_v: np.ndarray
    sigma_a: np.ndarray
    window_s: float
    scatter_m: float
    snr: float = float("nan")

    def __len__(self) -> int:
        return len(self.t)


def horizontal_track(gnss, origin) -> tuple[np.ndarray, np.ndarray]:
    """North/east fix positions in the run's tangent plane [m], shape (M, 2), and relative fit
    weights ``(median sigma / sigma)^2`` from the stated horizontal sigmas, shape (M,)."""
    p = origin.to_ned(gnss.lat, gnss.lon, gnss.h)[:, :2]
    s = np.sqrt(np.mean(np.asarray(gnss.sigma_ned, float)[:, :2] ** 2, axis=1))
    return p, (np.median(s) / s) ** 2


def local_fits(t: np.ndarray, p: np.ndarray, w: np.ndarray, centres: np.ndarray, window_s: float):
    """Weighted quadratic fits ``p = x0 + x1 s + x2 s^2 / 2``, ``s = (t - c) / (W/2)``, over
    ``|t - c| <= W/2`` for each centre ``c``.

    Returns
    -------
    x : ndarray, shape (n, 3, 2)
        Position [m], velocity [m/s] and acceleration [m/s^2] at each centre.
    var : ndarray, shape (n, 3)
        Their variances for a unit-weight fix of 1 m sigma.
    ok : ndarray of bool, shape (n,)
        At least :data:`MIN_FIXES` fixes, two on each side of the centre.
    resid : ndarray, shape (n, m, 2)
        Residuals of the fixes in each window (zero-padded), with ``dof`` (n,) = fixes - 3.
    """
    half = 0.5 * window_s
    lo = np.searchsorted(t, centres - half, "left")
    hi = np.searchsorted(t, centres + half, "right")
    m = max(int((hi - lo).max()), 1)
    idx = lo[:, None] + np.arange(m)[None, :]
    valid = idx < hi[:, None]
    idx = np.minimum(idx, len(t) - 1)
    s = np.where(valid, (t[idx] - centres[:, None]) / half, 0.0)
    ww = np.where(valid, w[idx], 0.0)
    A = np.stack([np.ones_like(s), s, 0.5 * s * s], -1)
    N = np.einsum("nmi,nm,nmj->nij", A, ww, A)
    ok = (
        ((hi - lo) >= MIN_FIXES) & ((valid & (s < 0)).sum(1) >= 2) & ((valid & (s > 0)).sum(1) >= 2)
    )
    ok &= _largest_gap(t, idx, valid, lo, hi, centres, half) <= _gap_limit(t, window_s)
    N[~ok] = np.eye(3)
    Ninv = np.linalg.inv(N)
    x = Ninv @ np.einsum("nmi,nm,nmk->nik", A, ww, p[idx])
    resid = np.where(valid[:, :, None], p[idx] - A @ x, 0.0) * np.sqrt(ww)[:, :, None]
    scale = np.array([1.0, 1.0 / half, 1.0 / half**2])
    var = np.diagonal(Ninv, axis1=1, axis2=2) * scale**2
    return x * scale[None, :, None], var, ok, resid, (hi - lo) - 3


#: A window's fit is used only when no stretch of it without fixes (inside, or at either end) is
#: longer than this fraction of the window (or twice the median fix interval, if longer): a
#: quadratic bridged over an outage invents the motion inside it, and a slow vehicle's turns
#: there read as accelerations no IMU saw (a clock offset of 16 s, a gyro "1.7 times" the course
#: rate, on a slow UGV with 20 s outages).
MAX_GAP_FRACTION = 0.25


def _gap_limit(t: np.ndarray, window_s: float) -> float:
    dt = float(np.median(np.diff(t))) if len(t) > 1 else window_s
    return max(MAX_GAP_FRACTION * window_s, 2.0 * dt)


def _largest_gap(t, idx, valid, lo, hi, centres, half) -> np.ndarray:
    """Per window: its longest stretch without fixes [s], the ends of the window included."""
    last = t[np.maximum(hi - 1, 0)]
    tv = np.where(valid, t[idx], last[:, None])  # padding repeats the last fix
    inner = np.diff(tv, axis=1).max(axis=1) if tv.shape[1] > 1 else np.zeros(len(tv))
    first = t[np.minimum(lo, len(t) - 1)]
    return np.maximum(inner, np.maximum(first - (centres - half), (centres + half) - last))


def fix_scatter(t: np.ndarray, p: np.ndarray, w: np.ndarray) -> float:
    """1-sigma white scatter of the fixes [m] about quadratics over ~7 fixes (a median, robust to
    the short moments where a vehicle's jerk bends the track; floored at 5 mm), per coordinate of
    ``p`` (shape (n, d): the horizontal track, or one axis)."""
    dt = float(np.median(np.diff(t)))
    centres = t[:: max(len(t) // 2000, 1)]
    _, _, ok, resid, dof = local_fits(t, p, w, centres, 6.5 * dt)
    if not np.any(ok):
        return 0.005
    k = p.shape[1] * dof[ok]
    per_window = (resid[ok] ** 2).sum(axis=(1, 2)) / k
    # Median of chi-square(k)/k is about (1 - 2/(9k))^3 (Wilson-Hilferty).
    sigma2 = np.median(per_window) / np.median((1.0 - 2.0 / (9.0 * k)) ** 3)
    return max(float(np.sqrt(sigma2)), 0.005)


def gnss_kinematics(
    gnss, origin, window_s: float, scatter_m: float | None = None
) -> GnssKinematics:
    """Velocity and acceleration of the fixes from quadratic fits over ``window_s`` (module notes).

    Window centres are uniformly spaced (a sixteenth of the window, at least the fix interval) over
    the fixes' span; centres without a well-posed fit (outages) are left out.
    """
    t = np.asarray(gnss.t, float)
    p, w = horizontal_track(gnss, origin)
    scatter = fix_scatter(t, p, w) if scatter_m is None else scatter_m
    step = max(float(np.median(np.diff(t))), window_s / 16.0)
    centres = np.arange(t[0] + 0.5 * window_s, t[-1] - 0.5 * window_s + 1e-9, step)
    if len(centres) == 0:
        return GnssKinematics(
            np.zeros(0),
            np.zeros((0, 2)),
            np.zeros((0, 2)),
            np.zeros(0),
            np.zeros(0),
            window_s,
            scatter,
        )
    x, var, ok, _, _ = local_fits(t, p, w, centres, window_s)
    a, sigma_a = x[ok, 2], scatter * np.sqrt(var[ok, 2])
    noise = float(np.mean(2.0 * sigma_a**2)) if np.any(ok) else float("nan")
    snr = (float(np.mean(np.sum(a**2, axis=1))) - noise) / noise if np.any(ok) else float("nan")
    return GnssKinematics(
        centres[ok], x[ok, 1], a, scatter * np.sqrt(var[ok, 1]), sigma_a, window_s, scatter, snr
    )


def choose_window(gnss, origin, duration_s: float) -> GnssKinematics | None:
    """The GNSS kinematics over the shortest window of :data:`WINDOWS_S` whose acceleration signal
    power (mean square minus the noise's) reaches :data:`TARGET_SNR` times the noise power
    (``None`` when no window has enough fixes).

    The test uses the fixes alone (units-free: a track in the wrong units scales signal and noise
    alike). Windows holding fewer than :data:`MIN_FIXES` fixes or longer than a quarter of the
    run are skipped; when none reaches the target the one with the best ratio is returned.
    """
    t = np.asarray(gnss.t, float)
    p, w = horizontal_track(gnss, origin)
    scatter = fix_scatter(t, p, w)
    dt = float(np.median(np.diff(t)))
    best, best_snr = None, -np.inf
    for W in WINDOWS_S:
        if W < (MIN_FIXES - 0.5) * dt or (best is not None and W > 0.25 * duration_s):
            continue
        kin = gnss_kinematics(gnss, origin, W, scatter)
        if len(kin) < 8:
            continue
        if kin.snr > best_snr:
            best, best_snr = kin, kin.snr
        if kin.snr >= TARGET_SNR:
            return kin
    return best


# --- comparison -------------------------------------------------------------------------------


def velocity_frame(kin: GnssKinematics, min_speed_sigmas: float = 4.0):
    """GNSS acceleration along and across the GNSS velocity, ``a_t + i a_n`` (``a_n`` > 0 to the
    right of travel), where the speed exceeds ``min_speed_sigmas`` of its noise (course known to
    ~15 deg).

    Returns
    -------
    z : ndarray of complex, shape (n,)
    speed : ndarray, shape (n,)
    moving : ndarray of bool, shape (n,)
    """
    speed = np.hypot(kin.v[:, 0], kin.v[:, 1])
    moving = speed > min_speed_sigmas * kin.sigma_v
    u = kin.v / np.maximum(speed, 1e-12)[:, None]
    a_t = kin.a[:, 0] * u[:, 0] + kin.a[:, 1] * u[:, 1]
    a_n = -kin.a[:, 0] * u[:, 1] + kin.a[:, 1] * u[:, 0]
    return a_t + 1j * a_n, speed, moving


@dataclass
class HorizontalFit:
    """The levelled IMU's horizontal specific force against the GNSS acceleration in the velocity
    frame, ``z_imu ~ c z_gnss`` (direct) or ``z_imu ~ c conj(z_gnss)`` (mirror).

    Attributes
    ----------
    rho_direct, rho_mirror : float
        Magnitude of the complex correlation coefficient of each model (0..1).
    c : complex
        The factor of the better model; ``|c|`` is noise-corrected (GNSS noise power removed).
    mirror : bool
        Whether the mirror model fits better.
    n_eff : float
        Effective number of independent comparisons (centres / window overlap).
    """

    rho_direct: float
    rho_mirror: float
    c: complex
    mirror: bool
    n_eff: float

    @property
    def yaw(self) -> float:
        """Angle from the direction of travel to IMU axis ``e1`` about down [rad]: ``arg c``."""
        return float(np.angle(self.c))

    @property
    def scale(self) -> float:
        """IMU acceleration over GNSS acceleration (1 when both are in m/s^2 and metres)."""
        return float(abs(self.c))


def complex_fit(
    z_imu: np.ndarray, z_gnss: np.ndarray, noise_var: np.ndarray, n_eff: float
) -> HorizontalFit:
    """Fit ``z_imu ~ c z_gnss`` and ``z_imu ~ c conj(z_gnss)`` (see :class:`HorizontalFit`).

    ``noise_var`` (n,) is the GNSS acceleration noise variance per axis (subtracted twice from
    ``|z_gnss|^2`` so that ``|c|`` is not biased by it)."""
    pi, pg = float(np.sum(np.abs(z_imu) ** 2)), float(np.sum(np.abs(z_gnss) ** 2))
    s_d, s_m = np.sum(z_imu * np.conj(z_gnss)), np.sum(z_imu * z_gnss)
    norm = np.sqrt(max(pi * pg, 1e-300))
    rho_d, rho_m = float(abs(s_d) / norm), float(abs(s_m) / norm)
    mirror = rho_m > rho_d
    signal = max(pg - 2.0 * float(np.sum(noise_var)), 0.25 * pg)
    c = (s_m if mirror else s_d) / signal
    return HorizontalFit(rho_d, rho_m, complex(c), bool(mirror), float(n_eff))


def _aligned(lev: LevelledImu, kin: GnssKinematics, offset_s: float, sel: np.ndarray) -> np.ndarray:
    """Centres in ``sel`` whose IMU time ``t - offset_s`` has a full window of IMU data."""
    tq = kin.t - offset_s
    half = 0.5 * kin.window_s
    return sel & (tq >= lev.t0 + half) & (tq <= lev.t_end - half)


def _n_eff(kin: GnssKinematics, n: int) -> float:
    """Independent comparisons among ``n`` centres: one per window."""
    step = float(np.median(np.diff(kin.t))) if len(kin) > 1 else kin.window_s
    return max(n * step / kin.window_s, 1.0)


def horizontal_fit(lev: LevelledImu, kin: GnssKinematics, offset_s: float) -> HorizontalFit | None:
    """:func:`complex_fit` of the smoothed levelled IMU (shifted by ``offset_s`` onto the GNSS clock)
    against the GNSS velocity-frame acceleration, over the moving centres; ``None`` with fewer
    than :data:`MIN_FIXES` of them."""
    z_g, _, moving = velocity_frame(kin)
    m = _aligned(lev, kin, offset_s, moving)
    if m.sum() < MIN_FIXES:
        return None
    x = at_times(lev.t0, lev.step, smooth_horizontal(lev, kin.window_s), kin.t[m] - offset_s)
    return complex_fit(
        x[:, 0] + 1j * x[:, 1], z_g[m], kin.sigma_a[m] ** 2, _n_eff(kin, int(m.sum()))
    )


@dataclass
class TurnFit:
    """GNSS course rate regressed on the IMU heading rate: ``course_rate ~ k * omega_v``.

    Attributes
    ----------
    k : float
        1 for a gyro in rad/s, pi/180 for one in deg/s, -1 when one of the two is mirrored.
    sigma_k : float
        1-sigma of ``k`` (the overlap of neighbouring windows accounted for).
    turned_deg : float
        Total heading change the IMU saw over the compared epochs [deg, in IMU units].
    rho : float
        Weighted correlation of the two rates (1: the turns match in time, whatever the units;
        a view of the clock offset independent of the accelerations, :mod:`gnssacc.checks.timeoffset`).
    """

    k: float
    sigma_k: float
    turned_deg: float
    rho: float = float("nan")


def turn_rate_fit(lev: LevelledImu, kin: GnssKinematics, offset_s: float) -> TurnFit | None:
    """The slope of the GNSS course rate (across-track acceleration over speed) on the IMU's
    smoothed heading rate, weighted by the course rate's precision ``(speed / sigma_a)^2``; ``None``
    with fewer than :data:`MIN_FIXES` moving centres."""
    z_g, speed, moving = velocity_frame(kin)
    m = _aligned(lev, kin, offset_s, moving)
    if m.sum() < MIN_FIXES:
        return None
    x = at_times(lev.t0, lev.step, smooth(lev.omega_v, lev.step, kin.window_s), kin.t[m] - offset_s)
    y = z_g[m].imag / speed[m]
    w = (speed[m] / kin.sigma_a[m]) ** 2
    sxx, syy = float(np.sum(w * x * x)), float(np.sum(w * y * y))
    if not sxx > 0:
        return None
    overlap = len(x) / _n_eff(kin, int(m.sum()))
    step = float(np.median(np.diff(kin.t))) if len(kin) > 1 else kin.window_s
    sxy = float(np.sum(w * x * y))
    return TurnFit(
        sxy / sxx,
        float(np.sqrt(overlap / sxx)),
        float(np.degrees(np.sum(np.abs(x)) * step)),
        sxy / np.sqrt(sxx * syy) if syy > 0 else float("nan"),
    )


@dataclass
class LateralFit:
    """The IMU's horizontal specific force regressed onto the centripetal acceleration
    ``v * omega_v`` (GNSS speed times IMU heading rate): ``v omega_v ~ b . f_h``.

    For a vehicle moving along its body x axis ``u``, ``f_h = a_t u + v omega_v (down x u)``, so
    ``b`` points along ``down x u`` (the body's right axis) whatever the along-track
    acceleration ``a_t``: this gives the forward axis from the turns alone, with no GNSS
    acceleration (which is noisy at low speed). Mirror-invariant on the GNSS side (speed only).

    Attributes
    ----------
    yaw : float
        Angle of the forward axis ``u`` from IMU axis ``e1`` towards ``e2`` about down [rad].
    sigma_yaw : float
        Its 1-sigma [rad].
    scale : float
        ``|b|``: 1 when specific force [m/s^2], heading rate [rad/s] and speed [m/s] agree.
    along_rho : float
        Correlation of the specific force along ``u`` with the GNSS along-track acceleration
        (positive for a vehicle moving forward along ``u``; negative when the gyro and the
        accelerometer disagree in handedness).
    """

    yaw: float
    sigma_yaw: float
    scale: float
    along_rho: float


def lateral_fit(
    lev: LevelledImu, kin: GnssKinematics, offset_s: float, imu_window_s: float = 2.0
) -> LateralFit | None:
    """:class:`LateralFit` over the moving centres, the IMU smoothed over ``imu_window_s`` and
    shifted by ``offset_s`` onto the GNSS clock; ``None`` with fewer than :data:`MIN_FIXES` of them
    or fewer than :data:`MIN_INDEPENDENT_WINDOWS` independent windows."""
    z_g, speed, moving = velocity_frame(kin)
    m = _aligned(lev, kin, offset_s, moving)
    if m.sum() < MIN_FIXES:
        return None
    tq = kin.t[m] - offset_s
    f = at_times(lev.t0, lev.step, smooth(lev.f_h, lev.step, imu_window_s), tq)
    w = at_times(lev.t0, lev.step, smooth(lev.omega_v, lev.step, imu_window_s), tq)
    y = speed[m] * w
    A = f.T @ f
    if np.linalg.cond(A) > 1e8:
        return None
    n_eff = _n_eff(kin, int(m.sum()))
    if n_eff < MIN_INDEPENDENT_WINDOWS:
        return None
    b = np.linalg.solve(A, f.T @ y)
    resid = y - f @ b
    cov = np.linalg.inv(A) * float(np.mean(resid**2)) * (len(y) / n_eff)
    yaw = float(np.arctan2(-b[0], b[1]))
    nb = float(np.linalg.norm(b))
    perp = np.array([b[1], -b[0]]) / max(nb, 1e-12)  # unit vector along u
    sigma_yaw = float(np.sqrt(max(perp @ cov @ perp, 0.0))) / max(nb, 1e-12)
    along = f @ perp
    a_t = z_g[m].real
    den = np.sqrt(np.sum((along - along.mean()) ** 2) * np.sum((a_t - a_t.mean()) ** 2))
    rho = float(np.sum((along - along.mean()) * (a_t - a_t.mean())) / den) if den > 0 else 0.0
    return LateralFit(yaw, sigma_yaw, nb, rho)
