"""The estimator's verdict on a proposed correction (gnssacc.prepare.judge, settle, clock): the
likelihood arithmetic in closed form, and the verdicts that a single heuristic got wrong."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from gnssacc.checks import views
from gnssacc.checks.timeoffset import OffsetEstimate
from gnssacc.core.config import load_config
from gnssacc.core.errors import InputError
from gnssacc.pipeline import check_input
from gnssacc.prepare.judge import LR_MIN, RATE_MIN, Innovations, Verdict, compare
from gnssacc.sources.sim import simulate


def _inn(t, ll, nis=1.0, t_start=0.0, t_end=1e9):
    t = np.asarray(t, float)
    return Innovations(
        t,
        np.full(len(t), float(ll)) if np.ndim(ll) == 0 else np.asarray(ll, float),
        np.full(len(t), nis),
        t_start,
        t_end,
    )


def test_compare_sums_over_the_common_fixes_after_the_burn_in():
    t = np.arange(0.0, 100.0)
    given, corrected = (
        _inn(t, -2.0),
        _inn(t[5:], -1.5, t_start=5.0),
    )  # the corrected pass starts later
    v = compare(given, corrected)
    scored = t[(t >= 15.0)]  # 10 s after the later start
    assert v.n_fixes == len(scored) and v.gain == pytest.approx(0.5 * len(scored))
    assert v.minutes == pytest.approx((scored[-1] - scored[0]) / 60.0)
    jac = compare(given, corrected, log_jacobian=-0.25)
    assert jac.gain == pytest.approx(0.25 * len(scored))


def test_decisive_needs_both_bounds_and_a_consistent_correction():
    assert (
        Verdict(LR_MIN, 50, 1.0, 1.0).decisive and not Verdict(LR_MIN - 0.1, 50, 1.0, 1.0).decisive
    )
    long = 3.0 * LR_MIN / RATE_MIN  # a long recording needs the per-minute rate too
    assert (
        not Verdict(2.0 * LR_MIN, 500, long, 1.0).decisive
        and Verdict(3.5 * LR_MIN, 500, long, 1.0).decisive
    )
    assert not Verdict(
        1e4, 50, 1.0, 40.0, nis_given=5.0
    ).decisive  # corrected: a model that does not fit
    assert Verdict(1e4, 50, 1.0, 40.0, nis_given=400.0).decisive  # ... but far better than as given
    assert not Verdict(1e4, 5, 1.0, 1.0).decisive  # too few fixes
    assert Verdict(1.0, 50, 1.0, 1.0).refuted and not Verdict(5.0, 50, 1.0, 1.0).refuted


def test_data_that_cannot_be_estimated_as_given():
    v = compare(None, _inn(np.arange(30.0), -1.0))
    assert v.gain == math.inf and v.decisive and "cannot be estimated" in v.text()


@pytest.fixture(scope="module")
def slow_ugv():
    return simulate("ugv-slow", 235.0, imu_grade="consumer", noise="white", seed=5)


def _chance_peak(monkeypatch, offset_s=44.5):
    """Stage 1 returns a confident peak far from the truth (0 s), as a long park's noise gave it
    on a real slow UGV; the views and the estimator must not believe it."""
    real = views.coarse_offset

    def fake(lev, kin, *args, **kwargs):
        real(lev, kin, *args, **kwargs)
        return OffsetEstimate(offset_s, 0.2, True, rho=0.7, rho_other=0.4)

    monkeypatch.setattr(views, "coarse_offset", fake)


def test_a_chance_correlation_peak_is_contradicted_by_the_turns(monkeypatch, slow_ugv):
    _chance_peak(monkeypatch)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # not even a warning: one view against another
        out, _, findings = check_input(slow_ugv, load_config())
    assert out is slow_ugv
    assert [(f.check, f.action) for f in findings] == [("time_offset", "refuted")]


def test_a_chance_correlation_peak_is_refuted_by_the_estimator(monkeypatch, slow_ugv):
    """With the turn view silenced, the estimator alone decides: the stamps as given are far
    likelier than shifted by 44.5 s (the real case: 187-215 nats), so nothing is refused, and the
    gyro check, whose rest epochs followed that offset, is not fooled either."""
    _chance_peak(monkeypatch)
    monkeypatch.setattr(views, "TURN_MARGIN", math.inf)
    out, _, findings = check_input(slow_ugv, load_config())
    assert out is slow_ugv and [f.check for f in findings] == ["time_offset"]
    verdict = findings[0].details["verdict"]
    assert findings[0].action == "refuted" and verdict["loglik_gain"] < -LR_MIN


def test_a_true_offset_is_refused_with_the_evidence_on_request(slow_ugv):
    bad = slow_ugv.with_imu_shift(-18.0)
    with pytest.raises(InputError) as exc:
        check_input(bad, load_config(overrides={"checks": {"on_proof": "refuse"}}))
    problem = exc.value.problem
    assert "imu_time_offset_s = 18." in problem and "the estimator proves it" in problem
    assert "as given" in problem and "as corrected" in problem  # the evidence both ways
    assert 'on_proof = "refuse"' in problem


def test_a_true_offset_is_applied_by_default_with_the_evidence(slow_ugv):
    bad = slow_ugv.with_imu_shift(-18.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # stated by the caller (header line, metrics), not warned
        out, cfg, findings = check_input(bad, load_config())
    (f,) = findings
    assert f.check == "time_offset" and f.action == "applied"
    assert abs(cfg["mounting"]["imu_time_offset_s"] - 18.0) < 0.3
    np.testing.assert_allclose(out.imu.t, slow_ugv.imu.t, atol=0.3)
    assert "as given" in f.details["evidence"] and f.details["verdict"]["decisive"]
