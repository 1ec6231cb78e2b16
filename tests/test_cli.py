"""The gnssacc command end to end: outputs, and one clear line with exit code 2 for bad input."""

import csv
import json
import re
import subprocess
import sys

import numpy as np
import pytest

from gnssacc.cli import main
from gnssacc.sources.csvdir import write_csv_run
from gnssacc.sources.sim import simulate

REQUIRED_COLUMNS = [
    "t",
    "lat_deg",
    "lon_deg",
    "h_m",
    "vn",
    "ve",
    "vd",
    "roll_deg",
    "pitch_deg",
    "yaw_deg",
]


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    path = tmp_path_factory.mktemp("simrun") / "run"
    write_csv_run(
        simulate("car", duration_s=120.0, imu_grade="industrial", noise="white", seed=2), path
    )
    return path


def _run_cli(args, capsys):
    code = main([str(a) for a in args])
    out = capsys.readouterr()
    return code, out.out, out.err


ALL_IDS = ("ekf", "ekf-acc", "smoother", "smoother-online", "smoother-acc", "smoother-acc-online")


def test_run_on_csv_dir_writes_all_outputs(run_dir, tmp_path, capsys):
    out = tmp_path / "res"
    code, stdout, stderr = _run_cli(
        ["run", run_dir, "--out", out], capsys
    )  # default: all four methods
    assert code == 0, stderr
    for name in ["metrics.json", "errors.png", "trajectory.png"] + [
        f"trajectory_{m}.csv" for m in ALL_IDS
    ]:
        assert (out / name).is_file(), name
    m = json.loads((out / "metrics.json").read_text())
    assert m["source"] == "run" and m["duration_s"] == pytest.approx(120.0, abs=0.1)
    assert set(m["methods"]) == set(ALL_IDS)
    for mid in ALL_IDS:
        entry = m["methods"][mid]
        assert entry["prmse_m"] < m["gnss_prmse_m"]
        assert entry["hrmse_m"] <= entry["prmse_m"] and entry["runtime_s"] > 0
    assert m["methods"]["smoother"]["prmse_m"] < m["methods"]["ekf"]["prmse_m"]
    with open(out / "trajectory_smoother.csv") as fh:
        sm_rows = list(csv.reader(fh))
    assert sm_rows[0][:10] == REQUIRED_COLUMNS and np.all(np.isfinite(np.array(sm_rows[1:], float)))
    # The table names every method with its PRMSE as in metrics.json.
    for mid in ALL_IDS:
        line = next(ln for ln in stdout.splitlines() if ln.startswith(mid + " "))
        assert f"{m['methods'][mid]['prmse_m']:.2f}" in line
    with open(out / "trajectory_ekf.csv") as fh:
        rows = list(csv.reader(fh))
    header = rows[0]
    assert header[:10] == REQUIRED_COLUMNS
    for col in ("sn_m", "se_m", "sd_m", "sroll_deg", "syaw_deg", "sbax_mg", "sbgz_dph"):
        assert col in header
    data = np.array(rows[1:], float)
    assert len(data) == m["methods"]["ekf"]["n_epochs"]
    assert np.all(np.diff(data[:, 0]) > 0) and np.all(np.isfinite(data))


def test_noise_and_outages_on_a_run_with_truth(run_dir, tmp_path, capsys):
    out = tmp_path / "res"
    code, stdout, stderr = _run_cli(
        [
            "run",
            run_dir,
            "--methods",
            "ekf",
            "--noise",
            "gm",
            "--seed",
            "3",
            "--outage",
            "40:15",
            "--out",
            out,
            "--no-plots",
        ],
        capsys,
    )
    assert code == 0, stderr
    m = json.loads((out / "metrics.json").read_text())
    assert m["run"]["noise"] == "gm" and m["run"]["outages"] == [[40.0, 55.0]]
    assert m["methods"]["ekf"]["prmse_outage_m"] is not None
    assert "outage PRMSE" in stdout


def _write(path, text):
    path.write_text(text)
    return path


def _bad(capsys, args):
    code, stdout, stderr = _run_cli(args, capsys)
    lines = [ln for ln in stderr.splitlines() if ln.startswith("gnssacc: error:")]
    assert code == 2
    assert len(lines) == 1 and "Traceback" not in stderr
    return lines[0]


def test_the_table_comes_before_the_files_and_figures(run_dir, tmp_path, capsys, monkeypatch):
    """What the user waits for first: the table is on the terminal before the files and figures
    are written; where they went comes last."""
    import gnssacc.api as api

    printed = []

    def write_result(*args, **kwargs):
        printed.append(capsys.readouterr().out)  # what was on the terminal when writing began
        return real(*args, **kwargs)

    real = api.write_result
    monkeypatch.setattr(api, "write_result", write_result)
    out = tmp_path / "res"
    code, rest, stderr = _run_cli(
        ["run", run_dir, "--methods", "ekf", "--tune", "none", "--out", out], capsys
    )
    assert code == 0, stderr
    assert (
        len(printed) == 1
        and re.search(r"^method\s+PRMSE", printed[0], re.M)
        and "results:" not in printed[0]
    )
    assert (
        rest.strip() == f"results: {out}"
        and (out / "metrics.json").is_file()
        and (out / "errors.png").is_file()
    )


def test_a_reader_gone_before_the_table_still_gets_the_files(run_dir, tmp_path):
    """``gnssacc run ... | head -0``: the table cannot be printed (exit 141, as a shell reports
    SIGPIPE), but the results are written all the same."""
    out = tmp_path / "res"
    args = [
        "run",
        str(run_dir),
        "--methods",
        "ekf",
        "--tune",
        "none",
        "--no-plots",
        "--out",
        str(out),
    ]
    proc = subprocess.Popen(
        [
            sys.executable,
            "-c",
            f"import sys; from gnssacc.cli import main; sys.exit(main({args!r}))",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    proc.stdout.close()
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=300) == 141, err
    assert (
        "gnssacc: error" not in err
        and json.loads((out / "metrics.json").read_text())["methods"]["ekf"]["status"] == "ok"
    )


def test_missing_source(tmp_path, capsys):
    line = _bad(capsys, ["run", tmp_path / "nope"])
    assert "nope" in line and "no such" in line


def _copy_run(run_dir, tmp_path):
    dst = tmp_path / "r"
    dst.mkdir()
    for f in run_dir.iterdir():
        (dst / f.name).write_bytes(f.read_bytes())
    return dst


def test_missing_file_and_columns(run_dir, tmp_path, capsys):
    d = _copy_run(run_dir, tmp_path)
    (d / "gnss.csv").unlink()
    assert "gnss.csv" in _bad(capsys, ["run", d, "--out", tmp_path / "o"])
    _write(d / "gnss.csv", "t,lat_deg,h_m\n0,32,50\n")
    line = _bad(capsys, ["run", d, "--out", tmp_path / "o"])
    assert "gnss.csv" in line and "lon_deg" in line
    assert not (tmp_path / "o").exists()


def test_time_going_backwards(run_dir, tmp_path, capsys):
    d = _copy_run(run_dir, tmp_path)
    lines = (d / "imu.csv").read_text().splitlines()
    lines[500], lines[501] = lines[501], lines[500]
    _write(d / "imu.csv", "\n".join(lines) + "\n")
    line = _bad(capsys, ["run", d])
    assert "imu.csv" in line and "backwards" in line


def test_no_gnss_fix(run_dir, tmp_path, capsys):
    d = _copy_run(run_dir, tmp_path)
    header = (d / "gnss.csv").read_text().splitlines()[0]
    _write(d / "gnss.csv", header + "\n")
    line = _bad(capsys, ["run", d])
    assert "gnss.csv" in line


def test_nan_rows_dropped_with_warning_or_error_above_fraction(run_dir, tmp_path, capsys):
    d = _copy_run(run_dir, tmp_path)
    lines = (d / "imu.csv").read_text().splitlines()
    header = next(ln for ln in lines if not ln.startswith("#"))
    n_cols = len(header.split(","))
    for k in (100, 2000, 4000):
        lines[k] = ",".join([lines[k].split(",")[0]] + ["nan"] * (n_cols - 1))
    _write(d / "imu.csv", "\n".join(lines) + "\n")
    code, stdout, stderr = _run_cli(
        ["run", d, "--methods", "ekf", "--out", tmp_path / "o", "--no-plots"], capsys
    )
    assert code == 0
    assert "warning" in stderr and "imu.csv" in stderr and "3 " in stderr
    cfg = _write(tmp_path / "strict.toml", "[data]\nmax_bad_fraction = 0.0001\n")
    line = _bad(capsys, ["run", d, "--config", cfg])
    assert "imu.csv" in line and "NaN" in line


def test_bad_config(tmp_path, capsys):
    cfg = _write(tmp_path / "c.toml", "[imu]\ngyro_arw = 3\n")
    line = _bad(capsys, ["run", "--config", cfg])
    assert "c.toml" in line and "gyro_arw" in line
    assert "--methods" in _bad(capsys, ["run", "--methods", "ekf,kalman"])
    assert "--outage" in _bad(capsys, ["run", "--outage", "abc"])


def test_console_script_and_default_source(tmp_path):
    """`gnssacc run` with no argument: the KITTI default, through the installed entry point."""
    res = subprocess.run(
        [sys.executable, "-m", "gnssacc.cli", "run", "--out", str(tmp_path / "k"), "--no-plots"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        timeout=300,
    )
    assert res.returncode == 0, res.stderr
    assert "kitti" in res.stdout and "ekf-acc" in res.stdout
    m = json.loads((tmp_path / "k" / "metrics.json").read_text())
    assert m["source"] == "kitti" and m["methods"]["ekf"]["prmse_m"] < m["gnss_prmse_m"]


def test_config_show_round_trips(tmp_path, capsys):
    code, stdout, _ = _run_cli(["config", "--show", "--preset", "kitti"], capsys)
    assert code == 0
    f = _write(tmp_path / "resolved.toml", stdout)
    code2, stdout2, _ = _run_cli(["config", "--config", f], capsys)
    assert code2 == 0
    import tomllib  # the same values (the notes say what set them: the preset, then the file)

    assert tomllib.loads(stdout) == tomllib.loads(stdout2)
    assert "# set by preset kitti" in stdout and f"# set by {f}" in stdout2


def test_sim_command_writes_a_loadable_run(tmp_path, capsys):
    code, stdout, _ = _run_cli(
        ["sim", tmp_path / "s", "--scenario", "ugv", "--duration", "60"], capsys
    )
    assert (
        code == 0
        and (tmp_path / "s" / "imu.csv").is_file()
        and (tmp_path / "s" / "truth.csv").is_file()
    )


def test_run_tunes_by_default_and_the_tuned_file_reproduces_it(run_dir, tmp_path, capsys):
    out = tmp_path / "auto"
    code, stdout, stderr = _run_cli(
        ["run", run_dir, "--methods", "ekf", "--out", out, "--no-plots"], capsys
    )
    assert code == 0, stderr
    assert "tuned noise (" in stdout and "start: " in stdout and "scored over t = " in stdout
    m = json.loads((out / "metrics.json").read_text())
    assert m["tuning"]["n_evaluations"] > 0 and m["tuning"]["seconds"] > 0
    assert m["consistency"]["ekf"]["nis"]["pos"] == pytest.approx(
        m["methods"]["ekf"]["stats"]["nis_pos_mean"]
    )
    assert m["coverage"]["ekf"]["fraction"] == pytest.approx(1.0)
    # The NIS column of the table shows the consistency figure.
    line = next(ln for ln in stdout.splitlines() if ln.startswith("ekf "))
    assert f"{m['consistency']['ekf']['nis']['pos']:.2f}" in line
    again = tmp_path / "again"
    code, stdout2, stderr = _run_cli(
        [
            "run",
            run_dir,
            "--methods",
            "ekf",
            "--out",
            again,
            "--no-plots",
            "--config",
            out / "tuned.toml",
            "--tune",
            "none",
        ],
        capsys,
    )
    assert code == 0, stderr
    assert "tuned noise" not in stdout2 and not (again / "tuned.toml").exists()
    m2 = json.loads((again / "metrics.json").read_text())
    assert m2["methods"]["ekf"]["prmse_m"] == pytest.approx(
        m["methods"]["ekf"]["prmse_m"], rel=0.01
    )


def test_too_optimistic_noise_prints_a_warning_naming_the_method(tmp_path, capsys):
    # A consumer IMU (vibration, scale-factor errors) configured 10x too optimistic.
    write_csv_run(
        simulate("car-city", duration_s=200.0, imu_grade="consumer", noise="white", seed=1),
        tmp_path / "r",
    )
    cfg = tmp_path / "optimistic.toml"
    cfg.write_text(
        "[imu]\ngyro_arw_deg_rth = 0.06\naccel_vrw_mps_rth = 0.02\ngyro_bias_instability_deg_h = 3.0\n"
        "accel_bias_instability_mg = 0.05\ngyro_bias_sigma0_deg_h = 50.0\naccel_bias_sigma0_mg = 3.0\n"
    )
    code, stdout, stderr = _run_cli(
        [
            "run",
            tmp_path / "r",
            "--methods",
            "ekf,smoother",
            "--config",
            cfg,
            "--tune",
            "none",
            "--out",
            tmp_path / "o",
            "--no-plots",
        ],
        capsys,
    )
    assert code == 0
    # A warning names the methods it is about before its first colon ("ekf, smoother: ...").
    named = [
        {m.strip() for m in line.split(": ")[2].split(",")}
        for line in stderr.splitlines()
        if line.startswith("gnssacc: warning: ")
    ]
    for mid in ("ekf", "smoother"):
        assert any(mid in methods for methods in named), stderr
    assert " !" in stdout  # the table marks the warned rows
