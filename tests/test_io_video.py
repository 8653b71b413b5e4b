"""Video reading (frame times, metadata, errors) against the PETS 2009 sample, and write/read round trips."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np
import pytest

from fusiontrack.errors import ConfigError, RecordingError
from fusiontrack.io.video import (
    VIDEO_WRITE_SUFFIXES,
    VideoReader,
    check_video_output,
    read_frame_times_csv,
    write_video,
)
from fusiontrack.types import Image

SHARED_DATA = (Path(__file__).resolve().parents[1] / ".." / "shared" / "data").resolve()  # as conftest.py
PETS = SHARED_DATA / "video/pets09_s2l1/vtest_pets09_s2l1_480x360.avi"
needs_pets = pytest.mark.skipif(not PETS.is_file(), reason="PETS 2009 sample video not available")


def _frames(n: int, h: int = 48, w: int = 64) -> list[np.ndarray]:
    """Frames of distinct flat grey levels with a bright square moving right (smooth, codec-friendly)."""
    out = []
    for i in range(n):
        f = np.full((h, w, 3), 20 + 10 * i, np.uint8)
        f[8:24, 4 * i:4 * i + 16] = (250, 200, 150)
        out.append(f)
    return out


# -- the PETS sample: facts from its README ----------------------------------------------------------


@needs_pets
def test_pets_metadata_matches_readme() -> None:
    # README: 795 frames, 480x360, 10 fps nominal
    with VideoReader(PETS) as video:
        assert video.frame_count == len(video) == 795
        assert (video.width, video.height) == (480, 360)
        assert video.fps == pytest.approx(10.0)
        assert video.duration_s == pytest.approx(79.5)
        t = video.frame_times_ns()
        assert t.dtype == np.int64
        assert t.shape == (795,)
        np.testing.assert_array_equal(t[:3], [0, 100_000_000, 200_000_000])
        assert t[-1] == 794 * 100_000_000
        assert not t.flags.writeable


@needs_pets
def test_pets_decodes_every_frame_with_its_time() -> None:
    video = VideoReader(PETS, sensor="cam_front", start_ns=1_000)
    images = list(video)
    assert len(images) == 795
    first = images[0]
    assert isinstance(first, Image)
    assert (first.sensor, first.frame_id, first.encoding) == ("cam_front", "cam_front", "bgr8")
    assert first.pixels.shape == (360, 480, 3)
    assert first.pixels.dtype == np.uint8
    np.testing.assert_array_equal([im.t_ns for im in images], video.frame_times_ns())
    assert images[0].t_ns == 1_000


@needs_pets
def test_fps_override_and_early_stop_releases_capture() -> None:
    with VideoReader(PETS, fps=25.0, frame_id="cam_optical") as video:
        assert video.fps == 25.0
        assert video.duration_s == pytest.approx(795 / 25)
        it = iter(video)
        a, b = next(it), next(it)
        assert (a.t_ns, b.t_ns) == (0, 40_000_000)
        assert a.frame_id == "cam_optical"
        assert len(video._caps) == 1  # the iteration's capture is open
    assert video._caps == []  # ... and the context manager released it


@needs_pets
def test_times_csv_overrides_times(tmp_path: Path) -> None:
    times = 1_700_000_000_000_000_000 + np.arange(795, dtype=np.int64) * 99_999_937
    one_col = tmp_path / "times.csv"
    one_col.write_text("\n".join(str(t) for t in times) + "\n")
    with VideoReader(PETS, times_csv=one_col) as video:
        np.testing.assert_array_equal(video.frame_times_ns(), times)  # exact beyond 2**53
        assert video.fps == pytest.approx(10.0)  # still the container's rate
        assert next(iter(video)).t_ns == times[0]
    pairs = tmp_path / "pairs.csv"
    pairs.write_text("frame,t_ns\n" + "".join(f"{i + 1},{t}\n" for i, t in enumerate(times)))
    np.testing.assert_array_equal(VideoReader(PETS, times_csv=pairs).frame_times_ns(), times)


@needs_pets
def test_times_csv_length_mismatch_is_an_error(tmp_path: Path) -> None:
    short = tmp_path / "short.csv"
    short.write_text("".join(f"{i * 100}\n" for i in range(794)))
    with pytest.raises(RecordingError, match=r"short\.csv: 794 frame times for 795 frames"):
        VideoReader(PETS, times_csv=short)


def test_read_frame_times_csv_errors(tmp_path: Path) -> None:
    p = tmp_path / "t.csv"
    p.write_text("# frame times\n0,10\n1,20\n3,30\n")
    with pytest.raises(RecordingError, match=r"t\.csv, line 4: frame 3, expected 2"):
        read_frame_times_csv(p)
    p.write_text("10\n20\n20\n")
    with pytest.raises(RecordingError, match=r"line 3: .*strictly increasing"):
        read_frame_times_csv(p)
    p.write_text("10\n2x0\n")
    with pytest.raises(RecordingError, match=r"t\.csv, line 2, column 1: expected an integer"):
        read_frame_times_csv(p)
    p.write_text("10\n20,5\n")
    with pytest.raises(RecordingError, match=r"line 2: expected 1 comma-separated"):
        read_frame_times_csv(p)
    with pytest.raises(RecordingError, match="no such file"):
        read_frame_times_csv(tmp_path / "none.csv")
    p.write_text("0,10\n1,20\n")
    np.testing.assert_array_equal(read_frame_times_csv(p), [10, 20])


# -- errors ----------------------------------------------------------------------------------------


def test_missing_file_names_path(tmp_path: Path) -> None:
    missing = tmp_path / "nope.avi"
    with pytest.raises(RecordingError, match=r"nope\.avi: no such file \(expected a video file"):
        VideoReader(missing)
    with pytest.raises(RecordingError, match="is a folder"):
        VideoReader(tmp_path)


def test_undecodable_file_names_path(tmp_path: Path) -> None:
    junk = tmp_path / "junk.mp4"
    junk.write_bytes(b"this is not a video" * 100)
    with pytest.raises(RecordingError, match=r"junk\.mp4: OpenCV cannot (open|decode).*expected a video file"):
        VideoReader(junk)


def test_bad_fps_argument(tmp_path: Path) -> None:
    path = tmp_path / "v.avi"
    write_video(path, _frames(2), fps=5)
    with pytest.raises(ConfigError, match="fps"):
        VideoReader(path, fps=0)


# -- writing -----------------------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["clip.mp4", "clip.avi"])
def test_write_read_round_trip(tmp_path: Path, name: str) -> None:
    frames = _frames(9)
    path = tmp_path / name
    assert write_video(path, iter(frames), fps=12.5) == 9
    with VideoReader(path, sensor="overlay") as video:
        assert video.frame_count == 9
        assert (video.width, video.height) == (64, 48)
        assert video.fps == pytest.approx(12.5)
        images = list(video)
    assert len(images) == 9
    assert [im.t_ns for im in images] == [round(i * 1e9 / 12.5) for i in range(9)]
    for im, f in zip(images, frames, strict=True):
        # lossy codecs: close, and each frame still the brightest where its square was
        assert np.abs(im.pixels.astype(int) - f).mean() < 6
        assert im.pixels[8:24].mean() > im.pixels[30:].mean()


def test_write_accepts_images_and_grey(tmp_path: Path) -> None:
    grey = [np.full((32, 40), v, np.uint8) for v in (0, 128, 255)]
    records = [Image(i, "cam", "cam", np.full((32, 40, 3), 90, np.uint8), "rgb8") for i in range(2)]
    path = tmp_path / "mixed.avi"
    assert write_video(path, [*grey, *records], fps=10, fourcc="MJPG") == 5
    video = VideoReader(path)
    assert (video.frame_count, video.width, video.height) == (5, 40, 32)


def test_write_errors(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="no frames"):
        write_video(tmp_path / "empty.avi", [], fps=10)
    with pytest.raises(ConfigError, match=r"frames_bgr\[1\]: size 10x10, expected 64x48"):
        write_video(tmp_path / "sizes.avi", [_frames(1)[0], np.zeros((10, 10, 3), np.uint8)], fps=10)
    with pytest.raises(ConfigError, match=r"frames_bgr\[0\]: expected an \(H, W, 3\)"):
        write_video(tmp_path / "float.avi", [np.zeros((10, 10, 3))], fps=10)
    with pytest.raises(ConfigError, match="fps"):
        write_video(tmp_path / "fps.avi", _frames(1), fps=-1)


@pytest.mark.parametrize("stop", [KeyboardInterrupt, RuntimeError])
def test_a_write_stopped_part_way_keeps_the_earlier_video_and_leaves_no_partial_file(tmp_path: Path,
                                                                                     stop: type) -> None:
    path = tmp_path / "tracks.mp4"
    assert write_video(path, _frames(4), fps=10) == 4
    before = path.read_bytes()

    def frames_then_stop() -> Iterator[np.ndarray]:
        yield from _frames(6)
        raise stop("stopped")

    with pytest.raises(stop):
        write_video(path, frames_then_stop(), fps=10)
    assert path.read_bytes() == before  # the earlier run's video, whole
    assert sorted(p.name for p in tmp_path.iterdir()) == ["tracks.mp4"]
    with VideoReader(path) as video:
        assert video.frame_count == 4
    # a bad frame part way, and a first write that stops: nothing at all is left
    with pytest.raises(ConfigError):
        write_video(tmp_path / "new.avi", [_frames(1)[0], np.zeros((10, 10, 3), np.uint8)], fps=10)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["tracks.mp4"]
    # and a complete write replaces the earlier video
    assert write_video(path, _frames(7), fps=10) == 7
    with VideoReader(path) as video:
        assert video.frame_count == 7
    assert sorted(p.name for p in tmp_path.iterdir()) == ["tracks.mp4"]
    # through a symlink: the linked video is rewritten, the link kept (it was replaced by a file)
    link = tmp_path / "links" / "latest.mp4"
    link.parent.mkdir()
    link.symlink_to(path)
    assert write_video(link, _frames(5), fps=10) == 5
    assert link.is_symlink()
    with VideoReader(path) as video:
        assert video.frame_count == 5
    assert sorted(p.name for p in link.parent.iterdir()) == ["latest.mp4"]


def _never_read() -> Iterator[np.ndarray]:
    raise AssertionError("write_video read a frame before checking its output path")
    yield np.zeros((1, 1, 3), np.uint8)


def test_write_to_a_folder_is_a_config_error_naming_it(tmp_path: Path) -> None:
    folder = tmp_path / "videos"
    folder.mkdir()
    with pytest.raises(ConfigError) as err:
        write_video(folder, _never_read(), fps=10)
    assert str(err.value).startswith(f"{folder}: is a folder")
    assert ".mp4" in str(err.value)  # says what to give instead
    assert list(folder.iterdir()) == []


@pytest.mark.parametrize("name", ["out.gif", "out", "out.MP3"])
def test_write_with_an_unsupported_suffix_lists_the_supported_ones(tmp_path: Path, name: str) -> None:
    path = tmp_path / name
    with pytest.raises(ConfigError) as err:
        write_video(path, _never_read(), fps=10)
    message = str(err.value)
    assert message.startswith(f"{path}: ")
    assert ("no file suffix" if name == "out" else f"suffix {path.suffix!r}") in message
    for suffix in VIDEO_WRITE_SUFFIXES:
        assert suffix in message
    assert "MJPG" not in message
    assert not path.exists()


def test_write_into_a_missing_folder_names_the_folder(tmp_path: Path) -> None:
    path = tmp_path / "no_dir" / "x.avi"
    with pytest.raises(ConfigError) as err:
        write_video(path, _never_read(), fps=10)
    assert str(err.value).startswith(f"{path}: folder {tmp_path / 'no_dir'} does not exist")
    assert not (tmp_path / "no_dir").exists()


@pytest.mark.parametrize(("name", "in_file"), [("a.MP4", b"FMP4"), ("a.avi", b"MJPG"), ("a.webm", b"VP80")])
def test_the_suffix_picks_the_codec_in_any_case(tmp_path: Path, name: str, in_file: bytes) -> None:
    """What OpenCV reads back from the written file: MPEG-4 Part 2 (FFmpeg's FMP4) in .mp4, Motion JPEG in .avi, VP8
    in .webm (the one browsers play)."""
    write_video(tmp_path / name, _frames(3), fps=10)
    cap = cv2.VideoCapture(str(tmp_path / name))
    try:
        assert int(cap.get(cv2.CAP_PROP_FOURCC)).to_bytes(4, "little").upper() == in_file
        assert int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) == 3
    finally:
        cap.release()


def test_an_explicit_codec_is_the_callers_and_must_be_four_characters(tmp_path: Path) -> None:
    assert check_video_output(tmp_path / "a.gif", fourcc="MJPG") == "MJPG"  # an explicit codec: the caller's call
    with pytest.raises(ConfigError, match="fourcc: expected four characters"):
        check_video_output(tmp_path / "a.avi", fourcc="MJPEG")


def test_a_codec_opencv_cannot_encode_is_a_recording_error_without_a_suffix_hint(tmp_path: Path) -> None:
    # "ZZZZ" is no codec FFmpeg knows: the writer does not open
    path = tmp_path / "x.avi"
    with pytest.raises(RecordingError) as err:
        write_video(path, _frames(2), fps=10, fourcc="ZZZZ")
    message = str(err.value)
    assert message.startswith(f"{path}: OpenCV cannot write a video with codec 'ZZZZ'")
    assert "another fourcc" in message
    assert "suffix" not in message


def test_webm_round_trip_is_vp8_in_a_webm_container(tmp_path: Path) -> None:
    path = tmp_path / "clip.webm"
    try:
        write_video(path, _frames(6), fps=10)
    except RecordingError:
        pytest.skip("this OpenCV build cannot encode VP8")
    head = path.read_bytes()[:64]
    assert head[:4] == b"\x1a\x45\xdf\xa3"  # EBML magic (Matroska/WebM)
    assert b"webm" in head  # DocType
    cap = cv2.VideoCapture(str(path))
    fourcc = int(cap.get(cv2.CAP_PROP_FOURCC))
    cap.release()
    assert fourcc.to_bytes(4, "little") == b"VP80"
    with VideoReader(path) as video:
        assert (video.frame_count, video.width, video.height) == (6, 64, 48)
        images = list(video)
    for im, f in zip(images, _frames(6), strict=True):
        assert np.abs(im.pixels.astype(int) - f).mean() < 6
