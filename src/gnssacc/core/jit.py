"""Where numba caches gnssacc's compiled kernels.

The first run after an install compiles the kernels (several seconds); later runs load them
from numba's on-disk cache in a fraction of a second. numba caches next to the sources
(``gnssacc/estimators/__pycache__``) when it can write there. A system or container install
usually cannot, so :func:`configure_cache` (called by ``gnssacc/__init__`` before numba is
imported) then points ``NUMBA_CACHE_DIR`` at a user cache folder; a ``NUMBA_CACHE_DIR`` set by the
user is always kept. :func:`cache_folder` says where the kernels go. Which kernels there are, and
compiling them in the background, is :mod:`gnssacc.estimators.kernels`' business.
"""
from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

ENV = "NUMBA_CACHE_DIR"
PACKAGE_DIR = Path(__file__).resolve().parent.parent
#: The folder of the modules holding numba kernels: numba caches them in its ``__pycache__``.
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
    """Set ``NUMBA_CACHE_DIR`` to :func:`user_cache_dir` when the package folder is read-only.

    Must run before numba is imported (numba reads the variable once); does nothing when the
    variable is already set or numba already imported (numba then falls back to its own
    user-wide cache folder).
    """
    if os.environ.get(ENV) or "numba" in sys.modules or _writable(KERNEL_DIR / "__pycache__"):
        return
    os.environ[ENV] = str(user_cache_dir())


def cache_folder() -> Path:
    """The folder numba caches gnssacc's kernels under: ``NUMBA_CACHE_DIR`` (numba adds a
    sub-folder per source tree) or the package's ``__pycache__``."""
    return Path(os.environ[ENV]) if os.environ.get(ENV) else KERNEL_DIR / "__pycache__"


