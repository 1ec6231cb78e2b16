"""Allan deviation of inertial sensor records, and the noise terms read from it.

The overlapping Allan variance of a rate series ``x`` (angular rate or specific force, one
sample every ``dt``, each sample the mean over its interval as an integrating IMU delivers) at
cluster time ``tau = m dt`` is

    sigma^2(tau) = 1 / (2 tau^2 (n - 2m + 1)) sum_k (theta[k+2m] - 2 theta[k+m] + theta[k])^2

with ``theta`` the integrated signal (``cumsum(x) dt``): half the mean squared difference of
consecutive ``tau``-averages, every start sample used (IEEE Std 952-1997, Annex C; Riley, *NIST
Special Publication 1065*, 2008, sec. 5.2.4). Each tau costs one vectorised pass over the
cumulative sum.

Noise terms (IEEE 952 Annex C; El-Sheimy, Hou & Niu, *IEEE Trans. Instrum. Meas.* 57(1), 2008):

* white noise (angle / velocity random walk) ``N``: ``sigma^2 = N^2 / tau`` (slope -1/2),
  ``N`` in [unit sqrt(s)] = [unit/sqrt(Hz)];
* bias instability ``B`` (flicker): a floor ``sigma = sqrt(2 ln 2 / pi) B = 0.664 B``;
* rate random walk ``K``: ``sigma^2 = K^2 tau / 3`` (slope +1/2); rate ramp ``R``:
  ``sigma^2 = R^2 tau^2 / 2`` (slope +1);
* quantisation ``Q`` and, in practice, vibration: ``sigma^2 = 3 Q^2 / tau^2`` (slope -1). A
  zero-mean vibration has a bounded integral, so its Allan variance falls as ``tau^-2`` beyond a
  few periods; a harmonic at frequency ``f`` gives ``A^2 sin^4(pi f tau) / (pi f tau)^2``, which
  oscillates under that envelope and still leaks into tau of tens of seconds when it is strong.

:func:`white_noise_density` makes ``N`` robust to vibration and to the long-tau terms in two
steps: (1) narrow spectral lines above 1 Hz (harmonic vibration: a bin 20 times above the median
level around it in a Hann-windowed periodogram) are removed from the record with their leakage
skirts, since their oscillating leak is not a smooth function of tau; (2) the Allan variance is
fitted over all taus by the five-term model above with non-negative coefficients (weighted
least squares as in Lv, Liu, Lai & Huang, *Optik* 126, 2015; see also Vaccaro & Zaki, *IEEE
Trans. Instrum. Meas.* 61(3), 2012; here with the exact non-negative solution). Whatever
vibration is left is absorbed by the ``tau^-2`` term and the bias terms take the long taus, so
``N`` comes from the -1/2 slope region where it exists. Each point is weighted by its
statistical error and a 10 % model-error floor (the model is an approximation: Gauss-Markov
bias, vibration leak), so no single tau steers the fit. When the record is too short to reach
20 s, only Q and N are fitted: the bias terms cannot be separated from white noise and
vibration leak there, and would otherwise take part of the white noise.

:func:`bias_instability` follows the IEEE 952 convention ``B = min sigma / 0.664``, read only
when the record shows the floor (see :data:`FLOOR_RULE`).
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import combinations

import numpy as np

#: ``sigma_floor = sqrt(2 ln 2 / pi) B`` for flicker (bias instability) noise (IEEE 952 Table C.1).
FLOOR_FACTOR = float(np.sqrt(2.0 * np.log(2.0) / np.pi))
#: Taus with fewer non-overlapping clusters than this are too noisy to read a floor from (the
#: minimum over many noisy points is biased low; with 32 clusters the error is ~10 %).
MIN_CLUSTERS_FLOOR = 32
#: The rule :func:`bias_instability` applies before it reads a floor.
FLOOR_RULE = (
    f"over the taus with >= {MIN_CLUSTERS_FLOOR} clusters, the minimum of the Allan deviation must lie "
    "at least half a decade after the first of them (the fall to the floor is seen), and there the "
    "white-noise line N / sqrt(tau) of the fitted model must be at most half the deviation (white "
    "noise then adds at most 25 % of the variance, B is overstated by at most 15 %); otherwise the "
    "record is too short to show the floor and the answer is None"
)
#: Relative model-error floor on each Allan variance point in the fit (see the module notes).
MODEL_ERROR = 0.10
#: The bias terms (B, K, R) are fitted only when the taus reach this far [s]: over shorter taus
#: they trade off against white noise and vibration leak and take part of the white noise.
LONG_TERMS_MIN_TAU_S = 20.0
#: Spectral line removal: threshold over the local median level, lowest frequency [Hz] and the
#: width of the frequency chunks [Hz] over which the median (background) level is taken.
LINE_FACTOR, LINE_FMIN_HZ, LINE_CHUNK_HZ = 20.0, 1.0, 10.0


@dataclass
class AllanDeviation:
    """Overlapping Allan deviation of one record (or pooled over several).

    Attributes
    ----------
    taus : ndarray, shape (K,)
        Cluster times actually used, integer multiples of ``dt`` [s].
    adev : ndarray, shape (K,) or (K, C)
        Allan deviation per tau (and channel), in the unit of the input.
    n_clusters : ndarray of int, shape (K,)
        Number of independent (non-overlapping) clusters ``floor(n / m)`` (summed over records).
    edf : ndarray, shape (K,)
        Equivalent degrees of freedom of the overlapping estimate for white rate noise
        (Howe, Allan & Barnes, Proc. 35th Frequency Control Symposium, 1981; reproduced in NIST
        SP 1065), summed over records.
    """

    taus: np.ndarray
    adev: np.ndarray
    n_clusters: np.ndarray
    edf: np.ndarray

    @property
    def rel_err(self) -> np.ndarray:
        """1-sigma relative error of ``adev`` per tau, ``1 / sqrt(2 edf)``, shape (K,)."""
        return 1.0 / np.sqrt(2.0 * self.edf)

    @property
    def avar(self) -> np.ndarray:
        """Allan variance [unit^2]."""
        return self.adev**2


def default_cluster_sizes(n: int, per_decade: int = 12, max_fraction: float = 0.25) -> np.ndarray:
    """Log-spaced cluster sizes ``m`` from 1 sample to ``max_fraction * n`` (at least 1), unique."""
    m_max = max(int(max_fraction * n), 1)
    k = max(int(np.ceil(per_decade * np.log10(m_max))) + 1, 1)
    return np.unique(np.round(np.logspace(0.0, np.log10(m_max), k)).astype(int))


def edf_white(n: int, m) -> np.ndarray:
    """Equivalent degrees of freedom of the overlapping Allan variance, white rate noise.

    ``edf = (3 (N - 1) / (2 m) - 2 (N - 2) / N) 4 m^2 / (4 m^2 + 5)`` with ``N = n + 1`` points of
    the integrated signal (Howe, Allan & Barnes 1981, white FM noise; in NIST SP 1065), floored at 1.
    ``1 / sqrt(2 edf)`` is then the 1-sigma relative error of the deviation.
    """
    m = np.asarray(m, float)
    big = n + 1.0
    return np.maximum(
        (3.0 * (big - 1.0) / (2.0 * m) - 2.0 * (big - 2.0) / big) * 4.0 * m**2 / (4.0 * m**2 + 5.0),
        1.0,
    )


def allan_sums(x: np.ndarray, ms: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sums of squared second differences of the integrated signal, for pooling records.

    Parameters
    ----------
    x : ndarray, shape (n,) or (n, C)
        Rate samples (any unit).
    ms : ndarray of int, shape (K,)
        Cluster sizes [samples]; those with ``2 m >= n + 1`` give a zero count.

    Returns
    -------
    ss : ndarray, shape (K,) or (K, C)
        ``sum_k (theta[k+2m] - 2 theta[k+m] + theta[k])^2`` with ``theta = cumsum(x)`` (no ``dt``).
    count : ndarray of int, shape (K,)
        Number of terms, ``n - 2m + 1`` (0 when too long).
    """
    x = np.asarray(x, float)
    # Removing the mean keeps the cumulative sum small, so no precision is lost on long records.
    theta = np.concatenate([np.zeros((1,) + x.shape[1:]), np.cumsum(x - x.mean(axis=0), axis=0)])
    ss = np.zeros((len(ms),) + x.shape[1:])
    count = np.zeros(len(ms), int)
    for j, m in enumerate(np.asarray(ms, int)):
        if 2 * m >= len(theta):
            continue
        d = theta[2 * m :] - 2.0 * theta[m:-m] + theta[: -2 * m]
        ss[j], count[j] = np.sum(d * d, axis=0), len(d)
    return ss, count


def _cluster_sizes(n: int, dt: float, taus) -> np.ndarray:
    if taus is None:
        return default_cluster_sizes(n)
    ms = np.unique(np.maximum(np.round(np.asarray(taus, float) / dt).astype(int), 1))
    return ms[2 * ms < n + 1]


def allan_deviation(x, dt: float, taus=None) -> AllanDeviation:
    """Overlapping Allan deviation of a rate series.

    Parameters
    ----------
    x : array_like, shape (N,) or (N, C)
        Samples (e.g. angular rate [rad/s] or specific force [m/s^2]), uniformly spaced; each
        sample the mean over its interval.
    dt : float
        Sample interval [s].
    taus : array_like, optional
        Wanted cluster times [s]; rounded to multiples of ``dt``, duplicates and those longer than
        half the record dropped. Default: about 12 per decade from ``dt`` to ``N dt / 4``.

    Returns
    -------
    AllanDeviation
    """
    x = np.asarray(x, float)
    return allan_deviation_pooled([x], dt, taus)


def allan_deviation_pooled(
    records, dt: float, taus=None, max_fraction: float = 0.25
) -> AllanDeviation:
    """Allan deviation pooled over independent records of the same sensor (e.g. several stops).

    At each tau the squared differences of all records are summed and divided by their total
    count, so each record weighs by its number of terms (about its length). A record contributes
    only to ``tau <= max_fraction`` of its length.

    Parameters
    ----------
    records : sequence of ndarray, each (n_i,) or (n_i, C)
    dt : float
        Sample interval [s].
    taus : array_like, optional
        As for :func:`allan_deviation`; default up to ``max_fraction`` of the longest record.
    max_fraction : float
        Longest cluster time as a fraction of a record's length.
    """
    records = [np.asarray(r, float) for r in records]
    n_max = max(len(r) for r in records)
    ms = (
        default_cluster_sizes(n_max, max_fraction=max_fraction)
        if taus is None
        else _cluster_sizes(n_max, dt, taus)
    )
    shape = (len(ms),) + records[0].shape[1:]
    ss, count, clusters, edf = (
        np.zeros(shape),
        np.zeros(len(ms)),
        np.zeros(len(ms), int),
        np.zeros(len(ms)),
    )
    for r in records:
        use = ms <= max(int(max_fraction * len(r)), 1) if taus is None else 2 * ms < len(r) + 1
        s, c = allan_sums(r, ms[use])
        ss[use] += s
        count[use] += c
        clusters[use] += len(r) // ms[use]
        edf[use] += edf_white(len(r), ms[use])
    ok = count > 0
    m = ms[ok].astype(float).reshape((-1,) + (1,) * (len(shape) - 1))
    avar = ss[ok] / (2.0 * m**2 * count[ok].reshape(m.shape))
    return AllanDeviation(ms[ok] * dt, np.sqrt(avar), clusters[ok], edf[ok])


def remove_spectral_lines(x, dt: float) -> np.ndarray:
    """The record with its narrow spectral lines (harmonic vibration) above 1 Hz removed.

    The periodogram of white noise is exponentially distributed about its level, so a bin above
    :data:`LINE_FACTOR` times the local level is a line with a false-alarm probability of
    ``exp(-20) = 2e-9`` per bin. Lines are found in a Hann-windowed periodogram (narrow lines,
    so the level, the median / ln 2 over chunks of :data:`LINE_CHUNK_HZ`, is not raised by their
    skirts). In the plain FFT each line and the skirt around it (bins above 3 times the level:
    the leakage of a tone that is not periodic in the record) are zeroed; the few white bins lost
    change the white level by a negligible fraction. Content below :data:`LINE_FMIN_HZ` (bias
    drift, slow motion) is never touched.

    Parameters
    ----------
    x : array_like, shape (N,) or (N, C)
    dt : float
        Sample interval [s].

    Returns
    -------
    ndarray, same shape as ``x``
    """
    x = np.asarray(x, float)
    n = len(x)
    f = np.fft.rfftfreq(n, dt)
    i0 = int(np.searchsorted(f, LINE_FMIN_HZ))
    nb = int(round(LINE_CHUNK_HZ / f[1])) if n > 1 else 0
    if nb < 8 or len(f) - i0 < nb:
        return x.copy()  # too short to tell a line from the noise around it
    mean = x.mean(axis=0)
    X = np.fft.rfft(x - mean, axis=0)
    hann = np.hanning(n).reshape((n,) + (1,) * (x.ndim - 1))
    P_hann = np.abs(np.fft.rfft((x - mean) * hann, axis=0)[i0:]) ** 2 * n / np.sum(hann**2)
    P = np.abs(X[i0:]) ** 2
    chunk = np.minimum(np.arange(len(P)) // nb, len(P) // nb - 1)
    level = np.stack([np.median(P_hann[chunk == c], axis=0) for c in range(chunk[-1] + 1)])[
        chunk
    ] / np.log(2.0)
    line = _grow(P_hann > LINE_FACTOR * level, P > 3.0 * level)
    X[i0:][line] = 0.0
    return np.fft.irfft(X, n, axis=0) + mean


def _grow(seed: np.ndarray, skirt: np.ndarray) -> np.ndarray:
    """The runs of ``skirt | seed`` (along axis 0, per column) that contain a ``seed``, widened by 2."""
    shape = seed.shape
    seed, mask = seed.reshape(len(seed), -1), (seed | skirt).reshape(len(seed), -1)
    out = np.zeros(mask.shape, bool)
    for ch in range(mask.shape[1]):
        d = np.diff(np.concatenate([[0], mask[:, ch].astype(np.int8), [0]]))
        starts, stops = np.flatnonzero(d == 1), np.flatnonzero(d == -1)
        hits = np.concatenate([[0], np.cumsum(seed[:, ch])])
        keep = hits[stops] > hits[starts]
        mark = np.zeros(len(mask) + 1, int)
        np.add.at(mark, np.maximum(starts[keep] - 2, 0), 1)
        np.add.at(mark, np.minimum(stops[keep] + 2, len(mask)), -1)
        out[:, ch] = np.cumsum(mark[:-1]) > 0
    return out.reshape(shape)


@dataclass
class NoiseTerms:
    """Fitted Allan variance model ``3Q^2/tau^2 + N^2/tau + 0.4413 B^2 + K^2 tau/3 + R^2 tau^2/2``.

    Each attribute is a float (one channel) or an ndarray (C,); ``unit`` is that of the input.

    Attributes
    ----------
    quantization : Q [unit s] (also absorbs vibration left in the record).
    white : N [unit sqrt(s)] = [unit/sqrt(Hz)] (angle / velocity random walk).
    bias_instability : B [unit], from the fitted constant term (compare :func:`bias_instability`).
    rate_random_walk : K [unit/sqrt(s)].
    rate_ramp : R [unit/s].
    """

    quantization: np.ndarray
    white: np.ndarray
    bias_instability: np.ndarray
    rate_random_walk: np.ndarray
    rate_ramp: np.ndarray

    def avar(self, taus) -> np.ndarray:
        """Model Allan variance at ``taus`` [s], shape (K,) or (K, C)."""
        tau = np.asarray(taus, float).reshape((-1,) + (1,) * np.ndim(self.white))
        return (
            3.0 * self.quantization**2 / tau**2
            + self.white**2 / tau
            + FLOOR_FACTOR**2 * self.bias_instability**2
            + self.rate_random_walk**2 * tau / 3.0
            + self.rate_ramp**2 * tau**2 / 2.0
        )


def _nnls(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Exact non-negative least squares for a handful of unknowns (every active set tried)."""
    k = A.shape[1]
    best, best_x = np.inf, np.zeros(k)
    for r in range(1, k + 1):
        for cols in combinations(range(k), r):
            c = np.linalg.lstsq(A[:, cols], b, rcond=None)[0]
            if np.any(c < 0.0):
                continue
            x = np.zeros(k)
            x[list(cols)] = c
            res = float(np.sum((A @ x - b) ** 2))
            if res < best:
                best, best_x = res, x
    return best_x


def fit_noise_terms(ad: AllanDeviation, iterations: int = 3) -> NoiseTerms:
    """Fit the five-term model to an Allan deviation (non-negative weighted least squares).

    The weight of each tau is ``1 / (sigma^2 sqrt(2 / edf + MODEL_ERROR^2))`` with ``sigma^2``
    the model itself after the first pass (weights from the noisy estimate would bias the fit low).
    When the taus stop short of :data:`LONG_TERMS_MIN_TAU_S`, only Q and N are fitted (B, K and
    R are returned as 0).
    """
    tau = ad.taus
    # The bias terms are fitted only when the taus reach LONG_TERMS_MIN_TAU_S.
    n_terms = 5 if tau[-1] >= LONG_TERMS_MIN_TAU_S else 2
    basis = np.column_stack([tau**-2, tau**-1, np.ones_like(tau), tau, tau**2])[:, :n_terms]
    avar = ad.avar.reshape(len(tau), -1)
    coef = np.zeros((avar.shape[1], 5))
    for ch in range(avar.shape[1]):
        model = avar[:, ch]
        for _ in range(iterations):
            s = np.maximum(model, 1e-300) * np.sqrt(2.0 / ad.edf + MODEL_ERROR**2)
            A = basis / s[:, None]
            scale = np.linalg.norm(A, axis=0)
            c = _nnls(A / scale, avar[:, ch] / s) / scale
            model = basis @ c
        coef[ch, :n_terms] = c
    q, n2, b2, k2, r2 = coef.T
    out = (
        np.sqrt(q / 3.0),
        np.sqrt(n2),
        np.sqrt(b2) / FLOOR_FACTOR,
        np.sqrt(3.0 * k2),
        np.sqrt(2.0 * r2),
    )
    if ad.adev.ndim == 1:
        out = tuple(float(v[0]) for v in out)
    return NoiseTerms(*out)


def floor_bias_instability(ad: AllanDeviation, white=None):
    """``B = min sigma / 0.664`` per channel when the floor is shown (:data:`FLOOR_RULE`), else None.

    Parameters
    ----------
    ad : AllanDeviation
    white : float or ndarray (C,), optional
        White-noise density of the record; default: fitted (:func:`fit_noise_terms`).

    Returns
    -------
    float or None for a single channel; list of (float or None) per channel otherwise.
    """
    white = np.atleast_1d(fit_noise_terms(ad).white if white is None else white)
    use = ad.n_clusters >= MIN_CLUSTERS_FLOOR
    tau, sig = ad.taus[use], ad.adev[use].reshape(int(use.sum()), -1)
    out = []
    for ch in range(sig.shape[1]):
        if len(tau) < 3:
            out.append(None)
            continue
        k = int(np.argmin(sig[:, ch]))
        shown = tau[k] >= np.sqrt(10.0) * tau[0] and white[ch] / np.sqrt(tau[k]) <= 0.5 * sig[k, ch]
        out.append(float(sig[k, ch] / FLOOR_FACTOR) if shown else None)
    return out[0] if ad.adev.ndim == 1 else out


def white_noise_density(x, dt: float, remove_lines: bool = True):
    """White-noise density ``N`` (angle / velocity random walk) of a record at rest.

    Parameters
    ----------
    x : array_like, shape (N,) or (N, C)
        Rate samples at rest, e.g. angular rate [rad/s] or specific force [m/s^2].
    dt : float
        Sample interval [s].
    remove_lines : bool
        Remove narrow spectral lines (harmonic vibration) first (:func:`remove_spectral_lines`).

    Returns
    -------
    float or ndarray (C,)
        ``N`` in [unit sqrt(s)] = [unit/sqrt(Hz)]: [rad/s/sqrt(Hz)] = [rad/sqrt(s)] for a gyro,
        [m/s^2/sqrt(Hz)] = [m/s/sqrt(s)] for an accelerometer. ``sigma(tau) = N / sqrt(tau)``.
    """
    x = remove_spectral_lines(x, dt) if remove_lines else np.asarray(x, float)
    return fit_noise_terms(allan_deviation(x, dt)).white


def bias_instability(x, dt: float, remove_lines: bool = True):
    """Bias instability ``B = min sigma / 0.664`` (IEEE Std 952), or None if the floor is not shown.

    Parameters are those of :func:`white_noise_density`; the rule is :data:`FLOOR_RULE`.

    Returns
    -------
    float or None (one channel); list of (float or None) per channel for (N, C) input. Unit: that
    of ``x`` (e.g. [rad/s]).
    """
    x = remove_spectral_lines(x, dt) if remove_lines else np.asarray(x, float)
    return floor_bias_instability(allan_deviation(x, dt))
