"""Allan deviation and the noise terms read from it, against processes with known statistics.

Truths come from theory, never from the code under test: white noise has
``sigma(tau) = N / sqrt(tau)``; a rate random walk ``K^2 tau / 3``; a first-order Gauss-Markov
process the closed form of IEEE Std 952 (Annex C); flicker noise with the two-sided PSD
``B^2 / (2 pi f)`` the floor ``0.664 B``. Vibration is an exact interval mean of sinusoids, as an
integrating IMU samples it.
"""

from __future__ import annotations

import numpy as np
import pytest

from gnssacc.core.units import DEG
from gnssacc.prepare.allan import (
    allan_deviation,
    allan_deviation_pooled,
    bias_instability,
    remove_spectral_lines,
    white_noise_density,
)


def _white(n, dt, N, rng):
    """White rate noise of density N [unit/sqrt(Hz)]: per-sample sigma N / sqrt(dt)."""
    return rng.standard_normal(n) * N / np.sqrt(dt)


def _flicker(n, dt, B, rng):
    """Flicker (1/f) noise with two-sided PSD B^2 / (2 pi f), synthesised by FFT."""
    f = np.fft.rfftfreq(n, dt)
    S = np.zeros_like(f)
    S[1:] = B**2 / (2.0 * np.pi * f[1:])
    # E|c_k|^2 = S df for each of +-f_k; irfft divides by n.
    c = np.sqrt(S * f[1] / 2.0) * (rng.standard_normal(len(f)) + 1j * rng.standard_normal(len(f)))
    return np.fft.irfft(c * n, n)


def _harmonics(t, dt, rng, parts):
    """Interval means over (t - dt, t] of sum A sin(2 pi f t + phase), exact."""
    out = np.zeros(len(t))
    for f, amp in parts:
        w, ph = 2.0 * np.pi * f, rng.uniform(0.0, 2.0 * np.pi)
        out += amp * (np.cos(w * (t - dt) + ph) - np.cos(w * t + ph)) / (w * dt)
    return out


def _slope(ad, lo, hi, ch=None):
    sel = (ad.taus >= lo) & (ad.taus <= hi)
    y = ad.adev[sel] if ch is None else ad.adev[sel, ch]
    return np.polyfit(np.log(ad.taus[sel]), np.log(y), 1)[0]


def test_white_noise_matches_n_over_sqrt_tau_within_error_bars():
    rng = np.random.default_rng(1)
    dt, N, n = 0.01, 2e-3, 100_000
    x = np.column_stack([_white(n, dt, N, rng), _white(n, dt, 3 * N, rng)])
    ad = allan_deviation(x, dt)
    m = np.round(ad.taus / dt).astype(int)
    assert np.allclose(ad.taus, m * dt) and m[0] == 1 and m[-1] <= n // 4 and m[-1] > n // 8
    assert np.array_equal(ad.n_clusters, n // m)
    assert ad.adev.shape == (len(ad.taus), 2)
    for ch, dens in enumerate((N, 3 * N)):
        z = (ad.adev[:, ch] / (dens / np.sqrt(ad.taus)) - 1.0) / ad.rel_err
        assert np.all(np.abs(z) < 3.5), z
        assert np.mean(np.abs(z) < 1.0) > 0.5  # the error bar is an honest 1-sigma
    # One channel alone gives the same numbers.
    assert np.allclose(allan_deviation(x[:, 1], dt).adev, ad.adev[:, 1])


def test_random_walk_and_gauss_markov_slopes():
    rng = np.random.default_rng(2)
    dt, n = 0.05, 200_000
    K = 1e-4
    rw = np.cumsum(rng.standard_normal(n)) * K * np.sqrt(dt)  # rate random walk
    ad = allan_deviation(rw, dt)
    assert _slope(ad, 1.0, 200.0) == pytest.approx(0.5, abs=0.07)
    sel = (ad.taus >= 1.0) & (ad.taus <= 200.0)
    assert np.allclose(ad.adev[sel], K * np.sqrt(ad.taus[sel] / 3.0), rtol=0.3)
    # First-order Gauss-Markov, correlation time Tc: +1/2 well below Tc, -1/2 well above.
    Tc, sig = 10.0, 1e-3
    a = np.exp(-dt / Tc)
    drive = rng.standard_normal(n) * sig * np.sqrt(1 - a * a)
    gm = np.empty(n)
    gm[0] = sig * rng.standard_normal()
    # x_k = a x_{k-1} + e_k in closed form by blocks (no per-sample loop).
    for s in range(0, n - 1, 2000):
        m = min(2000, n - 1 - s)
        p = a ** np.arange(1, m + 1)
        gm[s + 1 : s + m + 1] = p * (gm[s] + np.cumsum(drive[s + 1 : s + m + 1] / p))
    ad = allan_deviation(gm, dt)
    q = 2.0 * sig**2 / Tc
    tau = ad.taus
    theory = (
        q
        * Tc**2
        / tau
        * (1.0 - Tc / (2.0 * tau) * (3.0 - 4.0 * np.exp(-tau / Tc) + np.exp(-2.0 * tau / Tc)))
    )
    sel = tau <= 300.0
    assert np.allclose(ad.adev[sel], np.sqrt(theory[sel]), rtol=0.25)
    assert _slope(ad, 0.1, 0.5) == pytest.approx(0.5, abs=0.1)
    assert _slope(ad, 150.0, 1000.0) == pytest.approx(-0.5, abs=0.2)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_white_noise_density_robust_to_strong_harmonic_vibration(seed):
    # Consumer gyro: 0.01 deg/s/sqrt(Hz) white noise, engine vibration 30 Hz + 60 Hz + 90 Hz with a
    # per-sample scatter of ~2.4 deg/s (20x the white noise), a 30 deg/h flicker bias, sampled by
    # an integrating IMU at 100 Hz for 10 minutes.
    rng = np.random.default_rng(10 + seed)
    dt, n = 0.01, 60_000
    t = np.arange(1, n + 1) * dt
    N = 0.01 * DEG
    x = (
        _white(n, dt, N, rng)
        + _flicker(n, dt, 30.0 / 3600.0 * DEG, rng)
        + _harmonics(t, dt, rng, [(30.0, 3.9 * DEG), (60.0, 1.0 * DEG), (90.0, 0.7 * DEG)])
    )
    assert np.degrees(np.std(x)) > 2.0  # the scatter the brief describes
    assert np.std(x) * np.sqrt(dt) > 10.0 * N  # a naive reading is 10x+ off
    assert white_noise_density(x, dt) == pytest.approx(N, rel=0.10)


def test_remove_spectral_lines_keeps_white_noise_and_removes_tones():
    rng = np.random.default_rng(4)
    dt, n = 0.01, 30_000
    t = np.arange(1, n + 1) * dt
    w = _white(n, dt, 1e-3, rng)
    assert np.std(remove_spectral_lines(w, dt)) == pytest.approx(np.std(w), rel=0.01)
    tone = _harmonics(t, dt, rng, [(27.0, 0.1), (54.0, 0.05)])
    cleaned = remove_spectral_lines(w + tone, dt)
    assert np.std(cleaned - w) < 0.05 * np.std(tone)


def test_bias_instability_floor_on_long_record_none_on_short():
    # White N with flicker B: the ADEV reaches its floor 0.664 B after (N / 0.664 B)^2 = 9 s.
    N, B = 1e-3, 5e-4
    for seed in (0, 1, 2):
        rng = np.random.default_rng(20 + seed)
        dt, n = 0.1, 200_000  # 5.6 h
        x = _white(n, dt, N, rng) + _flicker(n, dt, B, rng)
        assert bias_instability(x, dt) == pytest.approx(B, rel=0.25)
        assert white_noise_density(x, dt) == pytest.approx(N, rel=0.10)
    rng = np.random.default_rng(30)
    dt = 0.01
    short = _white(2_000, dt, N, rng) + _flicker(
        2_000, dt, B, rng
    )  # 20 s: still on the white slope
    assert bias_instability(short, dt) is None
    white_only = _white(200_000, 0.1, N, rng)  # never flattens
    assert bias_instability(white_only, 0.1) is None


def test_pooled_allan_deviation_of_records():
    rng = np.random.default_rng(5)
    dt, N = 0.01, 1e-3
    a, b = _white(40_000, dt, N, rng), _white(20_000, dt, N, rng)
    one = allan_deviation_pooled([a], dt)
    assert np.allclose(one.adev, allan_deviation(a, dt).adev)
    both = allan_deviation_pooled([a, b], dt)
    z = (both.adev / (N / np.sqrt(both.taus)) - 1.0) / both.rel_err
    assert np.all(np.abs(z) < 3.5)
    # The short record stops adding clusters beyond a quarter of its length.
    m = np.round(both.taus / dt).astype(int)
    assert np.array_equal(both.n_clusters, 40_000 // m + np.where(m <= 5_000, 20_000 // m, 0))
