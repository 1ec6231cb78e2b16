"""``gnssacc batch`` on this machine: throughput, scheduler overhead and worker memory.

Prints:

* **throughput** of a campaign (simulated 300 s car runs, every method, default self-tuning and
  outputs with plots, as ``gnssacc batch`` runs by default) in this process (``--jobs 1``) and on a
  local Dask cluster of 1 and 2 worker processes: tasks per minute and recording-hours per hour,
  median over ``--repeats`` campaigns; the wall time includes starting the cluster. Beside it,
  each task's CPU time over its wall time (below 1: it waited for a core) and the cores other
  processes used meanwhile, so that figures taken on a shared machine can be read;
* **scheduler overhead per task**: the round trip of a no-op task submitted and gathered one
  at a time (latency), a no-op task's share of 200 submitted at once (throughput), and in the
  campaigns, wall time x workers minus the tasks' own time, per task;
* **memory per worker** across 50 tasks on one worker: its resident set size after each task
  (sampled with ``Client.run``), and the growth per task over the last 40 (a leak shows as a slope).

Usage::

    python bench/bench_batch.py [--repeats 3] [--runs 4] [--seeds 4] [--memory-tasks 50] [--parts memory]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
import psutil

from gnssacc.campaign.batch import Ledger, SerialExecutor, failed_record, run_task, run_tasks
from gnssacc.campaign.campaign import Pattern, make_settings, plan
from gnssacc.campaign.cluster import DaskExecutor
from gnssacc.core.progress import CampaignProgress
from gnssacc.sources.csvdir import write_csv_run
from gnssacc.sources.sim import simulate


def recordings(folder: Path, n: int, duration_s: float) -> list[str]:
    """``n`` simulated car runs of ``duration_s`` seconds, as CSV run directories."""
    return [
        str(
            write_csv_run(
                simulate(
                    "car", duration_s=duration_s, imu_grade="industrial", noise="white", seed=k
                ),
                folder / f"car{k}",
            )
        )
        for k in range(n)
    ]


def campaign(sources: list[str], seeds: int, root: Path | None) -> list:
    """The tasks of a campaign of ``sources`` x ``seeds`` (all methods, noise white)."""
    settings = make_settings(
        sources,
        ["ekf", "ekf-acc", "smoother", "smoother-acc"],
        list(range(seeds)),
        [Pattern()],
        noise="white",
    )
    return plan(settings, root)


def dask_executor(workers: int) -> DaskExecutor:
    """A local Dask cluster of ``workers`` processes running campaign tasks (as ``gnssacc batch``)."""
    return DaskExecutor(run_task, failed_record, workers=workers)


def busy_cpu_s() -> float:
    """CPU time all processes on this machine have used so far [s] (user + system)."""
    t = psutil.cpu_times()
    return t.user + t.system + t.nice


def run_once(tasks: list, executor) -> dict:
    """Run ``tasks`` on ``executor`` (started and stopped inside): ``wall`` [s], ``busy`` (the
    tasks' own wall times) [s], ``share`` (their CPU time / wall time: below 1, a task waited for
    a core), ``others`` (cores used meanwhile by processes other than the tasks and this one)."""
    ledger = Ledger(tasks)
    t0, cpu0, own0 = time.perf_counter(), busy_cpu_s(), time.process_time()
    run_tasks(tasks, executor, ledger, CampaignProgress(len(tasks), lines=False))
    wall = time.perf_counter() - t0
    assert ledger.count("ok") == len(tasks), [
        r["error"] for r in ledger.ordered() if r["status"] != "ok"
    ]
    busy = sum(r["task"]["task_s"] for r in ledger.records.values())
    cpu = sum(r["task"]["cpu_s"] for r in ledger.records.values())
    own = cpu if isinstance(executor, SerialExecutor) else cpu + time.process_time() - own0
    return {
        "wall": wall,
        "busy": busy,
        "share": cpu / busy,
        "others": (busy_cpu_s() - cpu0 - own) / wall,
    }


def throughput(
    sources: list[str], seeds: int, duration_s: float, repeats: int, scratch: Path
) -> None:
    n = len(sources) * seeds
    print(
        f"\nthroughput: {n} tasks ({len(sources)} runs of {duration_s:.0f} s x {seeds} seeds, all four methods, "
        f"tuning and plots), median of {repeats}"
    )
    print(
        f"{'executor':<26} {'wall [s]':>8} {'tasks/min':>9} {'rec-h/h':>7} {'overhead/task [s]':>17} "
        f"{'CPU/wall of a task':>18} {'other load [cores]':>18}"
    )
    for label, make, workers in (
        ("this process (--jobs 1)", SerialExecutor, 1),
        ("Dask, 1 worker process", lambda: dask_executor(1), 1),
        ("Dask, 2 worker processes", lambda: dask_executor(2), 2),
    ):
        runs = [
            run_once(campaign(sources, seeds, scratch / f"{label[:4]}-{workers}-{k}"), make())
            for k in range(repeats)
        ]
        med = {key: statistics.median(r[key] for r in runs) for key in runs[0]}
        print(
            f"{label:<26} {med['wall']:8.1f} {60 * n / med['wall']:9.1f} {n * duration_s / med['wall']:7.0f} "
            f"{(med['wall'] * workers - med['busy']) / n:17.2f} {med['share']:18.2f} {med['others']:18.2f}"
        )


def noop(x):
    return x


def overhead(executor: DaskExecutor, n: int = 200) -> None:
    client = executor.client
    client.submit(noop, -1, pure=False).result()
    lat = []
    for k in range(50):
        t0 = time.perf_counter()
        client.submit(noop, k, pure=False).result()
        lat.append(time.perf_counter() - t0)
    t0 = time.perf_counter()
    client.gather(client.map(noop, range(n), pure=False))
    bulk = (time.perf_counter() - t0) / n
    print(
        f"\nscheduler overhead (2 workers): one no-op task's round trip {1e3 * statistics.median(lat):.1f} ms "
        f"(median of 50); {1e3 * bulk:.2f} ms per no-op task when {n} are submitted at once"
    )


def rss_mib() -> float:
    return psutil.Process().memory_info().rss / 2**20


def memory(sources: list[str], n_tasks: int, scratch: Path) -> None:
    tasks = campaign(sources, -(-n_tasks // len(sources)), scratch / "memory")[:n_tasks]
    rss = []
    with dask_executor(1) as ex:
        for _ in ex.run(tasks):
            rss.extend(ex.client.run(rss_mib).values())
    rss = np.array(rss)
    tail = rss[10:]
    slope = np.polyfit(np.arange(len(tail)), tail, 1)[0] if len(tail) > 2 else float("nan")
    marks = ", ".join(f"after {k}: {rss[k - 1]:.0f}" for k in (1, 10, 25, n_tasks) if k <= len(rss))
    print(
        f"\nworker memory across {len(rss)} tasks (one worker, RSS MiB): {marks}; min {rss.min():.0f}, "
        f"max {rss.max():.0f}; growth over tasks 11-{len(rss)}: {1024 * slope:+.0f} KiB per task"
    )


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument(
        "--runs", type=int, default=4, help="simulated recordings in the throughput campaign"
    )
    ap.add_argument(
        "--seeds", type=int, default=4, help="seeds per recording in the throughput campaign"
    )
    ap.add_argument("--duration", type=float, default=300.0, help="recording length [s]")
    ap.add_argument("--memory-tasks", type=int, default=50)
    ap.add_argument(
        "--parts", default="throughput,overhead,memory", help="which figures (default: all three)"
    )
    args = ap.parse_args()
    parts = args.parts.split(",")
    with tempfile.TemporaryDirectory(prefix="gnssacc-batchbench-") as tmp:
        scratch = Path(tmp)
        if "throughput" in parts:
            throughput(
                recordings(scratch / "runs", args.runs, args.duration),
                args.seeds,
                args.duration,
                args.repeats,
                scratch,
            )
        if "overhead" in parts:
            with dask_executor(2) as ex:
                overhead(ex)
        if "memory" in parts:
            memory(recordings(scratch / "short", 5, 60.0), args.memory_tasks, scratch)


if __name__ == "__main__":
    main()
