"""``gnssacc batch``: campaigns on a real Dask cluster (a ``distributed.LocalCluster`` of two
worker processes) and in this process; nothing lost when a worker is killed or a task fails;
``--resume`` runs only what is missing and never mixes two settings."""

import csv
import json
import os
import shutil
import signal
import sys

import numpy as np
import pytest

distributed = pytest.importorskip("distributed")

from distributed.diagnostics.plugin import SchedulerPlugin  # noqa: E402

from gnssacc import pipeline  # noqa: E402
from gnssacc.analysis.montecarlo import summarise  # noqa: E402
from gnssacc.campaign import batch  # noqa: E402
from gnssacc.campaign.campaign import CAMPAIGN_FILE, TASK_FILE  # noqa: E402
from gnssacc.campaign.campaign_summary import TIMING_COLUMNS  # noqa: E402
from gnssacc.cli import main  # noqa: E402
from gnssacc.outputs.outdir import MARKER, FolderLock  # noqa: E402
from gnssacc.sources.csvdir import write_csv_run  # noqa: E402
from gnssacc.sources.sim import simulate  # noqa: E402

FAST = ["--methods", "ekf,ekf-acc", "--tune", "none", "--no-plots", "--noise", "white"]


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    """Three small simulated CSV runs (40 s, different trajectories)."""
    root = tmp_path_factory.mktemp("fleet")
    return [
        str(
            write_csv_run(
                simulate("car", duration_s=40.0, imu_grade="industrial", noise="white", seed=k),
                root / f"car{k}",
            )
        )
        for k in (1, 2, 3)
    ]


@pytest.fixture(scope="module")
def cluster():
    """A real local Dask cluster: two worker processes, one thread each."""
    with distributed.LocalCluster(
        processes=True, n_workers=2, threads_per_worker=1, dashboard_address=None
    ) as c:
        yield c


def _cli(args, capsys):
    code = main([str(a) for a in args])
    out = capsys.readouterr()
    return code, out.out, out.err


def _rows(campaign, drop=TIMING_COLUMNS):
    with open(campaign / "summary.csv") as fh:
        return [{k: v for k, v in row.items() if k not in drop} for row in csv.DictReader(fh)]


def _records(campaign):
    return {
        p.parent.relative_to(campaign).as_posix(): json.loads(p.read_text())
        for p in campaign.rglob(TASK_FILE)
    }


def _leftovers(campaign):
    """What a killed or interrupted writer could leave: partial or trash folders, lock files."""
    return sorted(
        p.name
        for p in campaign.rglob(".*")
        if p.name.startswith(".gnssacc-p")
        or p.name.startswith(".gnssacc-t")
        or p.name.endswith(".lock")
    )


class KillABusyWorker(SchedulerPlugin):
    """Once a campaign task has finished, SIGKILLs another worker that is running one."""

    name = "test-kill-a-busy-worker"

    def __init__(self, scheduler):
        self.scheduler = scheduler
        self.pid = None
        self.keys = []

    def transition(self, key, start, finish, *args, **kwargs):
        if self.pid is not None or finish != "memory" or not str(key).startswith("gnssacc-"):
            return
        for ws in self.scheduler.workers.values():
            if ws.address != kwargs.get("worker") and ws.processing:
                self.keys = [ts.key for ts in ws.processing]
                self.pid = ws.pid
                os.kill(ws.pid, signal.SIGKILL)
                return


def test_cluster_with_a_killed_worker_matches_this_process(recordings, cluster, tmp_path, capsys):
    here, there = tmp_path / "here", tmp_path / "there"
    code, _, err = _cli(
        ["batch", *recordings, "--seeds", "0-3", *FAST, "--jobs", "1", "--out", here], capsys
    )
    assert code == 0, err
    killer = KillABusyWorker(cluster.scheduler)
    cluster.scheduler.add_plugin(killer)
    try:
        code, out, err = _cli(
            [
                "batch",
                *recordings,
                "--seeds",
                "0-3",
                *FAST,
                "--scheduler",
                cluster.scheduler_address,
                "--out",
                there,
            ],
            capsys,
        )
    finally:
        cluster.scheduler.remove_plugin(killer.name)
    assert code == 0, err
    assert killer.pid is not None and killer.keys, "no worker was killed mid-campaign"
    # Every task ok, row for row the same numbers as in this process (only wall times differ).
    rows = _rows(there)
    assert len(rows) == 3 * 4 * 3 and {r["status"] for r in rows} == {"ok"}
    assert rows == _rows(here)
    # The killed worker's tasks ran again elsewhere (or in its restarted process) and finished.
    records = _records(there)
    assert len(records) == 12 and all(r["status"] == "ok" for r in records.values())
    rerun = [
        r
        for r in records.values()
        if any(k.startswith(f"gnssacc-{r['task']['key']}-") for k in killer.keys)
    ]
    assert rerun and all(not r["worker"].endswith(f":{killer.pid}") for r in rerun)
    # Whole folders only: nothing partial left by the killed writer.
    assert _leftovers(there) == []
    for name in records:
        assert (there / name / MARKER).is_file() and (there / name / "metrics.json").is_file()
    # summary.md: the paper-style table of all recordings from the same numbers.
    ekf = [float(r["prmse_m"]) for r in rows if r["method"] == "ekf"]
    md = (there / "summary.md").read_text()
    assert "all recordings: 12 of 12 tasks compared" in md
    assert f"{np.mean(ekf):.3f}" in md.split("all recordings")[1].splitlines()[3]
    assert "12 ok, 0 failed" in out


def test_failed_task_is_recorded_and_the_others_go_on(
    recordings, cluster, tmp_path, capsys, monkeypatch
):
    corrupt = tmp_path / "corrupt"
    shutil.copytree(recordings[0], corrupt)
    (corrupt / "imu.csv").write_bytes(b"t,ax,ay\n\x00\x17garbage;;;\n1,2\n")
    out = tmp_path / "c"
    code, _, err = _cli(
        [
            "batch",
            recordings[1],
            corrupt,
            "--seeds",
            "0-1",
            *FAST,
            "--scheduler",
            cluster.scheduler_address,
            "--out",
            out,
        ],
        capsys,
    )
    assert code == 1, err  # the campaign completed, some tasks failed
    rows = _rows(out)
    bad = [r for r in rows if r["source"] == "corrupt"]
    good = [r for r in rows if r["source"] != "corrupt"]
    assert len(bad) == 2 * 2 and {r["status"] for r in bad} == {"failed"}
    assert all("imu.csv" in r["error"] and "\n" not in r["error"] for r in bad)
    assert len(good) == 2 * 3 and {r["status"] for r in good} == {"ok"}
    record = _records(out)["corrupt/0"]
    assert (
        record["status"] == "failed"
        and record["kind"] == "input"
        and record["error"] == bad[0]["error"]
    )
    assert "## failed tasks" in (out / "summary.md").read_text()
    assert "Traceback" not in err
    # Repaired, the failed tasks (and only they) run again with --retry-failed.
    shutil.copy(os.path.join(recordings[0], "imu.csv"), corrupt / "imu.csv")
    ran = _count_tasks(monkeypatch)
    assert _cli(["batch", "--resume", out, "--jobs", "1"], capsys)[0] == 1 and ran == []
    assert _cli(["batch", "--resume", out, "--retry-failed", "--jobs", "1"], capsys)[0] == 0
    assert sorted(ran) == ["corrupt/none/0", "corrupt/none/1"]
    assert {r["status"] for r in _rows(out)} == {"ok"}


def _interrupt_at(monkeypatch, n):
    """Ctrl-C while the n-th task writes its folder (after one file)."""
    real, calls = pipeline.write_result_files, []

    def writing(folder, *args, **kwargs):
        calls.append(folder)
        if len(calls) == n:
            (folder / "table.txt").write_text("half")
            raise KeyboardInterrupt
        return real(folder, *args, **kwargs)

    monkeypatch.setattr(pipeline, "write_result_files", writing)


def _count_tasks(monkeypatch):
    real, ran = batch.run_task, []

    def counting(spec):
        ran.append(spec.key)
        return real(spec)

    monkeypatch.setattr(batch, "run_task", counting)
    return ran


def test_resume_runs_only_the_missing_tasks(recordings, tmp_path, capsys, monkeypatch):
    out = tmp_path / "c"
    args = ["batch", *recordings[:2], "--seeds", "0-2", *FAST, "--jobs", "1", "--out", out]
    with monkeypatch.context() as m:
        _interrupt_at(m, 4)
        code, _, err = _cli(args, capsys)
    assert code == 130 and "--resume" in err
    done = _records(out)
    assert sorted(done) == ["car1/0", "car1/1", "car1/2"] and _leftovers(out) == []
    assert not (out / "car2" / "0").exists()  # the interrupted task left nothing
    assert len(_rows(out)) == 3 * 3  # the summary holds the finished tasks
    stamps = {k: os.stat(out / k / MARKER).st_mtime_ns for k in done}
    ran = _count_tasks(monkeypatch)
    code, _, err = _cli(["batch", "--resume", out, "--jobs", "1"], capsys)
    assert code == 0, err
    assert sorted(ran) == ["car2/none/0", "car2/none/1", "car2/none/2"]
    assert stamps == {k: os.stat(out / k / MARKER).st_mtime_ns for k in done}  # never repeated
    assert len(_rows(out)) == 6 * 3 and {r["status"] for r in _rows(out)} == {"ok"}
    ran.clear()
    assert _cli(["batch", "--resume", out, "--seeds", "0-2"], capsys)[0] == 0 and ran == []


def test_a_campaign_grows_by_seeds_and_sources(recordings, tmp_path, capsys, monkeypatch):
    """``--resume C --seeds 0-3`` on a 0-1 campaign runs seeds 2 and 3 only; a new source adds its
    tasks; the finished tasks are never run again and the summary holds them all."""
    out = tmp_path / "c"
    assert (
        _cli(
            ["batch", recordings[0], "--seeds", "0-1", *FAST, "--jobs", "1", "--out", out], capsys
        )[0]
        == 0
    )
    stamps = {k: os.stat(out / k / MARKER).st_mtime_ns for k in _records(out)}
    ran = _count_tasks(monkeypatch)
    code, stdout, err = _cli(["batch", "--resume", out, "--seeds", "0-3", "--jobs", "1"], capsys)
    assert code == 0, err
    assert sorted(ran) == ["car1/none/2", "car1/none/3"]
    assert stamps == {k: os.stat(out / k / MARKER).st_mtime_ns for k in stamps}
    assert json.loads((out / CAMPAIGN_FILE).read_text())["settings"]["seeds"] == [0, 1, 2, 3]
    ran.clear()
    assert _cli(["batch", *recordings[:2], "--resume", out, "--jobs", "1"], capsys)[0] == 0
    assert sorted(ran) == [f"car2/none/{k}" for k in range(4)]
    assert len({(r["source"], r["seed"]) for r in _rows(out)}) == 8
    assert (out / "summary.html").is_file() and (out / "summary_prmse.png").is_file()


def _expect_error(capsys, args, *words):
    code, _, err = _cli(args, capsys)
    lines = [ln for ln in err.splitlines() if ln.startswith("gnssacc: error:")]
    assert code == 2 and len(lines) == 1 and "Traceback" not in err, err
    for w in words:
        assert w in lines[0], (w, lines[0])


def test_resume_with_other_settings_is_refused(recordings, tmp_path, capsys):
    config = tmp_path / "c.toml"
    config.write_text("[zupt]\nenabled = false\n")
    out = tmp_path / "c"
    assert (
        _cli(
            [
                "batch",
                recordings[0],
                "--seeds",
                "0-1",
                *FAST,
                "--config",
                config,
                "--jobs",
                "1",
                "--out",
                out,
            ],
            capsys,
        )[0]
        == 0
    )
    _expect_error(capsys, ["batch", "--resume", out, "--methods", "ekf"], "--methods")
    _expect_error(
        capsys, ["batch", "--resume", out, "--seeds", "0-5", "--methods", "ekf"], "--methods"
    )
    _expect_error(
        capsys, ["batch", "--resume", out, "--outage-every", "20:5"], "--outage", "one pattern"
    )
    _expect_error(capsys, ["batch", "--resume", out, "--noise", "gm"], "--noise")
    _expect_error(
        capsys,
        ["batch", recordings[0], "--seeds", "0-1", *FAST, "--out", out],
        "--out",
        "already holds a campaign",
        "--resume",
    )
    config.write_text("[zupt]\nenabled = true\n")
    _expect_error(capsys, ["batch", "--resume", out], "--config")
    config.write_text("[zupt]\nenabled = false\n")
    assert _cli(["batch", "--resume", out], capsys)[0] == 0
    # Two at once on one campaign: the second is refused.
    lock = FolderLock(out)
    assert lock.acquire()
    try:
        _expect_error(
            capsys, ["batch", "--resume", out], "another gnssacc batch is running this campaign"
        )
    finally:
        lock.release()
    # A task folder written with other settings is never mixed in.
    record = json.loads((out / "car1" / "1" / TASK_FILE).read_text())
    record["settings_hash"] = "0123456789abcdef"
    (out / "car1" / "1" / TASK_FILE).write_text(json.dumps(record))
    _expect_error(capsys, ["batch", "--resume", out], "car1/1", "other settings")


def test_bad_input_stops_before_any_task(recordings, tmp_path, capsys, monkeypatch):
    out = tmp_path / "c"
    _expect_error(
        capsys,
        ["batch", recordings[0], tmp_path / "nope", *FAST, "--out", out],
        "nope",
        "no such file",
    )
    _expect_error(capsys, ["batch", *FAST, "--out", out], "SOURCE", "--resume")
    _expect_error(
        capsys, ["batch", recordings[0], recordings[0], *FAST, "--out", out], "given twice"
    )
    _expect_error(capsys, ["batch", recordings[0], "--outage", "5:-1", "--out", out], "--outage")
    _expect_error(capsys, ["batch", recordings[0], "--jobs", "0", "--out", out], "--jobs")
    _expect_error(
        capsys,
        ["batch", recordings[0], "--scheduler", "not an address", "--out", out],
        "--scheduler",
    )
    _expect_error(
        capsys, ["batch", recordings[0], "--retry-failed", "--out", out], "--retry-failed"
    )
    _expect_error(capsys, ["batch", "--resume", tmp_path], "--resume", "no campaign")
    assert not out.exists()
    # Without Dask, a pool of processes is refused in one line (one job runs in this process).
    monkeypatch.setitem(sys.modules, "distributed", None)
    monkeypatch.delitem(sys.modules, "gnssacc.campaign.cluster", raising=False)
    _expect_error(
        capsys,
        ["batch", recordings[0], *FAST, "--jobs", "2", "--out", out],
        "batch: needs dask.distributed",
        'pip install "gnssacc[cluster]"',
    )
    assert not out.exists()
    assert _cli(["batch", recordings[0], *FAST, "--jobs", "1", "--out", out], capsys)[0] == 0
    assert (out / CAMPAIGN_FILE).is_file()


def test_outage_patterns_and_summary_tables(recordings, tmp_path, capsys):
    out = tmp_path / "c"
    code, _, err = _cli(
        [
            "batch",
            recordings[0],
            "--seeds",
            "0-2",
            *FAST,
            "--outage",
            "none",
            "--outage-every",
            "20:5",
            "--jobs",
            "1",
            "--out",
            out,
        ],
        capsys,
    )
    assert code == 0, err
    assert sorted(_records(out)) == [
        f"car1/{p}/{s}" for p in ("every-20_5", "none") for s in range(3)
    ]
    rows = _rows(out)
    assert {r["outages"] for r in rows} == {"none", "every 20:5"}
    assert all(
        r["prmse_outage_m"] for r in rows if r["outages"] != "none" and r["method"] != "gnss"
    )
    # summary.md's table is montecarlo.summarise of the same rows.
    results = {int(r["seed"]): {} for r in rows}
    for r in rows:
        if r["outages"] == "every 20:5":
            results[int(r["seed"])][r["method"]] = (float(r["prmse_m"]), None)
    table = summarise(results)
    md = (out / "summary.md").read_text().split("## outages: every 20:5")[1]
    assert f"{table['ekf-acc']['p_value']:.3f}" in md and f"{table['ekf']['mean']:.3f}" in md


def test_a_campaign_made_through_the_api_resumes_from_the_command_line(
    recordings, tmp_path, capsys
):
    # The API leaves the bag options out; the command line gives every one (None = not given).
    from gnssacc.campaign.batch import SerialExecutor, run_campaign
    from gnssacc.campaign.campaign import Campaign, Pattern, make_settings

    out = tmp_path / "api"
    settings = make_settings(
        [recordings[0]],
        ["ekf"],
        [0, 1],
        [Pattern(None, None)],
        noise="white",
        tune="none",
        plots=False,
    )
    with Campaign.create(out, settings) as camp, SerialExecutor() as ex:
        run_campaign(camp, ex, lines=False)
    first = _records(out)
    assert len(first) == 2 and all(r["status"] == "ok" for r in first.values())
    shutil.rmtree(out / next(iter(first)))  # one task lost
    code, _, err = _cli(["batch", "--resume", out, "--jobs", "1"], capsys)
    assert code == 0, err
    assert _records(out).keys() == first.keys()


@pytest.mark.parametrize(
    "source,warned", [("sim:ugv,imu=consumer", False), ("kitti", False), ("/data/run1", True)]
)
def test_seeds_warning_only_where_the_seed_changes_nothing(source, warned):
    """Without --noise a recording keeps its own fixes, so its seeds all give the same result; a
    simulated run draws its IMU and fixes from the seed (and KITTI its fixes): no warning there."""
    import warnings

    from gnssacc.campaign_args import _warn_if_seeds_do_nothing
    from gnssacc.core.errors import DataWarning

    settings = {
        "sources": [("x", source)],
        "seeds": [0, 1, 2],
        "noise": None,
        "bag": {"gnss_from_truth_hz": None},
    }
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        _warn_if_seeds_do_nothing(settings)
    said = [
        w for w in caught if issubclass(w.category, DataWarning) and "--seeds" in str(w.message)
    ]
    assert bool(said) == warned
