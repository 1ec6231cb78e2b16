"""The distribution functions the tool states bounds with, against closed forms and scipy.stats."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from gnssacc.core.distributions import binom_sf, chi2_isf, chi2_ppf, t_ppf


@pytest.mark.parametrize("p", [1e-3, 0.025, 0.5, 0.9])
def test_chi2_two_dof_closed_form(p):
    # chi-square of 2 dof is exponential with mean 2: P(X > x) = exp(-x / 2)
    assert chi2_isf(p, 2) == pytest.approx(-2.0 * math.log(p), rel=1e-12)
    assert chi2_ppf(p, 2) == pytest.approx(-2.0 * math.log1p(-p), rel=1e-12)


@pytest.mark.parametrize("dof", [1, 3, 6, 9.5, 120.7, 3000.0])
@pytest.mark.parametrize("q", [1e-3, 0.0015, 0.025, 0.5, 0.975, 0.9985])
def test_quantiles_match_scipy_stats(dof, q):
    assert chi2_ppf(q, dof) == pytest.approx(stats.chi2.ppf(q, dof), rel=1e-12)
    assert chi2_isf(q, dof) == pytest.approx(stats.chi2.isf(q, dof), rel=1e-12)
    assert t_ppf(q, dof) == pytest.approx(stats.t.ppf(q, dof), rel=1e-12, abs=1e-15)


def test_t_one_dof_is_cauchy():
    for q in (0.6, 0.975):
        assert t_ppf(q, 1) == pytest.approx(math.tan(math.pi * (q - 0.5)), rel=1e-12)


@pytest.mark.parametrize("n", [1, 5, 60])
def test_binom_sf_against_the_sum(n):
    p = 0.07
    for k in range(-1, n + 1):
        direct = sum(math.comb(n, j) * p**j * (1 - p) ** (n - j) for j in range(k + 1, n + 1))
        assert binom_sf(k, n, p) == pytest.approx(direct, rel=1e-9, abs=1e-300)


def test_binom_sf_large_n_matches_scipy_stats():
    for k in (0, 3, 10, 40):
        assert binom_sf(k, 5000, 1e-3) == pytest.approx(stats.binom.sf(k, 5000, 1e-3), rel=1e-9)


def test_the_run_does_not_load_scipy_stats():
    # loading scipy.stats costs every run 0.4-2 s; the tool's bounds must not need it
    import subprocess
    import sys

    code = (
        "import sys, gnssacc.pipeline, gnssacc.analysis.consistency, gnssacc.analysis.errorstats,"
        " gnssacc.analysis.nis_series, gnssacc.estimators.aids.base as b;"
        " b.tail_bound(3); print('scipy.stats' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
    assert np.isfinite(chi2_isf(1e-3, 3))
