"""TUM export, the Monte-Carlo bench with its paired test, and the HTML report."""

import json

import numpy as np
import pytest

from gnssacc.analysis.montecarlo import paired_permutation_pvalue, parse_seeds
from gnssacc.cli import main
from gnssacc.core.rotations import euler_to_dcm, rotvec_to_dcm
from gnssacc.outputs.export import dcm_to_quaternion
from gnssacc.sources.csvdir import write_csv_run
from gnssacc.sources.sim import simulate


def _quat_to_dcm(q):
    x, y, z, w = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def test_quaternion_round_trip_including_near_pi():
    rng = np.random.default_rng(0)
    mats = [euler_to_dcm(*rng.uniform(-3, 3, 3)) for _ in range(200)]
    mats += [rotvec_to_dcm(np.array([np.pi - 1e-9, 0, 0])), rotvec_to_dcm(np.array([0, np.pi, 0]))]
    for R in mats:
        q = dcm_to_quaternion(R)
        assert np.linalg.norm(q) == pytest.approx(1.0) and q[3] >= 0
        np.testing.assert_allclose(_quat_to_dcm(q), R, atol=1e-9)


def test_paired_permutation_pvalue_exact_values():
    # All n differences of one sign: only the two all-same-sign patterns are as extreme.
    assert paired_permutation_pvalue(np.ones(5)) == pytest.approx(2 / 32)
    assert paired_permutation_pvalue(-np.arange(1, 11, dtype=float)) == pytest.approx(2 / 1024)
    assert paired_permutation_pvalue(np.zeros(6)) == 1.0
    # Symmetric differences: nothing to detect.
    assert paired_permutation_pvalue(np.array([1.0, -1.0, 2.0, -2.0])) == 1.0
    # Large n uses random sign patterns and agrees with the normal approximation's order of magnitude.
    d = np.random.default_rng(1).normal(0.5, 1.0, 40)
    assert paired_permutation_pvalue(d) < 0.05
    assert parse_seeds("0-3,7") == [0, 1, 2, 3, 7]


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    path = tmp_path_factory.mktemp("rep") / "run"
    write_csv_run(
        simulate("car", duration_s=90.0, imu_grade="industrial", noise="white", seed=1), path
    )
    return path


def test_run_with_report_and_tum_export(run_dir, tmp_path, capsys):
    out = tmp_path / "o"
    assert (
        main(
            [
                "run",
                str(run_dir),
                "--methods",
                "ekf,smoother",
                "--report",
                "--export",
                "tum",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    capsys.readouterr()
    page = (out / "report.html").read_text()
    for name in ("errors.png", "trajectory.png", "sigmas.png"):
        assert (out / name).is_file() and f'src="{name}"' in page
    assert "IMU data quality" in page and "ekf" in page
    # What the input checks proposed and the estimator proved, and how well the clock is told.
    assert "Input checks: what was proposed and proven" in page and "on_proof" in page
    assert "could go unseen" in page
    # The observability section: motion shares that add up, and per-state variance shares.
    assert "Observability" in page and "position + acceleration" in page
    import re

    shares = [
        float(x)
        for x in re.findall(
            r"<tr><td>(?:stationary|straight|accelerating|turning)</td><td>([0-9.]+)", page
        )
    ]
    assert len(shares) == 4 and sum(shares) == pytest.approx(100.0, abs=0.2)
    # The comparison is a real table whose PRMSE cells are metrics.json's, method by method.
    from html.parser import HTMLParser

    class Rows(HTMLParser):
        rows, cell = [], None

        def handle_starttag(self, tag, attrs):
            if tag == "tr":
                self.rows.append([])
            elif tag in ("td", "th"):
                self.cell = ""

        def handle_data(self, data):
            if self.cell is not None:
                self.cell += data

        def handle_endtag(self, tag):
            if tag in ("td", "th"):
                self.rows[-1].append(self.cell)
                self.cell = None

    parser = Rows()
    # The answer comes first: the comparison is the page's first table.
    assert page.index("Answer: which method") < page.index("<table") < page.index("Statistics</h2>")
    parser.feed(page.split("Answer: which method, how good, how sure</h2>")[1].split("</table>")[0])
    head, *body = parser.rows
    metrics = json.loads((out / "metrics.json").read_text())
    col = head.index("PRMSE [m]")
    for row in body[:-1]:
        assert float(row[col]) == pytest.approx(metrics["methods"][row[0]]["prmse_m"], abs=0.006)
    assert body[-1][0] == "gnss (raw fixes)" and float(body[-1][col]) == pytest.approx(
        metrics["gnss_prmse_m"], abs=0.006
    )
    tum = np.loadtxt(out / "trajectory_ekf.tum")
    csv = np.genfromtxt(out / "trajectory_ekf.csv", delimiter=",", names=True)
    assert tum.shape == (len(csv), 8)
    np.testing.assert_allclose(tum[:, 0], csv["t"], atol=1e-6)
    truth = np.loadtxt(out / "truth.tum")
    # The TUM attitude is the CSV's roll/pitch/yaw (FRD body in NED), written as FLU body in ENU:
    # the body's forward axis keeps its direction, its right axis becomes minus the left one.
    enu_ned = np.array([[0, 1, 0], [1, 0, 0], [0, 0, -1]])
    for k in (0, len(csv) // 2, len(csv) - 1):
        R_nb = euler_to_dcm(
            *np.radians([csv["roll_deg"][k], csv["pitch_deg"][k], csv["yaw_deg"][k]])
        )
        R = _quat_to_dcm(tum[k, 4:8])
        np.testing.assert_allclose(R[:, 0], enu_ned @ R_nb[:, 0], atol=1e-5)
        np.testing.assert_allclose(R[:, 1], -(enu_ned @ R_nb[:, 1]), atol=1e-5)
        np.testing.assert_allclose(R[:, 2], -(enu_ned @ R_nb[:, 2]), atol=1e-5)
    # Positions are ENU: x east, y north, z up, from the CSV's latitude, longitude and height.
    from gnssacc.core.earth import LocalTangentFrame

    head = (out / "trajectory_ekf.tum").read_text().splitlines()[0]
    lat0, lon0, h0 = (
        float(x)
        for x in re.search(r"origin lat (\S+) deg, lon (\S+) deg, h (\S+) m", head).groups()
    )
    p_n = LocalTangentFrame(np.radians(lat0), np.radians(lon0), h0).to_ned(
        np.radians(csv["lat_deg"]), np.radians(csv["lon_deg"]), csv["h_m"]
    )
    np.testing.assert_allclose(
        tum[:, 1:4], np.column_stack([p_n[:, 1], p_n[:, 0], -p_n[:, 2]]), atol=2e-3
    )
    # Estimates and truth share the frame: the EKF is within metres of the truth at common epochs.
    common, ia, ib = np.intersect1d(
        np.round(tum[:, 0], 3), np.round(truth[:, 0], 3), return_indices=True
    )
    assert len(common) > 50
    assert np.sqrt(np.mean(np.sum((tum[ia, 1:4] - truth[ib, 1:4]) ** 2, axis=1))) < 6.0


def test_bench_command(run_dir, tmp_path, capsys):
    out = tmp_path / "bench.json"
    assert (
        main(
            [
                "bench",
                str(run_dir),
                "--seeds",
                "0-2",
                "--methods",
                "ekf,ekf-acc",
                "--jobs",
                "2",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    text = capsys.readouterr().out
    assert "ekf-acc" in text and "p (paired)" in text
    data = json.loads(out.read_text())
    assert set(data["per_seed"]) == {"0", "1", "2"}
    s = data["summary"]
    assert s["ekf-acc"]["baseline"] == "ekf" and 0.0 <= s["ekf-acc"]["p_value"] <= 1.0
    per = [data["per_seed"][k]["ekf"][0] for k in ("0", "1", "2")]
    assert s["ekf"]["mean"] == pytest.approx(np.mean(per))
    # Different seeds are different noise draws.
    assert len(set(np.round(per, 6))) == 3


def test_bench_bad_seeds(capsys):
    assert main(["bench", "--seeds", "a-b"]) == 2
    assert "--seeds" in capsys.readouterr().err


def _read_odometry(path):
    """Every message of an exported bag, read back with rosbags: {topic: [(t, msg)]}."""
    from rosbags.highlevel import AnyReader

    out = {}
    with AnyReader([path]) as reader:
        for conn, _, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            out.setdefault(conn.topic, []).append(
                (msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec, msg)
            )
    return out


@pytest.mark.parametrize("kind, name", [("bag", "trajectories"), ("ros1bag", "trajectories.bag")])
def test_odometry_bag_export_reads_back_as_the_csv_trajectory(
    kind, name, run_dir, tmp_path, capsys
):
    from gnssacc.core.earth import LocalTangentFrame
    from gnssacc.outputs.odombag import ORIGIN_TOPIC, topic_of

    out = tmp_path / "o"
    assert (
        main(
            [
                "run",
                str(run_dir),
                "--methods",
                "ekf,smoother",
                "--tune",
                "none",
                "--no-plots",
                "--export",
                kind,
                "--out",
                str(out),
            ]
        )
        == 0
    )
    capsys.readouterr()
    msgs = _read_odometry(out / name)
    assert set(msgs) == {ORIGIN_TOPIC, topic_of("truth")} | {
        topic_of(m) for m in ("ekf", "smoother", "smoother-online")
    }
    fix = msgs[ORIGIN_TOPIC][0][1]
    origin = LocalTangentFrame(*np.radians([fix.latitude, fix.longitude]), fix.altitude)
    for method in ("ekf", "smoother-online"):
        csv = np.genfromtxt(out / f"trajectory_{method}.csv", delimiter=",", names=True)
        got = msgs[topic_of(method)]
        assert len(got) == len(csv)
        t = np.array([s for s, _ in got])
        np.testing.assert_allclose(t, csv["t"], atol=1e-6)
        # Positions: ENU in the bag, lat/lon/h in the CSV, compared in NED through the stated origin.
        enu = np.array(
            [
                [m.pose.pose.position.x, m.pose.pose.position.y, m.pose.pose.position.z]
                for _, m in got
            ]
        )
        ned = origin.to_ned(np.radians(csv["lat_deg"]), np.radians(csv["lon_deg"]), csv["h_m"])
        np.testing.assert_allclose(enu, ned[:, [1, 0, 2]] * [1, 1, -1], atol=2e-3)
        # Attitude: the FLU->ENU quaternion is the CSV's roll/pitch/yaw (FRD->NED) in ROS axes.
        flu_frd, enu_ned = (
            np.diag([1.0, -1.0, -1.0]),
            np.array([[0.0, 1, 0], [1, 0, 0], [0, 0, -1]]),
        )
        for k in (0, len(csv) // 2, len(csv) - 1):
            q = got[k][1].pose.pose.orientation
            R_nb = euler_to_dcm(
                *np.radians([csv["roll_deg"][k], csv["pitch_deg"][k], csv["yaw_deg"][k]])
            )
            np.testing.assert_allclose(
                _quat_to_dcm([q.x, q.y, q.z, q.w]), enu_ned @ R_nb @ flu_frd, atol=1e-5
            )
            # Covariance diagonal: east, north, up sigmas of the CSV squared.
            cov = np.asarray(got[k][1].pose.covariance).reshape(6, 6)
            np.testing.assert_allclose(
                np.sqrt(np.diag(cov)[:3]),
                [csv["se_m"][k], csv["sn_m"][k], csv["sd_m"][k]],
                rtol=1e-4,
            )
            # Twist: the NED velocity expressed in body FLU axes.
            v = got[k][1].twist.twist.linear
            v_ned = np.array([csv["vn"][k], csv["ve"][k], csv["vd"][k]])
            np.testing.assert_allclose(
                enu_ned @ R_nb @ flu_frd @ [v.x, v.y, v.z], enu_ned @ v_ned, atol=2e-4
            )


def test_truth_without_attitude_is_exported_as_positions_only_and_says_so(tmp_path):
    from dataclasses import replace

    from gnssacc.core.errors import DataWarning
    from gnssacc.outputs.export import write_truth_tum

    run = simulate("car", 30.0, noise="white", seed=1)
    run = replace(run, truth=replace(run.truth, rpy=None))
    with pytest.warns(DataWarning, match="trans_part"):
        path = write_truth_tum(run, tmp_path)
    assert path.name == "truth.tum"  # one name whatever the truth holds
    assert "POSITIONS ONLY" in path.read_text().splitlines()[0]
    data = np.loadtxt(path)
    p_n = run.origin.to_ned(run.truth.lat, run.truth.lon, run.truth.h)
    np.testing.assert_allclose(
        data[:, 1:4], np.column_stack([p_n[:, 1], p_n[:, 0], -p_n[:, 2]]), atol=1e-5
    )
    np.testing.assert_allclose(data[:, 4:8], np.tile([0, 0, 0, 1.0], (len(data), 1)))


def test_report_reads_the_filters_own_pass(run_dir, tmp_path, monkeypatch):
    """One pass: the observability section comes from the ekf-acc run itself (no second EKF
    run), and equals a separate replay of that filter from the same start."""
    import gnssacc
    from gnssacc.analysis import observability as ob

    res = gnssacc.process(str(run_dir), methods=["ekf", "ekf-acc"], tune="none")
    ident = res.ident
    again = ob.replay_ekf(
        res.run,
        ident.cfg,
        "ekf-acc",
        quality=ident.quality,
        init=ident.init,
        stationary=ident.stationary,
    )
    a, b = ob.aiding_information(res.replay).summary(), ob.aiding_information(again).summary()
    for name in ob.STATE_NAMES:
        assert a[name]["pos_acc"] == pytest.approx(b[name]["pos_acc"], rel=1e-9, abs=1e-12)

    def no_second_pass(*args, **kwargs):
        raise AssertionError("the report ran the filter again")

    monkeypatch.setattr(ob, "replay_ekf", no_second_pass)
    out = res.save(tmp_path / "r", report=True, plots=False)
    assert "position + acceleration" in (out / "report.html").read_text()
