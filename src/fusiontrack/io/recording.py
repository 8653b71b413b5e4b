"""Reading recordings: ROS 1 bags and ROS 2 bags (sqlite3 and MCAP), one reader over several files.

Each file is opened with its own ``rosbags`` :class:`~rosbags.highlevel.AnyReader`, so ROS 1 and
ROS 2 files can be mixed; their streams are merged by log time with :func:`heapq.merge`. Messages
are converted into fusiontrack records (:mod:`fusiontrack.io.ros`) lazily, one at a time.

Time: a record's ``t_ns`` is its header stamp (the capture time on the sensor's clock) unless
``time_source="log"`` is asked for, or the message has no header (then the log time is used).
Header stamps of different sensors may disagree with each other and come out of order; put them
on one clock and in order with :mod:`fusiontrack.io.sync`.
"""

from __future__ import annotations

import ast
import heapq
import itertools
import json
import logging
import re
from collections import Counter, deque
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from rosbags.highlevel import AnyReader
from rosbags.interfaces import Connection

from ..errors import ConfigError, MessageTypeError, RecordingError, TopicError
from ..types import Message
from .recover import _folder_metadata, recording_kind
from .ros import (
    FROM_ROS,
    HEADERLESS,
    build_typestore,
    image_from_cdr_bytes,
    laserscan_from_cdr_bytes,
    laserscan_from_ros1_bytes,
    parse_definitions,
    stamp_to_ns,
)
from .sync import with_time

if TYPE_CHECKING:
    from ..geometry import TransformTree

log = logging.getLogger(__name__)

SENSOR_MAP_KEY = "fusiontrack.sensors"
"""Key of the topic -> sensor map that fusiontrack's writer stores in a rosbag2 recording."""

TimeSource = Literal["header", "log"]
LASERSCAN = "sensor_msgs/msg/LaserScan"
IMAGE = "sensor_msgs/msg/Image"
COMPRESSED_IMAGE = "sensor_msgs/msg/CompressedImage"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"


@dataclass(frozen=True, slots=True)
class TopicInfo:
    """What a topic holds: its type, how many messages, over what span of log time."""

    topic: str
    msgtype: str
    count: int
    t_start_ns: int
    t_end_ns: int
    sensor: str
    convertible: bool

    @property
    def duration_s(self) -> float:
        return (self.t_end_ns - self.t_start_ns) / 1e9

    @property
    def rate_hz(self) -> float:
        """Mean message rate; 0 for fewer than two messages."""
        span = self.t_end_ns - self.t_start_ns
        return (self.count - 1) / (span / 1e9) if self.count > 1 and span > 0 else 0.0


def _whole_bag(path: Path) -> Path:
    """A rosbag2 folder's one storage file, given alone, is read as its folder: the folder's ``metadata.yaml`` holds
    what the file does not (fusiontrack's sensor map: read without it, every topic is its own sensor, a camera's
    images lose their CameraInfo and a traffic or wearable run drops its cameras)."""
    if path.is_file() and path.suffix.lower() in (".mcap", ".db3"):
        listed = _folder_metadata(path.parent).get("relative_file_paths")
        if listed == [path.name]:
            log.debug("%s: read as its rosbag2 folder %s", path, path.parent)
            return path.parent
    return path


_DEPTH_NAMESPACE = re.compile(r"(aligned_)?depth(_\w+)?")
_TRANSPORTS = ("compressed", "theora", "zstd", "ffmpeg", "h264", "jpeg", "png")


_WARNED_NOT_COLOUR: set[tuple[tuple[str, ...], str]] = set()  # (recording, topic) warned of by image_topic


def _colour_image(topic: str) -> bool:
    """An image topic's name is not that of a label or depth image: the simulator's ``/<camera>/labels`` and
    ``/<camera>/depth``, an image named for depth (``.../image_depth``, ``.../compressedDepth``), or an image in a
    camera's depth namespace (``/ns/depth/image_raw``, ``/ns/depth_registered/image``,
    ``/ns/aligned_depth_to_color/image_raw``). A camera's own namespace may say depth (``/depth_cam/image``,
    ``/stereo_depth_camera/rgb/image_raw``): its colour images are colour images."""
    parts = [q for q in topic.split("/") if q]
    if len(parts) >= 2 and parts[-1] in _TRANSPORTS:  # image_transport's copy of a stream: as the stream
        parts = parts[:-1]
    if not parts or parts[-1] == "labels" or "depth" in parts[-1].lower():
        return False
    return not (len(parts) >= 3 and _DEPTH_NAMESPACE.fullmatch(parts[-2].lower()))


_TUPLE_OF_TEXTS = re.compile(r"""\((?:'[^'\\]*'|"[^"\\]*")(?:,\s*(?:'[^'\\]*'|"[^"\\]*"))*,?\)""")


def _plain_text(text: str) -> str:
    """A reader's message with the Python repr of an args tuple in it as plain text: rosbags words a damaged
    index as ``Bag index looks damaged: ('Header could not be read from file.',)``."""
    def plain(match: re.Match[str]) -> str:
        try:
            parts = ast.literal_eval(match.group(0))
        except (ValueError, SyntaxError):
            return match.group(0)
        return "; ".join(str(p) for p in (parts if isinstance(parts, tuple) else (parts,)))

    return _TUPLE_OF_TEXTS.sub(plain, text)


def _describe_open_error(path: Path, err: BaseException) -> str:
    text = _plain_text(" ".join(str(a) for a in err.args)) or type(err).__name__
    hint = _repair_hint(path)
    if path.is_file() and path.suffix not in (".bag", ".mcap", ".db3") and not hint:
        return (f"{path}: not a recording fusiontrack can open (expected a ROS 1 .bag, a ROS 2 bag folder, "
                f"a .mcap or a .db3 file): {text}")
    return f"{path}: cannot open the recording ({text}); is it complete and not corrupt?" + (
        f" If not, {hint}" if hint else "")


def _repair_hint(path: Path) -> str:
    """How to recover the messages of a damaged ROS 1 bag or MCAP ("" for anything else)."""
    kind = recording_kind(path)
    if kind is None:
        return ""
    name = path.name.removesuffix(".active")  # rosbag record's name for a bag still being written
    stem = name.removesuffix(".bag") if kind == "ros1" else name.removesuffix(".mcap")
    out = path.with_name(f"{stem}_repaired" + (".bag" if kind == "ros1" else ""))
    return f'run "fusiontrack repair {path} -o {out}" to recover the messages it holds'


def _storage_files(path: Path) -> set[Path]:
    """The files a recording path reads, resolved: a file itself; a rosbag2 folder its .mcap / .db3 files (and the
    folder)."""
    path = path.resolve()
    if not path.is_dir():
        return {path}
    return {path} | {f.resolve() for f in path.iterdir() if f.suffix in (".mcap", ".db3")}


def _check_distinct(paths: Sequence[Path]) -> None:
    """A recording given twice (the same path, the same file by another name, or a rosbag2 folder and a file in it)
    would be merged with itself, every message twice: a RecordingError naming both."""
    seen: dict[Path, Path] = {}
    for path in paths:
        files = _storage_files(path)
        first = next((seen[f] for f in sorted(files) if f in seen), None)
        if first is not None:
            what = f"{path} is given twice" if str(first) == str(path) else f"{first} and {path} are one recording"
            raise RecordingError(f"{what}: read together every message would count twice; give each recording once")
        seen.update(dict.fromkeys(files, path))


def _check_not_copies(paths: Sequence[Path], readers: Sequence[AnyReader]) -> None:
    """Two inputs with the same span and the same messages per topic are copies of one recording (merged, every
    message would count twice): a RecordingError naming both. Consecutive pieces, or the bags of two machines
    recorded together, differ in one or the other."""
    seen: dict[tuple[Any, ...], Path] = {}
    for path, reader in zip(paths, readers, strict=True):
        counts = tuple(sorted((c.topic, c.msgtype, c.msgcount) for c in reader.connections))
        if not counts or not sum(n for _, _, n in counts):
            continue
        key = (reader.start_time, reader.end_time, counts)
        if key in seen:
            raise RecordingError(f"{seen[key]} and {path} hold the same messages (a copy?): read together every "
                                 "message would count twice; give each recording once")
        seen[key] = path


def _warn_shared_topics(paths: Sequence[Path], readers: Sequence[AnyReader]) -> None:
    """A warning for two inputs that hold the same sensor topic over overlapping times: read as one, their messages
    interleave (two scenes merged: the tracks of both worlds in one). Consecutive pieces of a recording do not
    overlap; the bags of two machines recorded together hold different sensors (TF, ``/rosout`` and other
    non-sensor topics aside)."""
    spans = []
    for path, reader in zip(paths, readers, strict=True):
        # sensor data only: not /rosout, /parameter_events, TF (which every machine's bag may hold)
        topics = {c.topic for c in reader.connections if c.msgcount and c.msgtype in FROM_ROS
                  and not c.msgtype.startswith("tf2_msgs/")}
        if topics:
            spans.append((path, reader.start_time, reader.end_time, topics))
    for (pa, a0, a1, ta), (pb, b0, b1, tb) in itertools.combinations(spans, 2):
        both = ta & tb
        if both and a0 < b1 and b0 < a1:
            shown = ", ".join(sorted(both)[:3]) + (", ..." if len(both) > 3 else "")
            log.warning("%s and %s both hold %s over the same time: read together, their messages interleave "
                        "(two recordings of different scenes? give them one at a time)", pa, pb, shown)


class Recording:
    """One or several recording files read as a single time-ordered stream.

    Parameters
    ----------
    paths : path or sequence of paths
        ROS 1 ``.bag`` files, ROS 2 bag folders, ``.mcap`` or ``.db3`` files, in any mix.
    custom_types : mapping of message type -> definition (ROS .msg syntax), optional
        Types to register before deserialising, for recordings that do not embed their definitions
        (e.g. ``{"leg_tracker/msg/Person": "geometry_msgs/Pose pose\\nuint32 id"}``).
    sensors : mapping of topic -> sensor name, optional
        The ``sensor`` written into each record; by default the name stored in the recording by
        fusiontrack's writer, else the topic name.

    Use as a context manager, or call :meth:`close`.
    """

    def __init__(
        self,
        paths: str | Path | Sequence[str | Path],
        *,
        custom_types: Mapping[str, str] | None = None,
        sensors: Mapping[str, str] | None = None,
    ) -> None:
        if isinstance(paths, str | Path):
            paths = [paths]
        given = [Path(p) for p in paths]
        if not given:
            raise RecordingError("no recording given: expected at least one bag, MCAP or db3 path")
        missing = [str(p) for p in given if not p.exists()]
        if missing:
            raise RecordingError(f"recording not found: {', '.join(missing)}")
        _check_distinct(given)  # (as given: a folder and its .mcap are named as the user gave them)
        self.paths = [_whole_bag(p) for p in given]
        self._custom_fields = parse_definitions(custom_types or {})
        default_typestore = build_typestore(custom_types)
        self._readers: list[AnyReader] = []
        sensor_map: dict[str, str] = {}
        try:
            for path in self.paths:
                try:
                    reader = AnyReader([path], default_typestore=default_typestore)
                    reader.open()
                except Exception as err:  # rosbags raises its own, OSError, struct and yaml errors
                    raise RecordingError(_describe_open_error(path, err)) from err
                self._readers.append(reader)
                self._register_custom(reader, path)
                sensor_map.update(self._stored_sensor_map(reader))
            _check_not_copies(self.paths, self._readers)
            _warn_shared_topics(self.paths, self._readers)
        except BaseException:
            self.close()
            raise
        sensor_map.update(sensors or {})
        self._sensor_map = sensor_map
        self._topics: dict[str, TopicInfo] | None = None
        self.skipped: Counter[str] = Counter()
        """Messages skipped by the last :meth:`messages` pass, per topic."""

    # ---------------------------------------------------------------------------------------------
    def _register_custom(self, reader: AnyReader, path: Path) -> None:
        """Add user-given type definitions to a reader's typestore (bag definitions take precedence)."""
        new = {k: v for k, v in self._custom_fields.items() if k not in reader.typestore.fielddefs}
        if new:
            try:
                reader.typestore.register(new)
            except Exception as err:
                raise MessageTypeError(f"{path}: cannot register custom types {sorted(new)}: {err}") from err

    @staticmethod
    def _stored_sensor_map(reader: AnyReader) -> dict[str, str]:
        out: dict[str, str] = {}
        for sub in reader.readers:
            metadata = getattr(getattr(sub, "storage", None), "metadata", None)  # rosbag2 only
            custom = getattr(metadata, "custom", None) or {}
            if SENSOR_MAP_KEY in custom:
                try:
                    out.update(json.loads(custom[SENSOR_MAP_KEY]))
                except (ValueError, TypeError):
                    log.warning("ignoring an unreadable %s entry in %s", SENSOR_MAP_KEY, sub.path)
        return out

    def close(self) -> None:
        for reader in self._readers:
            try:
                reader.close()
            except Exception:  # closing must not hide the error that made us close
                log.debug("error while closing a reader", exc_info=True)
        self._readers = []

    def __enter__(self) -> Recording:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ---------------------------------------------------------------------------------------------
    @property
    def connections(self) -> list[Connection]:
        return [c for r in self._readers for c in r.connections]

    def sensor_of(self, topic: str) -> str:
        return self._sensor_map.get(topic, topic)

    def image_topics(self, camera: str | None = None) -> list[str]:
        """The colour image topics (``sensor_msgs/Image`` or ``CompressedImage``; not label or depth images) of a
        camera, or of every camera; one per camera, the preferred first.

        ``camera``: a sensor name (fusiontrack's sensor metadata), else, in a recording made by other tools (no
        metadata: each topic is its own sensor), a ``camera_info`` topic or a namespace, whose images are beside
        it as ROS names them (``/ns/image_raw`` for ``/ns/camera_info``; not those of a camera deeper down with a
        ``camera_info`` of its own), or one of its image topics. The variants image_transport publishes of one
        image stream (``/ns/image_raw/compressed`` beside ``/ns/image_raw``) are one camera: the raw stream is
        listed, its variants are not.
        """
        types = self.topic_types()
        colour = [t for t, m in types.items() if m in (IMAGE, COMPRESSED_IMAGE) and _colour_image(t)]
        if camera is not None:
            own = [t for t in colour if self.sensor_of(t) == camera]
            if not own and camera in colour:
                own = [camera]
            elif not own and camera.startswith("/"):
                ns = camera.rsplit("/", 1)[0] if camera.endswith("camera_info") else camera.rstrip("/")
                deeper = [t.rsplit("/", 1)[0] for t, m in types.items() if m == CAMERA_INFO and t != camera
                          and t.startswith(ns + "/") and len(t.rsplit("/", 1)[0]) > len(ns)]
                own = [t for t in colour if t.startswith(ns + "/")
                       and not any(t.startswith(d + "/") for d in deeper)]
            colour = own
        streams = [t for t in colour if not any(t.startswith(u + "/") for u in colour if u != t)]
        # raw before compressed, a simulated camera's ``/image`` before other names
        return sorted(streams, key=lambda t: (types[t] != IMAGE, not t.endswith("/image"), t))

    def image_topic(self, camera: str | None = None, topic: str | None = None, *, required: bool = True,
                    option: str = "camera_topic (--camera-topic)") -> str | None:
        """The image topic to read: ``topic`` (checked), else that of ``camera`` (:meth:`image_topics`: the first
        of its streams), else the recording's only camera's.

        Raises
        ------
        TopicError
            ``topic`` is not an image topic of the recording; or no image topic (``required``; else None).
        ConfigError
            ``camera`` and ``topic`` are None and the recording has several cameras.

        ``option`` names ``topic`` as the caller's user gives it, in the messages.
        """
        types = self.topic_types()
        where = ", ".join(str(q) for q in self.paths)
        if topic is not None:
            if types.get(topic) not in (IMAGE, COMPRESSED_IMAGE):
                found = ", ".join(self.image_topics()) or "none"
                what = "no such topic" if topic not in types else f"a {types[topic]} topic, not an image"
                raise TopicError(f"{where}: {option} {topic!r}: {what}; image topics: {found}")
            warned = (tuple(str(q) for q in self.paths), topic)
            if not _colour_image(topic) and warned not in _WARNED_NOT_COLOUR:  # the user's word, but its name says
                # labels or depth: said (once: a run's set-up, bias pass and overlay each ask) before a run that may
                # read none of its images (a label or depth image is no colour image to track people in)
                _WARNED_NOT_COLOUR.add(warned)
                log.warning("%s: %s %r is named as a label or depth image topic, not colour images (colour image "
                            "topics: %s)", where, option, topic, ", ".join(self.image_topics()) or "none")
            return topic
        found = self.image_topics(camera)
        if not found:
            if not required:
                return None
            whose = "" if camera is None else f" of camera {camera!r}"
            shown = [t if self.sensor_of(t) == t else f"{t} (camera {self.sensor_of(t)})" for t in self.image_topics()]
            others = "" if camera is None else f"; image topics: {', '.join(shown) or 'none'}"
            raise TopicError(f"{where}: no image topic{whose} (sensor_msgs/Image or CompressedImage){others}")
        if camera is None and len(found) > 1:
            raise ConfigError(f"{where}: several cameras' image topics ({', '.join(found)}); choose one with {option}")
        return found[0]

    def camera_info_topics(self, camera: str) -> list[str]:
        """The ``CameraInfo`` topics of a camera (its sensor name, or one of its image topics).

        Those of the same sensor (fusiontrack's sensor metadata) if there are any; else, as ROS names them, the
        ``camera_info`` beside the camera's image topics (``/ns/camera_info`` for ``/ns/image_raw`` or
        ``/ns/image_raw/compressed``), the nearest namespace first. A recording made by other tools has no
        sensor metadata: each topic is its own sensor, and only the names tie an image to its calibration.
        """
        types = self.topic_types()
        infos = [t for t, m in types.items() if m == CAMERA_INFO and self.sensor_of(t) == camera]
        if infos:
            return infos
        images = [t for t, m in types.items() if m in (IMAGE, COMPRESSED_IMAGE)
                  and (t == camera or self.sensor_of(t) == camera)]
        if camera.startswith("/") and camera not in images:  # an image topic, even one this recording lacks
            images.append(camera)
        near = []
        for t, m in types.items():
            if m == CAMERA_INFO:
                ns = t.rsplit("/", 1)[0]
                depth = max((len(ns) for img in images if img.startswith(ns + "/")), default=-1)
                if depth >= 0:
                    near.append((-depth, t))
        return [t for _, t in sorted(near)]

    @property
    def message_count(self) -> int:
        return sum(c.msgcount for c in self.connections)

    @property
    def start_ns(self) -> int:
        """Log time of the first message (0 for an empty recording)."""
        return min(r.start_time for r in self._readers) if self.message_count else 0

    @property
    def end_ns(self) -> int:
        """Log time of the last message (0 for an empty recording)."""
        return max(r.end_time for r in self._readers) if self.message_count else 0

    @property
    def duration_s(self) -> float:
        return max(self.end_ns - self.start_ns, 0) / 1e9

    def transform_tree(self, topics: Sequence[str] = ("/tf_static", "/tf")) -> TransformTree:
        """A :class:`~fusiontrack.geometry.TransformTree` of every transform on ``topics`` (those the recording has);
        a transform that cannot be used (NaN, a loop) is left out with a warning naming the recording and topic."""
        from ..geometry import TransformTree

        tree = TransformTree()
        types = self.topic_types()
        for tf_topic in topics:
            if tf_topic in types:
                for tf in self.messages([tf_topic]):
                    try:
                        tree.add_record(tf)
                    except ConfigError as err:
                        log.warning("%s %s: %s", self.paths[0], tf_topic, err)
        return tree

    def topic_types(self) -> dict[str, str]:
        """Every topic with its message type, from the recordings' connections (nothing is read).

        What a pipeline needs to pick its sensors; :meth:`topics` also counts the messages and their span, which
        for a ROS 2 recording is one pass over the whole file (about 1 s for a minute of two cameras)."""
        out: dict[str, str] = {}
        for conn in self.connections:
            out.setdefault(conn.topic, conn.msgtype)
        return dict(sorted(out.items()))  # in topic order, as topics()

    def topics(self) -> dict[str, TopicInfo]:
        """Every topic with its type, count and log-time span (read from the index where there is one; for a
        ROS 2 recording one pass over the raw messages, nothing deserialised: see :meth:`topic_types`)."""
        if self._topics is None:
            stats: dict[str, list[int]] = {}
            types: dict[str, str] = {}
            for conn in self.connections:
                types.setdefault(conn.topic, conn.msgtype)
            for conn in self.connections:
                times = self._index_times(conn)
                if times is None:
                    break
                s = stats.setdefault(conn.topic, [0, 2**63 - 1, 0])
                if times.size:
                    s[0] += int(times.size)
                    s[1] = min(s[1], int(times.min()))
                    s[2] = max(s[2], int(times.max()))
            else:
                self._topics = self._make_topics(stats, types)
                return self._topics
            # No index to read (ROS 2 storage): one pass over the raw stream, nothing deserialised.
            stats = {}
            for conn, t_ns, _ in self._raw():
                s = stats.setdefault(conn.topic, [0, t_ns, t_ns])
                s[0] += 1
                s[1] = min(s[1], t_ns)
                s[2] = max(s[2], t_ns)
            self._topics = self._make_topics(stats, types)
        return self._topics

    def _make_topics(self, stats: dict[str, list[int]], types: dict[str, str]) -> dict[str, TopicInfo]:
        out = {}
        for topic, msgtype in sorted(types.items()):
            count, t0, t1 = stats.get(topic, [0, 0, 0])
            if count == 0:
                t0 = t1 = 0
            out[topic] = TopicInfo(topic, msgtype, count, t0, t1, self.sensor_of(topic), msgtype in FROM_ROS)
        return out

    @staticmethod
    def _index_times(conn: Connection) -> np.ndarray | None:
        """Log times of a ROS 1 connection from the bag's index, without reading messages."""
        indexes = getattr(conn.owner, "indexes", None)
        if indexes is None or conn.id not in indexes:
            return None
        return np.fromiter((ix.time for ix in indexes[conn.id]), dtype=np.int64)

    # ---------------------------------------------------------------------------------------------
    def select(self, topics: Iterable[str] | None, convertible_only: bool = True) -> list[Connection]:
        """The connections of ``topics`` (all convertible ones for ``None``).

        Raises
        ------
        TopicError, MessageTypeError
            As :meth:`messages` would, so a caller can check its topics before doing anything else.
        """
        return self._select(topics, convertible_only)

    def _select(self, topics: Iterable[str] | None, convertible_only: bool) -> list[Connection]:
        conns = self.connections
        if topics is None:
            return [c for c in conns if c.msgtype in FROM_ROS] if convertible_only else conns
        wanted = list(dict.fromkeys(topics))
        have = {c.topic for c in conns}
        unknown = [t for t in wanted if t not in have]
        if unknown:
            raise TopicError(
                f"topic {', '.join(map(repr, unknown))} not in {', '.join(str(p) for p in self.paths)}; "
                f"it has: {', '.join(sorted(have)) or 'no topics'}"
            )
        chosen = [c for c in conns if c.topic in set(wanted)]
        if convertible_only:
            bad = sorted({f"{c.topic} ({c.msgtype})" for c in chosen if c.msgtype not in FROM_ROS})
            if bad:
                raise MessageTypeError(
                    f"cannot convert {', '.join(bad)}: fusiontrack reads {', '.join(sorted(FROM_ROS))}"
                )
        return chosen

    def _raw(
        self, connections: Sequence[Connection] | None = None, start_ns: int | None = None,
        stop_ns: int | None = None,
    ) -> Iterator[tuple[Connection, int, bytes]]:
        streams = []
        for reader in self._readers:
            conns = [c for c in (connections if connections is not None else reader.connections)
                     if c in reader.connections]
            if connections is not None and not conns:
                continue
            streams.append(self._guarded(reader, reader.messages(connections=conns, start=start_ns, stop=stop_ns)))
        if len(streams) == 1:
            return streams[0]
        return heapq.merge(*streams, key=lambda item: item[1])

    @staticmethod
    def _guarded(reader: AnyReader, it: Iterator[tuple[Connection, int, bytes]]) -> Iterator[Any]:
        """Turn storage failures in the middle of a file (truncation, corruption) into RecordingError."""
        try:
            yield from it
        except Exception as err:
            hint = _repair_hint(Path(reader.paths[0])) if len(reader.paths) == 1 else ""
            raise RecordingError(
                f"{', '.join(str(p) for p in reader.paths)}: reading stopped part-way "
                f"({' '.join(map(str, err.args)) or type(err).__name__}); the file is truncated or corrupt"
                + (f"; {hint}" if hint else "")
            ) from err

    def raw_messages(
        self, topics: Iterable[str] | None = None, start_ns: int | None = None, stop_ns: int | None = None,
    ) -> Iterator[tuple[str, str, int, Any]]:
        """``(topic, msgtype, log_t_ns, message)`` with messages deserialised but not converted."""
        conns = self._select(topics, convertible_only=False)
        owners = {id(c): r for r in self._readers for c in r.connections}
        for conn, t_ns, raw in self._raw(conns, start_ns, stop_ns):
            yield conn.topic, conn.msgtype, t_ns, owners[id(conn)].deserialize(raw, conn.msgtype)

    def messages(
        self,
        topics: Iterable[str] | None = None,
        *,
        start_ns: int | None = None,
        stop_ns: int | None = None,
        time_source: TimeSource = "header",
    ) -> Iterator[Message]:
        """Converted records in log-time order (:meth:`topic_messages` without the topics)."""
        for _, record in self.topic_messages(topics, start_ns=start_ns, stop_ns=stop_ns, time_source=time_source):
            yield record

    def topic_messages(
        self,
        topics: Iterable[str] | None = None,
        *,
        start_ns: int | None = None,
        stop_ns: int | None = None,
        time_source: TimeSource = "header",
    ) -> Iterator[tuple[str, Message]]:
        """``(topic, record)``: converted records in log-time order, each with the topic it was read from (a
        sensor's records of one type may come from several topics: a simulated camera's images and labels).

        With ``topics=None`` every topic of a convertible type is read (others are skipped).
        A message that cannot be deserialised or converted is skipped and counted; one warning with
        the counts is logged at the end (bad data inside a recording degrades, it does not stop it).

        Raises
        ------
        TopicError
            A requested topic is not in the recording.
        MessageTypeError
            A requested topic has a type fusiontrack cannot convert.
        RecordingError
            The storage itself fails part-way (truncated or corrupt file).
        """
        if time_source not in ("header", "log"):
            raise ValueError(f"time_source: expected 'header' or 'log', got {time_source!r}")
        conns = self._select(topics, convertible_only=True)
        yield from self._converted(self._raw(conns, start_ns, stop_ns), time_source)

    def messages_and_raw(
        self, topics: Iterable[str], raw_topics: Iterable[str], *, time_source: TimeSource = "header",
        keep_ns: int = 2_000_000_000,
    ) -> tuple[Iterator[Message], Iterator[tuple[Connection, int, bytes] | None]]:
        """Two readers of one pass over the recording: the records of ``topics`` converted (as :meth:`messages`
        reads them), and those of ``raw_topics`` as ``(connection, log time, raw bytes)``, unconverted.

        The storage is read once for both: where the records of both sets share the file's chunks (a camera's
        images between the scans), each chunk is read once instead of once per reader. Each reader may run ahead
        of the other; what one reads ahead for the other waits in memory until taken, but raw records waiting more
        than ``keep_ns`` (log time) behind the newest one read are dropped (the raw reader, e.g.
        :class:`~fusiontrack.fusion.frames.LazyFrames`, wants the records near the other reader's time, not all of
        them: a camera's images would otherwise pile up while nobody asks for one). Nor does the raw reader read
        more than ``keep_ns`` ahead of the other: it then yields ``None`` (nothing yet; ask again later) instead of
        a record.

        Raises
        ------
        TopicError, MessageTypeError
            As :meth:`messages` (for ``topics``; ``raw_topics`` need not be convertible).
        ValueError
            ``time_source`` is neither ``"header"`` nor ``"log"``.
        """
        if time_source not in ("header", "log"):
            raise ValueError(f"time_source: expected 'header' or 'log', got {time_source!r}")
        conns = self._select(topics, convertible_only=True)
        aside = [c for c in self._select(raw_topics, convertible_only=False) if c not in conns]
        split = _Split(self._raw([*conns, *aside]), {id(c) for c in aside}, keep_ns)
        converted = (record for _, record in self._converted(split.take(aside=False), time_source))
        return converted, split.take(aside=True)

    def _converted(self, raw_records: Iterator[tuple[Connection, int, bytes]], time_source: TimeSource,
                   ) -> Iterator[tuple[str, Message]]:
        """:meth:`topic_messages` of raw records."""
        owners = {id(c): r for r in self._readers for c in r.connections}
        skipped = self.skipped = Counter()
        reasons: dict[str, str] = {}
        unstamped: Counter[str] = Counter()  # header stamps of 0: the log time stands in
        read: Counter[str] = Counter()
        skew: dict[str, int] = {}  # per stamped topic, its first message's header time - log time
        for conn, log_ns, raw in raw_records:
            reader = owners[id(conn)]
            sensor = self.sensor_of(conn.topic)
            try:
                fast: Message | None = None
                if conn.msgtype == LASERSCAN:
                    fast = (laserscan_from_cdr_bytes if reader.is2 else laserscan_from_ros1_bytes)(raw, sensor)
                elif conn.msgtype == IMAGE and reader.is2:
                    fast = image_from_cdr_bytes(raw, sensor)  # the pixels a view of the raw bytes
                if fast is not None:
                    if time_source == "header":
                        read[conn.topic] += 1
                        if not fast.t_ns:
                            unstamped[conn.topic] += 1
                            fast = with_time(fast, log_ns)
                        elif conn.topic not in skew:
                            skew[conn.topic] = fast.t_ns - log_ns
                    else:
                        fast = with_time(fast, log_ns)
                    yield conn.topic, fast
                    continue
                msg = reader.deserialize(raw, conn.msgtype)
                t_ns = log_ns
                if time_source == "header" and conn.msgtype not in HEADERLESS:
                    read[conn.topic] += 1
                    t_ns = stamp_to_ns(msg.header.stamp)
                    if not t_ns:
                        unstamped[conn.topic] += 1
                        t_ns = log_ns
                    elif conn.topic not in skew:
                        skew[conn.topic] = t_ns - log_ns
                out = FROM_ROS[conn.msgtype](msg, t_ns, sensor, conn.topic)
            except Exception as err:  # one bad message must not end the stream
                skipped[conn.topic] += 1
                reasons.setdefault(conn.topic, str(err) or type(err).__name__)
                continue
            if isinstance(out, list):  # a TFMessage: one record per transform, each stamped by its own header
                for r in out:
                    yield conn.topic, r if time_source == "header" else with_time(r, log_ns)
            else:
                yield conn.topic, out
        if skipped:
            log.warning("skipped %d unreadable message(s): %s", sum(skipped.values()),
                        "; ".join(f"{t}: {n} (first: {reasons[t]})" for t, n in skipped.items()))
        # Header stamps of 0: a driver that does not stamp (every message: the log time is the clock, said at info
        # level), or stamps mixed with zeros: two clocks in one topic, which a user must hear about.
        for level, which in ((logging.WARNING, [t for t, n in unstamped.items() if n < read[t]]),
                             (logging.INFO, [t for t, n in unstamped.items() if n == read[t]])):
            if which:
                log.log(level, "header stamps of 0, the recorder's log time used instead: %s",
                        "; ".join(f"{t}: {unstamped[t]} of {read[t]} messages"
                                  + (" (the others are stamped: two clocks in one topic)" if level == logging.WARNING
                                     else "") for t in which))
        # a topic never stamped reads the recorder's clock; if the stamped topics' header times are far from their
        # log times (a bag re-recorded later, a sensor's own clock), the two sets of times do not line up
        apart = {t: d for t, d in skew.items() if abs(d) > 1_000_000_000}
        never = [t for t, n in unstamped.items() if n == read[t]]
        if never and apart:
            log.warning("%s: never stamped, read at the recorder's log times, while the header times of %s are up "
                        "to %s from their log times: two clocks; read with --time log (time_source='log') to put "
                        "every topic on the recorder's clock", ", ".join(never), ", ".join(sorted(apart)),
                        _span_text(max(abs(d) for d in apart.values())))


PAUSE = None  # what the raw reader of :meth:`Recording.messages_and_raw` yields when it may not read further yet


class _Split:
    """One stream of raw records read by two readers (:meth:`Recording.messages_and_raw`): the records of the
    ``aside`` connections for one, the others for the other; a record read by one for the other waits in a queue.

    The set-aside reader may not run more than ``keep_ns`` (log time) ahead of the other: when the records it has
    queued for the other span more, it yields :data:`PAUSE` instead of reading on (a camera that stops sending
    would otherwise make it read, and queue, the rest of the recording's scans while looking for its next image);
    asked again later, it goes on from where it stopped."""

    def __init__(self, records: Iterator[tuple[Connection, int, bytes]], aside: set[int], keep_ns: int) -> None:
        self._records = records
        self._aside_ids = aside
        self._keep_ns = int(keep_ns)
        self._queues: tuple[deque[tuple[Connection, int, bytes]], deque[tuple[Connection, int, bytes]]] = (
            deque(), deque())

    def take(self, aside: bool) -> Iterator[tuple[Connection, int, bytes] | None]:
        queue = self._queues[aside]
        other = self._queues[not aside]
        while True:
            while not queue:
                if aside and other and other[-1][1] - other[0][1] > self._keep_ns:
                    yield PAUSE
                    continue
                item = next(self._records, None)
                if item is None:
                    return
                mine = id(item[0]) in self._aside_ids
                self._queues[mine].append(item)
                if mine and not aside:
                    waiting = self._queues[True]
                    while len(waiting) > 1 and item[1] - waiting[0][1] > self._keep_ns:
                        waiting.popleft()
            yield queue.popleft()


def _span_text(ns: int) -> str:
    s = ns / 1e9
    return f"{s / 86400:.1f} days" if s >= 86400 else f"{s / 3600:.1f} h" if s >= 3600 else f"{s:.1f} s"


def open_recording(paths: str | Path | Sequence[str | Path], **kwargs: Any) -> Recording:
    """Open one or several recordings as one stream (see :class:`Recording`)."""
    return Recording(paths, **kwargs)
