"""The preparation is never paid twice: its outcome is kept per recording content, settings and code
(:mod:`gnssacc.prepare.cache`), reused by a rerun with other methods or outputs (same numbers, no
filter pass, said on the header line), recomputed when a setting it reads changes or ``--retune``
asks, and a damaged or stale file is ignored with a notice, never trusted."""

from __future__ import annotations

import json

import numpy as np
import pytest

import gnssacc
import gnssacc.pipeline as pipeline
import gnssacc.prepare.cache as cache_mod
from gnssacc.cli import main
from gnssacc.core.errors import DataWarning
from gnssacc.prepare.cache import PreparationCache, recording_digest


@pytest.fixture(scope="module")
def drive():
    return gnssacc.simulate("car", 60.0, seed=4)


@pytest.fixture
def passes(monkeypatch):
    """Counts the preparation's filter passes."""
    count = {"n": 0}
    real = pipeline.filter_pass

    def counted(*args, **kwargs):
        count["n"] += 1
        return real(*args, **kwargs)

    monkeypatch.setattr(pipeline, "filter_pass", counted)
    return count


def _tuned_values(res) -> dict:
    return dict(res.prepared.tuning.values)


def test_a_rerun_reuses_the_preparation_with_the_same_numbers(drive, tmp_path, passes):
    first = gnssacc.process(drive, methods=["ekf"], cache=tmp_path)
    made = passes["n"]
    assert made > 10 and first.prepared.cache["reused"] is False
    again = gnssacc.process(drive, methods=["ekf", "ekf-acc"], cache=tmp_path)
    assert passes["n"] == made  # not one filter pass more
    assert again.prepared.cache["reused"] is True
    assert again.metrics["preparation_cache"]["reused"] is True
    assert _tuned_values(again) == _tuned_values(first)
    assert again.prepared.init.rpy.tolist() == first.prepared.init.rpy.tolist()
    assert again.metrics["methods"]["ekf"]["prmse_m"] == first.metrics["methods"]["ekf"]["prmse_m"]
    np.testing.assert_array_equal(again.solutions["ekf"].lat, first.solutions["ekf"].lat)
    assert [f.to_dict() for f in again.prepared.checks] == [
        f.to_dict() for f in first.prepared.checks
    ]


#: Modules only the preparation's steps need: the steps themselves, the input checks and the
#: judges of their proposals.
PREPARATION_ONLY = (
    "gnssacc.prepare.preparation",
    "gnssacc.prepare.settle",
    "gnssacc.prepare.judge",
    "gnssacc.prepare.clock",
    "gnssacc.prepare.fix_noise",
    "gnssacc.checks.plausibility",
    "gnssacc.checks.motionmatch",
)
#: Libraries no run needs: ``scipy.fft`` (0.3 s to import; the input checks convolve with
#: numpy's FFT) and tqdm (a run without a terminal shows no bar).
NEVER = ("scipy.fft", "tqdm")
#: One run of the 60-s drive (the ``drive`` fixture's) in a fresh interpreter, with the cache in
#: ``argv[1]``: prints whether it reused the preparation, then the modules of
#: :data:`PREPARATION_ONLY` and :data:`NEVER` it loaded.
FRESH_RUN = """
import sys, gnssacc
res = gnssacc.process(gnssacc.simulate("car", 60.0, seed=4), methods=["ekf"], cache=sys.argv[1])
print(res.prepared.cache["reused"], *[m for m in sys.argv[2:] if m in sys.modules])
"""


def test_a_rerun_does_not_import_what_only_the_preparation_needs(tmp_path):
    """A rerun that reuses the kept preparation imports none of the preparation's steps and
    checks (issue 35: a second of imports in a rerun of three), where the first run, which
    prepares, does; neither imports scipy's FFT or tqdm; each in a fresh interpreter."""
    import subprocess
    import sys

    def fresh_run() -> list[str]:
        argv = [sys.executable, "-c", FRESH_RUN, str(tmp_path), *PREPARATION_ONLY, *NEVER]
        return subprocess.run(argv, capture_output=True, text=True, check=True).stdout.split()

    assert fresh_run() == ["False", *PREPARATION_ONLY]
    assert fresh_run() == ["True"]


def test_a_setting_the_preparation_reads_makes_it_afresh(drive, tmp_path, passes):
    gnssacc.process(drive, methods=["ekf"], cache=tmp_path)
    made = passes["n"]
    other = gnssacc.process(
        drive, methods=["ekf"], cache=tmp_path, config={"nhc": {"sigma_lateral_mps": 0.2}}
    )
    assert other.prepared.cache["reused"] is False and passes["n"] > made
    assert len(list(tmp_path.glob("*.prep"))) == 2
    # Another recording (one IMU sample changed) is another key too.
    imu = drive.imu
    f_b = imu.f_b.copy()
    f_b[100, 0] += 1e-3
    from dataclasses import replace

    changed = replace(drive, imu=replace(imu, f_b=f_b))
    assert recording_digest(changed) != recording_digest(drive)
    assert recording_digest(gnssacc.simulate("car", 60.0, seed=4)) == recording_digest(drive)


def test_retune_recomputes_and_the_cli_says_reuse_on_the_header_line(
    tmp_path, monkeypatch, capsys, passes
):
    monkeypatch.setenv("GNSSACC_CACHE_DIR", str(tmp_path / "cache"))
    out = tmp_path / "out"
    args = ["run", "sim:car,duration=60", "--no-plots", "--out", str(out), "--overwrite"]
    assert main([*args, "--methods", "ekf"]) == 0
    first = json.loads((out / "metrics.json").read_text())
    made = passes["n"]
    capsys.readouterr()
    assert main([*args, "--methods", "ekf,ekf-acc"]) == 0
    header = capsys.readouterr().out.splitlines()[0]
    assert "preparation reused from" in header and "--retune" in header
    assert passes["n"] == made
    second = json.loads((out / "metrics.json").read_text())
    assert second["tuning"] == first["tuning"]
    assert second["methods"]["ekf"]["prmse_m"] == first["methods"]["ekf"]["prmse_m"]
    assert main([*args, "--methods", "ekf", "--retune"]) == 0
    assert "preparation reused" not in capsys.readouterr().out
    assert passes["n"] >= 2 * made
    third = json.loads((out / "metrics.json").read_text())
    assert third["preparation_cache"]["reused"] is False
    assert third["tuning"]["values"] == first["tuning"]["values"]  # the same recording, again


def test_a_damaged_or_stale_file_is_ignored_with_a_notice(drive, tmp_path, monkeypatch, passes):
    gnssacc.process(drive, methods=["ekf"], cache=tmp_path)
    (path,) = tmp_path.glob("*.prep")
    data = bytearray(path.read_bytes())
    data[-10] ^= 0xFF  # one byte of the payload
    path.write_bytes(bytes(data))
    made = passes["n"]
    with pytest.warns(DataWarning, match="damaged"):
        res = gnssacc.process(drive, methods=["ekf"], cache=tmp_path)
    assert res.prepared.cache["reused"] is False and passes["n"] > made
    assert gnssacc.process(drive, methods=["ekf"], cache=tmp_path).prepared.cache["reused"]
    path.write_bytes(b"not a preparation at all")
    with pytest.warns(DataWarning, match="not a gnssacc preparation file"):
        assert not gnssacc.process(drive, methods=["ekf"], cache=tmp_path).prepared.cache["reused"]
    monkeypatch.setattr(cache_mod, "code_fingerprint", lambda: "other code")
    with pytest.warns(DataWarning, match="stale"):
        assert not gnssacc.process(drive, methods=["ekf"], cache=tmp_path).prepared.cache["reused"]


def test_the_preparations_warnings_are_said_again_on_reuse(drive, tmp_path, monkeypatch):
    """A warning the preparation gave (here one it is made to give) is given again on reuse."""
    real = pipeline.prepare_recording

    def warning(*args, **kwargs):
        from gnssacc.core.errors import warn_data

        warn_data("imu", "a note of the preparation")
        return real(*args, **kwargs)

    monkeypatch.setattr(pipeline, "prepare_recording", warning)
    with pytest.warns(DataWarning, match="a note of the preparation"):
        gnssacc.process(drive, methods=["ekf"], cache=tmp_path)
    monkeypatch.setattr(pipeline, "prepare_recording", real)
    with pytest.warns(DataWarning, match="imu: a note of the preparation"):
        res = gnssacc.process(drive, methods=["ekf"], cache=tmp_path)
    assert res.prepared.cache["reused"]


def test_the_gauss_markov_setup_is_added_to_a_kept_preparation(drive, tmp_path, passes):
    gnssacc.process(drive, methods=["ekf"], cache=tmp_path)
    gm = gnssacc.process(drive, methods=["ekf-gm"], cache=tmp_path)
    assert gm.prepared.cache["reused"] and gm.prepared.gauss_markov is not None
    after_gm = passes["n"]  # the -gm setup's own passes, not the preparation's
    again = gnssacc.process(drive, methods=["ekf-gm"], cache=tmp_path)
    assert passes["n"] == after_gm  # now kept with it
    assert (
        again.metrics["methods"]["ekf-gm"]["prmse_m"] == gm.metrics["methods"]["ekf-gm"]["prmse_m"]
    )


def test_the_folder_keeps_at_most_its_limit(tmp_path, monkeypatch):
    monkeypatch.setattr(cache_mod, "MAX_FILES", 2)
    c = PreparationCache(tmp_path)
    for key in "abc":
        c.folder.mkdir(exist_ok=True)
        c.store(key, cache_mod.Stored(prepared=None, warnings=[]))
    assert len(list(tmp_path.glob("*.prep"))) == 2
    # A file that holds something else than a prepared recording is not trusted.
    with pytest.warns(DataWarning, match="holds something else"):
        assert c.load("c") is None


def test_pruning_beside_another_process_pruning_the_same_folder_keeps_the_result(
    tmp_path, monkeypatch
):
    """Two runs storing into one folder prune it at once: a file the other removed between this
    one's listing and its look at the file is passed over, and the new file is stored."""
    monkeypatch.setattr(cache_mod, "MAX_FILES", 2)
    c = PreparationCache(tmp_path)
    for key in "abc":
        c.store(key, cache_mod.Stored(prepared=None, warnings=[]))
    real_glob = type(c.folder).glob

    def glob_then_other_prunes(self, pattern):
        found = list(real_glob(self, pattern))
        for p in found:
            if p != c.path("d"):
                p.unlink()  # the other process's prune, between the listing and the stat
                break
        return iter(found)

    monkeypatch.setattr(type(c.folder), "glob", glob_then_other_prunes)
    assert c.store("d", cache_mod.Stored(prepared=None, warnings=[])) == c.path("d")
    monkeypatch.undo()
    left = sorted(p.name for p in tmp_path.glob("*.prep"))
    assert c.path("d").name in left and len(left) <= 2
