"""Wheel odometry in the recording model: the simulator's model against its truth, odom.csv (round
trip, bad input, the IMU clock), bags (read as odometry, never as truth: the truth-candidate rule)."""

from __future__ import annotations

import re
import warnings

import numpy as np
import pytest

from gnssacc.cli import main
from gnssacc.core.config import load_config
from gnssacc.core.errors import DataWarning, InputError
from gnssacc.sources.csvdir import load_csv_run, write_csv_run
from gnssacc.sources.gnss_noise import apply_outages
from gnssacc.sources.sim import simulate
from gnssacc.sources.sim_odometry import (
    NOISE_V_MPS,
    SLIP_STIFFNESS,
    STANDARD_GRAVITY,
    simulate_odometry,
)

pytest.importorskip("rosbags")
from gnssacc.sources.bagwrite import write_bag  # noqa: E402
from gnssacc.sources.rosbag import inspect_bag, load_bag_run  # noqa: E402

# --- the simulator's model ----------------------------------------------------------------------------


def test_odometry_model_against_its_truth():
    """Straight cruising: v_odo / v = 1 + s within the white noise's standard error; accelerating:
    the longitudinal slip a / (C g) on top; the draws are the run's own and leave the IMU alone."""
    t = np.arange(0.0, 200.0, 0.02)
    v = np.full(len(t), 10.0)
    odo, d = simulate_odometry(t, v, np.zeros(len(t)), np.zeros(len(t)), "car", seed=4)
    ratio = np.mean(odo.v_forward) / 10.0 - 1.0
    assert ratio == pytest.approx(d["scale_factor"], abs=4 * NOISE_V_MPS / 10.0 / np.sqrt(len(t)))
    a = np.full(len(t), 3.0)
    acc, d2 = simulate_odometry(t, v, a, np.zeros(len(t)), "car", seed=4)
    slip = np.mean(acc.v_forward) / (10.0 * (1 + d2["scale_factor"])) - 1.0
    assert slip == pytest.approx(
        3.0 / (SLIP_STIFFNESS * STANDARD_GRAVITY), abs=4 * NOISE_V_MPS / 10.0 / np.sqrt(len(t))
    )
    with_odo, plain = simulate("car", 60.0, odom_hz=50.0, seed=3), simulate("car", 60.0, seed=3)
    np.testing.assert_array_equal(with_odo.imu.f_b, plain.imu.f_b)
    np.testing.assert_array_equal(with_odo.gnss.lat, plain.gnss.lat)


def test_skid_steer_slips_in_turns_on_the_spot():
    """A pivot on the spot (true speed 0, 0.5 rad/s for 400 s): the speed error's RMS is the model's
    sqrt(n^2 + (k |w| B / 2)^2), several times the noise alone (a Gauss-Markov error of 0.5 s
    over 400 s: about 400 independent pieces, so 10 % holds with margin); the yaw rate over-reads
    by (1 + s) chi. The UGV scenarios are skid steer, the others cars."""
    from gnssacc.sources.sim_odometry import SKID_TRACK_M, SKID_TURN_SLIP

    t = np.arange(0.0, 400.0, 0.02)
    w = np.full(len(t), 0.5)
    odo, d = simulate_odometry(t, np.zeros(len(t)), np.zeros(len(t)), w, "skid", seed=6)
    expected = np.hypot(NOISE_V_MPS, SKID_TURN_SLIP * 0.5 * SKID_TRACK_M / 2)
    assert np.sqrt(np.mean(odo.v_forward**2)) == pytest.approx(expected, rel=0.1)
    assert expected > 2 * NOISE_V_MPS
    assert np.mean(odo.yaw_rate) / 0.5 == pytest.approx(d["yaw_factor"], rel=1e-3)
    assert 1.3 <= d["chi"] <= 1.9
    car, dc = simulate_odometry(t, np.zeros(len(t)), np.zeros(len(t)), w, "car", seed=6)
    assert (
        np.sqrt(np.mean(car.v_forward**2)) == pytest.approx(NOISE_V_MPS, rel=0.05)
        and dc["chi"] == 1.0
    )
    assert simulate("ugv", 30.0, odom_hz=10.0).sim.odometry["kind"] == "skid"
    assert simulate("car", 30.0, odom_hz=10.0).sim.odometry["kind"] == "car"


# --- the recording model and odom.csv -----------------------------------------------------------------


def test_odometry_carried_through_copies_shifts_and_outages():
    run = simulate("car", 60.0, odom_hz=20.0, seed=1)
    shifted = run.with_imu_shift(0.25)
    np.testing.assert_array_equal(shifted.odometry.t, run.odometry.t + 0.25)
    np.testing.assert_array_equal(shifted.imu.t, run.imu.t + 0.25)
    assert apply_outages(run, [(10.0, 20.0)]).odometry is run.odometry
    assert run.with_gnss(run.gnss).odometry is run.odometry


def test_odom_csv_round_trip_and_the_imu_clock(tmp_path):
    run = simulate("car", 60.0, odom_hz=20.0, seed=1)
    write_csv_run(run, tmp_path)
    back = load_csv_run(tmp_path, load_config())
    for name in ("t", "v_forward", "yaw_rate", "sigma_v", "sigma_yaw_rate"):
        np.testing.assert_array_equal(
            getattr(back.odometry, name), getattr(run.odometry, name)
        )  # %.17g
    cfg = load_config(overrides={"mounting": {"imu_time_offset_s": 0.5}})
    moved = load_csv_run(tmp_path, cfg)
    np.testing.assert_allclose(moved.odometry.t - back.odometry.t, 0.5)
    np.testing.assert_allclose(moved.imu.t - back.imu.t, 0.5)


@pytest.mark.parametrize(
    "text,expect",
    [
        (
            "t,v_forward\n0,1\n0.1,1\n0.2\n0.3,1\n",
            r"odom.csv: line 4 has 1 cells but the header has 2",
        ),
        (
            "t,v_forward\n0,1\n0.1,x\n0.2,1\n",
            r"odom.csv: non-numeric value 'x' in column 'v_forward' at line 3",
        ),
        ("t,speed\n0,1\n0.1,1\n", r"odom.csv: missing required column\(s\) v_forward"),
        (
            "t,v_forward,sigma_v\n0,1,0.1\n0.1,1,0\n",
            r"odom.csv: sigma_v must be positive; not so at t = 0.100000 s",
        ),
    ],
)
def test_bad_odom_csv(tmp_path, capsys, text, expect):
    run = simulate("car", 20.0, seed=1)
    write_csv_run(run, tmp_path / "r")
    (tmp_path / "r" / "odom.csv").write_text(text)
    assert main(["run", str(tmp_path / "r"), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and re.search(expect, err[0]), err


def test_odometry_on_another_clock_is_refused(tmp_path):
    run = simulate("car", 20.0, odom_hz=10.0, seed=1)
    write_csv_run(run, tmp_path)
    text = (tmp_path / "odom.csv").read_text().splitlines()
    rows = [
        ln
        if ln.startswith(("#", "t"))
        else f"{float(ln.split(',')[0]) + 1e6!r}," + ln.split(",", 1)[1]
        for ln in text
    ]
    (tmp_path / "odom.csv").write_text("\n".join(rows) + "\n")
    with pytest.raises(InputError, match="does not overlap the IMU time span"):
        load_csv_run(tmp_path, load_config())


# --- bags: odometry, and the truth-candidate rule ------------------------------------------------------


@pytest.fixture(scope="module")
def ugv():
    return simulate("ugv", 120.0, odom_hz=20.0, truth_rate_hz=10.0, seed=1)


def _load(path, **kw):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", DataWarning)
        run = load_bag_run(path, load_config(), **kw)
    return run, [str(w.message) for w in caught]


def test_wheel_odometry_in_a_local_frame_is_odometry_not_truth(ugv, tmp_path):
    p = write_bag(ugv, tmp_path / "odom", "ros2-sqlite3", odom_topic="/odom")
    run, warned = _load(p)
    assert run.truth is None and run.meta["topics"]["odometry"] == "/odom"
    assert any(
        "/odom is not taken as truth: its pose is in the local frame 'odom'" in w for w in warned
    )
    np.testing.assert_allclose(run.odometry.t, ugv.odometry.t, atol=1e-9)  # ns stamps
    np.testing.assert_array_equal(run.odometry.v_forward, ugv.odometry.v_forward)
    np.testing.assert_allclose(
        run.odometry.yaw_rate, ugv.odometry.yaw_rate, rtol=0, atol=0
    )  # -(-w)
    np.testing.assert_allclose(run.odometry.sigma_v, ugv.odometry.sigma_v)
    assert "base_link" in run.odometry.frame


def test_geo_referenced_truth_and_wheel_odometry_together(ugv, tmp_path):
    p = write_bag(
        ugv,
        tmp_path / "both",
        "ros2-sqlite3",
        odom_topic="/odom",
        truth_topic="/ground_truth",
        truth_type="odometry",
    )
    run, warned = _load(p)
    assert (
        run.meta["topics"]["truth"] == "/ground_truth" and run.meta["topics"]["odometry"] == "/odom"
    )
    check = run.meta["truth_checks"]["/ground_truth"]
    assert check["ok"] and check["ratio"] < 3.0 and check["n"] == len(ugv.gnss)
    np.testing.assert_allclose(run.truth.t, ugv.truth.t, atol=1e-9)
    text = inspect_bag(p)
    assert "truth /ground_truth: geo-referenced and agrees with the fixes" in text
    assert "wheel odometry /odom: the only Odometry/TwistStamped topic" in text
    assert "not truth /odom: its pose is in the local frame 'odom'" in text


def test_a_truth_that_disagrees_is_not_taken_unless_forced(ugv, tmp_path):
    """A frame whose origin is 40 m from the first fix: the fixes (3 m sigmas) sit 40 m from it,
    over 13 sigmas, so it is no truth (and a rigid alignment is not tried); --truth-topic uses it
    all the same, with a warning naming the disagreement."""
    p = write_bag(
        ugv,
        tmp_path / "off",
        "ros2-sqlite3",
        truth_topic="/ground_truth",
        truth_type="odometry",
        truth_offset_enu_m=(40.0, 0.0, 0.0),
    )
    run, warned = _load(p)
    assert run.truth is None
    line = next(w for w in warned if "/ground_truth is not taken as truth" in w)
    assert "disagree with the fixes: 40." in line and "fix sigmas" in line
    forced, warned = _load(p, truth_topic="/ground_truth")
    assert forced.truth is not None and forced.meta["topics"]["truth"] == "/ground_truth"
    assert any(
        w.endswith(line.split("not taken as truth: ")[1])
        and "--truth-topic /ground_truth used as truth although" in w
        for w in warned
    )


def test_truth_in_an_odom_frame_is_refused_even_when_it_agrees(ugv, tmp_path):
    p = write_bag(
        ugv,
        tmp_path / "odomframe",
        "ros2-sqlite3",
        truth_topic="/ground_truth",
        truth_type="odometry",
        truth_frame_id="odom",
    )
    run, warned = _load(p)
    assert run.truth is None
    assert any(
        "/ground_truth is not taken as truth: its pose is in the local frame 'odom'" in w
        for w in warned
    )


def test_odom_topic_option(ugv, tmp_path):
    p = write_bag(ugv, tmp_path / "two", "ros2-sqlite3", odom_topic="/odom", truth_topic="/rtk/fix")
    run, _ = _load(p, gnss_topic="/gnss/fix", odom_topic="/odom")
    assert (
        run.meta["topics"]["odometry"] == "/odom"
        and "wheel odometry /odom: given by --odom-topic" in run.meta["selection"]
    )
    with pytest.raises(
        InputError, match="--odom-topic /gnss/fix has type sensor_msgs/msg/NavSatFix"
    ):
        load_bag_run(p, load_config(), gnss_topic="/gnss/fix", odom_topic="/gnss/fix")
