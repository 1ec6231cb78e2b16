"""A corpus of bad and awkward input, each run through ``gnssacc.cli.main`` in-process.

Bad input must end with exit code 2, no traceback, and exactly one ``gnssacc: error:`` line that
names the file or option and says what is wrong (checked by key words). Awkward but valid input
must run (exit code 0) and give the result the same data give in a plain form, judged against the
truth. Categories: configuration (TOML), command-line arguments, CSV run directories, ROS 1 /
ROS 2 / MCAP bags (real ones written with :func:`gnssacc.sources.bagwrite.write_bag`, then
damaged). Cases already covered in ``test_csvdir.py`` and ``test_cli.py`` are not repeated.
"""

from __future__ import annotations

import json
import os
import shutil
import sys
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

pytest.importorskip("rosbags")

from gnssacc import cli  # noqa: E402
from gnssacc.core.errors import InputError  # noqa: E402
from gnssacc.core.recording import ImuData  # noqa: E402
from gnssacc.sources.bagwrite import write_bag  # noqa: E402
from gnssacc.sources.csvdir import write_csv_run  # noqa: E402
from gnssacc.sources.gnss_noise import MAX_OUTAGES, parse_outages  # noqa: E402
from gnssacc.sources.sim import simulate  # noqa: E402

FAST = ["--methods", "ekf", "--no-plots", "--tune", "none"]


# --- fixtures and helpers ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def sim():
    return simulate("car", duration_s=60.0, imu_grade="industrial", noise="white", seed=4)


@pytest.fixture(scope="module")
def data(sim, tmp_path_factory):
    """A clean CSV run and clean bags of every kind, written once; cases damage copies of them."""
    root = tmp_path_factory.mktemp("clean")
    bags = {
        "ros1": write_bag(sim, root / "run.bag", "ros1-rooad", truth_topic="/truth"),
        "sqlite": write_bag(sim, root / "run_sqlite", "ros2-sqlite3"),
        "mcapdir": write_bag(
            sim, root / "run_mcap", "ros2-mcap", truth_topic="/odom", truth_type="odometry"
        ),
        "mcap": write_bag(sim, root / "run.mcap", "mcap"),
    }
    return SimpleNamespace(run_dir=write_csv_run(sim, root / "run"), bags=bags)


@pytest.fixture
def env(data, tmp_path):
    return SimpleNamespace(tmp=tmp_path, run_dir=data.run_dir, bags=data.bags)


def _cli(capsys, args):
    code = cli.main([str(a) for a in args])
    out = capsys.readouterr()
    return code, out.out, out.err


def _expect_error(capsys, args, words):
    code, _, err = _cli(capsys, args)
    assert "Traceback" not in err, err
    lines = [ln for ln in err.splitlines() if ln.startswith("gnssacc: error:")]
    assert code == 2, err
    assert len(lines) == 1, err
    for w in words:
        assert w in lines[0], (w, lines[0])
    return lines[0]


def _file(env, name, content):
    p = env.tmp / name
    p.write_bytes(content if isinstance(content, bytes) else content.encode())
    return p


def _copy(src: Path, dst: Path) -> Path:
    if src.is_dir():
        shutil.copytree(src, dst)
    else:
        shutil.copyfile(src, dst)
    return dst


def _run_copy(env, edit) -> Path:
    """A copy of the clean CSV run with ``edit(folder)`` applied."""
    d = _copy(env.run_dir, env.tmp / "r")
    edit(d)
    return d


def _edit_lines(path: Path, fn) -> None:
    path.write_text("\n".join(fn(path.read_text().splitlines())) + "\n")


def _header_index(lines) -> int:
    return next(i for i, ln in enumerate(lines) if not ln.startswith("#"))


def _set_cell(lines, row, col, value):
    """Lines with data row ``row`` (0-based, after the header), column ``col`` set to ``value``."""
    h = _header_index(lines)
    cells = lines[h + 1 + row].split(",")
    cells[col] = value
    return lines[: h + 1 + row] + [",".join(cells)] + lines[h + 2 + row :]


def _cfg_case(text, words, command=lambda env: ["config"]):
    return lambda env: (
        [*command(env), "--config", _file(env, "bad.toml", text)],
        ["bad.toml", *words],
    )


# --- configuration --------------------------------------------------------------------------------

CONFIG_CASES = {
    "string-for-number": _cfg_case(
        '[imu]\ngyro_arw_deg_rth = "high"\n', ["[imu] gyro_arw_deg_rth", '"high"', "not a number"]
    ),
    "number-with-unit": _cfg_case(
        '[smoother]\nlag_s = "10 s"\n',
        ["[smoother] lag_s", "not a number", "> 0"],
        lambda env: ["run", "--out", env.tmp / "o"],
    ),
    "mounting-word": _cfg_case(
        '[mounting]\nimu_to_body_rpy_deg = "upside"\n',
        ["[mounting] imu_to_body_rpy_deg", '"upside"'],
    ),
    "section-not-a-table": _cfg_case("imu = 5\n", ["imu = 5", "must be a table"]),
    "negative-density": _cfg_case(
        "[imu]\naccel_vrw_mps_rth = -0.1\n",
        ["accel_vrw_mps_rth", "-0.1", "out of range", "(0, 1000]"],
    ),
    # The estimator needs white noise: one line naming the key, not a run with 36-160 m errors.
    "zero-density": _cfg_case(
        "[imu]\ngyro_arw_deg_rth = 0\n",
        ["[imu] gyro_arw_deg_rth", "out of range", "(0, 1000]", "has no noise"],
    ),
    "zero-density-on-one-axis": _cfg_case(
        "[imu]\naccel_vrw_mps_rth = [0.1, 0.1, 0.0]\n",
        ["[imu] accel_vrw_mps_rth", "0.0", "out of range", "has no noise"],
    ),
    "zero-fix-sigma": _cfg_case(
        "[gnss]\ndefault_sigma_m = 0\n", ["[gnss] default_sigma_m", "out of range", "exact"]
    ),
    "negative-in-vector": _cfg_case(
        "[gnss]\ndefault_sigma_m = [3.0, -3.0, 5.0]\n",
        ["default_sigma_m", "-3.0", "out of range", "(0, 1e+09]"],
    ),
    "nan": _cfg_case("[gnss]\ngm_tau_s = nan\n", ["[gnss] gm_tau_s", "not a finite number"]),
    "inf": _cfg_case("[zupt]\ngate_nis = inf\n", ["[zupt] gate_nis", "not a finite number"]),
    "vector-of-two": _cfg_case(
        "[gnss]\nlever_arm_b_m = [0.1, 0.2]\n", ["lever_arm_b_m", "list of 2"]
    ),
    "fractional-count": _cfg_case(
        "[init]\nyaw_hypotheses = 12.5\n", ["yaw_hypotheses", "whole number"]
    ),
    "bool-as-word": _cfg_case('[zupt]\nenabled = "yes"\n', ["[zupt] enabled", "true or false"]),
    "probability-one": _cfg_case("[init]\nyaw_confidence = 1.0\n", ["yaw_confidence", "[0.5, 1)"]),
    "unknown-choice": _cfg_case(
        '[smoother]\nfactorization = "LU"\n', ["factorization", '"QR"', '"CHOLESKY"']
    ),
    "fraction-above-one": _cfg_case(
        "[data]\nmax_bad_fraction = 2\n", ["max_bad_fraction", "[0, 1]"]
    ),
    "toml-syntax": _cfg_case("[imu\ngyro_arw_deg_rth = 1\n", ["not valid TOML"]),
    "unknown-section": _cfg_case(
        "[imus]\ngyro_arw_deg_rth = 1\n", ["unknown config section [imus]"]
    ),
    "bool-for-number": _cfg_case(
        "[gnss]\nsigma_scale = true\n", ["[gnss] sigma_scale", "not a number"]
    ),
    "zero-time-constant": _cfg_case(
        "[imu]\nbias_correlation_time_s = 0\n", ["bias_correlation_time_s", "(0, 1e+09]"]
    ),
    "negative-start-sigma": _cfg_case(
        "[imu]\naccel_bias_sigma0_mg = -1.0\n", ["accel_bias_sigma0_mg", "[0, 1e+06]"]
    ),
    "zero-lag": _cfg_case("[smoother]\nlag_s = 0\n", ["[smoother] lag_s", "out of range", "> 0"]),
    "mappings-not-a-table": _cfg_case("[bag]\nfix_mappings = 5\n", ["fix_mappings", "table"]),
    "mapping-path-a-number": _cfg_case(
        '[bag.fix_mappings."acme/msg/Fix"]\nlat = 5\n',
        ['fix_mappings."acme/msg/Fix"] lat', "not a field path"],
    ),
    "mapping-unknown-key": _cfg_case(
        '[bag.fix_mappings."acme/msg/Fix"]\nlatt = "a"\n',
        ["unknown key 'latt'"],
        lambda env: ["inspect", env.bags["sqlite"]],
    ),
    "mapping-zero-scale": _cfg_case(
        '[bag.fix_mappings."acme/msg/Fix"]\nlatlon_scale_deg = 0\n',
        ["latlon_scale_deg", "non-zero"],
    ),
    "list-for-scalar": _cfg_case("[init]\nyaw_sigma_deg = [1, 2]\n", ["[init] yaw_sigma_deg"]),
    "bench-zero-budget": _cfg_case(
        "[tune]\nmax_evaluations = 0\n",
        ["max_evaluations", "[1, 100000]"],
        lambda env: ["bench", "--seeds", "0"],
    ),
    "stationary-key-text": _cfg_case(
        '[stationary]\nblock_s = "half a second"\n', ["[stationary] block_s"]
    ),
    "latin-1": lambda env: (
        ["config", "--config", _file(env, "latin.toml", b"# caf\xe9\n[imu]\n")],
        ["latin.toml", "UTF-8", "line 1"],
    ),
    "binary-file": lambda env: (["config", "--config", env.bags["ros1"]], ["run.bag", "UTF-8"]),
    "directory": lambda env: (["config", "--config", env.tmp], ["--config", "is a directory"]),
    "missing-file": lambda env: (
        ["config", "--config", env.tmp / "nope.toml"],
        ["--config", "nope.toml", "no such file"],
    ),
}


@pytest.mark.parametrize("case", list(CONFIG_CASES))
def test_bad_config(case, env, capsys):
    args, words = CONFIG_CASES[case](env)
    _expect_error(capsys, args, words)


def test_awkward_but_valid_config(env, capsys):
    """Empty file; byte-order mark, comments, lower-case choice, integer for a float, per-axis list."""
    code, out, err = _cli(capsys, ["config", "--config", _file(env, "empty.toml", "")])
    assert code == 0 and err == ""
    code0, plain, _ = _cli(capsys, ["config"])
    assert out.splitlines()[1:] == plain.splitlines()[1:]
    text = (
        '\ufeff# my IMU\n[smoother]\nfactorization = "cholesky"  # lower case\nlag_s = 5\n'
        "[imu]\ngyro_arw_deg_rth = [0.2, 0.2, 0.4]\n"
        "gyro_bias_instability_deg_h = 0\naccel_bias_sigma0_mg = 0  # a known bias\n"
    )
    code, out, err = _cli(capsys, ["config", "--config", _file(env, "odd.toml", text)])
    assert code == 0 and "Traceback" not in err
    assert 'factorization = "cholesky"' in out and "lag_s = 5" in out and "[0.2, 0.2, 0.4]" in out


# --- command-line arguments -----------------------------------------------------------------------


def _run(env, *extra):
    return ["run", env.run_dir, "--out", env.tmp / "o", *FAST, *extra]


ARG_CASES = {
    "outage-double-dot": (
        lambda env: _run(env, "--outage", "1..2:5"),
        ["--outage", "'1..2:5'", "START:LEN"],
    ),
    "outage-no-colon": (lambda env: _run(env, "--outage", "120"), ["--outage", "START:LEN"]),
    "outage-negative-start": (
        lambda env: _run(env, "--outage=-5:10"),
        ["--outage", "not negative"],
    ),
    "outage-zero-length": (lambda env: _run(env, "--outage", "10:0"), ["--outage", "positive"]),
    "outage-infinite": (lambda env: _run(env, "--outage", "inf:10"), ["--outage", "finite"]),
    "outage-after-the-end": (
        lambda env: _run(env, "--outage", "500:10"),
        ["--outage", "after the run's end"],
    ),
    "outage-every-tiny": (
        lambda env: _run(env, "--outage-every", "0.0001:0.00005"),
        ["--outage-every", "minimum"],
    ),
    "outage-every-whole-period": (
        lambda env: _run(env, "--outage-every", "10:10"),
        ["--outage-every", "shorter than"],
    ),
    "seed-negative-with-noise": (
        lambda env: _run(env, "--noise", "white", "--seed", "-1"),
        ["--seed", "-1", "[0,"],
    ),
    "seed-too-large": (lambda env: _run(env, "--seed", str(2**40)), ["--seed", "4294967295"]),
    "methods-empty": (lambda env: _run(env, "--methods", ","), ["--methods", "unknown"]),
    "gnss-from-truth-zero": (
        lambda env: ["run", env.bags["sqlite"], "--out", env.tmp / "o", "--gnss-from-truth", "0"],
        ["--gnss-from-truth", "(0, 1000]"],
    ),
    "gnss-from-truth-nan": (
        lambda env: ["run", env.bags["sqlite"], "--out", env.tmp / "o", "--gnss-from-truth", "nan"],
        ["--gnss-from-truth", "finite"],
    ),
    "out-is-a-file": (
        lambda env: _run(env)[:3] + [_file(env, "f.txt", "x")] + FAST,
        ["--out", "is a file"],
    ),
    "out-below-a-file": (
        lambda env: _run(env)[:3] + [_file(env, "f.txt", "x") / "sub"] + FAST,
        ["--out", "f.txt is a file, not a folder"],
    ),
    "bench-seeds-empty-range": (
        lambda env: ["bench", env.run_dir, "--seeds", "5-1"],
        ["--seeds", "empty range"],
    ),
    "bench-seeds-too-many": (
        lambda env: ["bench", env.run_dir, "--seeds", "0-5000"],
        ["--seeds", "more than 1000"],
    ),
    "bench-seeds-words": (
        lambda env: ["bench", env.run_dir, "--seeds", "a,b"],
        ["--seeds", "cannot read 'a'"],
    ),
    "bench-seeds-negative": (
        lambda env: ["bench", env.run_dir, "--seeds", "-1"],
        ["--seeds", "'-1'"],
    ),
    "bench-seeds-twice": (
        lambda env: ["bench", env.run_dir, "--seeds", "1,2,1"],
        ["--seeds", "seed 1", "twice"],
    ),
    "bench-jobs-zero": (lambda env: ["bench", env.run_dir, "--jobs", "0"], ["--jobs", "[1, 256]"]),
    "bench-out-is-a-folder": (
        lambda env: ["bench", env.run_dir, "--out", env.tmp],
        ["--out", "is a folder"],
    ),
    "bench-missing-source": (lambda env: ["bench", env.tmp / "nope"], ["nope", "no such file"]),
    "bench-workers-without-truth": (
        lambda env: [
            "bench",
            _run_copy(env, lambda d: (d / "truth.csv").unlink()),
            "--jobs",
            "2",
            "--seeds",
            "0-1",
            *FAST[:2],
        ],
        ["r", "no truth.csv"],
    ),
    "sim-duration-negative": (
        lambda env: ["sim", env.tmp / "s", "--duration", "-5"],
        ["--duration", "[1, 86400]"],
    ),
    "sim-duration-nan": (
        lambda env: ["sim", env.tmp / "s", "--duration", "nan"],
        ["--duration", "finite"],
    ),
    "sim-duration-huge": (
        lambda env: ["sim", env.tmp / "s", "--duration", "1e9"],
        ["--duration", "out of range"],
    ),
    "sim-imu-rate-zero": (
        lambda env: ["sim", env.tmp / "s", "--imu-rate", "0"],
        ["--imu-rate", "[1, 4000]"],
    ),
    "sim-gnss-faster-than-imu": (
        lambda env: ["sim", env.tmp / "s", "--imu-rate", "10", "--gnss-rate", "20"],
        ["--gnss-rate", "(0, 10]"],
    ),
    "sim-too-many-samples": (
        lambda env: ["sim", env.tmp / "s", "--duration", "86400", "--imu-rate", "1000"],
        ["--duration", "more than 2000000"],
    ),
    "sim-one-fix": (
        lambda env: ["sim", env.tmp / "s", "--duration", "5", "--gnss-rate", "0.1"],
        ["--duration", "fewer than two GNSS fixes"],
    ),
    "sim-unknown-scenario": (
        lambda env: ["sim", env.tmp / "s", "--scenario", "boat"],
        ["--scenario", "'boat'", "car-city"],
    ),
    "sim-unknown-grade": (
        lambda env: ["sim", env.tmp / "s", "--grade", "diamond"],
        ["--grade", "'diamond'", "tactical"],
    ),
    "sim-seed-negative": (lambda env: ["sim", env.tmp / "s", "--seed", "-3"], ["--seed", "-3"]),
    "sim-out-is-a-file": (
        lambda env: ["sim", _file(env, "f.txt", "x")],
        ["output folder", "is a file"],
    ),
}


@pytest.mark.parametrize("case", list(ARG_CASES))
def test_bad_argument(case, env, capsys):
    make, words = ARG_CASES[case]
    _expect_error(capsys, make(env), words)
    assert not (env.tmp / "o").exists() and not (env.tmp / "s").exists()


@pytest.mark.skipif(not Path("/proc/self").exists(), reason="needs /proc (Linux)")
def test_out_in_an_unwritable_place(env, capsys):
    """Refused before anything is loaded: /proc takes no folders, whoever runs the test."""
    _expect_error(
        capsys,
        ["run", env.run_dir, "--out", "/proc/gnssacc-out", *FAST],
        ["--out", "cannot write in /proc"],
    )


@pytest.mark.skipif(
    not hasattr(os, "geteuid") or os.geteuid() == 0, reason="root may write anywhere"
)
def test_out_in_a_read_only_folder(env, capsys):
    ro = env.tmp / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        _expect_error(
            capsys, ["run", env.run_dir, "--out", ro / "o", *FAST], ["--out", "cannot write in"]
        )
    finally:
        ro.chmod(0o755)


@pytest.mark.parametrize(
    "args",
    [["run", "--seed", "abc"], ["run", "--noise", "pink"], ["sim"], ["fly"]],
    ids=["seed-not-an-int", "unknown-noise", "sim-without-out", "unknown-command"],
)
def test_argparse_usage_errors_stay_exit_2(args, capsys):
    with pytest.raises(SystemExit) as exc:
        cli.main(args)
    err = capsys.readouterr().err
    assert exc.value.code == 2 and "Traceback" not in err and "error:" in err


def test_outage_count_bounded_in_python_too():
    with pytest.raises(InputError, match="choose a longer period"):
        parse_outages(None, "1:0.5", 2.0 * MAX_OUTAGES)
    assert parse_outages("60:10,20:5,62:3", None, 100.0) == [
        (20.0, 25.0),
        (60.0, 70.0),
        (62.0, 65.0),
    ]


# --- CSV run directories --------------------------------------------------------------------------


def _imu(d):
    return d / "imu.csv"


def _gnss(d):
    return d / "gnss.csv"


def _latin1_comment(path):
    path.write_bytes(b"# caf\xe9\n" + path.read_bytes())


def _truncate_rows(lines):
    h = _header_index(lines)
    return (
        lines[: h + 100]
        + [",".join(ln.split(",")[:3]) for ln in lines[h + 100 : h + 104]]
        + lines[h + 104 :]
    )


def _with_init(d, doc):
    (d / "init.json").write_text(doc if isinstance(doc, str) else json.dumps(doc))


INIT = {
    "t": 0.0,
    "lat_deg": 32.0,
    "lon_deg": 34.8,
    "h_m": 50.0,
    "vn": 0.0,
    "ve": 0.0,
    "vd": 0.0,
    "roll_deg": 0.0,
    "pitch_deg": 0.0,
    "yaw_deg": 30.0,
}


def _add_column(lines, name, value):
    h = _header_index(lines)
    return lines[:h] + [lines[h] + "," + name] + [ln + "," + value for ln in lines[h + 1 :]]


def _drop_column(lines, name):
    h = _header_index(lines)
    j = lines[h].split(",").index(name)
    return lines[:h] + [
        ",".join(c for i, c in enumerate(ln.split(",")) if i != j) for ln in lines[h:]
    ]


def _nan_every_other_row(lines):
    for row in range(1, len(lines) - _header_index(lines) - 1, 2):
        lines = _set_cell(lines, row, 1, "nan")
    return lines


CSV_CASES = {
    "imu-latin-1": (lambda d: _latin1_comment(_imu(d)), ["imu.csv", "UTF-8"]),
    "imu-is-a-folder": (
        lambda d: (_imu(d).unlink(), _imu(d).mkdir()),
        ["imu.csv", "is a directory"],
    ),
    "imu-truncated-rows": (
        lambda d: _edit_lines(_imu(d), _truncate_rows),
        ["imu.csv", "cells", "4 such line"],
    ),
    "imu-one-row": (
        lambda d: _edit_lines(_imu(d), lambda ls: ls[: _header_index(ls) + 2]),
        ["imu.csv", "need at least two"],
    ),
    "imu-column-twice": (
        lambda d: _edit_lines(_imu(d), lambda ls: _add_column(ls, "ax", "0")),
        ["imu.csv", "more than once"],
    ),
    "imu-iso-time-stamps": (
        lambda d: _edit_lines(_imu(d), lambda ls: _set_cell(ls, 7, 0, "2024-05-01T10:00:00")),
        ["imu.csv", "non-numeric", "'t'"],
    ),
    "imu-semicolons": (
        lambda d: _edit_lines(_imu(d), lambda ls: [ln.replace(",", ";") for ln in ls]),
        ["imu.csv", "missing required column"],
    ),
    "gnss-text-in-number": (
        lambda d: _edit_lines(_gnss(d), lambda ls: _set_cell(ls, 5, 1, "N/A")),
        ["gnss.csv", "non-numeric", "'N/A'"],
    ),
    "gnss-empty-file": (lambda d: _gnss(d).write_text(""), ["gnss.csv", "empty"]),
    "gnss-longitude-400": (
        lambda d: _edit_lines(_gnss(d), lambda ls: _set_cell(ls, 3, 2, "400.0")),
        ["gnss.csv", "longitude out of range"],
    ),
    "gnss-negative-sigma": (
        lambda d: _edit_lines(_gnss(d), lambda ls: _set_cell(ls, 3, 4, "-2.0")),
        ["gnss.csv", "positive"],
    ),
    "gnss-duplicated-row": (
        lambda d: _edit_lines(_gnss(d), lambda ls: ls[:12] + ls[11:]),
        ["gnss.csv", "repeats"],
    ),
    "gnss-half-nan": (
        lambda d: _edit_lines(_gnss(d), _nan_every_other_row),
        ["gnss.csv", "NaN/inf", "max_bad_fraction"],
    ),
    "truth-header-only": (
        lambda d: _edit_lines(d / "truth.csv", lambda ls: ls[: _header_index(ls) + 1]),
        ["truth.csv", "no data rows"],
    ),
    "truth-half-velocity": (
        lambda d: _edit_lines(d / "truth.csv", lambda ls: _drop_column(ls, "vd")),
        ["truth.csv", "vn, ve, vd"],
    ),
    "init-latin-1": (
        lambda d: (d / "init.json").write_bytes(b'{"t": 0, "note": "caf\xe9"}'),
        ["init.json", "UTF-8"],
    ),
    "init-a-list": (lambda d: _with_init(d, "[1, 2, 3]"), ["init.json", "JSON object"]),
    "init-nan": (
        lambda d: _with_init(d, {**INIT, "vn": float("nan")}),
        ["init.json", "finite number"],
    ),
    "folder-empty": (
        lambda d: [p.unlink() for p in list(d.iterdir())],
        ["not a run directory", "it is empty"],
    ),
    "folder-of-other-files": (
        lambda d: ([p.unlink() for p in list(d.iterdir())], (d / "notes.txt").write_text("x")),
        ["not a run directory", "notes.txt"],
    ),
}


@pytest.mark.parametrize("case", list(CSV_CASES))
def test_bad_csv_run(case, env, capsys):
    edit, words = CSV_CASES[case]
    d = _run_copy(env, edit)
    _expect_error(capsys, ["run", d, "--out", env.tmp / "o", *FAST], words)
    assert not (env.tmp / "o").exists()


def _metrics(env, capsys, source, name, *extra, warnings=None):
    """Run ``ekf`` on ``source``: metrics.json (stderr appended to ``warnings`` if given)."""
    out = env.tmp / name
    code, stdout, err = _cli(capsys, ["run", source, "--out", out, *FAST, *extra])
    assert code == 0, err
    assert "Traceback" not in err and "gnssacc: error" not in err
    if warnings is not None:
        warnings.append(err)
    return json.loads((out / "metrics.json").read_text())


def _quirky(lines):
    """Windows line ends, a byte-order mark, quoted upper-case names, columns reordered, an extra
    column, blank and comment lines between the rows."""
    h = _header_index(lines)
    names = lines[h].split(",")
    order = list(range(len(names)))[::-1]
    out = [
        "\ufeff# exported by a spreadsheet",
        ",".join(f'"{names[j].upper()}"' for j in order) + ",Note",
    ]
    for k, ln in enumerate(lines[h + 1 :]):
        cells = ln.split(",")
        out.append(",".join(cells[j] for j in order) + ",ok")
        if k % 50 == 0:
            out += ["", "# pause"]
    return out


def test_awkward_but_valid_csv_gives_the_same_result(env, capsys):
    plain = _metrics(env, capsys, env.run_dir, "plain")
    d = _copy(env.run_dir, env.tmp / "quirky")
    for name in ("imu.csv", "gnss.csv", "truth.csv"):
        text = "\r\n".join(_quirky((d / name).read_text().splitlines())) + "\r\n"
        (d / name).write_bytes(text.encode())
    odd = _metrics(env, capsys, d, "odd")
    assert odd["methods"]["ekf"]["prmse_m"] == pytest.approx(
        plain["methods"]["ekf"]["prmse_m"], rel=1e-9
    )
    assert plain["methods"]["ekf"]["prmse_m"] < plain["gnss_prmse_m"]


def test_awkward_but_valid_epoch_time_stamps(env, capsys):
    """Unix-epoch time stamps (1.7e9 s): the same run, the same accuracy against the truth."""
    run = simulate(
        "car", duration_s=60.0, imu_grade="industrial", noise="white", seed=4, t_start_s=1.7e9
    )
    m = _metrics(env, capsys, write_csv_run(run, env.tmp / "epoch"), "epoch-out")
    plain = _metrics(env, capsys, env.run_dir, "plain")
    assert m["methods"]["ekf"]["prmse_m"] < m["gnss_prmse_m"]
    assert m["methods"]["ekf"]["prmse_m"] == pytest.approx(
        plain["methods"]["ekf"]["prmse_m"], rel=0.05
    )


# --- bags -------------------------------------------------------------------------------------------


def _bag_copy(env, kind, name, damage=None):
    p = _copy(env.bags[kind], env.tmp / name)
    if damage:
        damage(p)
    return p


def _storage(p: Path) -> Path:
    return next(f for f in p.iterdir() if f.suffix in (".db3", ".mcap"))


def _cut(path: Path, n: int) -> None:
    path.write_bytes(path.read_bytes()[:n])


def _smash_middle(path: Path) -> None:
    data = bytearray(path.read_bytes())
    mid = len(data) // 2
    data[mid : mid + 1000] = b"\xff" * 1000
    path.write_bytes(bytes(data))


MAPPING = '[bag.fix_mappings."ubxtranslator/msg/hpposllh"]\nlat = "pos.lat"\n'


def _no_imu_messages(env, sim):
    empty = ImuData(np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3)))
    return write_bag(replace(sim, imu=empty), env.tmp / "noimu", "ros2-sqlite3")


BAG_CASES = {
    "text-named-bag-run": (
        lambda env, sim: ["run", _file(env, "x.bag", "hello\n")],
        ["x.bag", "not a ROS 1 bag", "hello"],
    ),
    "text-named-bag-inspect": (
        lambda env, sim: ["inspect", _file(env, "x.bag", "hello\n")],
        ["x.bag", "not a ROS 1 bag"],
    ),
    "empty-bag": (lambda env, sim: ["inspect", _file(env, "e.bag", b"")], ["e.bag", "empty file"]),
    "text-named-mcap": (
        lambda env, sim: ["run", _file(env, "t.mcap", "x,y\n1,2\n")],
        ["t.mcap", "not an MCAP file"],
    ),
    "mcap-named-bag": (
        lambda env, sim: ["inspect", _bag_copy(env, "mcap", "m.bag")],
        ["m.bag", "rename it to .mcap"],
    ),
    "db3-named-mcap": (
        lambda env, sim: ["inspect", _copy(_storage(env.bags["sqlite"]), env.tmp / "s.mcap")],
        ["s.mcap", "sqlite3", "rename it to .db3"],
    ),
    "ros1-old-format": (
        lambda env, sim: ["inspect", _file(env, "old.bag", "#ROSBAG V1.2\n" + "x" * 100)],
        ["old.bag", "format 1.2"],
    ),
    "ros1-magic-damaged": (
        lambda env, sim: [
            "run",
            _bag_copy(env, "ros1", "d.bag", lambda p: p.write_bytes(b"\x00" + p.read_bytes()[1:])),
        ],
        ["d.bag", "not a ROS 1 bag"],
    ),
    "ros1-header-only": (
        lambda env, sim: ["inspect", _bag_copy(env, "ros1", "h.bag", lambda p: _cut(p, 13))],
        ["h.bag", "cannot read the bag"],
    ),
    "ros2-without-metadata": (
        lambda env, sim: [
            "run",
            _bag_copy(env, "sqlite", "nometa", lambda p: (p / "metadata.yaml").unlink()),
        ],
        ["nometa", "ROS 2 bag without its metadata.yaml", "ros2 bag reindex"],
    ),
    "ros2-mcap-without-metadata": (
        lambda env, sim: [
            "inspect",
            _bag_copy(env, "mcapdir", "nometa2", lambda p: (p / "metadata.yaml").unlink()),
        ],
        ["nometa2", "metadata.yaml", "ros2 bag reindex"],
    ),
    "ros2-metadata-without-storage": (
        lambda env, sim: [
            "run",
            _bag_copy(env, "sqlite", "nostore", lambda p: _storage(p).unlink()),
        ],
        ["nostore", "no storage file"],
    ),
    "ros2-storage-renamed": (
        lambda env, sim: [
            "inspect",
            _bag_copy(env, "sqlite", "renamed", lambda p: _storage(p).rename(p / "other.db3")),
        ],
        ["renamed", "cannot read the bag"],
    ),
    "ros2-metadata-garbage": (
        lambda env, sim: [
            "run",
            _bag_copy(
                env,
                "mcapdir",
                "garbage",
                lambda p: (p / "metadata.yaml").write_text("::: [not yaml\n"),
            ),
        ],
        ["garbage", "cannot read the bag"],
    ),
    "ros2-db3-truncated": (
        lambda env, sim: [
            "inspect",
            _bag_copy(env, "sqlite", "short", lambda p: _cut(_storage(p), 100)),
        ],
        ["short", "cannot read the bag"],
    ),
    "mcap-truncated": (
        lambda env, sim: ["run", _bag_copy(env, "mcap", "short.mcap", lambda p: _cut(p, 20))],
        ["short.mcap", "cannot read the bag"],
    ),
    "no-imu-messages": (
        lambda env, sim: ["run", _no_imu_messages(env, sim), "--out", env.tmp / "o", *FAST],
        ["noimu", "no IMU topic"],
    ),
    "no-gnss-topic": (
        lambda env, sim: [
            "run",
            write_bag(sim, env.tmp / "nognss", "ros2-mcap", gnss_topic=None),
            "--out",
            env.tmp / "o",
            *FAST,
        ],
        ["nognss", "no GNSS topic"],
    ),
    "imu-topic-absent": (
        lambda env, sim: [
            "run",
            env.bags["sqlite"],
            "--imu-topic",
            "/nope",
            "--out",
            env.tmp / "o",
        ],
        ["--imu-topic /nope", "no such topic", "/imu/data"],
    ),
    "gnss-topic-absent": (
        lambda env, sim: [
            "run",
            env.bags["ros1"],
            "--gnss-topic",
            "/gps/fix",
            "--out",
            env.tmp / "o",
        ],
        ["--gnss-topic /gps/fix", "no such topic"],
    ),
    "truth-topic-absent": (
        lambda env, sim: ["run", env.bags["mcap"], "--truth-topic", "/gt", "--out", env.tmp / "o"],
        ["--truth-topic /gt", "no such topic"],
    ),
    "imu-topic-wrong-type": (
        lambda env, sim: [
            "run",
            env.bags["sqlite"],
            "--imu-topic",
            "/gnss/fix",
            "--out",
            env.tmp / "o",
        ],
        ["--imu-topic /gnss/fix", "NavSatFix"],
    ),
    "mapping-does-not-fit": (
        lambda env, sim: [
            "run",
            env.bags["ros1"],
            "--gnss-topic",
            "/UBX/hpposllh",
            "--out",
            env.tmp / "o",
            "--config",
            _file(env, "m.toml", MAPPING),
        ],
        ["run.bag", "field mapping of ubxtranslator/msg/hpposllh", "'pos'", "llh, err"],
    ),
    "noise-without-gnss-from-truth": (
        lambda env, sim: ["run", env.bags["sqlite"], "--noise", "white", "--out", env.tmp / "o"],
        ["--noise", "--gnss-from-truth"],
    ),
}


@pytest.mark.parametrize("case", list(BAG_CASES))
def test_bad_bag(case, env, sim, capsys):
    make, words = BAG_CASES[case]
    _expect_error(capsys, make(env, sim), words)
    assert not (env.tmp / "o").exists()


def test_awkward_but_valid_bags(env, capsys):
    """A ROS 2 MCAP bag with odometry truth and overlapping, unsorted outages; a ROS 1 bag damaged in
    the middle (read up to the damage, with a warning); a bare .db3 file; inspect with a topic missing."""
    m = _metrics(env, capsys, env.bags["mcapdir"], "bag-out", "--outage", "40:8,20:5,42:3")
    assert m["methods"]["ekf"]["prmse_m"] < m["gnss_prmse_m"]
    assert m["run"]["outages"] == [[20.0, 25.0], [40.0, 48.0], [42.0, 45.0]]
    err: list = []
    m = _metrics(
        env,
        capsys,
        _bag_copy(env, "ros1", "mid.bag", _smash_middle),
        "mid-out",
        "--gnss-topic",
        "/UBX/hpposllh",
        warnings=err,
    )
    assert "gnssacc: warning:" in err[0] and "mid.bag" in err[0] and "damaged" in err[0]
    assert 10.0 < m["duration_s"] < 50.0 and m["methods"]["ekf"]["prmse_m"] < m["gnss_prmse_m"]
    code, out, err = _cli(capsys, ["inspect", _storage(env.bags["sqlite"])])
    assert code == 0 and "/imu/data" in out and "gnssacc would use" in out
    assert "metadata.yaml beside it" in err and "is not used" in err  # said, not silent
    alone = env.tmp / "alone"
    alone.mkdir(exist_ok=True)
    shutil.copy(_storage(env.bags["sqlite"]), alone / "bag.db3")
    code, out, err = _cli(capsys, ["inspect", alone / "bag.db3"])
    assert code == 0 and "/imu/data" in out
    assert "without its bag's metadata.yaml" in err and "reconstructed" in err  # salvage notice
    code, out, err = _cli(capsys, ["inspect", env.bags["sqlite"], "--truth-topic", "/gt"])
    # It cannot pick them: the listing to choose from on stdout, one line on stderr, exit 2 (issue 22).
    assert code == 2 and "/imu/data" in out and "cannot pick the topics" in err and "/gt" in err
    assert err.count("\n") == 1


# --- the safety net ---------------------------------------------------------------------------------


def test_a_bug_is_one_line_and_a_crash_file(env, capsys, monkeypatch):
    import tempfile

    def broken(cfg):
        raise ZeroDivisionError("float division by zero")

    monkeypatch.setattr(tempfile, "tempdir", str(env.tmp))
    monkeypatch.setattr("gnssacc.core.config_docs.resolved_toml", broken)
    code, out, err = _cli(capsys, ["config"])
    assert code == 1 and "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(
        "gnssacc: internal error: ZeroDivisionError: float division"
    )
    crash = Path(lines[0].split("details written to ")[1].rstrip(")"))
    assert crash.parent == env.tmp and crash.name.startswith("gnssacc-crash-")
    text = crash.read_text()
    assert "Traceback" in text and "in broken" in text and "command: gnssacc config" in text


def test_interrupt_stays_130(monkeypatch, capsys):
    def interrupted(args):
        raise KeyboardInterrupt

    monkeypatch.setattr(cli, "_cmd_config", interrupted)
    code, _, err = _cli(capsys, ["config"])
    assert code == 130 and "interrupted" in err and "Traceback" not in err


def test_a_sigterm_that_reaches_main_stays_143(monkeypatch, capsys):
    """E.g. one landing as a command's signal handling is being undone: no traceback, exit 143."""
    from gnssacc.core.interrupts import Terminated

    def terminated(args):
        raise Terminated()

    monkeypatch.setattr(cli, "_cmd_config", terminated)
    code, _, err = _cli(capsys, ["config"])
    assert code == 143 and err.strip() == "gnssacc: terminated"


def test_a_reader_that_goes_away_is_not_a_bug(tmp_path):
    """``gnssacc config | true``: the pipe closes before gnssacc prints; it stops quietly
    (exit 141, as a shell reports SIGPIPE) instead of reporting an internal error."""
    import subprocess

    env = dict(os.environ, TMPDIR=str(tmp_path))  # a crash file would land here
    proc = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import sys; from gnssacc.cli import main; sys.exit(main(['config']))",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        env=env,
    )
    proc.stdout.close()  # at once: long before the interpreter has imported gnssacc and prints
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=60) == 141, err
    assert err == "" and list(tmp_path.iterdir()) == []
