"""Known-answer tests of gnssacc.analysis.observability and gnssacc.analysis.motion (simulated runs, < 30 s)."""

from __future__ import annotations

import numpy as np
import pytest

from gnssacc.analysis import motion
from gnssacc.analysis import observability as ob
from gnssacc.core.config import load_config
from gnssacc.prepare.passes import run_ekf
from gnssacc.sources.sim import grade_config, simulate

G = 9.80665
GRADE = "industrial"


def _cfg(accel_sigma: float | None = None, nhc: bool = True):
    over = {"imu": grade_config(GRADE), "nhc": {"enabled": nhc}}
    if accel_sigma is not None:
        over["accel"] = {"sigma_mps2": [accel_sigma] * 3}
    return load_config(overrides=over)


@pytest.fixture(scope="module")
def static():
    run = simulate("static", 90.0, GRADE, seed=1, give_init=True)
    cfg = _cfg()
    return run, cfg, ob.replay_ekf(run, cfg, "ekf", with_phi=True)


@pytest.fixture(scope="module")
def turns():
    # 10 s straight at 10 m/s, then full circles of 30 m radius (3.3 m/s^2 centripetal).
    run = simulate("turns", 90.0, GRADE, seed=1, give_init=True)
    cfg = _cfg()
    return run, cfg, ob.replay_ekf(run, cfg, "ekf", with_phi=True)


def test_replay_reproduces_the_filter_covariance(static):
    run, cfg, rp = static
    sol = run_ekf(run, cfg, "ekf", output_times=run.gnss.t, store_P=True)
    P = np.array([e.P_plus for e in rp.epochs])
    assert len(P) == len(sol.P)
    np.testing.assert_allclose(P, sol.P, rtol=1e-9, atol=1e-12)
    # With the acceleration update too.
    sol_a = run_ekf(run, cfg, "ekf-acc", output_times=run.gnss.t, store_P=True)
    rp_a = ob.replay_ekf(run, cfg, "ekf-acc")
    np.testing.assert_allclose(
        np.array([e.P_plus for e in rp_a.epochs]), sol_a.P, rtol=1e-9, atol=1e-12
    )


def test_sigma_history_is_the_solution_sigma(static):
    run, cfg, _ = static
    sol = run_ekf(run, cfg, "ekf")
    sh = ob.sigma_history(sol)
    np.testing.assert_array_equal(sh["yaw"], sol.sigma[:, 8])
    d = sh.as_dict(display_units=True)
    assert set(d) == {"t", *ob.STATE_NAMES}
    np.testing.assert_allclose(d["roll"], np.degrees(sol.sigma[:, 6]))


def test_stationary_heading_unobservable(static):
    run, cfg, rp = static
    sol = run_ekf(run, cfg, "ekf")
    yaw = ob.sigma_history(sol)["yaw"]
    # Heading sigma never shrinks below its start (it grows with the gyro noise / bias).
    assert yaw.min() >= 0.999 * yaw[0]
    assert yaw[-1] > yaw[0]
    for a in (0.0, 30.0, 60.0):
        g = ob.gramian(rp, a, a + 30.0, "pos")
        assert g.degree_of("yaw") < 0.01
        assert g.degree_of("bg_z") < 0.01
        # Position itself is observable.
        assert g.degree_of("pos_n") > 0.4


def test_stationary_tilt_and_accel_bias_inseparable(static):
    _, _, rp = static
    g = ob.gramian(rp, 0.0, 30.0, "pos")
    # Level vehicle: dv_dot = R_nb(-[f_b x] dtheta_b + b_a) with f_b = (0, 0, -g), so
    # g*d_roll + b_a_y and -g*d_pitch + b_a_x are what the position sees: the directions
    # (d_roll = 1, b_a_y = -g) and (d_pitch = 1, b_a_x = +g) are unobservable.
    tilt_y = np.zeros(15)
    tilt_y[ob.state_index("roll")], tilt_y[ob.state_index("ba_y")] = 1.0, -G
    tilt_x = np.zeros(15)
    tilt_x[ob.state_index("pitch")], tilt_x[ob.state_index("ba_x")] = 1.0, G
    weak = 1e-3  # eigenvalues of S W S: < 1e-3 of the prior information
    assert np.sum(g.eigvals < weak) == 4  # two tilt/bias directions, yaw and the vertical gyro bias
    assert g.subspace_projection(tilt_y, weak) > 0.999
    assert g.subspace_projection(tilt_x, weak) > 0.999
    # The window carries (almost) no information about them; about each state alone, or the
    # combination with the wrong sign, it carries a lot.
    # (measured: 0.0098 and 0.0064 against 4263 for roll alone, 352 for b_a_y alone, 1297 for
    # the wrong-sign combination).
    assert g.information(tilt_y) < 0.05 and g.information(tilt_x) < 0.05
    wrong = tilt_y.copy()
    wrong[ob.state_index("ba_y")] = G
    assert g.information(wrong) > 1e4 * g.information(tilt_y)
    for name in ("roll", "pitch", "ba_x", "ba_y"):
        e = np.zeros(15)
        e[ob.state_index(name)] = 1.0
        assert g.information(e) > 1e4 * max(g.information(tilt_x), g.information(tilt_y)), name
    # The weakest eigenvector itself combines tilt and horizontal accelerometer bias.
    v = g.eigvecs[:, 0]
    tilt_share = np.sum(v[6:8] ** 2)
    bias_share = np.sum(v[9:11] ** 2)
    assert tilt_share > 0.01 and bias_share > 0.5 and tilt_share + bias_share > 0.95


def test_turning_makes_heading_observable(static, turns):
    run, cfg, rp = turns
    sol = run_ekf(run, cfg, "ekf")
    yaw = ob.sigma_history(sol)["yaw"]
    assert yaw[-1] < 0.7 * yaw[0]
    straight = ob.gramian(rp, 0.0, 10.0, "pos")  # the straight segment before the circles
    turning = ob.gramian(rp, 30.0, 60.0, "pos")
    static_deg = ob.gramian(static[2], 30.0, 60.0, "pos").degree_of("yaw")
    assert straight.degree_of("yaw") < 0.05
    assert turning.degree_of("yaw") > 0.5
    assert turning.degree_of("yaw") > 100 * static_deg
    sl = ob.sliding_gramian(rp, 10.0, 5.0, "pos")
    assert sl["yaw"][0] < 0.01 and sl["yaw"].max() > 0.2


def test_acceleration_update_adds_tilt_and_bias_information():
    # Straight line at constant speed (mild motion), acceleration sigma 0.05 m/s^2; the paper's
    # model (the non-holonomic constraint off: it holds tilt and the lateral/vertical
    # accelerometer bias itself, and the acceleration's share shrinks).
    run = simulate("straight", 60.0, GRADE, seed=1, give_init=True)
    rp = ob.replay_ekf(run, _cfg(accel_sigma=0.05, nhc=False), "ekf", with_phi=True)
    ai = ob.aiding_information(rp)
    assert ai.has_acc.sum() >= 55
    cum = ai.cumulative()
    for name in ("roll", "pitch", "ba_x", "ba_y"):
        i = ob.state_index(name)
        assert cum["pos_acc"][-1, i] > 3.0 * cum["pos"][-1, i]
        assert np.all(ai.drop_acc_extra[ai.has_acc, i] >= -1e-15)
    g_p = ob.gramian(rp, 0.0, 30.0, "pos")
    g_pa = ob.gramian(rp, 0.0, 30.0, "pos+acc")
    assert g_pa.n_acc > 0 and g_p.n_acc == 0
    for name in ("roll", "pitch", "yaw", "ba_z"):
        assert g_pa.degree_of(name) > g_p.degree_of(name)
    # Information only adds: W(pos+acc) - W(pos) is positive semi-definite.
    assert np.linalg.eigvalsh(g_pa.W_bar - g_p.W_bar).min() > -1e-9


def test_consistency_with_truth(turns):
    run, cfg, _ = turns
    sol = run_ekf(run, cfg, "ekf")
    err = ob.state_errors(run, sol)
    assert np.all(np.isfinite(err))  # the simulator gives position, velocity, attitude and biases
    c = ob.consistency(run, sol, t_min=sol.t[0] + 10.0)
    for name in ("pos_n", "pos_e", "vel_n", "vel_e", "roll", "pitch", "yaw"):
        i = ob.state_index(name)
        assert c.within_3sigma[i] > 0.9, (name, c.within_3sigma[i])
    assert len(c.rows()) == 15


def test_motion_classifier_matches_the_simulated_segments():
    run = simulate("ugv", 240.0, GRADE, seed=0)
    sol = run_ekf(run, _cfg(), "ekf")
    mc = motion.classify_motion(run, sol)
    ref = motion.labels_from_segments(run.sim.segments, mc.t)
    # Away from the 1-s ramps at segment ends and the first seconds of the filter.
    m = motion.segment_interior(run.sim.segments, mc.t, 1.5) & (mc.t > sol.t[0] + 5.0)
    agree = np.mean(ref[m] == mc.label[m])
    assert agree > 0.97, agree
    for code in range(4):
        sel = m & (ref == code)
        assert sel.sum() > 100
        assert np.mean(mc.label[sel] == code) > 0.85, (
            motion.LABELS[code],
            np.mean(mc.label[sel] == code),
        )
    spans = mc.spans()
    assert spans[0][0] == mc.t[0] and {s[2] for s in spans} == set(motion.LABELS)


def test_the_report_classifies_motion_with_the_runs_own_stationary_spans(tmp_path):
    """The report's motion context uses the spans the estimators stood still in (the run's
    configuration: here the antenna's lever arm), not a detection of its own without it. A UGV
    with an antenna 1.2 m from the IMU pivots next to its stops; detected without the lever arm,
    the swing refuses stops (the report said 9 % stationary, the truth 20 %: at rest and not
    turning). The detector trims each span's edges, so the report's share is held to 70 % of the
    truth's at least."""
    import re

    from gnssacc.api import process
    from gnssacc.outputs.outdir import ResultDir

    lever = [1.0, 0.5, -1.0]
    run = simulate("ugv", 300.0, GRADE, noise="rtk", seed=0, lever_arm_b=tuple(lever))
    res = process(run, methods=["ekf"], tune="none", config={"gnss": {"lever_arm_b_m": lever}})
    with ResultDir(tmp_path / "out") as target:
        folder = res.write(target, plots=False, report=True)
    page = (folder / "report.html").read_text()
    share = float(re.search(r"<tr><td>stationary</td><td>([0-9.]+)</td>", page).group(1))
    truth, sol = res.run.truth, res.solutions["ekf"]
    speed = np.hypot(truth.v_n[:, 0], truth.v_n[:, 1])
    yaw_rate = np.degrees(np.gradient(np.unwrap(truth.rpy[:, 2]), truth.t))
    inside = (truth.t >= sol.t[0]) & (truth.t <= sol.t[-1])
    still = 100.0 * np.mean(((speed < 0.05) & (np.abs(yaw_rate) < 3.0))[inside])
    assert 0.7 * still <= share <= still, (share, still)
