"""Figures drawn in several processes (after the table is printed): the same files as in one, one
complete result (all or nothing), and a drawing process that dies costs no figure (its share is
drawn here)."""

from __future__ import annotations

import os

import pytest

import gnssacc
import gnssacc.pipeline as pipeline


@pytest.fixture(scope="module")
def result():
    return gnssacc.process(gnssacc.simulate("car", 60.0, seed=2), methods=["ekf"], tune="none")


def test_a_result_drawn_in_processes_is_one_complete_result(result, tmp_path, monkeypatch):
    import json

    from gnssacc.outputs.outdir import MARKER

    monkeypatch.setenv("GNSSACC_JOBS", "2")
    out = result.save(tmp_path / "res")
    listed = json.loads((out / MARKER).read_text())["files"]
    assert {"summary.png", "trajectory.png", "errors.png", "metrics.json"} <= set(listed)
    assert listed == sorted(p.name for p in out.iterdir() if p.name != MARKER)


def test_figures_drawn_in_processes_are_those_drawn_in_one(result, tmp_path):
    one, two = tmp_path / "one", tmp_path / "two"
    one.mkdir(), two.mkdir()
    args = (result.run, result.solutions, result.metrics, "all")
    drawn1 = pipeline.draw_figures(one, *args, jobs=1)
    drawn2 = pipeline.draw_figures(two, *args, jobs=2)
    assert drawn1 == drawn2 and list(drawn2) == list(pipeline.PLOT_SETS["all"])
    names = sorted(p.name for p in one.glob("*.png"))
    assert names and names == sorted(p.name for p in two.glob("*.png"))
    for n in names:
        assert (one / n).read_bytes() == (two / n).read_bytes(), n
    assert set(pipeline.PLOT_SETS) == {"none", "basic", "all"}  # no share left registered


def test_a_drawing_process_that_dies_costs_no_figure(result, tmp_path, monkeypatch):
    monkeypatch.setattr(pipeline, "_draw_share", lambda *a: os._exit(3))
    drawn = pipeline.draw_figures(
        tmp_path, result.run, result.solutions, result.metrics, "basic", jobs=2
    )
    # accel_effect.png needs a method with and one without the acceleration: said in words
    assert "acceleration" in drawn.pop("accel_effect")
    assert all(v is None for v in drawn.values())
    assert sorted(p.name for p in tmp_path.glob("*.png")) == [
        "errors.png",
        "summary.png",
        "trajectory.png",
    ]


def test_the_processes_follow_gnssacc_jobs(monkeypatch):
    monkeypatch.setenv("GNSSACC_JOBS", "1")
    assert pipeline.figure_jobs() == 1
    monkeypatch.setenv("GNSSACC_JOBS", "3")
    assert pipeline.figure_jobs() == 3
    monkeypatch.delenv("GNSSACC_JOBS")
    assert 1 <= pipeline.figure_jobs() <= 4
