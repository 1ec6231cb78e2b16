"""Ctrl-C and SIGTERM as exceptions that unwind a run, wherever they land.

Within :func:`signals_raise`, SIGINT raises ``KeyboardInterrupt`` and SIGTERM raises
:class:`Terminated` (neither is an ``Exception``), and each arrival is recorded. A signal that
lands inside compiled code does not always come back as itself: numba reports ``SystemError``
caused by it, and matplotlib's Agg renderer replaces it by ``ValueError: Invalid bounding box``
with no trace of the cause. :func:`raise_if_interrupted` therefore treats any exception met
after a recorded arrival as that interruption, so that code which isolates failures never
records an interruption as an estimator's (or a plot's) failure.
"""

from __future__ import annotations

import contextlib
import signal
import sys


class Terminated(BaseException):
    """SIGTERM, raised in the main thread; like ``KeyboardInterrupt``, not an ``Exception``."""


#: Signals that arrived within the innermost :func:`signals_raise` block, in order.
_ARRIVED: list[int] = []
_RAISED = (signal.SIGINT, signal.SIGTERM)


def _interruption(signum: int) -> BaseException:
    return Terminated() if signum == signal.SIGTERM else KeyboardInterrupt()


def _record_and_raise(signum, frame):
    _ARRIVED.append(signum)
    raise _interruption(signum)


def _record(signum, frame):
    _ARRIVED.append(signum)


def hold_signals() -> None:
    """From here on SIGINT and SIGTERM are recorded (:func:`arrived`), not raised: for a child
    process about to hand its answer over and end, which a signal must not cut in the middle of
    a write (its ``Terminated`` would escape the process's target, and ``multiprocessing`` would
    print it as a traceback). Outside the main thread this does nothing."""
    for s in _RAISED:
        try:
            signal.signal(s, _record)
        except ValueError:  # not the main thread
            return


def _quiet_unraisable(previous):
    """An ``sys.unraisablehook`` that drops our own interruptions: a signal landing in a
    weakref callback or a finaliser (the garbage collector's) cannot unwind from there, and
    Python would print it as "Exception ignored ... Traceback". Its arrival is recorded, and
    :func:`raise_if_arrived` raises it at the next checkpoint."""

    def hook(unraisable):
        if isinstance(unraisable.exc_value, (Terminated, KeyboardInterrupt)) and _ARRIVED:
            return
        previous(unraisable)

    return hook


def arrived() -> int | None:
    """The first signal (``signal.SIGINT`` or ``signal.SIGTERM``) that arrived within the current
    :func:`signals_raise` block, or ``None``."""
    return _ARRIVED[0] if _ARRIVED else None


@contextlib.contextmanager
def signals_raise():
    """Within the block, SIGINT raises ``KeyboardInterrupt`` and SIGTERM :class:`Terminated`, and
    :func:`arrived` says which came; the previous handlers are restored at its end. Outside the
    main thread (where handlers cannot be set) this does nothing."""
    _ARRIVED.clear()
    old = {}
    try:
        for s in _RAISED:
            old[s] = signal.signal(s, _record_and_raise)
    except ValueError:  # not the main thread
        pass
    previous_hook = sys.unraisablehook
    if old:
        sys.unraisablehook = _quiet_unraisable(previous_hook)
    try:
        yield
    finally:
        sys.unraisablehook = previous_hook
        for s, handler in old.items():
            signal.signal(s, handler if handler is not None else signal.SIG_DFL)
        _ARRIVED.clear()


def raise_if_interrupted(exc: BaseException) -> None:
    """Re-raise the interruption behind ``exc``, if any: one in its chain of causes, or else the
    signal that :func:`arrived` before it (compiled code may have replaced it by ``exc``)."""
    seen = set()
    link = exc
    while link is not None and id(link) not in seen:
        seen.add(id(link))
        if not isinstance(link, Exception):
            raise link
        link = link.__cause__ or link.__context__
    raise_if_arrived(exc)


def raise_if_arrived(cause: BaseException | None = None) -> None:
    """Raise the interruption of the signal that :func:`arrived`, if any (compiled code may have
    swallowed it, or replaced it by ``cause``)."""
    if arrived() is not None:
        raise _interruption(arrived()) from cause
