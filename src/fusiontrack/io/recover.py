"""Recovering the messages of a damaged recording: what ``rosbag reindex`` and ``mcap recover`` do.

A recording cut off (the robot's battery died, the disk filled up) has no index at its end, so
:class:`~fusiontrack.io.recording.Recording` cannot open it, yet every message written before the cut
is still in the file. :func:`repair_recording` reads the records one after the other from the start
and writes every complete message into a new recording that opens:

* a ROS 1 bag (format 2.0): bag header, chunks (none / bz2 / lz4), connection records, message data.
  The output is a ``.bag`` with the original types, definitions, md5sums and chunk compression.
* an MCAP file (or a rosbag2 folder of them): schemas, channels, messages, chunks (none / zstd / lz4).
  The output is a rosbag2 folder (MCAP) with the original schemas, QoS and the folder's custom data.

Reading stops cleanly at the first record that is incomplete or corrupt; a chunk cut off by the end
of the file still gives the messages of its complete part. A closed ROS 1 bag repeats its connection
records in its index: there a damaged record inside a chunk is passed over (a connection is known from its
copy, a damaged message is lost alone) and reading goes on. Record layouts:
http://wiki.ros.org/Bags/Format/2.0 and https://mcap.dev/spec.
"""

from __future__ import annotations

import bz2
import logging
import shutil
import struct
import zlib
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, BinaryIO, Literal

import lz4.frame
from rosbags.rosbag1 import Writer as Ros1Writer
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Ros2Writer
from rosbags.typesys import Stores, get_types_from_idl, get_types_from_msg, get_typestore
from rosbags.typesys.msg import normalize_msgtype

from ..errors import ConfigError, FusiontrackError, RecordingError

try:  # Python 3.14
    from compression import zstd  # type: ignore[import-not-found]
except ImportError:  # rosbags depends on the backport
    from backports import zstd  # type: ignore[no-redef]

log = logging.getLogger(__name__)

ROS1_MAGIC = b"#ROSBAG V2.0\n"
MCAP_MAGIC = b"\x89MCAP0\r\n"
_MAX_ROS1_HEADER = 1 << 20  # a record header holds a few short fields; definitions are in the data part

RecordingKind = Literal["ros1", "mcap"]


def recording_kind(path: str | Path) -> RecordingKind | None:
    """``"ros1"`` or ``"mcap"`` from a file's first bytes (an MCAP folder: from its ``.mcap`` files), else None."""
    path = Path(path)
    try:
        if path.is_dir():
            files = _mcap_files(path)
            with files[0].open("rb") as f:
                return "mcap" if f.read(len(MCAP_MAGIC)) == MCAP_MAGIC else None
        with path.open("rb") as f:
            head = f.read(len(ROS1_MAGIC))
    except (OSError, IndexError):
        return None
    return "ros1" if head == ROS1_MAGIC else "mcap" if head.startswith(MCAP_MAGIC) else None


# --------------------------------------------------------------------------------------------------
# What a scan found
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Ros1Connection:
    """A ROS 1 connection record's content (what a writer needs to write its messages again)."""

    topic: str
    msgtype: str  # as in the bag, e.g. sensor_msgs/LaserScan
    md5sum: str
    msgdef: str
    callerid: str | None
    latching: int | None


@dataclass(frozen=True, slots=True)
class McapChannel:
    """An MCAP channel with its schema."""

    topic: str
    msgtype: str  # the schema's name, e.g. sensor_msgs/msg/LaserScan
    schema_encoding: str  # ros2msg, ros2idl (or another profile's)
    msgdef: str
    message_encoding: str  # cdr for ROS 2
    qos: str  # the channel's offered_qos_profiles (YAML), "" if none


@dataclass(slots=True)
class ScanEnd:
    """Where and why a scan stopped: at the end of the data (``complete``) or at a damaged record."""

    file: Path
    size: int = 0
    offset: int = 0
    reason: str = "not read"
    complete: bool = False
    compression: str = "none"  # the chunks' compression (ROS 1), kept in the output
    # (ROS 1) damaged records inside the chunks of a closed bag, passed over (the bag's index has the connections):
    # their offsets (the chunk's for a compressed chunk)
    damaged: list[int] = field(default_factory=list)


class _Stop(Exception):
    """The record at ``offset`` cannot be read: the scan ends there."""

    def __init__(self, offset: int, reason: str) -> None:
        super().__init__(reason)
        self.offset = offset
        self.reason = reason


class _Short(_Stop):
    """A record inside a chunk runs past the chunk's (decompressed) data."""

    def __init__(self, offset: int) -> None:
        super().__init__(offset, "a record runs past the end of its chunk (corrupt)")


def _chunk(records: Iterator[Any], cut: bool, end_offset: int, chunk_pos: int, present: int,
           total: int) -> Iterator[Any]:
    """The messages of a chunk's records; a chunk cut off by the end of the file ends in a _Stop that
    says so, at the first record it does not hold whole."""
    try:
        yield from records
    except _Short as short:
        if not cut:
            raise
        end_offset = short.offset
    if cut:
        raise _Stop(end_offset, f"the file ends inside the chunk at byte {chunk_pos} ({present} of its {total} "
                                "bytes; their messages were read): truncated")


def _read(f: BinaryIO, n: int, offset: int, what: str) -> bytes:
    data = f.read(n)
    if len(data) < n:
        raise _Stop(offset, f"the file ends inside {what} (truncated)")
    return data


def _partial(data: bytes, compression: str) -> bytes:
    """What decompresses from the start of a cut-off compressed block (b"" where nothing does)."""
    try:
        if compression in ("", "none"):
            return data
        if compression == "lz4":
            return lz4.frame.LZ4FrameDecompressor().decompress(data)
        if compression == "bz2":
            return bz2.BZ2Decompressor().decompress(data)
        if compression == "zstd":
            return zstd.ZstdDecompressor().decompress(data)
    except Exception:  # corrupt as well as cut: nothing from it is trusted
        return b""
    return b""


def _decompress(data: bytes, compression: str) -> bytes:
    if compression in ("", "none"):
        return data
    if compression == "lz4":
        return lz4.frame.decompress(data)
    if compression == "bz2":
        return bz2.decompress(data)
    if compression == "zstd":
        return zstd.decompress(data)
    raise ValueError(f"unknown compression {compression!r}")


# --------------------------------------------------------------------------------------------------
# ROS 1 bag, format 2.0
# --------------------------------------------------------------------------------------------------

_OP_MSGDATA, _OP_BAGHEADER, _OP_IDXDATA, _OP_CHUNK, _OP_CHUNKINFO, _OP_CONNECTION = 2, 3, 4, 5, 6, 7


def _ros1_fields(blob: bytes, offset: int) -> dict[str, bytes]:
    """The ``name=value`` fields of a ROS 1 record header (or of a connection record's data)."""
    fields: dict[str, bytes] = {}
    pos = 0
    while pos < len(blob):
        if pos + 4 > len(blob):
            raise _Stop(offset, "a record header field is cut short (corrupt)")
        (size,) = struct.unpack_from("<I", blob, pos)
        pos += 4
        name, sep, value = blob[pos:pos + size].partition(b"=")
        if not sep or pos + size > len(blob):
            raise _Stop(offset, "a record header field cannot be parsed (corrupt)")
        fields[name.decode("latin-1")] = value
        pos += size
    return fields


def _u32(fields: dict[str, bytes], name: str, offset: int) -> int:
    try:
        return int(struct.unpack("<I", fields[name])[0])
    except (KeyError, struct.error):
        raise _Stop(offset, f"record without a valid {name!r} field (corrupt)") from None


def _ros1_record(f: BinaryIO, offset: int, remaining: int) -> tuple[dict[str, bytes], int]:
    """Read a record's header; returns its fields and the length of its data part (not read yet)."""
    (hlen,) = struct.unpack("<I", _read(f, 4, offset, "a record's header length"))
    if hlen > _MAX_ROS1_HEADER:
        raise _Stop(offset, f"record header of {hlen} bytes (corrupt)")
    fields = _ros1_fields(_read(f, hlen, offset, "a record header"), offset)
    if "op" not in fields or len(fields["op"]) != 1:
        raise _Stop(offset, "record without an op code (corrupt)")
    (dlen,) = struct.unpack("<I", _read(f, 4, offset, "a record's data length"))
    if fields["op"][0] != _OP_CHUNK and 4 + hlen + 4 + dlen > remaining:
        raise _Stop(offset, f"the file ends inside a record of {4 + hlen + 4 + dlen} bytes (truncated)")
    return fields, dlen


def _ros1_connection(fields: dict[str, bytes], data: bytes, offset: int) -> tuple[int, Ros1Connection]:
    conn_id = _u32(fields, "conn", offset)
    info = _ros1_fields(data, offset)
    try:
        latching = info.get("latching", b"").decode()
        conn = Ros1Connection(
            topic=fields["topic"].decode(), msgtype=info["type"].decode(), md5sum=info["md5sum"].decode(),
            msgdef=info["message_definition"].decode(),
            callerid=info["callerid"].decode() if "callerid" in info else None,
            latching=int(latching) if latching else None)
    except (KeyError, ValueError):
        raise _Stop(offset, "connection record without a topic, type, md5sum or definition (corrupt)") from None
    return conn_id, conn


def _ros1_message(fields: dict[str, bytes], body: bytes, connections: dict[int, Ros1Connection],
                  offset: int, copies: dict[int, Ros1Connection] | None = None) -> tuple[Ros1Connection, int, bytes]:
    conn_id = _u32(fields, "conn", offset)
    conn = connections.get(conn_id) or (copies or {}).get(conn_id)  # (its record damaged: the index's copy)
    if conn is None or len(fields.get("time", b"")) != 8:
        raise _Stop(offset, f"message of unknown connection {conn_id} or without a time (corrupt)")
    sec, nsec = struct.unpack("<II", fields["time"])
    return conn, sec * 1_000_000_000 + nsec, body


def _ros1_chunk_records(
    data: bytes, connections: dict[int, Ros1Connection], where: Callable[[int], int],
    copies: dict[int, Ros1Connection] | None = None, damaged: list[int] | None = None,
) -> Iterator[tuple[Ros1Connection, int, bytes]]:
    """Connection and message records inside a chunk's (uncompressed) data; ``where`` maps an offset
    inside the data to the file offset reported when a record there is damaged.

    With ``copies`` (the connection records of the bag's index: a closed bag), a record whose lengths hold but
    whose content does not read is passed over and its offset added to ``damaged``: a connection is then known
    from its copy, a damaged message is lost alone. Without them reading stops at it."""
    pos = 0
    while pos < len(data):
        off = where(pos)
        if pos + 4 > len(data):
            raise _Short(off)
        (hlen,) = struct.unpack_from("<I", data, pos)
        if hlen > _MAX_ROS1_HEADER:
            raise _Stop(off, f"record header of {hlen} bytes inside the chunk (corrupt)")
        if pos + 4 + hlen + 4 > len(data):
            raise _Short(off)
        (dlen,) = struct.unpack_from("<I", data, pos + 4 + hlen)
        start = pos + 8 + hlen
        if start + dlen > len(data):
            raise _Short(off)
        body = data[start:start + dlen]
        message = None
        try:
            fields = _ros1_fields(data[pos + 4:pos + 4 + hlen], off)
            op = fields.get("op", b"\0")[0]
            if op == _OP_CONNECTION:
                conn_id, conn = _ros1_connection(fields, body, off)
                connections[conn_id] = conn
            elif op == _OP_MSGDATA:
                message = _ros1_message(fields, body, connections, off, copies)
            else:
                raise _Stop(off, f"record of op {op} inside a chunk (corrupt)")
        except _Stop as stop:
            if not copies:
                raise
            if damaged is not None:
                damaged.append(off)
            log.warning("the record at byte %d is damaged (%s): passed over, the bag's index has its connections",
                        off, stop.reason)
        if message is not None:
            yield message
        pos = start + dlen


def _ros1_index_connections(f: BinaryIO, index_pos: int, size: int) -> dict[int, Ros1Connection]:
    """The connection records of a closed bag's index (at ``index_pos``: a ROS 1 bag repeats every connection
    record there, after its chunks), as far as they read; empty without an index. ``f`` is left where it was."""
    copies: dict[int, Ros1Connection] = {}
    if not 0 < index_pos < size:
        return copies
    back = f.tell()
    try:
        f.seek(index_pos)
        while (pos := f.tell()) < size:  # the connection records, then the chunk infos
            fields, dlen = _ros1_record(f, pos, size - pos)
            if fields["op"][0] != _OP_CONNECTION:
                break
            conn_id, conn = _ros1_connection(fields, _read(f, dlen, pos, "a record"), pos)
            copies[conn_id] = conn
    except _Stop:  # a damaged index: the copies read so far
        pass
    finally:
        f.seek(back)
    return copies


def scan_ros1(path: str | Path, end: ScanEnd | None = None) -> Iterator[tuple[Ros1Connection, int, bytes]]:
    """Every complete message of a ROS 1 bag (2.0) in file order, read without its index.

    Yields ``(connection, log_t_ns, raw_bytes)``; ``end`` (filled in when the iterator is exhausted)
    says where reading stopped and why.
    """
    path = Path(path)
    end = end if end is not None else ScanEnd(path)
    size = end.size = path.stat().st_size
    connections: dict[int, Ros1Connection] = {}
    index_pos: int | None = None  # from the bag header, once read
    copies: dict[int, Ros1Connection] = {}  # the connection records of the bag's index, once read
    with path.open("rb") as f:
        if f.read(len(ROS1_MAGIC)) != ROS1_MAGIC:
            raise RecordingError(f"{path}: not a ROS 1 bag (format 2.0): it does not start with '#ROSBAG V2.0'")
        pos = f.tell()
        try:
            while True:
                pos = f.tell()
                if pos == size:
                    break
                fields, dlen = _ros1_record(f, pos, size - pos)
                op = fields["op"][0]
                data_pos = f.tell()
                if op == _OP_CHUNK:
                    compression = fields.get("compression", b"").decode("latin-1")
                    if compression not in ("none", "bz2", "lz4"):
                        raise _Stop(pos, f"chunk of unknown compression {compression!r} (corrupt)")
                    if compression != "none":
                        end.compression = compression  # kept in the output
                    usize = _u32(fields, "size", pos)
                    data = f.read(dlen)
                    cut = len(data) < dlen
                    if cut:
                        raw = _partial(data, compression)[:usize]
                    else:
                        try:
                            raw = _decompress(data, compression)
                        except Exception as err:
                            raise _Stop(pos, f"chunk does not decompress ({err}) (corrupt)") from None
                        if len(raw) != usize:
                            raise _Stop(pos, f"chunk of {len(raw)} bytes where its header says {usize} (corrupt)")
                    # a damaged record inside the chunk: its file offset (uncompressed), else the chunk's
                    if compression == "none":
                        where, end_offset = (lambda p, base=data_pos: base + p), data_pos + len(raw)
                    else:
                        where, end_offset = (lambda p, base=pos: base), pos
                    yield from _chunk(_ros1_chunk_records(raw, connections, where, copies, end.damaged), cut,
                                      end_offset, pos, size - pos, data_pos - pos + dlen)
                    continue
                data = _read(f, dlen, pos, "a record")
                if op == _OP_BAGHEADER:
                    index_pos = struct.unpack("<Q", fields["index_pos"])[0] if len(
                        fields.get("index_pos", b"")) == 8 else 0
                    copies = _ros1_index_connections(f, index_pos, size)
                elif op == _OP_CONNECTION:
                    conn_id, conn = _ros1_connection(fields, data, pos)
                    connections[conn_id] = conn
                elif op == _OP_MSGDATA:  # a message outside chunks (allowed, though rosbag never writes it)
                    yield _ros1_message(fields, data, connections, pos)
                elif op not in (_OP_IDXDATA, _OP_CHUNKINFO):
                    raise _Stop(pos, f"record of unknown op {op} (corrupt)")
        except _Stop as stop:
            end.offset, end.reason, end.complete = stop.offset, stop.reason, False
            return
    end.offset = size
    if index_pos is None:
        end.reason, end.complete = "the end of the file, before the bag header: truncated", False
    elif index_pos == 0:
        end.reason, end.complete = "the end of the file; the bag was never closed (no index)", False
    elif index_pos >= size:
        end.reason, end.complete = f"the end of the file, before its index (at byte {index_pos}): truncated", False
    elif end.damaged:
        end.reason, end.complete = "the end of the file (the bag was closed)", True
    else:
        end.reason, end.complete = "the end of the file (the bag is complete)", True


# --------------------------------------------------------------------------------------------------
# MCAP
# --------------------------------------------------------------------------------------------------

_MCAP_KNOWN_OPS = set(range(0x01, 0x10))


class _Cursor:
    """Reads MCAP's little-endian primitives from a bytes record."""

    def __init__(self, data: bytes, offset: int) -> None:
        self.data, self.pos, self.offset = data, 0, offset

    def take(self, n: int) -> bytes:
        if self.pos + n > len(self.data):
            raise _Stop(self.offset, "a record's fields run past its end (corrupt)")
        out = self.data[self.pos:self.pos + n]
        self.pos += n
        return out

    def uint(self, fmt: str) -> int:
        return int(struct.unpack(fmt, self.take(struct.calcsize(fmt)))[0])

    def string(self) -> str:
        try:
            return self.take(self.uint("<I")).decode()
        except UnicodeDecodeError:
            raise _Stop(self.offset, "a string field is not UTF-8 (corrupt)") from None


class _McapState:
    def __init__(self) -> None:
        self.schemas: dict[int, tuple[str, str, str]] = {}
        self.channels: dict[int, McapChannel] = {}

    def record(self, op: int, content: bytes, offset: int) -> tuple[McapChannel, int, bytes] | None:
        """Handle one schema / channel / message record; a message is returned."""
        cur = _Cursor(content, offset)
        if op == 0x03:
            sid = cur.uint("<H")
            name, encoding = cur.string(), cur.string()
            self.schemas[sid] = (name, encoding, cur.take(cur.uint("<I")).decode(errors="replace"))
        elif op == 0x04:
            cid, sid = cur.uint("<H"), cur.uint("<H")
            topic, encoding = cur.string(), cur.string()
            meta = _Cursor(cur.take(cur.uint("<I")), offset)
            metadata = {}
            while meta.pos < len(meta.data):
                key = meta.string()
                metadata[key] = meta.string()
            name, schema_encoding, msgdef = self.schemas.get(sid, ("", "", ""))
            self.channels[cid] = McapChannel(topic, name, schema_encoding, msgdef, encoding,
                                             metadata.get("offered_qos_profiles", ""))
        elif op == 0x05:
            cid = cur.uint("<H")
            cur.take(4)  # sequence
            log_t_ns = cur.uint("<Q")
            cur.take(8)  # publish time
            if cid not in self.channels:
                raise _Stop(offset, f"message of unknown channel {cid} (corrupt)")
            return self.channels[cid], log_t_ns, content[cur.pos:]
        return None

    def chunk_records(self, data: bytes, where: Callable[[int], int]) -> Iterator[tuple[McapChannel, int, bytes]]:
        pos = 0
        while pos < len(data):
            if pos + 9 > len(data):
                raise _Short(where(pos))
            op, length = struct.unpack_from("<BQ", data, pos)
            if (op not in _MCAP_KNOWN_OPS and op < 0x80) or op in (0x02, 0x06, 0x0F):
                raise _Stop(where(pos), f"record of op {op:#04x} inside a chunk (corrupt)")
            if pos + 9 + length > len(data):
                raise _Short(where(pos))
            msg = self.record(op, data[pos + 9:pos + 9 + length], where(pos))
            if msg is not None:
                yield msg
            pos += 9 + length


def scan_mcap(path: str | Path, end: ScanEnd | None = None) -> Iterator[tuple[McapChannel, int, bytes]]:
    """Every complete message of an MCAP file in file order, read without its summary.

    Yields ``(channel, log_t_ns, raw_bytes)``; ``end`` (filled in when the iterator is exhausted)
    says where reading stopped and why.
    """
    path = Path(path)
    end = end if end is not None else ScanEnd(path)
    size = end.size = path.stat().st_size
    state = _McapState()
    with path.open("rb") as f:
        if f.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
            raise RecordingError(f"{path}: not an MCAP file: it does not start with the MCAP magic")
        try:
            while True:
                pos = f.tell()
                if pos == size:
                    raise _Stop(pos, "the end of the file, without the end of its data section: truncated")
                op, length = struct.unpack("<BQ", _read(f, 9, pos, "a record's op code and length"))
                if op not in _MCAP_KNOWN_OPS and op < 0x80:
                    raise _Stop(pos, f"record of unknown op {op:#04x} (corrupt)")
                if op == 0x06:
                    yield from _mcap_chunk(f, state, pos, length, size)
                    continue
                if pos + 9 + length > size:
                    raise _Stop(pos, f"the file ends inside a record of {9 + length} bytes (truncated)")
                if op in (0x0F, 0x02):  # data end, footer: what follows is the summary
                    break
                content = f.read(length)
                msg = state.record(op, content, pos)
                if msg is not None:
                    yield msg
        except _Stop as stop:
            end.offset, end.reason, end.complete = stop.offset, stop.reason, False
            return
    end.offset, end.reason, end.complete = pos, "the end of its data section (the file is complete)", True


def _mcap_chunk(f: BinaryIO, state: _McapState, pos: int, length: int,
                size: int) -> Iterator[tuple[McapChannel, int, bytes]]:
    head = _read(f, 32, pos, "a chunk's header")
    _t0, _t1, usize, crc, clen = struct.unpack("<QQQII", head)
    compression = _read(f, clen, pos, "a chunk's header").decode(errors="replace")
    (rlen,) = struct.unpack("<Q", _read(f, 8, pos, "a chunk's header"))
    if compression not in ("", "zstd", "lz4"):
        raise _Stop(pos, f"chunk of unknown compression {compression!r} (corrupt)")
    if 32 + clen + 8 + rlen != length:
        raise _Stop(pos, "chunk whose records do not fill it (corrupt)")
    data_pos = f.tell()
    data = f.read(rlen)
    cut = len(data) < rlen
    if cut:
        raw = _partial(data, compression)[:usize]
    else:
        try:
            raw = _decompress(data, compression)
        except Exception as err:
            raise _Stop(pos, f"chunk does not decompress ({err}) (corrupt)") from None
        if len(raw) != usize or (crc and zlib.crc32(raw) != crc):
            raise _Stop(pos, "chunk whose size or CRC does not match its header (corrupt)")
    if compression == "":
        where, end_offset = (lambda p: data_pos + p), data_pos + len(raw)
    else:
        where, end_offset = (lambda p: pos), pos
    yield from _chunk(state.chunk_records(raw, where), cut, end_offset, pos, size - pos, 9 + length)


# --------------------------------------------------------------------------------------------------
# Repair: scan, write a new recording
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class RepairReport:
    """What :func:`repair_recording` recovered and where reading stopped."""

    source: Path
    output: Path
    kind: RecordingKind
    counts: dict[str, int]  # messages recovered per topic
    start_ns: int
    end_ns: int
    ends: tuple[ScanEnd, ...]  # one per file read
    skipped: dict[str, int] = field(default_factory=dict)  # messages of channels a rosbag2 cannot hold

    @property
    def messages(self) -> int:
        return sum(self.counts.values())

    @property
    def complete(self) -> bool:
        """Every file was read to its end: nothing was damaged."""
        return all(e.complete and not e.damaged for e in self.ends)

    def summary(self) -> str:
        """One line: messages per topic, the time span, where reading stopped."""
        topics = ", ".join(f"{t} {n}" for t, n in sorted(self.counts.items()))
        span = (self.end_ns - self.start_ns) / 1e9
        stops = "; ".join(
            f"{e.file.name if len(self.ends) > 1 else 'reading'} stopped at byte {e.offset} of {e.size}: {e.reason}"
            for e in self.ends)
        skipped = (f"; skipped {sum(self.skipped.values())} messages of non-ROS channels "
                   f"({', '.join(sorted(self.skipped))})" if self.skipped else "")
        damaged = [off for e in self.ends for off in e.damaged]
        copies = (f"; {len(damaged)} damaged record{'s' * (len(damaged) != 1)} inside its chunks (at byte "
                  f"{', '.join(map(str, sorted(set(damaged))))}) passed over, their connections read from the copies "
                  "in the bag's index" if damaged else "")
        return (f"recovered {self.messages} message{'s' * (self.messages != 1)} ({topics}) over {span:.3f} s, "
                f"{_fmt_ns(self.start_ns)} to {_fmt_ns(self.end_ns)}, into {self.output}; {stops}{copies}{skipped}")


def _fmt_ns(t_ns: int) -> str:
    if t_ns > 10**17:  # plausibly epoch time
        return datetime.fromtimestamp(t_ns / 1e9, tz=UTC).strftime("%Y-%m-%d %H:%M:%S.%f")[:-3] + " UTC"
    return f"{t_ns / 1e9:.3f} s"


def _mcap_files(folder: Path) -> list[Path]:
    """A rosbag2 folder's MCAP files in recording order (metadata.yaml's order where it is readable)."""
    files = sorted(folder.glob("*.mcap"))
    listed = _folder_metadata(folder).get("relative_file_paths") or []
    order = {name: i for i, name in enumerate(listed)}
    return sorted(files, key=lambda p: (order.get(p.name, len(order)), p.name))


def _folder_metadata(folder: Path) -> dict[str, Any]:
    meta = folder / "metadata.yaml"
    if not meta.is_file():
        return {}
    try:
        from ruamel.yaml import YAML

        info = YAML(typ="safe").load(meta.read_text())["rosbag2_bagfile_information"]
        return info if isinstance(info, dict) else {}
    except Exception:  # a damaged metadata.yaml: the MCAP files are read without it
        log.warning("%s: unreadable, its custom data is not carried over", meta)
        return {}


def repair_recording(source: str | Path, output: str | Path) -> RepairReport:
    """Read every complete message of a damaged (or intact) recording into a new one that opens.

    Parameters
    ----------
    source : a ROS 1 ``.bag`` (format 2.0), an ``.mcap`` file, or a rosbag2 folder of ``.mcap`` files.
    output : the new recording: a ``.bag`` file for a ROS 1 bag, a rosbag2 folder (MCAP) otherwise.
        It must not exist.

    Returns
    -------
    RepairReport
        Messages per topic, their span, and where (byte offset) and why reading stopped.

    Raises
    ------
    RecordingError
        ``source`` is missing, is not a ROS 1 bag or MCAP, or holds no complete message (nothing is
        written then); ``output`` exists or cannot be written.
    ConfigError
        ``output`` has the wrong form (a ROS 1 bag is repaired into a ``.bag`` file).
    """
    source, output = Path(source), Path(output)
    if not source.exists():
        raise RecordingError(f"recording not found: {source}")
    kind = recording_kind(source)
    if kind is None:
        what = "holds no MCAP file" if source.is_dir() else "is neither a ROS 1 bag (format 2.0) nor an MCAP file"
        raise RecordingError(f"{source}: cannot repair it: it {what} (fusiontrack repairs ROS 1 .bag and MCAP)")
    if output.exists():
        raise RecordingError(f"{output}: already exists; fusiontrack does not overwrite recordings")
    if kind == "ros1" and output.suffix != ".bag":
        raise ConfigError(f"output {output}: a ROS 1 bag is repaired into a .bag file (e.g. {output}.bag)")
    if kind == "mcap" and output.suffix == ".bag":
        raise ConfigError(f"output {output}: an MCAP recording is repaired into a rosbag2 folder, not a .bag")
    sink = _Ros1Sink(output) if kind == "ros1" else _Ros2Sink(output, _folder_metadata(source) if source.is_dir()
                                                               else {})
    files = [source] if kind == "ros1" else (_mcap_files(source) if source.is_dir() else [source])
    ends: list[ScanEnd] = []
    counts: Counter[str] = Counter()
    t0, t1 = 2**63 - 1, 0
    try:
        for file in files:
            end = ScanEnd(file)
            ends.append(end)
            scan: Iterator[tuple[Any, int, bytes]] = scan_ros1(file, end) if kind == "ros1" else scan_mcap(file, end)
            for conn, t_ns, data in scan:
                if sink.write(conn, t_ns, data, end.compression):
                    counts[conn.topic] += 1
                    t0, t1 = min(t0, t_ns), max(t1, t_ns)
    except FusiontrackError:
        sink.abort()
        raise
    except Exception as err:  # an unreadable source, a full disk: one clear error, no half-written output
        sink.abort()
        raise RecordingError(f"{source}: repair failed ({err}); nothing written") from err
    except BaseException:
        sink.abort()
        raise
    if not counts:
        sink.abort()
        stops = "; ".join(f"reading stopped at byte {e.offset} of {e.size}: {e.reason}" for e in ends)
        raise RecordingError(f"{source}: no complete message to recover ({stops}); nothing written")
    sink.close()
    return RepairReport(source, output, kind, dict(counts), t0, t1, tuple(ends), dict(sink.skipped))


class _Ros1Sink:
    """A rosbags ROS 1 writer opened at the first message, with the input's chunk compression."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.writer: Ros1Writer | None = None
        self.connections: dict[Ros1Connection, Any] = {}
        self.skipped: Counter[str] = Counter()

    def write(self, conn: Ros1Connection, t_ns: int, data: bytes, compression: str) -> bool:
        if self.writer is None:
            writer = Ros1Writer(self.path)
            if compression in ("bz2", "lz4"):
                writer.set_compression(Ros1Writer.CompressionFormat[compression.upper()])
            try:
                writer.open()
            except Exception as err:
                raise RecordingError(f"{self.path}: cannot create the bag: {err}") from err
            self.writer = writer
        if conn not in self.connections:
            self.connections[conn] = self.writer.add_connection(
                conn.topic, normalize_msgtype(conn.msgtype), msgdef=conn.msgdef, md5sum=conn.md5sum,
                callerid=conn.callerid, latching=conn.latching)
        self.writer.write(self.connections[conn], t_ns, data)
        return True

    def close(self) -> None:
        if self.writer is not None:
            self.writer.close()

    def abort(self) -> None:
        if self.writer is not None:
            self.writer.abort()
            self.path.unlink(missing_ok=True)
            self.writer = None


class _Ros2Sink:
    """A rosbags rosbag2 (MCAP) writer opened at the first message; keeps schemas, QoS and custom data."""

    def __init__(self, path: Path, metadata: dict[str, Any]) -> None:
        self.path = path
        self.custom = {str(k): str(v) for k, v in (metadata.get("custom_data") or {}).items()}
        self.writer: Ros2Writer | None = None
        self.connections: dict[tuple[str, str, str, str], Any] = {}
        self.skipped: Counter[str] = Counter()

    def write(self, chan: McapChannel, t_ns: int, data: bytes, _compression: str) -> bool:
        if chan.schema_encoding not in ("ros2msg", "ros2idl") or chan.message_encoding != "cdr":
            self.skipped[chan.topic] += 1
            return False
        if self.writer is None:
            writer = Ros2Writer(self.path, version=9, storage_plugin=StoragePlugin.MCAP)
            try:
                writer.open()
            except Exception as err:
                raise RecordingError(f"{self.path}: cannot create the recording: {err}") from err
            self.writer = writer
        key = (chan.topic, chan.msgtype, chan.message_encoding, chan.qos)
        if key not in self.connections:
            self.connections[key] = self.writer.add_connection(
                chan.topic, chan.msgtype, msgdef=chan.msgdef, rihs01=_rihs01(chan),
                serialization_format=chan.message_encoding, offered_qos_profiles=_qos(chan.qos))
        self.writer.write(self.connections[key], t_ns, data)
        return True

    def close(self) -> None:
        if self.writer is not None:
            for key, value in self.custom.items():
                self.writer.set_custom_data(key, value)
            self.writer.close()

    def abort(self) -> None:
        if self.writer is not None:
            self.writer.abort()
            shutil.rmtree(self.path, ignore_errors=True)
            self.writer = None


def _rihs01(chan: McapChannel) -> str:
    """The type hash a reader computes from the schema (readers check it against the stored one)."""
    try:
        if chan.schema_encoding == "ros2msg":
            types = get_types_from_msg(chan.msgdef, chan.msgtype)
        else:  # ros2idl: one IDL, or several each after a line of 80 '=' and an "IDL: name" line
            sep = "=" * 80 + "\n"
            idls = ([part.split("\n", 1)[1] for part in chan.msgdef.split(sep)[1:]]
                    if chan.msgdef.startswith(sep + "IDL: ") else [chan.msgdef])
            types = {}
            for idl in idls:
                types.update(get_types_from_idl(idl))
        store = get_typestore(Stores.EMPTY)
        store.register(types)
        return store.hash_rihs01(chan.msgtype)
    except Exception as err:
        raise RecordingError(f"channel {chan.topic}: its schema {chan.msgtype} cannot be parsed: {err}") from err


def _qos(text: str) -> list[Any]:
    if not text:
        return []
    try:
        from rosbags.rosbag2.metadata import parse_qos

        return parse_qos(text)
    except Exception:  # QoS is for replaying in ROS 2; the messages matter more
        log.warning("unreadable QoS profiles dropped: %.60s", text)
        return []
