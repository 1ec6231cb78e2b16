"""Tests of the ROS bag source (gnssacc.sources.rosbag) and the bag writer (gnssacc.sources.bagwrite)."""

from __future__ import annotations

import shutil
import warnings

import numpy as np
import pytest

pytest.importorskip("rosbags")

from rosbags.highlevel import AnyReader  # noqa: E402
from rosbags.rosbag2 import Writer as Writer2  # noqa: E402
from rosbags.typesys import Stores, get_types_from_msg, get_typestore  # noqa: E402

from gnssacc.core.config import load_config  # noqa: E402
from gnssacc.core.config_docs import resolved_toml  # noqa: E402
from gnssacc.core.earth import LocalTangentFrame  # noqa: E402
from gnssacc.core.errors import DataWarning, InputError  # noqa: E402
from gnssacc.core.rotations import euler_to_dcm  # noqa: E402
from gnssacc.prepare.passes import run_ekf  # noqa: E402
from gnssacc.sources.bagwrite import ned_frd_to_enu_flu, write_bag  # noqa: E402
from gnssacc.sources.csvdir import load_csv_run, write_csv_run  # noqa: E402
from gnssacc.sources.rosbag import enu_flu_to_ned_frd, inspect_bag, load_bag_run  # noqa: E402
from gnssacc.sources.sim import simulate  # noqa: E402

KINDS = {
    "ros1-rooad": "run.bag",
    "ros2-sqlite3": "run_sqlite",
    "ros2-mcap": "run_mcap",
    "mcap": "run.mcap",
}
GNSS_TOPIC = {"ros1-rooad": "/UBX/hpposllh"}


@pytest.fixture(scope="module")
def cfg():
    return load_config()


@pytest.fixture(scope="module")
def sim():
    return simulate(
        "car", duration_s=120.0, imu_grade="industrial", noise="white", seed=2, truth_rate_hz=10.0
    )


@pytest.fixture(scope="module")
def csv_ekf(sim, cfg, tmp_path_factory):
    d = write_csv_run(sim, tmp_path_factory.mktemp("csv") / "run")
    return run_ekf(load_csv_run(d, cfg), cfg, "ekf", output_times=sim.imu.t[::10])


def _load(path, cfg, **kw):
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        run = load_bag_run(path, cfg, **kw)
    return run, [str(x.message) for x in w if issubclass(x.category, DataWarning)]


# --- round trips --------------------------------------------------------------------------------------


@pytest.mark.parametrize("kind", list(KINDS))
def test_round_trip_ekf_equals_csv(kind, sim, cfg, csv_ekf, tmp_path):
    """Every bag kind: the same samples come back and the EKF gives the CSV estimates to 1e-6 m."""
    p = write_bag(sim, tmp_path / KINDS[kind], kind, extra_image_topic_bytes=100)
    run, warns = _load(p, cfg)
    assert warns == []
    assert run.where == str(p) and run.name == p.stem
    assert run.meta["topics"]["gnss"] == GNSS_TOPIC.get(kind, "/gnss/fix")
    assert len(run.imu) == len(sim.imu) and len(run.gnss) == len(sim.gnss)
    np.testing.assert_allclose(run.imu.t, sim.imu.t, atol=1e-9, rtol=0)
    np.testing.assert_array_equal(run.imu.f_b, sim.imu.f_b)  # FLU <-> FRD sign flips are exact
    np.testing.assert_array_equal(run.imu.omega_ib_b, sim.imu.omega_ib_b)
    np.testing.assert_allclose(run.gnss.sigma_ned, sim.gnss.sigma_ned, rtol=1e-15)
    assert run.init is None  # orientation marked absent
    sol = run_ekf(run, cfg, "ekf", output_times=sim.imu.t[::10])
    lo = LocalTangentFrame(sim.origin.lat0, sim.origin.lon0, sim.origin.h0)
    d = lo.to_ned(sol.lat, sol.lon, sol.h) - lo.to_ned(csv_ekf.lat, csv_ekf.lon, csv_ekf.h)
    assert sol.t.shape == csv_ekf.t.shape
    assert np.abs(d).max() < 1e-6


def test_custom_hpposllh_fields_and_receive_time(sim, cfg, tmp_path):
    """ROOAD hpposllh: no header, so the fix time is the receive time; err fields are the sigmas."""
    p = write_bag(sim, tmp_path / "r.bag", "ros1-rooad", receive_delay_s=0.05)
    run, _ = _load(p, cfg)
    np.testing.assert_allclose(run.gnss.t, sim.gnss.t + 0.05, atol=1e-9)  # receive time
    np.testing.assert_allclose(run.imu.t, sim.imu.t, atol=1e-9)  # header stamp
    np.testing.assert_allclose(
        np.degrees(run.gnss.lat), np.degrees(sim.gnss.lat), rtol=0, atol=1e-12
    )
    np.testing.assert_array_equal(run.gnss.sigma_ned, sim.gnss.sigma_ned)
    run_r, _ = _load(p, cfg, time_source="receive")
    np.testing.assert_allclose(run_r.imu.t, sim.imu.t + 0.05, atol=1e-9)


def test_user_field_mapping_for_custom_type(cfg, tmp_path):
    """An unknown custom fix type is an error naming the topic; a mapping makes it readable."""
    ts = get_typestore(Stores.ROS2_HUMBLE)
    ts.register(
        get_types_from_msg(
            "std_msgs/Header header\nint32 lat_e7\nint32 lon_e7\nint32 h_mm\n"
            "float32 hacc\nfloat32 vacc\n",
            "acme/msg/Fix",
        )
    )
    Fix = ts.types["acme/msg/Fix"]
    p = tmp_path / "custom"
    msgs = _static_imu(ts, 0.0, 10.0, 100.0)
    for k in range(11):
        msgs.append(
            (
                "/acme/fix",
                "acme/msg/Fix",
                k * 1.0,
                Fix(
                    header=_hdr(ts, k * 1.0),
                    lat_e7=490000000 + k,
                    lon_e7=84000000,
                    h_mm=110000,
                    hacc=1.5,
                    vacc=2.5,
                ),
            )
        )
    _raw_bag(p, ts, msgs)
    with pytest.raises(InputError, match=r"no GNSS topic.*?/acme/fix \(acme/msg/Fix"):
        load_bag_run(p, cfg)
    with pytest.raises(
        InputError, match=r"--gnss-topic /acme/fix has type acme/msg/Fix.*field mapping"
    ):
        load_bag_run(p, cfg, gnss_topic="/acme/fix")
    mapping = {
        "acme/Fix": {
            "lat": "lat_e7",
            "lon": "lon_e7",
            "height": "h_mm",
            "latlon_scale_deg": 1e-7,
            "height_scale_m": 1e-3,
            "sigma_n": "hacc",
            "sigma_e": "hacc",
            "sigma_d": "vacc",
            "stamp": "header.stamp",
        }
    }
    run, _ = _load(p, cfg, fix_mappings=mapping)
    assert np.degrees(run.gnss.lat[3]) == pytest.approx(49.0000003, abs=1e-12)
    assert run.gnss.h[0] == pytest.approx(110.0)
    np.testing.assert_allclose(run.gnss.sigma_ned[0], [1.5, 1.5, 2.5])


# --- frames -------------------------------------------------------------------------------------------


def test_flu_enu_conversions(cfg, tmp_path):
    """A vehicle standing level, facing north, turning left at 0.1 rad/s (ROS: +z yaw rate, +z
    specific force, ENU yaw 90 deg) is FRD/NED: yaw rate -0.1, f_z = -g, yaw 0, x = north."""
    ts = get_typestore(Stores.ROS2_HUMBLE)
    qn = (0.0, 0.0, np.sin(np.pi / 4), np.cos(np.pi / 4))  # ENU yaw +90 deg: x-forward -> north
    msgs = _static_imu(ts, 0.0, 10.0, 100.0, w=(0.0, 0.0, 0.1), f=(0.2, 0.3, 9.8), q=qn)
    msgs += _fixes(ts, 0.0, 10.0)
    p = tmp_path / "frames"
    _raw_bag(p, ts, msgs)
    run, _ = _load(p, cfg)
    np.testing.assert_allclose(run.imu.omega_ib_b[0], [0.0, 0.0, -0.1])
    np.testing.assert_allclose(run.imu.f_b[0], [0.2, -0.3, -9.8])
    assert run.init is not None
    np.testing.assert_allclose(run.init.rpy, [0.0, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(run.init.sigma_att_rad, np.radians([1.0, 1.0, 5.0]))
    # and the general relation both ways
    R_nb = euler_to_dcm(0.1, -0.2, 2.5)
    np.testing.assert_allclose(enu_flu_to_ned_frd(ned_frd_to_enu_flu(R_nb)), R_nb, atol=1e-15)
    assert ned_frd_to_enu_flu(np.eye(3)) @ np.array([1.0, 0, 0]) == pytest.approx([0.0, 1.0, 0.0])


def test_orientation_gives_initial_state(sim, cfg, tmp_path):
    p = write_bag(sim, tmp_path / "o", "ros2-sqlite3", with_orientation=True)
    run, _ = _load(p, cfg)
    assert run.init is not None and run.init.t == pytest.approx(sim.gnss.t[0])
    np.testing.assert_allclose(run.init.rpy, sim.truth.rpy[0], atol=1e-9)
    assert np.linalg.norm(run.init.v_n - sim.truth.v_n[0]) < 3.0  # noisy 3 s line fit
    np.testing.assert_allclose(run.init.sigma_att_rad, np.radians([1.0, 1.0, 5.0]), rtol=1e-9)
    assert "orientation" in run.init.how
    run_ekf(run, cfg, "ekf")  # the filter accepts it


def test_tf_static_mounting(sim, cfg, tmp_path):
    """IMU written in mounted axes + /tf_static: the loader rotates back to the body frame."""
    p = write_bag(sim, tmp_path / "tf", "ros2-mcap", imu_mount_rpy_deg=(0.0, 0.0, 90.0))
    run, _ = _load(p, cfg)
    np.testing.assert_allclose(run.imu.f_b, sim.imu.f_b, atol=1e-12)
    assert run.meta["imu_mounting"]["from"].startswith("/tf_static base_link -> imu_link")
    assert run.meta["imu_mounting"]["imu_to_body_rpy_deg"] == pytest.approx([0.0, 0.0, 90.0])
    cfg_m = load_config(overrides={"mounting": {"imu_to_body_rpy_deg": [0.0, 0.0, 90.0]}})
    run_m, _ = _load(p, cfg_m)  # a configured mounting wins over /tf_static
    assert run_m.meta["imu_mounting"]["from"].startswith("config")
    np.testing.assert_allclose(run_m.imu.f_b, sim.imu.f_b, atol=1e-12)


def test_odometry_truth_enu(sim, cfg, tmp_path):
    p = write_bag(sim, tmp_path / "odo", "ros2-sqlite3", truth_topic="/odom", truth_type="odometry")
    run, _ = _load(p, cfg)
    assert run.meta["topics"]["truth"] == "/odom" and "assumed" in run.meta["truth_origin"]
    lo = run.origin
    d = lo.to_ned(run.truth.lat, run.truth.lon, run.truth.h) - lo.to_ned(
        sim.truth.lat, sim.truth.lon, sim.truth.h
    )
    assert np.abs(d).max() < 1e-6
    np.testing.assert_allclose(run.truth.v_n, sim.truth.v_n, atol=1e-9)
    dyaw = (run.truth.rpy - sim.truth.rpy + np.pi) % (2 * np.pi) - np.pi
    assert np.abs(dyaw).max() < 1e-9


def test_gnss_from_rtk_truth(sim, cfg, tmp_path):
    """ROOAD with only an RTK receiver: GNSS made by subsampling the truth at 1 Hz plus noise."""
    p = write_bag(
        sim, tmp_path / "rtk.bag", "ros1-rooad", gnss_topic=None, truth_topic="/RTK/hpposllh"
    )
    run, _ = _load(p, cfg, gnss_from_truth_hz=1.0, noise="white", seed=3)
    assert len(run.truth.t) == len(sim.truth.t)  # 10 Hz truth kept
    assert len(run.gnss) == 121
    np.testing.assert_allclose(np.diff(run.gnss.t), 1.0, atol=1e-6)
    err = run.origin.to_ned(run.gnss.lat, run.gnss.lon, run.gnss.h) - run.origin.to_ned(
        run.truth.lat[::10], run.truth.lon[::10], run.truth.h[::10]
    )
    assert 1.0 < np.std(err[:, 0]) < 6.0  # white: 3 m N
    assert run.meta["noise"] == "white" and run.meta["gnss_from_truth_hz"] == 1.0


# --- topic selection ---------------------------------------------------------------------------------


def test_autodetect_unique_and_ambiguous(sim, cfg, tmp_path):
    p = write_bag(sim, tmp_path / "two", "ros2-sqlite3", truth_topic="/rtk/fix")
    with pytest.raises(
        InputError,
        match=r"two: ambiguous GNSS topic: 2 candidates: /gnss/fix "
        r"\(sensor_msgs/msg/NavSatFix, 121 msgs, ~1\.0 Hz\); /rtk/fix .*--gnss-topic",
    ):
        load_bag_run(p, cfg)
    run, _ = _load(p, cfg, gnss_topic="/gnss/fix")
    assert run.meta["topics"] == {
        "imu": "/imu/data",
        "gnss": "/gnss/fix",
        "truth": "/rtk/fix",
        "odometry": None,
    }
    text = inspect_bag(p)
    assert "/rtk/fix" in text and "ambiguous GNSS" in text and "121" in text
    text = inspect_bag(p, gnss_topic="/gnss/fix")
    assert (
        "IMU /imu/data: the only Imu topic" in text
        and "truth /rtk/fix: geo-referenced and agrees" in text
    )


def test_autodetect_imu_rate_rules(cfg, tmp_path):
    ts = get_typestore(Stores.ROS2_HUMBLE)
    msgs = (
        _static_imu(ts, 0.0, 10.0, 100.0)
        + _static_imu(ts, 0.0, 10.0, 20.0, topic="/imu/slow")
        + _fixes(ts, 0, 10)
    )
    _raw_bag(tmp_path / "fast", ts, msgs)
    run, _ = _load(tmp_path / "fast", cfg)
    assert run.meta["topics"]["imu"] == "/imu/data" and len(run.imu) == 1001
    msgs = (
        _static_imu(ts, 0.0, 10.0, 100.0)
        + _static_imu(ts, 0.0, 10.0, 90.0, topic="/imu/b")
        + _fixes(ts, 0, 10)
    )
    _raw_bag(tmp_path / "same", ts, msgs)
    with pytest.raises(
        InputError,
        match=r"same: ambiguous IMU topic: 2 candidates: /imu/data .*/imu/b .*--imu-topic",
    ):
        load_bag_run(tmp_path / "same", cfg)
    run, _ = _load(tmp_path / "same", cfg, imu_topic="/imu/b")
    assert len(run.imu) == 901


def test_image_topics_not_decoded(sim, cfg, tmp_path, monkeypatch):
    p = write_bag(sim, tmp_path / "img", "ros2-mcap", extra_image_topic_bytes=20000)
    counts: dict = {}
    orig = AnyReader.deserialize

    def counting(self, raw, typ):
        counts[typ] = counts.get(typ, 0) + 1
        return orig(self, raw, typ)

    monkeypatch.setattr(AnyReader, "deserialize", counting)
    _load(p, cfg)
    assert counts == {
        "sensor_msgs/msg/Imu": len(sim.imu),
        "sensor_msgs/msg/NavSatFix": len(sim.gnss),
    }


# --- bad input ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("kind", list(KINDS))
def test_truncated_bag(kind, sim, cfg, tmp_path):
    p = write_bag(sim, tmp_path / KINDS[kind], kind)
    f = p if p.is_file() else next(x for x in p.iterdir() if x.name != "metadata.yaml")
    data = f.read_bytes()
    f.write_bytes(data[: int(len(data) * 0.7)])
    if kind != "ros1-rooad":  # sqlite3 / MCAP: a clear error naming the file
        with pytest.raises(InputError) as exc:
            load_bag_run(p, cfg)
        assert exc.value.where == str(p) and "truncated or corrupt" in exc.value.problem
        return
    run, warns = _load(p, cfg)  # ROS 1 without its index: salvaged up to the damage, said so
    assert any("damaged" in w and "read sequentially up to the damage" in w for w in warns)
    assert 0.3 * len(sim.imu) < len(run.imu) < 0.75 * len(sim.imu)
    np.testing.assert_array_equal(run.imu.f_b, sim.imu.f_b[: len(run.imu)])
    assert "damaged" in run.meta


def test_no_imu_no_gnss(cfg, tmp_path):
    ts = get_typestore(Stores.ROS2_HUMBLE)
    _raw_bag(tmp_path / "noimu", ts, _fixes(ts, 0, 10))
    with pytest.raises(
        InputError, match=r"noimu: no IMU topic: no sensor_msgs/msg/Imu .*/gnss/fix"
    ):
        load_bag_run(tmp_path / "noimu", cfg)
    _raw_bag(tmp_path / "nognss", ts, _static_imu(ts, 0.0, 5.0, 100.0))
    with pytest.raises(InputError, match=r"nognss: no GNSS topic"):
        load_bag_run(tmp_path / "nognss", cfg)
    with pytest.raises(InputError, match=r"nothere: no such file"):
        load_bag_run(tmp_path / "nothere", cfg)


def test_nan_rows_dropped_or_refused(sim, cfg, tmp_path):
    bad = _copy(sim)
    bad.imu.f_b[[100, 200, 300]] = np.nan
    p = write_bag(bad, tmp_path / "nan", "ros2-sqlite3")
    run, warns = _load(p, cfg)
    assert len(run.imu) == len(sim.imu) - 3
    assert any("dropped 3 of 12001 IMU topic /imu/data rows with NaN/inf" in w for w in warns)
    worse = _copy(sim)
    worse.imu.f_b[::20] = np.inf
    p = write_bag(worse, tmp_path / "inf", "ros2-sqlite3")
    with pytest.raises(
        InputError, match=r"inf: 601 of 12001 IMU topic /imu/data rows .*max_bad_fraction"
    ):
        load_bag_run(p, cfg)
    g = _copy(sim)
    g.gnss.lat[5] = np.nan
    p = write_bag(g, tmp_path / "gnan", "ros2-sqlite3")
    run, warns = _load(
        p,
        cfg,
    )
    assert len(run.gnss) == len(sim.gnss) - 1
    assert any("GNSS topic /gnss/fix" in w and "NaN/inf" in w for w in warns)


def test_zero_covariance_and_no_fix(sim, cfg, tmp_path):
    z = _copy(sim)
    z.gnss.sigma_ned[:10] = 0.0
    p = write_bag(z, tmp_path / "zero", "ros2-sqlite3")
    run, warns = _load(p, cfg)
    np.testing.assert_allclose(run.gnss.sigma_ned[:10], np.tile([3.0, 3.0, 5.0], (10, 1)))
    assert any(
        "GNSS topic /gnss/fix: 10 message(s) with an all-zero covariance" in w for w in warns
    )
    status = np.zeros(len(sim.gnss), int)
    status[:4] = -1
    p = write_bag(sim, tmp_path / "some", "ros2-sqlite3", fix_status=status)
    run, warns = _load(p, cfg)
    assert len(run.gnss) == len(sim.gnss) - 4 and any("skipped 4 NO_FIX" in w for w in warns)
    p = write_bag(sim, tmp_path / "nofix", "ros2-sqlite3", fix_status=-1)
    with pytest.raises(
        InputError, match=r"nofix: GNSS topic /gnss/fix: all 121 messages are NO_FIX"
    ):
        load_bag_run(p, cfg)


def test_time_backwards_and_duplicates(sim, cfg, tmp_path):
    p = write_bag(sim, tmp_path / "shuf", "ros2-sqlite3", shuffle_receive=True)
    run, warns = _load(p, cfg)
    np.testing.assert_allclose(run.imu.t, sim.imu.t, atol=1e-9)
    assert any(
        "IMU topic /imu/data: time went backwards 7 time(s); messages sorted" in w for w in warns
    )
    assert run.meta["time_fixes"]["imu"]["backwards_steps"] == 7
    ts = get_typestore(Stores.ROS2_HUMBLE)
    msgs = _static_imu(ts, 0.0, 10.0, 100.0)
    msgs += msgs[500:503]  # three exact duplicates
    _raw_bag(tmp_path / "dup", ts, msgs + _fixes(ts, 0, 10), sort=True)
    run, warns = _load(tmp_path / "dup", cfg)
    assert len(run.imu) == 1001 and any("dropped 3 exact duplicate" in w for w in warns)
    msgs = _static_imu(ts, 0.0, 10.0, 100.0)
    _raw_bag(tmp_path / "gap", ts, msgs[:300] + msgs[500:] + _fixes(ts, 0, 10))
    run, _ = _load(tmp_path / "gap", cfg)
    assert run.meta["gaps"]["imu"]["count"] == 1
    assert run.meta["gaps"]["imu"]["spans"][0] == pytest.approx([2.99, 2.01])


# --- helpers ------------------------------------------------------------------------------------------


def _copy(run):
    from copy import deepcopy

    return deepcopy(run)


def _hdr(ts, t, frame="imu_link"):
    ns = int(round(t * 1e9))
    return ts.types["std_msgs/msg/Header"](
        stamp=ts.types["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9),
        frame_id=frame,
    )


def _static_imu(ts, t0, t1, rate, topic="/imu/data", w=(0.0, 0.0, 0.0), f=(0.0, 0.0, 9.8), q=None):
    T = ts.types
    V = T["geometry_msgs/msg/Vector3"]
    Q = T["geometry_msgs/msg/Quaternion"]
    out = []
    n = int(round((t1 - t0) * rate)) + 1
    for k in range(n):
        t = t0 + k / rate
        msg = T["sensor_msgs/msg/Imu"](
            header=_hdr(ts, t),
            orientation=Q(x=0.0, y=0.0, z=0.0, w=1.0) if q is None else Q(*q),
            orientation_covariance=np.r_[-1.0, np.zeros(8)] if q is None else np.zeros(9),
            angular_velocity=V(*w),
            angular_velocity_covariance=np.zeros(9),
            linear_acceleration=V(*f),
            linear_acceleration_covariance=np.zeros(9),
        )
        out.append((topic, "sensor_msgs/msg/Imu", t, msg))
    return out


def _fixes(ts, t0, t1, topic="/gnss/fix"):
    T = ts.types
    out = []
    for k in range(int(t1 - t0) + 1):
        t = t0 + k
        cov = np.zeros(9)
        cov[[0, 4, 8]] = [4.0, 4.0, 9.0]
        msg = T["sensor_msgs/msg/NavSatFix"](
            header=_hdr(ts, t, "gnss"),
            status=T["sensor_msgs/msg/NavSatStatus"](status=0, service=1),
            latitude=49.0,
            longitude=8.4,
            altitude=110.0,
            position_covariance=cov,
            position_covariance_type=2,
        )
        out.append((topic, "sensor_msgs/msg/NavSatFix", float(t), msg))
    return out


def _raw_bag(path, ts, msgs, sort=True):
    """A ROS 2 sqlite3 bag of (topic, type, receive time [s], message) tuples."""
    if path.exists():
        shutil.rmtree(path)
    with Writer2(path, version=9) as w:
        conns = {}
        for topic, typ, _, _ in msgs:
            if topic not in conns:
                conns[topic] = w.add_connection(topic, typ, typestore=ts)
        items = sorted(msgs, key=lambda m: m[2]) if sort else msgs
        for topic, typ, t, msg in items:
            w.write(conns[topic], int(round(t * 1e9)), ts.serialize_cdr(msg, typ))


def test_imu_with_gravity_on_plus_y_husky_style(sim, cfg, csv_ekf, tmp_path):
    """An IMU mounted with its y axis up (Husky-type robots) works through /tf_static or the config."""
    mount = (
        90.0,
        0.0,
        0.0,
    )  # IMU axes -> body: roll 90 deg puts gravity's reaction on IMU +y (FLU)
    p = write_bag(sim, tmp_path / "husky", "ros2-sqlite3", imu_mount_rpy_deg=mount)
    # The raw IMU really reads gravity on +y: check the bag's own messages.
    ts = get_typestore(Stores.ROS2_HUMBLE)
    with AnyReader([p], default_typestore=ts) as reader:
        conn = [c for c in reader.connections if c.msgtype == "sensor_msgs/msg/Imu"]
        _, _, raw = next(reader.messages(connections=conn))
        acc = reader.deserialize(raw, conn[0].msgtype).linear_acceleration
    assert acc.y > 9.0 and abs(acc.z) < 1.0
    run, _ = _load(p, cfg)  # mounting from /tf_static
    sol = run_ekf(run, cfg, "ekf", output_times=sim.imu.t[::10])
    np.testing.assert_allclose(sol.lat, csv_ekf.lat, atol=1e-12)
    # The same mounting given in the configuration (which takes precedence over /tf_static).
    cfg_m = load_config(overrides={"mounting": {"imu_to_body_rpy_deg": list(mount)}})
    run_m, _ = _load(p, cfg_m)
    assert run_m.meta["imu_mounting"]["from"].startswith("config")
    np.testing.assert_allclose(run_m.imu.f_b, sim.imu.f_b, atol=1e-9)


def test_fix_mapping_from_the_config_file(tmp_path):
    """The custom-type mapping can live in the run configuration TOML."""
    toml = tmp_path / "bag.toml"
    toml.write_text(
        '[bag.fix_mappings."acme/msg/Fix"]\nlat = "lat_e7"\nlon = "lon_e7"\nheight = "h_mm"\n'
        'latlon_scale_deg = 1e-7\nheight_scale_m = 1e-3\nsigma_n = "hacc"\nsigma_e = "hacc"\n'
        'sigma_d = "vacc"\nstamp = "header.stamp"\n'
    )
    cfg_t = load_config(path=toml)
    ts = get_typestore(Stores.ROS2_HUMBLE)
    ts.register(
        get_types_from_msg(
            "std_msgs/Header header\nint32 lat_e7\nint32 lon_e7\nint32 h_mm\n"
            "float32 hacc\nfloat32 vacc\n",
            "acme/msg/Fix",
        )
    )
    Fix = ts.types["acme/msg/Fix"]
    msgs = _static_imu(ts, 0.0, 10.0, 100.0)
    for k in range(11):
        msgs.append(
            (
                "/acme/fix",
                "acme/msg/Fix",
                k * 1.0,
                Fix(
                    header=_hdr(ts, k * 1.0),
                    lat_e7=490000000 + k,
                    lon_e7=84000000,
                    h_mm=110000,
                    hacc=1.5,
                    vacc=2.5,
                ),
            )
        )
    p = tmp_path / "custom"
    _raw_bag(p, ts, msgs)
    run, _ = _load(p, cfg_t)
    assert np.degrees(run.gnss.lat[3]) == pytest.approx(49.0000003, abs=1e-12)
    np.testing.assert_allclose(run.gnss.sigma_ned[0], [1.5, 1.5, 2.5])
    assert '"acme/msg/Fix"' in resolved_toml(cfg_t)
