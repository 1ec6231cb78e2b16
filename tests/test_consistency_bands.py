"""The chi-square bands a run's mean NEES and NIS are judged by, when the errors are correlated in
time, and the attitude NEES in the table.

An estimator's errors at consecutive epochs are far from independent (a filter corrects its error
over its own time constant), so the mean NEES of one run scatters much more than a chi-square with
``n`` epochs says. The band counts the epochs the run is worth
(:func:`gnssacc.analysis.errorstats.effective_count`). Checked here against errors whose
correlation is known (AR(1): ``z_k = r z_(k-1) + sqrt(1 - r^2) w_k``, unit variance, for which the
mean of ``z^2`` over ``n`` epochs is worth ``n (1 - r^2) / (1 + r^2)`` independent ones), the
false-warning rate of a consistent estimator's band is near its nominal probability, while the
band of independent epochs warns on most consistent runs.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import binom

from gnssacc.analysis import errorstats
from gnssacc.analysis.consistency import band
from gnssacc.core.solution import NavSolution
from gnssacc.sources.sim import simulate


def ar1(rng, runs: int, n: int, m: int, r: float) -> np.ndarray:
    """``runs`` series of ``n`` epochs and ``m`` independent axes of a stationary unit AR(1)."""
    w = rng.standard_normal((runs, n, m))
    z = np.empty_like(w)
    z[:, 0] = w[:, 0]
    for k in range(1, n):
        z[:, k] = r * z[:, k - 1] + np.sqrt(1.0 - r * r) * w[:, k]
    return z


def test_effective_count_of_ar1_squares():
    """One long AR(1) axis: the count of its squares is ``n (1 - r^2) / (1 + r^2)`` (the squares
    correlate by ``r^2``), not the ``n (1 - r) / (1 + r)`` of the errors themselves."""
    rng = np.random.default_rng(1)
    n, r = 20_000, 0.9
    z = ar1(rng, 1, n, 1, r)[0]
    assert errorstats.effective_count(z) == pytest.approx(n * (1 - r * r) / (1 + r * r), rel=0.15)
    assert errorstats.effective_count(rng.normal(size=n)) == pytest.approx(n, rel=0.05)


def test_effective_count_of_axes_that_move_together():
    """Three axes that are one and the same error are worth one axis; three independent ones
    three times as much."""
    rng = np.random.default_rng(2)
    z = ar1(rng, 1, 5000, 3, 0.8)[0]
    one = errorstats.effective_count(z[:, 0])
    same = errorstats.effective_count(np.repeat(z[:, :1], 3, axis=1))
    assert same == pytest.approx(one / 3, rel=1e-6)
    assert errorstats.effective_count(z) == pytest.approx(one, rel=0.2)


@pytest.mark.parametrize("r", [0.9, 0.95])
def test_band_coverage_of_correlated_errors(r):
    """2000 consistent runs of 300 epochs, 3 axes, AR(1) errors of correlation time 10-20 epochs
    (a filter's errors at 1 Hz): the band from the run's own effective count leaves out about its
    nominal share ``alpha`` of them; the band of independent epochs leaves out most.

    Bounds: the count outside is binomial; at its true rate ``alpha`` the band's estimate of the
    count is taken to be right within a factor 2 (the effective count is estimated from the run
    itself, with a sampling error of its own), each bound at a false-failure rate below 1e-4."""
    runs, n, m = 2000, 300, 3
    z = ar1(np.random.default_rng([33, int(100 * r)]), runs, n, m, r)
    nees = np.mean(z**2, axis=(1, 2))
    count = np.array([errorstats.effective_count(x) for x in z])
    assert np.median(count) == pytest.approx(n * (1 - r * r) / (1 + r * r), rel=0.25)
    for alpha in (0.05, 0.01):
        lo, hi = np.array([errorstats.chi2_band(k, m, alpha) for k in count]).T
        outside = int(np.sum((nees < lo) | (nees > hi)))
        assert binom.sf(outside - 1, runs, 2 * alpha) > 1e-4, (alpha, outside)  # not too many
        assert binom.cdf(outside, runs, alpha / 2) > 1e-4, (alpha, outside)  # nor too few
        lo, hi = errorstats.chi2_band(n, m, alpha)
        independent = int(np.sum((nees < lo) | (nees > hi)))
        assert independent > 0.3 * runs, (alpha, independent)


def test_a_correlated_error_too_large_for_its_sigma_is_still_found():
    """The wider band of correlated errors still catches a stated sigma half the true one (NEES
    4), on nearly every run."""
    z = 2.0 * ar1(np.random.default_rng(4), 200, 300, 3, 0.95)
    sig = np.ones((300, 3))
    warned = [errorstats.nees(x, sig, errorstats.AXES_RPY)["pooled_outside"] for x in z]
    assert np.mean(warned) > 0.95


def test_nis_band_counts_correlated_innovations():
    """The NIS band of ``n`` updates with lag-1 autocorrelation ``r`` is that of
    ``n (1 - r^2) / (1 + r^2)`` independent ones; white innovations keep the plain band."""
    n, r = 100, 0.97
    n_eff = n * (1 - r * r) / (1 + r * r)
    assert band(n, 3, acf1=r)[1] == pytest.approx(1 + 3 * np.sqrt(2 / (3 * n_eff)), rel=1e-9)
    assert band(n, 3, acf1=None) == band(n, 3) == band(n, 3, acf1=-0.2)
    assert band(n, 3)[1] == 2.0  # the plain band of 100 updates is the floor's


def test_attitude_nees_has_its_own_column_and_warning(tmp_path):
    """A solution whose roll is 5 stated sigma off and whose position errors fit their sigma: the
    attitude NEES is warned about in its own column, the position NEES is not."""
    from gnssacc.analysis.consistency import assess
    from gnssacc.outputs.report import table_rows

    run = simulate("car", duration_s=60.0, imu_grade="industrial", noise="white", seed=5)
    tr = run.truth
    k = len(tr.t)
    rng = np.random.default_rng(6)
    p = run.origin.to_ned(tr.lat, tr.lon, tr.h) + rng.normal(size=(k, 3))
    lat, lon, h = run.origin.to_llh(p)
    sigma = np.ones((k, 15))
    sigma[:, 6:9] = 0.01
    rpy = tr.rpy + [0.05, 0.0, 0.0] + 0.01 * rng.normal(size=(k, 3))
    sol = NavSolution(
        "ekf", tr.t, lat, lon, h, tr.v_n, rpy, np.zeros((k, 3)), np.zeros((k, 3)), sigma
    )
    errors = errorstats.error_statistics(run, sol)
    c = assess(run, sol, errors=errors)
    assert "nees_att" in c.flags and "nees" not in c.flags
    metrics = {
        "methods": {"ekf": {"prmse_m": 1.7, "errors": errors, "runtime_s": 1.0, "status": "ok"}},
        "consistency": {"ekf": c.to_dict()},
    }
    head, rows = table_rows(metrics)
    cell = dict(zip(head, rows[0], strict=True))
    assert cell["NEES att"].endswith("!") and float(cell["NEES att"][:-2]) > 5
    assert not cell["NEES pos"].endswith("!")


def test_a_tuned_odometry_below_its_band_is_no_false_alarm():
    """The tuner inflates the odometry's white sigma for its errors' correlation (the fixes'
    likelihood decides), so its one-step NIS lies below 1 by design: no "too large" warning then;
    an odometry sigma the user set (not tuned) that low is still warned about. Too high is
    warned about either way."""
    from dataclasses import replace

    from gnssacc.analysis.consistency import assess

    run = simulate("car", duration_s=60.0, imu_grade="industrial", noise="white", seed=5)
    tr = run.truth
    k = len(tr.t)
    lat, lon, h = run.origin.to_llh(run.origin.to_ned(tr.lat, tr.lon, tr.h))
    zero = np.zeros((k, 3))
    sol = NavSolution("ekf", tr.t, lat, lon, h, tr.v_n, tr.rpy, zero, zero, np.ones((k, 15)))
    low = replace(sol, stats={"nis_odo_mean": 0.1, "n_odo_updates": 300})
    high = replace(sol, stats={"nis_odo_mean": 9.0, "n_odo_updates": 300})

    def odo_warned(s, tuned):
        return any("odometry NIS" in w for w in assess(run, s, tuned=tuned).warnings)

    assert not odo_warned(low, tuned=True)
    assert odo_warned(low, tuned=False)
    assert odo_warned(high, tuned=True) and odo_warned(high, tuned=False)
