"""GNSS files through the estimators: the same fixes as gnss.csv, gnss.pos and gnss.nmea give the
same PRMSE to the files' precision, a .pos file's per-fix covariance (with its correlations) is
the EKF's R, and ``--gnss FILE`` replaces a source's fixes."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import gnssacc
from gnssacc.core.config import load_config
from gnssacc.core.errors import DataWarning, InputError
from gnssacc.estimators.ekf import EkfObserver
from gnssacc.prepare.passes import run_ekf
from gnssacc.pipeline import prepare
from gnssacc.sources.csvdir import load_csv_run, write_csv_run
from gnssacc.sources.sim import simulate

UNIX_2024 = 1709294400.0
#: Fixed settings, so that the three formats meet the same estimator.
CONFIG = {"mounting": {"imu_time_offset_s": 0.0, "imu_to_body_rpy_deg": [0.0, 0.0, 0.0]}}


@pytest.fixture(scope="module")
def sim_run():
    return simulate(
        "car", 120.0, imu_grade="industrial", t_start_s=UNIX_2024, noise="white", seed=5
    )


def test_csv_pos_and_nmea_give_the_same_prmse(sim_run, tmp_path):
    """The formats round the fixes to 0.1 mm (.pos: 1e-9 deg, 1e-4 m; NMEA: 1e-7 arc minute, 1e-4 m)
    and the sigmas to 0.1 mm: a filter moves its estimate by at most its gain (< 1) times such a
    change per fix, so the PRMSEs (metres) agree far inside 1 mm, while a wrong time system (18 s
    of leap seconds: 300 m at 17 m/s) or a wrong axis would miss by metres."""
    prmse = {}
    for fmt in ("csv", "pos", "nmea"):
        write_csv_run(sim_run, tmp_path / fmt, gnss_format=fmt)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DataWarning)
            res = gnssacc.process(
                str(tmp_path / fmt), methods=["ekf"], tune="none", config=CONFIG, preset="none"
            )
        prmse[fmt] = res.prmse()
        assert res.run.meta.get("gnss_format", "csv") in ("csv", "rtklib-pos", "nmea")
    for fmt in ("pos", "nmea"):
        assert prmse[fmt]["ekf"] == pytest.approx(prmse["csv"]["ekf"], abs=1e-3), fmt
        assert prmse[fmt]["gnss"] == pytest.approx(prmse["csv"]["gnss"], abs=1e-3), fmt


class _Rs(EkfObserver):
    def __init__(self):
        self.R = []

    def update(self, t, m, nis, used, s):
        if m.kind == "pos":
            self.R.append((t, m.R.copy()))


def test_pos_covariance_with_correlations_is_the_ekf_r(sim_run, tmp_path):
    run = simulate("car", 60.0, t_start_s=UNIX_2024, noise="white", seed=5)
    m = len(run.gnss)
    rng = np.random.default_rng(3)
    corr = np.column_stack(
        [rng.uniform(-0.5, 0.5, m), rng.uniform(-0.3, 0.3, m), rng.uniform(-0.3, 0.3, m)]
    )
    run.gnss.corr_ned = corr
    write_csv_run(run, tmp_path, gnss_format="pos")
    cfg = load_config(None, overrides=CONFIG)
    loaded = load_csv_run(tmp_path, cfg)
    ident = prepare(loaded, cfg, "none")
    obs = _Rs()
    run_ekf(
        ident.run,
        ident.cfg,
        "ekf",
        init=ident.init,
        quality=ident.quality,
        stationary=ident.stationary,
        observer=obs,
    )
    assert len(obs.R) > 40
    expected = {
        float(t): run.gnss.cov_ned(k) for k, t in enumerate(run.gnss.t)
    }  # as simulated, unrounded
    for t, R in obs.R:
        # the file holds sigmas and signed roots of covariances to 1e-4 m: covariances to ~1e-3 m^2 of 25 m^2
        np.testing.assert_allclose(R, expected[t], atol=2e-3)
        assert abs(R[0, 1]) > 0.0  # correlated, not diagonal


def test_gnss_option_replaces_a_sources_fixes(sim_run, tmp_path):
    write_csv_run(sim_run, tmp_path / "pos", gnss_format="pos")
    other = simulate(
        "car", 120.0, t_start_s=UNIX_2024, noise="gm", seed=9
    )  # same IMU clock, other fixes
    write_csv_run(other, tmp_path / "run")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        run = gnssacc.load(
            str(tmp_path / "run"), config=CONFIG, preset="none", gnss=tmp_path / "pos" / "gnss.pos"
        )
    assert run.meta["gnss_format"] == "rtklib-pos" and run.meta["gnss_clock"] == "unix"
    np.testing.assert_allclose((run.gnss.lat - sim_run.gnss.lat) * 6.4e6, 0, atol=1e-3)
    with pytest.raises(InputError, match="--noise and --gnss-from-truth"):
        gnssacc.load(str(tmp_path / "run"), gnss=tmp_path / "pos" / "gnss.pos", noise="white")


def test_smoother_gnss_factors_use_the_full_covariance(tmp_path):
    """The GM factor's error with a full covariance is 0.5 e^T C^-1 e; the smoother's residual
    chi-square whitens with C too (with no estimate uncertainty: expectation 3); and a smoother pass
    on correlated .pos fixes runs and scores them."""
    gtsam = pytest.importorskip("gtsam")
    from types import SimpleNamespace

    from gnssacc.factors.gnss_error_factors import gnss_position_gm_factor

    from gnssacc.estimators.aids.gnss_position import residual_chi2

    from gnssacc.prepare.passes import run_smoother

    cov = np.array([[4.0, 1.2, -0.5], [1.2, 2.0, 0.3], [-0.5, 0.3, 9.0]])
    p_fix, lever = np.array([1.0, -2.0, 0.5]), np.array([0.3, 0.1, -0.2])
    f = gnss_position_gm_factor(0, 1, p_fix, lever, np.sqrt(np.diag(cov)), cov)
    values = gtsam.Values()
    pose = gtsam.Pose3(gtsam.Rot3.Ypr(0.3, -0.1, 0.05), np.array([2.0, 1.0, -1.0]))
    g = np.array([0.2, -0.1, 0.4])
    values.insert(0, pose)
    values.insert(1, g)
    e = pose.translation() + pose.rotation().matrix() @ lever + g - p_fix
    assert f.error(values) == pytest.approx(0.5 * e @ np.linalg.solve(cov, e), rel=1e-9)
    R = pose.rotation().matrix()
    rec = SimpleNamespace(
        R=R[None], p_n=np.array([pose.translation()]), cov_pose=np.zeros((1, 6, 6))
    )
    gm = (g[None], np.zeros((1, 3, 3)), np.zeros((1, 6, 3)))
    chi2, expected = residual_chi2(rec, np.array([0]), p_fix[None], cov[None], lever, gm)
    assert chi2[0] == pytest.approx(e @ np.linalg.solve(cov, e)) and expected[0] == pytest.approx(
        3.0
    )

    run = simulate("car", 60.0, t_start_s=UNIX_2024, noise="white", seed=5)
    run.gnss.corr_ned = np.tile([0.4, -0.2, 0.1], (len(run.gnss), 1))
    write_csv_run(run, tmp_path, gnss_format="pos")
    cfg = load_config(None, overrides=CONFIG)
    ident = prepare(load_csv_run(tmp_path, cfg), cfg, "none")
    sols = run_smoother(
        ident.run,
        ident.cfg,
        "smoother",
        init=ident.init,
        quality=ident.quality,
        stationary=ident.stationary,
    )
    assert sols["smoother"].stats["n_gps_factors"] > 40


def test_gnss_file_on_a_bags_unix_clock(tmp_path):
    """A bag's header stamps are UNIX time: a GPST .pos of the same fixes lands on exactly the
    bag's own fix stamps (18 leap seconds removed), and so does an NMEA log in UTC."""
    pytest.importorskip("rosbags")
    from dataclasses import replace

    from gnssacc.sources.bagwrite import write_bag
    from gnssacc.sources.gnssfile import write_gnss_file

    run = simulate("car", 60.0, noise="white", seed=5)
    bag = write_bag(run, tmp_path / "bag", "ros2-sqlite3", time_offset_s=UNIX_2024)
    shifted = replace(run.gnss, t=run.gnss.t + UNIX_2024)
    for kind in ("pos", "nmea"):
        path = write_gnss_file(tmp_path / f"fixes.{kind}", shifted, kind, truth=None)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DataWarning)
            own = gnssacc.load(str(bag), config=CONFIG, preset="none")
            other = gnssacc.load(str(bag), config=CONFIG, preset="none", gnss=path)
        np.testing.assert_allclose(other.gnss.t, own.gnss.t, atol=5e-3)
        np.testing.assert_allclose((other.gnss.lat - own.gnss.lat) * 6.4e6, 0, atol=1e-3)
        assert other.meta["gnss_clock"] == "unix"
