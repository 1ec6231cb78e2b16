"""A clock-offset proposal the first passes refute costs a few passes, not a search
(:func:`gnssacc.prepare.clock._refuted_at_once`, a sequential likelihood test), with the verdict
the search gave; a proposal that may be right, or a maximum near the stamps that is a real gain,
still goes to the search."""

from __future__ import annotations

import numpy as np
import pytest

import gnssacc.prepare.clock as clock
import gnssacc.prepare.settle as settle
from gnssacc.prepare.judge import Innovations


class _Quadratic:
    """A log-likelihood over 300 fixes (10 min) with its maximum at ``best`` [s] and a 1-sigma of
    ``sigma`` [s]: ``-(d - best)^2 / (2 sigma^2)`` in all, spread evenly over the fixes."""

    def __init__(self, best: float, sigma: float):
        self.best, self.sigma, self.asked = best, sigma, set()
        self.t = np.linspace(100.0, 700.0, 300)
        self.t_from, self.t_to = 90.0, 710.0

    def cost(self, d: float) -> float:
        self.asked.add(round(d, 9))
        return 0.5 * ((d - self.best) / self.sigma) ** 2 - 500.0

    def ahead(self, *ds: float) -> None:
        """Nothing to make ahead: :meth:`cost` counts what the test asks."""

    def at(self, d: float) -> Innovations:
        ll = np.full(len(self.t), -self.cost(d) / len(self.t))
        return Innovations(self.t, ll, np.ones(len(self.t)), 0.0, 800.0)


def test_a_refuted_proposal_costs_a_few_passes_and_finds_the_maximum_near_the_stamps():
    lik = _Quadratic(best=0.01, sigma=0.04)
    verdict, d, sigma = clock._refuted_at_once(lik, -0.41, 0.5)
    assert verdict.refuted and not verdict.decisive
    assert d == pytest.approx(0.01, abs=0.002)
    assert sigma == pytest.approx(0.04, rel=0.05)
    assert len(lik.asked) <= 8  # the stamps, the proposal, the curvature's steps, the vertex


def test_a_proposal_that_may_be_right_goes_to_the_search():
    # The proposal is the maximum: the stamps as given are the less likely.
    assert clock._refuted_at_once(_Quadratic(best=-0.41, sigma=0.04), -0.41, 0.5) is None
    # The proposal loses, but the maximum near the stamps gains (0.15 / 0.04)^2 / 2 = 7 nats over
    # them: not refuted here, the search decides.
    assert clock._refuted_at_once(_Quadratic(best=0.15, sigma=0.04), -0.41, 0.5) is None
    # Too flat to place a maximum (a 1-sigma of 2 s): the search decides.
    assert clock._refuted_at_once(_Quadratic(best=0.0, sigma=2.0), -0.41, 0.5) is None


def test_kittis_own_clock_proposal_is_refuted_in_a_few_passes(monkeypatch):
    """KITTI's motion views propose -0.41 s; the EKF refutes it from the first passes (the
    search took 21 passes for the same verdict: -0.041 +- 0.042 s, gain +0.47)."""
    from gnssacc.pipeline import check_input, configure, load
    from gnssacc.prepare.fix_noise import with_measured_sigmas

    monkeypatch.setenv("GNSSACC_JOBS", "1")  # every pass made here, where it is counted
    passes = {"n": 0}
    real = settle.evaluate_offset

    def counted(run, cfg, finding, base, filter_pass):
        def one(*a, **k):
            passes["n"] += 1
            return filter_pass(*a, **k)

        return real(run, cfg, finding, base, one)

    monkeypatch.setattr(settle, "evaluate_offset", counted)
    cfg = configure("kitti")
    run, _ = with_measured_sigmas(load("kitti", config=cfg))
    _, _, findings = check_input(run, cfg)
    (offset,) = [f for f in findings if f.check == "time_offset"]
    d = offset.details
    assert d["stage1_s"] == pytest.approx(-0.41, abs=0.05)
    assert offset.action == "refuted" and d["verdict"]["refuted"]
    assert abs(d["measured_s"]) < 2 * d["sigma_s"] and 0.02 < d["sigma_s"] < 0.08
    assert passes["n"] <= 8


@pytest.mark.parametrize("true_s, stage1_s", [(0.0, -0.3), (0.4, 0.35)])
def test_the_clock_passes_side_by_side_give_what_one_after_the_other_gives(
    monkeypatch, true_s, stage1_s
):
    """The shifted passes made ahead in forked workers (:meth:`clock._Shifts.ahead`): the same
    verdict, offset and sigma, to the last bit, as every pass made here; through the quick
    refutation (a proposal of -0.3 s on stamps that are right) and through the search and its
    curvature (an offset of 0.4 s, proposed at 0.35 s)."""
    from gnssacc.checks.findings import Finding
    from gnssacc.core import parallel
    from gnssacc.core.config import load_config
    from gnssacc.prepare.passes import filter_pass
    from gnssacc.prepare.start import start_pieces
    from gnssacc.sources.sim import simulate

    run = simulate("car", 120.0, imu_grade="consumer", noise="white", seed=2)
    run = run.with_imu_shift(-true_s)  # the IMU stamps run true_s behind the GNSS clock
    cfg = load_config()
    base = start_pieces(run, cfg, filter_pass)
    quick, real = [], clock._refuted_at_once
    monkeypatch.setattr(clock, "_refuted_at_once", lambda *a: quick.append(real(*a)) or quick[-1])
    got = {}
    for jobs in ("1", "2"):
        monkeypatch.setenv(parallel.JOBS_ENV, jobs)
        assert parallel.usable_jobs() == int(jobs) and not parallel.forks_held()  # forked at 2
        finding = Finding(
            "time_offset", "sim", "p", details={"stage1_s": stage1_s, "stage1_sigma_s": 0.05}
        )
        verdict, corrected, est = clock.evaluate_offset(run, cfg, finding, base, filter_pass)
        bound = clock.offset_sigma(run, cfg, base, filter_pass)
        got[jobs] = (verdict.to_dict(), est, corrected.imu.t, bound)
    alone, side = got["1"], got["2"]
    assert side[0] == alone[0] and side[1] == alone[1] and side[3] == alone[3]
    np.testing.assert_array_equal(side[2], alone[2])
    assert alone[1] is not None and abs(alone[1].offset_s - true_s) < 3 * alone[1].sigma_s
    assert alone[0]["refuted"] == (true_s == 0.0) and alone[0]["decisive"] == (true_s != 0.0)
    assert [q is not None for q in quick] == [true_s == 0.0] * 2  # the path taken, both times
    assert parallel._POOL["executor"] is None  # the workers ended with the search
