"""The ``--out`` folder holds exactly one complete result, or is left as it was.

On-disk protocol, for an output folder ``<parent>/<name>``:

* **Lock.** ``<parent>/.<name>.lock`` is locked (``fcntl.flock``, exclusive, non-blocking)
  before anything is computed and held to the end of the run; a second run into the same folder
  is refused at once (:class:`gnssacc.core.errors.InputError`, exit 2). The holder deletes the lock
  file when it is done (a process that dies loses its lock anyway).
* **What may be replaced.** A folder that does not exist, an empty folder, or a previous
  gnssacc result (it holds :data:`MARKER`, or a ``metrics.json`` written by gnssacc before the
  marker existed) is replaced as a whole. Anything else (a file, a non-empty folder of other
  things) is refused unless ``overwrite`` is set, which replaces it, and everything in it.
* **Write aside.** Every file is written into ``<parent>/.gnssacc-partial-<name>-<random>/``;
  :data:`MARKER` is written last.
* **Swap.** With SIGINT and SIGTERM held back (:func:`signals_held`), the old folder is renamed
  to ``<parent>/.gnssacc-trash-<name>-<random>`` and the new one to ``<name>``; if the second
  rename fails the first is undone. Then the trash is deleted.
* **Clean-up.** Each run deletes the partial and trash folders in its parent whose owner's lock
  is not held (left by a process killed with SIGKILL, or by a power cut); a trash folder whose
  result folder is missing (killed between the two renames) is renamed back instead.

SIGTERM unwinds like Ctrl-C (:func:`gnssacc.core.interrupts.signals_raise`); :meth:`ResultDir.kept`
says what an interruption left.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import json
import os
import secrets
import shutil
import signal
import tempfile
from datetime import datetime, timezone
from pathlib import Path
from typing import Callable

from ..core.errors import InputError
from ..core.version import __version__

#: Marker file of a complete result (JSON: gnssacc version, time written, files).
MARKER = ".gnssacc-result"
PARTIAL_PREFIX = ".gnssacc-partial-"
TRASH_PREFIX = ".gnssacc-trash-"
#: Signals held back while the old result is swapped for the new one.
SWAP_SIGNALS = {signal.SIGINT, signal.SIGTERM}


def is_result(path: Path) -> bool:
    """Whether ``path`` is a folder gnssacc wrote: it holds :data:`MARKER`, or a ``metrics.json``
    with gnssacc's keys (results written before the marker existed)."""
    path = Path(path)
    if (path / MARKER).is_file():
        return True
    try:
        doc = json.loads((path / "metrics.json").read_text())
    except (OSError, ValueError):
        return False
    return isinstance(doc, dict) and {"source", "methods"} <= set(doc)


class FolderLock:
    """The exclusive lock ``<parent>/.<name>.lock`` of output folder ``<parent>/<name>``."""

    def __init__(self, folder: Path):
        self.folder = Path(folder)
        self.path = self.folder.parent / f".{self.folder.name}.lock"
        self.fd: int | None = None

    def take(self, where: str, busy: str) -> None:
        """Create the folder's parent and take the lock, or raise :class:`InputError`
        (``where``: ``busy`` when another process holds it; also when the folder is the root)."""
        if not self.folder.name:
            raise InputError(where, f"{self.folder} cannot be an output folder (it is the root)")
        self.folder.parent.mkdir(parents=True, exist_ok=True)
        if not self.acquire():
            raise InputError(where, busy)

    def acquire(self) -> bool:
        """Take the lock without waiting; ``False`` when another process holds it."""
        for _ in range(5):
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError as exc:
                os.close(fd)
                if exc.errno in (errno.EWOULDBLOCK, errno.EACCES):
                    return False
                raise
            try:  # the holder before us may have deleted the file between our open and flock
                same = os.stat(self.path).st_ino == os.fstat(fd).st_ino
            except FileNotFoundError:
                same = False
            if same:
                self.fd = fd
                return True
            os.close(fd)
        return False

    def release(self) -> None:
        """Delete the lock file and let go of the lock (in that order: see :meth:`acquire`)."""
        if self.fd is None:
            return
        with contextlib.suppress(OSError):
            os.unlink(self.path)
        os.close(self.fd)
        self.fd = None


def clean_stale(parent: Path, own_name: str | None = None) -> list[Path]:
    """Tidy up after processes that died while writing into ``parent``.

    Partial and trash folders whose owner's lock is not held are deleted; a trash folder that
    holds a result whose folder is missing (killed between the two renames of the swap) is put
    back. ``own_name`` is the folder whose lock this process holds. Folders from gnssacc versions
    before the lock (no folder name in theirs) are left alone.

    Returns
    -------
    list of Path
        The folders removed or put back.
    """
    done = []
    for entry in sorted(Path(parent).glob(".gnssacc-*-*")):
        prefix = next((p for p in (PARTIAL_PREFIX, TRASH_PREFIX) if entry.name.startswith(p)), None)
        parts = entry.name[len(prefix) :].rsplit("-", 1) if prefix else []
        if len(parts) != 2 or not parts[0] or not entry.is_dir():
            continue
        lock = None if parts[0] == own_name else FolderLock(Path(parent) / parts[0])
        if lock is not None and not lock.acquire():
            continue
        try:
            target = Path(parent) / parts[0]
            if prefix == TRASH_PREFIX and not os.path.lexists(target) and is_result(entry):
                os.rename(entry, target)
            else:
                shutil.rmtree(entry, ignore_errors=True)
        finally:
            if lock is not None:
                lock.release()
        done.append(entry)
    return done


class ResultDir:
    """An output folder that holds one complete result: lock, check, write aside, swap.

    Use as a context manager around the whole run (the lock is held inside)::

        with ResultDir(out, overwrite=False) as rd:   # refused here: locked, or not ours
            ...compute...
            rd.replace(lambda tmp: write_files(tmp))

    Parameters
    ----------
    path : str or Path
        The output folder.
    overwrite : bool
        Also replace a file or a non-empty folder that is not a gnssacc result.
    keep_out : sequence of Path
        Paths that must not lie inside ``path`` (e.g. the input data), as it is replaced whole.
    """

    def __init__(self, path, overwrite: bool = False, keep_out=()):
        self.path = Path(os.path.abspath(path))
        self.overwrite = overwrite
        self.keep_out = [Path(os.path.abspath(p)) for p in keep_out]
        self.lock = FolderLock(self.path)
        self.had_result = False
        self.replaced = False

    def __enter__(self) -> "ResultDir":
        self.lock.take("--out", f"another gnssacc run is writing {self.path}")
        try:
            clean_stale(self.path.parent, self.path.name)
            self.check()
        except BaseException:
            self.lock.release()
            raise
        return self

    def __exit__(self, *exc) -> None:
        self.lock.release()

    def check(self) -> None:
        """Raise :class:`InputError` if the folder may not be replaced (see the module docstring)."""
        p = self.path
        for inner in self.keep_out + [Path.cwd()]:
            if inner == p or p in inner.parents:
                raise InputError(
                    "--out",
                    f"replacing {p} would delete {inner} (the run's input or the current "
                    f"folder); choose another output folder",
                )
        self.had_result = p.is_dir() and is_result(p)
        if self.overwrite or not os.path.lexists(p) or self.had_result:
            return
        if not p.is_dir() or p.is_symlink():
            raise InputError(
                "--out",
                f"{p} exists and is not a folder; choose another output folder, or "
                f"--overwrite to replace it",
            )
        if any(p.iterdir()):
            raise InputError(
                "--out",
                f"{p} is a non-empty folder that is not a gnssacc result; choose another "
                f"output folder, or --overwrite to replace it and everything in it",
            )

    def kept(self) -> str:
        """What the folder holds now, for the interruption message."""
        if self.replaced:
            return f"{self.path} holds the new complete result"
        if self.had_result:
            return f"{self.path} left unchanged"
        return f"nothing written to {self.path}"

    def replace(self, fill: Callable[[Path], None]) -> Path:
        """Write the new result with ``fill(folder)`` beside the old one, then swap them."""
        if self.lock.fd is None:
            raise RuntimeError("ResultDir.replace outside its 'with' block")
        self.check()
        tmp = Path(
            tempfile.mkdtemp(prefix=f"{PARTIAL_PREFIX}{self.path.name}-", dir=self.path.parent)
        )
        try:
            fill(tmp)
            _write_marker(tmp)
            _set_default_mode(tmp)
            with signals_held():
                self._swap(tmp)
        finally:
            if tmp.exists():  # not swapped in: a partial result
                with signals_held():
                    shutil.rmtree(tmp, ignore_errors=True)
        return self.path

    def _swap(self, tmp: Path) -> None:
        """Old folder to the trash, new one in its place (the first undone if the second fails)."""
        trash = self.path.parent / f"{TRASH_PREFIX}{self.path.name}-{secrets.token_hex(4)}"
        had_old = os.path.lexists(self.path)
        if had_old:
            os.rename(self.path, trash)
        try:
            os.rename(tmp, self.path)
        except BaseException:
            if had_old:
                os.rename(trash, self.path)
            raise
        self.replaced = True
        if had_old:
            _remove(trash)


@contextlib.contextmanager
def signals_held():
    """Hold SIGINT and SIGTERM back within the block; one that came meanwhile is raised at its end.

    The signals are blocked in this thread (``pthread_sigmask``) and, as another thread may still
    receive them, their Python handlers only take note until the block ends. Outside the main
    thread (where handlers cannot be set) this does nothing.
    """
    caught = []
    try:
        old = {
            s: signal.signal(s, lambda signum, frame: caught.append(signum)) for s in SWAP_SIGNALS
        }
    except ValueError:
        old = None
    mask = signal.pthread_sigmask(signal.SIG_BLOCK, SWAP_SIGNALS) if old is not None else None
    try:
        yield
    finally:
        if old is not None:
            signal.pthread_sigmask(
                signal.SIG_SETMASK, mask
            )  # a blocked one now reaches the note-taker
            for s, handler in old.items():
                signal.signal(s, handler)
            if caught:
                _deliver(caught[0], old[caught[0]])


def _deliver(signum: int, handler) -> None:
    """Act on a held-back signal as its own handler would have."""
    if callable(handler):
        handler(signum, None)
    elif handler == signal.SIG_DFL:
        signal.raise_signal(signum)


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path, ignore_errors=True)
    else:
        with contextlib.suppress(OSError):
            path.unlink()


def _write_marker(folder: Path) -> None:
    files = sorted(f.relative_to(folder).as_posix() for f in folder.rglob("*") if f.is_file())
    doc = {
        "gnssacc": __version__,
        "written": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "files": files,
    }
    (folder / MARKER).write_text(json.dumps(doc, indent=2) + "\n")


def _set_default_mode(folder: Path) -> None:
    """mkdtemp makes the folder private (0700); give it the mode of any new folder (umask)."""
    umask = os.umask(0)
    os.umask(umask)
    folder.chmod(0o777 & ~umask)
