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


def test_image_decoder_matches_generic_path(tmp_path):
    from fusiontrack.io.ros import image_from_cdr_bytes, image_from_ros
    from fusiontrack.types import Image

    rng = np.random.default_rng(1)
    t0 = 1_600_000_000_000_000_000
    images = [Image(t0 + i, "c", "f" * i, rng.integers(0, 256, (6 + i, 5 + i, 3), dtype=np.uint8), enc)
              for i, enc in enumerate(("bgr8", "rgb8", "bgr8", "rgb8"))]
    images += [Image(t0 + 10 + i, "c", "g" * i, rng.integers(0, 256, (7, 9 + i), dtype=np.uint8), "mono8")
               for i in range(3)]
    images += [Image(t0 + 20 + i, "c", "h" * i, rng.integers(0, 65536, (5, 3 + i), dtype=np.uint16), "mono16")
               for i in range(3)]
    write_recording(tmp_path / "r", images)
    n = 0
    with AnyReader([tmp_path / "r"]) as reader:
        for conn, _, raw in reader.messages():
            fast = image_from_cdr_bytes(raw, "c")
            assert fast is not None
            msg = reader.deserialize(raw, conn.msgtype)
            assert records_equal(fast, image_from_ros(msg, stamp_to_ns(msg.header.stamp), "c", conn.topic))
            assert not fast.pixels.flags.writeable
            n += 1
    assert n == len(images)


def test_image_decoder_honours_row_padding_and_byte_order_and_refuses_the_rest():
    from rosbags.typesys import Stores, get_typestore

    from fusiontrack.io.ros import image_from_cdr_bytes

    ts = get_typestore(Stores.ROS2_HUMBLE)
    Img, Header, Time = (ts.types[k] for k in ("sensor_msgs/msg/Image", "std_msgs/msg/Header",
                                               "builtin_interfaces/msg/Time"))
    grey = np.arange(12, dtype=np.uint16).reshape(3, 4) * 1000

    def wire(encoding, big, step, data, height=3, width=4):
        msg = Img(Header(Time(sec=5, nanosec=7), "cam"), height, width, encoding, big, step,
                  np.frombuffer(data, np.uint8))
        return bytes(ts.serialize_cdr(msg, "sensor_msgs/msg/Image"))

    padded = np.zeros((3, 12), np.uint16)  # 4 pixels of 2 bytes and 16 bytes of padding per row
    padded[:, :4] = grey
    im = image_from_cdr_bytes(wire("mono16", 0, 24, padded.astype("<u2").tobytes()), "c")
    assert im is not None
    assert im.t_ns == 5_000_000_007
    assert im.frame_id == "cam"
    assert np.array_equal(im.pixels, grey)
    big = image_from_cdr_bytes(wire("mono16", 1, 8, grey.astype(">u2").tobytes()), "c")
    assert big is not None
    assert np.array_equal(big.pixels, grey)
    assert big.pixels.dtype == np.uint16
    assert big.pixels.dtype.isnative
    # depth and other encodings go the general way; so does a buffer too short for its rows
    assert image_from_cdr_bytes(wire("16UC1", 0, 8, grey.astype("<u2").tobytes()), "c") is None
    assert image_from_cdr_bytes(wire("32FC1", 0, 16, np.zeros((3, 4), "<f4").tobytes()), "c") is None
    assert image_from_cdr_bytes(wire("mono16", 0, 8, grey.astype("<u2").tobytes()[:-2]), "c") is None
    assert image_from_cdr_bytes(b"\x00\x01\x00\x00\x01", "c") is None
