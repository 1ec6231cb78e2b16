"""The estimators' numba kernels: which ones a run needs, whether numba holds them, and compiling
them in the background.

The kernels come in groups (:data:`GROUPS`), and a run compiles or loads only the groups of its
methods (:func:`groups_for`): the EKF's propagation and update always (the preparation stage
decides with the EKF), ``ekf-accw``'s window integrals, the smoothers' window marginals, and
``smoother-accw``'s banded ones. Whether numba holds a group is decided by numba's own rules,
without importing numba (:func:`gnssacc.core.jit.kernel_cached`), so the notice comes at once.

:func:`start_background` compiles (or loads) the groups in the background while the caller loads
data, and prints one notice line when some are not in the cache. A first run compiles in child
processes (numba's compiler holds the GIL, so a thread would mostly take turns with the loading):
one for the EKF's propagation (the biggest kernel, needed first) and one for the other missing
groups; a thread then loads what they cached. The estimators wait for the kernels where they first
need them (:func:`warm_up` for the EKF's, :func:`ready` for a run's methods), never compile them
twice in one process (numba's compile lock). ``setup.py`` compiles every group into the wheel at
install time (:func:`compile_groups`), so that a first run after ``pip install`` finds them all.
Where the cache lives is :mod:`gnssacc.core.jit`'s business.
"""

from __future__ import annotations

import os
import sys
import threading
import time

from ..core.jit import KERNEL_DIR, PACKAGE_DIR, cache_folder, kernel_cached
from ..core.interrupts import Terminated
from ..core.parallel import hold_forks, release_forks

#: The kernels Python calls, by group, as ``(module file under gnssacc/estimators, function names)``
#: pairs (numba compiles and caches each kernel's callees with it).
GROUPS = {
    "propagation": (("mechanization.py", ("propagate",)),),
    "update": (
        ("kalman.py", ("joseph_update",)),
        ("mechanization.py", ("apply_correction", "update_state")),
        ("aids/gnss_position.py", ("position_model",)),
        ("aids/vehicle.py", ("vehicle_model",)),
        ("aids/gnss_velocity.py", ("velocity_model",)),
        ("aids/zupt.py", ("zero_rate_model",)),
        ("aids/odometry.py", ("odometry_model",)),
    ),
    "loop": (("event_loop.py", ("run_stretch",)),),
    "window": (("mechanization.py", ("kernel_force_integrals",)),),
    "chain": (
        ("window_marginals.py", ("_scatter", "_scatter_all", "_marginalize", "_node_covariances")),
        ("mechanization.py", ("half_interval_rotations",)),
    ),
    "band": (
        (
            "window_marginals.py",
            (
                "_scatter",
                "_scatter_all",
                "_band_marginalize",
                "_band_advance",
                "_band_covariances",
            ),
        ),
    ),
}
#: The EKF's groups: every run needs them, the preparation stage first.
EKF_GROUPS = ("propagation", "update")
#: The EKF's compiled event loop (:mod:`gnssacc.estimators.event_loop`): every run has it, but
#: nothing waits for it (the passes use the Python loop until it is loaded: :func:`loaded`).
LOOP_GROUP = "loop"
#: The groups of a run of the default methods (``gnssacc.pipeline.DEFAULT_METHODS``, which the
#: command line cannot import before the notice without importing numba).
DEFAULT_GROUPS = ("propagation", "update", "loop", "chain")


def groups_for(methods) -> tuple[str, ...]:
    """The kernel groups a run of ``methods`` (method ids) needs, in :data:`GROUPS` order."""
    methods = set(methods)
    need = {*EKF_GROUPS, LOOP_GROUP}
    if "ekf-accw" in methods:
        need.add("window")
    if any(m.startswith("smoother") for m in methods):
        need.add("chain")
    if "smoother-accw" in methods:
        need.add("band")
    return tuple(g for g in GROUPS if g in need)


def group_cached(group: str) -> bool:
    """Whether numba would load every kernel of ``group`` from its cache (no compilation)."""
    try:
        return all(
            kernel_cached(KERNEL_DIR / module, name)
            for module, names in GROUPS[group]
            for name in names
        )
    except OSError:
        return False


def compile_group(group: str) -> float:
    """Compile (or load from the cache) the kernels of ``group``; the seconds it took."""
    from . import mechanization

    if group == "propagation":
        return mechanization.warm_up(update=False)
    if group == "update":
        t0 = time.perf_counter()
        mechanization.warm_up(propagation=False)
        _warm_up_models()
        return time.perf_counter() - t0
    if group == "window":
        return mechanization.warm_up_window()
    if group == LOOP_GROUP:
        return _warm_up_loop()
    if group in ("chain", "band"):
        from .window_marginals import warm_up

        seconds = warm_up(band=group == "band")
        return seconds + (mechanization.warm_up_intervals() if group == "chain" else 0.0)
    raise ValueError(f"unknown kernel group {group!r}; expected one of {', '.join(GROUPS)}")


def _warm_up_models() -> None:
    """Compile (or load) the rest of the update group with the types the EKF calls them with: the
    update with its feedback, and the aids' compiled models."""
    import numpy as np

    from .aids.gnss_position import position_model
    from .aids.gnss_velocity import velocity_model
    from .aids.odometry import odometry_model
    from .aids.vehicle import vehicle_model
    from .aids.zupt import zero_rate_model
    from .layout import N_NAV
    from .mechanization import update_state

    z3, x_e, P, R_nb = np.zeros(3), np.zeros(0), np.eye(N_NAV), np.eye(3)
    pos, v_n, b_a, b_g = np.array([0.5, 0.1, 0.0]), z3.copy(), z3.copy(), z3.copy()
    H = np.zeros((2, N_NAV))
    H[:, 3:5] = np.eye(2)
    update_state(P, H, np.eye(2), np.ones(2), 0.0, -1, pos, v_n, R_nb, b_a, b_g, x_e)
    position_model(pos, R_nb, z3, 0.5, 0.1, 0.0, z3, -1, N_NAV)
    vehicle_model(R_nb, v_n, b_g, z3, z3, z3, np.eye(3), True, N_NAV)
    velocity_model(R_nb, v_n, b_g, z3, z3, z3, z3, np.arange(3, dtype=np.int64), N_NAV)
    zero_rate_model(R_nb, b_g, z3, z3, N_NAV)
    odometry_model(R_nb, v_n, b_g, z3, z3, z3, np.eye(3), True, 0.0, N_NAV, 1.0, N_NAV + 1)


def _warm_up_loop() -> float:
    """Compile (or load) the EKF's compiled event loop with the types a pass calls it with (the
    fix with a Gauss-Markov error, the constraint, an output, a velocity, a stationary epoch, an
    odometry sample); the seconds it took."""
    import numpy as np

    from .ekf_record import Recorder
    from .event_loop import run_stretch
    from .layout import N_NAV

    t0 = time.perf_counter()
    z3, n = np.zeros(3), N_NAV + 3
    prop: tuple = (np.array([0.0, 0.01, 0.02]), np.zeros((3, 3)), np.zeros((3, 3)), z3, z3, z3, z3)
    prop += (np.zeros(1, np.int64), np.ones(1, np.int64), np.zeros((1, 3)), np.zeros((1, 3)))
    prop += (
        1,
        True,
        10,
        np.eye(N_NAV),
        False,
        1.0,
        np.full(3, 60.0),
        np.ones(3),
        0.0,
        np.zeros((1, 3)),
        np.zeros(0, bool),
        np.zeros((4, 3)),
    )
    st: tuple = (np.array([0.5, 0.1, 0.0]), z3.copy(), np.eye(3), z3.copy(), z3.copy(), np.eye(n))
    st += (np.zeros(3), -1)
    fix = (np.full(1, 0.5), np.full(1, 0.1), np.zeros(1), np.eye(3)[None].copy(), z3, 0.0, N_NAV)
    nhc = (np.zeros((1, 3)), np.zeros(1, bool), z3, np.eye(3), True, 0.1, 0.5, np.eye(2))
    vel: tuple = (
        np.zeros((1, 3)),
        np.zeros((1, 3)),
        np.eye(3)[None].copy(),
        np.arange(3, dtype=np.int64),
    )
    vel += (z3, 0.0)
    zp = (np.zeros((1, 3)), np.eye(3)[None].copy(), np.eye(3), 0.0)
    odo = (
        np.zeros(1),
        np.ones(1),
        np.zeros((1, 3)),
        z3,
        np.eye(3),
        True,
        np.ones((1, 1, 1)),
        N_NAV,
    )
    out: tuple = (np.zeros(8, np.int64), *(np.zeros(8) for _ in range(3)), np.zeros(8, bool))
    out += (np.zeros((8, 3)),)
    r = Recorder(1, True)
    rec = (r.t, r.pos, r.v_n, r.R_nb, r.b_a, r.b_g, r.var, r.P_att, r.P)
    ev: tuple = (np.array([0.01, 0.012, 0.013, 0.014, 0.015, 0.016]),)
    ev += (np.array([1, 3, 4, 5, 7, 2], np.int64), np.zeros(6, np.int64))
    steps = (fix, nhc, vel, zp, odo)
    run_stretch(0, ev, 0.0, 0.02, 1, 0.0, prop, st, steps, out, rec, np.zeros(5, np.int64))
    return time.perf_counter() - t0


def compile_groups(groups=tuple(GROUPS)) -> None:
    """Compile (or load) ``groups`` into the cache (a compiling child process; the install)."""
    for group in groups:
        compile_group(group)


def _spawn(groups: list[str]):
    """A process compiling ``groups`` into the cache (numba's compilation holds the GIL: a thread
    would take turns with the loading it is meant to overlap); ``None`` when it cannot start."""
    import subprocess

    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join(
            filter(None, [str(PACKAGE_DIR.parent), os.environ.get("PYTHONPATH")])
        ),
    }
    code = (
        f"from gnssacc.estimators.kernels import compile_groups; compile_groups({list(groups)!r})"
    )
    try:
        return subprocess.Popen(
            [sys.executable, "-c", code],
            env=env,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
    except OSError:
        return None


def _compiled_by(proc) -> bool:
    """Wait for a compiling process; whether it filled the cache (exit code 0)."""
    return proc is not None and proc.wait() == 0


class BackgroundWarmUp:
    """Compiles (or loads) kernel groups in the background; :meth:`wait` returns the seconds the
    EKF's took, :meth:`wait_all` waits for the others too.

    A daemon thread loads the EKF's groups, then the others. With ``processes=True`` a first run
    compiles the missing groups in child processes (the EKF's propagation in one, the rest in
    another), which use the machine's other cores while this process loads and checks the data;
    the thread then loads what they cached (a failed child: it compiles here instead).

    Parameters
    ----------
    groups : sequence of str
        Groups of :data:`GROUPS` (the EKF's are always added).
    notice : file-like, optional
        Where the one-line notice goes, at once, when some groups are not in the cache yet
        (``None``: no notice).
    processes : bool
        Compile a first run's kernels in child processes (else in the thread).
    """

    def __init__(self, groups=EKF_GROUPS, notice=None, processes: bool = False):
        self.groups = tuple(dict.fromkeys((*EKF_GROUPS, *groups)))
        self.seconds: float | None = None
        self.error: BaseException | None = None
        #: The groups loaded so far (:func:`loaded`).
        self.loaded: set[str] = set()
        self.missing = [g for g in self.groups if not group_cached(g)]
        self.compiling = bool(self.missing)
        self._processes = processes and self.compiling
        self._children: dict = {}
        self._done = threading.Event()
        self._all_done = threading.Event()
        self._stopping = threading.Event()
        self._thread = threading.Thread(target=self._run, name="gnssacc-jit", daemon=True)
        if notice is not None and self.compiling:
            print(
                "gnssacc: first run: compiling the numba kernels it needs (once, several seconds; "
                "cache: "
                f"{cache_folder()}) while the data loads",
                file=notice,
                flush=True,
            )

    def start(self) -> "BackgroundWarmUp":
        import atexit

        # A daemon thread inside numba's loader or LLVM when the interpreter finalises (a
        # ``sys.exit`` right after Ctrl-C or SIGTERM) can abort the process ("Fatal Python
        # error: PyThreadState_Get"); the command itself leaves by ``os._exit`` (cli.entry).
        # Also ends the compiling children, which would go on after the process.
        atexit.register(self._settle_at_exit)
        if self._processes:
            first = [g for g in self.missing if g == "propagation"]
            rest = [g for g in self.missing if g != "propagation"]
            self._children = {tuple(part): _spawn(part) for part in (first, rest) if part}
        hold_forks()  # until the thread is done (released at the end of _run)
        self._thread.start()
        return self

    def stop(self) -> None:
        """End compiling children still running (the process is exiting without their kernels);
        the thread then compiles nothing more itself."""
        self._stopping.set()
        for proc in self._children.values():
            if proc is not None and proc.poll() is None:
                proc.terminate()

    def _settle_at_exit(self) -> None:
        """At the interpreter's exit: end the compiling children, then give the thread up to
        :data:`EXIT_WAIT_S` to finish (loading cached kernels takes a second or two)."""
        self.stop()
        self._all_done.wait(EXIT_WAIT_S)

    def _wait_children(self, groups) -> None:
        """Wait until each of ``groups`` that a child compiles is in the cache, or that child has
        ended (a child compiles its groups in order: the EKF's update is cached long before the
        smoother's groups after it); compile here what a failed one left."""
        for part, proc in self._children.items():
            wanted = [g for g in groups if g in part]
            if not wanted:
                continue
            while proc is not None and proc.poll() is None:
                if all(group_cached(g) for g in wanted):
                    break
                if self._stopping.wait(CHILD_POLL_S):
                    raise Terminated()  # the process is leaving: nothing to compile for
            else:
                if not _compiled_by(proc):
                    if self._stopping.is_set():
                        raise Terminated()
                    compile_groups(wanted)

    def _run(self) -> None:
        try:
            self._load_all()
        finally:
            release_forks()
            self._all_done.set()

    def _load_all(self) -> None:
        t0 = time.perf_counter()
        try:
            self._wait_children(EKF_GROUPS)  # the propagation's child, the update in the other
            compile_groups(EKF_GROUPS)  # loads what the children cached, or compiles
            self.loaded.update(EKF_GROUPS)
        except BaseException as exc:  # re-raised in the waiting thread
            self.error = exc
        self.seconds = time.perf_counter() - t0
        self._done.set()  # the EKF's kernels: the preparation stage may start
        try:  # then the other groups', while the EKF and the tuner run
            if self.error is None:
                for group in (g for g in self.groups if g not in EKF_GROUPS):
                    self._wait_children([group])
                    compile_group(group)
                    self.loaded.add(group)
        except (Exception, Terminated):  # an estimator compiles them itself when it first runs
            pass

    def wait_all(self) -> float:
        """Block until every group is ready (:meth:`wait` is the EKF's)."""
        self._all_done.wait()
        return self.wait()

    def wait(self) -> float:
        """Block until the EKF's kernels are ready; their compile (or load) time [s], imports
        included."""
        self._done.wait()
        if self.error is not None:
            raise self.error
        assert self.seconds is not None  # set before the event
        return float(self.seconds)


#: Longest wait at the interpreter's exit for the background thread to finish [s].
EXIT_WAIT_S = 5.0
#: How often the thread looks whether a compiling child has cached a group it waits for [s].
CHILD_POLL_S = 0.05

_background: BackgroundWarmUp | None = None
_start_lock = threading.Lock()


def start_background(methods=None, notice=sys.stderr, processes: bool = True) -> BackgroundWarmUp:
    """Start compiling the kernels ``methods`` need in the background (``None``: the default
    methods'); once per process: later calls return the same one. A first run compiles in child
    processes unless ``processes=False``."""
    global _background
    with _start_lock:  # estimators in several threads may ask at once
        if _background is None:
            groups = DEFAULT_GROUPS if methods is None else groups_for(methods)
            _background = BackgroundWarmUp(groups, notice, processes).start()
    return _background


def stop_background() -> None:
    """End the compiling children still running (a process leaving at once, without its exit
    handlers: they would go on compiling after the command ended)."""
    if _background is not None:
        _background.stop()


def loaded(group: str) -> bool:
    """Whether ``group`` is loaded in this process by the background compilation (without
    waiting; ``False`` when none was started)."""
    return _background is not None and group in _background.loaded


def warm_up() -> float:
    """The EKF kernels' compile (or load) time [s]: the background one's when started, else now
    (in a thread)."""
    return start_background(methods=(), notice=None, processes=False).wait()


def ready(methods) -> float:
    """Wait until the kernels ``methods`` need are loaded (compiled in the background on a first
    run, or now when the background does not do them); the seconds waited."""
    t0 = time.perf_counter()
    background = start_background(methods=methods, notice=None, processes=False)
    background.wait_all()
    for group in groups_for(methods):
        if group not in background.groups:
            compile_group(group)
    return time.perf_counter() - t0


def smoother_ready() -> float:
    """Wait for every kernel group (the smoothers' included); the seconds waited."""
    return ready(("smoother", "smoother-accw", "ekf-accw"))
