"""Figures and report lines that tell the truth (issue 34): nothing drawn for data that do not
exist, reasons in words (never an exception's text), plain-number log axes, the acceleration
effect as a paired difference with an honest interval, NIS means that never span an outage, the
first-screen verdict, and warnings that name whose number is whose."""

import math
import re
from dataclasses import replace

import numpy as np
import pytest

import gnssacc
from gnssacc.analysis.accel_effect import accel_effects, batch_interval
from gnssacc.analysis.nis_series import band_of_mean, fraction_in_band, moving_mean
from gnssacc.outputs.figstyle import plain_log_ticks, plain_number
from gnssacc.outputs.figures import PLOT_SETS, write_figures
from gnssacc.outputs.htmlreport import write_html_report
from gnssacc.outputs.report import format_table, group_warnings, verdict_line

EXCEPTION_TEXT = re.compile(r"(Error|Exception|Traceback)\b")


@pytest.fixture(scope="module")
def result():
    run = gnssacc.simulate("car", 60.0, imu_grade="industrial", noise="white", seed=3)
    return gnssacc.process(run, methods=["ekf", "ekf-acc"], tune="none")


def _draw(res, run, tmp_path, sols=None):
    return write_figures(tmp_path, run, sols or res.solutions, res.metrics, "all", cfg=res.config)


# --- nothing drawn for data that do not exist; reasons in words ----------------------------------


def test_a_truthless_run_draws_what_it_can_and_says_why_in_words(result, tmp_path):
    run = replace(result.run, truth=None)
    drawn = _draw(result, run, tmp_path)
    assert set(drawn) == set(PLOT_SETS["all"])
    for name in ("errors", "velocity_attitude"):
        assert drawn[name] and "no truth" in drawn[name] and not (tmp_path / f"{name}.png").exists()
    for name in ("summary", "accel_effect", "trajectory", "nis", "biases", "sigmas"):
        assert drawn[name] is None and (tmp_path / f"{name}.png").is_file(), name
    assert not any(EXCEPTION_TEXT.search(r) for r in drawn.values() if r)


def test_velocity_attitude_draws_only_the_parts_the_truth_has(result, tmp_path):
    tr = result.run.truth
    positions_only = replace(result.run, truth=replace(tr, v_n=None, rpy=None))
    drawn = _draw(result, positions_only, tmp_path)
    assert drawn["velocity_attitude"] == (
        "the truth has positions only (no velocity, no attitude) to compare with"
    )
    assert not (tmp_path / "velocity_attitude.png").exists()
    page = write_html_report(
        tmp_path, positions_only, result.solutions, result.metrics, None, figures=drawn
    ).read_text()
    assert "velocity_attitude.png not drawn: the truth has positions only" in page
    assert not EXCEPTION_TEXT.search(page)
    # With attitude only, one column (attitude) is drawn: no empty velocity panels.
    drawn = _draw(result, replace(result.run, truth=replace(tr, v_n=None)), tmp_path)
    assert drawn["velocity_attitude"] is None


def test_accel_effect_needs_both_methods_and_says_so(result, tmp_path):
    drawn = _draw(result, result.run, tmp_path, {"ekf": result.solutions["ekf"]})
    assert "both with and without the acceleration" in drawn["accel_effect"]
    assert not (tmp_path / "accel_effect.png").exists()


def test_the_report_has_one_observability_heading_and_no_empty_columns(result, tmp_path):
    drawn = _draw(result, result.run, tmp_path)
    page = write_html_report(
        tmp_path, result.run, result.solutions, result.metrics, result.config, figures=drawn
    ).read_text()
    assert page.count(">Observability</h2>") == 1
    for table in re.findall(r"<table>(.*?)</table>", page, re.S):
        rows = [re.findall(r"<t[dh][^>]*>(.*?)</t[dh]>", r) for r in table.split("</tr>") if r]
        body = [r for r in rows[1:] if r]
        for j in range(1, len(rows[0])):
            assert any(r[j] != "-" for r in body if j < len(r)), rows[0][j]
    assert '<p class="verdict">verdict: ' in page


# --- plain numbers on log axes --------------------------------------------------------------------


@pytest.mark.parametrize(
    "lo, hi", [(5.7, 6.5), (0.6, 3.2), (0.01, 1000.0), (1e-4, 1e4), (0.9, 1.1), (2.0, 3.0)]
)
def test_log_ticks_are_few_plain_and_inside(lo, hi):
    ticks = plain_log_ticks(lo, hi)
    assert 2 <= len(ticks) <= 7 and all(lo <= v <= hi for v in ticks)
    assert len(set(plain_number(v) for v in ticks)) == len(ticks)  # distinct labels
    assert not any(re.search(r"[e^x]", plain_number(v)) for v in ticks)


# --- the acceleration effect: a paired difference with an honest interval -----------------------


def test_batch_interval_of_a_constant_shift_is_that_shift():
    mean, lo, hi, k = batch_interval(np.full(400, -0.25))
    assert (mean, lo, hi, k) == (
        pytest.approx(-0.25),
        pytest.approx(-0.25),
        pytest.approx(-0.25),
        20,
    )


def test_batch_interval_is_wide_for_correlated_differences():
    rng = np.random.default_rng(1)
    white = rng.normal(0.0, 1.0, 4000)
    _, lo, hi, _ = batch_interval(white)
    naive = 1.96 / math.sqrt(len(white))  # independent values: the textbook half-width
    assert 0.6 * naive < (hi - lo) / 2 < 1.6 * naive
    ar = np.zeros(4000)  # a slowly varying difference (lag-1 correlation 0.99), unit variance
    for k in range(1, len(ar)):
        ar[k] = 0.99 * ar[k - 1] + math.sqrt(1 - 0.99**2) * rng.normal()
    _, lo, hi, _ = batch_interval(ar)
    assert (hi - lo) / 2 > 4 * naive  # independent values would claim a 4x narrower interval


def test_accel_effect_pairs_the_same_epochs(result):
    (e,) = accel_effects(result.run, result.solutions)
    assert (e.base, e.aided) == ("ekf", "ekf-acc") and e.truth
    from gnssacc.analysis.metrics import state_errors

    h = {m: np.hypot(*state_errors(result.run, s)[:, :2].T) for m, s in result.solutions.items()}
    ok = np.isfinite(h["ekf"]) & np.isfinite(h["ekf-acc"])
    np.testing.assert_allclose(e.d, (h["ekf-acc"] - h["ekf"])[ok])
    assert e.lo <= e.mean <= e.hi


# --- NIS over the run -----------------------------------------------------------------------------


def test_moving_mean_never_spans_a_gap():
    t = np.concatenate([np.arange(50.0), 80.0 + np.arange(50.0)])  # a 31 s outage
    x = np.concatenate([np.full(50, 4.0), np.full(50, 1.0)])
    m = moving_mean(t, x, 20)
    assert np.all(np.isnan(m[:19])) and np.all(m[19:50] == 4.0)
    assert np.all(np.isnan(m[50:69])) and np.all(m[69:] == 1.0)  # no mix of 4 and 1
    lo, hi = band_of_mean(20)
    assert lo < 1.0 < hi < 4.0
    assert fraction_in_band(t, x, 20) == pytest.approx(31 / 62)


# --- the verdict and the warnings ----------------------------------------------------------------


def _metrics(prmse: dict, fixes: float | None, nis: dict | None = None) -> dict:
    methods = {
        m: {"prmse_m": v, "errors": {"at_fixes": {"prmse_m": v}} if v is not None else {}}
        for m, v in prmse.items()
    }
    nis = nis or {m: 1.0 for m in prmse}
    return {
        "methods": methods,
        "gnss_prmse_m": fixes,
        "consistency": {m: {"nis": {"pos": v}} for m, v in nis.items()},
    }


def test_verdict_names_the_best_method_and_its_ties():
    line = verdict_line(_metrics({"ekf": 2.0, "ekf-acc": 1.5, "smoother": 1.505}, 6.0))
    assert line.startswith("verdict: ekf-acc and smoother (equal within 1 %) are most accurate")
    assert "4.0x better than the raw fixes (6.00 m)" in line
    line = verdict_line(_metrics({"ekf": 2.0, "ekf-acc": 1.5}, 6.0))
    assert line.startswith("verdict: ekf-acc is most accurate: 1.50 m")


def test_verdict_says_when_no_method_beats_the_fixes():
    line = verdict_line(_metrics({"ekf": 3.2, "smoother": 3.1}, 3.0))
    assert line.startswith("verdict: no method beats the raw fixes (best smoother")


def test_verdict_without_truth_names_the_most_consistent():
    m = _metrics({"ekf": None, "smoother": None}, None, {"ekf": 3.0, "smoother": 0.8})
    assert verdict_line(m).startswith("verdict (no truth: accuracy cannot be scored): smoother")


def test_verdict_without_truth_passes_over_a_flagged_nis():
    # A mean NIS of 1.0 made of innovations a warning flags (correlated, out of band most of the
    # run) is no evidence of consistency: the unflagged method is named; when all are flagged, the
    # nearest is named and the verdict says they are flagged.
    m = _metrics({"ekf": None, "smoother": None}, None, {"ekf": 1.0, "smoother": 1.3})
    m["consistency"]["ekf"]["flags"] = ["nis"]
    line = verdict_line(m)
    assert line.startswith("verdict (no truth: accuracy cannot be scored): smoother"), line
    assert "flagged" not in line
    m["consistency"]["smoother"]["flags"] = ["fixes", "nis"]
    line = verdict_line(m)
    assert ": ekf is the most consistent" in line and "every method's NIS is flagged" in line, line


def test_the_printed_table_starts_with_the_verdict(result):
    assert format_table(result.metrics).splitlines()[0].startswith("verdict: ")


def test_grouped_warnings_say_whose_number_is_whose():
    ((who, text),) = group_warnings(
        [("ekf", "NIS 2.1 in [0.4, 2.0]"), ("ekf-acc", "NIS 2.3 in [0.4, 2.0]")]
    )
    assert who == "ekf, ekf-acc" and text == "NIS 2.1 (ekf) / 2.3 (ekf-acc) in [0.4, 2.0]"


def test_a_tuned_run_is_never_advised_to_tune(result):
    from gnssacc.analysis.consistency import assess

    sol = result.solutions["ekf"]
    bad = replace(sol, stats={**sol.stats, "nis_pos_mean": 9.0})
    for tuned in (False, True):
        text = " ".join(assess(result.run, bad, tuned=tuned).warnings)
        assert "outside the consistent band" in text
        assert ("--tune auto" in text) is (not tuned)


# --- a straight road is readable; the preparation says what it does ------------------------


def test_a_straight_track_is_drawn_along_and_across_its_line():
    from gnssacc.outputs.figures import TrackFrame

    s = np.linspace(0.0, 1000.0, 200)  # 1 km at heading 30 deg, 2 m of wander across
    heading = np.radians(30.0)
    across = 2.0 * np.cos(6 * np.pi * s / 1000.0)  # even about the middle: no tilt of the line
    east = s * np.sin(heading) + across * np.cos(heading)
    north = s * np.cos(heading) - across * np.sin(heading)
    frame = TrackFrame(np.column_stack([east, north]))
    assert frame.straight
    x, y = frame.xy(east, north)
    assert np.ptp(x) == pytest.approx(1000.0, rel=1e-3)
    np.testing.assert_allclose(np.abs(y - y.mean()), np.abs(across - across.mean()), atol=0.05)
    loop = np.column_stack([100 * np.cos(s / 100), 100 * np.sin(s / 100)])
    assert not TrackFrame(loop).straight


def test_the_preparation_says_each_stage_without_a_terminal(capsys):
    from gnssacc.core.progress import StageProgress

    stages = StageProgress(2)
    stages("input checks")
    stages("start")
    stages.close()
    err = capsys.readouterr().err.splitlines()
    assert err == [
        "gnssacc: preparing: input checks (1 of 2) ...",
        "gnssacc: preparing: start (2 of 2) ...",
    ]
    StageProgress(2, enable=False)("input checks")
    assert capsys.readouterr().err == ""


def test_a_truth_with_a_caveat_says_it_on_the_report(result, tmp_path):
    """A reference that is not an independent truth (comma2k19's optimiser pose) says so at the
    top of the report, not only in a printed warning."""
    caveat = "the reference fuses these fixes: not an independent truth"
    run = replace(result.run, truth=replace(result.run.truth, caveat=caveat))
    page = write_html_report(
        tmp_path, run, result.solutions, result.metrics, None, figures={}
    ).read_text()
    top = page[: page.index("<nav>")]
    assert f"<b>Truth:</b> {caveat}" in top
    plain = write_html_report(
        tmp_path, result.run, result.solutions, result.metrics, None, figures={}
    ).read_text()
    assert "<b>Truth:</b>" not in plain
