"""Reading video files as time-stamped :class:`~fusiontrack.types.Image` records, and writing videos.

Frame times (``t_ns`` of frame ``i``, 0-based), in order of precedence:

1. ``times_csv`` given: the times in that file (the usual companion of a real recording), one per frame.
2. ``fps`` given: ``start_ns + round(i * 1e9 / fps)``.
3. otherwise the container's nominal rate (``CAP_PROP_FPS``): ``start_ns + round(i * 1e9 / fps)``.

The decoder's own per-frame position (``CAP_PROP_POS_MSEC``) is deliberately not used: with FFmpeg
it is the time of the next packet in decoding order, not of the frame just decoded. On the PETS 2009
sample (H.264 in AVI, 10 fps) it reads 200 ms after frame 0, 300 ms after frame 1, and 0 ms after the
last frame. A constant nominal rate is exact for the fixed-rate cameras and files fusiontrack meets;
for variable-rate video, give ``times_csv``.

``times_csv`` holds one integer nanosecond time per line, or ``frame,t_ns`` pairs (frames 0-based,
or 1-based when the first is 1, consecutive); a header line and ``#`` comments are allowed. Times
must increase strictly, and there must be exactly one per frame.
"""

from __future__ import annotations

import contextlib
import logging
import os
import sys
from collections.abc import Iterable, Iterator
from pathlib import Path
from types import TracebackType

import cv2
import numpy as np

from ..errors import ConfigError, RecordingError
from ..types import Image
from .csvtable import read_numeric_table

__all__ = ["VIDEO_WRITE_SUFFIXES", "VideoReader", "check_video_output", "read_frame_times_csv", "write_video"]

logger = logging.getLogger(__name__)

_EXPECTED = "a video file OpenCV (FFmpeg) can decode, e.g. .avi or .mp4"


def read_frame_times_csv(path: str | Path) -> np.ndarray:
    """Read per-frame times: one ``t_ns`` per line, or ``frame,t_ns`` (see the module docstring).

    Returns
    -------
    (n_frames,) int64
        Time of frame ``i`` in nanoseconds, strictly increasing.

    Raises
    ------
    RecordingError
        Missing file, bad line (file and line named), frames not consecutive, or times not increasing.
    """
    path = Path(path)
    what = "one integer t_ns per line, or frame,t_ns"
    try:
        with path.open(encoding="utf-8") as f:
            first = next((line for line in f if line.strip() and not line.lstrip().startswith("#")), "")
    except FileNotFoundError as err:
        raise RecordingError(f"{path}: no such file (expected frame times: {what})") from err
    except (OSError, UnicodeDecodeError) as err:
        raise RecordingError(f"{path}: cannot be read (expected frame times: {what})") from err
    has_header = any(ch.isalpha() for ch in first)
    n_cols = len(first.split(","))
    if n_cols not in (1, 2):
        raise RecordingError(f"{path}: {n_cols} columns; expected {what}")
    table = read_numeric_table(path, n_cols=n_cols, int_cols=range(n_cols), header=has_header, what=what)
    t_ns = table.ints[n_cols - 1]
    if n_cols == 2:
        frames = table.ints[0]
        expected = np.arange(frames.size, dtype=np.int64) + (1 if frames[0] == 1 else 0)
        bad = np.flatnonzero(frames != expected)
        if bad.size:
            i = int(bad[0])
            raise RecordingError(f"{path}, line {int(table.line_numbers[i])}: frame {int(frames[i])}, "
                                 f"expected {int(expected[i])} (frames must be consecutive from 0 or 1)")
    back = np.flatnonzero(np.diff(t_ns) <= 0)
    if back.size:
        i = int(back[0]) + 1
        raise RecordingError(f"{path}, line {int(table.line_numbers[i])}: t_ns {int(t_ns[i])} is not after "
                             f"the previous frame's {int(t_ns[i - 1])}; expected strictly increasing times")
    return t_ns


def _nominal_times_ns(n: int, fps: float, start_ns: int, first: int = 0) -> np.ndarray:
    """``start_ns + round(i * 1e9 / fps)`` for ``i`` in ``first .. first + n - 1``, ``(n,) int64``."""
    i = np.arange(first, first + n, dtype=np.float64)
    return start_ns + np.rint(i * (1e9 / fps)).astype(np.int64)


class VideoReader:
    """A video file as an iterable of time-stamped BGR :class:`~fusiontrack.types.Image` records.

    Each iteration decodes the file from the start with its own ``cv2.VideoCapture``; the reader
    itself only keeps the metadata. Use it as a context manager to release a capture left open by an
    iteration stopped early.

    Parameters
    ----------
    path : str or Path
        The video file.
    sensor : str
        ``sensor`` of every image.
    frame_id : str, optional
        ``frame_id`` of every image (the camera's optical frame); defaults to ``sensor``.
    start_ns : int
        Time of frame 0 in nanoseconds when times come from a frame rate.
    fps : float, optional
        Frame rate overriding the container's (frames per second).
    times_csv : str or Path, optional
        Per-frame times overriding both (see the module docstring).

    Raises
    ------
    RecordingError
        The file is missing, OpenCV cannot open or decode it, the container gives no frame rate and
        neither ``fps`` nor ``times_csv`` is given, or ``times_csv`` does not have one time per frame.
    ConfigError
        ``fps`` is not positive.
    """

    def __init__(
        self,
        path: str | Path,
        sensor: str = "camera",
        frame_id: str | None = None,
        start_ns: int = 0,
        fps: float | None = None,
        times_csv: str | Path | None = None,
    ) -> None:
        self.path = Path(path)
        self.sensor = sensor
        self.frame_id = sensor if frame_id is None else frame_id
        self.start_ns = int(start_ns)
        if fps is not None and not (np.isfinite(fps) and fps > 0):
            raise ConfigError(f"fps: expected a positive frame rate, got {fps!r}")
        if not self.path.is_file():
            what = "is a folder" if self.path.is_dir() else "no such file"
            raise RecordingError(f"{self.path}: {what} (expected {_EXPECTED})")
        self._caps: list[cv2.VideoCapture] = []

        cap = self._open()
        try:
            container_fps = float(cap.get(cv2.CAP_PROP_FPS))
            count = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
            ok, first = cap.read()
            if not ok or first is None:
                raise RecordingError(f"{self.path}: OpenCV opened the file but cannot decode a frame "
                                     f"(expected {_EXPECTED})")
            if count <= 0:  # streams and some containers do not say; count by decoding
                count = 1
                while cap.grab():
                    count += 1
        finally:
            self._release(cap)
        self._height, self._width = (int(n) for n in first.shape[:2])
        self._frame_count = count
        self._container_fps = container_fps if np.isfinite(container_fps) and container_fps > 0 else None

        times: np.ndarray | None = None
        if times_csv is not None:
            times = read_frame_times_csv(times_csv)
            if times.size != count:
                raise RecordingError(f"{times_csv}: {times.size} frame times for {count} frames in "
                                     f"{self.path} (expected one time per frame)")
        if fps is not None:
            self._fps = float(fps)
        elif self._container_fps is not None:
            self._fps = self._container_fps
        elif times is not None and count > 1:
            self._fps = float(1e9 / np.median(np.diff(times)))
        else:
            raise RecordingError(f"{self.path}: the container gives no frame rate; pass fps= or times_csv=")
        self._times_from_csv = times is not None
        self._times_ns = times if times is not None else _nominal_times_ns(count, self._fps, self.start_ns)
        self._times_ns.setflags(write=False)
        logger.debug("%s: %d frames %dx%d at %.3f fps", self.path, count, self._width, self._height,
                     self._fps)

    # -- metadata ---------------------------------------------------------------------------------

    @property
    def fps(self) -> float:
        """Frame rate in frames per second (the override, else the container's, else from ``times_csv``)."""
        return self._fps

    @property
    def frame_count(self) -> int:
        """Number of frames as the container states it (counted by decoding when it does not)."""
        return self._frame_count

    @property
    def width(self) -> int:
        """Frame width in pixels (of a decoded frame)."""
        return self._width

    @property
    def height(self) -> int:
        """Frame height in pixels (of a decoded frame)."""
        return self._height

    @property
    def duration_s(self) -> float:
        """``frame_count / fps`` in seconds: the span of the frame times plus one frame period."""
        return self._frame_count / self._fps

    def frame_times_ns(self) -> np.ndarray:
        """Time of every frame, ``(frame_count,) int64`` nanoseconds (read-only)."""
        return self._times_ns

    def __len__(self) -> int:
        return self._frame_count

    def count_decodable(self) -> int:
        """The frames that can be decoded: :attr:`frame_count` when the container's last frame decodes (one seek),
        else counted by decoding from the start (a truncated file: the container states the frames it was meant
        to hold)."""
        cap = self._open()
        try:
            with _native_stderr_off():  # (FFmpeg complains on stderr of a seek into a damaged stream)
                cap.set(cv2.CAP_PROP_POS_FRAMES, self._frame_count - 1)
                if cap.grab():
                    return self._frame_count
                cap.set(cv2.CAP_PROP_POS_FRAMES, 0)
                n = 0
                while cap.grab():
                    n += 1
            return n
        finally:
            self._release(cap)

    # -- decoding ---------------------------------------------------------------------------------

    def _open(self) -> cv2.VideoCapture:
        cap = cv2.VideoCapture(str(self.path))
        if not cap.isOpened():
            cap.release()
            raise RecordingError(f"{self.path}: OpenCV cannot open this file (expected {_EXPECTED})")
        self._caps.append(cap)
        return cap

    def _release(self, cap: cv2.VideoCapture) -> None:
        cap.release()
        if cap in self._caps:
            self._caps.remove(cap)

    def __iter__(self) -> Iterator[Image]:
        """Decode every frame, in order, as ``Image(t_ns, sensor, frame_id, (H, W, 3) uint8, "bgr8")``."""
        times = self.frame_times_ns()
        cap = self._open()
        try:
            i = 0
            while True:
                ok, pixels = cap.read()
                if not ok:
                    break
                if i < times.size:
                    t_ns = int(times[i])
                elif self._times_from_csv:
                    raise RecordingError(f"{self.path}: decoded more frames than the {times.size} "
                                         "frame times given")
                else:
                    t_ns = int(_nominal_times_ns(1, self._fps, self.start_ns, first=i)[0])
                yield Image(t_ns, self.sensor, self.frame_id, pixels, "bgr8")
                i += 1
            if i != self._frame_count:
                logger.warning("%s: decoded %d frames, the container states %d", self.path, i,
                               self._frame_count)
        finally:
            self._release(cap)

    def close(self) -> None:
        """Release any capture an unfinished iteration left open."""
        for cap in list(self._caps):
            self._release(cap)

    def __enter__(self) -> VideoReader:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    def __repr__(self) -> str:
        return (f"VideoReader({str(self.path)!r}, sensor={self.sensor!r}, {self._frame_count} frames "
                f"{self._width}x{self._height} @ {self._fps:g} fps)")


# The codec each supported suffix gets: what opencv-python's FFmpeg can encode (checked with 5.0.0, whose wheel
# has no H.264 (``avc1``/``H264``) encoder), so ``.mp4`` gets MPEG-4 Part 2, which desktop players
# read but browsers do not; ``.webm`` (VP8) is the one a browser's <video> plays.
_FOURCC_BY_SUFFIX = {".mp4": "mp4v", ".m4v": "mp4v", ".mov": "mp4v", ".avi": "MJPG", ".mkv": "MJPG",
                     ".webm": "VP80"}
VIDEO_WRITE_SUFFIXES = tuple(_FOURCC_BY_SUFFIX)
"""The file suffixes :func:`write_video` picks a codec for."""


@contextlib.contextmanager
def _native_stderr_off() -> Iterator[None]:
    """Silence the process's stderr (file descriptor 2) for a moment: OpenCV's FFmpeg writes a harmless notice
    there when it opens VP8 in WebM (``tag 0x30385056/'VP80' is not supported with codec id 139``), and the file
    it writes is fine."""
    sys.stderr.flush()
    try:
        saved = os.dup(2)
    except OSError:  # no stderr to silence
        yield
        return
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        os.close(devnull)


def check_video_output(path: str | Path, fourcc: str | None = None) -> str:
    """Check that :func:`write_video` can create ``path``, before any frame is made; returns the fourcc.

    Raises
    ------
    ConfigError
        ``path`` is a folder, has no suffix or one without a codec (when ``fourcc`` is not given), or its
        folder does not exist; ``fourcc`` is not four characters. The message names the path.
    """
    path = Path(path)
    supported = ", ".join(VIDEO_WRITE_SUFFIXES)
    if path.is_dir():
        raise ConfigError(f"{path}: is a folder; expected a video file name ending in one of {supported} "
                          f"(e.g. {path / 'video.mp4'})")
    suffix = path.suffix.lower()
    if fourcc is None and suffix not in _FOURCC_BY_SUFFIX:
        what = f"suffix {path.suffix!r} is not a video format fusiontrack writes" if suffix else "no file suffix"
        raise ConfigError(f"{path}: {what}; expected one of {supported}")
    if fourcc is not None and not suffix:
        raise ConfigError(f"{path}: no file suffix (the suffix picks the container); expected e.g. {supported}")
    code = fourcc if fourcc is not None else _FOURCC_BY_SUFFIX[suffix]
    if len(code) != 4:
        raise ConfigError(f"fourcc: expected four characters, got {code!r}")
    if not path.parent.is_dir():
        what = "is a file, not a folder" if path.parent.exists() else "does not exist"
        raise ConfigError(f"{path}: folder {path.parent} {what} (create it first; cannot write the video)")
    return code


def write_video(
    path: str | Path, frames_bgr: Iterable[np.ndarray | Image], fps: float, fourcc: str | None = None
) -> int:
    """Write frames to a video file with OpenCV (works with opencv-python-headless).

    Parameters
    ----------
    path : str or Path
        Output file; its folder must exist. The suffix picks the codec unless ``fourcc`` is given:
        ``.mp4``/``.m4v``/``.mov`` -> ``mp4v`` (MPEG-4 Part 2, which browsers do not play),
        ``.avi``/``.mkv`` -> ``MJPG``, ``.webm`` -> ``VP80`` (VP8, which browsers play; several times
        slower to encode). Other suffixes are refused unless ``fourcc`` is given. The video is written beside
        it under a hidden name and renamed onto it once complete: a write stopped part way (an error, Ctrl-C)
        leaves ``path`` as it was, e.g. an earlier run's video, and no partial file.
    frames_bgr : iterable of (H, W, 3) uint8 BGR arrays, (H, W) uint8 grey arrays or Image records
        All of the size of the first frame.
    fps : float
        Frame rate stored in the container.
    fourcc : str, optional
        Four-character codec code overriding the choice by suffix.

    Returns
    -------
    int
        Number of frames written.

    Raises
    ------
    ConfigError
        Before any frame is read: ``path`` is a folder, its suffix is not supported, its folder does not
        exist (see :func:`check_video_output`), ``fps`` not positive or ``fourcc`` not four characters.
        While writing: no frames, or a frame of the wrong size or type.
    RecordingError
        OpenCV cannot encode with the codec (its build lacks the encoder, or the container refuses it).
    """
    path = Path(path)
    if not (np.isfinite(fps) and fps > 0):
        raise ConfigError(f"fps: expected a positive frame rate, got {fps!r}")
    code = check_video_output(path, fourcc)
    # written beside ``path`` under a hidden name (same suffix: OpenCV picks the container by it) and renamed onto
    # it at the end: a run stopped part way (an error, Ctrl-C) leaves neither a truncated video nor a loss of the
    # one an earlier run wrote there
    target = path.resolve() if path.is_symlink() else path  # a linked video is rewritten, the link kept
    partial = target.with_name(f".{target.stem}.{os.getpid()}.partial{target.suffix}")
    writer: cv2.VideoWriter | None = None
    size: tuple[int, int] | None = None
    n = 0
    done = False
    try:
        for frame in frames_bgr:
            pixels = frame.bgr() if isinstance(frame, Image) else np.asarray(frame)
            grey_or_bgr = pixels.ndim == 2 or (pixels.ndim == 3 and pixels.shape[2] == 3)
            if pixels.dtype != np.uint8 or not grey_or_bgr:
                raise ConfigError(f"frames_bgr[{n}]: expected an (H, W, 3) or (H, W) uint8 array, "
                                  f"got {pixels.shape} {pixels.dtype}")
            if pixels.ndim == 2:
                pixels = cv2.cvtColor(pixels, cv2.COLOR_GRAY2BGR)
            if writer is None:
                size = (int(pixels.shape[1]), int(pixels.shape[0]))
                with _native_stderr_off() if code.upper() == "VP80" else contextlib.nullcontext():
                    writer = cv2.VideoWriter(str(partial), cv2.VideoWriter_fourcc(*code), float(fps), size)
                if not writer.isOpened():
                    hint = "another fourcc" if fourcc is not None else "another suffix, e.g. .avi or .mp4"
                    raise RecordingError(f"{path}: OpenCV cannot write a video with codec {code!r} "
                                         f"(this OpenCV build may lack its encoder; try {hint})")
            elif (pixels.shape[1], pixels.shape[0]) != size:
                raise ConfigError(f"frames_bgr[{n}]: size {pixels.shape[1]}x{pixels.shape[0]}, expected "
                                  f"{size[0]}x{size[1]} like the first frame")
            writer.write(np.ascontiguousarray(pixels))
            n += 1
        if n == 0:
            raise ConfigError("frames_bgr: no frames to write")
        writer.release()  # (n > 0: the writer was opened) the container is complete only once released
        writer = None
        os.replace(partial, target)
        done = True
    finally:
        if writer is not None:
            writer.release()
        if not done:
            partial.unlink(missing_ok=True)
    logger.debug("%s: wrote %d frames at %g fps (%s)", path, n, fps, code)
    return n
