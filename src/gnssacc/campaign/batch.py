"""``gnssacc batch``: run a campaign's tasks on an executor and keep its summary up to date.

One task (:class:`gnssacc.campaign.campaign.TaskSpec`: one recording, seed and outage pattern) is one call
of :func:`run_task`, wherever it runs: in this process (:class:`SerialExecutor`, ``--jobs 1``,
no Dask needed) or on Dask workers (:class:`gnssacc.campaign.cluster.DaskExecutor`: a local process pool or
an existing cluster). It loads the recording from its path, runs :func:`gnssacc.pipeline.compare`
and writes the task's folder all or nothing, as ``gnssacc run`` does, with its record
(:data:`gnssacc.campaign.campaign.TASK_FILE`) inside. A task that raises is recorded as failed with its
one-line error, never lost; the others go on.

:func:`run_campaign` drives a campaign: the finished tasks are read back from their folders, the
missing ones run, and ``summary.csv`` and ``summary.md`` are rewritten (atomically) as results
arrive. ``gnssacc bench`` is :func:`run_campaign` over one source, writing nothing
(:func:`bench`).
"""

from __future__ import annotations

import contextlib
import json
import os
import socket
import time
import traceback
import warnings
from dataclasses import dataclass
from pathlib import Path

from ..core.errors import DataWarning, InputError, warn_data
from ..core.interrupts import raise_if_interrupted
from ..core.parallel import JOBS_ENV
from ..core.progress import CampaignProgress
from ..outputs.outdir import ResultDir
from ..pipeline import compare, compare_and_write, configure, failure_reason, load
from ..prepare.cache import open_cache
from ..sources.simspec import is_sim_spec, known_noise_config
from .campaign import TASK_FILE, Campaign, TaskSpec, config_identity, write_atomic, write_record
from .campaign_summary import SummaryMarkdown, csv_text, task_rows
from .summary_figures import html_page, write_figures

#: The error line when Dask is needed and missing.
NEEDS_DASK = (
    'needs dask.distributed: pip install "gnssacc[cluster]" (or --jobs 1 to run in this process)'
)
#: Least time between two rewrites of summary.csv and of summary.md while a campaign runs [s];
#: each also waits at least 10 times as long as its last rewrite took (so a campaign of thousands
#: of tasks spends at most a tenth of its time on them). Both are written at the end.
SUMMARY_CSV_EVERY_S = 1.0
SUMMARY_MD_EVERY_S = 5.0
#: See :data:`SUMMARY_CSV_EVERY_S`.
SUMMARY_BUSY_RATIO = 10.0


def run_task(spec: TaskSpec) -> dict:
    """Run one task here and return its record; never raises for a task's own failure.

    The record (also written as :data:`~gnssacc.campaign.campaign.TASK_FILE` into the task folder, with
    the result, or alone when the task failed): ``settings_hash``, ``task`` (``key``, ``source``,
    ``path``, ``seed``, ``outages``, ``folder``, ``task_s`` [s] wall time, ``cpu_s`` [s] CPU time
    of the process meanwhile, ``warnings``), ``status``
    (``ok``/``failed``), ``error``, ``kind`` (``input`` for bad input, ``error`` otherwise),
    ``rows`` (its ``summary.csv`` rows), ``data_warnings`` (their text), ``worker`` (host:pid),
    ``traceback`` (of an unexpected error).
    """
    os.environ.setdefault(JOBS_ENV, "1")  # one task, one core: the worker's share
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", DataWarning)
        note = _Notary(spec, time.perf_counter(), time.process_time(), caught)
        if spec.folder is None:
            return _guarded(spec, note, None)
        try:
            keep = [] if spec.source == "kitti" or is_sim_spec(spec.source) else [spec.source]
            with ResultDir(spec.folder, keep_out=keep) as target:
                record = _guarded(spec, note, target)
                if record["status"] != "ok":
                    target.replace(lambda folder: write_record(folder, record))
                return record
        except InputError as exc:  # the folder itself was refused (e.g. another writer holds it)
            return note.refused(exc)


@dataclass
class _Notary:
    """Makes a task's record with its time and warnings so far."""

    spec: TaskSpec
    t0: float  # time.perf_counter() at the start [s]
    cpu0: float  # time.process_time() at the start [s]
    caught: list

    def refused(self, exc: InputError) -> dict:
        """The record of a task stopped by bad input (``where`` and ``problem`` kept apart)."""
        return {
            **self("failed", error=f"{exc.where}: {exc.problem}", kind="input"),
            "where": exc.where,
            "problem": exc.problem,
        }

    def __call__(
        self,
        status: str,
        *,
        metrics: dict | None = None,
        error: str | None = None,
        kind: str | None = None,
        trace: str | None = None,
    ) -> dict:
        """The record: ``metrics`` of a computed task, else ``error`` (see :func:`run_task`)."""
        s = self.spec
        texts = [str(w.message) for w in self.caught if issubclass(w.category, DataWarning)]
        task = {
            "key": s.key,
            "source": s.name,
            "path": s.source,
            "seed": s.seed,
            "outages": s.pattern.text,
            "folder": s.rel,
            "task_s": time.perf_counter() - self.t0,
            "warnings": len(texts),
            "cpu_s": time.process_time() - self.cpu0,
        }
        rows = task_rows(task, metrics, error, s.options["methods"])
        return {
            "settings_hash": s.settings_hash,
            "task": task,
            "status": status,
            "error": error,
            "kind": kind,
            "rows": rows,
            "data_warnings": texts,
            "worker": f"{socket.gethostname()}:{os.getpid()}",
            "traceback": trace,
        }


def _guarded(spec: TaskSpec, note: _Notary, target: ResultDir | None) -> dict:
    """:func:`_compute`, with any failure turned into a failed record."""
    try:
        return _compute(spec, note, target)
    except InputError as exc:
        return note.refused(exc)
    except Exception as exc:  # the task's failure, not the campaign's
        raise_if_interrupted(exc)
        return note("failed", error=failure_reason(exc), kind="error", trace=traceback.format_exc())


def _compute(spec: TaskSpec, note: _Notary, target: ResultDir | None) -> dict:
    """Load, compare, and (with ``target``) write the task's folder; return the record."""
    o = spec.options
    run, cfg = _load(spec)
    if target is None:
        metrics, sols, _ = compare(run, cfg, o["methods"], tune=o["tune"], cache=open_cache())
    else:
        kept: list[dict] = []

        def files(metrics: dict) -> dict[str, str]:
            kept.append(note("ok", metrics=metrics))
            return {TASK_FILE: json.dumps(kept[-1], indent=2) + "\n"}

        outputs = o["outputs"]
        metrics, sols, _, _ = compare_and_write(
            run,
            cfg,
            o["methods"],
            target,
            tune=o["tune"],
            plots=outputs["plots"],
            report=outputs["report"],
            export=tuple(outputs["export"]),
            extra_files=files,
            cache=open_cache(),  # tasks on one recording and settings prepare it once
            jobs=1,  # one task, one core: the worker's share
        )
        if sols:
            return kept[-1]
    if not sols:
        reasons = "; ".join(
            f"{r['method']}: {r['error']}"
            for r in note("failed", metrics=metrics)["rows"]
            if r["status"] == "failed"
        )
        return note(
            "failed", metrics=metrics, error=f"every method failed ({reasons})", kind="error"
        )
    return note("ok", metrics=metrics)


def _load(spec: TaskSpec):
    """The task's run (with its outages) and configuration, read from the paths."""
    o = spec.options
    if o["config"] and config_identity(o["config"]["path"])["sha256"] != o["config"]["sha256"]:
        raise InputError(
            o["config"]["path"],
            "changed since the campaign started (its settings hash would change)",
        )
    source = None if spec.source == "kitti" else spec.source
    cfg = configure(source, preset=o["preset"], config=o["config"]["path"] if o["config"] else None)
    run = load(
        source,
        config=cfg,
        noise=o["noise"],
        seed=spec.seed,
        outage=spec.pattern.outage,
        outage_every=spec.pattern.outage_every,
        imu_frame=o["imu_frame"],
        **o["bag"],
    )
    return run, known_noise_config(cfg, run, o["tune"])


def failed_record(spec: TaskSpec, error: str, kind: str = "worker") -> dict:
    """The record of a task that never returned (its workers died); written to its folder."""
    record = _Notary(spec, time.perf_counter(), time.process_time(), [])(
        "failed", error=error, kind=kind
    )
    if spec.folder is not None:
        with ResultDir(spec.folder) as target:
            target.replace(lambda folder: write_record(folder, record))
    return record


class SerialExecutor:
    """Runs the tasks one after another in this process (``--jobs 1``; needs no Dask)."""

    description = "this process"

    def __enter__(self) -> "SerialExecutor":
        return self

    def __exit__(self, *exc) -> None:
        pass

    def run(self, tasks: list[TaskSpec]):
        """Yield each task's record as it finishes."""
        for spec in tasks:
            yield run_task(spec)

    def slots(self) -> int:
        """How many tasks run at once."""
        return 1


def open_executor(jobs: int | None, scheduler: str | None):
    """The executor for ``--jobs`` / ``--scheduler``: an existing Dask cluster, this process
    (one job), or a local Dask cluster of ``jobs`` worker processes (default: every core).

    Raises
    ------
    InputError
        Dask is needed but not installed (``batch: needs dask.distributed ...``).
    """
    jobs = jobs or len(os.sched_getaffinity(0))
    if scheduler is None and jobs == 1:
        return SerialExecutor()
    try:
        from .cluster import DaskExecutor
    except ImportError:
        raise InputError("batch", NEEDS_DASK) from None
    return DaskExecutor(
        run_task, failed_record, scheduler=scheduler, workers=None if scheduler else jobs
    )


class Ledger:
    """The records of a campaign's tasks, kept in task order, and the summary files made from them.

    Parameters
    ----------
    tasks : list of TaskSpec
        Every task of the campaign (the order of ``summary.csv``).
    root : Path or None
        The campaign folder (``None``: nothing is written).
    """

    def __init__(self, tasks: list[TaskSpec], root: Path | None = None, header: str = ""):
        self.order = {t.key: i for i, t in enumerate(tasks)}
        self.root = root
        self.header = header
        self.records: dict[str, dict] = {}
        self._md = SummaryMarkdown()
        self._due = {"summary.csv": 0.0, "summary.md": 0.0}  # monotonic time of the next rewrite

    def add(self, record: dict) -> None:
        self.records[record["task"]["key"]] = record

    def ordered(self) -> list[dict]:
        """The records in task order."""
        return sorted(self.records.values(), key=lambda r: self.order[r["task"]["key"]])

    def count(self, status: str) -> int:
        return sum(r["status"] == status for r in self.records.values())

    def write(self, final: bool = False) -> None:
        """Rewrite ``summary.csv`` and ``summary.md``, each in one step, when due (see
        :data:`SUMMARY_CSV_EVERY_S`) or ``final``."""
        if self.root is None:
            return
        figures = self._figures() if final else []
        for name, every, text in (
            ("summary.csv", SUMMARY_CSV_EVERY_S, lambda: csv_text(self.ordered())),
            ("summary.md", SUMMARY_MD_EVERY_S, lambda: self.markdown(figures)),
        ):
            t0 = time.monotonic()
            if final or t0 >= self._due[name]:
                write_atomic(self.root / name, text())
                self._due[name] = t0 + max(every, SUMMARY_BUSY_RATIO * (time.monotonic() - t0))
        if final:
            write_atomic(self.root / "summary.html", html_page(self.markdown(), figures))

    def _figures(self) -> list[str]:
        """The campaign's figures (:mod:`gnssacc.campaign.summary_figures`), drawn once at the end; a
        failure costs the figures only, and is said."""
        try:
            return write_figures(self.root, self.ordered())
        except Exception as exc:
            raise_if_interrupted(exc)
            warn_data("summary figures", f"not drawn: {type(exc).__name__}: {exc}")
            return []

    def markdown(self, figures: list[str] = ()) -> str:
        """``summary.md``'s text from the records so far (with links to ``figures``)."""
        text = self._md.text(self.ordered(), len(self.order), self.header)
        links = "".join(f"![{f}]({f})\n\n" for f in figures)
        return text.replace("\n## ", "\n" + links + "## ", 1) if links else text


def run_tasks(tasks: list[TaskSpec], executor, ledger: Ledger, show: CampaignProgress) -> None:
    """Run ``tasks`` on ``executor`` (entered here), adding each record to ``ledger`` and
    rewriting its summaries as results arrive; the final summaries are written even when
    interrupted (Ctrl-C: the tasks still running are discarded)."""
    pending = len(tasks)
    if not tasks:  # nothing to run: no cluster to start
        ledger.write(final=True)
        return
    try:
        with (
            executor,
            contextlib.closing(executor.run(tasks)) as records,
        ):  # closed (tasks cancelled) first
            show.started(executor.description, min(pending, executor.slots()))
            for record in records:
                pending -= 1
                ledger.add(record)
                ledger.write()
                show.update(
                    record["task"]["folder"],
                    record["status"] == "ok",
                    record["task"]["task_s"],
                    running=min(pending, executor.slots()),
                    error=record["error"],
                )
    finally:
        show.close()
        ledger.write(final=True)


def run_campaign(
    camp: Campaign, executor, *, retry_failed: bool = False, lines: bool = True
) -> Ledger:
    """Run what is missing of a campaign (entered by the caller, so locked) on ``executor``.

    Parameters
    ----------
    camp : Campaign
    executor
        :class:`SerialExecutor` or :class:`gnssacc.campaign.cluster.DaskExecutor` (see :func:`open_executor`).
    retry_failed : bool
        Also run again the tasks recorded as failed.
    lines : bool
        Without a terminal, print a line per finished task (stderr).

    Returns
    -------
    Ledger
        Every finished task's record.
    """
    tasks = camp.tasks()
    ledger = Ledger(tasks, camp.root, header=f"settings hash `{camp.hash}`; folder `{camp.root}`.")
    for record in camp.finished(tasks).values():
        if record["status"] == "ok" or not retry_failed:
            ledger.add(record)
    todo = [t for t in tasks if t.key not in ledger.records]
    show = CampaignProgress(
        len(tasks), done=len(ledger.records), failed=ledger.count("failed"), lines=lines
    )
    try:
        run_tasks(todo, executor, ledger, show)
    except BaseException:  # interrupted: also keep the tasks that finished as the executor stopped
        for key, record in camp.finished(tasks).items():
            ledger.records.setdefault(key, record)
        ledger.write(final=True)
        raise
    return ledger


def bench(
    source: str | None,
    methods: list[str],
    seeds: list[int],
    *,
    noise: str = "white",
    outage: str | None = None,
    outage_every: str | None = None,
    preset: str | None = None,
    config: str | None = None,
    tune: str | None = None,
    imu_frame: str = "frd",
    jobs: int = 1,
    gnss: str | None = None,
) -> dict:
    """``gnssacc bench``: a campaign of one source and outage pattern that writes nothing
    (``gnss``: a GNSS file replacing the source's fixes; the noise is then not drawn).

    Returns
    -------
    dict
        ``{seed: {method: (prmse_m, prmse_outage_m)}}`` (``"gnss"``: the raw fixes) of the seeds
        where every method ran, for :func:`gnssacc.analysis.montecarlo.summarise`.

    Raises
    ------
    InputError
        A seed's task met bad input (the first such error), or no seed succeeded.
    """
    from .campaign import Pattern, make_settings, plan
    from .campaign_summary import bench_results

    settings = make_settings(
        [source or "kitti"],
        methods,
        seeds,
        [Pattern(outage, outage_every)],
        noise=None if gnss else noise,
        preset=preset,
        tune=tune,
        config=config,
        imu_frame=imu_frame,
        bag={"gnss": gnss} if gnss else None,
    )
    tasks = plan(settings, None)
    ledger = Ledger(tasks)
    run_tasks(tasks, open_executor(jobs, None), ledger, CampaignProgress(len(tasks), lines=False))
    records = ledger.ordered()
    bad = next((r for r in records if r["kind"] == "input"), None)
    if bad is not None:
        raise InputError(bad["where"], bad["problem"])
    for text in dict.fromkeys(t for r in records for t in r["data_warnings"]):
        warnings.warn(text, DataWarning, stacklevel=2)
    for r in records:
        if r["status"] != "ok":
            warnings.warn(
                f"seed {r['task']['seed']}: failed: {r['error']}", DataWarning, stacklevel=2
            )
    results = bench_results(records)
    if not results:
        raise InputError(source or "kitti", "no seed gave a result to compare (see the warnings)")
    return results
