"""How many processes a run may use for independent work (figures, likelihood passes), and
independent calls run side by side in forked processes.

``$GNSSACC_JOBS`` when set (a campaign task sets it to 1: one task, one core, the worker's
share); else the cores this process may run on (its CPU affinity), at most :data:`MAX_JOBS`;
1 where processes cannot be forked (the parallel work forks, so that the children share the
loaded recording without copying it).

:func:`side_by_side` calls one function on several argument tuples at once: this process takes
every ``jobs``-th call, worker processes forked from it (a
:class:`concurrent.futures.ProcessPoolExecutor` with the ``fork`` start method) the others. The
workers inherit the function and everything it holds (the recording, numba's compiled kernels:
nothing is copied or compiled again); only the arguments and the results travel. The results
come back in the order of the calls, so a caller gets what the calls one after the other give.
A pool kept for one function (``keep=True``, e.g. a likelihood called again and again) stays
until :func:`close_pool` or until another function's pool is asked for (one at a time).
"""

from __future__ import annotations

import os
import sys
import threading
from collections.abc import Callable, Sequence
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool

#: Most processes used without ``$GNSSACC_JOBS``.
MAX_JOBS = 4
#: The environment variable that sets it.
JOBS_ENV = "GNSSACC_JOBS"

_POOL: dict = {"target": None, "executor": None}  # the one kept pool
#: Threads of this process at work a fork would copy midway (:func:`hold_forks`).
_HELD = [0]
_HELD_LOCK = threading.Lock()
_TARGET: list = [None]  # in a worker: the function it was forked for


def usable_jobs() -> int:
    """Processes this run may use (module notes)."""
    env = os.environ.get(JOBS_ENV, "").strip()
    if env:
        return max(1, int(env)) if env.isdigit() else 1
    if not hasattr(os, "fork"):
        return 1
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return max(1, min(MAX_JOBS, cores or 1))


def hold_forks() -> None:
    """A thread of this process starts work whose locks a forked child would inherit held
    (numba compiling or loading kernels, importing modules): a child that needed one would wait
    for ever. Until :func:`release_forks`, :func:`side_by_side` makes its calls here, one after
    the other (the same results)."""
    with _HELD_LOCK:
        _HELD[0] += 1


def release_forks() -> None:
    """The work :func:`hold_forks` announced is done."""
    with _HELD_LOCK:
        _HELD[0] = max(_HELD[0] - 1, 0)


def forks_held() -> bool:
    """Whether a thread's work makes forking unsafe now (:func:`hold_forks`)."""
    return _HELD[0] > 0


def side_by_side(
    target: Callable, calls: Sequence[tuple], *, keep: bool = False, jobs: int | None = None
) -> list:
    """``[target(*args) for args in calls]``, the calls shared among ``jobs`` processes (default
    :func:`usable_jobs`; module notes).

    Parameters
    ----------
    target : callable
        The function; a worker forked for it holds it as this process did at the fork.
    calls : sequence of tuple
        Its arguments, one tuple per call (sent to the workers: keep them small).
    keep : bool
        Keep the workers for further calls of the same ``target`` (:func:`close_pool` ends them).
    jobs : int, optional
        Default :func:`usable_jobs`; the calls are made here while :func:`forks_held`.

    Returns
    -------
    list
        The results in the order of ``calls``.

    Raises
    ------
    Exception
        The first call's (in order) that raised, as the calls one after the other would.
    """
    jobs = usable_jobs() if jobs is None else max(1, int(jobs))
    if jobs < 2 or len(calls) < 2 or forks_held():
        return [target(*args) for args in calls]
    executor = _executor(target, min(jobs, len(calls)) - 1, keep)
    try:
        ahead: dict[int, Future] = {
            i: executor.submit(_call, args) for i, args in enumerate(calls) if i % jobs
        }
        here = {i: _outcome(target, args) for i, args in enumerate(calls) if not i % jobs}
        results = [
            here[i] if i in here else _future_outcome(ahead[i], target, calls[i])
            for i in range(len(calls))
        ]
    finally:
        if not keep:
            executor.shutdown(wait=True)
    for ok, value in results:
        if not ok:
            raise value
    return [value for _, value in results]


def close_pool(target: Callable | None = None) -> None:
    """End the kept pool's workers (:func:`side_by_side` with ``keep``), if any (with ``target``:
    only when they were kept for it)."""
    if target is not None and _POOL["target"] != target:
        return
    executor = _POOL["executor"]
    _POOL.update(target=None, executor=None)
    if executor is not None:
        executor.shutdown(wait=True, cancel_futures=True)


class KeptWorkers:
    """A ``with`` block for an object whose method :attr:`kept_for` is called side by side with
    ``keep=True`` again and again (a likelihood's passes): the workers kept for it end with the
    block."""

    kept_for: Callable  # the method the workers are kept for

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        close_pool(self.kept_for)


def _executor(target: Callable, workers: int, keep: bool) -> ProcessPoolExecutor:
    """Workers forked now for ``target`` (or the kept ones for it)."""
    if keep and _POOL["target"] == target and _POOL["executor"] is not None:
        return _POOL["executor"]
    if keep:
        close_pool()
    import multiprocessing

    sys.stdout.flush()  # a child must not write this process's buffers again
    sys.stderr.flush()
    executor = ProcessPoolExecutor(
        workers,
        mp_context=multiprocessing.get_context("fork"),
        initializer=_adopt,
        initargs=(target,),  # inherited by the fork, not pickled
    )
    if keep:
        _POOL.update(target=target, executor=executor)
    return executor


def _adopt(target: Callable) -> None:
    _TARGET[0] = target


def _call(args: tuple):
    return _TARGET[0](*args)


def _outcome(target: Callable, args: tuple) -> tuple[bool, object]:
    try:
        return True, target(*args)
    except Exception as exc:  # noqa: BLE001 (raised in the order of the calls)
        return False, exc


def _future_outcome(future: Future, target: Callable, args: tuple) -> tuple[bool, object]:
    """A worker's outcome; the call made here when the worker died (its pool is ended)."""
    try:
        return True, future.result()
    except BrokenProcessPool:
        if _POOL["target"] == target:
            close_pool()
        return _outcome(target, args)
    except Exception as exc:  # noqa: BLE001 (raised in the order of the calls)
        return False, exc
