"""Tuning whose cost does not grow with the recording (:mod:`gnssacc.prepare.tune_windows`): a long
run is identified on windows spanning a fixed number of IMU seconds, placed to keep the run's rests
and turns, their likelihoods those of passes over each window; the whole run confirms the result."""

from __future__ import annotations

import os
from collections import defaultdict
from types import SimpleNamespace

import numpy as np
import pytest

import gnssacc
import gnssacc.prepare.tune_windows as tw
from gnssacc.core.config import load_config
from gnssacc.core.parallel import JOBS_ENV
from gnssacc.core.recording import InitialState
from gnssacc.pipeline import prepare
from gnssacc.prepare.passes import filter_pass
from gnssacc.prepare.tuning import tune, ungated


def test_merged_statistics_add_likelihoods_and_weight_the_means():
    a = {"n_pos_updates": 10, "loglik_pos": -5.0, "nis_pos_mean": 1.0, "acf1_pos": 0.1}
    b = {"n_pos_updates": 30, "loglik_pos": -20.0, "nis_pos_mean": 2.0, "acf1_pos": None}
    m = tw.merged([a, b])
    assert m["n_pos_updates"] == 40 and m["loglik_pos"] == -25.0 and m["loglik"] == -25.0
    assert m["nis_pos_mean"] == pytest.approx((10 * 1.0 + 30 * 2.0) / 40)
    assert m["acf1_pos"] == pytest.approx(0.1)  # only the window that has one
    # b stands for three times its length: its likelihood counts three times, its updates as seen
    w = tw.merged([a, b], [1.0, 3.0])
    assert w["n_pos_updates"] == 40 and w["loglik_pos"] == -65.0
    assert w["nis_pos_mean"] == pytest.approx((10 * 1.0 + 90 * 2.0) / 100)


def test_stratified_windows_estimate_the_whole_runs_likelihood(long_drive):
    """Each later window's weight is its stratum's length over its scored seconds: the windows'
    weighted log-likelihood estimates the whole run's (the car repeats one cycle, so every stratum
    looks alike), where their sum as it is holds only the scored share of it."""
    run, prep = long_drive
    wins = tw.windows(run, prep.cfg, prep.init, prep.quality, prep.stationary, filter_pass)
    t0 = wins[0].t_to
    for w in wins[1:]:
        assert w.weight * (w.t_to - w.t_scored) == pytest.approx((run.t_end - t0) / tw.N_LATER)
    cfg = ungated(prep.cfg)
    kw = dict(stationary=prep.stationary, quality=prep.quality, output_times=np.zeros(0))
    whole = filter_pass(run, cfg, "ekf", init=prep.init, **kw).stats["loglik_pos"]
    got = tw.WindowedPass(wins, filter_pass)(run, cfg, "ekf", init=prep.init, **kw).stats
    assert got["loglik_pos"] == pytest.approx(whole, rel=0.15)
    assert got["n_pos_updates"] < 0.5 * run.duration_s  # while it saw a third of the fixes


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
    for w in wins:  # each window alone, its scored updates added up here (times its weight)
        start = prep.init if w.start is None else w.start
        st = filter_pass(
            run, cfg, "ekf", init=start, t_stop=w.t_to, record_innovations=True, **kw
        ).stats
        keep = np.asarray(st["nis_pos_t"]) >= w.t_scored
        total += w.weight * float(np.asarray(st["loglik_pos_series"])[keep].sum())
        n += int(keep.sum())
        assert st["nis_pos_t"][-1] <= w.t_to + 1e-6
    assert got.stats["n_pos_updates"] == n and got.stats["loglik_pos"] == pytest.approx(total)


@pytest.mark.slow
def test_a_long_run_is_tuned_on_a_bounded_span_and_confirmed(long_drive, monkeypatch):
    run, prep = long_drive
    spans = []
    monkeypatch.setenv(JOBS_ENV, "1")  # every pass in this process, where it is counted

    def counted(r, cfg, method="ekf", *, init=None, t_stop=None, **kw):
        spans.append(min(r.t_end, r.t_end if t_stop is None else t_stop) - init.t)
        return filter_pass(r, cfg, method, init=init, t_stop=t_stop, **kw)

    got = _on_windows(run, prep, counted)
    assert got is not None
    cfg, result = got
    info = result.from_stationary["windows"]
    assert info["confirmed"] and info["whole_run_loglik_gain"] >= 0.0
    line = result.line()  # said on the terminal
    assert "on windows of 600 s of the run's 1500 s, refined and confirmed over the whole" in line
    whole = [s for s in spans if s > 0.9 * run.duration_s]
    # the reference pass (the start), the slow terms' line searches, the confirming one (as tuned)
    refined = info["refined_over_whole_run"]
    assert set(refined) == {f"{s}.{k}" for s, k in tw.REFINED}
    assert len(whole) == 2 + sum(len(r["offsets"]) for r in refined.values())
    for (sec, key), r in zip(tw.REFINED, refined.values(), strict=True):
        assert cfg[sec][key] == pytest.approx(r["windows"] * 10 ** r["d"], rel=1e-3)
    assert sum(s for s in spans if s <= 0.9 * run.duration_s) <= tw.SPAN_S * (result.n_evaluations)
    assert result.nis_after == pytest.approx(1.0, abs=0.3)  # the whole run's, as tuned


@pytest.mark.slow
def test_a_run_up_to_the_threshold_is_tuned_whole_exactly_as_before(monkeypatch):
    """A run no longer than ``WINDOWED_FROM_S`` (with the default threshold) is prepared exactly
    as with the windows off: the same tuned values, likelihoods and passes."""
    run = gnssacc.simulate("car", 300.0, seed=2)
    assert run.duration_s <= tw.WINDOWED_FROM_S
    on = prepare(run, load_config(), "auto").tuning
    monkeypatch.setattr(tw, "WINDOWED_FROM_S", float("inf"))
    off = prepare(run, load_config(), "auto").tuning
    assert "windows" not in on.from_stationary
    assert (on.values, on.loglik_after, on.n_evaluations) == (
        off.values,
        off.loglik_after,
        off.n_evaluations,
    )


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


def test_a_subset_the_whole_run_refutes_is_not_used(long_drive, monkeypatch):
    """A bad subset forced (the windows' search 'finds' the accelerometer noise 100x and the fixes'
    sigma 10x the configured): the two whole-run passes refute it, and the run is tuned whole."""
    import gnssacc.prepare.tuning as tuning

    run, prep = long_drive

    def bad(r, cfg, *args, filter_pass, **kw):
        assert isinstance(filter_pass, tw.WindowedPass)  # the search ran on the windows
        vals = {
            "imu": {"accel_vrw_mps_rth": 100.0 * float(cfg["imu"]["accel_vrw_mps_rth"])},
            "gnss": {"sigma_scale": 10.0 * float(cfg["gnss"]["sigma_scale"])},
        }
        return cfg.with_values(vals, "tuned"), tuning.TuneResult(vals, {}, [])

    monkeypatch.setattr(tuning, "tune", bad)
    got = _on_windows(run, prep, filter_pass)
    assert got is None


def test_trial_points_side_by_side_over_shared_windows_give_the_same_numbers(long_drive):
    """The tuner evaluates trial points in forked processes (``core.parallel.side_by_side``) while
    the windows of a point are shared with the windowed pass's own workers: a forked trial point
    runs its windows itself (the owner's pipes are not shared), so each point gets its own
    numbers, as one after the other."""
    from gnssacc.core.parallel import side_by_side

    run, prep = long_drive
    wins = tw.windows(run, prep.cfg, prep.init, prep.quality, prep.stationary, filter_pass)
    kw = dict(stationary=prep.stationary, quality=prep.quality, output_times=np.zeros(0))
    cfgs = [
        ungated(prep.cfg.with_values({"gnss": {"sigma_scale": s}}, "trial")) for s in (0.5, 2.0)
    ]
    alone = tw.WindowedPass(wins, filter_pass, jobs=1)
    one = [alone(run, c, "ekf", init=prep.init, **kw).stats["loglik"] for c in cfgs]
    shared = tw.WindowedPass(wins, filter_pass, jobs=2)
    try:
        assert shared(run, cfgs[0], "ekf", init=prep.init, **kw).stats["loglik"] == one[0]
        got = side_by_side(
            lambda c: shared(run, c, "ekf", init=prep.init, **kw).stats["loglik"],
            [(c,) for c in cfgs],
            jobs=2,
        )
    finally:
        shared.close()
    assert one[0] != one[1] and got == one


@pytest.mark.slow
def test_the_windows_noise_agrees_with_the_whole_runs_within_its_spread(long_drive):
    """The same long run tuned on windows and over its whole length: the fixes' sigma scale within
    5 % (each estimate's standard error is ~2 %), the gyro and accelerometer white noise within
    three times the scatter of the whole-run estimate between recordings (0.2 and 0.3 decades:
    the 2,400 s car, seeds 0-3, bench/bench_tuning_length.py --accuracy)."""
    run, prep = long_drive
    cfg = load_config()
    args = (run, cfg, prep.stationary, prep.quality, prep.init, prep.rest_noise)
    got = tw.tuned_on_windows(*args, filter_pass=filter_pass)
    assert got is not None
    whole = tune(*args, filter_pass=filter_pass)[1].values
    windowed = got[1].values
    assert windowed["gnss"]["sigma_scale"] == pytest.approx(whole["gnss"]["sigma_scale"], rel=0.05)
    for key, spread in (("gyro_arw_deg_rth", 0.2), ("accel_vrw_mps_rth", 0.3)):
        ratio = np.log10(np.asarray(windowed["imu"][key]) / np.asarray(whole["imu"][key]))
        assert np.all(np.abs(ratio) <= 3.0 * spread), (key, windowed["imu"][key], whole["imu"][key])


def test_a_window_reads_whole_every_span_an_end_would_cut():
    """The span a window's pass reads: its own and MARGIN_S on each side, the acceleration fit's
    last fixes before it, widened to hold whole a stationary span and a suspect IMU span (with its
    local window) that an end cuts, and again for a span the widening reaches."""
    fixes = SimpleNamespace(t=np.arange(0.0, 1000.0, 2.0))
    run = SimpleNamespace(t_start=0.0, t_end=999.99, gnss=fixes, gnss_vel=None)
    cfg = {"accel": {"window": 3}, "quality": {"suspect_local_window_s": 2.0}}
    w = tw.Window(500.0, 530.0, 590.0)
    assert tw.reads(run, w, cfg, None, None) == (492.0, 595.0)  # 4 fixes 2 s apart before it
    rest = SimpleNamespace(spans=[SimpleNamespace(t_start=480.0, t_end=494.0)])
    suspect = SimpleNamespace(
        spans=[
            SimpleNamespace(t_start=477.0, t_end=481.0),
            SimpleNamespace(t_start=594.0, t_end=600.0),
        ]
    )
    assert tw.reads(run, w, cfg, rest, None) == (480.0, 595.0)
    # the rest span reaches the first suspect span (with its 2 s): widened again
    assert tw.reads(run, w, cfg, rest, suspect) == (475.0, 602.0)
    far = SimpleNamespace(spans=[SimpleNamespace(t_start=100.0, t_end=200.0)])
    assert tw.reads(run, w, cfg, far, far) == (492.0, 595.0)


@pytest.mark.parametrize("method", ["ekf", "ekf-acc"])
def test_a_windows_pass_over_the_span_it_reads_gives_the_whole_runs_numbers(long_drive, method):
    """Each window's pass reads its span of the run (its setup costs the span, not the run) and
    gives the numbers of a pass over the whole run (to rounding: running sums start elsewhere),
    here with a suspect IMU span that the first later window's margin would cut: the inflation's
    local sigma must see both sides of it. Cut there, the numbers differ."""
    from dataclasses import replace

    from gnssacc.checks.quality import QualityReport, Span

    run, prep = long_drive
    later = tw.windows(run, prep.cfg, prep.init, prep.quality, prep.stationary, filter_pass)[1]
    i0, i1 = run.imu_range(later.t_from - 7.0, later.t_from + 1.0)
    span = Span("interpolated", run.imu.t[i0], run.imu.t[i1 - 1], i0, i1, "all", "test")
    quality = QualityReport([span], len(run.imu))
    wins = tw.windows(run, prep.cfg, prep.init, quality, prep.stationary, filter_pass)
    assert wins[1].reads[0] <= span.t_start - 2.0  # the local window before the span
    assert all(w.reads[1] - w.reads[0] < 0.5 * run.duration_s for w in wins)
    cfg = ungated(prep.cfg)
    kw = dict(stationary=prep.stationary, quality=quality, output_times=np.zeros(0))
    parts = tw.WindowedPass(wins, filter_pass)
    whole = tw.WindowedPass([replace(w, reads=None) for w in wins], filter_pass)
    for k in range(len(wins)):
        got, _ = parts._window(k, run, cfg, method, prep.init, kw)
        want, _ = whole._window(k, run, cfg, method, prep.init, kw)
        assert got.keys() == want.keys()
        for key, v in want.items():
            if isinstance(v, float):
                assert got[key] == pytest.approx(v, rel=1e-9, abs=1e-12), (k, key)
            elif key not in ("wall_s", "seconds"):
                assert got[key] == v, (k, key)
    short = replace(wins[1], reads=(later.t_from - 5.0, wins[1].reads[1]))
    got, _ = tw.WindowedPass([short], filter_pass)._window(0, run, cfg, method, prep.init, kw)
    want, _ = whole._window(1, run, cfg, method, prep.init, kw)
    assert abs(got["loglik_pos"] - want["loglik_pos"]) > 1e-6 * abs(want["loglik_pos"])


def test_a_pass_over_a_window_makes_the_same_stationary_epochs_as_the_whole_run(long_drive):
    """A pass from t0 to t_stop computes the zero-velocity epochs of the rest spans that reach into
    it only (its cost the window's, not the run's): the same epochs, means, variances and span
    indices as those of the whole run in that time."""
    from gnssacc.estimators.aids import zupt
    from gnssacc.estimators.settings import EkfSettings

    run, prep = long_drive
    settings = EkfSettings.from_config(prep.cfg)
    args = (run, settings.zupt, settings.imu.gyro_psd, prep.stationary)
    whole = zupt.epochs_for(*args)
    t0, t1 = run.t_start + 500.0, run.t_start + 800.0
    part = zupt.epochs_for(*args, t0, t1)
    spans = prep.stationary.spans
    inside = [
        k
        for k in range(len(whole))
        if spans[whole.span[k]].t_end >= t0 and spans[whole.span[k]].t_start <= t1
    ]
    assert 0 < len(part) == len(inside) < len(whole)
    np.testing.assert_array_equal(part.t, whole.t[inside])
    np.testing.assert_array_equal(part.omega_mean_b, whole.omega_mean_b[inside])
    np.testing.assert_array_equal(part.omega_var_b, whole.omega_var_b[inside])
    np.testing.assert_array_equal(part.span, whole.span[inside])
    assert np.any((part.t >= t0) & (part.t <= t1))


@pytest.mark.parametrize("slope", [0.0, 30.0])
def test_the_whole_run_line_search_finds_the_maximum_of_likelihood_and_prior(slope):
    """``refined_whole`` on passes whose log-likelihood is known in closed form, a parabola in the
    log of the accelerometer's bias instability with its peak at 0.05 mg (plus ``slope`` per
    decade): the value maximising it plus the log-normal prior around the tuner's start, found by
    hand; where that lies beyond the offsets searched, the farthest one that way."""
    from gnssacc.prepare.tuning import refined_whole

    run = gnssacc.simulate("car", 120.0, seed=1)
    key = ("imu", "accel_bias_instability_mg")
    cfg = load_config().with_values({"imu": {key[1]: 0.2}}, "the windows' value")

    def known(r, c, method="ekf", *, init=None, **kw):
        x = np.log10(float(c["imu"][key[1]]) / 0.05)
        stats = defaultdict(float, loglik_pos=-8.0 * x * x + slope * x)
        return SimpleNamespace(stats=stats)

    start, width = 0.5, float(cfg["tune"]["prior_decades"])
    init = InitialState(0.0, 0.0, 0.0, 0.0, *np.zeros((2, 3)), *np.ones((3, 3)))
    got, passes, profile = refined_whole(
        run,
        cfg,
        key,
        start,
        (-1.0, -0.5, 0.0, 0.5),
        None,
        None,
        init,
        init_scale=1.0,
        filter_pass=known,
    )
    # d/dx [8 x^2 - slope x + (x - log10(start / 0.05))^2 / (2 width^2)] = 0
    u = np.log10(start / 0.05)
    x = (slope + u / width**2) / (16.0 + 1.0 / width**2)
    x = np.clip(x, np.log10(0.2 / 0.05) - 1.0, np.log10(0.2 / 0.05) + 0.5)
    assert got == pytest.approx(0.05 * 10.0**x, rel=1e-6)
    xs = np.log10(0.2 / 0.05) + np.array([-1.0, -0.5, 0.0, 0.5])  # the points evaluated
    j = 8.0 * xs**2 - slope * xs + 0.5 * ((xs - u) / width) ** 2
    assert passes == 4 and profile["objective"] == pytest.approx(j - j.min())
    assert profile["d"] == pytest.approx(np.log10(got / 0.2))


def _on_windows(run, prep, filter_pass):
    """:func:`tune_windows.tuned_on_windows` of ``run`` from ``prep``'s pieces, default settings."""
    return tw.tuned_on_windows(
        run,
        load_config(),
        prep.stationary,
        prep.quality,
        prep.init,
        prep.rest_noise,
        filter_pass=filter_pass,
    )


def test_a_span_of_a_run_keeps_every_stream_in_it_and_its_quality_spans_point_at_the_same_samples():
    """RecordedRun.between: each stream's samples stamped in the span (the IMU's to the one
    holding at its end), the truth's too; QualityReport.between counts the span's suspect samples
    from its first IMU sample, so they index the same samples of the part as of the whole."""
    from gnssacc.checks.quality import QualityReport, Span

    run = gnssacc.simulate("ugv", 120.0, seed=3, odom_hz=10, velocity=True)
    t_a, t_b = run.t_start + 30.0, run.t_start + 70.005
    part = run.between(t_a, t_b)
    i0, i1 = run.imu_range(t_a, t_b)
    np.testing.assert_array_equal(part.imu.f_b, run.imu.f_b[i0:i1])
    assert part.imu.t[0] >= t_a and part.imu.t[-2] < t_b <= part.imu.t[-1]
    for name in ("gnss", "gnss_vel", "odometry", "truth"):
        whole, got = getattr(run, name).t, getattr(part, name).t
        np.testing.assert_array_equal(got, whole[(whole >= t_a) & (whole <= t_b)])
        assert len(got) > 0
    assert part.init is None and part.sim is None
    j0, j1 = i0 + 500, i0 + 600
    span = Span("frozen", run.imu.t[j0], run.imu.t[j1 - 1], j0, j1, "gx", "test")
    cut = QualityReport([span], len(run.imu)).between(i0, i1)
    assert cut.n_samples == i1 - i0
    (s,) = cut.spans
    np.testing.assert_array_equal(part.imu.t[s.i_start : s.i_end], run.imu.t[j0:j1])
    assert QualityReport([span], len(run.imu)).between(j1, j1 + 10).spans == []
