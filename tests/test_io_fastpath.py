"""The LaserScan wire decoder gives exactly what rosbags' generic deserialiser + conversion give."""

from __future__ import annotations

import numpy as np
from rosbags.highlevel import AnyReader

from fusiontrack.io.ros import laserscan_from_cdr_bytes, laserscan_from_ros, laserscan_from_ros1_bytes, stamp_to_ns
from fusiontrack.io.writer import write_recording
from fusiontrack.types import LaserScan, records_equal

DEMO = "laser/leg_tracker_demo/demo_stationary_simple_environment.bag"


def generic(reader: AnyReader, conn, raw: bytes, sensor: str) -> LaserScan:
    msg = reader.deserialize(raw, conn.msgtype)
    return laserscan_from_ros(msg, stamp_to_ns(msg.header.stamp), sensor, conn.topic)


def test_ros1_decoder_matches_generic_path_on_real_scans(shared_data):
    n = 0
    with AnyReader([shared_data / DEMO]) as reader:
        for conn, _, raw in reader.messages():
            fast = laserscan_from_ros1_bytes(raw, "s")
            assert fast is not None
            assert records_equal(fast, generic(reader, conn, raw, "s"))
            n += 1
            if n == 200:
                break
    assert n == 200


def test_cdr_decoder_matches_generic_path(tmp_path):
    rng = np.random.default_rng(0)
    # frame ids of every length modulo 4 exercise the CDR alignment; with and without intensities
    scans = [LaserScan(1_600_000_000_000_000_000 + i, "l", "f" * i, -1.0 + i, 0.01, 0.02, 5.0,
                       rng.random(100 + i), rng.random(100 + i) if i % 2 else [], 1e-4, 0.1)
             for i in range(8)]
    write_recording(tmp_path / "r", scans)
    with AnyReader([tmp_path / "r"]) as reader:
        for conn, _, raw in reader.messages():
            fast = laserscan_from_cdr_bytes(raw, "l")
            assert fast is not None
            assert records_equal(fast, generic(reader, conn, raw, "l"))


def test_decoder_refuses_a_buffer_it_does_not_understand(shared_data):
    with AnyReader([shared_data / DEMO]) as reader:
        _, _, raw = next(iter(reader.messages()))
    assert laserscan_from_ros1_bytes(raw[:-3], "s") is None  # cut short
    assert laserscan_from_ros1_bytes(raw + b"\x00" * 8, "s") is None  # trailing bytes: not a LaserScan
    assert laserscan_from_cdr_bytes(b"\x00\x01\x00\x00\x01", "s") is None
