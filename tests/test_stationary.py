"""Stationary detection: simulated runs with a vibrating consumer IMU, and real recordings.

The simulated truth (speed, yaw rate, hold segments) comes from ``gnssacc.sources.sim``; the IMU
errors are added here, independently of the package: white noise at consumer densities, turn-on
biases (0.17 deg/s on gyro z), and idle-engine vibration at the level of a real parked car
(gyro x/y scatter ~2.4 deg/s, accelerometers 0.5-1 m/s^2 per sample): a 27 Hz fundamental with
two harmonics, integrated over each sample interval as an IMU does, plus zero-mean broadband
vibration. "Driving texture" (slow steering/throttle/terrain fluctuations that grow with speed)
is added where a test says so; without it a constant-speed stretch is IMU-still, the worst case.

Real data (``../shared/data``, skipped when absent) and the KITTI sequence in the gtsam wheel:
the expected figures come from the data documentation (static logs, a highway minute) and the
KITTI truth positions.
"""

from __future__ import annotations

import csv
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from gnssacc.core.earth import LocalTangentFrame
from gnssacc.core.errors import InputError
from gnssacc.core.recording import GnssFixes, ImuData, RecordedRun
from gnssacc.prepare.stationary import (
    StationaryParams,
    StationaryReport,
    detect_stationary,
    imu_still_stretches,
    noise_from_stationary,
    params_from_config,
)
from gnssacc.sources import sim
from gnssacc.core.units import DEG

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
#: Consumer white noise: 0.2 m/s/sqrt(h) and 0.6 deg/sqrt(h) as densities [m/s^2/sqrt(Hz)], [rad/s/sqrt(Hz)].
NA, NG = 0.2 / 60.0, 0.6 / 60.0 * DEG
#: Turn-on biases, accelerometers [m/s^2] then gyros [rad/s] (gyro z: the 600 deg/h of the brief).
BIAS = np.array([0.05, -0.08, 0.10, 0.05 * DEG, -0.08 * DEG, 0.17 * DEG])


# --- simulated IMU errors ------------------------------------------------------------------------


def _vibration(t: np.ndarray, dt: float, rng) -> np.ndarray:
    """Idle-engine vibration (n, 6): 27/54/81 Hz harmonics as interval means, plus broadband."""
    peak = np.array([0.7, 0.7, 1.0, 3.4 * DEG, 3.4 * DEG, 0.8 * DEG])  # fundamental, per channel
    out = np.zeros((len(t), 6))
    for order, share in ((1, 1.0), (2, 0.6), (3, 0.35)):
        w = 2.0 * np.pi * 27.0 * order
        ph = rng.uniform(0.0, 2.0 * np.pi, 6)
        out += (
            share
            * peak
            * (np.cos(w * (t[:, None] - dt) + ph) - np.cos(w * t[:, None] + ph))
            / (w * dt)
        )
    # Broadband: the second difference of white noise has zero mean over any block (a shaking
    # mount does not drift away), like real vibration.
    e = rng.standard_normal((len(t) + 2, 6))
    rms = np.array([0.2, 0.2, 0.25, 0.4 * DEG, 0.4 * DEG, 0.2 * DEG])
    return out + rms * (e[2:] - 2.0 * e[1:-1] + e[:-2]) / np.sqrt(6.0)


def _texture(t: np.ndarray, speed: np.ndarray, rng) -> np.ndarray:
    """Driving texture (n, 6): first-order Gauss-Markov (1 s), 0.1 m/s^2 and 0.3-0.5 deg/s at
    full development, scaled by min(1, speed / 2 m/s) (nothing at rest)."""
    dt = float(np.median(np.diff(t)))
    a = np.exp(-dt / 1.0)
    drive = rng.standard_normal((len(t), 6)) * np.sqrt(1.0 - a * a)
    x = np.empty_like(drive)
    x[0] = rng.standard_normal(6)
    for s in range(0, len(t) - 1, 1000):  # x_k = a x_{k-1} + e_k, closed form per block
        m = min(1000, len(t) - 1 - s)
        p = a ** np.arange(1, m + 1)
        x[s + 1 : s + m + 1] = p[:, None] * (
            x[s] + np.cumsum(drive[s + 1 : s + m + 1] / p[:, None], axis=0)
        )
    rms = np.array([0.1, 0.1, 0.1, 0.3 * DEG, 0.3 * DEG, 0.5 * DEG])
    return x * rms * np.minimum(1.0, speed / 2.0)[:, None]


def _consumer(run: RecordedRun, seed: int, speed: np.ndarray | None = None) -> RecordedRun:
    """The run's perfect IMU with consumer noise, biases, vibration (and texture if ``speed``)."""
    rng = np.random.default_rng(1000 + seed)
    t = run.imu.t
    dt = float(np.median(np.diff(t)))
    err = _vibration(t, dt, rng) + rng.standard_normal((len(t), 6)) * np.array(
        [NA] * 3 + [NG] * 3
    ) / np.sqrt(dt)
    if speed is not None:
        err += _texture(t, speed, rng)
    x = np.hstack([run.imu.f_b, run.imu.omega_ib_b]) + err + BIAS
    return replace(run, imu=ImuData(t, x[:, :3], x[:, 3:]))


def _sim(scenario, duration_s: float, seed: int = 0, texture: bool = False):
    """A consumer-IMU run and its truth at the IMU epochs."""
    run = sim.simulate(scenario, duration_s, imu_grade="perfect", noise="white", seed=seed)
    truth = sim.dense_truth(scenario, duration_s)
    assert np.allclose(truth.t, run.imu.t)
    return _consumer(run, seed, truth.speed if texture else None), truth


def _score(report: StationaryReport, truth, segments, min_hold_s: float = 3.0) -> dict:
    """Detected share of the holds of at least ``min_hold_s``; detected seconds while moving."""
    dt = float(np.median(np.diff(truth.t)))
    m = report.mask(truth.t)
    hold = np.zeros(len(truth.t), bool)
    for s in segments:
        if s["kind"] == "hold" and s["t1"] - s["t0"] >= min_hold_s:
            hold |= (truth.t >= s["t0"]) & (truth.t <= s["t1"])
    yaw_rate = np.gradient(np.unwrap(truth.rpy[:, 2]), truth.t)
    return {
        "detected": float((m & hold).sum() / max(hold.sum(), 1)),
        "fp_speed_s": float((m & (truth.speed > 0.05)).sum() * dt),
        "fp_yaw_s": float((m & (np.abs(yaw_rate) > 0.5 * DEG)).sum() * dt),
    }


# --- simulated runs ------------------------------------------------------------------------------


def test_parked_with_idling_engine_is_stationary():
    run, truth = _sim("static", 60.0)
    # The IMU the brief describes: a per-sample 2 deg/s gyro test would call every sample moving.
    assert np.all(np.degrees(np.std(run.imu.omega_ib_b[:, :2], axis=0)) > 2.0)
    assert np.all(np.std(run.imu.f_b, axis=0) > 0.5)
    report = detect_stationary(run.imu, run.gnss, run.origin)
    assert report.fraction >= 0.95, report.summary()
    assert all(s.gnss_checked for s in report.spans)
    # The span's mean rate is the bias plus the earth rate (truth), within its stated error.
    span = max(report.spans, key=lambda s: s.duration_s)
    expected = BIAS[3:] + truth.omega_ib_b[span.i_start : span.i_end].mean(axis=0)
    assert np.all(np.abs(span.omega_mean_b - expected) < 4.0 * span.omega_se_b + 1e-6)
    assert np.all(span.omega_se_b < 0.01 * DEG)  # the mean is good to < 36 deg/h ...
    assert np.all(span.omega_std_b[:2] > 2.0 * DEG)  # ... though each sample scatters by 2 deg/s


@pytest.mark.parametrize("scenario", ["ugv", "car"])
def test_stops_detected_and_motion_rejected(scenario):
    run, truth = _sim(scenario, 300.0, seed=3, texture=True)
    report = detect_stationary(run.imu, run.gnss, run.origin)
    score = _score(report, truth, run.sim.segments)
    print(scenario, score, report.summary())
    assert score["detected"] >= 0.90
    assert score["fp_speed_s"] == 0.0 and score["fp_yaw_s"] == 0.0
    # Pivots on the spot (ugv: 90 deg at 30 deg/s) are never stationary.
    for s in run.sim.segments:
        if s["kind"] == "turn":
            inside = (truth.t > s["t0"]) & (truth.t < s["t1"])
            assert not np.any(report.mask(truth.t[inside])), s


@pytest.mark.parametrize("scenario", ["ugv", "car"])
def test_imu_still_motion_is_never_accepted(scenario):
    # Worst case: no driving texture, so every constant-speed or constant-acceleration stretch
    # looks IMU-still; only the GNSS fixes and the IMU velocity chain can reject them.
    run, truth = _sim(scenario, 300.0, seed=4, texture=False)
    report = detect_stationary(run.imu, run.gnss, run.origin)
    score = _score(report, truth, run.sim.segments)
    print(scenario, score, report.summary())
    moving_still = [
        (a, b) for a, b in imu_still_stretches(run.imu) if np.max(truth.speed[a:b]) > 1.0
    ]
    assert len(moving_still) >= 3  # the case is real
    assert score["fp_speed_s"] == 0.0 and score["fp_yaw_s"] == 0.0
    assert score["detected"] >= 0.75


def test_constant_speed_cruise_rejected_by_gnss():
    run, truth = _sim("straight", 60.0)
    assert np.all(truth.speed > 9.9)
    still = imu_still_stretches(run.imu)
    assert sum(b - a for a, b in still) * 0.01 > 50.0  # the IMU alone would call it stationary
    report = detect_stationary(run.imu, run.gnss, run.origin)
    assert report.spans == [] and report.fraction == 0.0
    assert report.rejected and all(r["why"] == "GNSS shows motion" for r in report.rejected)


def test_cruise_inside_a_gnss_outage_rejected_by_the_fixes_around_it():
    # A 6-8 m/s drive whose 30 s cruise is IMU-still and lies in a GNSS outage: step 4 has no
    # fixes in or near it, but those before and after, carried to it by the IMU, show the cruise.
    scen = sim.Scenario("outage cruise").hold(10).speed_to(6.0, 4.0).cruise(10)
    scen = scen.speed_to(8.0, 2.0).cruise(30).speed_to(6.0, 2.0).cruise(15)
    run, truth = _sim(scen, scen.t_end)
    cruise = [a for a, b in imu_still_stretches(run.imu) if truth.speed[a] > 7.9]
    assert cruise  # the IMU alone would call the cruise stationary
    g = run.gnss
    run = replace(run, gnss=g.select((g.t < 25.0) | (g.t > 60.0)))
    report = detect_stationary(run.imu, run.gnss, run.origin)
    assert _score(report, truth, run.sim.segments)["fp_speed_s"] == 0.0
    assert _score(report, truth, run.sim.segments)["detected"] >= 0.85  # the first hold
    linked = [r for r in report.rejected if "carried by the IMU" in r["why"]]
    assert any(r["t_start"] > 25.0 and r["t_end"] < 60.0 for r in linked), report.rejected


def test_antenna_swing_around_a_pivot_is_not_motion():
    # Precise fixes of an antenna 1.2 m from the IMU: the UGV pivots on the spot next to its
    # stops and the antenna swings by up to 2.3 m, which the fixes see. Told the lever arm, the
    # detector keeps every stop; not told, it refuses those the swing contradicts.
    lever = (1.0, 0.5, -1.0)
    run = sim.simulate("ugv", 300.0, imu_grade="industrial", noise="rtk", seed=0, lever_arm_b=lever)
    t, speed = run.truth.t, np.hypot(run.truth.v_n[:, 0], run.truth.v_n[:, 1])

    def at_rest(t0, t1):
        return speed[(t >= t0) & (t <= t1)].max() <= 0.05

    told = detect_stationary(run.imu, run.gnss, run.origin, lever_arm_b=lever)
    blind = detect_stationary(run.imu, run.gnss, run.origin)
    assert all(at_rest(s.t_start, s.t_end) for s in told.spans)
    assert not [r for r in told.rejected if at_rest(r["t_start"], r["t_end"])]
    assert sum(at_rest(r["t_start"], r["t_end"]) for r in blind.rejected) >= 3
    assert len(told.spans) >= len(blind.spans) + 3


def test_slow_creep_rejected_by_gnss_stops_kept():
    scen = sim.Scenario("creep").hold(10).speed_to(0.5, 2.0).cruise(30).speed_to(0.0, 2.0).hold(10)
    run, truth = _sim(scen, scen.t_end)
    creep = truth.speed > 0.49
    still = np.zeros(len(truth.t), bool)
    for a, b in imu_still_stretches(run.imu):
        still[a:b] = True
    assert (still & creep).sum() > 0.8 * creep.sum()  # the creep looks IMU-still
    report = detect_stationary(run.imu, run.gnss, run.origin)
    score = _score(report, truth, run.sim.segments)
    assert score["fp_speed_s"] == 0.0
    assert score["detected"] >= 0.85, score
    t_creep = truth.t[creep]
    assert any(
        r["why"] == "GNSS shows motion" and r["t_start"] < t_creep[-1] and r["t_end"] > t_creep[0]
        for r in report.rejected
    )


def test_stop_in_gnss_outage_accepted_on_imu_evidence():
    # No texture: this module's texture is added to the IMU only, not to the truth, so it is an
    # IMU error of ~25 deg/sqrt(h) on the gyros, and the fixes carried to the stop by such an IMU
    # (step 4b) rightly disagree with it. A real vehicle's texture is motion the fixes share.
    run, truth = _sim("car", 300.0, seed=5, texture=False)
    hold = [s for s in run.sim.segments if s["kind"] == "hold" and s["t0"] > 50.0][0]
    g = run.gnss
    run = replace(run, gnss=g.select((g.t < hold["t0"] - 5.0) | (g.t > hold["t1"] + 5.0)))
    report = detect_stationary(run.imu, run.gnss, run.origin)
    inside = [
        s for s in report.spans if hold["t0"] - 1.0 <= s.t_start and s.t_end <= hold["t1"] + 1.0
    ]
    assert len(inside) == 1 and not inside[0].gnss_checked and inside[0].gnss_speed_mps is None
    assert inside[0].duration_s >= 0.85 * (hold["t1"] - hold["t0"])
    assert all(s.gnss_checked for s in report.spans if s is not inside[0])
    assert _score(report, truth, run.sim.segments)["fp_speed_s"] == 0.0


def test_noise_free_imu_and_data_gap():
    run = sim.simulate("ugv", 120.0, imu_grade="perfect", noise="white", seed=0)
    truth = sim.dense_truth("ugv", 120.0)
    report = detect_stationary(run.imu, run.gnss, run.origin)
    score = _score(report, truth, run.sim.segments)
    assert score["detected"] >= 0.9 and score["fp_speed_s"] == 0.0 and score["fp_yaw_s"] == 0.0
    # A 0.5 s hole in the IMU record inside a stop splits it: nothing is known inside the hole.
    static = sim.simulate("static", 30.0, imu_grade="perfect", noise="white", seed=0)
    keep = (static.imu.t < 15.0) | (static.imu.t > 15.5)
    report = detect_stationary(static.imu.select(keep), static.gnss, static.origin)
    assert len(report.spans) == 2
    assert report.spans[0].t_end < 15.0 and report.spans[1].t_start > 15.5


def test_report_interface():
    run, _ = _sim("ugv", 120.0, seed=1, texture=True)
    report = detect_stationary(run.imu, run.gnss, run.origin, StationaryParams())
    assert report.spans
    for s in report.spans:
        assert run.imu.t[s.i_start] == s.t_start and run.imu.t[s.i_end - 1] == s.t_end
        assert s.f_mean_b.shape == s.omega_se_b.shape == (3,)
        assert np.allclose(s.f_mean_b, run.imu.f_b[s.i_start : s.i_end].mean(axis=0))
    t = run.imu.t
    m = report.mask(t)
    assert m.sum() == sum(s.i_end - s.i_start for s in report.spans)
    assert report.fraction == pytest.approx(
        sum(s.duration_s for s in report.spans) / (t[-1] - t[0])
    )
    d = json.loads(json.dumps(report.to_dict()))
    assert d["n_spans"] == len(report.spans) and len(json.dumps(d)) < 20_000
    assert "\n" not in report.summary() and str(len(report.spans)) in report.summary()
    # Without any fix every IMU-still stretch stands on IMU evidence alone, flagged as such.
    no_fix = run.gnss.select(np.zeros(len(run.gnss), bool))
    bare = detect_stationary(run.imu, no_fix, run.origin)
    assert bare.spans and not any(s.gnss_checked for s in bare.spans)
    assert bare.total_s >= report.total_s


def test_params_from_config():
    from gnssacc.core.config import load_config

    assert params_from_config(load_config()) == StationaryParams()  # no section: the defaults
    p = params_from_config({"stationary": {"z": 5, "min_duration_s": 3}})
    assert p.z == 5.0 and p.min_duration_s == 3.0 and p.block_s == StationaryParams().block_s
    with pytest.raises(InputError):
        params_from_config({"stationary": {"zz": 5}})


def test_noise_densities_from_stationary_spans():
    run, truth = _sim("static", 300.0, seed=2)
    report = detect_stationary(run.imu, run.gnss, run.origin)
    noise = noise_from_stationary(run.imu, report)
    assert noise.total_s > 280.0
    assert np.allclose(noise.white_density, [NA] * 3 + [NG] * 3, rtol=0.10), noise.white_density / (
        [NA] * 3 + [NG] * 3
    )
    assert noise.bias_instability == [None] * 6  # white noise only: no floor to read
    assert (
        np.array_equal(noise.gyro_density, noise.white_density[3:])
        and noise.seconds == noise.total_s
    )
    gz = np.array([d["omega_mean_b"][2] for d in noise.turn_on])
    assert np.allclose(gz, BIAS[5] + truth.omega_ib_b[0, 2], atol=0.002 * DEG)  # bias + earth rate
    json.dumps(noise.to_dict())
    # Too short to read densities from: NaN, not a guess.
    short = noise_from_stationary(run.imu, report, min_span_s=1e6)
    assert np.all(np.isnan(short.white_density)) and short.total_s == 0.0


# --- real data -----------------------------------------------------------------------------------


def _data_dir(name: str) -> Path:
    path = DATA / name
    if not path.is_dir():
        pytest.skip(
            f"real-data folder {path} is absent (it sits beside the repository at ../shared/data; "
            f"a fresh clone has none)"
        )
    return path


def _read_vn_csv(path: Path) -> dict[str, np.ndarray]:
    """Numeric columns of an INSTINCT VectorNav CSV by header name (copied from test_real_data)."""
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    out = {}
    for i, name in enumerate(rows[0]):
        try:
            out[name] = np.array([float(r[i]) for r in rows[1:]])
        except ValueError:
            pass
    return out


def _load_vn(log: str) -> RecordedRun:
    """A VN-310E static log: compensated IMU (FRD, 50 Hz) and GNSS1 fixes with their own sigmas."""
    root = _data_dir("vn310_static")
    imu = _read_vn_csv(root / f"{log}_vn310-imu.csv")
    gnss = _read_vn_csv(root / f"{log}_vn310-gnss.csv")
    t0 = imu["GpsTow [s]"][0]
    f_b = np.column_stack([imu[f"IMU::Accel::{a} [m/s^2]"] for a in "XYZ"])
    w_b = np.column_stack(
        [
            imu["IMU::AngularRate::X"],
            imu["IMU::AngularRate::Y [rad/s]"],
            imu["IMU::AngularRate::Z [rad/s]"],
        ]
    )
    lat = np.radians(gnss["GNSS1::PosLla::latitude [deg]"])
    lon = np.radians(gnss["GNSS1::PosLla::longitude [deg]"])
    fixes = GnssFixes(
        gnss["GNSS1::Tow [ns]"] * 1e-9 - t0,
        lat,
        lon,
        gnss["GNSS1::PosLla::altitude [m]"],
        np.column_stack([gnss[f"GNSS1::PosU::{a} [m]"] for a in "NED"]),
    )
    return RecordedRun(
        f"vn310-{log}",
        str(root),
        ImuData(imu["GpsTow [s]"] - t0, f_b, w_b),
        fixes,
        LocalTangentFrame(lat[0], lon[0], fixes.h[0]),
    ).validate()


@pytest.mark.parametrize("log", ["lckf", "tckf"])
def test_vn310_static_logs_are_stationary(log):
    run = _load_vn(log)
    report = detect_stationary(run.imu, run.gnss, run.origin)
    print(log, report.summary())
    assert report.fraction >= 0.90
    assert all(s.gnss_checked for s in report.spans)


def test_comma_highway_minute_has_no_stationary_time():
    root = _data_dir("comma2k19_example1")

    def arr(rel):
        return np.load(root / rel)

    t = arr("processed_log/IMU/accelerometer/t")
    imu = ImuData(
        t, arr("processed_log/IMU/accelerometer/value"), arr("processed_log/IMU/gyro/value")
    )
    tg, ub = (
        arr("processed_log/GNSS/live_gnss_ublox/t"),
        arr("processed_log/GNSS/live_gnss_ublox/value"),
    )
    # u-blox columns: lat deg, lon deg, speed, UTC ms, altitude m, bearing; no sigma: 2.5 m / 5 m.
    fixes = GnssFixes(
        tg,
        np.radians(ub[:, 0]),
        np.radians(ub[:, 1]),
        ub[:, 4],
        np.tile([2.5, 2.5, 5.0], (len(tg), 1)),
    )
    report = detect_stationary(
        imu, fixes, LocalTangentFrame(fixes.lat[0], fixes.lon[0], fixes.h[0])
    )
    print(report.summary())
    assert report.total_s == 0.0
    assert ub[:, 2].min() > 5.0  # it is indeed moving all the time


def test_kitti_no_stationary_time_while_moving():
    from gnssacc.core.config import load_config
    from gnssacc.sources.kitti import load_kitti

    try:
        run = load_kitti(load_config("kitti"), "white", 0)
    except InputError as exc:
        pytest.skip(f"KITTI data not available: {exc}")
    report = detect_stationary(run.imu, run.gnss, run.origin)
    print(report.summary())
    tr = run.truth
    p = run.origin.to_ned(tr.lat, tr.lon, tr.h)
    speed = np.hypot(*np.gradient(p[:, :2], tr.t, axis=0).T)  # 1 Hz truth, finite differences
    t = run.imu.t[report.mask(run.imu.t)]
    assert not np.any(np.interp(t, tr.t, speed) > 0.3)
