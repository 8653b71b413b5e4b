"""The ``fusiontrack`` command line: a thin layer that parses, calls the library and prints.

Errors a user can cause end as one line on stderr and a non-zero exit code, never a traceback
(set ``FUSIONTRACK_DEBUG=1`` to see the traceback).
"""

from __future__ import annotations

import json
import logging
import os
import sys
from collections.abc import Iterator, Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.console import Console
from rich.logging import RichHandler
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)
from rich.table import Table

from . import __version__
from .errors import ConfigError, FusiontrackError

app = typer.Typer(
    name="fusiontrack",
    help="Track people and vehicles with lasers, cameras, RGB-D and phone IMUs fused in one tracker.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)
# On a terminal rich uses its width; piped output (CI logs, files) gets room for full topic names.
console = Console(width=None if sys.stdout.isatty() else 150)
err_console = Console(stderr=True, width=None if sys.stderr.isatty() else 150)
log = logging.getLogger("fusiontrack")

DEFAULT_DEMO_BAG = Path("../shared/data/laser/leg_tracker_demo/demo_stationary_simple_environment.bag")

VIDEO_SUFFIXES = {".avi", ".mp4", ".mkv", ".mov", ".m4v", ".webm", ".mpg", ".mpeg"}


def _version(value: bool) -> None:
    if value:
        console.print(f"fusiontrack {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: Annotated[bool, typer.Option("--version", callback=_version, is_eager=True,
                                          help="Print the version and exit.")] = False,
    verbose: Annotated[bool, typer.Option("--verbose", "-v", help="Log progress details.")] = False,
) -> None:
    logging.basicConfig(level=logging.INFO if verbose else logging.WARNING, format="%(message)s",
                        handlers=[RichHandler(console=err_console, show_path=False, show_time=False)])


def progress() -> Progress:
    """A rich progress bar (drawn only on a terminal)."""
    return Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                    TimeRemainingColumn(), console=err_console, transient=True)


def _track(items: Iterator[Any], bar: Progress, description: str, total: int) -> Iterator[Any]:
    task = bar.add_task(description, total=total)
    for item in items:
        bar.advance(task)
        yield item


def _fmt_time(t_ns: int) -> str:
    if t_ns > 10**17:  # plausibly epoch time
        return datetime.fromtimestamp(t_ns / 1e9, tz=UTC).strftime("%Y-%m-%d %H:%M:%S.%f")[:-3] + " UTC"
    return f"{t_ns / 1e9:.3f} s"


# --------------------------------------------------------------------------------------------------
# info
# --------------------------------------------------------------------------------------------------


def describe_recording(paths: Sequence[Path]) -> dict[str, Any]:
    """Facts about a bag / MCAP recording (one or several files read as one)."""
    from .io.recording import Recording

    with Recording(paths) as rec:
        topics = rec.topics()
        return {
            "kind": "recording",
            "paths": [str(p) for p in paths],
            "messages": rec.message_count,
            "start_ns": rec.start_ns,
            "end_ns": rec.end_ns,
            "duration_s": rec.duration_s,
            "topics": [
                {"topic": t.topic, "type": t.msgtype, "sensor": t.sensor, "count": t.count,
                 "rate_hz": round(t.rate_hz, 3), "duration_s": round(t.duration_s, 3), "read": t.convertible}
                for t in topics.values()
            ],
        }


def describe_video(path: Path) -> dict[str, Any]:
    from .io.video import VideoReader

    with VideoReader(path) as video:
        return {"kind": "video", "paths": [str(path)], "frames": video.frame_count, "fps": video.fps,
                "width": video.width, "height": video.height, "duration_s": video.duration_s}


def describe_imu_csv(path: Path) -> dict[str, Any]:
    from .io.imu_csv import read_imu_csv

    data = read_imu_csv(path)
    out: dict[str, Any] = {"kind": "imu_csv", "paths": [str(path)], "format": data.format, "samples": len(data),
                           "duration_s": data.duration_s, "rate_hz": data.rate_hz}
    if data.n_steps_gt is not None:
        out["ground_truth_steps"] = data.n_steps_gt
    return out


def _print_description(d: dict[str, Any]) -> None:
    if d["kind"] == "recording":
        console.print(f"[bold]{', '.join(d['paths'])}[/]")
        console.print(f"  duration {d['duration_s']:.2f} s, from {_fmt_time(d['start_ns'])} to "
                      f"{_fmt_time(d['end_ns'])}, {d['messages']} messages")
        table = Table(show_edge=False, header_style="bold")
        for col, justify in (("topic", "left"), ("type", "left"), ("count", "right"), ("rate Hz", "right"),
                             ("span s", "right"), ("read", "center")):
            table.add_column(col, justify=justify)  # type: ignore[arg-type]
        for t in d["topics"]:
            table.add_row(t["topic"], t["type"], str(t["count"]), f"{t['rate_hz']:.2f}", f"{t['duration_s']:.1f}",
                          "yes" if t["read"] else "-")
        console.print(table)
    elif d["kind"] == "video":
        console.print(f"[bold]{d['paths'][0]}[/]: video, {d['frames']} frames of {d['width']}x{d['height']} "
                      f"at {d['fps']:.2f} fps, {d['duration_s']:.2f} s")
    else:
        extra = f", {d['ground_truth_steps']} ground-truth steps" if "ground_truth_steps" in d else ""
        console.print(f"[bold]{d['paths'][0]}[/]: IMU CSV ({d['format']}), {d['samples']} samples at "
                      f"{d['rate_hz']:.1f} Hz, {d['duration_s']:.1f} s{extra}")


def _describe(paths: list[Path], merge: bool) -> list[dict[str, Any]]:
    videos = [p for p in paths if p.suffix.lower() in VIDEO_SUFFIXES]
    csvs = [p for p in paths if p.suffix.lower() == ".csv"]
    bags = [p for p in paths if p not in videos and p not in csvs]
    out = ([describe_recording(bags)] if merge else [describe_recording([p]) for p in bags]) if bags else []
    out += [describe_video(p) for p in videos]
    out += [describe_imu_csv(p) for p in csvs]
    return out


@app.command()
def info(
    recordings: Annotated[list[Path], typer.Argument(help="Bags (ROS 1 .bag, ROS 2 folder, .mcap, .db3), "
                                                          "video files or IMU CSV files.")],
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON instead of a table.")] = False,
    merge: Annotated[bool, typer.Option(
        "--merge", help="Describe several bags as one recording (streams merged by time), as the tracker reads them."
    )] = False,
) -> None:
    """Show what recordings hold: topics, message types, counts, rates and duration."""
    descriptions = _describe(recordings, merge)
    if as_json:
        console.print_json(json.dumps(descriptions if len(descriptions) > 1 else descriptions[0]))
        return
    for d in descriptions:
        _print_description(d)


# --------------------------------------------------------------------------------------------------
# convert
# --------------------------------------------------------------------------------------------------


def _load_config(path: Path | None) -> Any:
    from .config import PipelineConfig, load_config

    return load_config(path) if path is not None else PipelineConfig()


@app.command()
def convert(
    recordings: Annotated[list[Path], typer.Argument(help="Input bags (ROS 1 or ROS 2, several are merged).")],
    output: Annotated[Path, typer.Option("--output", "-o", help="Folder of the new rosbag2 recording.")],
    topic: Annotated[list[str] | None, typer.Option("--topic", "-t", help="Topic to keep (repeatable); "
                                                    "default: every topic fusiontrack can read.")] = None,
    storage: Annotated[str, typer.Option(help="mcap or sqlite3.")] = "mcap",
    config: Annotated[Path | None, typer.Option("--config", "-c", help="Pipeline file: sensor names, "
                                                "clock offsets, sync window.")] = None,
    time_source: Annotated[str, typer.Option("--time", help="header (capture stamps) or log (recorder).")] = "header",
) -> None:
    """Convert recordings into one time-synchronised rosbag2 (MCAP by default) with standard ROS types."""
    from .io.recording import Recording
    from .io.sync import Synchronizer
    from .io.writer import RecordingWriter

    if time_source not in ("header", "log"):
        raise ConfigError(f"--time: expected 'header' or 'log', got {time_source!r}")
    cfg = _load_config(config)
    sync = Synchronizer(cfg.sync.window_ns, cfg.clock_offsets_ns())
    with Recording(recordings, sensors=cfg.topics()) as rec:
        selected = [t for t in rec.topics().values() if (topic is None and t.convertible) or
                    (topic is not None and t.topic in topic)]
        total = sum(t.count for t in selected)
        with RecordingWriter(output, storage=storage) as writer, progress() as bar:  # type: ignore[arg-type]
            stream = _track(rec.messages(topic, time_source=time_source), bar, "converting", total)  # type: ignore[arg-type]
            n = writer.write_all(sync(stream))
    dropped = sum(sync.dropped.values())
    console.print(f"wrote {n} messages to {output}"
                  + (f" ({dropped} dropped as too far out of order)" if dropped else "")
                  + (f" ({sum(rec.skipped.values())} unreadable skipped)" if rec.skipped else ""))


# --------------------------------------------------------------------------------------------------
# birdseye
# --------------------------------------------------------------------------------------------------


def render_birdseye(
    recordings: Sequence[Path], output: Path, topics: Sequence[str] | None, config_path: Path | None,
    max_frames: int | None = None,
) -> dict[str, Any]:
    """Render laser scans of a recording into a bird's-eye video; returns what was drawn."""
    import numpy as np

    from .geometry import scan_to_world
    from .io.recording import Recording
    from .io.sync import Synchronizer
    from .io.video import write_video
    from .types import LaserScan
    from .viz.birdseye import BirdseyeView

    cfg = _load_config(config_path)
    colours = [(80, 220, 255), (255, 160, 60), (120, 255, 120), (200, 120, 255)]
    with Recording(recordings, sensors=cfg.topics()) as rec:
        infos = rec.topics()
        lasers = [t.topic for t in infos.values() if t.msgtype == "sensor_msgs/msg/LaserScan"]
        chosen = list(topics) if topics else lasers
        if not chosen:
            raise ConfigError(f"{', '.join(map(str, recordings))}: no LaserScan topic to draw")
        sensors = [rec.sensor_of(t) for t in chosen]
        poses = {name: (cfg.sensors[name].pose.matrix() if name in cfg.sensors else np.eye(4)) for name in sensors}
        sync = Synchronizer(cfg.sync.window_ns, cfg.clock_offsets_ns())
        total = sum(infos[t].count for t in chosen if t in infos)
        if max_frames:
            total = min(total, max_frames)
        scans: list[LaserScan] = []
        with progress() as bar:
            for scan in _track(sync(rec.messages(chosen)), bar, "reading scans", total):
                scans.append(scan)
                if max_frames and len(scans) >= max_frames:
                    break
    if not scans:
        raise FusiontrackError(f"{', '.join(map(str, recordings))}: the laser topics hold no scans")
    points = [scan_to_world(s, poses[s.sensor]) for s in scans]
    view = BirdseyeView.fit(np.concatenate([p[::4] for p in points]), margin_m=0.5)
    background = view.background()
    latest: dict[str, np.ndarray] = {}
    period = float(np.median(np.diff([s.t_ns for s in scans]))) / 1e9 if len(scans) > 1 else 0.1
    fps = min(max(1.0 / period if period > 0 else 10.0, 1.0), 60.0) / max(len(sensors), 1)

    def frames() -> Iterator[np.ndarray]:
        for scan, pts in zip(scans, points, strict=True):
            latest[scan.sensor] = pts
            img = background.copy()
            for i, name in enumerate(sensors):
                if name in latest:
                    view.draw_points(img, latest[name], colours[i % len(colours)], radius_px=1)
            yield view.label(img, f"{(scan.t_ns - scans[0].t_ns) / 1e9:7.2f} s  {scan.sensor}")

    n = write_video(output, frames(), fps=max(fps, 1.0))
    return {"frames": n, "scans": len(scans), "sensors": sensors, "fps": fps, "size_px": list(view.size_px)}


@app.command()
def birdseye(
    recordings: Annotated[list[Path], typer.Argument(help="Recording(s) with LaserScan topics.")],
    output: Annotated[Path, typer.Option("--output", "-o", help="Video file to write (.mp4 or .avi).")],
    topic: Annotated[list[str] | None, typer.Option("--topic", "-t", help="Laser topic (repeatable); "
                                                    "default: all LaserScan topics.")] = None,
    config: Annotated[Path | None, typer.Option("--config", "-c", help="Pipeline file with sensor poses.")] = None,
    max_frames: Annotated[int | None, typer.Option(help="Stop after this many scans.")] = None,
) -> None:
    """Draw the laser scans of a recording from above (world frame when poses are configured)."""
    result = render_birdseye(recordings, output, topic, config, max_frames)
    console.print(f"wrote {result['frames']} frames ({result['size_px'][0]}x{result['size_px'][1]}) to {output}")


# --------------------------------------------------------------------------------------------------
# demo
# --------------------------------------------------------------------------------------------------


@app.command()
def demo(
    output: Annotated[Path, typer.Option("--output", "-o", help="Folder for everything the demo writes.")] = Path(
        "out/demo"),
    recording: Annotated[Path, typer.Option(help="ROS 1 bag to use.")] = DEFAULT_DEMO_BAG,
) -> None:
    """Run the most complete job fusiontrack has on a real laser recording.

    Describes the recording, converts it to a time-synchronised MCAP, reads that back and renders a
    bird's-eye video of the scans; writes ``summary.json`` with what was measured.
    """
    import shutil

    if not recording.exists():
        raise FusiontrackError(f"demo recording not found: {recording} (the demo reads ../shared/data beside the "
                               "repository; run it from the repository root or pass --recording)")
    output.mkdir(parents=True, exist_ok=True)
    desc = describe_recording([recording])
    _print_description(desc)
    mcap_dir = output / "recording"
    if mcap_dir.exists():
        shutil.rmtree(mcap_dir)
    convert([recording], mcap_dir)
    round_trip = describe_recording([mcap_dir])
    video = output / "birdseye.mp4"
    drawn = render_birdseye([mcap_dir], video, None, None)
    summary = {"input": desc, "converted": round_trip, "birdseye": {"path": str(video), **drawn}}
    (output / "summary.json").write_text(json.dumps(summary, indent=2))
    console.print(f"bird's-eye video: {video} ({drawn['frames']} frames); summary: {output / 'summary.json'}")


def main() -> None:
    """Entry point: run the app, turning fusiontrack's errors into one clear line and exit code 2."""
    try:
        app()
    except FusiontrackError as err:
        if os.environ.get("FUSIONTRACK_DEBUG"):
            raise
        err_console.print(f"[bold red]error:[/] {err}", highlight=False, soft_wrap=True)
        sys.exit(2)
    except KeyboardInterrupt:
        err_console.print("interrupted")
        sys.exit(130)


if __name__ == "__main__":
    main()
