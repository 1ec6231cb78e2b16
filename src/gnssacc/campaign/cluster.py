"""Campaign tasks on Dask (``dask.distributed``): a local process pool or an existing cluster.

Imported only when a campaign runs on Dask (it needs the ``cluster`` extra). Each task is one
``Client.submit`` of :func:`gnssacc.campaign.batch.run_task` with a :class:`~gnssacc.campaign.campaign.TaskSpec`:
paths and settings, never recording data, so workers must see the recordings and the campaign
folder at the same paths (a shared filesystem).

Nothing is lost when a worker dies: the scheduler gives the tasks of a lost worker to another
(up to ``distributed.scheduler.allowed-failures`` times, 3 by default; then
:class:`distributed.KilledWorker`, recorded as the task's failure). A task's folder is written
all or nothing, so a task killed half-way leaves nothing behind but a partial folder that the
next writer in that place deletes.

Each worker keeps its compiled numba kernels across tasks (it is one long-lived process); the
:class:`WarmUp` plugin loads them when a worker starts, before its first task.
"""

from __future__ import annotations

import contextlib
import logging
import signal
import threading
import uuid

import dask
from distributed import Client, KilledWorker, LocalCluster, as_completed
from distributed.diagnostics.plugin import WorkerPlugin
from tqdm import tqdm

from ..core.errors import InputError
from ..pipeline import failure_reason
from .campaign import TaskSpec

#: Seconds to wait for a scheduler given with ``--scheduler``.
CONNECT_TIMEOUT_S = 30
#: Dask settings of the local cluster (its workers keep them when they restart). Off: the
#: workers' statistical profiler, which feeds only the dashboard (off here) and keeps about a MB
#: of call trees per second of work, for up to ``distributed.admin.low-level-log-length`` seconds.
LOCAL_CONFIG = {"distributed.worker.profile.enabled": False}
#: Dask's re-runs of a task that raised outside :func:`~gnssacc.campaign.batch.run_task`'s own guard
#: (e.g. a worker that cannot unpickle it); a worker's death is handled by the scheduler instead.
RETRIES = 1


class WarmUp(WorkerPlugin):
    """Loads gnssacc's numba kernels on each worker when it starts (and on every restarted one).

    Parameters
    ----------
    ignore_sigint : bool
        Let the worker ignore SIGINT: set for the local cluster, whose worker processes share the
        terminal, so that Ctrl-C reaches only ``gnssacc batch``, which then closes them.
    """

    name = "gnssacc-warm-up"
    idempotent = True

    def __init__(self, ignore_sigint: bool = False):
        self.ignore_sigint = ignore_sigint

    def setup(self, worker) -> None:
        if self.ignore_sigint:
            signal.signal(
                signal.SIGINT, signal.SIG_IGN
            )  # the worker's event loop runs in its main thread
        # tqdm's default lock holds a multiprocessing semaphore, which a worker killed mid-task
        # would leak (a warning at exit); a worker's bars are off, a thread lock is enough.
        tqdm.set_lock(threading.RLock())
        # In the background: registering the plugin returns at once, and a cluster closed meanwhile
        # (Ctrl-C at the start) does not wait for it. A task that starts first waits for the same
        # imports and kernels (Python's import lock, numba's compile lock), never compiles them twice.
        threading.Thread(target=_warm_up, name="gnssacc-warm-up", daemon=True).start()


def _warm_up() -> None:
    """Import what a task needs (gtsam included) and load the numba kernels."""
    from .. import pipeline  # noqa: F401
    from ..estimators import kernels, smoother  # noqa: F401

    kernels.compile_groups(("propagation", "update", "loop", "window"))  # the EKFs (ekf-accw too)


@contextlib.contextmanager
def _sigint_ignored():
    """Ignore SIGINT within the block (in the main thread; elsewhere this does nothing).

    Processes started meanwhile inherit the ignored signal (it survives ``exec``), so a local
    cluster's workers never see the terminal's Ctrl-C, even before :class:`WarmUp` runs in them.
    A Ctrl-C within the block is lost (the cluster starts in a second or two).
    """
    try:
        old = signal.signal(signal.SIGINT, signal.SIG_IGN)
    except ValueError:
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old)


class DaskExecutor:
    """Runs tasks on a Dask cluster: an existing one (``scheduler``) or a local one started here.

    Parameters
    ----------
    run_task : callable
        ``run_task(spec) -> record``, submitted once per task (:func:`gnssacc.campaign.batch.run_task`).
    failed_record : callable
        ``failed_record(spec, error, kind) -> record`` for a task that never returned.
    scheduler : str, optional
        Address of a running scheduler (``tcp://host:8786``).
    workers : int, optional
        Without ``scheduler``: worker processes of the local cluster (one thread each).
    """

    def __init__(
        self, run_task, failed_record, scheduler: str | None = None, workers: int | None = None
    ):
        self.run_task, self.failed_record = run_task, failed_record
        self.scheduler = scheduler
        self.workers = workers
        self.cluster = None
        self.client = None
        self.description = scheduler or f"a local Dask cluster of {workers} worker processes"

    def __enter__(self) -> "DaskExecutor":
        try:
            if self.scheduler is None:
                with _sigint_ignored(), dask.config.set(LOCAL_CONFIG):
                    self.cluster = LocalCluster(
                        n_workers=self.workers,
                        threads_per_worker=1,
                        processes=True,
                        dashboard_address=None,
                        silence_logs=logging.CRITICAL,
                    )
            self.client = Client(self.cluster or self.scheduler, timeout=CONNECT_TIMEOUT_S)
            self.client.register_plugin(WarmUp(ignore_sigint=self.cluster is not None))
        except OSError as exc:
            self.__exit__()
            if self.scheduler is None:
                raise InputError("batch", f"cannot start a local Dask cluster: {exc}") from None
            raise InputError("--scheduler", f"cannot connect to {self.scheduler}: {exc}") from None
        except BaseException:
            self.__exit__()
            raise
        return self

    def __exit__(self, *exc) -> None:
        for part in (self.client, self.cluster):
            if part is not None:
                part.close()

    def slots(self) -> int:
        """Worker threads in the cluster now (tasks that can run at once)."""
        return max(sum(self.client.nthreads().values()), 1)

    def run(self, tasks: list[TaskSpec]):
        """Submit every task, then yield each one's record as it finishes; a task whose workers
        kept dying gets a failed record. Leaving early cancels the tasks not yet finished."""
        token = uuid.uuid4().hex[:8]
        futures = {
            self.client.submit(
                self.run_task, t, key=f"gnssacc-{t.key}-{token}", pure=False, retries=RETRIES
            ): t
            for t in tasks
        }
        try:
            for fut in as_completed(list(futures)):
                spec = futures.pop(fut)
                yield self._record(fut, spec)
                fut.release()
        finally:
            if futures:
                self.client.cancel(list(futures))

    def _record(self, fut, spec: TaskSpec) -> dict:
        """The finished future's record; a failed record when its workers died, or it raised."""
        try:
            return fut.result()
        except KilledWorker as exc:
            return self.failed_record(
                spec,
                f"its workers died while running it (killed, or out of memory): "
                f"{failure_reason(exc)}",
            )
        except Exception as exc:
            if fut.cancelled():
                raise InputError(
                    self.description,
                    f"the cluster cancelled task {spec.key} (scheduler lost or "
                    f"restarted?); resume the campaign with --resume",
                ) from None
            return self.failed_record(spec, failure_reason(exc), kind="error")
