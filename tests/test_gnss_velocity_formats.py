"""GNSS velocities in every format: a simulated run's velocities (truth velocity plus noise)
written and read back within each format's resolution, hand-written files in the real layouts
read with the right axes and signs, the bag's velocity topic told apart from wheel odometry, and
bad input refused with one line (exit 2)."""

from __future__ import annotations

import dataclasses

import warnings
from pathlib import Path

import numpy as np
import pytest

from gnssacc.cli import main
from gnssacc.core.config import load_config
from gnssacc.core.earth import R_en, llh_to_ecef
from gnssacc.core.errors import DataWarning, InputError
from gnssacc.core.recording import GnssVelocity
from gnssacc.sources.csvdir import load_csv_run, write_csv_run
from gnssacc.sources.gnss_vel import COURSE_MIN_SPEED_MPS, DEFAULT_VELOCITY_SIGMA_MPS
from gnssacc.sources.gnssfile import load_gnss_data
from gnssacc.sources.nmea import checksum
from gnssacc.sources.rtklib import read_pos
from gnssacc.sources.sim import simulate

UNIX_2024 = 1709294400.0
CFG = {"mounting": {"imu_time_offset_s": 0.0, "imu_to_body_rpy_deg": [0.0, 0.0, 0.0]}}
SIGMA = np.array([0.05, 0.06, 0.1])
CORR = np.array([0.2, -0.1, 0.05])


def with_velocity(run, seed: int = 0, corr: bool = True):
    """The run with GNSS velocities at its fixes: the truth's velocity plus white noise of
    :data:`SIGMA` (correlated by :data:`CORR`), in this test (the simulator may not make them)."""
    g, tr = run.gnss, run.truth
    v = np.column_stack([np.interp(g.t, tr.t, tr.v_n[:, i]) for i in range(3)])
    C = (
        np.diag(SIGMA)
        @ np.array([[1, CORR[0], CORR[1]], [CORR[0], 1, CORR[2]], [CORR[1], CORR[2], 1]])
        @ np.diag(SIGMA)
    )
    v = v + np.random.default_rng(seed).multivariate_normal(np.zeros(3), C, len(g))
    run.gnss_vel = GnssVelocity(
        g.t.copy(),
        v,
        np.tile(SIGMA, (len(g), 1)),
        np.tile(CORR, (len(g), 1)) if corr else None,
        True,
    )
    return run


@pytest.fixture(scope="module")
def sim_run():
    run = simulate("car", 90.0, t_start_s=UNIX_2024, noise="white", seed=4)
    return with_velocity(run)


def _load(root):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        return load_csv_run(root, load_config(overrides=CFG))


# --- round trips ---------------------------------------------------------------------------------


def test_csv_round_trip_is_exact(sim_run, tmp_path):
    write_csv_run(sim_run, tmp_path)
    back = _load(tmp_path).gnss_vel
    v = sim_run.gnss_vel
    assert back.sigma_stated
    np.testing.assert_array_equal(back.t, v.t)
    np.testing.assert_array_equal(back.v_ned, v.v_ned)
    np.testing.assert_array_equal(back.sigma_ned, v.sigma_ned)
    np.testing.assert_allclose(back.corr_ned, v.corr_ned, atol=1e-15)


def test_pos_round_trip_to_rtklibs_precision(sim_run, tmp_path):
    """RTKLIB writes velocities and sigmas to 1e-5 m/s and the cross terms as signed roots to
    1e-5 (m/s): a correlation then carries about 2e-5 / sqrt(|c|) relative error."""
    write_csv_run(sim_run, tmp_path, gnss_format="pos")
    back = _load(tmp_path).gnss_vel
    v = sim_run.gnss_vel
    np.testing.assert_allclose(back.t, v.t, atol=1e-3)
    np.testing.assert_allclose(back.v_ned, v.v_ned, atol=5.1e-6)
    np.testing.assert_allclose(back.sigma_ned, v.sigma_ned, atol=5.1e-6)
    np.testing.assert_allclose(back.corr_ned, v.corr_ned, atol=2e-3)
    assert back.sigma_stated


def test_ubx_round_trip_to_nav_pvt_precision(sim_run, tmp_path):
    """NAV-PVT holds mm/s velocities and one speed accuracy sAcc (the largest axis sigma)."""
    write_csv_run(sim_run, tmp_path, gnss_format="ubx")
    run = _load(tmp_path)
    back, g = run.gnss_vel, sim_run.gnss
    np.testing.assert_allclose(back.t, sim_run.gnss_vel.t, atol=1e-3)
    np.testing.assert_allclose(back.v_ned, sim_run.gnss_vel.v_ned, atol=5.1e-4)
    np.testing.assert_allclose(back.sigma_ned, SIGMA.max(), atol=5e-4)
    # the fixes too: 1e-7 deg (1.1 cm), 1 mm, hAcc the larger horizontal sigma
    np.testing.assert_allclose((run.gnss.lat - g.lat) * 6.4e6, 0, atol=0.012)
    np.testing.assert_allclose((run.gnss.lon - g.lon) * 6.4e6, 0, atol=0.012)
    np.testing.assert_allclose(run.gnss.h, g.h, atol=5.1e-4)
    np.testing.assert_allclose(run.gnss.sigma_ned[:, 2], g.sigma_ned[:, 2], atol=5e-4)
    assert run.meta["gnss_format"] == "ubx"


def test_nmea_round_trip_horizontal_with_the_course_rule(sim_run, tmp_path):
    """Speed in knots to 1e-3 and course to 0.01 deg; no down axis; below the stated speed the
    course is not used: zero velocity with the speed-based sigma."""
    write_csv_run(sim_run, tmp_path, gnss_format="nmea")
    back = _load(tmp_path).gnss_vel
    v = sim_run.gnss_vel.v_ned
    s = np.hypot(v[:, 0], v[:, 1])
    assert not back.sigma_stated and np.all(np.isnan(back.v_ned[:, 2]))
    np.testing.assert_allclose(back.t, sim_run.gnss_vel.t, atol=5e-3)
    fast = s >= COURSE_MIN_SPEED_MPS + 0.01
    tol = 3e-4 + s[fast] * np.radians(0.005)
    assert np.all(np.abs(back.v_ned[fast, :2] - v[fast, :2]) <= tol[:, None])
    np.testing.assert_allclose(back.sigma_ned[fast, :2], DEFAULT_VELOCITY_SIGMA_MPS[0])
    slow = s < COURSE_MIN_SPEED_MPS - 0.01
    assert slow.any()  # the car starts standing
    np.testing.assert_array_equal(back.v_ned[slow, :2], 0.0)
    np.testing.assert_allclose(
        back.sigma_ned[slow, 0], np.hypot(s[slow], DEFAULT_VELOCITY_SIGMA_MPS[0]), atol=1e-3
    )


@pytest.mark.parametrize("kind", ["ros2-sqlite3", "ros1-rooad", "mcap"])
def test_bag_round_trip_and_choice(sim_run, tmp_path, kind):
    from gnssacc.sources.bagwrite import write_bag
    from gnssacc.sources.rosbag import load_bag_run

    run = simulate("car", 60.0, noise="white", seed=2)
    run = with_velocity(run)
    path = tmp_path / ("b.bag" if kind == "ros1-rooad" else "b.mcap" if kind == "mcap" else "b")
    write_bag(run, path, kind)
    back = load_bag_run(path, load_config())
    v = run.gnss_vel
    assert back.meta["topics"]["gnss_velocity"] == "/gnss/vel"
    np.testing.assert_allclose(back.gnss_vel.t, v.t, atol=1e-9)
    np.testing.assert_allclose(back.gnss_vel.v_ned, v.v_ned, atol=1e-12)
    np.testing.assert_allclose(back.gnss_vel.sigma_ned, v.sigma_ned, atol=1e-12)
    np.testing.assert_allclose(back.gnss_vel.corr_ned, v.corr_ned, atol=1e-12)


def test_bag_velocity_is_told_apart_from_wheel_odometry(tmp_path):
    """A plain TwistStamped GNSS velocity beside a drive controller's Odometry: each is what it
    is. A body-frame forward speed stamped at the fix epochs in the fixes' frame (only its
    values can tell) disagrees with the fixes' differences and is refused as GNSS velocity."""
    from gnssacc.sources.bagwrite import write_bag
    from gnssacc.sources.rosbag import inspect_bag, load_bag_run

    run = with_velocity(simulate("car", 60.0, noise="white", seed=2, odom_hz=50.0), corr=False)
    write_bag(run, tmp_path / "a", "ros2-sqlite3", odom_topic="/odom", gnss_vel_covariance=False)
    back = load_bag_run(tmp_path / "a", load_config())
    assert back.meta["topics"]["gnss_velocity"] == "/gnss/vel"
    assert back.meta["topics"]["odometry"] == "/odom" and back.odometry is not None
    assert not back.gnss_vel.sigma_stated  # TwistStamped: the default sigma
    np.testing.assert_allclose(back.gnss_vel.v_ned, run.gnss_vel.v_ned, atol=1e-12)
    # a forward speed as a twist (linear.x, ENU x): written as the NED velocity [0, speed, 0]
    v = run.gnss_vel
    speed = np.hypot(v.v_ned[:, 0], v.v_ned[:, 1])
    body = GnssVelocity(v.t, np.column_stack([0 * speed, speed, 0 * speed]), v.sigma_ned)
    run.gnss_vel = body
    write_bag(run, tmp_path / "b", "ros2-sqlite3", gnss_vel_covariance=False)
    back = load_bag_run(tmp_path / "b", load_config())
    assert back.gnss_vel is None and "gnss_velocity" not in back.meta["topics"]
    text = inspect_bag(tmp_path / "b")
    assert "not GNSS velocity /gnss/vel: read as ENU it disagrees with the fixes' differences" in (
        text
    )
    # the forward speed is then the wheel odometry (a TwistStamped that moves)
    assert back.meta["topics"]["odometry"] == "/gnss/vel"


# --- hand-written files in the real layouts ---------------------------------------------------

POS_HEAD = (
    "% program   : RTKPOST ver.2.4.3 b34\n"
    "% (lat/lon/height=WGS84/ellipsoidal,Q=1:fix,2:float,3:sbas,4:dgps,5:single,6:ppp,"
    "ns=# of satellites)\n"
    "%  GPST                  latitude(deg) longitude(deg)  height(m)   Q  ns   sdn(m)   sde(m)"
    "   sdu(m)  sdne(m)  sdeu(m)  sdun(m) age(s)  ratio    vn(m/s)    ve(m/s)    vu(m/s)"
    "      sdvn     sdve     sdvu    sdvne    sdveu    sdvun\n"
)


def test_pos_velocity_axes_signs_and_cross_terms(tmp_path):
    """``vu`` is up (NED down is its negative); the cross terms are signed roots of the ENU
    covariance: sdvne the E-N, sdveu the E-U, sdvun the U-N term (RTKLIB's ``outpos``)."""
    line = (
        "2024/03/01 12:00:00.000   47.480954411   19.056534073   181.7826   5   9   2.1245"
        "   1.9103   3.7333   0.1328   0.9211   1.1049   0.00    0.0    1.00000    2.00000"
        "    3.00000   0.04000  0.03000  0.08000  0.01000 -0.02000  0.00500"
    )
    (tmp_path / "v.pos").write_text(POS_HEAD + line + "\n")
    pos = read_pos(tmp_path / "v.pos")
    np.testing.assert_allclose(pos.vel_ned[0], [1.0, 2.0, -3.0])
    C = pos.vel_cov_ned[0]
    np.testing.assert_allclose(np.diag(C), [0.04**2, 0.03**2, 0.08**2])
    assert C[0, 1] == pytest.approx(0.01**2)  # N-E = E-N
    assert C[1, 2] == pytest.approx(+(0.02**2))  # E-D = -(E-U) = -(-0.02^2)
    assert C[0, 2] == pytest.approx(-(0.005**2))  # N-D = -(U-N)


def test_pos_xyz_velocity_is_rotated_from_ecef(tmp_path):
    lat, lon, h = np.radians(47.48), np.radians(19.05), 180.0
    r = llh_to_ecef(lat, lon, h)
    v_ned = np.array([3.0, -4.0, 0.5])
    v_e = R_en(lat, lon).T @ v_ned
    head = (
        "%  GPST                      x-ecef(m)      y-ecef(m)      z-ecef(m)   Q  ns   sdx(m)"
        "   sdy(m)   sdz(m)  sdxy(m)  sdyz(m)  sdzx(m) age(s)  ratio    vx(m/s)    vy(m/s)"
        "    vz(m/s)      sdvx     sdvy     sdvz    sdvxy    sdvyz    sdvzx\n"
    )
    line = (
        f"2024/03/01 12:00:00.000 {r[0]:14.4f} {r[1]:14.4f} {r[2]:14.4f}   5   9   1.0000   1.0000"
        "   1.0000   0.0000   0.0000   0.0000   0.00    0.0 "
        + " ".join(f"{x:10.5f}" for x in v_e)
        + "   0.05000  0.05000  0.05000  0.00000  0.00000  0.00000"
    )
    (tmp_path / "x.pos").write_text(head + line + "\n")
    pos = read_pos(tmp_path / "x.pos")
    np.testing.assert_allclose(pos.vel_ned[0], v_ned, atol=2e-5)
    np.testing.assert_allclose(pos.vel_cov_ned[0], 0.05**2 * np.eye(3), atol=1e-12)


def _sentence(body: str) -> str:
    return f"${body}*{checksum(body):02X}"


def test_nmea_rmc_vtg_speed_course_and_void(tmp_path):
    """RMC's speed (knots) and course; a void RMC (status V) gives none, its epoch takes the
    VTG's (km/h when the knots field is empty); a standing receiver's course is not used."""
    gga = "GPGGA,{},4807.0380,N,01131.0000,E,1,08,0.9,545.4,M,46.9,M,,"
    lines = []
    for k, (rmc, vtg) in enumerate(
        [
            ("A,010.0,090.0", None),  # 10 kn due east
            ("V,010.0,090.0", "180.0,T,,M,,N,36.0,K,A"),  # void RMC: VTG 36 km/h due south
            ("A,000.5,045.0", None),  # 0.26 m/s: the course is not used
        ]
    ):
        tod = f"1200{k:02d}.00"
        st, sp, co = rmc.split(",")
        lines.append(_sentence(f"GPRMC,{tod},{st},4807.0380,N,01131.0000,E,{sp},{co},010324,,,A"))
        if vtg:
            lines.append(_sentence(f"GPVTG,{vtg}"))
        lines.append(_sentence(gga.format(tod)))
    (tmp_path / "f.nmea").write_text("\r\n".join(lines) + "\r\n")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        _, vel, _ = load_gnss_data(tmp_path / "f.nmea", load_config(), UNIX_2024 + np.arange(9.0))
    kn = 1852.0 / 3600.0
    np.testing.assert_allclose(vel.v_ned[0, :2], [0.0, 10 * kn], atol=1e-12)
    np.testing.assert_allclose(vel.v_ned[1, :2], [-10.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(vel.v_ned[2, :2], [0.0, 0.0])
    assert vel.sigma_ned[2, 0] == pytest.approx(np.hypot(0.5 * kn, DEFAULT_VELOCITY_SIGMA_MPS[0]))
    assert np.all(np.isnan(vel.v_ned[:, 2])) and np.all(np.isnan(vel.sigma_ned[:, 2]))


def test_gnss_csv_horizontal_velocity_and_empty_cells(tmp_path):
    """``vn, ve`` without ``vd``: horizontal; an empty cell: no velocity at that fix; no sigma
    columns: the documented default, not stated."""
    run = simulate("car", 20.0, seed=1)
    write_csv_run(run, tmp_path)
    lines = (tmp_path / "gnss.csv").read_text().splitlines()
    head = next(i for i, line in enumerate(lines) if line.startswith("t,"))
    lines[head] += ",vn,ve"
    for i in range(head + 1, len(lines)):
        lines[i] += ",1.5,-2.5" if i != head + 3 else ",,"
    (tmp_path / "gnss.csv").write_text("\n".join(lines) + "\n")
    vel = _load(tmp_path).gnss_vel
    assert len(vel) == len(run.gnss) - 1 and not vel.sigma_stated
    np.testing.assert_array_equal(vel.v_ned[:, :2], [[1.5, -2.5]] * len(vel))
    assert np.all(np.isnan(vel.v_ned[:, 2]))
    np.testing.assert_array_equal(vel.sigma_ned[0, :2], DEFAULT_VELOCITY_SIGMA_MPS[:2])


# --- bad input -----------------------------------------------------------------------------------


def _csv_with(tmp_path, cols: str, value: str):
    run = simulate("car", 20.0, seed=1)
    write_csv_run(run, tmp_path)
    lines = (tmp_path / "gnss.csv").read_text().splitlines()
    head = next(i for i, line in enumerate(lines) if line.startswith("t,"))
    lines[head] += "," + cols
    for i in range(head + 1, len(lines)):
        lines[i] += "," + value
    (tmp_path / "gnss.csv").write_text("\n".join(lines) + "\n")
    return tmp_path


@pytest.mark.parametrize(
    "cols, value, message",
    [
        ("vn", "1.0", "velocity columns vn need vn and ve"),
        ("vn,ve", "1500,20", "GNSS velocity above 600 m/s: not m/s"),
        (
            "vn,ve,vd,sigma_vn",
            "1,2,3,0.1",
            "give all of the columns sigma_vn, sigma_ve, sigma_vd or none",
        ),
        ("vn,ve,sigma_vn,sigma_ve", "1,2,0,0.1", "velocity sigmas must be positive m/s"),
    ],
)
def test_bad_velocity_columns_exit_2_with_one_line(tmp_path, capsys, cols, value, message):
    root = _csv_with(tmp_path, cols, value)
    code = main(["run", str(root), "--out", str(tmp_path / "o"), "--plots", "none"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert err[-1].startswith("gnssacc: error: ") and message in err[-1]


def test_not_a_ubx_log_and_no_nav_pvt(tmp_path):
    from gnssacc.sources.ubx import read_ubx

    (tmp_path / "junk.ubx").write_bytes(b"\xb5\x62" + bytes(range(256)) * 4)
    with pytest.raises(InputError, match="junk.ubx"):
        read_ubx(tmp_path / "junk.ubx")
    from pyubx2 import GET, UBXMessage

    msg = UBXMessage("NAV", "NAV-CLOCK", GET, iTOW=1000, clkB=1, clkD=2, tAcc=3, fAcc=4)
    (tmp_path / "clock.ubx").write_bytes(msg.serialize() * 3)
    with pytest.raises(InputError, match=r"no NAV-PVT message \(NAV-CLOCK 3\)"):
        read_ubx(tmp_path / "clock.ubx")


# --- the public recordings in ../shared/data -----------------------------------------------------

SHARED = Path(__file__).resolve().parents[2] / "shared" / "data"
COMMA = SHARED / "comma2k19_example1"
VN = SHARED / "vn310_static"
needs_comma = pytest.mark.skipif(not COMMA.is_dir(), reason=f"no comma2k19 example at {COMMA}")
needs_vn = pytest.mark.skipif(not VN.is_dir(), reason=f"no VN-310 logs at {VN}")


@needs_comma
def test_comma2k19_reader_and_its_velocity_against_the_reference():
    """The u-blox speed and bearing, as velocities, agree with comma's reference velocity (an
    independent estimate: its optimiser fuses positions, IMU and vision) to about 0.1 m/s."""
    from gnssacc.sources.comma2k19 import REFERENCE_CAVEAT, load_comma2k19

    with pytest.warns(DataWarning, match="comma's own optimiser output"):
        run = load_comma2k19(COMMA, load_config())
    assert (len(run.imu), len(run.gnss), len(run.odometry), len(run.truth.t)) == (
        6256,
        579,
        4974,
        1200,
    )
    assert run.truth.caveat == REFERENCE_CAVEAT and not run.gnss.sigma_stated
    v, tr = run.gnss_vel, run.truth
    ref = np.column_stack([np.interp(v.t, tr.t, tr.v_n[:, i]) for i in range(2)])
    assert np.sqrt(np.mean((v.v_ned[:, :2] - ref) ** 2)) < 0.2
    # the CAN speed is the car's speed to its scale factor
    odo = run.odometry
    speed = np.interp(odo.t, tr.t, np.hypot(tr.v_n[:, 0], tr.v_n[:, 1]))
    assert np.median(odo.v_forward / speed) == pytest.approx(1.0, abs=0.03)


@needs_vn
@pytest.mark.parametrize("log, n_imu, n_fix", [("lckf", 1612, 163), ("tckf", 1638, 166)])
def test_vectornav_reader_static_logs(log, n_imu, n_fix):
    """Standing still: every GNSS velocity within 3 of its stated sigmas of zero."""
    from gnssacc.sources.vectornav import load_vectornav

    run = load_vectornav(VN / f"{log}_vn310-imu.csv")
    assert (len(run.imu), len(run.gnss), len(run.gnss_vel)) == (n_imu, n_fix, n_fix)
    assert run.truth is None and run.gnss.sigma_stated and run.gnss_vel.sigma_stated
    v = run.gnss_vel
    assert np.all(np.abs(v.v_ned) < 3 * v.sigma_ned)
    np.testing.assert_allclose(np.median(run.imu.f_b, axis=0)[2], -9.8, atol=0.1)  # FRD, level


@needs_vn
def test_vectornav_folder_with_two_logs_is_refused_naming_them(tmp_path, capsys):
    code = main(["run", str(VN), "--out", str(tmp_path / "o"), "--plots", "none"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and err[-1].startswith("gnssacc: error: ")
    assert "holds 2 VectorNav exports (lckf_vn310-imu.csv, tckf_vn310-imu.csv)" in err[-1]


@needs_vn
def test_vectornav_partner_missing(tmp_path, capsys):
    import shutil

    shutil.copy(VN / "lckf_vn310-imu.csv", tmp_path / "x-imu.csv")
    code = main(["run", str(tmp_path / "x-imu.csv"), "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and "needs its partner x-gnss.csv" in err[-1]


@needs_vn
@needs_comma
@pytest.mark.parametrize("source", [COMMA, VN / "lckf_vn310-gnss.csv"])
def test_public_recordings_run_directly(tmp_path, capsys, source):
    out = tmp_path / "o"
    args = ["run", str(source), "--out", str(out), "--plots", "none", "--tune", "none"]
    code = main(args + ["--methods", "ekf"])
    assert code == 0, capsys.readouterr().err
    metrics = __import__("json").loads((out / "metrics.json").read_text())
    assert metrics["methods"]["ekf"]["n_epochs"] > 0


def test_same_run_as_csv_pos_ubx_and_a_bag_gives_the_same_prmse(sim_run, tmp_path):
    """One simulated run (with its velocities) written as gnss.csv, .pos, UBX and a ROS 2 bag:
    the EKF's PRMSE with the noise model fixed moves only by the formats' rounding (UBX: 1e-7 deg
    and 1 mm, under 1 cm; .pos: 0.1 mm; a bag holds float64), far inside the acceptance's 1 %."""
    import gnssacc
    from gnssacc.sources.bagwrite import write_bag

    prmse = {}
    sources = {}
    for fmt in ("csv", "pos", "ubx"):
        write_csv_run(sim_run, tmp_path / fmt, gnss_format=fmt)
        sources[fmt] = str(tmp_path / fmt)
    sources["bag"] = str(write_bag(sim_run, tmp_path / "bag", "ros2-sqlite3", truth_topic="/rtk"))
    for fmt, src in sources.items():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DataWarning)
            topics = {"gnss_topic": "/gnss/fix", "truth_topic": "/rtk"} if fmt == "bag" else {}
            res = gnssacc.process(
                src, methods=["ekf"], tune="none", config=CFG, preset="none", **topics
            )
        assert res.run.truth is not None, fmt
        assert res.run.gnss_vel is not None and len(res.run.gnss_vel) == len(sim_run.gnss)
        prmse[fmt] = res.prmse()["ekf"]
    # UBX states one speed accuracy (sAcc) for all axes: it is compared with the CSV run that
    # carries the same information (every axis at the largest axis sigma).
    vel = sim_run.gnss_vel
    iso = np.repeat(np.nanmax(vel.sigma_ned, axis=1, keepdims=True), 3, axis=1)
    same_info = dataclasses.replace(sim_run, gnss_vel=dataclasses.replace(vel, sigma_ned=iso))
    write_csv_run(same_info, tmp_path / "csv-iso", gnss_format="csv")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        res = gnssacc.process(
            str(tmp_path / "csv-iso"), methods=["ekf"], tune="none", config=CFG, preset="none"
        )
    reference = {"pos": prmse["csv"], "ubx": res.prmse()["ekf"], "bag": prmse["csv"]}
    tol = {"pos": 1e-3, "ubx": 1e-2, "bag": 1e-6}
    for fmt, t in tol.items():
        assert prmse[fmt] == pytest.approx(reference[fmt], abs=t), (fmt, prmse, reference)
        assert abs(prmse[fmt] / reference[fmt] - 1) < 0.01


def test_sim_writes_ubx_and_gnss_file_replaces_fixes_and_velocities(tmp_path, capsys):
    """``gnssacc sim --gnss-format ubx`` writes a UBX log of the simulated fixes; the same log as
    ``--gnss FILE`` on another source brings its velocities (here none: the simulator's run has
    none) in place of the source's."""
    from gnssacc.sources.gnssfile import with_gnss_file

    assert main(["sim", str(tmp_path / "s"), "--duration", "30", "--gnss-format", "ubx"]) == 0
    capsys.readouterr()
    run = _load(tmp_path / "s")
    assert run.meta["gnss_format"] == "ubx" and len(run.gnss) >= 30
    ubx = tmp_path / "v.ubx"
    src = with_velocity(simulate("car", 30.0, t_start_s=UNIX_2024, seed=3), corr=False)
    from gnssacc.sources.ubx import write_ubx
    from gnssacc.sources.gnssfile import velocity_at_fixes

    write_ubx(ubx, src.gnss, *velocity_at_fixes(src.gnss_vel, src.gnss.t))
    replaced = with_gnss_file(run, ubx, load_config())
    np.testing.assert_allclose(replaced.gnss_vel.v_ned, src.gnss_vel.v_ned, atol=5.1e-4)


def test_pos_with_part_of_the_velocity_columns_is_refused(tmp_path):
    head = POS_HEAD.replace(
        "    vu(m/s)      sdvn     sdve     sdvu    sdvne    sdveu    sdvun", ""
    )
    line = (
        "2024/03/01 12:00:00.000   47.480954411   19.056534073   181.7826   5   9   2.1245"
        "   1.9103   3.7333   0.1328   0.9211   1.1049   0.00    0.0    1.00000    2.00000"
    )
    (tmp_path / "p.pos").write_text(head + line + "\n")
    with pytest.raises(InputError, match=r"has vn\(m/s\), ve\(m/s\) but not all of"):
        read_pos(tmp_path / "p.pos")


def test_quality_policy_drops_the_velocities_of_dropped_fixes(sim_run, tmp_path):
    from gnssacc.core.recording import FIX_QUALITY

    run = with_velocity(simulate("car", 40.0, t_start_s=UNIX_2024, seed=1))
    q = np.where(np.arange(len(run.gnss)) % 4 == 0, FIX_QUALITY["float"], FIX_QUALITY["single"])
    run.gnss.quality = q
    write_csv_run(run, tmp_path, gnss_format="pos")
    cfg = load_config(overrides={**CFG, "gnss": {"quality": {"float": "drop"}}})
    with pytest.warns(DataWarning, match="quality dropped"):
        back = load_csv_run(tmp_path, cfg)
    kept = q == FIX_QUALITY["single"]
    np.testing.assert_allclose(back.gnss_vel.t, run.gnss.t[kept], atol=1e-3)
    np.testing.assert_allclose(back.gnss_vel.v_ned, run.gnss_vel.v_ned[kept], atol=5.1e-6)


def test_bag_velocity_stamped_late_is_paired_and_a_fast_twist_is_not(tmp_path):
    """A driver that stamps the velocity sentence 70 ms after the position (as it arrives)
    keeps one message per fix at a steady offset: taken. A 50 Hz twist in the fixes' frame is
    not one velocity per fix: refused (whatever its values)."""
    from gnssacc.sources.bagwrite import write_bag
    from gnssacc.sources.rosbag import load_bag_run

    run = with_velocity(simulate("car", 60.0, noise="white", seed=2), corr=False)
    v = run.gnss_vel
    run.gnss_vel = GnssVelocity(v.t + 0.07, v.v_ned, v.sigma_ned)
    write_bag(run, tmp_path / "late", "ros2-sqlite3")
    back = load_bag_run(tmp_path / "late", load_config())
    assert back.meta["topics"]["gnss_velocity"] == "/gnss/vel"
    assert any("100 % stamped at fix epochs" in r for r in back.meta["selection"])
    tr = run.truth
    t = np.arange(tr.t[0], tr.t[-1], 0.02)
    fast = np.column_stack([np.interp(t, tr.t, tr.v_n[:, i]) for i in range(3)])
    run.gnss_vel = GnssVelocity(t, fast, np.full((len(t), 3), 0.05))
    write_bag(run, tmp_path / "fast", "ros2-sqlite3")
    back = load_bag_run(tmp_path / "fast", load_config())
    assert back.gnss_vel is None
    assert any("not one per fix epoch" in r for r in back.meta["selection"])


@needs_vn
def test_vectornav_export_without_a_needed_column_is_refused(tmp_path, capsys):
    for name in ("x-imu.csv", "x-gnss.csv"):
        src = VN / name.replace("x-", "lckf_vn310-")
        text = src.read_text()
        if "gnss" in name:
            text = text.replace("GNSS1::PosU::D [m]", "GNSS1::PosUncertainty::D [m]", 1)
        (tmp_path / name).write_text(text)
    code = main(["run", str(tmp_path / "x-imu.csv"), "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and err[-1].startswith("gnssacc: error: ")
    assert "x-gnss.csv: no column GNSS1::PosU::D: not a VectorNav export gnssacc reads" in err[-1]


@needs_comma
def test_comma2k19_segment_without_fixes_is_refused(tmp_path, capsys):
    import shutil

    seg = tmp_path / "seg"
    shutil.copytree(COMMA / "processed_log" / "IMU", seg / "processed_log" / "IMU")
    code = main(["run", str(seg), "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and err[-1].startswith("gnssacc: error: ")
    assert "live_gnss_ublox/t: missing: a comma2k19 segment needs the u-blox fixes" in err[-1]


def test_velocities_at_no_fix_time_are_warned_not_lost_silently(tmp_path):
    run = with_velocity(simulate("car", 20.0, seed=1))
    v = run.gnss_vel
    run.gnss_vel = GnssVelocity(v.t + 0.5, v.v_ned, v.sigma_ned)  # between the 1 Hz fixes
    with pytest.warns(DataWarning, match=rf"{len(v)} of {len(v)} velocities are at no fix's time"):
        write_csv_run(run, tmp_path)
    assert _load(tmp_path).gnss_vel is None
