"""The HTML report's videos: a browser-playable WebM (VP8) copy beside each linked video, checked by reading it back.

Browsers play VP8/VP9 in WebM and H.264 in MP4, not the MPEG-4 Part 2 (``mp4v``) that ``.mp4`` files written
with opencv-python hold; what a written file holds is read from the file itself (its EBML header and the
decoder's fourcc), not taken from the code.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import cv2
import numpy as np
import pytest

from fusiontrack.errors import RecordingError
from fusiontrack.io.video import write_video
from fusiontrack.viz.report import Report, browser_video

_SOURCE = re.compile(r"<source src='([^']+)'(?: type='([^']+)')?>")


def _frames(n: int, h: int = 48, w: int = 64) -> list[np.ndarray]:
    out = []
    for i in range(n):
        f = np.full((h, w, 3), 30 + 8 * i, np.uint8)
        f[10:26, 3 * i:3 * i + 16] = (240, 190, 140)
        out.append(f)
    return out


def _fourcc(path: Path) -> bytes:
    cap = cv2.VideoCapture(str(path))
    try:
        return int(cap.get(cv2.CAP_PROP_FOURCC)).to_bytes(4, "little")
    finally:
        cap.release()


def _frame_count(path: Path) -> int:
    cap = cv2.VideoCapture(str(path))
    n = 0
    while cap.read()[0]:
        n += 1
    cap.release()
    return n


@pytest.fixture(scope="module")
def vp8(tmp_path_factory: pytest.TempPathFactory) -> None:
    """Skip when this OpenCV build has no VP8 encoder."""
    try:
        write_video(tmp_path_factory.mktemp("probe") / "p.webm", _frames(2), fps=10)
    except RecordingError:
        pytest.skip("this OpenCV build cannot encode VP8 (WebM)")


def test_report_embeds_a_webm_vp8_copy_first_and_the_mp4_second(tmp_path: Path, vp8: None) -> None:
    (tmp_path / "videos").mkdir()
    write_video(tmp_path / "videos" / "tracks.mp4", _frames(7), fps=12.5)
    assert _fourcc(tmp_path / "videos" / "tracks.mp4") in (b"FMP4", b"mp4v")  # MPEG-4 Part 2: browsers do not play it
    rep = Report("t")
    rep.video("Bird's-eye view", "videos/tracks.mp4")
    html = rep.write(tmp_path / "report.html").read_text()
    assert _SOURCE.findall(html) == [("videos/tracks.webm", "video/webm"), ("videos/tracks.mp4", "video/mp4")]
    webm = tmp_path / "videos" / "tracks.webm"
    head = webm.read_bytes()[:64]
    assert head[:4] == b"\x1a\x45\xdf\xa3"  # EBML magic: a Matroska/WebM file
    assert b"webm" in head  # ... whose DocType is webm
    assert _fourcc(webm) == b"VP80"
    assert _frame_count(webm) == 7
    cap = cv2.VideoCapture(str(webm))
    assert cap.get(cv2.CAP_PROP_FPS) == pytest.approx(12.5)
    ok, first = cap.read()
    cap.release()
    assert ok
    assert np.abs(first.astype(int) - _frames(1)[0]).mean() < 6  # the same picture
    assert "<a href='videos/tracks.mp4' download>" in html  # the original stays one click away
    assert "class='warning'" not in html


def test_copy_is_reused_while_current_and_remade_when_the_video_changes(tmp_path: Path, vp8: None) -> None:
    mp4 = tmp_path / "clip.mp4"
    write_video(mp4, _frames(4), fps=10)
    webm = browser_video(mp4)
    assert webm == tmp_path / "clip.webm"
    assert _frame_count(webm) == 4
    os.utime(webm, ns=(mp4.stat().st_mtime_ns + 10**9,) * 2)
    stamp = webm.stat().st_mtime_ns
    assert browser_video(mp4) == webm
    assert webm.stat().st_mtime_ns == stamp  # not rewritten
    write_video(mp4, _frames(9), fps=10)
    os.utime(mp4, ns=(stamp + 10**9,) * 2)
    assert _frame_count(browser_video(mp4)) == 9
    assert browser_video(webm) == webm  # a WebM is its own copy


def test_two_videos_with_one_stem_get_two_copies(tmp_path: Path, vp8: None) -> None:
    write_video(tmp_path / "clip.mp4", _frames(3), fps=10)
    write_video(tmp_path / "clip.avi", _frames(5), fps=10)
    rep = Report("t")
    rep.video("a", "clip.mp4")
    rep.video("b", "clip.avi")
    html = rep.write(tmp_path / "report.html").read_text()
    sources = [src for src, _ in _SOURCE.findall(html)]
    assert sources == ["clip.webm", "clip.mp4", "clip_avi.webm", "clip.avi"]
    assert _frame_count(tmp_path / "clip.webm") == 3
    assert _frame_count(tmp_path / "clip_avi.webm") == 5


def test_missing_video_gets_a_visible_note_and_link(tmp_path: Path) -> None:
    rep = Report("t")
    rep.video("Overlay", "overlay.mp4")
    html = rep.write(tmp_path / "report.html").read_text()
    assert _SOURCE.findall(html) == [("overlay.mp4", "video/mp4")]
    assert "<p class='warning'><a href='overlay.mp4' download>overlay.mp4</a> was not found" in html
    assert not (tmp_path / "overlay.webm").exists()


def test_failed_copy_gets_a_visible_note_and_leaves_no_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import fusiontrack.io.video as video_io

    write_video(tmp_path / "clip.mp4", _frames(3), fps=10)

    real = video_io.write_video

    def no_vp8(path: Path, frames: object, fps: float, fourcc: str | None = None) -> int:
        return real(path, frames, fps, fourcc="ZZZZ")  # an OpenCV build without the encoder: the real failure

    monkeypatch.setattr(video_io, "write_video", no_vp8)
    rep = Report("t")
    rep.video("Clip", "clip.mp4")
    html = rep.write(tmp_path / "report.html").read_text()
    assert _SOURCE.findall(html) == [("clip.mp4", "video/mp4")]
    assert "class='warning'" in html
    assert "browsers may not play" in html
    assert "cannot write a video with codec &#x27;ZZZZ&#x27;" in html
    assert sorted(p.name for p in tmp_path.iterdir()) == ["clip.mp4", "report.html"]  # no WebM, no partial file


def test_browser_copies_can_be_turned_off(tmp_path: Path) -> None:
    """Report(browser_copies=False): the video is linked as it is, no WebM is made (VP8 costs ~10x the mp4v)."""
    write_video(tmp_path / "clip.mp4", [np.full((48, 64, 3), 128, np.uint8)] * 3, fps=10)
    rep = Report("t", browser_copies=False)
    rep.video("Clip", "clip.mp4")
    html = rep.write(tmp_path / "report.html").read_text()
    assert _SOURCE.findall(html) == [("clip.mp4", "video/mp4")]
    assert "class='warning'" not in html
    assert not (tmp_path / "clip.webm").exists()
