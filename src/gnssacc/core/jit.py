"""Where numba caches gnssacc's compiled kernels, and whether it holds them.

The first run after an install compiles the kernels (several seconds) unless the install put them
there already (``setup.py`` compiles them into the wheel); later runs load them from numba's
on-disk cache in a fraction of a second. numba caches next to the sources
(``gnssacc/estimators/__pycache__``, and ``estimators/aids/``'s for the aids' compiled models)
when it can write there. A system or container install
usually cannot, so :func:`configure_cache` (called by ``gnssacc/__init__`` before numba is
imported) then points ``NUMBA_CACHE_DIR`` at a user cache folder; a ``NUMBA_CACHE_DIR`` set by the
user is always kept. :func:`cache_folder` says where the kernels go, :func:`kernel_cached` whether
numba would load a kernel from there or compile it, decided by numba's own rules and without
importing numba (so that a first run can say at once that it compiles). Which kernels there are,
and compiling them in the background, is :mod:`gnssacc.estimators.kernels`' business.
"""

from __future__ import annotations

import hashlib
import os
import pickle
import pickletools
import sys
import tempfile
from functools import lru_cache
from pathlib import Path

ENV = "NUMBA_CACHE_DIR"
PACKAGE_DIR = Path(__file__).resolve().parent.parent
#: The folder of the modules holding numba kernels (and its ``aids`` folder): numba caches them in
#: their ``__pycache__``.
KERNEL_DIR = PACKAGE_DIR / "estimators"


def _writable(folder: Path) -> bool:
    """Whether files can be created in ``folder`` (made if missing), as numba itself checks."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=folder):
            return True
    except OSError:
        return False


def user_cache_dir() -> Path:
    """``$XDG_CACHE_HOME/gnssacc/numba`` (default ``~/.cache``), or a per-user temporary folder
    when the home folder is not writable either."""
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    folder = Path(base) / "gnssacc" / "numba"
    if _writable(folder):
        return folder
    uid = os.getuid() if hasattr(os, "getuid") else "user"
    return Path(tempfile.gettempdir()) / f"gnssacc-numba-{uid}"


def configure_cache() -> None:
    """Set ``NUMBA_CACHE_DIR`` to :func:`user_cache_dir` when the package folder is read-only, then
    drop kernels compiled from other sources (:func:`drop_stale_kernels`).

    Must run before numba is imported (numba reads the variable once); the variable is left alone
    when it is already set or numba already imported (numba then falls back to its own user-wide
    cache folder).
    """
    if not (os.environ.get(ENV) or "numba" in sys.modules or _writable(KERNEL_DIR / "__pycache__")):
        os.environ[ENV] = str(user_cache_dir())
    if "numba" not in sys.modules:
        drop_stale_kernels()


#: The file in each kernel cache folder naming the sources its kernels were compiled from.
STAMP = "gnssacc-kernels.sha1"


def kernel_sources() -> list[Path]:
    """The sources numba compiles into the kernels: the estimators' modules (with the aids') and
    the earth model whose constants they take."""
    found = [*KERNEL_DIR.glob("*.py"), *(KERNEL_DIR / "aids").glob("*.py")]
    return sorted(found) + [PACKAGE_DIR / "core" / "earth.py"]


def kernels_digest() -> str:
    """SHA-1 of :func:`kernel_sources`' names and contents."""
    h = hashlib.sha1()
    for path in kernel_sources():
        h.update(path.name.encode())
        h.update(path.read_bytes())
    return h.hexdigest()


def drop_stale_kernels() -> int:
    """Delete the cached kernels of sources other than these; the files deleted.

    numba stores a kernel with the code of the kernels it calls, but validates the cache by the
    kernel's own module only: after an edit of ``mechanization.py``, the event loop of
    ``event_loop.py`` would load its old copy of the propagation (a source checkout, an editable
    install after ``git pull``). So each cache folder holds :data:`STAMP`, the
    :func:`kernels_digest` its kernels were compiled from; when it differs (or is missing beside
    cached kernels), the folder's kernels are deleted and compiled again on first use. ~2 ms.
    """
    try:
        digest = kernels_digest()
    except OSError:
        return 0
    dropped = 0
    for folder in {
        kernel_cache_folder(KERNEL_DIR / "kernels.py"),
        kernel_cache_folder(KERNEL_DIR / "aids" / "base.py"),
    }:
        stamp = folder / STAMP
        try:
            if stamp.read_text().strip() == digest:
                continue
        except OSError:
            pass
        for old in [*folder.glob("*.nbi"), *folder.glob("*.nbc")]:
            try:
                old.unlink()
                dropped += 1
            except OSError:
                pass
        try:
            folder.mkdir(parents=True, exist_ok=True)
            stamp.write_text(digest + "\n")
        except OSError:
            pass
    return dropped


def cache_folder() -> Path:
    """The folder numba caches gnssacc's kernels under: ``NUMBA_CACHE_DIR`` (numba adds a
    sub-folder per source tree) or the package's ``__pycache__``."""
    return Path(os.environ[ENV]) if os.environ.get(ENV) else KERNEL_DIR / "__pycache__"


def kernel_cache_folder(source: Path) -> Path:
    """The folder numba caches the kernels of the module file ``source`` in, chosen as numba's
    cache locators choose it: ``NUMBA_CACHE_DIR/<folder>_<SHA-1 of the folder's path>`` when the
    variable is set, else the source folder's ``__pycache__``."""
    folder = os.path.dirname(os.path.abspath(source))
    if os.environ.get(ENV):
        tag = hashlib.sha1(folder.encode()).hexdigest()
        return Path(os.environ[ENV]) / f"{os.path.basename(folder)}_{tag}"
    return Path(folder) / "__pycache__"


@lru_cache(maxsize=None)
def numba_version() -> str | None:
    """``numba.__version__``, read from numba's ``_version.py`` without importing numba (which
    takes about a second); ``None`` when numba is not installed."""
    if "numba" in sys.modules:
        return sys.modules["numba"].__version__
    import importlib.util
    import json

    spec = importlib.util.find_spec("numba")
    if spec is None or not spec.submodule_search_locations:
        return None
    path = Path(list(spec.submodule_search_locations)[0]) / "_version.py"
    try:
        text = path.read_text()
        return json.loads(text.split("version_json = '''")[1].split("'''")[0])["version"]
    except (OSError, IndexError, KeyError, ValueError):
        return None


def _source_stamp(source: Path, old: bool):
    """numba's freshness stamp of a source file: the SHA-256 of its bytes (numba >= 0.68), or
    its modification time and size (``old``: earlier numba)."""
    if old:
        st = os.stat(source)
        return st.st_mtime, st.st_size
    return hashlib.sha256(Path(source).read_bytes()).digest()


def _index_stamp_and_strings(data: bytes) -> tuple[object, set]:
    """The source stamp an index holds (the first item of its pickled ``(stamp, overloads)``) and
    the strings in its overloads (the CPU names among them), read without unpickling the
    overloads (that would import numba for their types)."""
    values, strings = [], set()
    for op, arg, _ in pickletools.genops(data):
        if (
            op.name
            in (
                "SHORT_BINBYTES",
                "BINBYTES",
                "BINBYTES8",
                "BINFLOAT",
                "BININT",
                "BININT1",
                "BININT2",
                "LONG1",
            )
            and len(values) < 2
        ):
            values.append(arg)
        elif isinstance(arg, str) and op.name.endswith("UNICODE"):
            strings.add(arg)
    if values and isinstance(values[0], bytes):
        return values[0], strings
    return tuple(values), strings


def _host_cpu_name() -> str:
    """The CPU name numba compiles for: ``NUMBA_CPU_NAME``, else LLVM's name of this CPU."""
    if os.environ.get("NUMBA_CPU_NAME"):
        return os.environ["NUMBA_CPU_NAME"]
    import llvmlite.binding as ll  # numba's own dependency; a tenth of a second

    return ll.get_host_cpu_name()


def kernel_cached(source: Path, qualname: str) -> bool:
    """Whether numba would load the kernel ``qualname`` of the module file ``source`` from its
    cache instead of compiling it, by numba's rules (``numba/core/caching.py``): an index file
    ``<module>.<qualname>-<line>.py<XY>.nbi`` in :func:`kernel_cache_folder`, written by this
    numba version, whose source stamp is the file's (its content from numba 0.68 on: a reinstall
    or ``touch`` of an unchanged file keeps the kernels; before, its modification time), and an
    entry compiled for this CPU. The line is not looked at: an index of an older edit of the file
    has an older stamp."""
    version = numba_version()
    if version is None:
        return False
    tag = f"py{sys.version_info[0]}{sys.version_info[1]}{getattr(sys, 'abiflags', '')}"
    name = Path(source).name.removesuffix(".py")
    for index in kernel_cache_folder(source).glob(f"{name}.{qualname}-*.{tag}.nbi"):
        try:
            with open(index, "rb") as f:
                if pickle.load(f) != version:
                    continue
                stamp, strings = _index_stamp_and_strings(f.read())
            if (
                stamp == _source_stamp(source, old=not isinstance(stamp, bytes))
                and _host_cpu_name() in strings
            ):
                return True
        except (OSError, pickle.UnpicklingError, ValueError, EOFError):
            continue
    return False
