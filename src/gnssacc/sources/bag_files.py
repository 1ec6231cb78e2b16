"""Opening a bag: what a bag path must look like, and a reader for it (damaged ROS 1 bags salvaged).

Checks names and magic bytes before rosbags sees the file, so a wrong file gets an error that
says what it is; rosbags itself is imported only when a bag is opened.
"""

from __future__ import annotations

from pathlib import Path

from ..core.errors import InputError, warn_data
from .bag_salvage import Ros1Salvage
from .common import one_line

#: First bytes of each bag file type (ROS 1 format 2.0, MCAP, and the sqlite3 storage of ROS 2).
MAGIC = {".bag": b"#ROSBAG V2.0\n", ".mcap": b"\x89MCAP0\r\n", ".db3": b"SQLite format 3\x00"}
#: Storage files of a ROS 2 bag directory (possibly compressed: ``x.db3.zstd``).
STORAGE_SUFFIXES = (".db3", ".mcap", ".zstd")


def storage_files(folder: Path) -> list[str]:
    """Names of the ROS 2 storage files (``.db3``, ``.mcap``, compressed ``.zstd``) in a folder."""
    return sorted(
        p.name for p in Path(folder).iterdir() if p.is_file() and p.name.endswith(STORAGE_SUFFIXES)
    )


def check_bag_path(path: Path) -> None:
    """Raise :class:`InputError` unless ``path`` looks like a bag rosbags can open.

    A ``.bag``, ``.mcap`` or ``.db3`` file must start with its format's magic bytes (so a text file or an
    empty file named ``.bag`` is refused with what it starts with); a ROS 2 bag directory needs
    ``metadata.yaml`` (without it, ``ros2 bag reindex`` rebuilds it) and a storage file.
    """
    where = str(path)
    if not path.exists():
        raise InputError(where, "no such file or directory")
    if path.is_dir():
        found = storage_files(path)
        if not (path / "metadata.yaml").is_file():
            if found:
                raise InputError(
                    where,
                    f"looks like a ROS 2 bag without its metadata.yaml (holds {', '.join(found[:3])})"
                    f": rebuild it with 'ros2 bag reindex {path}', then try again",
                )
            raise InputError(where, "not a ROS 2 bag directory (no metadata.yaml)")
        if not found:
            raise InputError(
                where,
                "a ROS 2 bag directory with metadata.yaml but no storage file (.db3 or .mcap)",
            )
        return
    if path.suffix not in MAGIC:
        raise InputError(
            where,
            f"not a ROS bag: expected .bag, .mcap, .db3 or a ROS 2 bag directory, got {path.name}",
        )
    _check_magic(path, where)


def _check_magic(path: Path, where: str) -> None:
    """The file starts with the magic bytes its suffix promises (else InputError saying what it is)."""
    with open(path, "rb") as fh:
        head = fh.read(16)
    if not head:
        raise InputError(where, "empty file (0 bytes): not a ROS bag")
    magic = MAGIC[path.suffix]
    if head.startswith(magic):
        return
    kind = {
        ".bag": "a ROS 1 bag (format 2.0)",
        ".mcap": "an MCAP file",
        ".db3": "an sqlite3 database",
    }[path.suffix]
    other = next((s for s, m in MAGIC.items() if head.startswith(m)), None)
    if other == ".mcap":
        hint = "; it is an MCAP file: rename it to .mcap"
    elif other == ".db3":
        hint = "; it is an sqlite3 database: rename it to .db3"
    elif head.startswith(b"#ROSBAG V"):
        hint = (
            f"; ROS 1 bag format {head[9:12].decode(errors='replace')} is not supported (only 2.0)"
        )
    else:
        hint = ""
    raise InputError(where, f"not {kind}: it starts with {head!r}, expected {magic!r}{hint}")


def _db3_notice(path: Path) -> str:
    """What reading a ROS 2 storage file on its own reconstructs (a salvage notice)."""
    if (path.parent / "metadata.yaml").is_file():
        return (
            f"read as a storage file on its own: the bag's metadata.yaml beside it (and any other "
            f"file of a split bag) is not used; give the directory {path.parent} to read the "
            f"whole bag"
        )
    return (
        "a ROS 2 storage file without its bag's metadata.yaml: the topics, message types, counts "
        "and time span are reconstructed from the database itself (what metadata.yaml would "
        "have said), and any other file of a split bag is missing; 'ros2 bag reindex' rebuilds "
        "the metadata"
    )


def open_reader(path: Path):
    """An open reader of the bag at ``path``.

    Returns
    -------
    rosbags.highlevel.AnyReader or Ros1Salvage
        The salvage reader (with its ``damaged`` reason set and a warning given) when a ROS 1
        bag cannot be opened normally but complete chunks precede the damage.

    Raises
    ------
    InputError
        Not a bag (:func:`check_bag_path`), or a bag that cannot be read at all.
    """
    from rosbags.highlevel import AnyReader

    where = str(path)
    check_bag_path(path)
    if path.is_file() and path.suffix == ".db3":
        warn_data(where, _db3_notice(path))
    try:
        reader = AnyReader([path])
        reader.open()
    except InputError:
        raise
    except Exception as err:  # rosbags raises several error types for damaged files
        problem = one_line(err)
        if path.is_file() and path.suffix == ".bag":
            salvage = Ros1Salvage(path)
            if salvage.message_count:
                warn_data(
                    where,
                    f"the bag is damaged ({problem}); read sequentially up to the damage: "
                    f"{salvage.message_count} messages in {salvage.n_chunks} complete chunk(s), "
                    f"{salvage.good_bytes} of {salvage.file_bytes} bytes; the rest is lost",
                )
                salvage.damaged = problem
                return salvage
        raise InputError(where, f"cannot read the bag (truncated or corrupt?): {problem}") from None
    return reader
