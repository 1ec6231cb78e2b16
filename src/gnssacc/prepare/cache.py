"""The preparation's outcome kept on disk: a rerun of the same recording never pays it twice.

The preparation (input checks and their verdicts, the start, the tuned noise:
:func:`gnssacc.prepare.preparation.prepare`) depends only on the recording, the settings and the
code. Its outcome, the :class:`~gnssacc.prepare.prepared.Prepared` itself with the warnings it
gave, is stored in one file per recording and settings:

- the file's name is a digest of the recording's content (every array and field of the loaded
  :class:`~gnssacc.core.recording.RecordedRun`: :func:`recording_digest`), of the resolved
  configuration's values and of the tuning mode (:func:`preparation_key`);
- its header holds that key, the gnssacc version, a fingerprint of the installed code
  (:func:`code_fingerprint`: a change of any module makes it stale) and the payload's SHA-256.

A file that cannot be read, whose payload does not match its digest, or that another version or
code made, is ignored with a notice (a :class:`~gnssacc.core.errors.DataWarning` naming it) and
replaced by the fresh outcome: it is never trusted. Files are written whole (a temporary file
renamed), so concurrent campaign tasks on one recording at worst both prepare it. The folder keeps
the :data:`MAX_FILES` most recently used files.

Where: ``$GNSSACC_CACHE_DIR`` when set (``none`` or ``off``: no cache), else
``$XDG_CACHE_HOME/gnssacc/prepared`` (``~/.cache/gnssacc/prepared``; on Windows under
``%LOCALAPPDATA%``): :func:`default_folder`.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import pickle
import sys
import tempfile
import time
import warnings
from functools import lru_cache
from pathlib import Path
from typing import Callable

import numpy as np

from ..core.config import RunConfig
from ..core.errors import DataWarning, warn_data
from ..core.recording import RecordedRun
from ..core.version import __version__
from .prepared import Prepared

#: The environment variable naming the cache folder (``none``/``off``: no cache).
CACHE_ENV = "GNSSACC_CACHE_DIR"
#: The file layout's version (a new layout makes older files stale).
FORMAT = 1
MAGIC = b"GNSSACC-PREPARED\n"
#: Most files the folder keeps (the least recently used go first).
MAX_FILES = 64


def default_folder() -> Path | None:
    """The cache folder (module notes); ``None`` when ``$GNSSACC_CACHE_DIR`` turns the cache off."""
    env = os.environ.get(CACHE_ENV)
    if env is not None:
        return None if env.strip().lower() in ("", "none", "off") else Path(env).expanduser()
    if sys.platform == "win32" and os.environ.get("LOCALAPPDATA"):
        return Path(os.environ["LOCALAPPDATA"]) / "gnssacc" / "prepared"
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "gnssacc" / "prepared"


def _feed(h, obj) -> None:
    """Hash ``obj`` into ``h``: arrays by dtype, shape and bytes; dataclasses, containers and plain
    objects field by field; random generators by their state; functions by name; anything else by
    its type and ``repr``."""
    if isinstance(obj, np.ndarray):
        a = np.ascontiguousarray(obj)
        h.update(f"nd{a.dtype.str}{a.shape}".encode())
        h.update(a.view(np.uint8).reshape(-1) if a.dtype != object else repr(a.tolist()).encode())
    elif dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        h.update(f"dc{type(obj).__qualname__}".encode())
        for f in dataclasses.fields(obj):
            h.update(f.name.encode())
            _feed(h, getattr(obj, f.name))
    elif isinstance(obj, dict):
        h.update(f"d{len(obj)}".encode())
        for k in sorted(obj, key=repr):
            _feed(h, k)
            _feed(h, obj[k])
    elif isinstance(obj, (list, tuple)):
        h.update(f"l{len(obj)}".encode())
        for v in obj:
            _feed(h, v)
    elif isinstance(obj, np.random.Generator):
        _feed(h, obj.bit_generator.state)
    elif callable(obj):
        h.update(f"fn{getattr(obj, '__module__', '')}.{getattr(obj, '__qualname__', '')};".encode())
    elif hasattr(obj, "__dict__") and " at 0x" in object.__repr__(obj) == repr(obj):
        h.update(f"ob{type(obj).__qualname__}".encode())  # a plain object: by its attributes
        _feed(h, vars(obj))
    else:
        h.update(f"{type(obj).__qualname__}:{obj!r};".encode())


def recording_digest(run: RecordedRun) -> str:
    """A digest of the recording's content: every array and field of the loaded run (hex)."""
    h = hashlib.blake2b(digest_size=20)
    _feed(h, run)
    return h.hexdigest()


@lru_cache(maxsize=1)
def code_fingerprint() -> str:
    """The gnssacc version and the size and modification time of each of its modules (hex): a
    changed module makes every stored preparation stale."""
    root = Path(__file__).resolve().parents[1]
    h = hashlib.blake2b(__version__.encode(), digest_size=12)
    for p in sorted(root.rglob("*.py")):
        st = p.stat()
        h.update(f"{p.relative_to(root)}:{st.st_size}:{st.st_mtime_ns};".encode())
    return h.hexdigest()


def preparation_key(run: RecordedRun, cfg: RunConfig, tune_mode: str) -> str:
    """The file name's key: the recording's content, the configuration's values and the tuning mode
    (the settings the preparation reads; the method list, plots and exports are not among them)."""
    h = hashlib.blake2b(digest_size=20)
    h.update(recording_digest(run).encode())
    _feed(h, cfg.values)
    _feed(h, sorted(cfg.explicit))  # the tuner leaves the keys the user set alone
    h.update(f"tune={tune_mode}".encode())
    return h.hexdigest()


@dataclasses.dataclass
class Stored:
    """What a cache file holds: the prepared recording and the warnings its preparation gave
    (``(message, category name)``, said again on reuse)."""

    prepared: Prepared
    warnings: list


class _Recorder:
    """Records the warnings shown while it is active (and shows them as before), except while
    :attr:`paused` (the caller's own reaction, which it makes again on reuse)."""

    def __init__(self):
        self.seen: list = []
        self.paused = False

    def __enter__(self):
        self._ctx = warnings.catch_warnings()
        self._ctx.__enter__()
        shown = warnings.showwarning

        def show(message, category, *args, **kwargs):
            if not self.paused and issubclass(category, DataWarning):
                self.seen.append(str(message))
            shown(message, category, *args, **kwargs)

        warnings.showwarning = show
        return self

    def __exit__(self, *exc):
        return self._ctx.__exit__(*exc)


class PreparationCache:
    """One cache folder (module notes).

    Parameters
    ----------
    folder : Path
    retune : bool
        Never reuse: prepare afresh (``--retune``) and store the outcome.
    """

    def __init__(self, folder: Path, retune: bool = False):
        self.folder, self.retune = Path(folder), retune

    def path(self, key: str) -> Path:
        return self.folder / f"{key}.prep"

    def load(self, key: str) -> Stored | None:
        """The stored outcome for ``key``; ``None`` when there is none, or (with a notice) when the
        file is unreadable, damaged or stale."""
        path = self.path(key)
        if self.retune or not path.is_file():
            return None
        try:
            data = path.read_bytes()
            if not data.startswith(MAGIC):
                raise ValueError("not a gnssacc preparation file")
            head, _, payload = data[len(MAGIC) :].partition(b"\n")
            meta = json.loads(head)
            if meta.get("key") != key:
                raise ValueError("made for another recording or settings")
            if hashlib.sha256(payload).hexdigest() != meta.get("sha256"):
                raise ValueError("damaged: its content does not match its digest")
            made = (meta.get("format"), meta.get("version"), meta.get("code"))
            if made != (FORMAT, __version__, code_fingerprint()):
                warn_data(
                    str(path),
                    f"made by gnssacc {meta.get('version')} or other code: stale, "
                    "ignored; the recording is prepared afresh",
                )
                return None
            stored = pickle.loads(payload)
            if not isinstance(stored, Stored) or not isinstance(stored.prepared, Prepared):
                raise ValueError("holds something else")
        except Exception as exc:  # anything wrong with the file: ignored, never trusted
            warn_data(str(path), f"stored preparation ignored ({exc}); prepared afresh")
            return None
        os.utime(path)  # recently used
        return stored

    def store(self, key: str, stored: Stored) -> Path | None:
        """Write ``stored`` for ``key`` whole (a temporary file renamed); ``None`` (and a notice)
        when the folder cannot be written."""
        payload = pickle.dumps(stored, protocol=pickle.HIGHEST_PROTOCOL)
        head = {
            "format": FORMAT,
            "key": key,
            "version": __version__,
            "code": code_fingerprint(),
            "sha256": hashlib.sha256(payload).hexdigest(),
            "made": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        }
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(dir=self.folder, suffix=".tmp")
            with os.fdopen(fd, "wb") as f:
                f.write(MAGIC + json.dumps(head).encode() + b"\n" + payload)
            os.replace(tmp, self.path(key))
        except OSError as exc:
            warn_data(str(self.folder), f"cannot store the preparation ({exc}); not cached")
            return None
        self._prune()
        return self.path(key)

    def _prune(self) -> None:
        """Keep the :data:`MAX_FILES` most recently used files. Another process storing into the
        same folder may prune it at the same moment: a file it removed first is passed over,
        and one that cannot be removed is left (the run's own file is stored either way)."""
        used = []
        for p in self.folder.glob("*.prep"):
            try:
                used.append((p.stat().st_mtime, p))
            except OSError:
                continue  # removed meanwhile
        for _, p in sorted(used, reverse=True)[MAX_FILES:]:
            try:
                p.unlink(missing_ok=True)
            except OSError:
                continue


def _storable(prep: Prepared) -> Prepared:
    """``prep`` without what cannot be stored: the checks' proposed repairs (callables, used only
    while the checks are settled)."""
    checks = tuple(dataclasses.replace(f, repair=None) for f in prep.checks)
    gm = prep.gauss_markov
    if gm is not None:
        gm = (_storable(gm[0]),) + tuple(gm[1:])
    return dataclasses.replace(prep, checks=checks, gauss_markov=gm)


def prepared_once(
    run: RecordedRun,
    cfg: RunConfig,
    tune_mode: str,
    cache: PreparationCache,
    make: Callable[[Callable | None], Prepared],
    add_gauss_markov: Callable[[Prepared], Prepared] | None = None,
    on_checked: Callable | None = None,
) -> Prepared:
    """The prepared recording from ``cache`` when it holds it, else ``make(on_checked)``, stored.

    Parameters
    ----------
    run, cfg, tune_mode
        What the preparation reads (:func:`preparation_key`).
    cache : PreparationCache
    make : callable
        ``make(on_checked) -> Prepared``: the preparation itself.
    add_gauss_markov : callable, optional
        Adds the ``-gm`` methods' setup to a prepared recording that lacks it (then stored with it).
    on_checked : callable, optional
        As for :func:`gnssacc.prepare.preparation.prepare`; on reuse it is told the stored findings
        and ``reused=`` a phrase saying where they come from (for the run's header line).

    Returns
    -------
    Prepared
        On reuse, :attr:`Prepared.cache` says so (``{"reused": True, "file": ..., ...}``) and
        :attr:`Prepared.seconds` holds the load time.
    """
    t = time.perf_counter()
    key = preparation_key(run, cfg, tune_mode)
    stored = cache.load(key)
    if stored is not None:
        for message in stored.warnings:
            where, _, problem = message.partition(": ")
            warn_data(where, problem)
        prep = stored.prepared
        note = f"preparation reused from {cache.path(key)} (--retune to redo it)"
        if on_checked is not None:
            on_checked(list(prep.checks), reused=note)
        fresh = add_gauss_markov is not None and prep.gauss_markov is None
        if fresh:
            prep = add_gauss_markov(prep)
            cache.store(key, Stored(_storable(prep), stored.warnings))
        seconds = {"cache_load_s": time.perf_counter() - t}
        info = {"reused": True, "file": str(cache.path(key)), "key": key}
        return dataclasses.replace(prep, seconds=seconds, cache=info)
    with _Recorder() as rec:

        def told(findings, **kw):
            rec.paused = True
            try:
                on_checked(findings, **kw)
            finally:
                rec.paused = False

        prep = make(told if on_checked is not None else None)
        if add_gauss_markov is not None:
            prep = add_gauss_markov(prep)
    path = cache.store(key, Stored(_storable(prep), rec.seen))
    info = {"reused": False, "file": str(path) if path else None, "key": key}
    return dataclasses.replace(prep, cache=info)


def open_cache(where=True, retune: bool = False) -> PreparationCache | None:
    """The cache to use: ``where`` a folder, ``True`` the default one (:func:`default_folder`;
    ``None`` when ``$GNSSACC_CACHE_DIR`` turns it off), ``False`` or ``None`` none."""
    if where is None or where is False:
        return None
    folder = default_folder() if where is True else Path(where)
    return None if folder is None else PreparationCache(folder, retune=retune)
