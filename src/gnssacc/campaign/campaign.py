"""A ``gnssacc batch`` campaign: its settings, its tasks, and what of it is on disk.

A campaign runs every method on every (recording, seed, outage pattern); each such triple is a
**task**. Its folder ``C`` holds::

    C/campaign.json                    the settings, their hash, the gnssacc version
    C/summary.csv, C/summary.md        the results so far (see gnssacc.campaign.campaign_summary)
    C/<recording>/<seed>/              one task: the folder ``gnssacc run`` writes, plus TASK_FILE
    C/<recording>/<pattern>/<seed>/    ... when the campaign has more than one outage pattern

Every task folder is written all or nothing (:class:`gnssacc.outputs.outdir.ResultDir`) and holds
:data:`TASK_FILE`: the task, its status (``ok`` or ``failed`` with the one-line error), its rows of
``summary.csv`` and the settings hash. A task whose folder holds a complete result with the
campaign's task hash is finished; ``--resume`` runs the others. A folder with another hash is never
mixed in: the resume is refused.

A campaign grows: ``--resume C`` with more seeds, sources or outage patterns (:data:`GROWABLE`) adds
their tasks and keeps the finished ones, whose numbers do not depend on which other tasks exist
(their records carry :func:`task_hash`, the hash of every other setting). A setting that would
change a finished task (methods, noise, configuration, outputs, ...) is refused. Adding an outage
pattern to a campaign of one is refused too: its task folders would move under a pattern folder.

The settings are everything that changes a task's numbers or files: sources, methods, seeds,
outage patterns, noise, preset, tune mode, configuration file content (its SHA-256), IMU frame,
bag options, outputs, and the gnssacc version.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import tempfile
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

from ..core.errors import InputError
from ..core.version import __version__
from ..outputs.outdir import MARKER, FolderLock, clean_stale

#: The campaign's settings file, in its folder.
CAMPAIGN_FILE = "campaign.json"
#: A task's record, in its folder.
TASK_FILE = "batch.json"
#: Names in the campaign folder that are not recordings.
RESERVED = {
    CAMPAIGN_FILE,
    "summary.csv",
    "summary.md",
    "summary.html",
    "summary_prmse.png",
    "summary_effects.png",
}
#: Settings that name what ``gnssacc batch`` options set them (for the refusal message).
OPTION_OF = {
    "sources": "SOURCE",
    "methods": "--methods",
    "seeds": "--seeds",
    "outages": "--outage/--outage-every",
    "noise": "--noise",
    "preset": "--preset",
    "tune": "--tune",
    "config": "--config",
    "imu_frame": "--imu-frame",
    "bag": "the bag options",
    "outputs": "--no-plots/--report/--export",
    "gnssacc": "the gnssacc version",
}


@dataclass(frozen=True)
class Pattern:
    """One outage pattern: ``--outage`` spans or an ``--outage-every`` cycle, or none.

    Attributes
    ----------
    outage, outage_every : str or None
        As for ``gnssacc run`` (``START:LEN[,...]`` and ``PERIOD:LEN``, seconds).
    """

    outage: str | None = None
    outage_every: str | None = None

    @property
    def text(self) -> str:
        """The ``outages`` column of ``summary.csv``: ``none``, ``120:30,300:10`` or ``every 60:20``."""
        parts = ([self.outage] if self.outage else []) + (
            [f"every {self.outage_every}"] if self.outage_every else []
        )
        return " + ".join(parts) or "none"

    @property
    def label(self) -> str:
        """A folder name for the pattern: ``none``, ``at-120_30-300_10``, ``every-60_20``."""
        parts = ([f"at-{self.outage}"] if self.outage else []) + (
            [f"every-{self.outage_every}"] if self.outage_every else []
        )
        return "+".join(parts).replace(":", "_").replace(",", "-") or "none"


@dataclass(frozen=True)
class TaskSpec:
    """One task, as sent to a worker (small: paths, never data).

    Attributes
    ----------
    source : str
        ``"kitti"`` or the recording's absolute path (workers read it there: shared filesystem).
    name : str
        The recording's name in the campaign (its folder).
    seed : int
        GNSS noise seed.
    pattern : Pattern
    root : str or None
        The campaign folder (absolute); ``None``: compute only, write nothing (``gnssacc bench``).
    rel : str
        The task's folder relative to ``root``.
    options : dict
        The campaign settings the computation needs (see :func:`make_settings`).
    settings_hash : str
    """

    source: str
    name: str
    seed: int
    pattern: Pattern
    root: str | None
    rel: str
    options: dict = field(compare=False)
    settings_hash: str = ""

    @property
    def folder(self) -> str | None:
        """The task's folder (absolute), or ``None`` when the task writes nothing."""
        return None if self.root is None else os.path.join(self.root, self.rel)

    @property
    def key(self) -> str:
        """``<recording>/<pattern label>/<seed>``: unique within a campaign."""
        return f"{self.name}/{self.pattern.label}/{self.seed}"


#: The bag options of a campaign and their defaults (``gnssacc run``'s), all stored, so that a
#: campaign made through the API (which may give none) resumes from the command line.
BAG_DEFAULTS = {
    "imu_topic": None,
    "gnss_topic": None,
    "truth_topic": None,
    "time_source": "header",
    "gnss_from_truth_hz": None,
    "odom_topic": None,
    "gnss": None,
}


def full_bag(bag: dict | None) -> dict:
    """``bag`` with every option of :data:`BAG_DEFAULTS` (the defaults where it has none)."""
    return {**BAG_DEFAULTS, **(bag or {})}


def make_settings(
    sources: list[str],
    methods: list[str],
    seeds: list[int],
    patterns: list[Pattern],
    *,
    noise: str | None = None,
    preset: str | None = None,
    tune: str | None = None,
    config: str | None = None,
    imu_frame: str = "frd",
    bag: dict | None = None,
    plots: bool = True,
    report: bool = False,
    export: tuple = (),
) -> dict:
    """The settings of a campaign, as stored in :data:`CAMPAIGN_FILE` (JSON-ready).

    Parameters
    ----------
    sources : list of str
        ``"kitti"``, ``sim:`` specs (:mod:`gnssacc.sources.simspec`, checked here, kept as they are) or paths
        (made absolute here); each must exist.
    methods, seeds, patterns
        What every task runs.
    noise, preset, tune, imu_frame, bag
        As for ``gnssacc run`` (``preset`` as given; the KITTI source resolves its own).
    config : str, optional
        A configuration file; its path and SHA-256 are stored, so a changed file is noticed.
    plots, report, export
        What each task folder holds besides the result files.

    Raises
    ------
    InputError
        A source given twice.
    """
    from ..sources.simspec import is_sim_spec, parse_sim_spec

    for s in sources:
        if is_sim_spec(s):
            parse_sim_spec(s)  # a bad spec: one line before the campaign starts
    paths = [s if s == "kitti" or is_sim_spec(s) else os.path.abspath(s) for s in sources]
    bag = full_bag(bag)
    if bag["gnss"] is not None:
        bag["gnss"] = os.path.abspath(bag["gnss"])
    twice = sorted({p for p in paths if paths.count(p) > 1})
    if twice:
        raise InputError(twice[0], "given twice as a source")
    return {
        "gnssacc": __version__,
        "sources": [[n, p] for n, p in zip(recording_names(paths), paths)],
        "methods": list(methods),
        "seeds": [int(s) for s in seeds],
        "outages": [[p.outage, p.outage_every] for p in patterns],
        "noise": noise,
        "preset": preset,
        "tune": tune,
        "config": config_identity(config) if config else None,
        "imu_frame": imu_frame,
        "bag": bag,
        "outputs": {"plots": bool(plots), "report": bool(report), "export": sorted(export)},
    }


def config_identity(path: str) -> dict:
    """``{"path", "sha256"}`` of a configuration file (:class:`InputError` when unreadable)."""
    try:
        data = Path(path).read_bytes()
    except OSError as exc:
        raise InputError("--config", f"{path}: {exc.strerror or exc}") from None
    return {"path": os.path.abspath(path), "sha256": hashlib.sha256(data).hexdigest()}


def settings_hash(settings: dict) -> str:
    """A short hash of the settings (16 hex digits of the SHA-256 of their canonical JSON)."""
    return hashlib.sha256(json.dumps(settings, sort_keys=True).encode()).hexdigest()[:16]


#: Settings that say which tasks a campaign has, not what a task computes: a campaign may grow in them.
GROWABLE = ("sources", "seeds", "outages")


def task_hash(settings: dict) -> str:
    """:func:`settings_hash` of the settings that change a task's numbers or files (all but :data:`GROWABLE`)."""
    return settings_hash({k: v for k, v in settings.items() if k not in GROWABLE})


def grown(stored: dict, wanted: dict) -> dict:
    """``wanted`` with the seeds, sources and outage patterns of ``stored`` and then those of ``wanted``
    it lacks (``stored``'s order kept, the new ones after); every other setting as ``wanted`` has it
    (compared with ``stored`` by the caller).

    Raises
    ------
    InputError
        A new outage pattern for a campaign of one pattern (its task folders would move).
    """
    out = dict(wanted)
    out["seeds"] = stored["seeds"] + [s for s in wanted["seeds"] if s not in stored["seeds"]]
    out["outages"] = stored["outages"] + [
        p for p in wanted["outages"] if p not in stored["outages"]
    ]
    if len(stored["outages"]) == 1 and len(out["outages"]) > 1:
        raise InputError(
            "--outage",
            "cannot add an outage pattern to a campaign of one pattern (its task folders "
            "would move under a pattern folder); start a new campaign with --out",
        )
    paths = [p for _, p in stored["sources"]]
    paths += [p for _, p in wanted["sources"] if p not in paths]
    out["sources"] = [
        [n, p] for n, p in zip(recording_names(paths), paths)
    ]  # the stored ones keep their names
    return out


def recording_names(sources: list[str]) -> list[str]:
    """A distinct folder name per source: its last path component (``kitti`` for KITTI, the spec with
    ``:,=`` replaced for a ``sim:`` spec, :func:`gnssacc.sources.simspec.folder_name`; ``_``
    before a leading dot), with ``-2``, ``-3``... after a name already taken (or one of the
    campaign's own files), in the order given."""
    from ..sources.simspec import folder_name, is_sim_spec

    names: list[str] = []
    for s in sources:
        base = (
            "kitti"
            if s == "kitti"
            else folder_name(s)
            if is_sim_spec(s)
            else (Path(s).name or "recording")
        )
        base = "_" + base if base.startswith(".") else base
        name, k = base, 2
        while name in names or name in RESERVED:
            name, k = f"{base}-{k}", k + 1
        names.append(name)
    return names


def plan(settings: dict, root: Path | None) -> list[TaskSpec]:
    """The campaign's tasks in a fixed order: by source, outage pattern, then seed.

    ``root`` is the campaign folder (``None``: tasks that write nothing).
    """
    patterns = [Pattern(*p) for p in settings["outages"]]
    options = {
        k: settings[k]
        for k in ("methods", "noise", "preset", "tune", "config", "imu_frame", "bag", "outputs")
    }
    digest = task_hash(settings)
    tasks = []
    for name, source in settings["sources"]:
        for pattern in patterns:
            for seed in settings["seeds"]:
                rel = (
                    Path(name, pattern.label, str(seed))
                    if len(patterns) > 1
                    else Path(name, str(seed))
                )
                tasks.append(
                    TaskSpec(
                        source,
                        name,
                        seed,
                        pattern,
                        str(root) if root else None,
                        rel.as_posix(),
                        options,
                        digest,
                    )
                )
    return tasks


def write_atomic(path: Path, text: str) -> None:
    """Replace ``path`` by ``text`` in one step (a temporary file beside it, then a rename)."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}-", dir=path.parent)
    try:
        with open(fd, "w") as fh:
            fh.write(text)
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


class Campaign:
    """A campaign folder: its settings, lock and finished tasks.

    Use :meth:`create` for a new campaign or :meth:`open` to resume one, as a context manager
    (the folder is locked inside, so two ``gnssacc batch`` never run the same campaign).
    """

    def __init__(self, root: Path, settings: dict, new: bool = False):
        self.root = Path(os.path.abspath(root))
        self.settings = settings
        self.hash = settings_hash(settings)
        self.new = new
        self.lock = FolderLock(self.root)
        self.added = 0  # tasks added by :meth:`grow`

    def grow(self, settings: dict) -> None:
        """Take ``settings`` (:func:`grown`: more seeds, sources or patterns) as the campaign's; written
        to :data:`CAMPAIGN_FILE` when the campaign is entered (locked)."""
        before = len(self.tasks())
        self.settings, self.hash = settings, settings_hash(settings)
        self.added = len(self.tasks()) - before

    @classmethod
    def create(cls, root, settings: dict) -> "Campaign":
        """A new campaign in ``root``, which must be absent or an empty folder (checked when entered)."""
        return cls(root, settings, new=True)

    @classmethod
    def open(cls, root) -> "Campaign":
        """The campaign in ``root``, to resume (:class:`InputError` when there is none or it is damaged)."""
        path = Path(root) / CAMPAIGN_FILE
        try:
            doc = json.loads(path.read_text())
            settings, digest = doc["settings"], doc["settings_hash"]
        except FileNotFoundError:
            raise InputError("--resume", f"{root} holds no campaign (no {CAMPAIGN_FILE})") from None
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise InputError(str(path), f"not a readable campaign file ({exc})") from None
        camp = cls(root, settings)
        if camp.hash != digest:
            raise InputError(
                str(path), "its settings do not match their stored hash (edited by hand?)"
            )
        return camp

    def __enter__(self) -> "Campaign":
        self.lock.take(str(self.root), "another gnssacc batch is running this campaign")
        try:
            if self.new:
                self._start()
            elif self.added:
                self._write_settings()
        except BaseException:
            self.lock.release()
            raise
        return self

    def _start(self) -> None:
        """Check that the folder may hold a new campaign, and write :data:`CAMPAIGN_FILE` into it."""
        p = self.root
        if (p / CAMPAIGN_FILE).exists():
            raise InputError(
                "--out",
                f"{p} already holds a campaign; finish it with 'gnssacc batch --resume {p}', or "
                f"choose another output folder",
            )
        if os.path.lexists(p) and (not p.is_dir() or any(p.iterdir())):
            raise InputError(
                "--out", f"{p} exists and is not an empty folder; choose another output folder"
            )
        p.mkdir(exist_ok=True)
        self._write_settings()

    def _write_settings(self) -> None:
        doc = {
            "gnssacc": __version__,
            "created": datetime.now(timezone.utc).isoformat(timespec="seconds"),
            "settings_hash": self.hash,
            "settings": self.settings,
        }
        write_atomic(self.root / CAMPAIGN_FILE, json.dumps(doc, indent=2) + "\n")

    def __exit__(self, *exc) -> None:
        self.lock.release()

    def tasks(self) -> list[TaskSpec]:
        """Every task of the campaign (:func:`plan`)."""
        return plan(self.settings, self.root)

    def finished(self, tasks: list[TaskSpec]) -> dict[str, dict]:
        """The records of the tasks whose folders hold a complete result, by task key.

        Also deletes what interrupted tasks left (partial folders whose writer is gone).

        Raises
        ------
        InputError
            A task folder written with other settings (its hash differs): the campaign would mix them.
        """
        self.tidy(tasks)
        done = {}
        for t in tasks:
            record = read_record(Path(t.folder))
            if record is None:
                continue
            if record.get("settings_hash") not in (
                t.settings_hash,
                self.hash,
            ):  # the latter: before task hashes
                raise InputError(
                    t.folder,
                    f"written with other settings (hash {record.get('settings_hash')}, "
                    f"campaign {t.settings_hash}); move it away to resume",
                )
            done[t.key] = record
        return done

    def tidy(self, tasks: list[TaskSpec]) -> None:
        """Delete what killed or interrupted tasks left: partial folders and lock files that no
        living writer holds (:func:`gnssacc.outputs.outdir.clean_stale`)."""
        for parent in sorted({Path(t.folder).parent for t in tasks}):
            if parent.is_dir():
                clean_stale(parent)
        for t in tasks:
            lock = FolderLock(Path(t.folder))
            if lock.path.exists() and lock.acquire():
                lock.release()


def write_record(folder: Path, record: dict) -> None:
    """Write a task's record as :data:`TASK_FILE` into ``folder`` (the task folder being filled)."""
    (Path(folder) / TASK_FILE).write_text(json.dumps(record, indent=2) + "\n")


def read_record(folder: Path) -> dict | None:
    """The :data:`TASK_FILE` record of a complete task folder, or ``None`` (absent, partial, unreadable)."""
    if not (folder / MARKER).is_file():
        return None
    try:
        return json.loads((folder / TASK_FILE).read_text())
    except (OSError, ValueError):
        return None


def differing_setting(stored: dict, given: dict) -> str | None:
    """The first setting (by its option's name) in which ``given`` differs from ``stored``."""
    for key in OPTION_OF:
        a, b = stored.get(key), given.get(key)
        if key == "bag":  # campaigns stored before every bag option was kept
            a, b = full_bag(a), full_bag(b)
        if a != b:
            return key
    return None
