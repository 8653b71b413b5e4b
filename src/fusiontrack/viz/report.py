"""A self-contained HTML report: metrics tables, figures (embedded PNG), videos (linked) and an event timeline.

One file a user can open or mail: figures are embedded as base64 PNGs, so only the videos are separate files
(linked relative to the report). Built from plain Python values, so every pipeline and the demo share it::

    report = Report("Traffic on road, seed 0")
    report.table("Tracking", rows)                      # rows: list of dicts, one per line
    report.figure("Events", events_timeline(events, truth))
    report.video("Bird's-eye view", "tracks.mp4")
    report.write(out / "report.html")

Browsers do not play the ``.mp4`` files fusiontrack writes: opencv-python's FFmpeg has no H.264 encoder, so
they hold MPEG-4 Part 2 (``mp4v``). :meth:`Report.write` therefore makes a WebM (VP8) copy beside each linked
video (``tracks.mp4`` -> ``tracks.webm``, remade only when older than the video) and embeds it as the first
``<source>``, the original as the second, with a download link under the player. When the copy cannot be made
(no VP8 encoder, or the video is not there when the report is written), the report says so under the player.
VP8 encoding costs about 8-12x the mp4v the videos were written with; ``Report(..., browser_copies=False)`` skips
the copies.
"""

from __future__ import annotations

import base64
import html
import io
import logging
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import FusiontrackError, RecordingError
from ..types import Event

__all__ = ["Report", "browser_video", "events_timeline"]

logger = logging.getLogger(__name__)

_BROWSER_SUFFIX = ".webm"  # VP8 in WebM: the browser-playable video opencv-python can write
_MIME = {".webm": "video/webm", ".mp4": "video/mp4", ".m4v": "video/mp4", ".mov": "video/quicktime"}


def browser_video(video: str | Path, target: str | Path | None = None) -> Path:
    """A WebM (VP8) copy of ``video`` that browsers play, written beside it (same name, ``.webm``) by default.

    ``video`` itself is returned when it is the target (a ``.webm``); an existing copy no older than ``video`` is
    reused.

    Raises
    ------
    RecordingError
        ``video`` is missing or cannot be read, or this OpenCV build cannot encode VP8 (no partial copy is left).
    ConfigError
        ``target``'s folder does not exist.
    """
    from ..io.video import VideoReader, write_video

    video = Path(video)
    if not video.is_file():
        raise RecordingError(f"{video}: no such video file (cannot make a browser-playable copy)")
    out = Path(target) if target is not None else video.with_suffix(_BROWSER_SUFFIX)
    if out.resolve() == video.resolve():
        return video
    if out.is_file() and out.stat().st_size > 0 and out.stat().st_mtime >= video.stat().st_mtime:
        return out
    with VideoReader(video) as reader:  # (write_video leaves no partial file, and an earlier copy whole)
        write_video(out, iter(reader), fps=reader.fps, fourcc="VP80")
    return out


@dataclass(frozen=True)
class _Video:
    heading: str
    relative_path: str


def _cell(value: Any) -> str:
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float | np.floating):
        v = float(value)
        if not math.isfinite(v):
            return "–"
        return f"{v:.3g}" if abs(v) < 1e-2 or abs(v) >= 1e4 else f"{v:.3f}".rstrip("0").rstrip(".")
    return html.escape(str(value))


class Report:
    """Sections in order; :meth:`write` renders them into one HTML file.

    Parameters
    ----------
    title : str
    browser_copies : bool
        Make the WebM copies of the videos when the report is written (VP8 encoding costs about 8-12x the mp4v
        the videos were written with: ~50 ms a 1280x480 frame on 2 cores); ``False`` links the videos as they are.
    """

    def __init__(self, title: str, *, browser_copies: bool = True) -> None:
        self.title = title
        self.browser_copies = bool(browser_copies)
        self._parts: list[str | _Video] = []

    def text(self, heading: str | None, body: str) -> None:
        """A paragraph (plain text, escaped)."""
        if heading:
            self._parts.append(f"<h2>{html.escape(heading)}</h2>")
        self._parts.append(f"<p>{html.escape(body)}</p>")

    def table(self, heading: str, rows: Sequence[Mapping[str, Any]], note: str = "") -> None:
        """A table from dicts; the columns are the union of keys in first-seen order."""
        cols: list[str] = []
        for r in rows:
            cols += [k for k in r if k not in cols]
        head = "".join(f"<th>{html.escape(c)}</th>" for c in cols)
        body = "".join("<tr>" + "".join(f"<td>{_cell(r.get(c, ''))}</td>" for c in cols) + "</tr>" for r in rows)
        self._parts.append(f"<h2>{html.escape(heading)}</h2><table><tr>{head}</tr>{body}</table>")
        if note:
            self._parts.append(f"<p class='note'>{html.escape(note)}</p>")

    def figure(self, heading: str, fig: Any, note: str = "") -> None:
        """A matplotlib figure, embedded as PNG (the figure is closed)."""
        import matplotlib.pyplot as plt

        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=100, bbox_inches="tight")
        plt.close(fig)
        data = base64.b64encode(buf.getvalue()).decode("ascii")
        self._parts.append(f"<h2>{html.escape(heading)}</h2><img alt='{html.escape(heading)}' "
                           f"src='data:image/png;base64,{data}'>")
        if note:
            self._parts.append(f"<p class='note'>{html.escape(note)}</p>")

    def video(self, heading: str, relative_path: str | Path) -> None:
        """A video beside the report (linked, not embedded; a browser-playable copy is made by :meth:`write`)."""
        self._parts.append(_Video(heading, Path(relative_path).as_posix()))

    def _video_html(self, video: _Video, folder: Path, taken: dict[Path, Path]) -> str:
        """The player: the WebM copy first (made now), the original second, a download link and any problem."""
        original = folder / video.relative_path
        sources = [video.relative_path]
        problem = ""
        if not self.browser_copies:
            problem = "" if original.is_file() else "was not found when the report was written"
        elif Path(video.relative_path).suffix.lower() != _BROWSER_SUFFIX:
            if not original.is_file():
                problem = "was not found when the report was written"
            else:
                target = original.with_suffix(_BROWSER_SUFFIX)
                if taken.get(target, original) != original:  # clip.mp4 and clip.avi in one report
                    target = original.with_name(f"{original.stem}_{original.suffix[1:]}{_BROWSER_SUFFIX}")
                taken[target] = original
                try:
                    browser_video(original, target)
                    sources.insert(0, Path(video.relative_path).with_name(target.name).as_posix())
                except FusiontrackError as err:
                    logger.warning("%s: no browser-playable copy (%s)", original, err)
                    problem = (f"is in a format browsers may not play, and no WebM copy could be made ({err}); "
                               "open it in a video player such as VLC")
        tags = ""
        for source in sources:
            kind = _MIME.get(Path(source).suffix.lower())
            tags += f"<source src='{html.escape(source)}'" + (f" type='{kind}'>" if kind else ">")
        src = html.escape(video.relative_path)
        link = f"<a href='{src}' download>{src}</a>"
        note = f"{link} {html.escape(problem)}" if problem else f"download: {link}"
        return (f"<h2>{html.escape(video.heading)}</h2><video controls width='800'>{tags}</video>"
                f"<p class='{'warning' if problem else 'note'}'>{note}</p>")

    def write(self, path: str | Path) -> Path:
        """Render the report into ``path`` (its folder is created), making the videos' WebM copies beside them."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        taken: dict[Path, Path] = {}
        parts = [p if isinstance(p, str) else self._video_html(p, path.parent, taken) for p in self._parts]
        style = ("body{font-family:sans-serif;max-width:1100px;margin:2em auto;color:#222}"
                 "table{border-collapse:collapse;margin:0.5em 0}td,th{border:1px solid #bbb;padding:3px 8px;"
                 "text-align:right}th{background:#eee}td:first-child{text-align:left}.note{color:#666;"
                 "font-size:90%}.warning{color:#a40;font-size:90%}img{max-width:100%}")
        doc = (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{html.escape(self.title)}</title>"
               f"<style>{style}</style></head><body><h1>{html.escape(self.title)}</h1>{''.join(parts)}"
               "</body></html>")
        path.write_text(doc, encoding="utf-8")
        return path


def events_timeline(events: Iterable[Event], truth: Iterable[Event] = (), *, t0_ns: int | None = None,
                    t_end_ns: int | None = None) -> Any:
    """A timeline figure: one row per event kind, detected events (bars) above the ground truth (hatched)."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    events, truth = list(events), list(truth)
    every = events + truth
    kinds = sorted({e.kind for e in every})
    if t0_ns is None:
        t0_ns = min((e.t_ns for e in every), default=0)
    ends = [e.t_end_ns if e.t_end_ns is not None else e.t_ns for e in every]
    t_end = t_end_ns if t_end_ns is not None else max(ends, default=t0_ns + 1)
    fig, ax = plt.subplots(figsize=(10, 0.6 + 0.7 * max(len(kinds), 1)))
    for row, kind in enumerate(kinds):
        for items, dy, style in ((truth, -0.18, {"facecolor": "none", "edgecolor": "k", "hatch": "///"}),
                                 (events, 0.18, {"color": "tab:red", "alpha": 0.8})):
            spans = [((e.t_ns - t0_ns) / 1e9, ((e.t_end_ns if e.t_end_ns is not None else t_end) - e.t_ns) / 1e9)
                     for e in items if e.kind == kind]
            if spans:
                ax.broken_barh([(s, max(w, 0.2)) for s, w in spans], (row + dy - 0.15, 0.3), **style)
    ax.set_yticks(range(len(kinds)), kinds)
    ax.set_xlim(0, max((t_end - t0_ns) / 1e9, 1.0))
    ax.set_xlabel("time (s)")
    ax.set_title("events: detected (filled, upper) and ground truth (hatched, lower)")
    ax.grid(axis="x", alpha=0.3)
    return fig
