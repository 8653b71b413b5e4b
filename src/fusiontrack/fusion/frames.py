"""A recording's camera images, read lazily: an image is converted only when the tracker asks for it.

Seed 001's fused system is fast because "only a limited number of targets required visual processing": the
camera is read for the targets that need it (training, score maps, splits). :class:`LazyFrames` follows the
laser clock through the image topic, keeping the raw bytes of the latest image only, and converts (to a
:class:`~fusiontrack.types.Image`: a ROS 2 raw image as a view of its bytes, as
:meth:`~fusiontrack.io.Recording.messages` reads it, other images deserialised) the image nearest to a time on
request, once.
"""

from __future__ import annotations

import logging
import struct
from collections.abc import Iterator
from typing import Any

from ..errors import RecordingError
from ..io.recording import IMAGE
from ..io.ros import FROM_ROS, image_from_cdr_bytes
from ..io.sync import with_time
from ..types import Image

__all__ = ["LazyFrames"]

log = logging.getLogger(__name__)


class LazyFrames:
    """The images of one topic of an open :class:`~fusiontrack.io.recording.Recording`, converted on demand.

    Parameters
    ----------
    rec : Recording
        Open recording (the caller closes it).
    topic : str
        ``sensor_msgs/Image`` or ``CompressedImage`` topic.
    max_dt_ns : int
        :meth:`at` gives an image only if its log time is this close to the time asked for.
    clock_correction_ns : int
        Added to the image times (the camera client's clock offset, as for the scans).
    raw : iterator of (connection, log time, bytes), optional
        The topic's raw records, if the caller reads them (e.g. the second reader of
        :meth:`~fusiontrack.io.Recording.messages_and_raw`, which reads the file once for the scans and the
        images); by default they are read from ``rec`` here. ``None`` from it: no record yet (the reader may not
        read further ahead now); the next image is then taken as not within ``max_dt_ns``, and asked for again
        at the next call.

    Notes
    -----
    Times must be asked for in increasing order (the stream is read once, forwards). An image's time is its
    capture stamp (header, read from the raw bytes without deserialising; the log time when it is 0) plus
    ``clock_correction_ns``; a camera's latency (log time after capture) does not shift the selection.
    """

    def __init__(self, rec: Any, topic: str, max_dt_ns: int = 50_000_000, clock_correction_ns: int = 0,
                 raw: Iterator[tuple[Any, int, bytes]] | None = None) -> None:
        conns = rec.select([topic], convertible_only=True)
        if not conns:
            raise RecordingError(f"{rec.paths[0]}: no image topic {topic!r}")
        self.topic = topic
        self.sensor = rec.sensor_of(topic)
        self.max_dt_ns = int(max_dt_ns)
        self.correction_ns = int(clock_correction_ns)
        # Recording has no public "raw bytes, convert later" stream: its raw reader is used here so that images
        # the tracker never needs are never deserialised (seed 001's "camera read only when needed").
        owners = {id(c): r for r in rec._readers for c in r.connections}
        self._deser = {id(c): owners[id(c)] for c in conns}
        self._it: Iterator[tuple[Any, int, bytes] | None] = rec._raw(conns) if raw is None else raw
        self._ended = False
        self._prev: tuple[Any, int, bytes] | None = None
        self._next: tuple[Any, int, bytes] | None = self._pull()
        self._cache: tuple[int, Image | None] | None = None  # (log time, converted image)
        self.converted = 0  # images converted so far
        self.seen = 0  # images passed so far
        self.unreadable = 0  # images converted so far that could not be used (skipped)
        self.first_unreadable = ""  # why the first of them could not

    @staticmethod
    def _stamp(data: bytes, t_log: int, ros1: bool) -> int:
        """The header stamp of a raw image message: ``sec`` and ``nanosec`` are at bytes 4-12 both in ROS 2 CDR
        (after the 4-byte encapsulation header, byte 1 = 1 for little-endian) and in ROS 1 (after ``seq``)."""
        if len(data) < 12:
            return t_log
        order = "<" if ros1 or data[1] == 1 else ">"  # ROS 1 is little-endian; CDR says so in byte 1
        sec, nsec = struct.unpack_from(order + "iI", data, 4)
        t = sec * 1_000_000_000 + nsec
        return t if sec > 0 and nsec < 1_000_000_000 else t_log

    def _pull(self) -> tuple[Any, int, bytes] | None:
        """The next raw image with its stamp, or None: the stream has ended, or has nothing yet (``raw``)."""
        item = next(self._it, _END)
        if item is _END:
            self._ended = True
            return None
        if item is None:
            return None
        conn, t_log, data = item
        return conn, self._stamp(data, t_log, _is_ros1(conn)) + self.correction_ns, data

    def _advance(self, t_ns: int) -> None:
        if self._next is None and not self._ended:  # nothing was there yet: look again
            self._next = self._pull()
        while self._next is not None and self._next[1] <= t_ns:
            self._prev, self._next = self._next, self._pull()
            self.seen += 1

    def nearest_time(self, t_ns: int) -> int | None:
        """Time of the image nearest to ``t_ns`` within ``max_dt_ns`` (no conversion), or None."""
        self._advance(t_ns)
        best = None
        for cand in (self._prev, self._next):
            if cand is not None and abs(cand[1] - t_ns) <= self.max_dt_ns and (
                    best is None or abs(cand[1] - t_ns) < abs(best[1] - t_ns)):
                best = cand
        return None if best is None else int(best[1])

    def at(self, t_ns: int) -> Image | None:
        """The image nearest to ``t_ns`` (converted once and cached), or None if none is within ``max_dt_ns``."""
        t_log = self.nearest_time(t_ns)
        if t_log is None:
            return None
        if self._cache is not None and self._cache[0] == t_log:
            return self._cache[1]
        raw = self._prev if self._prev is not None and self._prev[1] == t_log else self._next
        assert raw is not None
        conn, _, data = raw
        img: Image | None = None
        try:
            # a ROS 2 raw image: its pixels a view of the bytes (as Recording.messages reads it), else deserialised
            reader = self._deser[id(conn)]
            out = image_from_cdr_bytes(data, self.sensor) if conn.msgtype == IMAGE and reader.is2 else None
            if out is not None:
                out = with_time(out, t_log)
            else:
                msg = reader.deserialize(data, conn.msgtype)
                out = FROM_ROS[conn.msgtype](msg, t_log, self.sensor, conn.topic)
            img = out if isinstance(out, Image) and out.encoding in ("bgr8", "rgb8") else None
            if img is not None and img.encoding == "rgb8":
                img = Image(img.t_ns, img.sensor, img.frame_id, img.pixels[..., ::-1], "bgr8")
        except Exception as err:  # one bad image must not end the run: the laser goes on alone
            self.unreadable += 1  # counted, and said once at the end of the run (:meth:`warn_unreadable`)
            self.first_unreadable = self.first_unreadable or f"image at {t_log} ns: {err}"
            log.debug("%s: image at %d ns unreadable (%s); skipped", self.topic, t_log, err)
        self.converted += 1
        self._cache = (t_log, img)
        return img


    def warn_unreadable(self) -> None:
        """At the end of a run: one warning with the number of images skipped as unreadable (a truncated or empty
        image, an unknown encoding), if any, and why the first was."""
        if self.unreadable:
            log.warning("%s: %d of the %d images converted were unreadable and skipped (first: %s)", self.topic,
                        self.unreadable, self.converted, self.first_unreadable)


_END = object()


def _is_ros1(conn: Any) -> bool:
    """Whether a rosbags connection comes from a ROS 1 bag (its messages have no CDR encapsulation header)."""
    return type(getattr(conn, "ext", None)).__name__ == "ConnectionExtRosbag1"
