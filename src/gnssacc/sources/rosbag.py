"""ROS bags as a run source: ROS 1 ``.bag``, ROS 2 directories (sqlite3 or MCAP) and bare ``.mcap``.

Everything is read through :class:`rosbags.highlevel.AnyReader`, with the message definitions
taken from the bag itself, so custom message types decode without a ROS installation.

Topics
    IMU: ``sensor_msgs/msg/Imu``. GNSS: ``sensor_msgs/msg/NavSatFix`` or a custom fix type with
    a field mapping (:data:`FIX_MAPPINGS`, shipped for the ROOAD ``ubxtranslator/hpposllh``).
    Truth (optional): ``nav_msgs/msg/Odometry``, ``geometry_msgs/msg/PoseStamped``,
    ``geometry_msgs/msg/PoseWithCovarianceStamped`` or a second fix topic (e.g. an RTK receiver).
    Topics are picked by type and rate when unambiguous (see :func:`select_topics`); otherwise
    an :class:`~gnssacc.errors.InputError` lists the candidates and the argument that picks one.

Frames (ROS REP-103 -> gnssacc)
    IMU samples are body Front-Left-Up and converted to Front-Right-Down ``(x, -y, -z)`` before
    the ``[mounting]`` rotation. Pose positions and orientations are in a local East-North-Up
    frame: ``(e, n, u) -> (n, e, -u)`` and ``R_nb = T_ned_enu @ R_enu_flu @ T_flu_frd``.
    ASSUMPTION for pose truth: the pose frame is ENU with its origin at the first GNSS fix,
    unless ``truth_origin_llh_deg`` says otherwise.

Times
    Header stamps by default (the bag receive time for header-less types such as hpposllh);
    ``time_source="receive"`` uses the receive time of every message. Out-of-order messages are
    sorted (counted, warned), exact duplicates dropped (counted, warned), gaps listed in
    ``run.meta["gaps"]``.

Only the chosen connections are read (``reader.messages(connections=...)``): image and other
topics are skipped without being decoded, and memory is bounded by the IMU/GNSS data.
"""
from __future__ import annotations

from array import array
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..config import DEG, RunConfig, vec3
from ..config_check import FIX_MAPPING_FIELDS
from ..earth import LocalTangentFrame
from ..errors import InputError, warn_data
from ..run import GnssFixes, ImuData, InitialState, RecordedRun, Truth, drop_nonfinite
from ..rotations import ENU_NED, FLU_FRD, dcm_to_euler, quaternion_to_dcm, ros_to_R_nb
from .common import apply_mounting, check_degrees

IMU_TYPE = "sensor_msgs/msg/Imu"
NAVSATFIX_TYPE = "sensor_msgs/msg/NavSatFix"
POSE_TYPES = ("nav_msgs/msg/Odometry", "geometry_msgs/msg/PoseStamped",
              "geometry_msgs/msg/PoseWithCovarianceStamped")
TF_TYPE = "tf2_msgs/msg/TFMessage"
TIME_SOURCES = ("header", "receive")
BASE_FRAMES = ("base_link", "base_footprint")

#: Field mappings of custom GNSS fix messages, by message type. Keys:
#: ``lat``, ``lon``, ``height``: field paths; ``latlon_scale_deg``: factor to degrees;
#: ``height_scale_m``: factor to metres (ellipsoidal height); ``sigma_n``, ``sigma_e``,
#: ``sigma_d``: field paths of 1-sigma accuracies (or None: ``gnss.default_sigma_m``);
#: ``sigma_scale_m``: factor to metres; ``stamp``: path of a ``builtin_interfaces/Time`` field or
#: None (then the bag receive time is used); ``status`` and ``no_fix_values``: a field whose
#: listed values mark a fix as invalid (skipped), or None.
FIX_MAPPINGS: dict[str, dict] = {
    # ROOAD: ubxtranslator/hpposllh = ubxtranslator/llh llh + ubxtranslator/llh err, no header.
    "ubxtranslator/msg/hpposllh": {
        "lat": "llh.lat", "lon": "llh.lon", "height": "llh.height",
        "latlon_scale_deg": 1.0, "height_scale_m": 1.0,
        "sigma_n": "err.lat", "sigma_e": "err.lon", "sigma_d": "err.height", "sigma_scale_m": 1.0,
        "stamp": None, "status": None, "no_fix_values": [],
    },
}
_MAPPING_KEYS = set(FIX_MAPPING_FIELDS)
_MAPPING_DEFAULTS = {"latlon_scale_deg": 1.0, "height_scale_m": 1.0, "sigma_n": None, "sigma_e": None,
                     "sigma_d": None, "sigma_scale_m": 1.0, "stamp": None, "status": None, "no_fix_values": []}

#: Initial-state sigmas when the IMU orientation has no (valid) covariance.
INIT_SIGMA_ROLL_PITCH_DEG = 1.0
INIT_SIGMA_YAW_DEG = 5.0
INIT_VEL_FIT_S = 3.0



def normalize_type(name: str) -> str:
    """``pkg/Type`` -> ``pkg/msg/Type`` (the form rosbags uses for ROS 1 and ROS 2)."""
    parts = str(name).strip().split("/")
    if len(parts) == 2:
        return f"{parts[0]}/msg/{parts[1]}"
    return "/".join(parts)


def _mappings(user: dict | None) -> dict[str, dict]:
    out = {k: dict(v) for k, v in FIX_MAPPINGS.items()}
    for typ, m in (user or {}).items():
        if not isinstance(m, dict):
            raise InputError("fix mapping", f"the mapping for {typ} must be a dict of field paths")
        unknown = set(m) - _MAPPING_KEYS
        if unknown:
            raise InputError("fix mapping", f"unknown key(s) {', '.join(sorted(unknown))} in the mapping for {typ} "
                                            f"(known: {', '.join(sorted(_MAPPING_KEYS))})")
        base = out.get(normalize_type(typ), {})
        merged = {**_MAPPING_DEFAULTS, **base, **m}
        missing = [k for k in ("lat", "lon", "height") if not merged.get(k)]
        if missing:
            raise InputError("fix mapping", f"the mapping for {typ} needs field path(s) {', '.join(missing)}")
        out[normalize_type(typ)] = merged
    return out


# --- topic survey and selection -------------------------------------------------------------------

@dataclass
class TopicStat:
    topic: str
    msgtype: str
    count: int
    rate_hz: float          # count / bag span (approximate: rosbag2 stores no per-topic span)

    def describe(self) -> str:
        return f"{self.topic} ({self.msgtype}, {self.count} msgs, ~{self.rate_hz:.1f} Hz)"


@dataclass
class Selection:
    imu: TopicStat
    gnss: TopicStat | None          # None when the GNSS is made from the truth
    truth: TopicStat | None
    truth_kind: str | None          # "fix" or "pose"
    reasons: list[str]


def _survey(reader) -> list[TopicStat]:
    span = max((reader.end_time - reader.start_time) * 1e-9, 1e-9) if reader.message_count else 0.0
    out = []
    for topic, info in reader.topics.items():
        typ = info.msgtype or "?"
        out.append(TopicStat(topic, typ, int(info.msgcount), info.msgcount / span if span > 0 else 0.0))
    return sorted(out, key=lambda s: s.topic)


def _ambiguous(where, what: str, cands: list[TopicStat], flag: str):
    listing = "; ".join(c.describe() for c in cands)
    return InputError(where, f"ambiguous {what} topic: {len(cands)} candidates: {listing}; pick one with {flag}")


def _find(stats, topic, where, flag) -> TopicStat:
    for s in stats:
        if s.topic == topic:
            return s
    raise InputError(where, f"{flag} {topic}: no such topic in the bag (topics: "
                            f"{', '.join(s.topic for s in stats) or 'none'})")


def select_topics(stats: list[TopicStat], where: str, *, imu_topic=None, gnss_topic=None, truth_topic=None,
                  gnss_from_truth: bool = False, mappings: dict | None = None) -> Selection:
    """Pick the IMU, GNSS and truth topics.

    Rules: IMU = the only ``Imu`` topic, or the highest-rate one if at least 1.5x the rate of
    the next; GNSS = the only fix topic (NavSatFix or a mapped custom type) left after the truth;
    truth = the given topic, else the only Odometry/Pose topic, else the only fix topic left
    beside the GNSS when ``gnss_topic`` was given. With ``gnss_from_truth`` the single fix topic
    is the truth. Anything else raises :class:`InputError` listing the candidates and the flag.
    """
    mappings = _mappings(None) if mappings is None else mappings
    reasons: list[str] = []
    is_fix = lambda s: s.msgtype == NAVSATFIX_TYPE or s.msgtype in mappings  # noqa: E731
    nonempty = [s for s in stats if s.count > 0]

    # IMU
    if imu_topic:
        imu = _find(stats, imu_topic, where, "--imu-topic")
        if imu.msgtype != IMU_TYPE:
            raise InputError(where, f"--imu-topic {imu.topic} has type {imu.msgtype}, expected {IMU_TYPE}")
        reasons.append(f"IMU {imu.topic}: given by --imu-topic")
    else:
        cands = sorted([s for s in nonempty if s.msgtype == IMU_TYPE], key=lambda s: -s.rate_hz)
        if not cands:
            raise InputError(where, f"no IMU topic: no {IMU_TYPE} messages in the bag (topics: "
                                    f"{'; '.join(s.describe() for s in stats) or 'none'})")
        if len(cands) > 1 and cands[0].rate_hz < 1.5 * cands[1].rate_hz:
            raise _ambiguous(where, "IMU", cands, "--imu-topic")
        imu = cands[0]
        reasons.append(f"IMU {imu.topic}: " + ("the only Imu topic" if len(cands) == 1 else
                                               f"the highest-rate of {len(cands)} Imu topics"))

    def check_fix(s: TopicStat, flag: str):
        if not is_fix(s):
            raise InputError(where, f"{flag} {s.topic} has type {s.msgtype}, which gnssacc cannot read as a GNSS "
                                    f"fix: give a field mapping for it (known: {NAVSATFIX_TYPE}, "
                                    f"{', '.join(sorted(mappings))})")

    # truth given?
    truth = None
    truth_kind = None
    if truth_topic:
        truth = _find(stats, truth_topic, where, "--truth-topic")
        if truth.msgtype in POSE_TYPES:
            truth_kind = "pose"
        else:
            check_fix(truth, "--truth-topic")
            truth_kind = "fix"
        reasons.append(f"truth {truth.topic}: given by --truth-topic")

    fixes = [s for s in nonempty if is_fix(s) and (truth is None or s.topic != truth.topic)]
    gnss = None
    if gnss_from_truth:
        if gnss_topic:
            raise InputError(where, "give either --gnss-topic or --gnss-from-truth (the fixes are made from the truth topic), not both")
        if truth is None:
            if len(fixes) == 1:
                truth, truth_kind = fixes[0], "fix"
                reasons.append(f"truth {truth.topic}: the only fix topic (GNSS made from it by subsampling)")
            elif not fixes:
                raise InputError(where, "--gnss-from-truth needs a truth fix topic, and the bag has no NavSatFix "
                                        "or mapped fix topic")
            else:
                raise _ambiguous(where, "truth (for --gnss-from-truth)", fixes, "--truth-topic")
        elif truth_kind != "fix":
            raise InputError(where, f"--gnss-from-truth needs a fix-type truth topic; {truth.topic} is "
                                    f"{truth.msgtype}")
        return Selection(imu, None, truth, truth_kind, reasons)

    if gnss_topic:
        gnss = _find(stats, gnss_topic, where, "--gnss-topic")
        check_fix(gnss, "--gnss-topic")
        reasons.append(f"GNSS {gnss.topic}: given by --gnss-topic")
    else:
        if not fixes:
            unknown = [s for s in nonempty if s.msgtype not in (IMU_TYPE, TF_TYPE, "sensor_msgs/msg/Image",
                                                                  "sensor_msgs/msg/CompressedImage")
                       and s.msgtype not in POSE_TYPES and not s.msgtype.startswith(("std_msgs/", "rosgraph_msgs/"))]
            hint = (f"; topics of other types: {'; '.join(s.describe() for s in unknown)} -- if one is a fix, "
                    f"give --gnss-topic and a field mapping for its type") if unknown else ""
            raise InputError(where, f"no GNSS topic: no {NAVSATFIX_TYPE} or known custom fix type "
                                    f"({', '.join(sorted(mappings))}){hint}")
        if len(fixes) > 1:
            raise _ambiguous(where, "GNSS", fixes, "--gnss-topic (and --truth-topic for a reference receiver)")
        gnss = fixes[0]
        reasons.append(f"GNSS {gnss.topic}: the only fix topic" + (" besides the truth" if truth else ""))

    if truth is None:
        poses = [s for s in nonempty if s.msgtype in POSE_TYPES]
        others = [s for s in fixes if s.topic != gnss.topic]
        if len(poses) == 1:
            truth, truth_kind = poses[0], "pose"
            reasons.append(f"truth {truth.topic}: the only Odometry/Pose topic")
        elif len(poses) > 1:
            reasons.append("no truth: several Odometry/Pose topics (" + ", ".join(p.topic for p in poses)
                           + "); pick one with --truth-topic")
        elif gnss_topic and len(others) == 1:
            truth, truth_kind = others[0], "fix"
            reasons.append(f"truth {truth.topic}: the only other fix topic")
        elif len(others) > 1:
            reasons.append("no truth: several other fix topics; pick one with --truth-topic")
        else:
            reasons.append("no truth topic")
    return Selection(imu, gnss, truth, truth_kind, reasons)


# --- reading ----------------------------------------------------------------------------------------

#: First bytes of each bag file type (ROS 1 format 2.0, MCAP, and the sqlite3 storage of ROS 2).
MAGIC = {".bag": b"#ROSBAG V2.0\n", ".mcap": b"\x89MCAP0\r\n", ".db3": b"SQLite format 3\x00"}
#: Storage files of a ROS 2 bag directory (possibly compressed: ``x.db3.zstd``).
STORAGE_SUFFIXES = (".db3", ".mcap", ".zstd")


def storage_files(folder: Path) -> list[str]:
    """Names of the ROS 2 storage files (``.db3``, ``.mcap``, compressed ``.zstd``) in a folder."""
    return sorted(p.name for p in Path(folder).iterdir() if p.is_file() and p.name.endswith(STORAGE_SUFFIXES))


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
                raise InputError(where, f"looks like a ROS 2 bag without its metadata.yaml (holds {', '.join(found[:3])})"
                                        f": rebuild it with 'ros2 bag reindex {path}', then try again")
            raise InputError(where, "not a ROS 2 bag directory (no metadata.yaml)")
        if not found:
            raise InputError(where, "a ROS 2 bag directory with metadata.yaml but no storage file (.db3 or .mcap)")
        return
    if path.suffix not in MAGIC:
        raise InputError(where, f"not a ROS bag: expected .bag, .mcap, .db3 or a ROS 2 bag directory, got {path.name}")
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
    kind = {".bag": "a ROS 1 bag (format 2.0)", ".mcap": "an MCAP file", ".db3": "an sqlite3 database"}[path.suffix]
    other = next((s for s, m in MAGIC.items() if head.startswith(m)), None)
    if other == ".mcap":
        hint = "; it is an MCAP file: rename it to .mcap"
    elif other == ".db3":
        hint = "; it is an sqlite3 database: rename it to .db3"
    elif head.startswith(b"#ROSBAG V"):
        hint = f"; ROS 1 bag format {head[9:12].decode(errors='replace')} is not supported (only 2.0)"
    else:
        hint = ""
    raise InputError(where, f"not {kind}: it starts with {head!r}, expected {magic!r}{hint}")


def _open_reader(path: Path):
    from rosbags.highlevel import AnyReader
    where = str(path)
    check_bag_path(path)
    try:
        reader = AnyReader([path])
        reader.open()
    except InputError:
        raise
    except Exception as err:  # rosbags raises several error types for damaged files
        problem = _one_line(err)
        if path.is_file() and path.suffix == ".bag":
            salvage = _Ros1Salvage(path)
            if salvage.message_count:
                warn_data(where, f"the bag is damaged ({problem}); read sequentially up to the damage: "
                                 f"{salvage.message_count} messages in {salvage.n_chunks} complete chunk(s), "
                                 f"{salvage.good_bytes} of {salvage.file_bytes} bytes; the rest is lost")
                salvage.damaged = problem
                return salvage
        raise InputError(where, f"cannot read the bag (truncated or corrupt?): {problem}") from None
    return reader


class _SalvageConnection:
    def __init__(self, cid: int, topic: str, msgtype: str, msgdef: str):
        self.id, self.topic, self.msgtype, self.msgdef_text = cid, topic, msgtype, msgdef


class _TopicCount:
    def __init__(self, msgtype: str):
        self.msgtype, self.msgcount = msgtype, 0


class _Ros1Salvage:
    """Sequential reader of a ROS 1 bag (v2.0) whose index is missing (e.g. recording cut off).

    Reads the complete chunks from the start of the file and stops at the first damaged or
    incomplete record. Offers the small part of the AnyReader interface the loader uses.
    """

    is2 = False

    def __init__(self, path: Path):
        import bz2
        self.path = path
        self.file_bytes = path.stat().st_size
        self.connections: list[_SalvageConnection] = []
        self._conn_by_id: dict[int, _SalvageConnection] = {}
        self._counts: dict[int, int] = {}
        self.chunks: list[tuple[int, int, str]] = []       # (data offset, size, compression)
        self.good_bytes = 0
        self.start_time, self.end_time = 2**63 - 1, 0
        self.damaged = None
        self.n_chunks = self.message_count = 0
        self._decomp = {"none": lambda b: b, "bz2": bz2.decompress}
        try:
            import lz4.frame
            self._decomp["lz4"] = lz4.frame.decompress
        except ImportError:  # pragma: no cover
            pass
        with open(path, "rb") as fh:
            if fh.read(13) != b"#ROSBAG V2.0\n":
                return
            pos = 13
            while True:
                rec = self._record(fh, pos)
                if rec is None:
                    break
                hdr, data_pos, data_len, end = rec
                op = hdr.get("op", b"\xff")[0]
                if op == 5:            # chunk
                    comp = hdr.get("compression", b"none").decode()
                    if comp not in self._decomp:
                        break
                    try:
                        fh.seek(data_pos)
                        raw = self._decomp[comp](fh.read(data_len))
                        for _ in self._scan_chunk(raw, count=True):
                            pass
                    except Exception:
                        break
                    self.chunks.append((data_pos, data_len, comp))
                elif op == 7:
                    fh.seek(data_pos)
                    self._add_connection(hdr, fh.read(data_len))
                pos = end
                self.good_bytes = end
        self.n_chunks = len(self.chunks)
        self.message_count = sum(self._counts.values())
        from rosbags.typesys import Stores, get_types_from_msg, get_typestore
        self.typestore = get_typestore(Stores.EMPTY)
        types: dict = {}
        for c in self.connections:
            try:
                types.update(get_types_from_msg(c.msgdef_text, c.msgtype))
            except Exception:
                pass
        self.typestore.register(types)

    def _record(self, fh, pos):
        fh.seek(pos)
        b = fh.read(4)
        if len(b) < 4:
            return None
        hlen = int.from_bytes(b, "little")
        hb = fh.read(hlen)
        lb = fh.read(4)
        if len(hb) < hlen or len(lb) < 4:
            return None
        try:
            hdr = self._fields(hb)
        except Exception:
            return None
        dlen = int.from_bytes(lb, "little")
        data_pos = pos + 8 + hlen
        if data_pos + dlen > self.file_bytes:
            return None
        return hdr, data_pos, dlen, data_pos + dlen

    @staticmethod
    def _fields(b: bytes) -> dict:
        out, i = {}, 0
        while i < len(b):
            n = int.from_bytes(b[i:i + 4], "little")
            if n <= 0 or i + 4 + n > len(b):
                raise ValueError("bad header field")
            key, _, val = b[i + 4:i + 4 + n].partition(b"=")
            out[key.decode()] = val
            i += 4 + n
        return out

    def _add_connection(self, hdr: dict, data: bytes):
        cid = int.from_bytes(hdr["conn"], "little")
        if cid in self._conn_by_id:
            return
        f = self._fields(data)
        topic = hdr["topic"].decode()
        typ = normalize_type(f["type"].decode())
        c = _SalvageConnection(cid, topic, typ, f.get("message_definition", b"").decode())
        self.connections.append(c)
        self._conn_by_id[cid] = c

    def _scan_chunk(self, raw: bytes, count: bool = False, wanted=None):
        i, n = 0, len(raw)
        while i + 8 <= n:
            hlen = int.from_bytes(raw[i:i + 4], "little")
            hdr = self._fields(raw[i + 4:i + 4 + hlen])
            j = i + 4 + hlen
            dlen = int.from_bytes(raw[j:j + 4], "little")
            data = raw[j + 4:j + 4 + dlen]
            i = j + 4 + dlen
            op = hdr["op"][0]
            if op == 7:
                self._add_connection(hdr, data)
            elif op == 2:
                cid = int.from_bytes(hdr["conn"], "little")
                tb = hdr["time"]
                t_ns = int.from_bytes(tb[:4], "little") * 1_000_000_000 + int.from_bytes(tb[4:8], "little")
                if count:
                    self._counts[cid] = self._counts.get(cid, 0) + 1
                    self.start_time = min(self.start_time, t_ns)
                    self.end_time = max(self.end_time, t_ns)
                elif wanted is None or cid in wanted:
                    yield self._conn_by_id[cid], t_ns, data

    @property
    def topics(self) -> dict:
        out: dict = {}
        for c in self.connections:
            tc = out.setdefault(c.topic, _TopicCount(c.msgtype))
            tc.msgcount += self._counts.get(c.id, 0)
        return out

    def messages(self, connections=()):
        wanted = {c.id for c in connections} if connections else None
        with open(self.path, "rb") as fh:
            for pos, size, comp in self.chunks:
                fh.seek(pos)
                yield from self._scan_chunk(self._decomp[comp](fh.read(size)), wanted=wanted)

    def deserialize(self, raw: bytes, typ: str):
        return self.typestore.deserialize_ros1(raw, typ)

    def close(self) -> None:
        pass


def _one_line(err: Exception) -> str:
    text = " ".join(str(a) for a in err.args) or type(err).__name__
    return " ".join(text.split())[:300]


def _get(msg, path: str):
    for part in path.split("."):
        msg = getattr(msg, part)
    return msg


def _stamp_s(stamp) -> float:
    # exact integer nanoseconds, one correctly rounded division: the float nearest the stamp
    return (int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)) / 1e9


class _Collector:
    """Per-topic accumulation of rows (time first); bounded by the data kept."""

    def __init__(self, topic: str, ncols: int):
        self.topic = topic
        self._buf = array("d")          # 8 bytes per value: no per-row Python objects kept
        self.ncols = ncols
        self.skipped_no_fix = 0
        self.zero_cov = 0
        self.total = 0

    def add(self, row) -> None:
        self._buf.extend(row)

    def __len__(self) -> int:
        return len(self._buf) // self.ncols

    def table(self) -> np.ndarray:
        return np.frombuffer(self._buf, float).reshape(-1, self.ncols).copy()


def _imu_row(msg, t):
    q, w, a = msg.orientation, msg.angular_velocity, msg.linear_acceleration
    cov = msg.orientation_covariance
    has_q = float(cov[0]) != -1.0 and (q.x or q.y or q.z or q.w)
    return (t, a.x, a.y, a.z, w.x, w.y, w.z,
            q.x if has_q else np.nan, q.y if has_q else np.nan, q.z if has_q else np.nan, q.w if has_q else np.nan,
            cov[0] if has_q else np.nan, cov[4] if has_q else np.nan, cov[8] if has_q else np.nan)


def _navsat_row(msg, t, col: _Collector, default_sigma: np.ndarray):
    if int(msg.status.status) < 0:       # STATUS_NO_FIX = -1
        col.skipped_no_fix += 1
        return None
    cov = np.asarray(msg.position_covariance, float)
    ctype = int(msg.position_covariance_type)
    if ctype == 0:
        sig = default_sigma
    else:
        diag = np.array([cov[4], cov[0], cov[8]])     # ENU diagonal -> N, E, D variances
        if not np.any(cov):
            col.zero_cov += 1
            sig = default_sigma
        else:
            sig = np.sqrt(np.where(diag > 0, diag, np.nan))
    return (t, msg.latitude, msg.longitude, msg.altitude, sig[0], sig[1], sig[2])


def _custom_fix_row(msg, t, col: _Collector, m: dict, default_sigma: np.ndarray):
    if m.get("status") and _get(msg, m["status"]) in m.get("no_fix_values", []):
        col.skipped_no_fix += 1
        return None
    if m.get("stamp"):
        t = _stamp_s(_get(msg, m["stamp"]))
    sc = float(m["latlon_scale_deg"])
    sig = []
    for k, d in zip(("sigma_n", "sigma_e", "sigma_d"), default_sigma):
        sig.append(float(_get(msg, m[k])) * float(m["sigma_scale_m"]) if m.get(k) else d)
    if all(s == 0 for s in sig):
        col.zero_cov += 1
        sig = list(default_sigma)
    sig = [s if s > 0 else np.nan for s in sig]
    return (t, float(_get(msg, m["lat"])) * sc, float(_get(msg, m["lon"])) * sc,
            float(_get(msg, m["height"])) * float(m["height_scale_m"]), *sig)


def _mapped_fix_row(msg, t, col: _Collector, m: dict, default_sigma: np.ndarray, where: str, topic: str, typ: str):
    """:func:`_custom_fix_row`, with a mapping that does not fit the message an :class:`InputError`."""
    try:
        return _custom_fix_row(msg, t, col, m, default_sigma)
    except (AttributeError, TypeError, ValueError) as err:
        raise InputError(where, f"topic {topic}: the field mapping of {typ} does not fit its messages: "
                                f"{_one_line(err)} (fields of the message: "
                                f"{', '.join(k for k in getattr(msg, '__dataclass_fields__', {}) if not k.startswith('_'))})"
                         ) from None


enu_flu_to_ned_frd = ros_to_R_nb  # name kept for callers of this module


def _pose_row(msg, t, msgtype):
    if msgtype == "geometry_msgs/msg/PoseStamped":
        pose, twist = msg.pose, None
    else:
        pose = msg.pose.pose
        twist = msg.twist.twist if msgtype == "nav_msgs/msg/Odometry" else None
    p, q = pose.position, pose.orientation
    if q.x or q.y or q.z or q.w:
        R = enu_flu_to_ned_frd(quaternion_to_dcm(q.x, q.y, q.z, q.w))
        rpy = dcm_to_euler(R)
        v = ENU_NED @ quaternion_to_dcm(q.x, q.y, q.z, q.w) @ np.array(
            [twist.linear.x, twist.linear.y, twist.linear.z]) if twist is not None else (np.nan,) * 3
    else:
        rpy, v = (np.nan,) * 3, (np.nan,) * 3
    return (t, p.y, p.x, -p.z, *v, *rpy)


def _sorted_unique(tab: np.ndarray, where: str, what: str, meta: dict, key: str) -> np.ndarray:
    """Sort rows by time (warn with the count of backward steps), drop repeated time stamps."""
    if len(tab) == 0:
        return tab
    t = tab[:, 0]
    back = int(np.sum(np.diff(t) < 0))
    if back:
        warn_data(where, f"{what}: time went backwards {back} time(s); messages sorted by time")
        tab = tab[np.argsort(t, kind="stable")]
        t = tab[:, 0]
    same = np.flatnonzero(np.diff(t) == 0) + 1
    exact = conflicting = 0
    if same.size:
        eq = np.array([np.array_equal(tab[k], tab[k - 1], equal_nan=True) for k in same])
        exact, conflicting = int(eq.sum()), int((~eq).sum())
        keep = np.ones(len(tab), bool)
        keep[same] = False
        tab = tab[keep]
        parts = []
        if exact:
            parts.append(f"{exact} exact duplicate message(s)")
        if conflicting:
            parts.append(f"{conflicting} message(s) repeating a time stamp with different data (first kept)")
        warn_data(where, f"{what}: dropped " + " and ".join(parts))
    meta.setdefault("time_fixes", {})[key] = {"backwards_steps": back, "exact_duplicates": exact,
                                              "conflicting_duplicates": conflicting}
    return tab


def _gaps(t: np.ndarray, factor: float) -> dict:
    if len(t) < 3:
        return {"count": 0, "spans": []}
    d = np.diff(t)
    med = float(np.median(d))
    idx = np.flatnonzero(d > factor * med)
    return {"nominal_dt_s": med, "count": int(idx.size),
            "spans": [[float(t[k]), float(d[k])] for k in idx[:20]]}


def _tf_mounting(reader, imu_frame_id: str, where: str):
    """R_bi (FRD) from a /tf_static transform base_link|base_footprint -> imu frame, or None."""
    conns = [c for c in reader.connections if c.msgtype == TF_TYPE and c.topic in ("/tf_static", "tf_static")]
    if not conns or not imu_frame_id:
        return None
    child = imu_frame_id.lstrip("/")
    for conn, _, raw in reader.messages(connections=conns):
        msg = reader.deserialize(raw, conn.msgtype)
        for tr in msg.transforms:
            parent = tr.header.frame_id.lstrip("/")
            if tr.child_frame_id.lstrip("/") == child and parent in BASE_FRAMES:
                q = tr.transform.rotation
                R_flu = quaternion_to_dcm(q.x, q.y, q.z, q.w)           # p_parent = R @ p_child
                return FLU_FRD @ R_flu @ FLU_FRD, f"/tf_static {parent} -> {child}"
    return None


def load_bag_run(path, cfg: RunConfig, *, imu_topic: str | None = None, gnss_topic: str | None = None,
                 truth_topic: str | None = None, time_source: str = "header",
                 gnss_from_truth_hz: float | None = None, noise: str | None = None, seed: int = 0,
                 fix_mappings: dict | None = None, truth_origin_llh_deg=None) -> RecordedRun:
    """Load a ROS 1 / ROS 2 bag as a :class:`RecordedRun`.

    Parameters
    ----------
    path : str or Path
        A ``.bag`` file, a ROS 2 bag directory (sqlite3 or MCAP storage) or a bare ``.mcap``.
    cfg : RunConfig
        Uses ``[mounting]``, ``gnss.default_sigma_m`` and ``data.max_bad_fraction``.
    imu_topic, gnss_topic, truth_topic : str, optional
        Topic choices; by default picked by :func:`select_topics`.
    time_source : {"header", "receive"}
        Header stamps (receive time for header-less types) or bag receive times.
    gnss_from_truth_hz : float, optional
        Make the estimators' GNSS from the truth fix topic, subsampled at this rate [Hz], with
        the noise profile ``noise`` (default ``white``) and ``seed``; the truth stays the truth.
    noise : str, optional
        With ``gnss_from_truth_hz`` only.
    seed : int
    fix_mappings : dict, optional
        Extra or replacement field mappings of custom fix types (see :data:`FIX_MAPPINGS`).
    truth_origin_llh_deg : (lat, lon, h), optional
        Origin of the ENU frame of pose/odometry truth; default: the first GNSS fix.

    Returns
    -------
    RecordedRun
        Validated; ``name`` the file stem, ``where`` the path, ``origin`` at the first fix.
        ``init`` is set when the IMU messages carry a valid orientation (REP-145).
    """
    path = Path(path)
    where = str(path)
    if time_source not in TIME_SOURCES:
        raise InputError(where, f"time_source must be one of {', '.join(TIME_SOURCES)}, got {time_source!r}")
    if noise is not None and gnss_from_truth_hz is None:
        raise InputError(where, "--noise on a bag needs --gnss-from-truth RATE_HZ (without it the bag's own "
                                "fixes are used as they are)")
    if gnss_from_truth_hz is not None and not float(gnss_from_truth_hz) > 0:
        raise InputError(where, f"--gnss-from-truth must be a positive rate in Hz, got {gnss_from_truth_hz}")
    mappings = _mappings(cfg["bag"]["fix_mappings"] if fix_mappings is None else fix_mappings)
    default_sigma = vec3(cfg["gnss"]["default_sigma_m"], "gnss.default_sigma_m", "config")
    max_bad = float(cfg["data"]["max_bad_fraction"])
    meta: dict = {"source": "bag", "time_source": time_source}

    reader = _open_reader(path)
    try:
        meta["bag_format"] = "ros2" if reader.is2 else "ros1"
        if getattr(reader, "damaged", None):
            meta["damaged"] = f"{reader.damaged}; salvaged {reader.good_bytes} of {reader.file_bytes} bytes"
        stats = _survey(reader)
        sel = select_topics(stats, where, imu_topic=imu_topic, gnss_topic=gnss_topic, truth_topic=truth_topic,
                            gnss_from_truth=gnss_from_truth_hz is not None, mappings=mappings)
        meta["topics"] = {"imu": sel.imu.topic, "gnss": sel.gnss.topic if sel.gnss else None,
                          "truth": sel.truth.topic if sel.truth else None}
        meta["selection"] = sel.reasons
        wanted = {s.topic: s for s in (sel.imu, sel.gnss, sel.truth) if s is not None}
        conns = [c for c in reader.connections if c.topic in wanted]
        cols = {sel.imu.topic: _Collector(sel.imu.topic, 14)}
        for s in (sel.gnss, sel.truth):
            if s is not None:
                cols[s.topic] = _Collector(s.topic, 7 if s.msgtype not in POSE_TYPES else 10)
        imu_frame_id = ""
        damaged = None
        it = reader.messages(connections=conns)
        while True:
            try:
                conn, t_recv_ns, raw = next(it)
            except StopIteration:
                break
            except Exception as err:
                damaged = _one_line(err)
                break
            topic, typ = conn.topic, conn.msgtype
            col = cols[topic]
            col.total += 1
            try:
                msg = reader.deserialize(raw, typ)
            except Exception as err:
                raise InputError(where, f"topic {topic}: cannot decode a {typ} message: {_one_line(err)}") from None
            t = t_recv_ns / 1e9
            if time_source == "header" and hasattr(msg, "header"):
                t = _stamp_s(msg.header.stamp)
            if typ == IMU_TYPE:
                if not imu_frame_id:
                    imu_frame_id = msg.header.frame_id
                col.add(_imu_row(msg, t))
            elif typ == NAVSATFIX_TYPE:
                row = _navsat_row(msg, t, col, default_sigma)
                if row is not None:
                    col.add(row)
            elif typ in POSE_TYPES:
                col.add(_pose_row(msg, t, typ))
            else:
                m = dict(mappings[typ])
                if time_source == "receive":
                    m["stamp"] = None
                row = _mapped_fix_row(msg, t, col, m, default_sigma, where, topic, typ)
                if row is not None:
                    col.add(row)
        if damaged is not None:
            if not any(len(c) for c in cols.values()):
                raise InputError(where, f"cannot read the bag (truncated or corrupt?): {damaged}")
            warn_data(where, f"the bag is damaged ({damaged}); using the {sum(len(c) for c in cols.values())} "
                             f"messages read before the damage")
            meta["damaged"] = damaged
        tf = None
        if not np.any(vec3(cfg["mounting"]["imu_to_body_rpy_deg"], "imu_to_body_rpy_deg", "config")):
            try:
                tf = _tf_mounting(reader, imu_frame_id, where)
            except Exception as err:
                warn_data(where, f"/tf_static could not be read ({_one_line(err)}); IMU mounting from the config")
    finally:
        reader.close()

    # IMU
    icol = cols[sel.imu.topic]
    itab = icol.table()
    what_imu = f"IMU topic {sel.imu.topic}"
    if len(itab) == 0:
        raise InputError(where, f"{what_imu}: no messages")
    finite = np.all(np.isfinite(itab[:, :7]), axis=1)
    if not finite.all():
        drop_nonfinite(itab[:, :7], where, what_imu, max_bad)      # warns with the count, or raises
        itab = itab[finite]
    itab = _sorted_unique(itab, where, what_imu, meta, "imu")
    good_q = np.isfinite(itab[:, 7:11]).all(axis=1)
    if len(itab) < 2:
        raise InputError(where, f"{what_imu}: {len(itab)} usable message(s), need at least two")
    f_imu = itab[:, 1:4] @ FLU_FRD          # FLU -> FRD (diagonal: same as T @ x per row)
    w_imu = itab[:, 4:7] @ FLU_FRD
    if tf is not None:
        R_bi_tf, what_tf = tf
        f_imu, w_imu = f_imu @ R_bi_tf.T, w_imu @ R_bi_tf.T
        r, p, y = dcm_to_euler(R_bi_tf)
        meta["imu_mounting"] = {"from": what_tf, "imu_to_body_rpy_deg": [float(np.degrees(a)) for a in (r, p, y)]}
        R_bi_total = cfg.R_bi @ R_bi_tf
    else:
        meta["imu_mounting"] = {"from": "config [mounting] imu_to_body_rpy_deg",
                                "imu_to_body_rpy_deg": [float(v) for v in
                                                        vec3(cfg["mounting"]["imu_to_body_rpy_deg"], "m", "config")]}
        R_bi_total = cfg.R_bi
    imu = apply_mounting(ImuData(itab[:, 0].copy(), f_imu, w_imu), cfg)
    meta["gaps"] = {"imu": _gaps(imu.t, 5.0)}

    # truth
    truth = None
    origin = None
    if sel.truth is not None and sel.truth_kind == "fix":
        truth_fix = _fix_table(cols[sel.truth.topic], where, "truth", max_bad, meta, "truth")
        truth = Truth(truth_fix[:, 0], truth_fix[:, 1] * DEG, truth_fix[:, 2] * DEG, truth_fix[:, 3])
    # GNSS
    if sel.gnss is not None:
        g = _fix_table(cols[sel.gnss.topic], where, "GNSS", max_bad, meta, "gnss")
        gnss = GnssFixes(g[:, 0], g[:, 1] * DEG, g[:, 2] * DEG, g[:, 3], g[:, 4:7])
        origin = LocalTangentFrame(gnss.lat[0], gnss.lon[0], gnss.h[0])
    else:
        from ..gnss_noise import fixes_from_truth
        origin = LocalTangentFrame(truth.lat[0], truth.lon[0], truth.h[0])
        sub = _subsample(truth.t, float(gnss_from_truth_hz))
        sub_truth = Truth(truth.t[sub], truth.lat[sub], truth.lon[sub], truth.h[sub])
        holder = RecordedRun("tmp", where, imu, GnssFixes(*(np.empty(0),) * 4, np.empty((0, 3))), origin)
        gnss = fixes_from_truth(holder, sub_truth, noise or "white", seed)
        meta.update(gnss_from_truth_hz=float(gnss_from_truth_hz), noise=noise or "white", seed=seed)
    meta["gaps"]["gnss"] = _gaps(gnss.t, 3.0)
    if sel.truth is not None and sel.truth_kind == "pose":
        ptab = cols[sel.truth.topic].table()
        what_t = f"truth topic {sel.truth.topic}"
        if len(ptab) == 0:
            raise InputError(where, f"{what_t}: no messages")
        keep = np.all(np.isfinite(ptab[:, :4]), axis=1)
        if not keep.all():
            drop_nonfinite(ptab[:, :4], where, what_t, max_bad)
        ptab = _sorted_unique(ptab[keep], where, what_t, meta, "truth")
        if truth_origin_llh_deg is not None:
            lat0, lon0, h0 = (float(v) for v in truth_origin_llh_deg)
            porigin = LocalTangentFrame(lat0 * DEG, lon0 * DEG, h0)
            meta["truth_origin"] = f"given: {lat0}, {lon0} deg, {h0} m"
        else:
            porigin = origin
            meta["truth_origin"] = "assumed: the pose frame is ENU with origin at the first GNSS fix"
        lat, lon, h = porigin.to_llh(ptab[:, 1:4])
        v_n = ptab[:, 4:7] if np.all(np.isfinite(ptab[:, 4:7])) else None
        rpy = ptab[:, 7:10] if np.all(np.isfinite(ptab[:, 7:10])) else None
        truth = Truth(ptab[:, 0], lat, lon, h, v_n, rpy)

    init = None
    if good_q.any():
        init = _initial_state(itab, good_q, imu, gnss, R_bi_total, cfg, sel.imu.topic)

    run = RecordedRun(name=path.stem if path.is_file() else path.name, where=where, imu=imu, gnss=gnss,
                      origin=origin, truth=truth, init=init, meta=meta)
    return run.validate()


def _subsample(t: np.ndarray, rate: float) -> np.ndarray:
    """Indices of the first sample in each 1/rate bin from t[0]."""
    bins = np.floor((t - t[0]) * rate + 1e-9).astype(np.int64)
    return np.flatnonzero(np.r_[True, np.diff(bins) > 0])


def _fix_table(col: _Collector, where: str, what: str, max_bad: float, meta: dict, key: str) -> np.ndarray:
    label = f"{what} topic {col.topic}"
    tab = col.table()
    if col.skipped_no_fix:
        if len(tab) == 0:
            raise InputError(where, f"{label}: all {col.skipped_no_fix} messages are NO_FIX (status -1); no usable fix")
        warn_data(where, f"{label}: skipped {col.skipped_no_fix} NO_FIX message(s)")
    if col.zero_cov:
        warn_data(where, f"{label}: {col.zero_cov} message(s) with an all-zero covariance; "
                         f"used gnss.default_sigma_m instead")
    meta.setdefault("fix_counts", {})[key] = {"messages": col.total, "no_fix": col.skipped_no_fix,
                                              "zero_covariance": col.zero_cov}
    if len(tab) == 0:
        raise InputError(where, f"{label}: no messages")
    tab = drop_nonfinite(tab, where, label, max_bad)
    if len(tab) == 0:
        raise InputError(where, f"{label}: no usable fix")
    tab = _sorted_unique(tab, where, label, meta, key)
    check_degrees(tab[:, 1], tab[:, 2], tab[:, 0], where, label)
    return tab


def _initial_state(itab, good_q, imu: ImuData, gnss: GnssFixes, R_bi: np.ndarray, cfg: RunConfig,
                   topic: str) -> InitialState | None:
    """Initial state from the IMU orientation and the first GNSS fixes."""
    inside = np.flatnonzero((gnss.t >= imu.t[0]) & (gnss.t <= imu.t[-1]))
    if inside.size == 0:
        return None
    k0 = int(inside[0])
    t0 = float(gnss.t[k0])
    qi = np.flatnonzero(good_q)
    j = int(qi[np.argmin(np.abs(imu.t[qi] - t0))])
    q = itab[j, 7:11]
    R_n_imu = enu_flu_to_ned_frd(quaternion_to_dcm(*q))
    R_nb = R_n_imu @ R_bi.T
    rpy = np.array(dcm_to_euler(R_nb))
    cov = itab[j, 11:14]       # roll, pitch, yaw variances of the IMU orientation (FLU axes)
    sig_att = np.array([INIT_SIGMA_ROLL_PITCH_DEG, INIT_SIGMA_ROLL_PITCH_DEG, INIT_SIGMA_YAW_DEG]) * DEG
    if np.all(np.isfinite(cov)) and np.all(cov > 0):
        sig_att = np.sqrt(cov)
    # velocity: straight-line fit over the fixes in [t0, t0 + 3 s]
    origin = LocalTangentFrame(gnss.lat[k0], gnss.lon[k0], gnss.h[k0])
    win = np.flatnonzero((gnss.t >= t0) & (gnss.t <= t0 + INIT_VEL_FIT_S))
    sig_p = gnss.sigma_ned[k0].copy()
    if win.size >= 2:
        p = origin.to_ned(gnss.lat[win], gnss.lon[win], gnss.h[win])
        dt = gnss.t[win] - t0
        A = np.column_stack([np.ones_like(dt), dt])
        coef, *_ = np.linalg.lstsq(A, p, rcond=None)
        v_n = coef[1]
        span = max(float(dt[-1]), 1e-3)
        # slope sigma of a line fit (~sigma_p * sqrt(12 / n) / span) plus 0.3 m/s for acceleration in the window
        sig_v = np.sqrt((gnss.sigma_ned[win].mean(axis=0) * np.sqrt(12.0 / win.size) / span) ** 2 + 0.3 ** 2)
        how_v = f"velocity fitted to {win.size} fixes over {span:.1f} s"
    else:
        v_n = np.zeros(3)
        sig_v = np.full(3, 5.0)
        how_v = "velocity unknown (one fix): 0 +- 5 m/s"
    return InitialState(t=t0, lat=float(gnss.lat[k0]), lon=float(gnss.lon[k0]), h=float(gnss.h[k0]), v_n=v_n,
                        rpy=rpy, sigma_pos_m=sig_p, sigma_vel_mps=sig_v, sigma_att_rad=sig_att,
                        how=f"attitude from the orientation on {topic}, position from the first fix, {how_v}")


# --- inspection -------------------------------------------------------------------------------------

def inspect_bag(path, *, imu_topic=None, gnss_topic=None, truth_topic=None, fix_mappings=None) -> str:
    """A text summary of a bag: topics, types, counts, rates, time span, and the topics gnssacc would use."""
    path = Path(path)
    where = str(path)
    reader = _open_reader(path)
    try:
        stats = _survey(reader)
        span = (reader.end_time - reader.start_time) * 1e-9 if reader.message_count else 0.0
        start = reader.start_time * 1e-9 if reader.message_count else 0.0
        kind = "ROS 2" if reader.is2 else "ROS 1"
    finally:
        reader.close()
    lines = [f"{where}: {kind} bag, {sum(s.count for s in stats)} messages, {span:.2f} s "
             f"(from {start:.3f} s receive time)", ""]
    w = max([len(s.topic) for s in stats] + [5])
    wt = max([len(s.msgtype) for s in stats] + [4])
    lines.append(f"  {'topic':<{w}}  {'type':<{wt}}  {'count':>8}  {'~rate Hz':>9}")
    for s in stats:
        lines.append(f"  {s.topic:<{w}}  {s.msgtype:<{wt}}  {s.count:>8}  {s.rate_hz:>9.2f}")
    lines.append("")
    try:
        sel = select_topics(stats, where, imu_topic=imu_topic, gnss_topic=gnss_topic, truth_topic=truth_topic,
                            mappings=_mappings(fix_mappings))
        lines.append("gnssacc would use:")
        lines += [f"  {r}" for r in sel.reasons]
    except InputError as err:
        lines.append(f"gnssacc cannot pick the topics: {err.problem}")
    return "\n".join(lines)
