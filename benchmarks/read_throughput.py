"""Read throughput: fusiontrack's Recording against plain rosbags on the outdoor laser bag.

Runs every variant in this process, several times, and prints the median of each beside its ratio
to merely iterating the raw bag with rosbags (the reference the foundation issue names: our
conversion should cost less than 2x that). The bag is ../shared/data/laser/leg_tracker_outdoor
(7170 LaserScans + 6179 annotations, 720 s); it is also converted to MCAP to time the ROS 2 path.

    .venv/bin/python benchmarks/read_throughput.py [--repeats 5]
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
import zipfile
from collections.abc import Callable
from pathlib import Path

from rich.console import Console
from rich.table import Table
from rosbags.highlevel import AnyReader

from fusiontrack.io.recording import Recording
from fusiontrack.io.ros import laserscan_from_ros, stamp_to_ns
from fusiontrack.io.writer import write_recording

ROOT = Path(__file__).resolve().parents[1]
ZIPPED = ROOT / ".." / "shared" / "data" / "laser" / "leg_tracker_outdoor" / "person_following_outdoor_1.bag.zip"
TOPIC = "/scan_base2"


def rosbags_raw(path: Path) -> tuple[int, int]:
    """Iterate the raw messages of the scan topic: no deserialisation."""
    n = size = 0
    with AnyReader([path]) as reader:
        conns = [c for c in reader.connections if c.topic == TOPIC]
        for _, _, raw in reader.messages(connections=conns):
            n += 1
            size += len(raw)
    return n, size


def rosbags_deserialize(path: Path) -> tuple[int, int]:
    """Iterate and deserialise with rosbags' generic deserialiser."""
    n = size = 0
    with AnyReader([path]) as reader:
        conns = [c for c in reader.connections if c.topic == TOPIC]
        for conn, _, raw in reader.messages(connections=conns):
            reader.deserialize(raw, conn.msgtype)
            n += 1
            size += len(raw)
    return n, size


def generic_conversion(path: Path) -> tuple[int, int]:
    """What fusiontrack would cost without its LaserScan fast path: deserialise, then convert."""
    n = size = 0
    with AnyReader([path]) as reader:
        conns = [c for c in reader.connections if c.topic == TOPIC]
        for conn, _, raw in reader.messages(connections=conns):
            msg = reader.deserialize(raw, conn.msgtype)
            laserscan_from_ros(msg, stamp_to_ns(msg.header.stamp), TOPIC, TOPIC)
            n += 1
            size += len(raw)
    return n, size


def fusiontrack_records(path: Path) -> tuple[int, int]:
    """fusiontrack's Recording: LaserScan records, header time."""
    n = size = 0
    with Recording(path) as rec:
        for scan in rec.messages([TOPIC]):
            n += 1
            size += scan.ranges_m.nbytes + scan.intensities.nbytes
    return n, size


def timed(fn: Callable[[Path], tuple[int, int]], path: Path, repeats: int) -> tuple[float, int, int]:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        n, size = fn(path)
        times.append(time.perf_counter() - t0)
    return statistics.median(times), n, size


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    console = Console(width=110)
    with tempfile.TemporaryDirectory() as tmp:
        with zipfile.ZipFile(ZIPPED) as zf:
            zf.extractall(tmp)
        bag = next(Path(tmp).glob("**/*.bag"))
        mcap = Path(tmp) / "mcap"
        with Recording(bag) as rec:
            write_recording(mcap, rec.messages([TOPIC]))
        bag_mb = bag.stat().st_size / 1e6
        variants = [
            ("rosbags: iterate raw (reference)", rosbags_raw),
            ("rosbags: iterate + deserialise", rosbags_deserialize),
            ("generic deserialise + convert", generic_conversion),
            ("fusiontrack Recording.messages", fusiontrack_records),
        ]
        for label, path in (("ROS 1 bag", bag), ("rosbag2 MCAP", mcap)):
            table = Table(title=f"{label}: {TOPIC} of the outdoor bag ({bag_mb:.1f} MB file), "
                                f"median of {args.repeats}", header_style="bold")
            for col in ("variant", "messages", "seconds", "msg/s", "MB/s (payload)", "x reference"):
                table.add_column(col, justify="left" if col == "variant" else "right")
            reference = None
            for name, fn in variants:
                seconds, n, size = timed(fn, path, args.repeats)
                reference = reference or seconds
                table.add_row(name, str(n), f"{seconds:.3f}", f"{n / seconds:,.0f}", f"{size / 1e6 / seconds:.1f}",
                              f"{seconds / reference:.2f}")
            console.print(table)


if __name__ == "__main__":
    main()
