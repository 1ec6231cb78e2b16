"""TUM export, the Monte-Carlo bench with its paired test, and the HTML report."""
import json

import numpy as np
import pytest

from gnssacc.cli import main
from gnssacc.export import dcm_to_quaternion
from gnssacc.montecarlo import paired_permutation_pvalue, parse_seeds
from gnssacc.rotations import euler_to_dcm, rotvec_to_dcm
from gnssacc.sources.csvdir import write_csv_run
from gnssacc.sources.sim import simulate


def _quat_to_dcm(q):
    x, y, z, w = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


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
    write_csv_run(simulate("car", duration_s=90.0, imu_grade="industrial", noise="white", seed=1), path)
    return path


def test_run_with_report_and_tum_export(run_dir, tmp_path, capsys):
    out = tmp_path / "o"
    assert main(["run", str(run_dir), "--methods", "ekf,smoother", "--report", "--export", "tum", "--out",
                 str(out)]) == 0
    capsys.readouterr()
    page = (out / "report.html").read_text()
    for name in ("errors.png", "trajectory.png", "sigmas.png"):
        assert (out / name).is_file() and f'src="{name}"' in page
    assert "IMU data quality" in page and "ekf" in page
    # The observability section: motion shares that add up, and per-state variance shares.
    assert "Observability" in page and "position + acceleration" in page
    import re
    shares = [float(x) for x in re.findall(r"<tr><td>(?:stationary|straight|accelerating|turning)</td><td>([0-9.]+)", page)]
    assert len(shares) == 4 and sum(shares) == pytest.approx(100.0, abs=0.2)
    tum = np.loadtxt(out / "trajectory_ekf.tum")
    csv = np.genfromtxt(out / "trajectory_ekf.csv", delimiter=",", names=True)
    assert tum.shape == (len(csv), 8)
    np.testing.assert_allclose(tum[:, 0], csv["t"], atol=1e-6)
    truth = np.loadtxt(out / "truth.tum")
    # The TUM attitude is the CSV's roll/pitch/yaw.
    for k in (0, len(csv) // 2, len(csv) - 1):
        R = euler_to_dcm(*np.radians([csv["roll_deg"][k], csv["pitch_deg"][k], csv["yaw_deg"][k]]))
        np.testing.assert_allclose(_quat_to_dcm(tum[k, 4:8]), R, atol=1e-5)
    # Estimates and truth share the frame: the EKF is within metres of the truth at common epochs.
    common, ia, ib = np.intersect1d(np.round(tum[:, 0], 3), np.round(truth[:, 0], 3), return_indices=True)
    assert len(common) > 50
    assert np.sqrt(np.mean(np.sum((tum[ia, 1:4] - truth[ib, 1:4]) ** 2, axis=1))) < 6.0


def test_bench_command(run_dir, tmp_path, capsys):
    out = tmp_path / "bench.json"
    assert main(["bench", str(run_dir), "--seeds", "0-2", "--methods", "ekf,ekf-acc", "--jobs", "2",
                 "--out", str(out)]) == 0
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
