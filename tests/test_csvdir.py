"""Tests of the CSV run directory reader/writer and the shared source helpers."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

from gnssacc.checks.plausibility import fix_imu_time_units
from gnssacc.core.config import DEG, load_config
from gnssacc.core.earth import LocalTangentFrame
from gnssacc.core.errors import DataWarning, InputError
from gnssacc.core.recording import GnssFixes, ImuData, InitialState, RecordedRun, Truth
from gnssacc.sources.common import apply_mounting, read_table
from gnssacc.sources.csvdir import load_csv_run, write_csv_run

LAT0, LON0, H0 = 49.0, 8.4, 110.0  # degrees, degrees, metres


@pytest.fixture(scope="module")
def cfg():
    return load_config()


def _arrays(seed=0):
    """20 s of static IMU at 100 Hz and 1 Hz fixes, as plain arrays (degrees where the files use them)."""
    rng = np.random.default_rng(seed)
    t = 100.0 + np.arange(2000) * 0.01
    f = np.array([0.1, -0.2, -9.81]) + 0.01 * rng.standard_normal((2000, 3))
    w = 1e-3 * rng.standard_normal((2000, 3))
    tg = 100.0 + np.arange(20.0)
    lat = LAT0 + 1e-7 * rng.standard_normal(20)
    lon = LON0 + 1e-7 * rng.standard_normal(20)
    h = H0 + 0.1 * rng.standard_normal(20)
    sig = np.tile([1.0, 1.5, 2.5], (20, 1))
    return dict(t=t, f=f, w=w, tg=tg, lat=lat, lon=lon, h=h, sig=sig)


def _write_csv(path, names, cols, comment=None):
    with open(path, "w") as fh:
        if comment:
            fh.write(f"# {comment}\n")
        fh.write(",".join(names) + "\n")
        for row in zip(*cols):
            fh.write(",".join(v if isinstance(v, str) else repr(float(v)) for v in row) + "\n")


def _make_dir(tmp_path, a, imu_names=("t", "ax", "ay", "az", "gx", "gy", "gz"), with_sigma=True):
    """Write imu.csv (with an extra column and a comment) and gnss.csv from the arrays."""
    d = tmp_path / "myrun"
    d.mkdir()
    cols = {
        "t": a["t"],
        "ax": a["f"][:, 0],
        "ay": a["f"][:, 1],
        "az": a["f"][:, 2],
        "gx": a["w"][:, 0],
        "gy": a["w"][:, 1],
        "gz": a["w"][:, 2],
        "temp_c": np.full(len(a["t"]), 25.0),
    }
    names = list(imu_names) + ["temp_c"]
    _write_csv(d / "imu.csv", names, [cols[n.strip().lower()] for n in names], "a comment line")
    gcols = [a["tg"], a["lat"], a["lon"], a["h"]]
    gnames = ["t", "lat_deg", "lon_deg", "h_m"]
    if with_sigma:
        gcols += list(a["sig"].T)
        gnames += ["sn", "se", "sd"]
    _write_csv(d / "gnss.csv", gnames, gcols)
    return d


# --- round trips ---------------------------------------------------------------------------------------


def test_read_values_units_and_names(tmp_path, cfg):
    a = _arrays()
    # Shuffled column order and odd capitalisation/blanks in the header.
    d = _make_dir(tmp_path, a, imu_names=("GZ", " t ", "ax", "Gy", "az", "ay", "gx"))
    run = load_csv_run(d, cfg)
    assert run.name == "myrun" and run.where == str(d)
    np.testing.assert_array_equal(run.imu.t, a["t"])
    np.testing.assert_array_equal(run.imu.f_b, a["f"])
    np.testing.assert_array_equal(run.imu.omega_ib_b, a["w"])
    np.testing.assert_allclose(run.gnss.lat, a["lat"] * DEG, rtol=0, atol=1e-15)
    np.testing.assert_allclose(run.gnss.lon, a["lon"] * DEG, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(run.gnss.h, a["h"])
    np.testing.assert_array_equal(run.gnss.sigma_ned, a["sig"])
    assert run.origin.lat0 == run.gnss.lat[0] and run.origin.h0 == a["h"][0]
    assert run.truth is None and run.init is None


def test_default_gnss_sigma_from_config(tmp_path):
    d = _make_dir(tmp_path, _arrays(), with_sigma=False)
    cfg = load_config(overrides={"gnss": {"default_sigma_m": [2.0, 2.0, 4.0]}})
    np.testing.assert_array_equal(
        load_csv_run(d, cfg).gnss.sigma_ned, np.tile([2.0, 2.0, 4.0], (20, 1))
    )


def test_flu_is_converted_to_frd(tmp_path, cfg):
    a = _arrays()
    run = load_csv_run(_make_dir(tmp_path, a), cfg, imu_frame="flu")
    np.testing.assert_array_equal(run.imu.f_b, a["f"] * [1, -1, -1])
    np.testing.assert_array_equal(run.imu.omega_ib_b, a["w"] * [1, -1, -1])


def _full_run(a):
    lat, lon = a["lat"] * DEG, a["lon"] * DEG
    truth = Truth(
        a["tg"],
        lat,
        lon,
        a["h"],
        v_n=np.zeros((20, 3)) + [0.1, 0.2, 0.0],
        rpy=np.tile([0.01, -0.02, 1.0], (20, 1)),
    )
    init = InitialState(
        t=100.0,
        lat=lat[0],
        lon=lon[0],
        h=a["h"][0],
        v_n=np.array([0.0, 0.1, 0.0]),
        rpy=np.array([0.01, -0.02, 1.0]),
        sigma_pos_m=np.array([1.0, 1.5, 2.5]),
        sigma_vel_mps=np.array([0.2, 0.2, 0.3]),
        sigma_att_rad=np.array([1.0, 1.0, 4.0]) * DEG,
    )
    return RecordedRun(
        "sim",
        "synthetic",
        ImuData(a["t"], a["f"], a["w"]),
        GnssFixes(a["tg"], lat, lon, a["h"], a["sig"]),
        LocalTangentFrame(lat[0], lon[0], a["h"][0]),
        truth,
        init,
    )


def test_write_then_load_round_trip(tmp_path, cfg):
    run = _full_run(_arrays())
    d = write_csv_run(run, tmp_path / "exported")
    back = load_csv_run(d, cfg)
    assert back.name == "exported"
    for name in ("t", "f_b", "omega_ib_b"):
        np.testing.assert_array_equal(getattr(back.imu, name), getattr(run.imu, name))
    for name in ("t", "lat", "lon", "h", "sigma_ned"):
        np.testing.assert_allclose(
            getattr(back.gnss, name), getattr(run.gnss, name), rtol=1e-15, atol=0
        )
    for name in ("t", "lat", "lon", "h", "v_n", "rpy"):
        np.testing.assert_allclose(
            getattr(back.truth, name), getattr(run.truth, name), rtol=1e-15, atol=1e-18
        )
    for name in (
        "t",
        "lat",
        "lon",
        "h",
        "v_n",
        "rpy",
        "sigma_pos_m",
        "sigma_vel_mps",
        "sigma_att_rad",
    ):
        np.testing.assert_allclose(
            getattr(back.init, name), getattr(run.init, name), rtol=1e-15, atol=1e-18
        )


def test_truth_without_optional_groups_and_init_defaults(tmp_path, cfg):
    a = _arrays()
    d = _make_dir(tmp_path, a)
    _write_csv(
        d / "truth.csv", ["t", "lat_deg", "lon_deg", "h_m"], [a["tg"], a["lat"], a["lon"], a["h"]]
    )
    (d / "init.json").write_text(
        json.dumps(
            {
                "t": 100.0,
                "lat_deg": LAT0,
                "lon_deg": LON0,
                "h_m": H0,
                "vn": 0,
                "ve": 0,
                "vd": 0,
                "roll_deg": 1.0,
                "pitch_deg": -2.0,
                "yaw_deg": 90.0,
            }
        )
    )
    run = load_csv_run(d, cfg)
    assert run.truth.v_n is None and run.truth.rpy is None
    np.testing.assert_allclose(run.init.rpy, np.array([1.0, -2.0, 90.0]) * DEG)
    np.testing.assert_array_equal(run.init.sigma_pos_m, a["sig"][0])
    np.testing.assert_array_equal(run.init.sigma_vel_mps, [0.5, 0.5, 0.5])
    np.testing.assert_allclose(run.init.sigma_att_rad, np.array([2.0, 2.0, 5.0]) * DEG)


# --- mounting -----------------------------------------------------------------------------------------


def test_mounting_upside_down_flips_y_and_z(tmp_path):
    a = _arrays()
    cfg = load_config(overrides={"mounting": {"imu_to_body_rpy_deg": [180.0, 0.0, 0.0]}})
    run = load_csv_run(_make_dir(tmp_path, a), cfg)
    np.testing.assert_allclose(run.imu.f_b, a["f"] * [1, -1, -1], atol=1e-12)
    np.testing.assert_allclose(run.imu.omega_ib_b, a["w"] * [1, -1, -1], atol=1e-12)


def test_time_offset_shifts_imu_times_only(tmp_path):
    a = _arrays()
    cfg = load_config(overrides={"mounting": {"imu_time_offset_s": -0.1}})
    run = load_csv_run(_make_dir(tmp_path, a), cfg)
    np.testing.assert_allclose(run.imu.t, a["t"] - 0.1, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(run.gnss.t, a["tg"])


def test_apply_mounting_yaw(cfg):
    imu = ImuData(np.array([0.0, 1.0]), np.array([[1.0, 0, 0], [0, 1.0, 0]]), np.zeros((2, 3)))
    yawed = load_config(overrides={"mounting": {"imu_to_body_rpy_deg": [0.0, 0.0, 90.0]}})
    out = apply_mounting(imu, yawed)
    # x_b = R_z(90 deg) x_imu: IMU x becomes body y, IMU y becomes body -x.
    np.testing.assert_allclose(out.f_b, [[0, 1, 0], [-1, 0, 0]], atol=1e-15)
    assert out is not imu and imu.f_b[0, 0] == 1.0


# --- bad input ------------------------------------------------------------------------------------------


def _error(d, cfg, **kw) -> str:
    with pytest.raises(InputError) as exc:
        load_csv_run(d, cfg, **kw)
    return str(exc.value)


def test_missing_directory_and_files(tmp_path, cfg):
    assert "not found" in _error(tmp_path / "nope", cfg)
    d = _make_dir(tmp_path, _arrays())
    (d / "gnss.csv").unlink()
    msg = _error(d, cfg)
    assert "gnss.csv" in msg and "not found" in msg
    (d / "imu.csv").unlink()
    assert "imu.csv" in _error(d, cfg)
    assert "imu_frame" in _error(tmp_path, cfg, imu_frame="enu")
    f = tmp_path / "plain.txt"
    f.write_text("x")
    assert "not a directory" in _error(f, cfg)


def test_missing_columns_named_with_header(tmp_path, cfg):
    a = _arrays()
    d = _make_dir(tmp_path, a)
    _write_csv(
        d / "imu.csv", ["t", "ax", "ay", "az", "gx", "gy"], [a["t"], *a["f"].T, *a["w"][:, :2].T]
    )
    msg = _error(d, cfg)
    assert (
        "imu.csv" in msg and "missing required column(s) gz" in msg and "header found: t, ax" in msg
    )


@pytest.mark.parametrize(
    "what, make, words",
    [
        (
            "non-numeric",
            lambda c: c.replace("\n100.05,", "\n100.05x,", 1),
            ("imu.csv", "non-numeric", "line"),
        ),
        ("backwards", lambda c: c.replace("\n100.05,", "\n100.02,", 1), ("imu.csv", "backwards")),
        ("repeat", lambda c: c.replace("\n100.05,", "\n100.04,", 1), ("imu.csv", "repeats")),
        (
            "ragged",
            lambda c: c.replace("\n100.05,", "\n100.05,1,", 1),
            ("imu.csv", "cells", "line"),
        ),
        ("empty", lambda c: "", ("imu.csv", "empty")),
        ("comment only", lambda c: "# nothing\n\n", ("imu.csv", "empty")),
        ("header only", lambda c: c.splitlines()[1] + "\n", ("imu.csv", "row")),
    ],
)
def test_bad_imu_file(tmp_path, cfg, what, make, words):
    d = _make_dir(tmp_path, _arrays())
    p = d / "imu.csv"
    text = p.read_text()
    new = make(text)
    assert new != text, what
    p.write_text(new)
    msg = _error(d, cfg)
    for w in words:
        assert w in msg, (what, msg)


def test_bad_gnss_file(tmp_path, cfg):
    a = _arrays()
    d = _make_dir(tmp_path, a)
    _write_csv(d / "gnss.csv", ["t", "lat_deg", "lon_deg", "h_m"], [[], [], [], []])
    msg = _error(d, cfg)
    assert "gnss.csv" in msg and "no GNSS fix" in msg
    _write_csv(
        d / "gnss.csv",
        ["t", "lat_deg", "lon_deg", "h_m"],
        [a["tg"], a["lat"] + 50.0, a["lon"], a["h"]],
    )
    msg = _error(d, cfg)
    assert "gnss.csv" in msg and "latitude out of range" in msg
    tg = a["tg"].copy()
    tg[5] = tg[3]
    _write_csv(d / "gnss.csv", ["t", "lat_deg", "lon_deg", "h_m"], [tg, a["lat"], a["lon"], a["h"]])
    msg = _error(d, cfg)
    assert "gnss.csv" in msg and "backwards" in msg
    _write_csv(
        d / "gnss.csv",
        ["t", "lat_deg", "lon_deg", "h_m", "sn"],
        [a["tg"], a["lat"], a["lon"], a["h"], a["sig"][:, 0]],
    )
    msg = _error(d, cfg)
    assert "gnss.csv" in msg and "sn, se, sd" in msg
    _write_csv(
        d / "gnss.csv",
        ["t", "lat_deg", "lon_deg", "h_m", "sn", "se", "sd"],
        [a["tg"], a["lat"], a["lon"], a["h"], a["sig"][:, 0], a["sig"][:, 1], 0 * a["sig"][:, 2]],
    )
    assert "positive" in _error(d, cfg)


def test_bad_truth_and_init(tmp_path, cfg):
    a = _arrays()
    d = _make_dir(tmp_path, a)
    tg = a["tg"][::-1]
    _write_csv(
        d / "truth.csv", ["t", "lat_deg", "lon_deg", "h_m"], [tg, a["lat"], a["lon"], a["h"]]
    )
    msg = _error(d, cfg)
    assert "truth.csv" in msg and "backwards" in msg
    (d / "truth.csv").unlink()
    good = {
        "t": 100.0,
        "lat_deg": LAT0,
        "lon_deg": LON0,
        "h_m": H0,
        "vn": 0,
        "ve": 0,
        "vd": 0,
        "roll_deg": 0,
        "pitch_deg": 0,
        "yaw_deg": 0,
    }
    for doc, word in (
        (good | {"lat_deg": 95.0}, "latitude"),
        ({k: v for k, v in good.items() if k != "vd"}, "vd"),
        (good | {"yaw": 1.0}, "unknown"),
        (good | {"vn": "fast"}, "number"),
        (good | {"sigma": {"pos_m": -1}}, "positive"),
    ):
        (d / "init.json").write_text(json.dumps(doc))
        msg = _error(d, cfg)
        assert "init.json" in msg and word in msg, msg
    (d / "init.json").write_text("{not json")
    assert "JSON" in _error(d, cfg)


def test_gnss_not_overlapping_imu(tmp_path, cfg):
    a = _arrays()
    a["tg"] = a["tg"] + 1000.0
    assert "overlap" in _error(_make_dir(tmp_path, a), cfg)


@pytest.mark.parametrize(
    "unit, scale, divisor", [("milliseconds", 1e3, "1000"), ("nanoseconds", 1e9, "1e9")]
)
def test_imu_stamps_in_another_unit_named_or_rescaled(tmp_path, unit, scale, divisor):
    # Stamps since the Unix epoch: the IMU's in ms or ns, the fixes' in s. The loader names the
    # unit (not "different clocks?") and, unless told to refuse, rescales before the time offset
    # (the input checks' unit finding, which the pipeline hands to the loader).
    a = _arrays()
    a["t"], a["tg"] = (a["t"] + 1.7e9) * scale, a["tg"] + 1.7e9
    d = _make_dir(tmp_path, a)
    strict = load_config(overrides={"checks": {"on_proof": "refuse"}})
    with pytest.raises(InputError) as exc:
        load_csv_run(d, strict, time_units=fix_imu_time_units)
    assert exc.value.where == str(d / "imu.csv") and unit in exc.value.problem
    cfg = load_config(overrides={"mounting": {"imu_time_offset_s": -0.1}})  # rescaled by default
    with pytest.warns(DataWarning, match=f"divided the IMU time stamps by {divisor} "):
        run = load_csv_run(d, cfg, time_units=fix_imu_time_units)
    np.testing.assert_allclose(run.imu.t, a["t"] / scale - 0.1, rtol=0, atol=1e-6)


# --- NaN rows -------------------------------------------------------------------------------------------


def test_nan_rows_dropped_with_warning(tmp_path, cfg):
    a = _arrays()
    a["f"][[10, 20, 30], 1] = np.nan
    a["w"][40, 0] = np.inf
    d = _make_dir(tmp_path, a)
    # An empty cell is a missing value too.
    p = d / "imu.csv"
    lines = p.read_text().splitlines()
    cells = lines[2 + 50].split(",")  # comment, header, then data row 50
    cells[3] = ""
    lines[2 + 50] = ",".join(cells)
    p.write_text("\n".join(lines) + "\n")
    with pytest.warns(DataWarning, match=r"imu.csv.*dropped 5 of 2000"):
        run = load_csv_run(d, cfg)
    assert len(run.imu) == 1995 and np.all(np.isfinite(run.imu.f_b))
    assert 10 not in np.round((run.imu.t - 100.0) / 0.01)


def test_nan_rows_above_fraction_is_error(tmp_path, cfg):
    a = _arrays()
    a["f"][:100, 2] = np.nan  # 5 % > 1 %
    msg = _error(_make_dir(tmp_path, a), cfg)
    assert "imu.csv" in msg and "max_bad_fraction" in msg
    loose = load_config(overrides={"data": {"max_bad_fraction": 0.1}})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        assert len(load_csv_run(tmp_path / "myrun", loose).imu) == 1900


def test_truncated_last_line_dropped(tmp_path, cfg):
    d = _make_dir(tmp_path, _arrays())
    p = d / "imu.csv"
    p.write_text(p.read_text() + "120.0,0.1,\n")
    with pytest.warns(DataWarning, match="truncated"):
        assert len(load_csv_run(d, cfg).imu) == 2000


# --- speed ------------------------------------------------------------------------------------------------


def test_read_table_100k_rows(tmp_path):
    """(Its speed is measured by bench/bench_inputs.py.)"""
    rng = np.random.default_rng(3)
    n = 100_000
    table = np.column_stack([np.arange(n) * 0.01, rng.standard_normal((n, 6))])
    p = tmp_path / "imu.csv"
    np.savetxt(p, table, fmt="%.10g", delimiter=",", header="t,ax,ay,az,gx,gy,gz", comments="")
    tab = read_table(p, ["t", "ax", "ay", "az", "gx", "gy", "gz"])
    assert len(tab["t"]) == n and np.allclose(tab["gz"], table[:, 6], rtol=1e-9)


def test_read_table_in_blocks_equals_one_pass_and_keeps_line_numbers(tmp_path, monkeypatch):
    """Blocks of rows (so a long file needs its numbers' memory, not several copies of its text):
    the same table as one pass, comments and blank lines anywhere, a bad cell named by its file
    line in a later block, and a truncated last line dropped even when it opens a block."""
    import warnings

    from gnssacc.core.errors import DataWarning, InputError
    from gnssacc.sources import common

    rows = [f"{0.01 * k:.2f},{k},{-k}" for k in range(23)]
    text = (
        "# a comment\nt,a,b\n" + "\n".join(rows[:10]) + "\n\n# mid\n" + "\n".join(rows[10:]) + "\n"
    )
    path = tmp_path / "x.csv"
    path.write_text(text)
    whole = common.read_table(path, ["t", "a", "b"])
    monkeypatch.setattr(common, "BLOCK_LINES", 4)
    blocks = common.read_table(path, ["t", "a", "b"])
    for c in "tab":
        np.testing.assert_array_equal(blocks[c], whole[c])
    assert len(whole["t"]) == 23 and whole["a"][-1] == 22.0
    path.write_text(text.replace("17,-17", "17,x"))
    with pytest.raises(InputError, match="line 22"):
        common.read_table(path, ["t", "a", "b"])
    path.write_text(text + "0.24,24")  # 24 data rows: the truncated one alone in the 6th block
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        out = common.read_table(path, ["t", "a", "b"])
    assert len(out["t"]) == 23 and any(
        issubclass(w.category, DataWarning) and "truncated" in str(w.message) for w in caught
    )
