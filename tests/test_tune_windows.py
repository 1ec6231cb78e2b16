"""Tuning whose cost does not grow with the recording (:mod:`gnssacc.prepare.tune_windows`): a long
run is identified on windows spanning a fixed number of IMU seconds, placed to keep the run's rests
and turns, their likelihoods those of passes over each window; the whole run confirms the result."""

from __future__ import annotations

import os
from types import SimpleNamespace

import numpy as np
import pytest

import gnssacc
import gnssacc.prepare.tune_windows as tw
from gnssacc.core.config import load_config
from gnssacc.pipeline import prepare
from gnssacc.prepare.passes import filter_pass
from gnssacc.prepare.tuning import ungated


@pytest.fixture(autouse=True)
def windowed(monkeypatch):
    """Windows from 900 s (off by default: see ``WINDOWED_FROM_S``)."""
    monkeypatch.setattr(tw, "WINDOWED_FROM_S", 900.0)


def test_merged_statistics_add_likelihoods_and_weight_the_means():
    a = {"n_pos_updates": 10, "loglik_pos": -5.0, "nis_pos_mean": 1.0, "acf1_pos": 0.1}
    b = {"n_pos_updates": 30, "loglik_pos": -20.0, "nis_pos_mean": 2.0, "acf1_pos": None}
    m = tw.merged([a, b])
    assert m["n_pos_updates"] == 40 and m["loglik_pos"] == -25.0 and m["loglik"] == -25.0
    assert m["nis_pos_mean"] == pytest.approx((10 * 1.0 + 30 * 2.0) / 40)
    assert m["acf1_pos"] == pytest.approx(0.1)  # only the window that has one


def test_windows_are_placed_where_their_rest_and_turning_match_their_stratum():
    """A synthetic run: in each stratum the vehicle rests in one stretch of a tenth of it; a
    window in the middle of the moving part would have no rest at all."""
    t = np.arange(0.0, 3000.0, 0.1)
    rest = (t % 600.0) > 540.0  # the last 60 s of every 600 s at rest
    w = np.where(rest, 0.0, 0.1)  # turning while moving
    run = SimpleNamespace(
        imu=SimpleNamespace(t=t, omega_ib_b=np.column_stack([w * 0, w * 0, w])), t_end=t[-1]
    )
    stationary = SimpleNamespace(mask=lambda s: (np.asarray(s) % 600.0) > 540.0)
    spans = tw.placements(run, stationary, 600.0)
    assert len(spans) == tw.N_LATER
    length = (tw.SPAN_S - tw.FIRST_S) / tw.N_LATER
    edges = np.linspace(600.0, t[-1], tw.N_LATER + 1)
    for (a, b), lo, hi in zip(spans, edges[:-1], edges[1:], strict=True):
        assert b - a == pytest.approx(length) and lo <= a and b <= hi + 1e-9
        sec = np.arange(a, b, 1.0)
        assert 0.0 < np.mean(stationary.mask(sec)) < 1.0  # holds rest and motion


@pytest.fixture(scope="module")
def long_drive():
    run = gnssacc.simulate("car", 1500.0, seed=1)
    return run, prepare(run, load_config(), "none")


def test_a_windowed_pass_scores_each_window_after_its_lead(long_drive):
    run, prep = long_drive
    wins = tw.windows(run, prep.cfg, prep.init, prep.quality, prep.stationary, filter_pass)
    assert len(wins) == 1 + tw.N_LATER
    assert sum(w.t_to - w.t_from for w in wins) == pytest.approx(tw.SPAN_S, abs=1.0)
    cfg = ungated(prep.cfg)
    kw = dict(stationary=prep.stationary, quality=prep.quality, output_times=np.zeros(0))
    got = tw.WindowedPass(wins, filter_pass)(run, cfg, "ekf", init=prep.init, **kw)
    total, n = 0.0, 0
    for w in wins:  # each window alone, its scored updates added up here
        start = prep.init if w.start is None else w.start
        st = filter_pass(
            run, cfg, "ekf", init=start, t_stop=w.t_to, record_innovations=True, **kw
        ).stats
        keep = np.asarray(st["nis_pos_t"]) >= w.t_scored
        total += float(np.asarray(st["loglik_pos_series"])[keep].sum())
        n += int(keep.sum())
        assert st["nis_pos_t"][-1] <= w.t_to + 1e-6
    assert got.stats["n_pos_updates"] == n and got.stats["loglik_pos"] == pytest.approx(total)


def test_a_long_run_is_tuned_on_a_bounded_span_and_confirmed(long_drive, monkeypatch):
    run, prep = long_drive
    spans = []

    def counted(r, cfg, method="ekf", *, init=None, t_stop=None, **kw):
        spans.append(min(r.t_end, r.t_end if t_stop is None else t_stop) - init.t)
        return filter_pass(r, cfg, method, init=init, t_stop=t_stop, **kw)

    got = tw.tuned_on_windows(
        run,
        load_config(),
        prep.stationary,
        prep.quality,
        prep.init,
        prep.rest_noise,
        filter_pass=counted,
    )
    assert got is not None
    cfg, result = got
    info = result.from_stationary["windows"]
    assert info["confirmed"] and info["whole_run_loglik_gain"] >= 0.0
    whole = [s for s in spans if s > 0.9 * run.duration_s]
    assert len(whole) == 3  # the reference pass and the two confirming ones
    assert sum(s for s in spans if s <= 0.9 * run.duration_s) <= tw.SPAN_S * (result.n_evaluations)
    assert result.nis_after == pytest.approx(1.0, abs=0.3)  # the whole run's, as tuned


def test_windows_are_off_by_default(long_drive, monkeypatch):
    monkeypatch.undo()
    run, prep = long_drive
    assert tw.WINDOWED_FROM_S == float("inf")
    assert tw.windows(run, prep.cfg, prep.init, prep.quality, prep.stationary, filter_pass) == []


def test_a_short_run_is_tuned_whole():
    run = gnssacc.simulate("car", 120.0, seed=1)
    prep = prepare(run, load_config(), "none")
    assert (
        tw.tuned_on_windows(
            run, prep.cfg, prep.stationary, prep.quality, prep.init, None, filter_pass=filter_pass
        )
        is None
    )


def test_windows_shared_among_processes_give_the_same_numbers(long_drive, monkeypatch):
    run, prep = long_drive
    wins = tw.windows(run, prep.cfg, prep.init, prep.quality, prep.stationary, filter_pass)
    cfg = ungated(prep.cfg)
    kw = dict(stationary=prep.stationary, quality=prep.quality, output_times=np.zeros(0))
    one = tw.WindowedPass(wins, filter_pass, jobs=1)(run, cfg, "ekf", init=prep.init, **kw)
    shared = tw.WindowedPass(wins, filter_pass, jobs=2)
    try:
        for _ in range(2):  # the workers serve one trial point after another
            two = shared(run, cfg, "ekf", init=prep.init, **kw)
            assert two.stats == one.stats
        assert shared.workers is not None and len(shared.workers) == 1
    finally:
        shared.close()
    # A worker that dies: its windows run here, the same numbers.
    monkeypatch.setattr(tw.WindowedPass, "_serve", lambda self, conn, j, run: os._exit(3))
    dying = tw.WindowedPass(wins, filter_pass, jobs=2)
    try:
        assert dying(run, cfg, "ekf", init=prep.init, **kw).stats == one.stats
        assert dying.workers is None  # no workers more
    finally:
        dying.close()
