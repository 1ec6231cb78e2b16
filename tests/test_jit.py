"""Where the numba kernels are cached, the first-run notice, which kernels a run compiles, and who
compiles them.

The package is copied to a temporary folder whose ``gnssacc/__pycache__`` cannot be created (a
read-only install: the folder is made read-only, or, as root, who may write anywhere, a file
takes the cache folder's name), and run in fresh processes with an empty user cache folder. A
probe process starts the background compilation for the methods in ``$METHODS`` (the default
methods when unset) and prints the cache folder, the EKF propagation kernel's cache hits and
misses in the probe itself, the number of compiling child processes and the groups loaded.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import threading
from pathlib import Path

import pytest

import gnssacc
from gnssacc.core.jit import kernel_cache_folder
from gnssacc.estimators import kernels

PROBE = """
import os, subprocess, sys
from gnssacc.estimators import kernels as jit
from gnssacc.estimators import mechanization
if os.environ.get("CHILDREN_FAIL"):   # the compiling processes die at once: this process compiles
    jit._spawn = lambda groups: subprocess.Popen([sys.executable, "-c", "raise SystemExit(3)"])
methods = os.environ["METHODS"].split(",") if os.environ.get("METHODS") else None
b = jit.start_background(methods)
b.wait_all()
s = mechanization.propagate.stats
print(os.environ.get("NUMBA_CACHE_DIR"))
print(len(s.cache_hits), len(s.cache_misses))
print(len(b._children), ",".join(b.groups))
print(len(mechanization.update_state.stats.cache_misses))
"""


def _read_only_copy(tmp_path: Path) -> Path:
    root = tmp_path / "site"
    shutil.copytree(
        Path(gnssacc.__file__).parent,
        root / "gnssacc",
        ignore=shutil.ignore_patterns("__pycache__", "*.pyc"),
    )
    if os.geteuid() == 0:
        for pkg in [root / "gnssacc", *(p for p in (root / "gnssacc").iterdir() if p.is_dir())]:
            (pkg / "__pycache__").write_text("not a folder\n")
    else:
        for p in sorted((root / "gnssacc").rglob("*"), reverse=True) + [root / "gnssacc"]:
            p.chmod(p.stat().st_mode & ~0o222)
    return root


def _probe(root: Path, cache_home: Path, **extra) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env.update(PYTHONPATH=str(root), XDG_CACHE_HOME=str(cache_home), **extra)
    return subprocess.run(
        [sys.executable, "-c", PROBE], env=env, capture_output=True, text=True, check=True, cwd=root
    )


@pytest.mark.slow
def test_read_only_install_caches_in_the_user_folder_and_says_so_once(tmp_path):
    root = _read_only_copy(tmp_path)
    cache_home = tmp_path / "cache"
    first = _probe(root, cache_home)
    folder = cache_home / "gnssacc" / "numba"
    assert first.stdout.splitlines()[0] == str(folder)
    notice = [line for line in first.stderr.splitlines() if line.startswith("gnssacc: ")]
    assert len(notice) == 1 and "compiling" in notice[0] and str(folder) in notice[0]
    hits, misses = first.stdout.splitlines()[1].split()
    assert hits != "0" and misses == "0"  # compiled by the child processes, loaded from the cache
    assert first.stdout.splitlines()[3] == "0"  # the EKF's update too, not compiled here again
    assert list(folder.rglob("mechanization.propagate-*.nbi"))  # ... written to the user folder
    assert list(folder.rglob("window_marginals.*.nbi"))  # the smoother's too
    assert not list(folder.rglob("mechanization.kernel_force_integrals-*.nbi"))  # only ekf-accw's
    assert not list(folder.rglob("window_marginals._band_*.nbi"))  # only smoother-accw's
    assert not (root / "gnssacc" / "__pycache__").is_dir()

    second = _probe(root, cache_home)
    assert "gnssacc: " not in second.stderr  # no notice once cached
    hits, misses = second.stdout.splitlines()[1].split()
    assert hits != "0" and misses == "0"  # loaded from the user folder


def test_numba_cache_dir_set_by_the_user_is_kept(tmp_path):
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "mine")}
    out = subprocess.run(
        [sys.executable, "-c", "import os, gnssacc; print(os.environ['NUMBA_CACHE_DIR'])"],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    assert out.stdout.strip() == str(tmp_path / "mine")


@pytest.mark.slow
def test_failed_compiling_processes_fall_back_to_compiling_in_process(tmp_path):
    root = _read_only_copy(tmp_path)
    cache_home = tmp_path / "cache"
    first = _probe(root, cache_home, CHILDREN_FAIL="1")
    hits, misses = first.stdout.splitlines()[1].split()
    assert misses != "0"  # compiled here
    folder = cache_home / "gnssacc" / "numba"
    assert list(folder.rglob("window_marginals.*.nbi"))
    assert not list(folder.rglob("*.stamp"))  # numba's own index files say what is compiled
    second = _probe(root, cache_home)
    assert "gnssacc: " not in second.stderr


def _notice(proc: subprocess.CompletedProcess) -> list[str]:
    return [
        line
        for line in proc.stderr.splitlines()
        if line.startswith("gnssacc: ") and "compiling" in line
    ]


def _counts(proc: subprocess.CompletedProcess) -> tuple[int, int, int]:
    """Cache hits and misses of the propagation kernel in the probe, compiling children started."""
    hits, misses = proc.stdout.splitlines()[1].split()
    return int(hits), int(misses), int(proc.stdout.splitlines()[2].split()[0])


def _writable(path: Path) -> Path:
    path.chmod(path.stat().st_mode | 0o200)
    return path


def _ekf_compiled(tmp: Path) -> tuple[Path, Path]:
    """A read-only copy and its empty user cache after a first run of ``ekf,ekf-acc``, which
    says at once that it compiles, compiles the EKF's groups (propagation, update, and its
    compiled event loop) in child processes and nothing else."""
    root, cache_home = _read_only_copy(tmp), tmp / "cache"
    first = _probe(root, cache_home, METHODS="ekf,ekf-acc")
    assert len(_notice(first)) == 1 and _counts(first)[2] > 0
    assert first.stdout.splitlines()[2].split()[1] == "propagation,update,loop"
    folder = cache_home / "gnssacc" / "numba"
    assert list(folder.rglob("mechanization.propagate-*.nbi"))
    assert not list(folder.rglob("window_marginals.*.nbi")) and not list(
        folder.rglob("*kernel_force_integrals*")
    )
    return root, cache_home


def _moved(compiled, tmp_path: Path) -> tuple[Path, Path]:
    """A copy of ``compiled`` (a copy and its cache) in ``tmp_path``, as if the first run had
    compiled there: numba names a cache folder by its source folder's path, which changed."""
    root, cache_home = compiled
    new_root, new_cache = tmp_path / "site", tmp_path / "cache"
    shutil.copytree(root, new_root)
    shutil.copytree(cache_home, new_cache)
    for rel in _KERNEL_FOLDERS:  # where numba puts the kernels of each folder of each copy
        with pytest.MonkeyPatch.context() as mp:
            mp.setenv("NUMBA_CACHE_DIR", str(cache_home / "gnssacc" / "numba"))
            src = kernel_cache_folder(root / "gnssacc" / "estimators" / rel)
            mp.setenv("NUMBA_CACHE_DIR", str(new_cache / "gnssacc" / "numba"))
            dst = kernel_cache_folder(new_root / "gnssacc" / "estimators" / rel)
        if (new_cache / src.relative_to(cache_home)).exists():
            (new_cache / src.relative_to(cache_home)).rename(dst)
    return new_root, new_cache


#: One kernel module of each folder the kernels live in (numba caches a folder's kernels
#: together): the estimators' and the aids'.
_KERNEL_FOLDERS = sorted(
    {str(Path(f).parent / "x.py") for spec in kernels.GROUPS.values() for f, _ in spec}
)


def _check_compiled_is_decided_by_the_source_content(ekf_compiled, tmp_path: Path) -> None:
    """numba (0.68) keeps a kernel whose source file only has a new modification time (a reinstall
    or ``touch`` of the same code) and compiles again one whose content changed: a touched source
    must start no compilation and print no notice, an edited one must do both. (After a first
    run that compiled the EKF's kernels: :func:`ekf_compiled`.)"""
    root, cache_home = _moved(ekf_compiled, tmp_path)
    source = root / "gnssacc" / "estimators" / "mechanization.py"
    st = source.stat()
    os.utime(source, ns=(st.st_atime_ns, st.st_mtime_ns + 10**10))  # 10 s newer, same content
    touched = _probe(root, cache_home, METHODS="ekf")
    hits, misses, children = _counts(touched)
    assert not _notice(touched) and children == 0  # no notice, no compiling process
    assert hits > 0 and misses == 0  # and numba loads it: nothing compiled

    _writable(source).write_text(source.read_text() + "\n# an edit: the content changed\n")
    edited = _probe(root, cache_home, METHODS="ekf")
    hits, misses, children = _counts(edited)
    assert len(_notice(edited)) == 1 and children > 0  # said at once, compiled by the children
    assert hits > 0 and misses == 0  # then loaded here
    again = _probe(root, cache_home, METHODS="ekf")
    assert not _notice(again) and _counts(again)[2] == 0


def _check_a_run_compiles_only_the_kernels_its_methods_need(ekf_compiled, tmp_path: Path) -> None:
    """A first run of ``ekf,ekf-acc`` compiles only the EKF's kernels (:func:`ekf_compiled`); one
    that adds ``ekf-accw`` and ``smoother-accw`` then compiles only what those add."""
    root, cache_home = _moved(ekf_compiled, tmp_path)
    folder = cache_home / "gnssacc" / "numba"
    more = _probe(root, cache_home, METHODS="ekf,ekf-accw,smoother-accw")
    hits, misses, children = _counts(more)
    assert len(_notice(more)) == 1 and children == 1  # one process for what is missing
    assert hits > 0 and misses == 0  # the EKF's are not compiled again
    assert list(folder.rglob("window_marginals._band_covariances-*.nbi"))
    assert list(folder.rglob("mechanization.kernel_force_integrals-*.nbi"))
    assert not _notice(_probe(root, cache_home, METHODS="ekf-accw,smoother-accw"))


@pytest.mark.slow
def test_a_first_run_compiles_what_its_methods_need_and_an_edit_compiles_again(tmp_path):
    """After a first run that compiled the EKF's kernels (:func:`_ekf_compiled`, shared by the two
    checks: one compilation; a fixture shared by two tests would need them on one worker, which
    ``--dist loadgroup`` no longer ensures on pytest 9.2, pytest-xdist issue 1386):
    :func:`_check_compiled_is_decided_by_the_source_content` and
    :func:`_check_a_run_compiles_only_the_kernels_its_methods_need`, each on its own copy."""
    (tmp_path / "first").mkdir()
    compiled = _ekf_compiled(tmp_path / "first")
    for n, check in enumerate(
        (
            _check_compiled_is_decided_by_the_source_content,
            _check_a_run_compiles_only_the_kernels_its_methods_need,
        )
    ):
        (tmp_path / f"copy{n}").mkdir()
        check(compiled, tmp_path / f"copy{n}")


RUN_TYPES = """
import os
os.environ["GNSSACC_JOBS"] = "1"  # the methods here, where their kernels' signatures are seen
from gnssacc import pipeline
from gnssacc.core.config import load_config
from gnssacc.estimators import ekf, event_loop, kalman, kernels, mechanization, small_linalg
from gnssacc.estimators import window_marginals
from gnssacc.estimators.aids import gnss_position, gnss_velocity, nhc, odometry, vehicle, zupt
from gnssacc.sources.sim import simulate

MODULES = (mechanization, kalman, window_marginals, small_linalg, gnss_position, vehicle, nhc,
           event_loop, gnss_velocity, zupt, odometry)
ekf.COMPILED_LOOP = True  # the passes run their fixes, velocities, constraints, stops compiled

def signatures():
    return {(m.__name__, name): set(d.signatures) for m in MODULES
            for name, d in vars(m).items() if hasattr(d, "signatures")}

kernels.compile_groups()
warmed = signatures()
run = simulate("car", 40.0, seed=3)
pipeline.compare(run, load_config(None, overrides={"gnss": {"gm_sigma_m": 0.5, "gm_tau_s": 60.0}}), ["ekf", "ekf-acc", "ekf-accw", "smoother", "smoother-acc",
                 "smoother-accw", "ekf-gm", "smoother-gm"], tune="none")
# Wheel odometry (the scale-factor state after the GNSS error's, in the EKF and on the nodes)
# and 5 Hz fixes (folded into the nodes before them).
run = simulate("car", 30.0, seed=3, odom_hz=10.0, gnss_rate_hz=5.0)
_, sols, _ = pipeline.compare(run, load_config(None, overrides={"gnss": {"gm_sigma_m": 0.5, "gm_tau_s": 60.0}}),
                              ["ekf", "smoother", "smoother-accw", "ekf-gm", "smoother-gm"], tune="none")
assert sols["smoother-gm"].stats["n_odo_factors"] > 0 and sols["smoother"].stats["n_gps_folded"] > 0
# Doppler velocities, stops (the stationary updates) and odometry, in both loops.
run = simulate("ugv", 90.0, seed=3, velocity=True, odom_hz=10.0)
_, sols, _ = pipeline.compare(run, load_config(), ["ekf"], tune="none")
assert sols["ekf"].stats["n_vel_updates"] > 0 and sols["ekf"].stats["n_zupt_updates"] > 0
assert sols["ekf"].stats["n_odo_updates"] > 0
ekf.COMPILED_LOOP = False
pipeline.compare(run, load_config(), ["ekf"], tune="none")
new = {k: v - warmed.get(k, set()) for k, v in signatures().items() if v - warmed.get(k, set())}
print(sorted(k[1] for k in new))
"""


@pytest.mark.slow
def test_the_group_warm_ups_compile_every_kernel_a_run_calls():
    """The warm-ups (also the install's) call each kernel with the types a real run gives it (a
    kernel compiled with other types, or not at all, is compiled again inside an estimator); a
    run of every method then compiles nothing new, nor does one with wheel odometry (its scale
    state) and folded fast fixes."""
    out = subprocess.run(
        [sys.executable, "-c", RUN_TYPES], capture_output=True, text=True, check=True
    )
    assert out.stdout.strip() == "[]"


#: A process as pip's isolated build environment is: numba and numpy, no scipy
#: (``[build-system] requires``), compiling (or loading) every kernel group as ``setup.py`` does.
NO_SCIPY_BUILD = """
import sys
class NoScipy:
    def find_spec(self, name, path=None, target=None):
        if name == "scipy" or name.startswith("scipy."):
            raise ModuleNotFoundError("No module named 'scipy'")
sys.meta_path.insert(0, NoScipy())
from gnssacc.estimators.kernels import GROUPS, compile_groups
compile_groups(list(GROUPS))
"""


def test_the_kernels_compile_where_the_package_is_built_without_scipy():
    """The build compiles the kernels with the build requirements only (numba, numpy): a kernel
    module that imported scipy made every group but the propagation fail there, silently, and
    the first run after ``pip install .`` compiled them for 24 s."""
    out = subprocess.run([sys.executable, "-c", NO_SCIPY_BUILD], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr[-2000:]


@pytest.mark.slow
def test_the_install_compiles_the_kernels_into_the_package_and_a_first_run_loads_them(tmp_path):
    """``setup.py``'s build step: the package in the build folder carries every kernel group in
    numba's cache; installed elsewhere (copied, new modification times, as pip installs a wheel)
    a first run finds them, prints no notice and compiles nothing, in-process or in children."""
    repo = Path(__file__).resolve().parents[1]
    if not (repo / "setup.py").is_file():
        import pytest

        pytest.skip("not a source checkout (no setup.py)")
    build = tmp_path / "build"
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    subprocess.run(
        [sys.executable, "setup.py", "-q", "build_py", "--build-lib", str(build)],
        cwd=repo,
        env=env,
        check=True,
        capture_output=True,
    )
    kernels = sorted(
        p.name for p in (build / "gnssacc" / "estimators" / "__pycache__").glob("*.nbi")
    )
    assert any(n.startswith("mechanization.propagate-") for n in kernels)
    assert any(n.startswith("window_marginals._band_covariances-") for n in kernels)
    site = tmp_path / "site"
    shutil.copytree(build, site)  # elsewhere, every file with a new modification time
    probe = _probe(site, tmp_path / "cache", METHODS="ekf,ekf-accw,smoother,smoother-accw")
    hits, misses, children = _counts(probe)
    assert not _notice(probe) and children == 0 and misses == 0 and hits > 0
    assert probe.stdout.splitlines()[2].split()[1] == "propagation,update,loop,window,chain,band"


class _Child:
    """A compiling child process as :class:`kernels.BackgroundWarmUp` sees it (``poll``, ``wait``):
    alive until ``ends`` is set, then its exit code."""

    def __init__(self, code: int = 0):
        self.code, self.ends = code, threading.Event()

    def poll(self):
        return self.code if self.ends.is_set() else None

    def wait(self):
        self.ends.wait()
        return self.code


def _waiting_for_the_ekf(monkeypatch, child: _Child, cached: set) -> tuple[threading.Thread, list]:
    """A warm-up whose propagation is cached and whose other groups one ``child`` compiles,
    waiting for the EKF's groups in a thread; the groups compiled in this process are listed."""
    here: list = []
    monkeypatch.setattr(kernels, "group_cached", lambda g: g in cached)
    monkeypatch.setattr(kernels, "compile_groups", lambda groups: here.extend(groups))
    warm = kernels.BackgroundWarmUp(groups=("loop", "chain"), processes=False)
    warm._children = {("update", "loop", "chain"): child}
    waiting = threading.Thread(target=warm._wait_children, args=(kernels.EKF_GROUPS,), daemon=True)
    waiting.start()
    return waiting, here


def test_the_ekf_waits_for_the_child_compiling_its_update_not_for_all_it_compiles(monkeypatch):
    """The EKF's update is compiled by the child that then compiles the other groups: the warm-up
    waits until the child has cached it (compiling it here as well doubled a first run's
    compile work), and not until the child's later groups are done."""
    child, cached = _Child(), {"propagation"}
    waiting, here = _waiting_for_the_ekf(monkeypatch, child, cached)
    try:
        waiting.join(0.3)
        assert waiting.is_alive() and here == []  # the update is being compiled by the child
        cached.add("update")
        waiting.join(2.0)
        assert not waiting.is_alive() and here == []  # cached by the child, still running
    finally:
        child.ends.set()


def test_a_child_that_fails_leaves_the_ekf_update_to_this_process(monkeypatch):
    child = _Child(code=3)
    waiting, here = _waiting_for_the_ekf(monkeypatch, child, {"propagation"})
    child.ends.set()
    waiting.join(2.0)
    assert not waiting.is_alive() and here == ["update"]  # only what the EKF waits for


def test_an_edit_of_any_kernel_source_drops_every_cached_kernel(tmp_path, monkeypatch):
    """numba validates a cached kernel by its own module's source alone, yet stores with it the
    code of the kernels it calls from other modules (the event loop holds the propagation): an
    edit of ``mechanization.py`` left ``event_loop.run_stretch``'s old copy loaded, and the
    compiled loop then differed from the Python loop (found on this repository). Each cache folder
    is stamped with the digest of every kernel source; kernels beside another stamp, or none, are
    deleted (compiled again on first use), a touched source keeps them."""
    from gnssacc.core import jit

    pkg = tmp_path / "gnssacc"
    est, aids, core = pkg / "estimators", pkg / "estimators" / "aids", pkg / "core"
    for folder in (aids, core):
        folder.mkdir(parents=True)
    for source in (est / "event_loop.py", est / "mechanization.py", aids / "zupt.py"):
        source.write_text("def kernel():\n    return 1\n")
    (core / "earth.py").write_text("A = 6378137.0\n")
    monkeypatch.setattr(jit, "KERNEL_DIR", est)
    monkeypatch.setattr(jit, "PACKAGE_DIR", pkg)
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    cached = [
        est / "__pycache__" / "event_loop.run_stretch-1.py311.nbi",
        est / "__pycache__" / "event_loop.run_stretch-1.py311.1.nbc",
        aids / "__pycache__" / "zupt.zero_rate_model-1.py311.nbi",
    ]

    def compiled() -> None:
        for path in cached:
            path.parent.mkdir(exist_ok=True)
            path.write_bytes(b"kernel")

    compiled()
    assert jit.drop_stale_kernels() == 3  # no stamp: compiled from sources nobody knows
    compiled()
    assert jit.drop_stale_kernels() == 0 and all(p.exists() for p in cached)
    source = est / "mechanization.py"
    st = source.stat()
    os.utime(source, ns=(st.st_atime_ns, st.st_mtime_ns + 10**10))  # touched, the same content
    assert jit.drop_stale_kernels() == 0 and all(p.exists() for p in cached)
    source.write_text("def kernel():\n    return 2\n")  # a callee's module, not the kernels'
    assert jit.drop_stale_kernels() == 3 and not any(p.exists() for p in cached)
    compiled()
    (core / "earth.py").write_text("A = 6378137.5\n")  # a constant the kernels take
    assert jit.drop_stale_kernels() == 3
    stamps = [p.read_text().strip() for p in pkg.rglob(jit.STAMP)]
    assert len(stamps) == 2 and stamps[0] == stamps[1] == jit.kernels_digest()
