"""What the estimator proves, the tool applies (issue 32), on simulated runs with known truth.

* A sideways IMU without tf in a ROS 1 and a ROS 2 bag runs by default with the mounting applied
  and stated, as accurate as the same bag mounted right (an upside-down CSV run: in
  ``test_plausibility.py``, through the command line, with the header line).
* One clock: IMU, truth and odometry stamped GPS time on the UNIX epoch beside a GPST ``.pos``
  run by default, the truth and the odometry moved with the IMU's correction.
* The truth checked against the fixes after the corrections: shifted in time or offset in
  position, it is reported and not scored.
* Ambiguity is refused naming both readings; what the motion cannot prove is said, not guessed.
"""

from __future__ import annotations

import warnings
from dataclasses import replace

import numpy as np
import pytest

import gnssacc
from gnssacc.core.config import load_config
from gnssacc.core.errors import DataWarning, InputError
from gnssacc.core.recording import ImuData
from gnssacc.pipeline import check_input, prepare
from gnssacc.sources.csvdir import write_csv_run
from gnssacc.sources.sim import simulate

#: A moment on the UNIX clock in 2024, when GPS time ran 18 s ahead of UTC [s].
UNIX_2024 = 1709294400.0
LEAP_2024_S = 18.0


def _prmse(res) -> dict:
    return {m: res.metrics["methods"][m]["prmse_m"] for m in ("ekf", "smoother")}


@pytest.fixture(scope="module")
def robot():
    """A skid-steer robot: consumer IMU at 30 Hz, 2.5 Hz precise fixes, wheel odometry."""
    return simulate(
        "ugv",
        150.0,
        imu_grade="consumer",
        imu_rate_hz=30.0,
        gnss_rate_hz=2.5,
        noise="precise",
        seed=4,
        odom_hz=10.0,
    )


@pytest.mark.parametrize("kind", ["ros1-rooad", "ros2-sqlite3"])
@pytest.mark.slow
def test_sideways_imu_bag_without_tf_is_mounted_by_default(kind, robot, tmp_path):
    pytest.importorskip("rosbags")
    from gnssacc.sources.bagwrite import write_bag

    got = {}
    for name, mount in (("sideways", (90.0, 0.0, 90.0)), ("mounted", (0.0, 0.0, 0.0))):
        path = tmp_path / (name + (".bag" if kind.startswith("ros1") else ""))
        write_bag(robot, path, kind, imu_mount_rpy_deg=mount, odom_topic="/odom", write_tf=False)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            res = gnssacc.process(
                replace(gnssacc.load(str(path)), truth=robot.truth), methods=["ekf", "smoother"]
            )
        stated = [str(w.message) for w in caught if issubclass(w.category, DataWarning)]
        got[name] = (_prmse(res), res.metrics["input_corrections"]["applied"], stated)
    (applied,) = got["sideways"][1]
    assert applied["check"] == "mounting"
    assert applied["correction"] == "imu_to_body_rpy_deg = [90, 0, 90]"
    assert "log-likelihood" in applied["evidence"]
    assert any("[90, 0, 90]" in t and "as the estimator proves" in t for t in got["sideways"][2])
    assert got["mounted"][1] == []
    for m, value in got["mounted"][0].items():
        assert got["sideways"][0][m] == pytest.approx(value, rel=0.05), (m, got)


def _on_gps_time(run, leap_s: float):
    """The run as a logger stamping GPS time on the UNIX epoch records it: the IMU, the truth
    and the odometry ``leap_s`` ahead of the fixes (which stay on UTC)."""
    return replace(
        run,
        imu=ImuData(run.imu.t + leap_s, run.imu.f_b, run.imu.omega_ib_b),
        truth=replace(run.truth, t=run.truth.t + leap_s),
        odometry=run.odometry.shifted(leap_s),
    )


@pytest.mark.slow
def test_imu_truth_and_odometry_on_gps_time_beside_a_gpst_pos(tmp_path):
    """Acceptance: a CSV run whose IMU, truth and odometry are GPS time on the UNIX epoch, beside
    its receiver's GPST .pos: it runs by default, the clock offset is the leap seconds to the
    millisecond, the raw fixes' row against the truth is within 10 % of the simulated fix noise,
    and the estimators' PRMSE within 5 % of the same run with consistent clocks."""
    run = simulate(
        "car", 120.0, imu_grade="consumer", noise="white", seed=1, odom_hz=10.0, t_start_s=UNIX_2024
    )
    consistent = write_csv_run(run, tmp_path / "utc", gnss_format="pos")
    gps = write_csv_run(_on_gps_time(run, LEAP_2024_S), tmp_path / "gps", gnss_format="pos")
    ref = gnssacc.process(str(consistent), methods=["ekf", "smoother"])
    res = gnssacc.process(str(gps), methods=["ekf", "smoother"])
    (applied,) = res.metrics["input_corrections"]["applied"]
    assert applied["check"] == "time_offset", applied
    assert abs(res.prepared.cfg["mounting"]["imu_time_offset_s"] + LEAP_2024_S) < 1e-3
    # Every stream on the IMU's clock moved with it; the fixes kept theirs.
    np.testing.assert_allclose(res.run.truth.t, ref.run.truth.t, atol=1e-3)
    np.testing.assert_allclose(res.run.odometry.t, ref.run.odometry.t, atol=1e-3)
    np.testing.assert_allclose(res.run.gnss.t, ref.run.gnss.t, atol=0)
    # The raw fixes against the truth: the simulated fix noise, as the consistent run scores it.
    g, o = run.gnss, run.origin
    tr = run.truth
    truth_at = np.column_stack(
        [np.interp(g.t, tr.t, x) for x in (o.to_ned(tr.lat, tr.lon, tr.h)).T]
    )
    noise_rms = float(np.sqrt(np.mean(np.sum((o.to_ned(g.lat, g.lon, g.h) - truth_at) ** 2, 1))))
    assert res.metrics["gnss_prmse_m"] == pytest.approx(noise_rms, rel=0.10)
    for m, value in _prmse(ref).items():
        assert _prmse(res)[m] == pytest.approx(value, rel=0.05), (m, _prmse(res), _prmse(ref))


@pytest.fixture(scope="module")
def car():
    """A car at 10-20 m/s (industrial IMU, 3 m fixes)."""
    return simulate("car", 120.0, imu_grade="industrial", noise="white", seed=2)


def _moved(run, north_m: float = 0.0, late_s: float = 0.0):
    """The run's truth ``north_m`` further north and ``late_s`` later."""
    tr, o = run.truth, run.origin
    lat, lon, h = o.to_llh(o.to_ned(tr.lat, tr.lon, tr.h) + np.array([north_m, 0.0, 0.0]))
    return replace(run, truth=replace(tr, t=tr.t + late_s, lat=lat, lon=lon, h=h))


@pytest.mark.parametrize(
    "north_m, late_s, says", [(0.0, 5.0, "shifted by -5.0"), (50.0, 0.0, "+49.4 m north")]
)
def test_a_truth_that_disagrees_with_the_fixes_is_reported_and_not_scored(
    car, north_m, late_s, says
):
    """On a moving car a truth 5 s late (70 m behind) or 50 m north is said, with what would make
    it agree, and not scored; the estimates still run."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = gnssacc.process(_moved(car, north_m, late_s), methods=["ekf"], tune="none")
    texts = [str(w.message) for w in caught if issubclass(w.category, DataWarning)]
    why = res.metrics["input_corrections"]["truth_not_scored"]
    assert why and "disagrees with the GNSS fixes" in why and says in why, why
    assert any(why in t for t in texts)
    assert res.metrics["methods"]["ekf"]["prmse_m"] is None and res.run.truth is None
    assert "truth not scored: the truth disagrees" in res.table()


def test_a_truth_offset_is_caught_on_a_parked_vehicle():
    """Parked, a clock error cannot show, an offset in position does."""
    static = simulate("static", 60.0, imu_grade="industrial", noise="white", seed=2)
    out, _, findings = check_input(_moved(static, late_s=5.0), load_config())
    assert out.truth is not None and [f for f in findings if f.check == "truth"] == []
    out, _, findings = check_input(_moved(static, north_m=50.0), load_config())
    (f,) = [f for f in findings if f.check == "truth"]
    assert out.truth is None and f.action == "not scored" and "+50.0 m north" in f.problem


def test_clean_truths_agree(car):
    """Truth and fixes on one clock and place: kept, nothing said (also every clean case of the
    false-alarm test)."""
    out, _, findings = check_input(car, load_config())
    assert out.truth is car.truth and [f for f in findings if f.check == "truth"] == []


def test_a_truth_is_not_held_against_sigmas_the_fixes_never_stated():
    """A rover's receiver-filtered 10 Hz fixes state no sigma: their scatter (4 cm) stands in
    for it in the estimators, but their errors wander by 0.6 m; the truth is judged by the
    configured default for such fixes, and kept (it was taken for 16 fix sigmas off)."""
    run = simulate(
        "rover", 120.0, imu_grade="consumer", gnss_rate_hz=10.0, noise="filtered", seed=2
    )
    run = run.with_gnss(replace(run.gnss, sigma_stated=False))
    prep = prepare(run, load_config(), tune="none")
    assert prep.run.gnss.sigma_ned[0, 0] < 0.1  # the scatter, for the estimators
    assert prep.run.truth is not None and [f for f in prep.checks if f.check == "truth"] == []


@pytest.mark.parametrize("scenario, alternatives", [("straight", 1), ("static", 3)])
def test_an_upside_down_imu_whose_forward_axis_the_motion_never_shows_is_refused(
    scenario, alternatives
):
    """Upside down is proven, but without turns the data cannot tell which horizontal axis points
    forward: refused naming every reading, whatever the policy (never guessed)."""
    run = simulate(scenario, 60.0, imu_grade="industrial", noise="white", seed=3)
    R = np.diag([1.0, -1.0, -1.0])
    flipped = replace(run, imu=ImuData(run.imu.t, run.imu.f_b @ R.T, run.imu.omega_ib_b @ R.T))
    for policy in ("apply", "refuse"):
        with pytest.raises(InputError) as exc:
            check_input(flipped, load_config(overrides={"checks": {"on_proof": policy}}))
        problem = exc.value.problem
        assert "cannot tell imu_to_body_rpy_deg = [" in problem and "not guessed" in problem
        assert problem.count("imu_to_body_rpy_deg = [180, 0, ") == 1 + alternatives, problem


def test_a_clock_offset_the_motion_cannot_prove_is_said_how_large_it_could_be():
    """A slow UGV with 3 m fixes: a 1 s offset is not proven (the data are used as given), and
    the run says that an offset of that size could go unseen."""
    run = simulate("ugv-slow", 240.0, imu_grade="industrial", noise="white", seed=0)
    late = replace(run, imu=ImuData(run.imu.t - 1.0, run.imu.f_b, run.imu.omega_ib_b))
    prep = prepare(late, load_config(), tune="none")
    assert prep.cfg["mounting"]["imu_time_offset_s"] == 0.0 and prep.run.imu.t[0] == late.imu.t[0]
    (bound,) = [f for f in prep.checks if f.action == "bound"]
    assert bound.details["unseen_s"] >= 1.0 and "could go unseen" in bound.problem


def test_a_one_second_offset_on_a_slow_ugv_is_proven_where_the_fixes_allow():
    """The same slow UGV with 0.5 m fixes: the 1 s offset is proven and applied by default,
    within three of its sigmas."""
    run = simulate("ugv-slow", 240.0, imu_grade="industrial", noise="precise", seed=0)
    late = replace(run, imu=ImuData(run.imu.t - 1.0, run.imu.f_b, run.imu.omega_ib_b))
    out, cfg, findings = check_input(late, load_config())
    (f,) = [f for f in findings if f.check == "time_offset"]
    assert f.action == "applied"
    assert abs(cfg["mounting"]["imu_time_offset_s"] - 1.0) <= 3.0 * f.details["sigma_s"]


def test_a_small_clock_offset_is_proven_where_the_fixes_allow():
    """5 cm fixes on a car: 0.1 s is proven and applied ("auto"), to a few milliseconds."""
    run = simulate("car", 120.0, imu_grade="industrial", noise="none", seed=1)
    g, rng = run.gnss, np.random.default_rng(0)
    p = run.origin.to_ned(g.lat, g.lon, g.h) + rng.normal(0.0, 0.05, (len(g), 3))
    lat, lon, h = run.origin.to_llh(p)
    rtk = replace(run, gnss=replace(g, lat=lat, lon=lon, h=h, sigma_ned=np.full((len(g), 3), 0.05)))
    late = replace(rtk, imu=ImuData(rtk.imu.t - 0.1, rtk.imu.f_b, rtk.imu.omega_ib_b))
    cfg = load_config(overrides={"mounting": {"imu_time_offset_s": "auto"}})
    prep = prepare(late, cfg, tune="none")
    assert abs(prep.cfg["mounting"]["imu_time_offset_s"] - 0.1) < 0.01
    (bound,) = [f for f in prep.checks if f.action == "bound"]
    assert bound.details["unseen_s"] < 0.1


@pytest.mark.slow
def test_the_readme_example_prints_no_warning():
    """KITTI seed 3: its clock proposal (0.09 s) is not proven; recorded, not warned of."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = gnssacc.process("kitti", methods=["ekf", "ekf-acc"], seed=3)
    assert [str(w.message) for w in caught if issubclass(w.category, DataWarning)] == []
    left = res.metrics["input_corrections"]["not_applied"]
    assert [e["check"] for e in left] == ["time_offset"] and left[0]["evidence"]
