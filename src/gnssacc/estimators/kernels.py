"""The estimators' numba kernels: which they are, and compiling them in the background.

:func:`start_background` compiles (or loads) the kernels in the background while the caller loads
data, and prints one notice line at once when they are not in the cache yet (a stamp file
written after a compilation says they are; see :func:`kernels_stamp`). A first run compiles in
child processes (numba's compiler holds the GIL, so a thread would mostly take turns with the
loading); a thread then loads what they cached. The estimators wait for the kernels where they
first need them (:func:`warm_up`, :func:`smoother_ready`), never compile them twice in one
process (numba's compile lock); without a background start, :func:`warm_up` compiles. Where the
cache lives is :mod:`gnssacc.core.jit`'s business.
"""
from __future__ import annotations

import os
import sys
import threading
import time
from pathlib import Path

from ..core.jit import KERNEL_DIR, PACKAGE_DIR, cache_folder

#: The modules whose kernels :func:`gnssacc.estimators.mechanization.warm_up` compiles.
KERNEL_SOURCES = ("mechanization.py", "kalman.py", "window_marginals.py")


def kernels_stamp() -> Path:
    """The file that marks the kernels as compiled into the cache, named by a hash of what
    numba's cache depends on (the kernels' sources with their modification times and sizes,
    numba, Python, the machine); found without importing numba, so the notice can come at once.

    numba takes a cached kernel as stale when its source file's modification time changed, even
    if its content did not (a reinstall, a checkout): the stamp must change with it, or such a
    run would compile without a notice, inside the estimators' wall times."""
    import hashlib
    import platform
    from importlib.metadata import version

    h = hashlib.sha256(f"{version('numba')} {sys.version} {platform.machine()}".encode())
    for name in KERNEL_SOURCES:
        path = KERNEL_DIR / name
        st = path.stat()
        h.update(f"{name} {st.st_mtime!r} {st.st_size}".encode())
        h.update(path.read_bytes())
    return cache_folder() / f"gnssacc-kernels-{h.hexdigest()[:16]}.stamp"


def kernels_cached() -> bool:
    """Whether a previous process compiled the kernels into the cache (see :func:`kernels_stamp`)."""
    try:
        return kernels_stamp().exists()
    except OSError:
        return False


#: The compiling processes of a first run: the EKF's propagation (the biggest kernel, needed
#: first), and the rest (the EKF's update, the smoother's, the window-consistent update's).
PARTS = ("propagation", "rest")


def compile_part(part: str) -> None:
    """Compile (or load) one of :data:`PARTS` into the cache."""
    from .mechanization import warm_up, warm_up_window

    if part == "propagation":
        warm_up(update=False)
    elif part == "rest":
        from .smoother import warm_up as smoother_warm_up

        warm_up(propagation=False)
        smoother_warm_up()
        warm_up_window()
    else:
        raise ValueError(f"unknown kernel part {part!r}; expected one of {PARTS}")


def _spawn(part: str):
    """A process compiling ``part`` into the cache (numba's compilation holds the GIL: a thread
    would take turns with the loading it is meant to overlap); ``None`` when it cannot start."""
    import subprocess

    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(PACKAGE_DIR.parent),
                                                                       os.environ.get("PYTHONPATH")]))}
    code = f"from gnssacc.estimators.kernels import compile_part; compile_part({part!r})"
    try:
        return subprocess.Popen([sys.executable, "-c", code], env=env, stdin=subprocess.DEVNULL,
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    except OSError:
        return None


def _compiled_by(proc) -> bool:
    """Wait for a compiling process; whether it filled the cache (exit code 0)."""
    return proc is not None and proc.wait() == 0


class BackgroundWarmUp:
    """Compiles (or loads) the kernels in the background; :meth:`wait` returns the seconds it took.

    A daemon thread loads the EKF's kernels, then (first run) makes sure the smoother's are in
    the cache. With ``processes=True`` a first run compiles in two child processes, one per
    :data:`PARTS`, which use the machine's other cores while this process loads and checks the
    data; the thread then loads what they cached (a failed child: it compiles here instead).

    Parameters
    ----------
    notice : file-like, optional
        Where the one-line notice goes, at once, when the kernels are not in the cache yet
        (``None``: no notice).
    processes : bool
        Compile a first run's kernels in child processes (else in the thread).
    """

    def __init__(self, notice=None, processes: bool = False):
        self.seconds: float | None = None
        self.error: BaseException | None = None
        self.compiling = not kernels_cached()
        self._processes = processes and self.compiling
        self._children: dict = {}
        self._done = threading.Event()
        self._smoother_done = threading.Event()
        self._thread = threading.Thread(target=self._run, name="gnssacc-jit", daemon=True)
        if notice is not None and self.compiling:
            print(f"gnssacc: first run: compiling the numba kernels (once, about 10 s; cache: {cache_folder()}) "
                  "while the data loads", file=notice, flush=True)

    def start(self) -> "BackgroundWarmUp":
        if self._processes:
            import atexit

            self._children = {part: _spawn(part) for part in PARTS}
            atexit.register(self.stop)
        self._thread.start()
        return self

    def stop(self) -> None:
        """End compiling children still running (the process is exiting without their kernels)."""
        for proc in self._children.values():
            if proc is not None and proc.poll() is None:
                proc.terminate()

    def _run(self) -> None:
        t0 = time.perf_counter()
        try:
            from .mechanization import warm_up

            _compiled_by(self._children.get("propagation"))
            warm_up()   # loads what the children cached, or compiles
        except BaseException as exc:   # re-raised in the waiting thread
            self.error = exc
        self.seconds = time.perf_counter() - t0
        self._done.set()   # the EKF's kernels: the estimators may start
        try:               # then, on a first run, the smoother's while the EKF and the tuner run
            if self.compiling and self.error is None:
                if not _compiled_by(self._children.get("rest")):
                    compile_part("rest")
                _write_stamp()
        except Exception:  # the smoother compiles them itself when it first runs
            pass
        self._smoother_done.set()

    def wait_all(self) -> float:
        """Block until the smoother's kernels are ready too (:meth:`wait` is the EKF's)."""
        self._smoother_done.wait()
        return self.wait()

    def wait(self) -> float:
        """Block until the kernels are ready; their compile (or load) time [s], imports included."""
        self._done.wait()
        if self.error is not None:
            raise self.error
        return float(self.seconds)


def _write_stamp() -> None:
    try:
        stamp = kernels_stamp()
        stamp.parent.mkdir(parents=True, exist_ok=True)
        stamp.touch()
    except OSError:   # no cache folder to write to: numba did not cache either, the notice repeats
        pass


_background: BackgroundWarmUp | None = None


_start_lock = threading.Lock()


def start_background(notice=sys.stderr, processes: bool = True) -> BackgroundWarmUp:
    """Start compiling the kernels in the background (once per process; later calls return the
    same one); a first run compiles in child processes unless ``processes=False``."""
    global _background
    with _start_lock:   # estimators in several threads may ask at once
        if _background is None:
            _background = BackgroundWarmUp(notice, processes).start()
    return _background


def warm_up() -> float:
    """The EKF kernels' compile (or load) time [s]: the background one's when started, else now
    (the smoother's then follow in the background on a first run)."""
    return start_background(notice=None, processes=False).wait()


def smoother_ready() -> float:
    """Wait for the smoother's (and the window-consistent update's) kernels compiled in the
    background on a first run; the seconds waited."""
    if _background is None:
        return 0.0
    t0 = time.perf_counter()
    _background.wait_all()
    return time.perf_counter() - t0
