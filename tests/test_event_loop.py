"""The EKF's compiled event loop against the Python loop it stands in for: a simulated pass run
both ways gives the same statistics and the same trajectory (a tuner's pass: no outputs, the
covariance every tenth sample; a method's pass: outputs and their covariances), with the fixes,
the Doppler velocities, the constraint, the wheel odometry and the stationary updates in the
compiled loop, and the events each loop ran counted so that the comparison cannot pass by running
the Python loop twice."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from gnssacc import pipeline
from gnssacc.core.config import load_config
from gnssacc.estimators import ekf, event_loop, kernels
from gnssacc.sources.sim import simulate

#: Figures of a pass compared (the NIS and log-likelihood per kind, the decisions' counts).
KEYS = ("loglik", "loglik_pos", "loglik_nhc", "nis_pos_mean", "nis_nhc_mean", "acf1_pos")
KEYS += ("loglik_vel", "nis_vel_mean", "acf1_vel", "loglik_zupt", "loglik_zaru", "nis_zaru_mean")
KEYS += ("loglik_odo", "nis_odo_mean", "odometry_scale", "odometry_scale_sigma")


@pytest.fixture(scope="module")
def prepared():
    """A skid-steer vehicle with stops and turns on the spot, fixes and Doppler velocities with a
    lever arm and the Gauss-Markov fix error, wheel odometry (its scale-factor state), the
    constraint with a reference point off the IMU and a mounting rotation; prepared without
    tuning."""
    cfg = load_config(
        overrides={
            "gnss": {"lever_arm_b_m": [0.4, -0.2, -1.1], "gm_sigma_m": 0.5, "gm_tau_s": 60.0},
            "nhc": {
                "pitch_offset_deg": 1.0,
                "yaw_offset_deg": -0.5,
                "lever_arm_b_m": [-0.3, 0.1, 0.4],
            },
        }
    )
    run = simulate(
        "ugv",
        180.0,
        imu_grade="industrial",
        seed=4,
        lever_arm_b=(0.4, -0.2, -1.1),
        velocity=True,
        odom_hz=10.0,
    )
    return pipeline.prepare(run, cfg, tune="none"), cfg


def _pass(prepared, compiled: bool, monkeypatch, **options):
    """The pass with the compiled loop or the Python loop; the events the compiled one ran, and
    the update events (not outputs, not past the pass's end) the Python loop ran."""
    prep, cfg = prepared
    ran, in_python = [], []
    run_stretch, step = event_loop.run_stretch, ekf._EventLoop.step

    def counted(e, *args):
        out = run_stretch(e, *args)
        ran.append(out[0] - e)
        return out

    def counted_step(loop, e):
        in_python.append(loop.ev_src[e] < len(loop.aids) and loop.ev_t[e] <= loop.t_end)
        return step(loop, e)

    monkeypatch.setattr(event_loop, "run_stretch", counted)
    monkeypatch.setattr(ekf._EventLoop, "step", counted_step)
    monkeypatch.setattr(ekf, "COMPILED_LOOP", compiled)
    sol = ekf.estimate(prep, cfg, "ekf", **options)
    return sol, sum(ran), sum(in_python)


def _assert_same(a, b) -> None:
    for key in KEYS:
        if a.stats.get(key) is None:  # an aid the pass does not have
            assert b.stats.get(key) is None, key
            continue
        assert a.stats[key] == pytest.approx(b.stats[key], rel=1e-12, abs=1e-12), key
    for key, v in a.stats.items():
        if key.startswith("n_"):
            assert v == b.stats[key], key
    for x, y in ((a.lat, b.lat), (a.lon, b.lon), (a.h, b.h), (a.v_n, b.v_n), (a.rpy, b.rpy)):
        assert np.allclose(x, y, rtol=1e-12, atol=1e-12)
    assert np.allclose(a.sigma, b.sigma, rtol=1e-12, atol=1e-15)


def test_tuner_pass_compiled_equals_python_loop(prepared, monkeypatch):
    """No outputs, the covariance every tenth sample: every update event runs in the compiled loop
    (none in Python), with the same figures as the Python loop."""
    opts = {"output_times": np.zeros(0), "cov_every": 10}
    fast, n_compiled, n_python = _pass(prepared, True, monkeypatch, **opts)
    ref, n_none, n_ref = _pass(prepared, False, monkeypatch, **opts)
    assert n_none == 0 and n_python == 0 and n_compiled == n_ref > 500
    assert fast.stats["n_pos_updates"] > 150 and fast.stats["n_nhc_updates"] > 50
    assert fast.stats["n_nhc_skipped_turn"] > 0 and fast.stats["n_nhc_skipped_rest"] > 0
    assert fast.stats["n_vel_updates"] > 150 and fast.stats["n_zupt_updates"] > 10
    assert fast.stats["n_zaru_updates"] == fast.stats["n_zupt_updates"]
    assert fast.stats["n_odo_updates"] > 500
    _assert_same(fast, ref)


def test_method_pass_with_outputs_compiled_equals_python_loop(prepared, monkeypatch):
    """The default outputs with their covariances and the covariance at every sample, stopped
    before the end: the same trajectory, covariances and figures both ways."""
    prep = prepared[0]
    opts = {"t_stop": float(prep.run.t_end) - 20.0, "record_innovations": True, "store_P": True}
    fast, n_compiled, n_python = _pass(prepared, True, monkeypatch, **opts)
    ref, _, _ = _pass(prepared, False, monkeypatch, **opts)
    assert n_compiled > 600 and n_python == 0 and len(fast.t) == len(ref.t) > 100
    assert fast.stats["n_vel_updates"] > 150 and fast.stats["n_zupt_updates"] > 10
    for kind in ("pos", "vel", "zupt", "zaru", "nhc", "odo"):  # every update, to the last bit
        assert np.array_equal(fast.stats[f"nis_{kind}"], ref.stats[f"nis_{kind}"]), kind
    assert np.allclose(fast.P, ref.P, rtol=1e-12, atol=1e-18)
    _assert_same(fast, ref)


def test_velocities_whose_measured_axes_change_run_in_python_with_the_same_figures(monkeypatch):
    """Doppler velocities with the vertical missing at every other epoch: the velocity's step is
    the Python loop's (its degrees of freedom change), the pass runs both ways to the same
    figures, and its innovations' lag-1 sums pair each update with the last of the same axes
    (this crashed)."""
    run = simulate("car", 60.0, imu_grade="industrial", seed=1, velocity=True)
    v = run.gnss_vel.v_ned.copy()
    v[::2, 2] = np.nan
    run = replace(run, gnss_vel=replace(run.gnss_vel, v_ned=v))
    cfg = load_config()
    prep = pipeline.prepare(run, cfg, tune="none")
    opts = {"output_times": np.zeros(0), "cov_every": 10}
    fast, n_compiled, n_python = _pass((prep, cfg), True, monkeypatch, **opts)
    ref, _, _ = _pass((prep, cfg), False, monkeypatch, **opts)
    n_vel = fast.stats["n_vel_updates"]
    assert n_compiled > 0 and n_python == n_vel > 50
    assert ref.stats["n_vel_updates"] == n_vel and fast.stats["acf1_vel"] is not None
    _assert_same(fast, ref)


def test_a_pass_uses_the_python_loop_until_the_loop_kernel_is_loaded(prepared, monkeypatch):
    """Left to the background compilation (``COMPILED_LOOP`` unset), a pass runs in Python while
    the loop's group is not loaded, and in the compiled loop once it is, which the background
    says for the groups it has loaded."""
    prep, cfg = prepared
    ran = []
    run_stretch = event_loop.run_stretch
    monkeypatch.setattr(event_loop, "run_stretch", lambda *a: ran.append(1) or run_stretch(*a))
    opts = {"output_times": np.zeros(0), "cov_every": 10, "t_stop": float(prep.init.t) + 30.0}
    for loaded, calls in ((False, 0), (True, 1)):
        monkeypatch.setattr(kernels, "loaded", lambda group, yes=loaded: yes and group == "loop")
        ran.clear()
        ekf.estimate(prep, cfg, "ekf", **opts)
        assert (len(ran) > 0) == bool(calls)
    background = kernels.BackgroundWarmUp(("loop",), notice=None, processes=False).start()
    background.wait_all()
    assert {"propagation", "update", "loop"} <= background.loaded


@pytest.mark.parametrize("keep", [False, True])
def test_a_tally_of_updates_at_once_equals_one_by_one(keep):
    """:meth:`Tally.add_updates` (a compiled stretch's updates per kind) against
    :meth:`Tally.add_update` one by one: the same figures to the last bit, the rejected updates
    left out of the sums and the lag-1 products carried from one stretch into the next."""
    from gnssacc.estimators.ekf_record import Tally, innovation_loglik

    rng = np.random.default_rng(7)
    m, dof = 400, 3
    t = np.cumsum(rng.uniform(0.5, 1.5, m))
    nis = rng.chisquare(dof, m) * rng.uniform(0.5, 10.0, m)
    logdet = rng.normal(2.0, 3.0, m)
    used = rng.uniform(size=m) > 0.1
    wz = rng.standard_normal((m, dof))
    one, batch = Tally(keep), Tally(keep)
    for i in range(m):
        loglik = innovation_loglik(float(nis[i]), float(logdet[i]), dof)
        one.add_update(float(t[i]), "pos", dof, float(nis[i]), loglik, bool(used[i]), wz[i])
    for a, b in ((0, 1), (1, 150), (150, 151), (151, m)):  # stretches, one of a single update
        batch.add_updates("pos", dof, t[a:b], nis[a:b], logdet[a:b], used[a:b], wz[a:b])
    s1, s2 = one.stats(), batch.stats()
    assert s1["n_pos_rejected"] > 10 and s1["n_pos_beyond"] > 10 and s1["acf1_pos"] != 0
    for key, v in s1.items():
        if isinstance(v, np.ndarray):
            assert np.array_equal(v, s2[key]), key
        else:
            assert v == s2[key], key
