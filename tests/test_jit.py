"""Where the numba kernels are cached, the first-run notice, and who compiles them.

The package is copied to a temporary folder whose ``gnssacc/__pycache__`` cannot be created (a
read-only install: the folder is made read-only, or, as root, who may write anywhere, a file
takes the cache folder's name), and run in fresh processes with an empty user cache folder.
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import gnssacc

PROBE = """
import os, subprocess, sys
from gnssacc.estimators import kernels as jit
from gnssacc.estimators import mechanization
if os.environ.get("CHILDREN_FAIL"):   # the compiling processes die at once: this process compiles
    jit._spawn = lambda part: subprocess.Popen([sys.executable, "-c", "raise SystemExit(3)"])
b = jit.start_background()
b.wait_all()
s = mechanization.propagate.stats
print(os.environ.get("NUMBA_CACHE_DIR"))
print(len(s.cache_hits), len(s.cache_misses))
"""


def _read_only_copy(tmp_path: Path) -> Path:
    root = tmp_path / "site"
    shutil.copytree(Path(gnssacc.__file__).parent, root / "gnssacc",
                    ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
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
    return subprocess.run([sys.executable, "-c", PROBE], env=env, capture_output=True, text=True, check=True,
                          cwd=root)


def test_read_only_install_caches_in_the_user_folder_and_says_so_once(tmp_path):
    root = _read_only_copy(tmp_path)
    cache_home = tmp_path / "cache"
    first = _probe(root, cache_home)
    folder = cache_home / "gnssacc" / "numba"
    assert first.stdout.splitlines()[0] == str(folder)
    notice = [line for line in first.stderr.splitlines() if line.startswith("gnssacc: ")]
    assert len(notice) == 1 and "compiling" in notice[0] and str(folder) in notice[0]
    hits, misses = first.stdout.splitlines()[1].split()
    assert hits != "0" and misses == "0"      # compiled by the child processes, loaded from the cache
    assert list(folder.rglob("mechanization.propagate-*.nbi"))      # ... written to the user folder
    assert list(folder.rglob("window_marginals.*.nbi"))             # the smoother's too
    assert list(folder.rglob("mechanization.kernel_force_integrals-*.nbi"))
    assert not (root / "gnssacc" / "__pycache__").is_dir()

    second = _probe(root, cache_home)
    assert "gnssacc: " not in second.stderr                           # no notice once cached
    hits, misses = second.stdout.splitlines()[1].split()
    assert hits != "0" and misses == "0"                              # loaded from the user folder


def test_numba_cache_dir_set_by_the_user_is_kept(tmp_path):
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "mine")}
    out = subprocess.run([sys.executable, "-c", "import os, gnssacc; print(os.environ['NUMBA_CACHE_DIR'])"],
                         env=env, capture_output=True, text=True, check=True)
    assert out.stdout.strip() == str(tmp_path / "mine")


def test_failed_compiling_processes_fall_back_to_compiling_in_process(tmp_path):
    root = _read_only_copy(tmp_path)
    cache_home = tmp_path / "cache"
    first = _probe(root, cache_home, CHILDREN_FAIL="1")
    hits, misses = first.stdout.splitlines()[1].split()
    assert misses != "0"                      # compiled here
    folder = cache_home / "gnssacc" / "numba"
    assert list(folder.rglob("window_marginals.*.nbi")) and list(folder.rglob("gnssacc-kernels-*.stamp"))
    second = _probe(root, cache_home)
    assert "gnssacc: " not in second.stderr


def test_a_touched_kernel_source_is_compiled_again_with_the_notice(tmp_path):
    """numba recompiles a kernel whose source file has a new modification time (a reinstall of the
    same code): the run must say so and compile in the background, not silently in the estimators."""
    root = _read_only_copy(tmp_path)
    cache_home = tmp_path / "cache"
    _probe(root, cache_home)
    source = root / "gnssacc" / "estimators" / "mechanization.py"
    st = source.stat()
    os.utime(source, ns=(st.st_atime_ns, st.st_mtime_ns + 10**10))   # 10 s newer, same content
    again = _probe(root, cache_home)
    assert any(line.startswith("gnssacc: ") and "compiling" in line for line in again.stderr.splitlines())
    hits, misses = again.stdout.splitlines()[1].split()
    assert hits != "0" and misses == "0"      # compiled by the child processes again, then loaded
    third = _probe(root, cache_home)
    assert "gnssacc: " not in third.stderr
