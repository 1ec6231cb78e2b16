"""The GNSS velocities' trust (issue 31, item 5): their frame, vertical sign and time tags proven
by the estimator's likelihood (:mod:`gnssacc.checks.velcheck` proposes, :mod:`gnssacc.prepare.judge`
proves), an axis that contradicts the fixes warned of by name, and ``--gnss FILE`` pairing.

Every corruption is made here from a clean simulated run, so the expected repair is the clean
run's velocities themselves (the simulator's truth), and a correct run must draw nothing.
"""

from __future__ import annotations

import json
import warnings
from dataclasses import replace

import numpy as np
import pytest

from gnssacc import cli
from gnssacc.checks import velcheck
from gnssacc.core.config import load_config
from gnssacc.core.errors import DataWarning
from gnssacc.pipeline import check_input, load_source
from gnssacc.prepare.judge import Innovations, compare
from gnssacc.sources.csvdir import write_csv_run
from gnssacc.sources.gnssfile import write_gnss_file
from gnssacc.sources.sim import simulate

T0_UNIX = 1709294400.0
ENU = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
UP = np.diag([1.0, 1.0, -1.0])
FAST = ["--methods", "ekf", "--tune", "none", "--no-plots"]


def _vel(run, **kw):
    return replace(run, gnss_vel=replace(run.gnss_vel, **kw))


def _enu(run):
    """Velocities written as ENU where NED is meant."""
    return replace(run, gnss_vel=velcheck.transformed(run.gnss_vel, ENU))


def _up(run):
    """The vertical written as up."""
    return replace(run, gnss_vel=velcheck.transformed(run.gnss_vel, UP))


def _late(lag_s):
    """Velocity time tags ``lag_s`` behind the fixes'."""
    return lambda run: _vel(run, t=run.gnss_vel.t + lag_s)


def _axis(i, how):
    def corrupt(run):
        v = run.gnss_vel.v_ned.copy()
        v[:, i] = how(v[:, i])
        return _vel(run, v_ned=v)

    return corrupt


@pytest.fixture(scope="module")
def car():
    return simulate("car", 180.0, imu_grade="industrial", noise="white", seed=3, velocity=True)


def _checked(run, **over):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        out, _, findings = check_input(run, load_config(overrides=over or None))
    texts = [str(w.message) for w in caught if issubclass(w.category, DataWarning)]
    return out, findings, texts


# --- the likelihood -------------------------------------------------------------------------------


def _inn(t, ll, t_vel=(), ll_vel=0.0):
    t, tv = np.asarray(t, float), np.asarray(t_vel, float)
    return Innovations(
        t, np.full(len(t), ll), np.ones(len(t)), 0.0, 1e9, tv, np.full(len(tv), ll_vel),
        np.ones(len(tv)),
    )  # fmt: skip


def test_compare_adds_the_velocities_matched_by_their_shift():
    """The velocity log-likelihood joins the fixes' over the velocities both passes score; with a
    time-tag correction the corrected velocities are the given ones moved by ``vel_shift``."""
    t = np.arange(0.0, 100.0)
    given = _inn(t, -2.0, t, -3.0)
    same = compare(given, _inn(t, -2.0, t, -1.0))
    scored = int(np.sum(t >= 10.0))
    assert same.n_vel == scored and same.gain == pytest.approx(2.0 * scored)
    moved = compare(given, _inn(t, -2.0, t - 0.4, -1.0), vel_shift=-0.4)
    assert moved.n_vel == scored - 1 and moved.gain == pytest.approx(2.0 * (scored - 1))
    assert "and velocity" in moved.text() and f"{scored - 1} velocities" in moved.text()
    assert compare(given, _inn(t, -2.0, t - 0.4, -1.0)).n_vel == 0  # unmatched without the shift
    assert compare(_inn(t, -2.0), _inn(t, -1.0)).n_vel == 0  # no velocities: the fixes alone


# --- the proofs -----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "corrupt, check, undo",
    [
        (_enu, "velocity_frame", None),
        (_up, "velocity_frame", None),
        (_late(1.0), "velocity_time", 1.0),
        (_late(-0.5), "velocity_time", -0.5),
    ],
    ids=["enu-as-ned", "vertical-up", "tags-1s-late", "tags-0.5s-early"],
)
def test_wrong_velocities_are_proven_and_corrected(car, corrupt, check, undo):
    """ENU as NED, the vertical's sign and the time tags: proposed, proven decisively by the
    estimator (with the velocity innovations' likelihood), applied; the corrected velocities
    are the simulator's."""
    out, findings, texts = _checked(corrupt(car))
    f = [f for f in findings if f.check.startswith("velocity")]
    assert [x.check for x in f] == [check] and f[0].action == "repaired", findings
    v = f[0].details["verdict"]
    assert v["decisive"] and v["n_vel"] > 100 and v["nis_vel_corrected"] < 2.0
    np.testing.assert_allclose(out.gnss_vel.v_ned, car.gnss_vel.v_ned, atol=1e-12)
    tol = 0.0 if undo is None else 0.02  # the likelihood's best shift, against the truth
    np.testing.assert_allclose(out.gnss_vel.t, car.gnss_vel.t, atol=tol + 1e-9)
    assert not texts, texts


@pytest.mark.parametrize(
    "scenario, grade, seconds, seed, noise",
    [
        ("car", "consumer", 180.0, 0, "white"),
        ("car", "industrial", 180.0, 1, "white"),
        ("ugv-slow", "consumer", 240.0, 2, "white"),
        ("ugv-slow", "industrial", 240.0, 0, "white"),
        ("static", "consumer", 120.0, 1, "white"),
        # time-correlated fixes beside a flat road's vertical velocity (noise: its sign was
        # once "proven"), and 3 cm fixes beside the velocities' integrated noise
        ("car-city", "consumer", 300.0, 2, "gm"),
        ("car", "consumer", 180.0, 0, "rtk"),
    ],
)
def test_correct_velocities_draw_nothing(scenario, grade, seconds, seed, noise):
    """No proposal, no warning, the run as given, on correct runs with velocities."""
    run = simulate(scenario, seconds, imu_grade=grade, noise=noise, seed=seed, velocity=True)
    out, findings, texts = _checked(run)
    assert out.gnss_vel is run.gnss_vel
    assert not [f for f in findings if f.check.startswith("velocity")], findings
    assert not texts, texts


def test_velocity_free_and_disabled_runs_are_not_looked_at(car, monkeypatch):
    """Without velocities (or with [velocity] enabled = false) the velocity checks compute
    nothing."""

    def boom(*a, **k):
        raise AssertionError("looked at")

    monkeypatch.setattr(velcheck, "Track", boom)
    _checked(replace(_enu(car), gnss_vel=None))
    _checked(_enu(car), velocity={"enabled": False})


# --- the axes -------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "corrupt, axis",
    [
        (_axis(1, lambda v: v + 0.5), "east"),
        (_axis(0, lambda v: 0.0 * v), "north"),
        (_axis(0, lambda v: 1.3 * v), "north"),
        # 17 sigma / T (velcheck's notes): about 0.5 m/s over 180 s of fixes 5 m sigma down
        (_axis(2, lambda v: v - 0.8), "down"),
    ],
    ids=["east-bias", "north-zeroed", "north-scaled", "down-bias"],
)
def test_a_contradicting_axis_is_warned_of_by_name(car, corrupt, axis):
    """A biased, zeroed or scaled axis: one warning naming that axis alone with its figures; the
    data used as given, never refused."""
    bad = corrupt(car)
    out, findings, texts = _checked(bad)
    f = [f for f in findings if f.check == "velocity"]
    assert len(f) == 1 and f[0].action == "noted" and f[0].details["contradicting"] == [axis]
    assert out.gnss_vel is bad.gnss_vel
    said = [t for t in texts if "contradict" in t]
    assert len(said) == 1 and f"{axis}: the fixes depart" in said[0] and "m RMS" in said[0]


# --- the command line -----------------------------------------------------------------------------


@pytest.fixture(scope="module")
def car_dirs(tmp_path_factory):
    """A car run with velocities as a clean CSV run directory and one with its velocities
    written as ENU; the clean run's metrics."""
    root = tmp_path_factory.mktemp("velcli")
    run = simulate(
        "car", 150.0, imu_grade="industrial", noise="white", seed=5, t_start_s=T0_UNIX,
        velocity=True,
    )  # fmt: skip
    clean, bad = write_csv_run(run, root / "clean"), write_csv_run(_enu(run), root / "enu")
    assert cli.main(["run", str(clean), "--out", str(root / "o_clean"), *FAST]) == 0
    return run, bad, json.loads((root / "o_clean" / "metrics.json").read_text())


def test_cli_enu_velocities_corrected_and_stated_or_refused_with_strict(car_dirs, tmp_path, capsys):
    """Default: applied, stated on the header line, the EKF's PRMSE and velocity NIS as the
    correct run's; --strict: exit 2 and one error line naming the file and the reading."""
    _, bad, clean = car_dirs
    code = cli.main(["run", str(bad), "--out", str(tmp_path / "s"), "--strict", *FAST])
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.startswith("gnssacc: error:")]
    assert code == 2 and len(lines) == 1 and "Traceback" not in err, err
    assert str(bad / "gnss.csv") in lines[0] and "ENU" in lines[0] and "on_proof" in lines[0]
    assert cli.main(["run", str(bad), "--out", str(tmp_path / "o"), *FAST]) == 0
    got = capsys.readouterr()
    assert "read the velocities as ENU" in got.out.splitlines()[0], got.out
    m = json.loads((tmp_path / "o" / "metrics.json").read_text())
    assert [a["check"] for a in m["input_corrections"]["applied"]] == ["velocity_frame"]
    e, c = m["methods"]["ekf"], clean["methods"]["ekf"]
    assert c["stats"]["n_vel_updates"] > 100 and e["stats"]["n_vel_updates"] > 100
    assert e["prmse_m"] == pytest.approx(c["prmse_m"], rel=0.02)
    assert e["stats"]["nis_vel_mean"] == pytest.approx(c["stats"]["nis_vel_mean"], rel=0.05)


def test_gnss_file_brings_its_own_velocities(car_dirs, tmp_path):
    """--gnss FILE: the velocities are the file's (another receiver's: another seed's), or none
    with a notice when the file has none."""
    run, _, _ = car_dirs
    clean = write_csv_run(run, tmp_path / "clean")
    other = simulate(
        "car", 150.0, imu_grade="industrial", noise="white", seed=6, t_start_s=T0_UNIX,
        velocity=True,
    )  # fmt: skip
    pos = write_gnss_file(tmp_path / "other.pos", other.gnss, "pos", vel=other.gnss_vel)
    cfg = load_config()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        got = load_source(str(clean), cfg, gnss=str(pos))
    np.testing.assert_allclose(got.gnss_vel.v_ned, other.gnss_vel.v_ned, atol=2e-3)
    assert not np.allclose(got.gnss_vel.v_ned, run.gnss_vel.v_ned, atol=2e-3)
    bare = write_gnss_file(tmp_path / "bare.pos", other.gnss, "pos")
    with pytest.warns(DataWarning, match="no GNSS velocities: the source's .* dropped"):
        got = load_source(str(clean), cfg, gnss=str(bare))
    assert got.gnss_vel is None


def test_cli_velocities_tagged_at_the_next_fix_are_moved_back(car_dirs, tmp_path, capsys):
    """Each velocity written beside the next fix (tags 1 s late, as a CSV run can hold them):
    corrected by the likelihood's shift (within 20 ms of 1 s), stated, and the EKF's PRMSE and
    velocity NIS as the correct run's."""
    run, _, clean = car_dirs
    late = write_csv_run(_late(1.0)(run), tmp_path / "late")
    assert cli.main(["run", str(late), "--out", str(tmp_path / "o"), *FAST]) == 0
    assert "from the velocities' time tags" in capsys.readouterr().out.splitlines()[0]
    m = json.loads((tmp_path / "o" / "metrics.json").read_text())
    got = [c for c in m["input_checks"] if c["check"] == "velocity_time"]
    assert got[0]["action"] == "repaired" and abs(got[0]["details"]["lag_s"] - 1.0) < 0.02
    e, c = m["methods"]["ekf"], clean["methods"]["ekf"]
    assert e["prmse_m"] == pytest.approx(c["prmse_m"], rel=0.05)
    assert e["stats"]["nis_vel_mean"] == pytest.approx(c["stats"]["nis_vel_mean"], rel=0.1)
