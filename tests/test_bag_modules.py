"""Tests of the bag reader's and writer's parts on their own: the ROS 1 salvage reader against
rosbags' reader of the intact bag, the time-stamp repair against hand-made rows, the topic rules
on made-up surveys, the ``"auto"`` mounting through the typed accessor, and write_bag's options."""

from __future__ import annotations

import warnings
from collections import Counter
from dataclasses import replace

import numpy as np
import pytest

pytest.importorskip("rosbags")

from rosbags.highlevel import AnyReader  # noqa: E402

from gnssacc.core.config import load_config  # noqa: E402
from gnssacc.core.errors import DataWarning, InputError  # noqa: E402
from gnssacc.sources.bag_salvage import Ros1Salvage  # noqa: E402
from gnssacc.sources.bag_times import find_gaps, sorted_unique  # noqa: E402
from gnssacc.sources.bag_topics import TopicStat, select_topics  # noqa: E402
from gnssacc.sources.bagwrite import BagOptions, write_bag  # noqa: E402
from gnssacc.sources.rosbag import load_bag_run  # noqa: E402
from gnssacc.sources.sim import simulate  # noqa: E402


@pytest.fixture(scope="module")
def sim():
    return simulate(
        "car", duration_s=60.0, imu_grade="industrial", noise="white", seed=5, truth_rate_hz=10.0
    )


def test_salvage_reads_the_complete_chunks_as_rosbags_reads_the_intact_bag(sim, tmp_path):
    """Cut a ROS 1 bag: the salvaged messages are exactly the first messages of the intact bag."""
    p = write_bag(sim, tmp_path / "full.bag", "ros1-rooad", truth_topic="/truth")
    with AnyReader([p]) as reader:
        intact = [(c.topic, t, bytes(raw)) for c, t, raw in reader.messages()]
    cut = tmp_path / "cut.bag"
    cut.write_bytes(p.read_bytes()[: int(p.stat().st_size * 0.6)])
    salvage = Ros1Salvage(cut)
    got = [(c.topic, t, bytes(raw)) for c, t, raw in salvage.messages()]
    assert 0.3 * len(intact) < len(got) < 0.65 * len(intact)
    assert salvage.message_count == len(got) and 0 < salvage.good_bytes < cut.stat().st_size
    # the messages up to the damage, each once, and none of them later than a lost one
    rest = Counter(intact)
    rest.subtract(Counter(got))
    assert min(rest.values()) >= 0 and rest.total() == len(intact) - len(got)
    assert max(m[1] for m in got) <= min(m[1] for m, n in rest.items() if n > 0)
    assert {s: salvage.topics[s].msgcount for s in salvage.topics} == {
        s: sum(1 for m in got if m[0] == s) for s in ("/vectornav/IMU", "/UBX/hpposllh", "/truth")
    }


def test_sorted_unique_repairs_and_counts():
    t = [0.0, 1.0, 3.0, 2.0, 3.0, 4.0, 4.0]
    rows = np.column_stack([t, [10, 11, 13, 12, 13, 14, 99]]).astype(float)
    meta: dict = {}
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        out = sorted_unique(rows, "bag", "topic /x", meta, "imu")
    np.testing.assert_array_equal(out, [[0, 10], [1, 11], [2, 12], [3, 13], [4, 14]])
    assert meta["time_fixes"]["imu"] == {
        "backwards_steps": 1,
        "exact_duplicates": 1,
        "conflicting_duplicates": 1,
    }
    text = " ".join(str(x.message) for x in w if issubclass(x.category, DataWarning))
    assert (
        "backwards 1 time" in text
        and "1 exact duplicate" in text
        and "1 message(s) repeating" in text
    )


def test_find_gaps():
    t = np.r_[np.arange(0.0, 10.0, 0.1), np.arange(12.0, 13.0, 0.1)]
    g = find_gaps(t, 5.0)
    assert g["count"] == 1 and g["nominal_dt_s"] == pytest.approx(0.1)
    assert g["spans"][0] == pytest.approx([9.9, 2.1])


def _stat(topic, typ, rate):
    return TopicStat(topic, typ, int(rate * 60), rate)


def test_select_topics_rules_on_a_survey():
    imu, fix = "sensor_msgs/msg/Imu", "sensor_msgs/msg/NavSatFix"
    stats = [
        _stat("/imu_fast", imu, 200.0),
        _stat("/imu_slow", imu, 100.0),
        _stat("/fix", fix, 1.0),
        _stat("/odom", "nav_msgs/msg/Odometry", 50.0),
        _stat("/cam", "sensor_msgs/msg/Image", 10.0),
    ]
    sel = select_topics(stats, "bag")
    # An Odometry topic is only a candidate: truth if its data are geo-referenced and agree with the
    # fixes, else the wheel odometry (decided when the bag is read).
    assert (sel.imu.topic, sel.gnss.topic, sel.truth) == ("/imu_fast", "/fix", None)
    assert [(c.topic, k) for c, k in sel.truth_candidates] == [("/odom", "pose")]
    assert [c.topic for c in sel.odom_candidates] == ["/odom"]
    close = [_stat("/a", imu, 100.0), _stat("/b", imu, 80.0), _stat("/fix", fix, 1.0)]
    with pytest.raises(
        InputError, match=r"ambiguous IMU topic: 2 candidates: /a .*/b .*--imu-topic"
    ):
        select_topics(close, "bag")
    sel = select_topics(
        close + [_stat("/rtk", fix, 10.0)], "bag", imu_topic="/b", gnss_topic="/fix"
    )
    assert sel.imu.topic == "/b" and [(c.topic, k) for c, k in sel.truth_candidates] == [
        ("/rtk", "fix")
    ]
    sel = select_topics(
        close + [_stat("/rtk", fix, 10.0)],
        "bag",
        imu_topic="/b",
        gnss_topic="/fix",
        truth_topic="/rtk",
    )
    assert (sel.truth.topic, sel.truth_kind, sel.truth_candidates) == ("/rtk", "fix", [])
    sel = select_topics(close[:1] + [_stat("/rtk", fix, 10.0)], "bag", gnss_from_truth=True)
    assert sel.gnss is None and sel.truth.topic == "/rtk"


def test_auto_mounting_loads_like_identity(sim, tmp_path):
    """``imu_to_body_rpy_deg = "auto"`` is read through RunConfig (identity until the input checks
    measure it): a bag loads as with a zero mounting, and /tf_static still applies."""
    auto = load_config(overrides={"mounting": {"imu_to_body_rpy_deg": "auto"}})
    plain = write_bag(sim, tmp_path / "plain", "ros2-sqlite3")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        a, z = load_bag_run(plain, auto), load_bag_run(plain, load_config())
    np.testing.assert_array_equal(a.imu.f_b, z.imu.f_b)
    assert a.meta["imu_mounting"] == z.meta["imu_mounting"]
    mounted = write_bag(sim, tmp_path / "tf", "ros2-mcap", imu_mount_rpy_deg=(0.0, 0.0, 90.0))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        run = load_bag_run(mounted, auto)
    assert run.meta["imu_mounting"]["from"].startswith("/tf_static")
    np.testing.assert_allclose(run.imu.f_b, sim.imu.f_b, atol=1e-12)


def test_write_bag_options(sim, tmp_path):
    """An options object and keywords write the same bytes; bad options write nothing."""
    opts = BagOptions(truth_topic="/truth", receive_delay_s=0.05, with_orientation=True)
    a = write_bag(sim, tmp_path / "a.bag", "ros1-rooad", opts)
    b = write_bag(
        sim,
        tmp_path / "b.bag",
        "ros1-rooad",
        truth_topic="/truth",
        receive_delay_s=0.05,
        with_orientation=True,
    )
    c = write_bag(sim, tmp_path / "c.bag", "ros1-rooad", opts, receive_delay_s=0.0)
    assert a.read_bytes() == b.read_bytes() != c.read_bytes()
    with pytest.raises(TypeError, match="imu_topik"):
        write_bag(sim, tmp_path / "d.bag", "ros1-rooad", imu_topik="/x")
    with pytest.raises(InputError, match="the run has no truth"):
        write_bag(replace(sim, truth=None), tmp_path / "e", "ros2-sqlite3", truth_topic="/t")
    assert not (tmp_path / "e").exists() and not (tmp_path / "d.bag").exists()
