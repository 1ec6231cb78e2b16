"""Reading what is left of a damaged ROS 1 bag (format 2.0): the complete chunks before the damage.

A recording that was cut off (power loss, full disk) has no index at its end, and
:class:`rosbags.highlevel.AnyReader` refuses it. :class:`Ros1Salvage` walks the records from the
start of the file instead, keeps every chunk that decompresses and parses, and stops at the first
damaged or incomplete record. It offers the part of the AnyReader interface the bag loader uses
(``connections``, ``topics``, ``messages``, ``deserialize``, ``start_time``, ``end_time``,
``message_count``, ``is2``, ``close``), with the message definitions taken from the bag.

Record layout (ROS 1 bag format 2.0): ``<header_len: u32><header: fields><data_len: u32><data>``,
a header field being ``<len: u32><name>=<value>``; ``op`` 5 is a chunk, 7 a connection, 2 a message.
"""

from __future__ import annotations

import bz2
from pathlib import Path

from .bag_decode import normalize_type

ROS1_MAGIC = b"#ROSBAG V2.0\n"
OP_MESSAGE, OP_CHUNK, OP_CONNECTION = 2, 5, 7


class _SalvageConnection:
    def __init__(self, cid: int, topic: str, msgtype: str, msgdef: str):
        self.id, self.topic, self.msgtype, self.msgdef_text = cid, topic, msgtype, msgdef


class _TopicCount:
    def __init__(self, msgtype: str):
        self.msgtype, self.msgcount = msgtype, 0


def _fields(b: bytes) -> dict:
    """The ``name=value`` fields of a record header."""
    out, i = {}, 0
    while i < len(b):
        n = int.from_bytes(b[i : i + 4], "little")
        if n <= 0 or i + 4 + n > len(b):
            raise ValueError("bad header field")
        key, _, val = b[i + 4 : i + 4 + n].partition(b"=")
        out[key.decode()] = val
        i += 4 + n
    return out


class Ros1Salvage:
    """Sequential reader of a ROS 1 bag (v2.0) whose index is missing (e.g. recording cut off).

    Parameters
    ----------
    path : Path
        The ``.bag`` file.

    Attributes
    ----------
    message_count, n_chunks : int
        Messages and complete chunks found before the damage (0 when nothing is usable).
    good_bytes, file_bytes : int
        End of the last complete record, and the file size [bytes].
    start_time, end_time : int
        First and last receive time [ns].
    damaged : str or None
        Set by the caller to what made the normal reader fail.
    """

    is2 = False

    def __init__(self, path: Path):
        self.path = path
        self.file_bytes = path.stat().st_size
        self.connections: list[_SalvageConnection] = []
        self._conn_by_id: dict[int, _SalvageConnection] = {}
        self._counts: dict[int, int] = {}
        self.chunks: list[tuple[int, int, str]] = []  # (data offset, size, compression)
        self.good_bytes = 0
        self.start_time, self.end_time = 2**63 - 1, 0
        self.damaged = None
        self._decomp = {"none": lambda b: b, "bz2": bz2.decompress}
        try:
            import lz4.frame

            self._decomp["lz4"] = lz4.frame.decompress
        except ImportError:  # pragma: no cover
            pass
        with open(path, "rb") as fh:
            if fh.read(13) == ROS1_MAGIC:
                self._walk(fh)
        self.n_chunks = len(self.chunks)
        self.message_count = sum(self._counts.values())
        self.typestore = self._typestore()

    def _walk(self, fh) -> None:
        """Record by record from the magic on, up to the first one that is incomplete or corrupt."""
        pos = len(ROS1_MAGIC)
        while True:
            rec = self._record(fh, pos)
            if rec is None:
                return
            hdr, data_pos, data_len, end = rec
            op = hdr.get("op", b"\xff")[0]
            if op == OP_CHUNK:
                comp = hdr.get("compression", b"none").decode()
                if comp not in self._decomp:
                    return
                try:
                    fh.seek(data_pos)
                    raw = self._decomp[comp](fh.read(data_len))
                    for _ in self._scan_chunk(raw, count=True):
                        pass
                except Exception:
                    return
                self.chunks.append((data_pos, data_len, comp))
            elif op == OP_CONNECTION:
                fh.seek(data_pos)
                self._add_connection(hdr, fh.read(data_len))
            pos = end
            self.good_bytes = end

    def _typestore(self):
        """A typestore with the message definitions stored in the bag's connections."""
        from rosbags.typesys import Stores, get_types_from_msg, get_typestore

        typestore = get_typestore(Stores.EMPTY)
        types: dict = {}
        for c in self.connections:
            try:
                types.update(get_types_from_msg(c.msgdef_text, c.msgtype))
            except Exception:
                pass
        typestore.register(types)
        return typestore

    def _record(self, fh, pos):
        """(header fields, data offset, data length, end offset) of the record at ``pos``, or None."""
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
            hdr = _fields(hb)
        except Exception:
            return None
        dlen = int.from_bytes(lb, "little")
        data_pos = pos + 8 + hlen
        if data_pos + dlen > self.file_bytes:
            return None
        return hdr, data_pos, dlen, data_pos + dlen

    def _add_connection(self, hdr: dict, data: bytes):
        cid = int.from_bytes(hdr["conn"], "little")
        if cid in self._conn_by_id:
            return
        f = _fields(data)
        topic = hdr["topic"].decode()
        typ = normalize_type(f["type"].decode())
        c = _SalvageConnection(cid, topic, typ, f.get("message_definition", b"").decode())
        self.connections.append(c)
        self._conn_by_id[cid] = c

    def _scan_chunk(self, raw: bytes, count: bool = False, wanted=None):
        """Messages of a decompressed chunk as (connection, receive time [ns], bytes); with
        ``count``, only count them (and their time span) and yield nothing."""
        i, n = 0, len(raw)
        while i + 8 <= n:
            hlen = int.from_bytes(raw[i : i + 4], "little")
            hdr = _fields(raw[i + 4 : i + 4 + hlen])
            j = i + 4 + hlen
            dlen = int.from_bytes(raw[j : j + 4], "little")
            data = raw[j + 4 : j + 4 + dlen]
            i = j + 4 + dlen
            op = hdr["op"][0]
            if op == OP_CONNECTION:
                self._add_connection(hdr, data)
            elif op == OP_MESSAGE:
                cid = int.from_bytes(hdr["conn"], "little")
                tb = hdr["time"]
                t_ns = int.from_bytes(tb[:4], "little") * 1_000_000_000 + int.from_bytes(
                    tb[4:8], "little"
                )
                if count:
                    self._counts[cid] = self._counts.get(cid, 0) + 1
                    self.start_time = min(self.start_time, t_ns)
                    self.end_time = max(self.end_time, t_ns)
                elif wanted is None or cid in wanted:
                    yield self._conn_by_id[cid], t_ns, data

    @property
    def topics(self) -> dict:
        """Topic -> object with ``msgtype`` and ``msgcount`` (as AnyReader's)."""
        out: dict = {}
        for c in self.connections:
            tc = out.setdefault(c.topic, _TopicCount(c.msgtype))
            tc.msgcount += self._counts.get(c.id, 0)
        return out

    def messages(self, connections=()):
        """(connection, receive time [ns], raw bytes) of the given connections (all by default)."""
        wanted = {c.id for c in connections} if connections else None
        with open(self.path, "rb") as fh:
            for pos, size, comp in self.chunks:
                fh.seek(pos)
                yield from self._scan_chunk(self._decomp[comp](fh.read(size)), wanted=wanted)

    def deserialize(self, raw: bytes, typ: str):
        """A message object from its ROS 1 serialisation."""
        return self.typestore.deserialize_ros1(raw, typ)

    def close(self) -> None:
        pass
