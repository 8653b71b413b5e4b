"""Repairing cut-off and damaged recordings: every complete message comes back, identical, and opens.

The truth is the intact recording (read by rosbags through its index) or the messages a test wrote
itself: a repaired recording must hold a prefix of the original messages, with the same log times and
payload bytes, as long as the cut allows.
"""

from __future__ import annotations

import re
import struct
import subprocess
import sys
import zlib
from pathlib import Path

import lz4.frame
import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from rosbags.rosbag1 import Reader as Ros1Reader
from rosbags.rosbag1 import Writer as Ros1Writer

from fusiontrack.errors import ConfigError, RecordingError
from fusiontrack.io.recording import Recording
from fusiontrack.io.recover import MCAP_MAGIC, repair_recording, zstd
from fusiontrack.io.writer import write_recording
from fusiontrack.types import LaserScan

DEMO = "laser/leg_tracker_demo/demo_stationary_simple_environment.bag"
DEMO_MESSAGES = 1265  # /scan messages of the demo bag (its README)


@pytest.fixture(scope="module")
def demo(shared_data):
    """The demo bag read through its index: bytes, messages ``(t_ns, payload)`` and the chunks' extents."""
    path = shared_data / DEMO
    with Ros1Reader(path) as reader:
        (conn,) = reader.connections
        messages = [(t, bytes(raw)) for _, t, raw in reader.messages()]
        index = reader.indexes[conn.id]
        chunks = [(info.pos, reader.chunks[info.pos].datapos + reader.chunks[info.pos].datasize,
                   sum(info.connection_counts.values())) for info in reader.chunk_infos]
        return {"path": path, "bytes": path.read_bytes(), "messages": messages, "index": index, "chunks": chunks,
                "datapos": {pos: c.datapos for pos, c in reader.chunks.items()}, "conn": conn}


def _ros1_messages(path: Path) -> list[tuple[int, bytes]]:
    with Ros1Reader(path) as reader:
        return [(t, bytes(raw)) for _, t, raw in reader.messages()]


def test_intact_bag_comes_out_identical(demo, tmp_path):
    out = tmp_path / "same.bag"
    report = repair_recording(demo["path"], out)
    assert report.complete
    assert report.counts == {"/scan": DEMO_MESSAGES}
    assert report.ends[0].offset == len(demo["bytes"])
    with Ros1Reader(out) as reader:
        (conn,) = reader.connections
        assert (conn.topic, conn.msgtype, conn.digest, conn.msgdef) == (
            demo["conn"].topic, demo["conn"].msgtype, demo["conn"].digest, demo["conn"].msgdef)
    assert _ros1_messages(out) == demo["messages"]
    assert (report.start_ns, report.end_ns) == (demo["messages"][0][0], demo["messages"][-1][0])


def test_cut_bag_gives_back_every_complete_message(demo, tmp_path):
    data, original = demo["bytes"], demo["messages"]
    counts = []
    for keep in (0.01, 0.25, 0.5, 0.9, 0.999):
        cut = tmp_path / f"cut{keep}.bag"
        cut.write_bytes(data[: int(len(data) * keep)])
        with pytest.raises(RecordingError, match=r"(complete|corrupt).*fusiontrack repair .*cut.*-o"):
            Recording(cut)
        out = tmp_path / f"fixed{keep}.bag"
        report = repair_recording(cut, out)
        assert not report.complete
        assert report.ends[0].offset <= cut.stat().st_size
        with Recording(out) as rec:  # it opens, and the fast reader sees the same scans
            n = rec.topics()["/scan"].count
            scans = list(rec.messages(time_source="log"))
        assert report.counts == {"/scan": n}
        assert _ros1_messages(out) == original[:n]
        assert [s.t_ns for s in scans] == [t for t, _ in original[:n]]
        # every message of the chunks the cut left whole, and about the share of the file that is left
        whole = sum(count for _, end, count in demo["chunks"] if end <= len(data) * keep)
        assert n >= whole
        assert abs(n / DEMO_MESSAGES - keep) < 0.02
        counts.append(n)
    assert counts == sorted(counts)
    assert counts[0] > 0


def test_cut_inside_the_bag_header(demo, tmp_path):
    for size in (13, 2000, 4000):  # the magic only; inside the 4 KiB bag header
        cut = tmp_path / f"head{size}.bag"
        cut.write_bytes(demo["bytes"][:size])
        out = tmp_path / f"head{size}_fixed.bag"
        with pytest.raises(RecordingError, match=rf"head{size}\.bag: no complete message.*truncated"):
            repair_recording(cut, out)
        assert not out.exists()


def test_corrupt_record_stops_the_scan_there_unless_the_bag_was_closed(demo, tmp_path):
    """A message record whose op code is damaged. In a bag cut off before its index the record's connection may
    be unknown: the messages before it come back and reading stops at it. In the closed bag (its index repeats
    the connection records) it is passed over, and every other message comes back."""
    k = 700
    entry = demo["index"][k]
    record = demo["datapos"][entry.chunk_pos] + entry.offset  # the chunk is uncompressed: a file offset
    data = bytearray(demo["bytes"])
    op = data.index(b"op=\x02", record)
    assert op < record + 64
    data[op + 3] = 9
    cut = tmp_path / "cut.bag"
    cut.write_bytes(bytes(data[: int(len(data) * 0.9)]))
    report = repair_recording(cut, tmp_path / "cut_fixed.bag")
    assert report.counts == {"/scan": k}
    assert report.ends[0].offset == record
    assert "corrupt" in report.ends[0].reason
    assert _ros1_messages(tmp_path / "cut_fixed.bag") == demo["messages"][:k]
    bad = tmp_path / "bad.bag"
    bad.write_bytes(bytes(data))
    report = repair_recording(bad, tmp_path / "bad_fixed.bag")
    assert report.counts == {"/scan": DEMO_MESSAGES - 1}
    assert report.ends[0].damaged == [record]
    assert not report.complete
    assert f"1 damaged record inside its chunks (at byte {record}) passed over" in report.summary()
    assert _ros1_messages(tmp_path / "bad_fixed.bag") == demo["messages"][:k] + demo["messages"][k + 1:]


@pytest.mark.parametrize("damage", ["type=", "message_definition=", "topic=", "op=\x07"])
def test_damaged_connection_record_of_a_closed_bag_is_read_from_the_index(demo, tmp_path, damage):
    """Flipped bytes in the connection record at the start of the first chunk (in its data: a field name, a field's
    length; in its header: a field's length, the op's name): rosbags reads the bag whole through the copy of every
    connection record a closed bag keeps in its index, but repair stopped there with nothing written. The damaged
    record is now passed over and its connection read from that copy: every message comes back, under the original
    connection. Without the index (the bag cut before it) that copy is gone: nothing to recover, said clearly."""
    data = bytearray(demo["bytes"])
    first = min(demo["datapos"].values())
    record = data.index(b"op=\x07", first)
    if damage == "op=\x07":  # the op's name: "oP=" is no op code
        at = record
    elif damage == "message_definition=":  # the length of this field
        at = data.index(damage.encode(), record) - 4
    elif damage == "topic=":  # the length of this header field
        at = data.index(damage.encode(), first) - 4
    else:
        at = data.index(damage.encode(), record)
    data[at] ^= 0x55
    bad = tmp_path / "bad.bag"
    bad.write_bytes(bytes(data))
    with Recording(bad) as rec:  # (read through the index, as rosbags does)
        assert rec.topics()["/scan"].count == DEMO_MESSAGES
    out = tmp_path / "fixed.bag"
    report = repair_recording(bad, out)
    assert report.counts == {"/scan": DEMO_MESSAGES}
    assert not report.complete  # a record was damaged
    assert "1 damaged record inside its chunks" in report.summary()
    assert _ros1_messages(out) == demo["messages"]
    with Ros1Reader(out) as reader:
        (conn,) = reader.connections
        assert (conn.topic, conn.msgtype, conn.digest, conn.msgdef) == (
            demo["conn"].topic, demo["conn"].msgtype, demo["conn"].digest, demo["conn"].msgdef)
    cut = tmp_path / "cut.bag"  # the same damage, and the file cut in half: no index
    cut.write_bytes(bytes(data[: len(data) // 2]))
    with pytest.raises(RecordingError, match=r"no complete message.*corrupt.*nothing written"):
        repair_recording(cut, tmp_path / "cut_fixed.bag")
    assert not (tmp_path / "cut_fixed.bag").exists()


def _ros1_record(fields: dict[str, bytes], data: bytes) -> bytes:
    """A ROS 1 bag record (wiki.ros.org/Bags/Format/2.0): header length, name=value fields, data length, data."""
    header = b"".join(struct.pack("<I", len(k) + 1 + len(v)) + k.encode() + b"=" + v for k, v in fields.items())
    return struct.pack("<I", len(header)) + header + struct.pack("<I", len(data)) + data


def test_bag_that_was_never_closed(demo, tmp_path):
    """What rosbag record leaves when the power goes: no index (index_pos 0), and the open chunk's header still
    says size 0 with its connection and message records written after it, the last one cut off."""
    conn = demo["conn"]
    head = _ros1_record({"op": b"\x03", "index_pos": struct.pack("<Q", 0), "conn_count": struct.pack("<I", 0),
                         "chunk_count": struct.pack("<I", 0)}, b"")
    bag = bytearray(b"#ROSBAG V2.0\n" + head[:-4] + struct.pack("<I", 4096 - len(head)) + b" " * (4096 - len(head)))
    bag += _ros1_record({"op": b"\x05", "compression": b"none", "size": struct.pack("<I", 0)}, b"")
    bag += _ros1_record({"op": b"\x07", "conn": struct.pack("<I", 0), "topic": b"/scan"}, b"".join(
        struct.pack("<I", len(k) + 1 + len(v)) + k.encode() + b"=" + v.encode() for k, v in (
            ("topic", "/scan"), ("type", "sensor_msgs/LaserScan"), ("md5sum", conn.digest),
            ("message_definition", conn.msgdef.data))))
    for t, raw in demo["messages"][:100]:
        bag += _ros1_record({"op": b"\x02", "conn": struct.pack("<I", 0),
                             "time": struct.pack("<II", t // 10**9, t % 10**9)}, raw)
    last = len(bag)
    t, raw = demo["messages"][100]
    bag += _ros1_record({"op": b"\x02", "conn": struct.pack("<I", 0),
                         "time": struct.pack("<II", t // 10**9, t % 10**9)}, raw)[:900]
    path = tmp_path / "unclosed.bag"
    path.write_bytes(bytes(bag))
    with pytest.raises(RecordingError, match=r"unclosed\.bag.*complete.*fusiontrack repair"):
        Recording(path)
    report = repair_recording(path, tmp_path / "closed.bag")
    assert report.counts == {"/scan": 100}
    assert report.ends[0].offset == last
    assert "truncated" in report.ends[0].reason
    assert _ros1_messages(tmp_path / "closed.bag") == demo["messages"][:100]
    path.write_bytes(bytes(bag[:last]))  # cut exactly after a message: the missing index is the reason
    report = repair_recording(path, tmp_path / "closed2.bag")
    assert report.messages == 100
    assert "no index" in report.ends[0].reason


@pytest.mark.parametrize("compression", ["bz2", "lz4"])
def test_compressed_bag(demo, tmp_path, compression):
    src = tmp_path / f"{compression}.bag"
    original = demo["messages"][:150]
    writer = Ros1Writer(src)
    writer.set_compression(Ros1Writer.CompressionFormat[compression.upper()])
    writer.chunk_threshold = 40_000  # about 19 messages a chunk
    with writer:
        conn = writer.add_connection("/scan", demo["conn"].msgtype, msgdef=demo["conn"].msgdef.data,
                                     md5sum=demo["conn"].digest)
        for t, raw in original:
            writer.write(conn, t, raw)
    with Ros1Reader(src) as reader:
        chunk_ends = [(reader.chunks[i.pos].datapos + reader.chunks[i.pos].datasize,
                       sum(i.connection_counts.values())) for i in reader.chunk_infos]
    assert len(chunk_ends) > 4
    out = tmp_path / f"{compression}_same.bag"
    assert repair_recording(src, out).complete
    assert _ros1_messages(out) == original
    assert f"compression={compression}".encode() in out.read_bytes()[:6000]  # the first chunk's header
    data = src.read_bytes()
    cut = tmp_path / f"{compression}_cut.bag"
    cut.write_bytes(data[: int(len(data) * 0.6)])
    out = tmp_path / f"{compression}_fixed.bag"
    report = repair_recording(cut, out)
    n = report.messages
    assert _ros1_messages(out) == original[:n]
    assert n >= sum(count for end, count in chunk_ends if end <= len(data) * 0.6)


# --------------------------------------------------------------------------------------------------
# MCAP
# --------------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def scans():
    rng = np.random.default_rng(3)
    return [LaserScan((i + 1) * 50_000_000, "front", "laser", -1.5, 0.006, 0.02, 6.0,
                      (rng.random(500) * 6).astype(np.float32)) for i in range(600)]


@pytest.fixture(scope="module")
def mcap_recording(scans, tmp_path_factory):
    """A rosbag2 folder written by fusiontrack (two MCAP chunks), its schema and raw messages."""
    folder = tmp_path_factory.mktemp("mcap") / "rec"
    write_recording(folder, scans)
    with AnyReader([folder]) as reader:
        (conn,) = reader.connections
        raw = [(t, bytes(data)) for _, t, data in reader.messages()]
        return {"folder": folder, "msgtype": conn.msgtype, "msgdef": conn.msgdef.data, "raw": raw}


def _same_scans(got: list[LaserScan], want: list[LaserScan]) -> bool:
    if len(got) != len(want):
        return False
    return all(g.t_ns == w.t_ns and g.sensor == w.sensor and np.array_equal(g.ranges_m, w.ranges_m)
               for g, w in zip(got, want, strict=True))


def test_cut_mcap_folder(mcap_recording, scans, tmp_path):
    (mcap,) = mcap_recording["folder"].glob("*.mcap")
    data = mcap.read_bytes()
    assert repair_recording(mcap_recording["folder"], tmp_path / "same").complete
    with Recording(tmp_path / "same") as rec:
        assert _same_scans(list(rec.messages()), scans)
    counts = []
    for keep in (0.05, 0.3, 0.7, 0.95):
        folder = tmp_path / f"cut{keep}"
        folder.mkdir()
        (folder / "metadata.yaml").write_bytes((mcap_recording["folder"] / "metadata.yaml").read_bytes())
        (folder / mcap.name).write_bytes(data[: int(len(data) * keep)])
        with pytest.raises(RecordingError, match=rf"cut{keep}.*corrupt.*fusiontrack repair"):
            Recording(folder)
        report = repair_recording(folder, tmp_path / f"fixed{keep}")
        n = report.messages
        assert not report.complete
        with Recording(tmp_path / f"fixed{keep}") as rec:  # the sensor name comes back from the folder's metadata
            assert _same_scans(list(rec.messages()), scans[:n])
        assert abs(n / len(scans) - keep) < 0.02
        counts.append(n)
    assert counts == sorted(counts)


QOS = """- history: 1
  depth: 1
  reliability: 1
  durability: 1
  deadline: {sec: 0, nsec: 0}
  lifespan: {sec: 0, nsec: 0}
  liveliness: 1
  liveliness_lease_duration: {sec: 0, nsec: 0}
  avoid_ros_namespace_conventions: false"""  # keep last 1, reliable, transient local: a latched topic


def _record(op: int, content: bytes) -> bytes:
    return struct.pack("<BQ", op, len(content)) + content


def _string(text: str) -> bytes:
    return struct.pack("<I", len(text.encode())) + text.encode()


def _write_mcap(path: Path, msgtype: str, msgdef: str, raw: list[tuple[int, bytes]], compression: str,
                per_chunk: int) -> list[tuple[int, int]]:
    """An MCAP file written from the spec (mcap.dev/spec); returns each chunk's (end offset, message count)."""
    compress = {"": lambda b: b, "zstd": zstd.compress, "lz4": lz4.frame.compress}[compression]
    out = bytearray(MCAP_MAGIC + _record(0x01, _string("ros2") + _string("test")))
    schema = _record(0x03, struct.pack("<H", 1) + _string(msgtype) + _string("ros2msg") + _string(msgdef))
    metadata = _string("offered_qos_profiles") + _string(QOS)
    channel = _record(0x04, struct.pack("<HH", 1, 1) + _string("/front/scan") + _string("cdr")
                      + struct.pack("<I", len(metadata)) + metadata)
    ends = []
    for first in range(0, len(raw), per_chunk):
        part = raw[first:first + per_chunk]
        body = (schema + channel if first == 0 else b"") + b"".join(
            _record(0x05, struct.pack("<HIQQ", 1, first + k, t, t) + data) for k, (t, data) in enumerate(part))
        packed = compress(body)
        out += _record(0x06, struct.pack("<QQQI", part[0][0], part[-1][0], len(body), zlib.crc32(body))
                       + _string(compression) + struct.pack("<Q", len(packed)) + packed)
        ends.append((len(out), len(part)))
    out += _record(0x0F, struct.pack("<I", 0)) + _record(0x02, struct.pack("<QQI", 0, 0, 0)) + MCAP_MAGIC
    path.write_bytes(bytes(out))
    return ends


@pytest.mark.parametrize("compression", ["zstd", "lz4"])
def test_compressed_mcap(mcap_recording, scans, tmp_path, compression):
    src = tmp_path / f"{compression}.mcap"
    ends = _write_mcap(src, mcap_recording["msgtype"], mcap_recording["msgdef"], mcap_recording["raw"],
                       compression, per_chunk=50)
    report = repair_recording(src, tmp_path / "same")
    assert report.complete
    with AnyReader([tmp_path / "same"]) as reader:
        assert [(t, bytes(d)) for _, t, d in reader.messages()] == mcap_recording["raw"]
        ((qos,),) = [c.ext.offered_qos_profiles for c in reader.connections]
    assert (qos.depth, qos.durability.name, qos.reliability.name) == (1, "TRANSIENT_LOCAL", "RELIABLE")
    data = src.read_bytes()
    for keep in (0.4, 0.8):
        cut = tmp_path / f"cut{keep}.mcap"
        cut.write_bytes(data[: int(len(data) * keep)])
        report = repair_recording(cut, tmp_path / f"fixed{keep}")
        with AnyReader([tmp_path / f"fixed{keep}"]) as reader:
            assert [(t, bytes(d)) for _, t, d in reader.messages()] == mcap_recording["raw"][: report.messages]
        assert report.messages >= sum(count for end, count in ends if end <= len(data) * keep)
        with Recording(tmp_path / f"fixed{keep}") as rec:  # no folder metadata: the sensor is the topic
            got = list(rec.messages())
        assert [g.t_ns for g in got] == [s.t_ns for s in scans[: report.messages]]
    # a damaged byte inside the third chunk's compressed data: the two chunks before it come back
    bad = bytearray(data)
    bad[ends[1][0] + 200] ^= 0xFF
    (tmp_path / "bad.mcap").write_bytes(bytes(bad))
    report = repair_recording(tmp_path / "bad.mcap", tmp_path / "bad_fixed")
    assert report.messages == ends[0][1] + ends[1][1]
    assert report.ends[0].offset == ends[1][0]
    assert "corrupt" in report.ends[0].reason


# --------------------------------------------------------------------------------------------------
# Bad input, the command line
# --------------------------------------------------------------------------------------------------


def test_what_cannot_be_repaired(demo, tmp_path):
    notes = tmp_path / "notes.bag"
    notes.write_text("this is not a rosbag\n")
    with pytest.raises(RecordingError, match=r"notes\.bag.*neither a ROS 1 bag"):
        repair_recording(notes, tmp_path / "out.bag")
    empty = tmp_path / "empty.mcap"
    empty.write_bytes(b"")
    with pytest.raises(RecordingError, match=r"empty\.mcap"):
        repair_recording(empty, tmp_path / "out")
    with pytest.raises(RecordingError, match=r"nowhere\.bag"):
        repair_recording(tmp_path / "nowhere.bag", tmp_path / "out.bag")
    with pytest.raises(ConfigError, match=r"\.bag file"):
        repair_recording(demo["path"], tmp_path / "folder")
    (tmp_path / "taken.bag").write_bytes(b"")
    with pytest.raises(RecordingError, match=r"taken\.bag: already exists"):
        repair_recording(demo["path"], tmp_path / "taken.bag")


def _cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "fusiontrack", *args], capture_output=True, text=True, timeout=120)


def test_cli_repair(demo, tmp_path):
    cut = tmp_path / "cut.bag"
    cut.write_bytes(demo["bytes"][: len(demo["bytes"]) // 2])
    result = _cli("repair", str(cut), "-o", str(tmp_path / "fixed.bag"))
    assert result.returncode == 0, result.stderr
    (line,) = [ln for ln in result.stdout.splitlines() if ln.strip()]
    with Recording(tmp_path / "fixed.bag") as rec:
        n = rec.message_count
    assert f"recovered {n} messages (/scan {n})" in line
    stop = re.search(r"stopped at byte (\d+) of (\d+): .*truncated", line)
    assert stop is not None, line
    assert int(stop[1]) <= int(stop[2]) == len(demo["bytes"]) // 2
    junk = tmp_path / "junk.bag"
    junk.write_bytes(b"\x00" * 100)
    result = _cli("repair", str(junk), "-o", str(tmp_path / "junk_fixed.bag"))
    assert result.returncode == 2
    (line,) = [ln for ln in result.stderr.splitlines() if ln.strip()]
    assert line.startswith("error:")
    assert "junk.bag" in line
    assert "Traceback" not in result.stderr
