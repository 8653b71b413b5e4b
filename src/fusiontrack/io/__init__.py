"""Recordings in and out: bags (ROS 1, ROS 2 sqlite3/MCAP), video, IMU CSV, tracks; time alignment."""

from .imu_csv import ImuCsv, read_imu_csv
from .recording import Recording, TopicInfo, open_recording
from .sync import Synchronizer, align_nearest, estimate_clock_offset, merge, synchronize
from .tracks import (
    MotBoxes,
    group_tracks,
    read_jsonl,
    read_mot,
    read_tracks_csv,
    write_jsonl,
    write_mot,
    write_tracks_csv,
)
from .video import VideoReader, write_video
from .writer import RecordingWriter, write_recording

__all__ = [
    "ImuCsv",
    "MotBoxes",
    "Recording",
    "RecordingWriter",
    "Synchronizer",
    "TopicInfo",
    "VideoReader",
    "align_nearest",
    "estimate_clock_offset",
    "group_tracks",
    "merge",
    "open_recording",
    "read_imu_csv",
    "read_jsonl",
    "read_mot",
    "read_tracks_csv",
    "synchronize",
    "write_jsonl",
    "write_mot",
    "write_recording",
    "write_tracks_csv",
    "write_video",
]
