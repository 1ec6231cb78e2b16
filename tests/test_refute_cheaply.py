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
