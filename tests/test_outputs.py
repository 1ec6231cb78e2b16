"""What a user reads: the report on every kind of run, the evo-style statistics (checked against an
independent APE computed as evo computes it), like-for-like comparison with the raw fixes, NEES
warnings, grouped warnings, and the export and inspect options."""

import json
import re
from dataclasses import replace

import numpy as np
import pytest

from gnssacc.analysis import errorstats
from gnssacc.analysis.consistency import nees_warnings
from gnssacc.cli import main
from gnssacc.core.solution import NavSolution
from gnssacc.outputs.report import group_warnings, table_rows
from gnssacc.sources.bagwrite import write_bag
from gnssacc.sources.csvdir import write_csv_run
from gnssacc.sources.sim import simulate


def _cli(args, capsys):
    code = main([str(a) for a in args])
    out = capsys.readouterr()
    return code, out.out, out.err


@pytest.fixture(scope="module")
def sim_run():
    return simulate("car", duration_s=80.0, imu_grade="industrial", noise="white", seed=3)


@pytest.fixture(scope="module")
def run_dir(sim_run, tmp_path_factory):
    return write_csv_run(sim_run, tmp_path_factory.mktemp("out") / "run")


# --- the report never takes the run down ----------------------------------------------------------


def _no_truth_dir(sim_run, tmp_path):
    d = write_csv_run(replace(sim_run, truth=None), tmp_path / "notruth")
    assert not (d / "truth.csv").exists()
    return d


CASES = {  # name: (source maker, extra arguments)
    "gauss-markov": (lambda r, d, t: "sim:car,duration=60", ["--noise", "gm"]),
    "outages": (lambda r, d, t: d, ["--outage-every", "30:10", "--tune", "none"]),
    "no-truth": (lambda r, d, t: _no_truth_dir(r, t), ["--tune", "none"]),
    "bag": (
        lambda r, d, t: write_bag(r, t / "b", "ros2-sqlite3"),
        ["--tune", "none", "--methods", "ekf,smoother"],
    ),
    "one-method": (lambda r, d, t: d, ["--tune", "none", "--methods", "ekf"]),
}


@pytest.mark.parametrize("case", list(CASES))
@pytest.mark.slow
def test_report_is_written_for_every_kind_of_run(case, sim_run, run_dir, tmp_path, capsys):
    make, extra = CASES[case]
    out = tmp_path / "o"
    code, stdout, stderr = _cli(
        ["run", make(sim_run, run_dir, tmp_path), "--report", "--out", out] + extra, capsys
    )
    assert code == 0, stderr
    page = (out / "report.html").read_text()
    assert "could not be made" not in page and "not drawn" not in stderr
    for name in re.findall(r'<img src="([^"]+)"', page):  # every figure the page shows exists
        assert (out / name).is_file(), name
    assert (
        'src="summary.png"' in page and 'src="trajectory.png"' in page and 'src="nis.png"' in page
    )
    assert "/site-packages/" not in page and str(tmp_path) not in page  # relative paths only
    if case in ("no-truth", "bag"):  # the bag has no truth topic: what the issue's user had
        assert "No truth" in page and "fix residual [m]" in stdout and "PRMSE" not in stdout
        assert not (out / "errors.png").exists()
    else:
        assert (out / "errors.png").is_file() and "NEES pos" in stdout
    # Results as they come: the preparation and each method are said before the table.
    lines = stdout.splitlines()
    table = next(i for i, ln in enumerate(lines) if ln.startswith("method "))
    assert any(ln.startswith("start: ") for ln in lines[:table])
    assert any(re.match(r"ekf: done in [0-9.]+ s", ln) for ln in lines[:table])


def test_a_failing_report_section_is_one_line(run_dir, tmp_path, capsys, monkeypatch):
    from gnssacc.outputs import htmlreport

    def broken(metrics):
        raise KeyError("something the section needed")

    monkeypatch.setattr(htmlreport, "statistics_html", broken)
    out = tmp_path / "o"
    assert (
        _cli(
            [
                "run",
                run_dir,
                "--methods",
                "ekf",
                "--tune",
                "none",
                "--report",
                "--plots",
                "none",
                "--out",
                out,
            ],
            capsys,
        )[0]
        == 0
    )
    page = (out / "report.html").read_text()
    assert (
        page.count("could not be made") == 1 and "Consistency</h2>" in page and "KeyError" in page
    )


# --- statistics ----------------------------------------------------------------------------------


def test_summary_has_evos_statistics():
    x = np.array([3.0, 4.0, 0.0, 5.0])
    s = errorstats.summary(x)
    assert s["rmse"] == pytest.approx(np.sqrt(50 / 4)) and s["mean"] == 3.0 and s["median"] == 3.5
    assert s["std"] == pytest.approx(np.sqrt(((x - 3) ** 2).mean())) and (
        s["min"],
        s["max"],
        s["n"],
    ) == (0, 5, 4)


def test_cep_of_a_circular_gaussian_is_its_closed_form():
    # |e| of a 2-D N(0, s^2 I) is Rayleigh: the q-quantile is s sqrt(-2 ln(1 - q)).
    s = 2.0
    e = np.random.default_rng(0).normal(0, s, (200_000, 2))
    h = errorstats.horizontal(e)
    assert h["cep50"] == pytest.approx(s * np.sqrt(-2 * np.log(0.5)), rel=0.01)
    assert h["cep95"] == pytest.approx(s * np.sqrt(-2 * np.log(0.05)), rel=0.01)


def test_nees_inside_its_band_when_the_sigma_is_right_and_named_per_axis_when_not():
    rng = np.random.default_rng(2)
    s = np.tile([1.0, 2.0, 0.5], (3000, 1))
    e = rng.normal(size=s.shape) * s
    ok = errorstats.nees(e, s, errorstats.AXES_NED)
    assert (
        ok["band"][0] <= ok["value"] <= ok["band"][1]
        and ok["outside"] == []
        and not ok["pooled_outside"]
    )
    assert nees_warnings({"nees_position": ok}) == []
    e[:, 2] *= 5.0  # the down errors 5x their stated sigma: NEES 25 on that axis
    bad = errorstats.nees(e, s, errorstats.AXES_NED)
    assert bad["per_axis"]["D"]["value"] == pytest.approx(25, rel=0.1) and bad["outside"] == ["D"]
    ((text, column),) = nees_warnings({"nees_position": bad})
    assert (
        text.startswith("position NEES per dof")
        and "D: errors larger than the stated sigma" in text
        and column == "nees"
    )
    assert "N:" not in text and "E:" not in text
    e[:, 0] *= 0.1  # north errors a tenth of their sigma: too cautious there
    ((text, _),) = nees_warnings({"nees_position": errorstats.nees(e, s, errorstats.AXES_NED)})
    assert "D: errors larger" in text and "N: stated sigma larger than the errors" in text


def test_a_nees_warning_says_outside_only_of_what_is_outside():
    """The pooled NEES inside its band, one axis outside its own: the warning names the axis with
    its figure and band, says the pooled one is inside, and concerns no table column for the
    attitude (the table has no attitude NEES column)."""
    axis = {"value": 4.1, "band": [0.5, 2.0]}
    inside = {"value": 1.0, "band": [0.5, 2.0]}
    stats = {
        "value": 1.94,
        "band": [0.5, 2.0],
        "per_axis": {"roll": axis, "pitch": inside, "yaw": {"value": 0.72, "band": [0.5, 2.0]}},
        "outside": ["roll"],
        "pooled_outside": False,
    }
    ((text, column),) = nees_warnings({"nees_attitude": stats})
    assert column == "nees_att"
    assert "roll 4.1 outside [0.5, 2.0]" in text and "inside [0.5, 2.0]" in text, text
    assert "1.94 outside" not in text and "1.9 outside" not in text


@pytest.mark.parametrize(
    "value, lo, hi, expected",
    [
        (1.94, 0.5, 1.9, "1.94 outside [0.50, 1.90]"),
        (2.004, 0.5, 2.0, "2.004 outside [0.500, 2.000]"),
        (0.4999, 0.5, 2.0, "0.4999 outside [0.5000, 2.0000]"),
        (7.0, 0.5, 2.0, "7.00 outside [0.50, 2.00]"),
    ],
)
def test_outside_reads_outside(value, lo, hi, expected):
    from gnssacc.analysis.consistency import outside

    assert outside(value, lo, hi) == expected


def _solution_from_truth(run, offset_ned):
    """A solution that is the truth moved by ``offset_ned(t)`` [m] (K, 3), with 1 m sigmas."""
    tr = run.truth
    p = run.origin.to_ned(tr.lat, tr.lon, tr.h) + offset_ned(tr.t - run.t_start)
    lat, lon, h = run.origin.to_llh(p)
    k = len(tr.t)
    return NavSolution(
        "test",
        tr.t,
        lat,
        lon,
        h,
        tr.v_n,
        tr.rpy,
        np.zeros((k, 3)),
        np.zeros((k, 3)),
        np.ones((k, 15)),
    )


def test_the_raw_fixes_are_compared_at_their_own_epochs(sim_run):
    """Like for like: 0.5 m off outside a 20 s outage and 40 m off inside it, against fixes whose
    error is known: the comparison at the fix epochs sees the 0.5 m only."""
    from gnssacc.sources.gnss_noise import apply_outages

    run = apply_outages(sim_run, [(30.0, 50.0)])  # spans are (start, end) [s from the start]
    far_in = lambda t: (t > 30.5) & (t < 49.5)  # off by 40 m away from the fixes around the outage
    sol = _solution_from_truth(
        run, lambda t: np.where(far_in(t)[:, None], [40.0, 0, 0], [0.3, 0.4, 0.0])
    )
    t = sol.t - run.t_start
    in_outage = (t >= 30.0) & (t < 50.0)  # spans are [start, end)
    off = np.where(far_in(t), 40.0, 0.5)
    stats = errorstats.error_statistics(run, sol)
    g = run.gnss
    fix_err = run.origin.to_ned(g.lat, g.lon, g.h) - run.origin.to_ned(*_truth_llh_at(run, g.t))
    assert stats["at_fixes"]["prmse_m"] == pytest.approx(0.5, abs=1e-6)
    assert stats["at_fixes"]["gnss_prmse_m"] == pytest.approx(
        np.sqrt(np.mean(np.sum(fix_err**2, axis=1))), rel=1e-6
    )
    assert stats["outage"]["rmse"] == pytest.approx(np.sqrt(np.mean(off[in_outage] ** 2)), abs=1e-6)
    assert stats["no_outage"]["rmse"] == pytest.approx(0.5, abs=1e-6)
    assert stats["position"]["max"] == pytest.approx(40.0, abs=1e-6)


def test_no_worse_than_the_fixes_warning_for_outage_errors(tmp_path, capsys):
    """The issue's KITTI case on a simulated run: outage errors make the EKF's all-epoch PRMSE far
    worse than the raw fixes', but at the fixes' own epochs it beats them: no warning, no '!'."""
    out = tmp_path / "o"
    code, stdout, err = _cli(
        [
            "run",
            "sim:car,imu=consumer,duration=120",
            "--outage-every",
            "60:30",
            "--methods",
            "ekf",
            "--tune",
            "none",
            "--nhc",
            "off",
            "--plots",
            "none",
            "--out",
            out,
        ],
        capsys,
    )
    assert code == 0, err  # IMU-only through the outages (the constraint would bridge them)
    m = json.loads((out / "metrics.json").read_text())
    ekf = m["methods"]["ekf"]
    assert ekf["prmse_m"] > 2 * m["gnss_prmse_m"]  # the old, unfair comparison would have warned
    assert ekf["errors"]["at_fixes"]["prmse_m"] < ekf["errors"]["at_fixes"]["gnss_prmse_m"]
    assert "worse than the raw fixes" not in err and "fixes" not in m["consistency"]["ekf"]["flags"]
    row = next(ln for ln in stdout.splitlines() if ln.startswith("ekf "))
    head = next(ln for ln in stdout.splitlines() if ln.startswith("method "))
    at = head.index("PRMSE at fixes [m]") + len("PRMSE at fixes [m]")
    assert not row[:at].rstrip().endswith("!")


def _truth_llh_at(run, t):
    tr = run.truth
    return tuple(np.interp(t, tr.t, x) for x in (tr.lat, tr.lon, tr.h))


# --- evo ----------------------------------------------------------------------------------------


def evo_like_ape(ref_tum, est_tum, max_diff=0.01):
    """``evo_ape tum REF EST --pose_relation trans_part`` with ``--align`` off, as evo computes it
    (evo.core.sync.associate_trajectories, then APE): every estimate pose is matched to the reference
    pose nearest in time, kept when within ``max_diff`` [s] (no interpolation); the APE of a pair is
    the norm of the translation difference; the statistics are over the pairs (std: population)."""
    ref, est = np.loadtxt(ref_tum), np.loadtxt(est_tum)
    j = np.clip(np.searchsorted(ref[:, 0], est[:, 0]), 1, len(ref) - 1)
    j = np.where(np.abs(ref[j - 1, 0] - est[:, 0]) <= np.abs(ref[j, 0] - est[:, 0]), j - 1, j)
    keep = np.abs(ref[j, 0] - est[:, 0]) <= max_diff
    d = np.linalg.norm(est[keep, 1:4] - ref[j[keep], 1:4], axis=1)
    return {
        "rmse": np.sqrt(np.mean(d**2)),
        "mean": d.mean(),
        "median": np.median(d),
        "std": d.std(),
        "max": d.max(),
        "n": int(keep.sum()),
    }


def test_evo_ape_on_the_tum_export_is_the_tables_position_error(run_dir, tmp_path, capsys):
    out = tmp_path / "o"
    assert (
        _cli(
            [
                "run",
                run_dir,
                "--methods",
                "ekf,smoother",
                "--tune",
                "none",
                "--plots",
                "none",
                "--export",
                "tum",
                "--out",
                out,
            ],
            capsys,
        )[0]
        == 0
    )
    metrics = json.loads((out / "metrics.json").read_text())
    for mid in ("ekf", "smoother", "smoother-online"):
        ours = metrics["methods"][mid]
        ape = evo_like_ape(out / "truth.tum", out / f"trajectory_{mid}.tum")
        assert ape["n"] == ours["n_epochs"]
        assert ape["rmse"] == pytest.approx(ours["prmse_m"], abs=1e-3)
        for k in ("mean", "median", "std", "max"):
            assert ape[k] == pytest.approx(ours["errors"]["position"][k], abs=1e-3), (mid, k)


def test_evo_ape_agrees_where_the_truth_is_sparser_than_the_estimate(tmp_path, capsys):
    """KITTI's truth is at its 1 Hz fix epochs, the smoother's nodes are not all there: evo (no
    interpolation) sees the table's errors only because truth.tum holds the truth at every estimate
    epoch too."""
    out = tmp_path / "k"
    assert (
        _cli(
            [
                "run",
                "kitti",
                "--methods",
                "smoother",
                "--tune",
                "none",
                "--plots",
                "none",
                "--export",
                "tum",
                "--out",
                out,
            ],
            capsys,
        )[0]
        == 0
    )
    metrics = json.loads((out / "metrics.json").read_text())
    import gnssacc

    own = gnssacc.load("kitti").truth.t  # the truth as the source has it
    est_t = np.loadtxt(out / "trajectory_smoother.tum")[:, 0]
    inside = (est_t >= own[0]) & (est_t <= own[-1])
    gap = np.min(np.abs(est_t[inside, None] - own[None, :]), axis=1)
    assert np.sum(gap > 0.01) >= 5  # epochs evo would drop against the source's truth alone
    assert np.all(
        np.isin(np.round(own, 6), np.round(np.loadtxt(out / "truth.tum")[:, 0], 6))
    )  # own epochs kept
    for mid in ("smoother", "smoother-online"):
        ape = evo_like_ape(out / "truth.tum", out / f"trajectory_{mid}.tum")
        assert ape["n"] == metrics["methods"][mid]["n_epochs"]
        assert ape["rmse"] == pytest.approx(metrics["methods"][mid]["prmse_m"], abs=1e-3)


# --- warnings, options ---------------------------------------------------------------------------


def test_warnings_that_differ_in_numbers_only_are_one_line():
    items = [
        ("ekf", "PRMSE 3.10 m at 300 epochs is worse"),
        ("ekf-acc", "PRMSE 3.40 m at 300 epochs is worse"),
        ("smoother", "model misfit"),
        ("smoother-acc", "model misfit"),
    ]
    assert group_warnings(items) == [
        ("ekf, ekf-acc", "PRMSE 3.10 (ekf) / 3.40 (ekf-acc) m at 300 epochs is worse"),
        ("smoother, smoother-acc", "model misfit"),
    ]


@pytest.mark.parametrize(
    "export", [["--export", "tum,bag"], ["--export", "tum", "--export", "bag"]]
)
def test_export_takes_a_comma_list_or_a_repeated_flag(export, run_dir, tmp_path, capsys):
    out = tmp_path / "o"
    code, _, err = _cli(
        ["run", run_dir, "--methods", "ekf", "--tune", "none", "--no-plots", "--out", out] + export,
        capsys,
    )
    assert code == 0, err
    assert (
        (out / "trajectory_ekf.tum").is_file()
        and (out / "truth.tum").is_file()
        and (out / "trajectories").is_dir()
    )
    assert not list(out.glob("*.png"))


def test_a_bad_export_kind_is_named(run_dir, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["run", str(run_dir), "--export", "tum,csvx"])
    assert exc.value.code == 2 and "csvx" in capsys.readouterr().err


def test_inspect_exits_2_when_it_cannot_pick_the_topics(sim_run, tmp_path, capsys):
    p = write_bag(sim_run, tmp_path / "two", "ros2-sqlite3", truth_topic="/rtk/fix")
    code, out, err = _cli(["inspect", p], capsys)
    assert code == 2 and "/rtk/fix" in out  # the listing, to choose from
    assert err.count("\n") == 1 and err.startswith("gnssacc: error: ") and "--gnss-topic" in err
    assert _cli(["inspect", p, "--gnss-topic", "/gnss/fix"], capsys)[0] == 0


def _one_method_metrics(flags: list) -> dict:
    """A ``metrics.json`` of one EKF method with truth, whose warnings concern ``flags``."""
    return {
        "duration_s": 10.0,
        "gnss_prmse_m": 5.0,
        "methods": {
            "ekf": {
                "status": "ok",
                "prmse_m": 1.0,
                "hrmse_m": 0.9,
                "n_epochs": 10,
                "improvement_pct": None,
                "runtime_s": 0.1,
                "realtime_factor": 100.0,
                "errors": {"nees_position": {"value": 1.2}, "at_fixes": {"prmse_m": 1.0}},
            }
        },
        "consistency": {
            "ekf": {"nis": {"pos": 1.0}, "warnings": ["w"] * len(flags), "flags": flags}
        },
    }


@pytest.mark.parametrize(
    "flags, marked",
    [
        (["nees_att"], []),  # an attitude NEES warning: the table has no such column
        (["zupt", "config"], []),  # another update kind's NIS, the configured noise
        (["nees"], ["NEES pos"]),
        (["nis", "fixes"], ["NIS", "PRMSE at fixes [m]"]),
    ],
)
def test_the_table_marks_the_column_a_warning_is_about(flags, marked):
    head, rows = table_rows(_one_method_metrics(flags))
    cells = dict(zip(head, rows[0], strict=True))
    assert sorted(h for h, c in cells.items() if c.endswith("!")) == sorted(marked), cells


def test_a_warning_is_flagged_with_the_figure_it_is_about(sim_run):
    """A zero-velocity NIS out of its band concerns no table column (the NIS column is the
    position NIS's); a position NIS out of its band concerns the NIS column."""
    from gnssacc.analysis.consistency import assess

    sol = _solution_from_truth(sim_run, lambda t: np.zeros((len(t), 3)))
    sol.stats = {"nis_zupt_mean": 9.0, "n_zupt_updates": 50}
    c = assess(sim_run, sol)
    assert c.flags == ["zupt"] and "zero-velocity NIS per dof 9.00, outside" in c.warnings[0]
    sol.stats = {"nis_pos_mean": 9.0, "n_pos_updates": 50}
    assert assess(sim_run, sol).flags == ["nis"]
