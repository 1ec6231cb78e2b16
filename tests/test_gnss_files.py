"""GNSS files: RTKLIB .pos and NMEA 0183 read from hand-written files in the real formats, round
trips through our writers, time systems and leap seconds, the clock rule, the quality policy,
and bad input (exit 2, one line naming the file and the line)."""

from __future__ import annotations

import calendar
import re
import shutil
from functools import reduce
from pathlib import Path

import numpy as np
import pytest

from gnssacc.cli import main
from gnssacc.core.config import load_config
from gnssacc.core.earth import R_en, llh_to_ecef
from gnssacc.core.errors import DataWarning, InputError
from gnssacc.core.recording import FIX_QUALITY
from gnssacc.sources.csvdir import load_csv_run, write_csv_run
from gnssacc.sources.gnss_time import (
    FileTimes,
    gps_seconds_to_unix,
    place_on_clock,
    unix_to_gps_seconds,
)
from gnssacc.sources.gnssfile import load_gnss_file
from gnssacc.sources.nmea import checksum, read_nmea
from gnssacc.sources.rtklib import read_pos
from gnssacc.sources.sim import simulate

DATA = Path(__file__).parent / "data"
UNIX_2024 = 1709294400.0  # 2024-03-01 12:00:00 UTC
UERE = {0: 5.0, 1: 0.02, 2: 0.3, 3: 1.0, 4: 0.7, 5: 3.0, 6: 0.2, 7: 10.0}


def _utc(*ymdhms) -> float:
    y, mo, d, h, mi, s = ymdhms
    return calendar.timegm((y, mo, d, h, mi, 0)) + s


def _enu_to_ned(c):
    T = np.array([[0, 1, 0], [1, 0, 0], [0, 0, -1.0]])
    return T @ c @ T.T


# --- time systems ------------------------------------------------------------------------------------


def test_leap_seconds_against_published_offsets():
    # GPS - UTC: 15 s in 2010, 17 s in the first half of 2016, 18 s since 2017-01-01 (IERS Bulletin C).
    for when, leap in (
        ((2010, 6, 1, 0, 0, 0.0), 15),
        ((2016, 6, 1, 0, 0, 0.0), 17),
        ((2024, 3, 1, 12, 0, 0.0), 18),
        ((2016, 12, 31, 23, 59, 59.0), 17),
        ((2017, 1, 1, 0, 0, 1.0), 18),
    ):
        unix = _utc(*when)
        gps = unix - 315964800.0 + leap
        assert unix_to_gps_seconds(unix) == pytest.approx(gps, abs=1e-6)
        assert gps_seconds_to_unix(gps) == pytest.approx(unix, abs=1e-6)


def test_clock_rule_absolute_fixes_need_an_absolute_imu_clock():
    t = UNIX_2024 + np.arange(10.0)
    times = FileTimes(t, "absolute", "GPST")
    on, clock = place_on_clock(times, UNIX_2024 + np.arange(0, 10, 0.01), "f")
    assert clock == "unix" and np.array_equal(on, t)
    gps_imu = unix_to_gps_seconds(UNIX_2024) + np.arange(
        0, 10, 0.01
    )  # an IMU stamped in GPS seconds
    on, clock = place_on_clock(times, gps_imu, "f")
    assert clock == "gps" and on[0] == pytest.approx(gps_imu[0], abs=1e-6)
    with pytest.raises(
        InputError,
        match=r"absolute GPST .*2024-03-01 12:00:00 UTC.* IMU's time stamps are not "
        r"\(0\.000 \.\. 9\.990 s",
    ):
        place_on_clock(times, np.arange(0, 10, 0.01), "f")
    tod = FileTimes(np.array([43200.0, 43201.0]), "utc_time_of_day", "UTC")
    on, _ = place_on_clock(tod, UNIX_2024 + np.arange(0, 5, 0.01), "f")
    assert np.array_equal(on, [UNIX_2024, UNIX_2024 + 1])
    with pytest.raises(InputError, match="no date"):
        place_on_clock(tod, np.arange(0, 5, 0.01), "f")


# --- RTKLIB .pos: the real format --------------------------------------------------------------------


def test_rtkpost_llh_file_as_rtklib_writes_it():
    pos = read_pos(DATA / "rtkpost_llh.pos")
    assert (
        pos.meta["form"] == "llh"
        and pos.meta["time_system"] == "GPST"
        and pos.meta["height_kind"] == "ellipsoidal"
    )
    # 2015/06/01 00:00:00 GPST, 16 leap seconds then (the 17th came on 2015-07-01).
    np.testing.assert_allclose(
        pos.times.t, _utc(2015, 6, 1, 0, 0, 0.0) - 16.0 + np.arange(4), atol=1e-6
    )
    np.testing.assert_allclose(
        np.degrees(pos.lat), [47.480954411, 47.480954070, 47.480953632, 47.480953699], atol=1e-12
    )
    np.testing.assert_allclose(pos.h, [181.7826, 181.9513, 182.0809, 182.2652])
    assert pos.quality.tolist() == [1, 2, 5, 1] and pos.n_sat.tolist() == [9, 9, 8, 9]
    # sdne, sdeu, sdun are signed square roots of the covariances (RTKLIB's sqvar)
    sdn, sde, sdu, sdne, sdeu, sdun = 2.1240, 1.9095, 3.7639, 0.1361, 0.9338, 1.1387
    enu = np.array(
        [[sde**2, sdne**2, sdeu**2], [sdne**2, sdn**2, sdun**2], [sdeu**2, sdun**2, sdu**2]]
    )
    np.testing.assert_allclose(pos.cov_ned[2], _enu_to_ned(enu), rtol=1e-12)
    sdeu = -0.0061
    assert pos.cov_ned[0][1, 2] == pytest.approx(sdeu**2)  # E-D = -(E-U) = +0.0061^2


def test_rtkpost_ecef_file_with_week_and_utc():
    pos = read_pos(DATA / "rtkpost_xyz_week_utc.pos")
    # UTC written as week 1847, 86384 s of that scale: 2015-06-01 00:00:00 minus 16 s, UTC.
    np.testing.assert_allclose(
        pos.times.t, 315964800.0 + 1847 * 604800.0 + 86384.0 + np.arange(2), atol=1e-6
    )
    r = np.array([4081882.3780, 1410011.1426, 4678199.3010])
    np.testing.assert_allclose(llh_to_ecef(pos.lat[0], pos.lon[0], pos.h[0]), r, atol=1e-6)
    P = np.array([[4.0, 0.25, 1.44], [0.25, 1.0, -0.16], [1.44, -0.16, 9.0]])
    R = R_en(pos.lat[0], pos.lon[0])
    np.testing.assert_allclose(pos.cov_ned[0], R @ P @ R.T, atol=1e-9)


@pytest.mark.parametrize("form", ["llh", "xyz", "enu"])
@pytest.mark.parametrize("system,fmt", [("GPST", "calendar"), ("UTC", "week"), ("JST", "calendar")])
def test_pos_round_trip_to_the_files_precision(tmp_path, form, system, fmt):
    from gnssacc.sources.rtklib import write_pos

    rng = np.random.default_rng(7)
    m = 6
    t = UNIX_2024 + np.arange(m) * 0.2
    lat, lon, h = (
        np.radians(32 + 1e-4 * rng.random(m)),
        np.radians(34.8 + 1e-4 * rng.random(m)),
        50 + rng.random(m),
    )
    A = rng.normal(size=(m, 3, 3))
    cov = A @ A.transpose(0, 2, 1) + np.eye(3)
    write_pos(
        tmp_path / "x.pos",
        t,
        lat,
        lon,
        h,
        cov,
        [1, 2, 3, 4, 5, 6],
        form=form,
        time_system=system,
        time_format=fmt,
    )
    back = read_pos(tmp_path / "x.pos")
    np.testing.assert_allclose(back.times.t, t, atol=5e-4)  # ms
    np.testing.assert_allclose((back.lat - lat) * 6.4e6, 0, atol=1e-3)  # 1e-9 deg / 0.1 mm
    np.testing.assert_allclose(back.h, h, atol=1e-3)
    # standard deviations to 1e-4 m, so covariances to about 2 * 3 * 1e-4 m^2
    np.testing.assert_allclose(back.cov_ned, cov, atol=2e-3)
    assert back.quality.tolist() == [1, 2, 3, 4, 5, 6]


# --- NMEA: the real format ----------------------------------------------------------------------------


def test_checksum_of_the_classic_example_sentences():
    assert checksum("GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,") == 0x47
    assert checksum("GPRMC,123519,A,4807.038,N,01131.000,E,022.4,084.4,230394,003.1,W") == 0x6A


def test_nmea_example_log():
    nm = read_nmea(DATA / "nmea_example.nmea", UERE, 1.7, np.array([3.0, 3.0, 5.0]), 0.01)
    np.testing.assert_allclose(
        nm.times.t, [_utc(1994, 3, 23, 12, 35, 19.0), _utc(1994, 3, 23, 12, 35, 20.0)]
    )
    np.testing.assert_allclose(np.degrees(nm.lat), [48 + 7.038 / 60, 48 + 7.040 / 60], atol=1e-12)
    np.testing.assert_allclose(np.degrees(nm.lon), [11 + 31.000 / 60, 11 + 31.010 / 60], atol=1e-12)
    np.testing.assert_allclose(nm.h, [545.4 + 46.9, 545.6 + 46.9])  # altitude + geoid separation
    assert nm.quality.tolist() == [
        FIX_QUALITY["single"],
        FIX_QUALITY["dgps"],
    ]  # GGA 1, 2; the quality-0 one dropped
    assert nm.meta["dropped_quality"] == {"0": 1}
    np.testing.assert_allclose(nm.sigma_ned[0], [0.023, 0.020, 0.031])  # GST wins over HDOP
    np.testing.assert_allclose(
        nm.sigma_ned[1], [1.2 * 0.7 / np.sqrt(2)] * 2 + [1.7 * 1.2 * 0.7]
    )  # HDOP x UERE(dgps)
    th = np.radians(273.6)
    assert nm.corr_ned[0, 0] == pytest.approx(
        (0.023**2 - 0.020**2) * np.sin(th) * np.cos(th) / (0.023 * 0.020)
    )
    np.testing.assert_allclose(nm.speed_mps, 22.4 * 1852 / 3600)
    assert nm.meta["sigma_from"] == {"gst": 1, "hdop": 1, "default": 0}


def test_nmea_round_trip_to_the_files_precision(tmp_path):
    run = simulate("car", 60.0, t_start_s=UNIX_2024, noise="gm", seed=2)
    write_csv_run(run, tmp_path, gnss_format="nmea")
    back, meta = load_gnss_file(tmp_path / "gnss.nmea", load_config(), run.imu.t)
    g = run.gnss
    np.testing.assert_allclose(back.t, g.t, atol=5e-3)  # hundredths of a second
    np.testing.assert_allclose((back.lat - g.lat) * 6.4e6, 0, atol=1e-3)  # 1e-7 arc minute
    np.testing.assert_allclose((back.lon - g.lon) * 6.4e6, 0, atol=1e-3)
    np.testing.assert_allclose(back.h, g.h, atol=1e-4)
    np.testing.assert_allclose(back.sigma_ned, g.sigma_ned, atol=1e-4)
    assert meta["gnss_clock"] == "unix" and meta["gnss_sigma_from"]["gst"] == len(g)


# --- CSV run directories with .pos / NMEA, the quality policy ----------------------------------------


def test_pos_run_directory_and_the_quality_policy(tmp_path):
    run = simulate("car", 60.0, t_start_s=UNIX_2024, seed=1)
    q = np.where(np.arange(len(run.gnss)) % 3 == 0, FIX_QUALITY["float"], FIX_QUALITY["single"])
    run.gnss.quality = q
    write_csv_run(run, tmp_path, gnss_format="pos")
    plain = load_csv_run(tmp_path, load_config())
    assert plain.gnss.quality.tolist() == q.tolist() and plain.meta["gnss_format"] == "rtklib-pos"
    cfg = load_config(overrides={"gnss": {"quality": {"float": "drop", "single": 2.0}}})
    with pytest.warns(DataWarning, match=r"\[gnss\] quality dropped 21 of 61 fixes \(float 21\)"):
        policed = load_csv_run(tmp_path, cfg)
    assert len(policed.gnss) == np.sum(q == FIX_QUALITY["single"])
    np.testing.assert_allclose(
        policed.gnss.sigma_ned, 2.0 * plain.gnss.sigma_ned[q == FIX_QUALITY["single"]]
    )


def test_several_gnss_files_in_a_run_directory_are_refused(tmp_path):
    run = simulate("car", 30.0, t_start_s=UNIX_2024, seed=1)
    write_csv_run(run, tmp_path)
    shutil.copy(DATA / "rtkpost_llh.pos", tmp_path / "gnss.pos")
    with pytest.raises(InputError, match="holds gnss.csv and gnss.pos: keep one"):
        load_csv_run(tmp_path, load_config())


def test_pos_with_a_relative_imu_clock_is_refused(tmp_path, capsys):
    run = simulate("car", 30.0, seed=1)  # IMU from 0 s
    write_csv_run(run, tmp_path)
    (tmp_path / "gnss.csv").unlink()
    shutil.copy(DATA / "rtkpost_llh.pos", tmp_path / "gnss.pos")
    assert main(["run", str(tmp_path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert (
        len(err) == 1
        and "gnss.pos: its fix times are absolute GPST" in err[0]
        and "are not" in err[0]
    )


# --- bad input: exit 2, one line naming the file and the line -----------------------------------------


def _bad_run(tmp_path: Path, name: str, text: str) -> Path:
    run = simulate("car", 20.0, t_start_s=UNIX_2024, seed=1)
    write_csv_run(run, tmp_path / "r")
    (tmp_path / "r" / "gnss.csv").unlink()
    (tmp_path / "r" / name).write_text(text)
    return tmp_path / "r"


def _pos_lines(text_lines: list[str]) -> str:
    head = (DATA / "rtkpost_llh.pos").read_text().splitlines()[:14]
    return "\n".join(head + text_lines) + "\n"


GOOD_POS = (
    "2024/03/01 12:00:{:06.3f}   32.000000000   34.800000000    50.0000   5   8   3.0000   3.0000   5.0000"
    "   0.0000   0.0000   0.0000   0.00    0.0"
)


@pytest.mark.parametrize(
    "case,lines,expect",
    [
        (
            "truncated line",
            [GOOD_POS.format(18.0), GOOD_POS.format(19.0)[:60], GOOD_POS.format(20.0)],
            r"gnss.pos: line 16 has [0-9] fields, but the column header \(line 14\) gives 15",
        ),
        (
            "wrong column count",
            [GOOD_POS.format(18.0), GOOD_POS.format(19.0) + "   7.0", GOOD_POS.format(20.0)],
            r"gnss.pos: line 16 has 16 fields, but the column header \(line 14\) gives 15",
        ),
        (
            "not a number",
            [GOOD_POS.format(18.0), GOOD_POS.format(19.0).replace("50.0000", "5O.0000")],
            r"gnss.pos: line 16: '5O.0000' is not a number",
        ),
    ],
)
def test_bad_pos_files(tmp_path, capsys, case, lines, expect):
    root = _bad_run(tmp_path, "gnss.pos", _pos_lines(lines))
    assert main(["run", str(root), "--out", str(tmp_path / "out")]) == 2, case
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("gnssacc: error: ")
    assert re.search(expect, err[0]), err[0]


def test_unknown_time_system_and_missing_header(tmp_path, capsys):
    text = _pos_lines([GOOD_POS.format(18.0)]).replace("%  GPST ", "%  TAI  ")
    root = _bad_run(tmp_path, "gnss.pos", text)
    assert main(["run", str(root), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert (
        "gnss.pos: line 14: unknown time system 'TAI' in the column header (known: GPST, UTC, JST)"
        in err
    )
    (root / "gnss.pos").write_text(GOOD_POS.format(18.0) + "\n")
    assert main(["run", str(root), "--out", str(tmp_path / "out")]) == 2
    assert "no RTKLIB column header" in capsys.readouterr().err


def _sentence(body: str) -> str:
    return f"${body}*{reduce(lambda a, c: a ^ ord(c), body, 0):02X}"


def _gga(sec: int) -> str:
    return _sentence(
        f"GPGGA,1200{sec:02d}.00,3200.0000000,N,03448.0000000,E,1,08,1.00,50.0,M,0.0,M,,"
    )


def _rmc(sec: int) -> str:
    return _sentence(f"GPRMC,1200{sec:02d}.00,A,3200.0000000,N,03448.0000000,E,0.0,0.0,010324,,,A")


def test_bad_nmea_checksums_warn_or_refuse(tmp_path, capsys):
    lines = [s for k in range(20) for s in (_rmc(k), _gga(k))]
    bad = lines[:7] + [lines[7][:-2] + "00"] + lines[8:]  # line 8: a wrong checksum
    root = _bad_run(tmp_path, "gnss.nmea", "\n".join(bad) + "\n")
    assert main(["run", str(root), "--out", str(tmp_path / "out")]) == 2  # 1 of 40 > 1 %
    err = capsys.readouterr().err.strip().splitlines()
    assert (
        len(err) == 1
        and "gnss.nmea: 1 of 40 line(s) are not usable sentences (1 bad checksum); first at line 8"
        in err[0]
        and "data.max_bad_fraction" in err[0]
    )
    cfg = load_config(overrides={"data": {"max_bad_fraction": 0.05}})
    with pytest.warns(
        DataWarning, match=r"skipped 1 of 40 line\(s\) .*first at line 8 \(bad checksum\)"
    ):
        g, _ = load_gnss_file(root / "gnss.nmea", cfg, UNIX_2024 + np.arange(0, 20, 0.01))
    assert len(g) == 19


def test_truncated_nmea_sentence_and_unreadable_file(tmp_path, capsys):
    lines = [s for k in range(5) for s in (_rmc(k), _gga(k))]
    lines[3] = lines[3][:30]  # cut off, no checksum
    root = _bad_run(tmp_path, "gnss.nmea", "\n".join(lines) + "\n")
    assert main(["run", str(root), "--out", str(tmp_path / "out")]) == 2
    assert "first at line 4 (no checksum)" in capsys.readouterr().err
    (root / "gnss.nmea").write_bytes(b"$GPGGA,1\n\xff\xfe\x00binary\n")
    assert main(["run", str(root), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "gnss.nmea: line 2 is not text" in err[0]


def test_gga_without_dates_takes_the_day_of_a_unix_imu_clock(tmp_path):
    path = tmp_path / "f.nmea"
    path.write_text("\n".join(_gga(k) for k in range(5)) + "\n")
    g, meta = load_gnss_file(path, load_config(), UNIX_2024 + np.arange(0, 10, 0.01))
    np.testing.assert_allclose(g.t, UNIX_2024 + np.arange(5))
    assert meta["gnss_time_system"] == "UTC"


def test_rtklib_dms_and_enu_forms(tmp_path):
    """The degrees-minutes-seconds form (RTKLIB labels its third cross term "sdue") and the
    e/n/u-baseline form from the reference position, written as RTKLIB's format strings do."""
    dms = tmp_path / "dms.pos"
    dms.write_text(
        "% (lat/lon/height=WGS84/ellipsoidal,Q=1:fix,2:float,3:sbas,4:dgps,5:single,6:ppp,ns=# of satellites)\n"
        "%  GPST                  latitude(d'\")  longitude(d'\")  height(m)   Q  ns   sdn(m)   sde(m)   sdu(m)  "
        "sdne(m)  sdeu(m)  sdue(m) age(s)  ratio\n"
        "2015/06/01 00:00:00.000   47 28 51.43588    -0 03 23.52266   181.7826   1   9   0.0125   0.0103   0.0333"
        "   0.0028  -0.0061   0.0049   1.00   12.5\n"
    )
    pos = read_pos(dms)
    assert np.degrees(pos.lat[0]) == pytest.approx(47 + 28 / 60 + 51.43588 / 3600, abs=1e-12)
    assert np.degrees(pos.lon[0]) == pytest.approx(
        -(3 / 60 + 23.52266 / 3600), abs=1e-12
    )  # "-0" keeps its sign
    assert pos.cov_ned[0][0, 2] == pytest.approx(-(0.0049**2))  # N-D = -(U-N)
    enu = tmp_path / "enu.pos"
    enu.write_text(
        "% ref pos   : 47.480000000   19.050000000   180.0000\n"
        "%\n"
        "% (e/n/u-baseline=WGS84,Q=1:fix,2:float,3:sbas,4:dgps,5:single,6:ppp,ns=# of satellites)\n"
        "%  GPST                  e-baseline(m)  n-baseline(m)  u-baseline(m)   Q  ns   sde(m)   sdn(m)   sdu(m)  "
        "sden(m)  sdnu(m)  sdue(m) age(s)  ratio\n"
        "2015/06/01 00:00:00.000        10.0000        20.0000        -1.0000   1   9   0.0100   0.0200   0.0300"
        "   0.0000   0.0000   0.0000   1.00   12.5\n"
    )
    pos = read_pos(enu)
    from gnssacc.core.earth import LocalTangentFrame

    base = LocalTangentFrame(np.radians(47.48), np.radians(19.05), 180.0)
    np.testing.assert_allclose(
        base.to_ned(pos.lat, pos.lon, pos.h)[0], [20.0, 10.0, 1.0], atol=1e-6
    )
    np.testing.assert_allclose(np.sqrt(np.diag(pos.cov_ned[0])), [0.02, 0.01, 0.03], atol=1e-6)
