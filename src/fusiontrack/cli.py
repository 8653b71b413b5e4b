"""The ``fusiontrack`` command line: a thin layer that parses, calls the library and prints.

Errors a user can cause end as one line on stderr and a non-zero exit code, never a traceback
(set ``FUSIONTRACK_DEBUG=1`` to see the traceback).
"""

from __future__ import annotations

import collections
import csv
import json
import logging
import math
import os
import sys
import time
from collections.abc import Iterable, Iterator, Mapping, Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.console import Console
from rich.logging import RichHandler
from rich.markup import escape
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
from .errors import ConfigError, FusiontrackError, RecordingError

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
        frames = video.count_decodable()
        out = {"kind": "video", "paths": [str(path)], "frames": frames, "fps": video.fps,
               "width": video.width, "height": video.height, "duration_s": frames / video.fps}
        if frames != video.frame_count:
            out["frames_stated"] = video.frame_count
            log.warning("%s: %d of the %d frames the container states can be decoded (a truncated file?)", path,
                        frames, video.frame_count)
        return out


def describe_imu_csv(path: Path) -> dict[str, Any]:
    from .io.imu_csv import read_imu_csv

    data = read_imu_csv(path)
    out: dict[str, Any] = {"kind": "imu_csv", "paths": [str(path)], "format": data.format, "samples": len(data),
                           "duration_s": data.duration_s,
                           "rate_hz": data.rate_hz if math.isfinite(data.rate_hz) else None}  # (one sample: no rate)
    if data.n_steps_gt is not None:
        out["ground_truth_steps"] = data.n_steps_gt
    return out


def _is_tracks(path: Path) -> bool:
    """Whether ``path`` is a tracker's output rather than a recording: a folder of `fusiontrack track` (no
    metadata.yaml, a tracks.jsonl or tracks.csv), a .jsonl file, or a CSV whose header names id, x and y (tracks or
    positions of people, where an IMU CSV has ax, ay, az)."""
    if path.is_dir():
        return not (path / "metadata.yaml").exists() and any((path / n).is_file() for n in ("tracks.jsonl",
                                                                                              "tracks.csv"))
    suffix = path.suffix.lower()
    if suffix == ".jsonl":
        return True
    if suffix != ".csv" or not path.is_file():
        return False
    try:
        with path.open(newline="", encoding="utf-8") as f:
            header = next(csv.reader(f), [])
    except (OSError, UnicodeDecodeError):
        return False  # (read as an IMU CSV, which says what is wrong)
    return {"id", "x", "y"} <= {h.strip().lower() for h in header}


def describe_tracks(path: Path) -> dict[str, Any]:
    """Facts about a tracks file (``fusiontrack track``'s tracks.jsonl or tracks.csv, or its folder): states, tracks,
    time span, classes, situations, the sensors that confirmed the states, image boxes and events."""
    file = _tracks_file(path)
    states, events = _read_tracks(path)
    t = [s.t_ns for s in states]
    out: dict[str, Any] = {
        "kind": "tracks", "paths": [str(file)], "states": len(states), "tracks": len({s.track_id for s in states}),
        "start_ns": min(t) if t else None, "end_ns": max(t) if t else None,
        "duration_s": (max(t) - min(t)) / 1e9 if t else 0.0,
        "classes": dict(collections.Counter(str(s.cls) for s in states).most_common()),
        "situations": dict(collections.Counter(str(s.situation) for s in states).most_common()),
        "confirmed_by": dict(collections.Counter(x for s in states for x in s.sensors).most_common()),
        "image_boxes": dict(collections.Counter(s.camera or "camera" for s in states
                                                if s.box_px is not None).most_common()),
    }
    if file.suffix != ".csv":
        out["events"] = dict(collections.Counter(e.kind for e in events).most_common())
    return out


def _print_description(d: dict[str, Any]) -> None:
    if d["kind"] == "tracks":
        n = d["states"]
        console.print(f"[bold]{d['paths'][0]}[/]: tracks, {d['tracks']} track{'s' if d['tracks'] != 1 else ''}, "
                      f"{n} state{'s' if n != 1 else ''}"
                      + (f" over {d['duration_s']:.2f} s, from {_fmt_time(d['start_ns'])} to {_fmt_time(d['end_ns'])}"
                         if n else ""))

        def share(counts: dict[str, int]) -> str:
            return ", ".join(f"{k} {v} ({100 * v / n:.0f} %)" for k, v in counts.items()) if counts else "none"

        console.print(f"  states by class: {share(d['classes'])}")
        console.print(f"  by situation: {share(d['situations'])}")
        console.print(f"  confirmed by: {share(d['confirmed_by'])}")
        if d["image_boxes"]:
            console.print(f"  with an image box: {share(d['image_boxes'])}")
        if "events" in d:
            console.print(f"  events: {_counts(d['events'])}")
    elif d["kind"] == "recording":
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
        rate = f" at {d['rate_hz']:.1f} Hz" if d["rate_hz"] is not None else ""
        console.print(f"[bold]{d['paths'][0]}[/]: IMU CSV ({d['format']}), {d['samples']} "
                      f"sample{'s' if d['samples'] != 1 else ''}{rate}, {d['duration_s']:.1f} s{extra}")


def _describe(paths: list[Path], merge: bool) -> list[dict[str, Any]]:
    tracks = [p for p in paths if _is_tracks(p)]
    videos = [p for p in paths if p.suffix.lower() in VIDEO_SUFFIXES and p not in tracks]
    csvs = [p for p in paths if p.suffix.lower() == ".csv" and p not in tracks]
    bags = [p for p in paths if p not in videos and p not in csvs and p not in tracks]
    out = ([describe_recording(bags)] if merge else [describe_recording([p]) for p in bags]) if bags else []
    out += [describe_video(p) for p in videos]
    out += [describe_imu_csv(p) for p in csvs]
    out += [describe_tracks(p) for p in tracks]
    return out


@app.command()
def info(
    recordings: Annotated[list[Path], typer.Argument(help="Bags (ROS 1 .bag, ROS 2 folder, .mcap, .db3), "
                                                          "video files, IMU CSV files, or tracks (tracks.jsonl, "
                                                          "tracks.csv or the folder of `fusiontrack track`).")],
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON instead of a table.")] = False,
    merge: Annotated[bool, typer.Option(
        "--merge", help="Describe several bags as one recording (streams merged by time), as the tracker reads them."
    )] = False,
) -> None:
    """Show what recordings hold: topics, message types, counts, rates and duration (for tracks: tracks, states,
    time span, classes, situations, confirming sensors, image boxes and events)."""
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
    """The pipeline file, its every section checked at once whatever the pipeline, errors naming the file (a typo in
    a table the run does not use was silently ignored; in one it uses, named the key but not the file)."""
    from .config import PipelineConfig, load_config

    if path is None:
        return PipelineConfig()
    cfg = load_config(path)
    if cfg.laser:
        from .laser.detector import check_detector_params

        check_detector_params(cfg.laser, f"{path}: [laser]")
    if cfg.fusion:
        from .fusion import FusionParams

        FusionParams.from_mapping(cfg.fusion, f"{path}: [fusion]")
    if cfg.traffic:
        from .fusion.traffic import TrafficParams

        TrafficParams.from_mapping({k: v for k, v in cfg.traffic.items() if k != "calibration"}, f"{path}: [traffic]")
    if cfg.wearable:
        from .fusion.wearable import check_options

        check_options(cfg.wearable, f"{path}: [wearable]")
    return cfg


def _counts(counts: Mapping[str, int] | None) -> str:
    """``{"appear": 18, "born": 3}`` as ``appear 18, born 3`` (``none`` when empty), for the summary lines."""
    return ", ".join(f"{k} {v}" for k, v in counts.items()) if counts else "none"


def _check_time(time_source: str) -> None:
    if time_source not in ("header", "log"):
        raise ConfigError(f"--time: expected 'header' or 'log', got {time_source!r}")


def _no_folder_under_a_file(path: Path, option: str) -> None:
    """Refused before any work, naming the option: a path whose nearest existing parent is a file (no folder can be
    made there; found only when writing, after the work, the error lost it)."""
    for parent in path.parents:
        if parent.exists():
            if not parent.is_dir():
                raise ConfigError(f"{option} {path}: {parent} is a file, not a folder")
            return


def _out_folder(path: Path, option: str = "--output") -> Path:
    """``--output`` that names a folder to write into: refused, naming it, when it is an existing file or lies
    under one."""
    if path.exists() and not path.is_dir():
        raise ConfigError(f"{option} {path}: is a file; give a folder to write into")
    _no_folder_under_a_file(path, option)
    return path


def _out_file(path: Path, example: str, reads: Iterable[Path | None] = (), option: str = "--output",
              recordings: Iterable[Path | None] = ()) -> Path:
    """An option (``--output``) that names a file to write: refused, naming it, when it is an existing folder, lies
    under a file, is one of the files the command ``reads`` (overwritten, the input would be lost), or lies inside a
    recording folder it reads (``recordings``: a folder, or a storage file of one; its metadata.yaml, storage files
    and ground truth are all inputs)."""
    if path.is_dir():
        raise ConfigError(f"{option} {path}: is a folder; give a file name (e.g. {path / example})")
    _no_folder_under_a_file(path, option)
    if path.exists():
        for r in reads:
            if r is not None and r.exists() and path.resolve() == r.resolve():
                raise ConfigError(f"{option} {path}: is the input {r} this command reads; writing it would lose it "
                                  f"(give another file, e.g. {path.with_name(example)})")
    for r in recordings:
        if r is None or not r.exists():
            continue
        folder = r if r.is_dir() else r.parent if (r.suffix.lower() in (".mcap", ".db3")
                                                   and (r.parent / "metadata.yaml").is_file()) else None
        if folder is not None and folder.resolve() in path.resolve().parents:
            raise ConfigError(f"{option} {path}: is inside the recording {folder} this command reads; write it "
                              f"beside the recording, not into it (e.g. {folder.parent / example})")
    return path


def _check_sensor_topics(cfg: Any, config: Path | None, recordings: Sequence[Path], kinds: set[str]) -> None:
    """The topics the pipeline file gives the sensors of ``kinds`` are in the recording: else an error naming the
    file and the sensor's table, before any reading (the recording's own error named neither)."""
    if config is None or not any(s.kind in kinds for s in cfg.sensors.values()):
        return
    from .errors import TopicError
    from .io.recording import Recording

    with Recording(recordings) as rec:
        have = set(rec.topic_types())  # (the names only: topics() counts the messages)
    for name, sensor in cfg.sensors.items():
        if sensor.kind not in kinds:
            continue
        for key in ("topic", "info_topic", "depth_topic"):
            topic = getattr(sensor, key)
            if topic and topic not in have:
                raise TopicError(f"{config}: [sensors.{name}] {key} {topic!r} is not in "
                                 f"{', '.join(str(p) for p in recordings)}; it has: {', '.join(sorted(have))}")


def _check_laser_tables(cfg: Any, config: Path | None, tracker_kind: str) -> None:
    """A pipeline file's [laser] and [tracking] tables checked before any reading, errors naming the file.
    ``tracker_kind`` "any" (a command that tracks nothing): [tracking] must suit the pf or the kalman tracker."""
    from .laser.detector import check_detector_params

    where = f"{config}: " if config is not None else ""
    if cfg.laser:
        check_detector_params(cfg.laser, f"{where}[laser]")
    if tracker_kind == "any":  # a [tracking] table for either tracker; suiting neither, the error of the one
        # whose keys it uses (the Kalman's when it knows them all, else the particle filter's, the default)
        from .tracking.online import kalman_keys

        tracker_kind = "kalman" if cfg.tracking and set(cfg.tracking) <= kalman_keys() else "pf"
    if cfg.tracking and tracker_kind == "pf":
        from .tracking.tracker import TrackerParams

        try:
            TrackerParams().replace(**cfg.tracking)
        except ConfigError as err:
            raise ConfigError(f"{where}[tracking]: {err}") from None
    elif cfg.tracking and tracker_kind == "kalman":
        from .tracking.online import make_tracker

        try:
            make_tracker("kalman", cfg.tracking, None, None)
        except ConfigError as err:
            raise ConfigError(f"{where}[tracking] with --tracker kalman: {err}") from None


@app.command()
def convert(
    recordings: Annotated[list[Path], typer.Argument(help="Input bags (ROS 1 or ROS 2, several are merged).")],
    output: Annotated[Path, typer.Option("--output", "-o", help="Folder of the new rosbag2 recording.")],
    topic: Annotated[list[str] | None, typer.Option("--topic", "-t", help="Topic to keep (repeatable); "
                                                    "default: every topic fusiontrack can read.")] = None,
    storage: Annotated[str, typer.Option(help="mcap or sqlite3.")] = "mcap",
    config: Annotated[Path | None, typer.Option("--config", "-c", help="Pipeline file: sensor names, "
                                                "clock offsets, sync window, laser poses (written as /tf_static).")
                      ] = None,
    time_source: Annotated[str, typer.Option("--time", help="header (capture stamps) or log (recorder).")] = "header",
) -> None:
    """Convert recordings into one time-synchronised rosbag2 (MCAP by default) with standard ROS types.

    A pipeline file's laser poses (``\\[sensors.<name>] pose``) become ``/tf_static`` transforms from ``world`` to
    each scanner's frame, replacing the recording's own for those frames: the new recording is posed as the
    pipeline file poses it, without the file."""
    from .io.recording import Recording
    from .io.sync import Synchronizer, with_time
    from .io.writer import RecordingWriter
    from .types import Transform

    if time_source not in ("header", "log"):
        raise ConfigError(f"--time: expected 'header' or 'log', got {time_source!r}")
    _no_folder_under_a_file(output, "--output")
    cfg = _load_config(config)
    _check_laser_tables(cfg, config, "any")  # (not used here, but a typo in the file is an error whatever the run)
    from .config import SensorKind

    _check_sensor_topics(cfg, config, recordings, {k.value for k in SensorKind})
    sync = Synchronizer(cfg.sync.window_ns, cfg.clock_corrections_ns())
    with Recording(recordings, sensors=cfg.topics()) as rec:
        rec.select(topic)  # unknown or unconvertible topics fail here, before the output exists
        selected = [t for t in rec.topics().values() if (topic is None and t.convertible) or
                    (topic is not None and t.topic in topic)]
        total = sum(t.count for t in selected)
        poses = _pose_transforms(rec, cfg.laser_poses(), [t.topic for t in selected], time_source)
        with RecordingWriter(output, storage=storage) as writer, progress() as bar:  # type: ignore[arg-type]
            n = writer.write_all(poses)
            # each record keeps the topic it was read from (a simulated camera's label images are Image records
            # of the camera's sensor too: by type alone they were written onto its image topic), carried through
            # the synchroniser with it (its clock corrections, held leaps and drops act on the pair)
            stream = _track((_Topical(m.t_ns, m.sensor, m, tp)
                             for tp, m in rec.topic_messages(topic, time_source=time_source)),
                            bar, "converting", total)  # type: ignore[arg-type]
            replaced = {tf.child_frame for tf in poses}
            for item in sync(stream):
                m = item.record if item.t_ns == item.record.t_ns else with_time(item.record, item.t_ns)
                if not (isinstance(m, Transform) and m.static and m.child_frame in replaced):
                    writer.write(m, topic=item.topic)
                    n += 1
    dropped = sum(sync.dropped.values())
    console.print(f"wrote {n} messages to {output}"
                  + (f" ({dropped} dropped as too far out of order)" if dropped else "")
                  + (f" ({sum(rec.skipped.values())} unreadable skipped)" if rec.skipped else ""))


class _Topical:
    """A record and the topic it was read from, as the synchroniser sees a record (``t_ns``, ``sensor``)."""

    __slots__ = ("record", "sensor", "t_ns", "topic")

    def __init__(self, t_ns: int, sensor: str, record: Any, topic: str) -> None:
        self.t_ns, self.sensor, self.record, self.topic = t_ns, sensor, record, topic


def _pose_transforms(rec: Any, laser_poses: Mapping[str, Any], topics: Sequence[str], time_source: str
                     ) -> list[Any]:
    """``/tf_static`` transforms ``world`` -> each posed laser's frame (its scans' ``frame_id``, else its sensor
    name), stamped at the recording's start; poses of lasers not converted are left out with a warning."""
    from .geometry import static_transform
    from .laser.detector import first_scans

    wanted = {t: T for t, T in laser_poses.items() if t in topics}
    left = sorted(set(laser_poses) - set(wanted))
    if left:
        log.warning("the pipeline file poses %s, which %s not converted: no /tf_static for %s", ", ".join(left),
                    "is" if len(left) == 1 else "are", "it" if len(left) == 1 else "them")
    first = first_scans(rec, list(wanted), time_source)
    out = []
    for topic, T in wanted.items():
        scan = first.get(rec.sensor_of(topic))
        if scan is None:
            log.warning("%s holds no scans: its pose is not written", topic)
            continue
        out.append(static_transform(rec.start_ns, "world", scan.frame_id or scan.sensor, T))
    return out


@app.command()
def repair(
    recording: Annotated[Path, typer.Argument(help="A truncated or damaged ROS 1 .bag, .mcap file or rosbag2 "
                                                   "folder of .mcap files.")],
    output: Annotated[Path, typer.Option("--output", "-o", help="The new recording: a .bag file for a ROS 1 bag, "
                                         "a rosbag2 folder (MCAP) for MCAP.")],
) -> None:
    """Recover every complete message of a cut-off or damaged recording into a new one (as rosbag reindex and
    mcap recover do): the records are read from the start, up to the first incomplete or corrupt one (in a closed
    ROS 1 bag, whose index repeats its connection records, a damaged record is passed over)."""
    from .io.recover import repair_recording

    _no_folder_under_a_file(output, "--output")
    report = repair_recording(recording, output)
    console.print(escape(report.summary()), highlight=False, soft_wrap=True)


# --------------------------------------------------------------------------------------------------
# view
# --------------------------------------------------------------------------------------------------


@app.command()
def view(
    recordings: Annotated[list[Path], typer.Argument(help="Recording(s), simulated or real.")],
    output: Annotated[Path, typer.Option("--output", "-o", help="Video file to write (.mp4, .avi, .mkv or .webm: "
                                                   ".webm plays in browsers).")],
    max_frames: Annotated[int | None, typer.Option(help="Stop after this many frames.")] = None,
    fps: Annotated[float | None, typer.Option(help="Frame rate of the video (default: the recording's).")] = None,
) -> None:
    """A preview video: laser points and ground truth from above, beside the camera image.

    One frame per camera image (or per laser scan when there is no camera); sensor poses come from
    the recording's tf_static, so a simulated recording is drawn in the world frame.
    """
    import math

    from .io.video import VIDEO_WRITE_SUFFIXES, check_video_output
    from .viz.preview import render_preview

    if max_frames is not None and max_frames < 1:  # (said before any folder is made for the video)
        raise ConfigError(f"--max-frames: expected a number of frames >= 1, got {max_frames}")
    if fps is not None and not (math.isfinite(fps) and 0.1 <= fps <= 1000):  # (what the encoders take and players
        # show: mp4v failed at 0.001 and 65536 with a message about the codec)
        raise ConfigError(f"--fps: expected a frame rate from 0.1 to 1000 frames per second, got {fps:g}")
    _no_folder_under_a_file(output, "--output")
    if not output.parent.exists():
        if output.suffix.lower() not in VIDEO_WRITE_SUFFIXES:
            check_video_output(output)  # a bad suffix is said first, before a folder is made for it
        output.parent.mkdir(parents=True)  # as track and pdr make theirs
    with progress() as bar:
        task = bar.add_task("rendering", total=None)
        result = render_preview(recordings, output, max_frames=max_frames, fps=fps,
                                progress=lambda n, total: bar.update(task, completed=n, total=total))
    what = ", ".join(result.lasers + result.cameras) + (" + ground truth" if result.truth else "")
    console.print(f"wrote {result.frames} frames of {what} to {output}")


# --------------------------------------------------------------------------------------------------
# scenarios, simulate
# --------------------------------------------------------------------------------------------------


@app.command()
def scenarios() -> None:
    """List the built-in simulator scenarios with a one-line description."""
    from .sim.scenario import builtin_names, load_scenario

    table = Table(show_edge=False, header_style="bold")
    for col in ("scenario", "seconds", "sensors", "description"):
        table.add_column(col)
    for name in builtin_names():
        sc = load_scenario(name)
        c = sc.config
        sensors = f"{len(c.lasers)} laser, {len(c.cameras)} camera, {len(c.phones)} phone"
        table.add_row(name, f"{c.scenario.duration_s:g}", sensors, sc.description)
    console.print(table)
    console.print("Simulate one with: fusiontrack simulate NAME -o out/NAME  (or pass your own .toml file)")


def _parse_settings(items: list[str] | None) -> dict[str, Any]:
    import tomllib

    out: dict[str, Any] = {}
    for item in items or []:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise ConfigError(f"--set {item!r}: expected KEY=VALUE, e.g. --set agents.mean_present=12")
        try:
            out[key.strip()] = tomllib.loads(f"v = {value.strip()}")["v"]
        except tomllib.TOMLDecodeError:
            out[key.strip()] = value.strip()  # a bare word: a string
    return out


@app.command()
def simulate(
    scenario: Annotated[str, typer.Argument(help="Built-in scenario name (see `fusiontrack scenarios`) or a "
                                                 "scenario .toml file.")],
    output: Annotated[Path, typer.Option("--output", "-o", help="Folder of the new recording (rosbag2 MCAP).")],
    seconds: Annotated[float | None, typer.Option(help="Duration (default: the scenario's).")] = None,
    seed: Annotated[int | None, typer.Option(help="Random seed (default: the scenario's).")] = None,
    set_: Annotated[list[str] | None, typer.Option("--set", help="Override any scenario value, e.g. "
                                                   "--set agents.mean_present=12 (repeatable).")] = None,
) -> None:
    """Simulate a scenario into a recording with ground truth (MCAP + CSV in OUTPUT/ground_truth)."""
    from .sim.scenario import load_scenario
    from .sim.simulator import simulate as run_simulation

    _no_folder_under_a_file(output, "--output")  # (said before the simulation, not after it)
    if seconds is not None and not (math.isfinite(seconds) and seconds > 0):  # (named by the option, not the field)
        raise ConfigError(f"--seconds: expected a duration > 0, got {seconds:g}")
    if seed is not None and seed < 0:
        raise ConfigError(f"--seed: expected an integer >= 0, got {seed}")
    sc = load_scenario(scenario).with_overrides(seconds=seconds, seed=seed, settings=_parse_settings(set_))
    duration = sc.config.scenario.duration_s
    with progress() as bar:
        task = bar.add_task(f"simulating {sc.name}", total=duration)
        result = run_simulation(sc, output, progress=lambda t: bar.update(task, completed=t))
    msgs = ", ".join(f"{name} {n}" for name, n in result.messages.items())
    console.print(f"wrote {output}: {duration:g} s, {result.n_agents} agents ({result.mean_present:.1f} present on "
                  f"average), messages: {msgs}")


# --------------------------------------------------------------------------------------------------
# track, eval
# --------------------------------------------------------------------------------------------------

PIPELINES = {
    "people-laser": "people tracked with 2D lasers (seed 001's laser side)",
    "people-camera": "people tracked in one camera's images: foreground blobs, or a MOTChallenge detection file",
    # seed 001's fused pipeline (fusiontrack.fusion): needs LaserScan topics and one calibrated camera
    "people": "people tracked with 2D lasers and a camera: per-target classifiers learnt online check identities "
              "after close contact and re-identify reborn tracks (seed 001's tracking-learning loop)",
    # seed 003 (fusiontrack.fusion.traffic): lasers and cameras on a road, vehicle models, incidents
    # seed 002 (fusiontrack.fusion.wearable): phones (IMU) + RGB-D cameras
    "wearable": "people identified by the phone they carry: dead reckoning corrected by RGB-D fixes, visual "
                "trackers per camera checked by the projected inertial position (failure / recovery events)",
    "traffic": "vehicles on a road from lasers and cameras: fused object models, mode particle filter, incidents "
               "(stopped vehicle, road leaving, jam, wrong way)",
}


@app.command()
def track(
    recordings: Annotated[list[Path], typer.Argument(help="Recording(s) with LaserScan topics; for "
                                                          "people-camera a video file or a recording with images.")],
    output: Annotated[Path, typer.Option("--output", "-o", help="Folder for tracks, events and video.")],
    pipeline: Annotated[str, typer.Option(help=f"One of: {', '.join(PIPELINES)}.")] = "people-laser",
    config: Annotated[Path | None, typer.Option("--config", "-c", help="Pipeline file: sensors, topics, clock "
                                                "offsets, \\[laser] and \\[tracking] parameters.")] = None,
    tracker_kind: Annotated[str, typer.Option("--tracker", help="pf (two-feet particle filters) or kalman "
                                              "(constant-velocity baseline).")] = "pf",
    time_source: Annotated[str, typer.Option("--time", help="header (capture stamps) or log (recorder).")] = "header",
    video: Annotated[bool, typer.Option(help="Also write a bird's-eye video with the tracks (people-camera: the "
                                        "overlay video; people: both, overlay.mp4 the camera's).")] = True,
    seed: Annotated[int | None, typer.Option(help="Random seed of the particle filters (default 0, or for traffic "
                                             "and wearable the pipeline file's own seed).")] = None,
    area: Annotated[str, typer.Option(help="Covered area, where people appear and leave: 'auto' (from the "
                                      "learnt laser backgrounds), 'none' (a moving scanner: no edge) or "
                                      "x_min,y_min,x_max,y_max in metres.")] = "auto",
    detections: Annotated[Path | None, typer.Option(help="people-camera: MOTChallenge detections (det.txt, "
                                                    "frames 1-based in image order) instead of foreground "
                                                    "blobs.")] = None,
    detection_scale: Annotated[float, typer.Option(help="people-camera: multiply the detection boxes by this "
                                                   "(0.625 for 768x576 boxes on a 480x360 video).")] = 1.0,
    min_score: Annotated[float | None, typer.Option(help="people-camera: drop detections with a lower "
                                                    "confidence.")] = None,
    camera_topic: Annotated[str | None, typer.Option(help="people-camera, people: the recording's image topic "
                                                     "(default: its only one).")] = None,
    max_frames: Annotated[int | None, typer.Option(help="people-camera: stop after this many frames.")] = None,
    camera_bias: Annotated[bool, typer.Option(help="people: first learn the camera's horizontal bias against the "
                                              "lasers (seed 000; over the first seconds, until it settles) and fuse "
                                              "through the corrected camera; writes bias.csv. --no-camera-bias for "
                                              "a camera calibrated well.")] = True,
    geometry: Annotated[Path | None, typer.Option(help="traffic: road geometry TOML (roads, lanes, zones); default "
                                                  "the simulator's ground_truth/world.json beside the recording."
                                                  )] = None,
    rules: Annotated[Path | None, typer.Option(help="traffic: incident rules TOML (default: the shipped D8 rules)."
                                               )] = None,
    compare: Annotated[bool, typer.Option(help="traffic: also run camera-only, laser-only and fusion without the "
                                          "particle filter, and score them all when there is ground truth.")] = False,
    scene: Annotated[str, typer.Option(help="traffic: incidents by the D8 'rules' (alarms after their hold times: "
                                       "10 s stopped, 30 s jam) or the 'learned' behaviour model (alarms within "
                                       "about 2 s).")] = "rules",
    calibration: Annotated[Path | None, typer.Option(help="traffic: road calibration JSON from `fusiontrack "
                                                     "calibrate-road` (or \\[traffic] calibration = FILE in the "
                                                     "pipeline file); the sensors it names are posed by it instead "
                                                     "of the recording's /tf_static.")] = None,
    workers: Annotated[int | None, typer.Option(help="traffic: camera branches in this many worker processes "
                                                "beside the main one (0: none; default: one per camera within "
                                                "the cores, minus one for the main process). Same tracks.")] = None,
) -> None:
    """Track people in a recording; writes tracks.csv, tracks.jsonl (states + events) and tracks.mp4.

    With --pipeline people-camera: tracks people in a video or a recording's camera, from the foreground
    blobs or from --detections; writes tracks.csv, tracks.jsonl, tracks_mot.txt (image boxes, MOTChallenge
    format) and overlay.mp4 (boxes, ids, foreground contours). Floor positions need a calibrated camera
    (a recording's CameraInfo and /tf_static); otherwise x, y are NaN.

    With --pipeline people: the lasers and a camera fused (seed 001), the camera's horizontal bias learnt first
    (seed 000): also bias.csv (the bias after each camera frame of that pass) and overlay.mp4 (laser points, boxes,
    ids, situations and the live bias in the camera image); each state's sensors say when the camera was used, and
    its box_px is the person's box in the camera.
    """
    from .io.tracks import write_jsonl, write_tracks_csv

    if pipeline not in PIPELINES:
        raise ConfigError(f"--pipeline: expected one of {', '.join(PIPELINES)}, got {pipeline!r}")
    if tracker_kind not in ("pf", "kalman"):
        raise ConfigError(f"--tracker: expected 'pf' or 'kalman', got {tracker_kind!r}")
    _check_time(time_source)
    _out_folder(output)
    traffic_only = {"--geometry": geometry is not None, "--rules": rules is not None, "--compare": compare,
                    "--calibration": calibration is not None, "--scene": scene != "rules",
                    "--workers": workers is not None}
    if pipeline != "traffic" and any(traffic_only.values()):
        given = ", ".join(k for k, v in traffic_only.items() if v)
        raise ConfigError(f"{given}: only for --pipeline traffic (got --pipeline {pipeline})")
    if not camera_bias and pipeline != "people":
        raise ConfigError(f"--no-camera-bias: only for --pipeline people (got --pipeline {pipeline})")
    if seed is not None and seed < 0:
        raise ConfigError(f"--seed: expected an integer >= 0, got {seed}")
    if scene not in ("rules", "learned"):
        raise ConfigError(f"--scene: expected 'rules' or 'learned', got {scene!r}")
    if scene == "learned" and rules is not None:
        raise ConfigError("--rules: the learned scene model (--scene learned) takes no rules file")
    laser_people = {"--tracker": tracker_kind != "pf", "--area": area != "auto"}
    if pipeline in ("traffic", "wearable", "people-camera") and any(laser_people.values()):
        given = ", ".join(k for k, v in laser_people.items() if v)
        raise ConfigError(f"{given}: only for the laser people pipelines people-laser and people (got --pipeline "
                          f"{pipeline})")
    if pipeline == "people-camera" and seed is not None:
        raise ConfigError("--seed: the people-camera pipeline draws no random numbers (it has no particle filter)")
    camera_only = {"--detections": detections is not None, "--detection-scale": detection_scale != 1.0,
                   "--min-score": min_score is not None,
                   "--camera-topic": camera_topic is not None and pipeline != "people",  # people: its camera
                   "--max-frames": max_frames is not None}
    if pipeline != "people-camera" and any(camera_only.values()):  # (traffic and wearable ignored them)
        given = ", ".join(k for k, v in camera_only.items() if v)
        raise ConfigError(f"{given}: only for --pipeline people-camera (got --pipeline {pipeline})")
    if pipeline == "people-camera":
        if detection_scale != 1.0 and detections is None:
            raise ConfigError("--detection-scale: scales the boxes of --detections, and none were given")
        if min_score is not None and not math.isfinite(min_score):
            raise ConfigError(f"--min-score: expected a finite detection score, got {min_score}")
        video_in = len(recordings) == 1 and recordings[0].suffix.lower() in VIDEO_SUFFIXES
        if camera_topic is not None and video_in:
            raise ConfigError(f"--camera-topic: {recordings[0]} is a video file (it has no topics)")
    if pipeline == "wearable" and time_source != "header":
        raise ConfigError("--time: the wearable pipeline reads its sensors by their header stamps only")
    before = _snapshot(output)  # the earlier run's outputs, to remove those this run does not rewrite
    if pipeline == "wearable":
        _track_wearable(recordings, output, config=config, seed=seed)
        _drop_stale_outputs(output, before)
        return
    if pipeline == "traffic":
        _track_traffic(recordings, output, config=config, geometry=geometry, rules=rules, compare=compare,
                       video=video, time_source=time_source, seed=seed, calibration=calibration, scene=scene,
                       workers=workers)
        _drop_stale_outputs(output, before)
        return
    seed = 0 if seed is None else seed
    if pipeline == "people-camera":
        if config is not None:
            raise ConfigError("--config: the people-camera pipeline takes no pipeline file yet (its camera comes "
                              "from the recording's CameraInfo and /tf_static)")
        _track_camera(recordings, output, detections=detections, detection_scale=detection_scale,
                      min_score=min_score, camera_topic=camera_topic, max_frames=max_frames,
                      time_source=time_source, video=video)
        _drop_stale_outputs(output, before)
        return
    from .tracking.tracker import track_recording

    cfg = _load_config(config)
    _check_laser_tables(cfg, config, tracker_kind)
    _check_sensor_topics(cfg, config, recordings, {"laser", "camera", "rgbd"} if pipeline == "people" else {"laser"})
    topics = [s.topic for s in cfg.sensors.values() if s.kind == "laser"] or None
    if topics:  # the file's lasers are the ones tracked: the recording's others left out are said, not silent
        from .io.recording import LASERSCAN, Recording

        with Recording(recordings) as rec:
            others = sorted(t for t, ty in rec.topic_types().items() if ty == LASERSCAN and t not in topics)
        if others:
            log.warning("%s lists the laser(s) %s: only they are tracked; the recording's %s %s left out (list "
                        "them under [sensors] to track with them too)", config, ", ".join(topics),
                        ", ".join(others), "is" if len(others) == 1 else "are")
    area_m: Any = {"auto": "auto", "none": None}.get(area)
    if area_m is None and area != "none":
        try:
            area_m = [float(v) for v in area.split(",")]
        except ValueError as err:
            raise ConfigError(f"--area: expected auto, none or x_min,y_min,x_max,y_max, got {area!r}") from err
        if len(area_m) != 4 or not (area_m[0] < area_m[2] and area_m[1] < area_m[3]):
            raise ConfigError(f"--area: expected x_min,y_min,x_max,y_max with min < max, got {area!r}")
    timings: dict[str, list[float]] = {"detect_s": [], "track_s": []}
    with progress() as bar:
        task = bar.add_task(f"tracking ({tracker_kind})", total=1.0)
        if pipeline == "people":  # seed 001's fused pipeline (fusiontrack.fusion)
            from .fusion import FusionParams, camera_boxes, track_fused

            if tracker_kind != "pf":
                raise ConfigError(f"--tracker: the people pipeline uses the pf tracker, got {tracker_kind!r}")
            cameras = [s.topic for s in cfg.sensors.values() if s.kind in ("camera", "rgbd")]
            if camera_topic is None and len(cameras) == 1:  # the camera the pipeline file names
                camera_topic = cameras[0]
            elif camera_topic is None and len(cameras) > 1:
                raise ConfigError(f"{config} lists several cameras ({', '.join(cameras)}): the people pipeline "
                                  "fuses one; choose it with --camera-topic")
            fusion_params = FusionParams.from_mapping(cfg.fusion, f"{config}: [fusion]") if cfg.fusion else None
            states, events, fstats = track_fused(
                recordings, params=fusion_params, tracker_params=cfg.tracking or None, camera_topic=camera_topic,
                topics=topics, time_source=time_source, clock_corrections_ns=cfg.clock_corrections_ns(),
                detector_params=cfg.laser or None, rng=seed, area_m=area_m, timings=timings,
                adaptive_bias=camera_bias, progress=lambda f: bar.update(task, completed=f),
                laser_poses=cfg.laser_poses(), sync_window_ns=cfg.sync.window_ns, camera_poses=cfg.camera_poses())
            states = camera_boxes(states, fstats, fusion_params)  # each person's box in the camera (box_px)
            if not fstats.camera:
                console.print("[yellow]no usable camera: people tracked with the lasers only[/yellow]")
            else:
                console.print(f"{fstats.camera}: {fstats.frames_used} images read, {fstats.train_updates} "
                              f"classifier updates from {fstats.train_frames} training frames, "
                              f"{fstats.checks} identity checks ({fstats.exchanges} exchanged), {fstats.reids} of "
                              f"{fstats.reid_claims} reborn tracks re-identified, {fstats.splits_by_appearance} of "
                              f"{fstats.splits} splits by appearance")
            if fstats.bias is not None:
                from .calibration.bias_run import write_bias_history

                output.mkdir(parents=True, exist_ok=True)
                write_bias_history(output / "bias.csv", fstats.bias.history)
                b = fstats.bias
                state = ("settled" if b.settled else "not settled") + ("" if b.applied else ", not applied")
                console.print(f"{fstats.camera} horizontal bias {math.degrees(b.bias_rad):.3f} deg ({b.updates} "
                              f"updates, {state}; {b.seconds:.1f} s) -> {output / 'bias.csv'}")
        else:
            states, events = track_recording(
                recordings, tracker=tracker_kind, params=cfg.tracking or None, topics=topics,
                time_source=time_source, clock_corrections_ns=cfg.clock_corrections_ns(),
                detector_params=cfg.laser or None, rng=seed, area_m=area_m, timings=timings,
                progress=lambda f: bar.update(task, completed=f), laser_poses=cfg.laser_poses(),
                sync_window_ns=cfg.sync.window_ns)
    output.mkdir(parents=True, exist_ok=True)
    write_tracks_csv(output / "tracks.csv", states)
    write_jsonl(output / "tracks.jsonl", [*states, *events])
    n_tracks = len({s.track_id for s in states})
    kinds: dict[str, int] = {}
    for ev in events:
        kinds[ev.kind] = kinds.get(ev.kind, 0) + 1
    import numpy as np

    per_scan = (np.array(timings["detect_s"]) + np.array(timings["track_s"])) * 1e3 if timings["track_s"] else []
    console.print(f"{n_tracks} tracks, {len(states)} states, events: {_counts(kinds)}"
                  + (f"; per scan median {np.median(per_scan):.2f} ms, p95 {np.percentile(per_scan, 95):.2f} ms"
                     if len(per_scan) else "") + f" -> {output}")
    if video:
        from .viz.preview import render_preview

        drawn = render_preview(recordings, output / "tracks.mp4", tracks=states, laser_poses=cfg.laser_poses())
        console.print(f"video: {output / 'tracks.mp4'} ({drawn.frames} frames)")
        if pipeline == "people" and fstats.camera:  # laser points, boxes, ids, situations, live bias
            from .viz.fused_overlay import render_fused_overlay

            lasers = None  # every laser, unless the pipeline file chose some
            if topics:
                from .io.recording import Recording

                with Recording(recordings) as rec:
                    lasers = [rec.sensor_of(t) for t in topics]
            from .io.recording import Recording

            with Recording(recordings) as rec:  # the overlay names its lasers by sensor
                poses = {rec.sensor_of(t): pose for t, pose in cfg.laser_poses().items()}
            ov = render_fused_overlay(recordings, output / "overlay.mp4", states, camera=fstats.camera,
                                      camera_model=fstats.camera_model,  # (posed as the tracker's: -c's pose)
                                      image_topic=camera_topic, bias_history=fstats.bias, events=events,
                                      time_source=time_source, clock_corrections_ns=cfg.clock_corrections_ns(),
                                      lasers=lasers, laser_poses=poses or None)
            console.print(f"overlay: {output / 'overlay.mp4'} ({ov.frames} frames)")
    _drop_stale_outputs(output, before)


MANIFEST = ".fusiontrack-track"
"""The file, in a ``track`` output folder, that lists what the run wrote there (one name per line)."""


def _file_stats(output: Path) -> dict[str, tuple[int, int, int]]:
    """name -> (inode, mtime, size) of the files in ``output`` (none if it does not exist)."""
    out = {}
    for f in output.iterdir() if output.is_dir() else []:
        try:
            if f.is_file():
                st = f.stat()
                out[f.name] = (st.st_ino, st.st_mtime_ns, st.st_size)
        except OSError:
            continue
    return out


def _snapshot(output: Path) -> tuple[set[str], dict[str, tuple[int, int, int]]]:
    """Before a run: the names the earlier run listed in its manifest, and every file's state."""
    try:
        listed = set((output / MANIFEST).read_text(encoding="utf-8").split("\n")) - {"", MANIFEST}
    except OSError:
        listed = set()
    return {n for n in listed if "/" not in n}, _file_stats(output)


def _drop_stale_outputs(output: Path, before: tuple[set[str], dict[str, tuple[int, int, int]]]) -> None:
    """After a run into a folder used before: the earlier run's outputs (its manifest, :data:`MANIFEST`) that this
    one did not rewrite (a video kept by --no-video, another pipeline's overlay or bias history) are removed, so
    that none is taken for this run's; said in one line. Only files an earlier ``track`` listed as its own and this
    run left as they were are removed (never a file fusiontrack did not write; no clock is compared), and only
    after the run succeeded (a failed run loses nothing). The new manifest lists the files this run wrote."""
    listed, stats = before
    now = _file_stats(output)
    written = sorted(n for n, st in now.items() if n != MANIFEST and stats.get(n) != st)
    stale = []
    for name in sorted(listed - set(written)):
        if name in now and now[name] == stats.get(name):
            try:
                (output / name).unlink()
                stale.append(name)
            except OSError as err:
                log.warning("%s: an output of an earlier run could not be removed (%s)", output / name,
                            err.strerror or err)
    try:
        (output / MANIFEST).write_text("".join(f"{n}\n" for n in written), encoding="utf-8")
    except OSError as err:
        log.warning("%s: cannot write the list of outputs (%s)", output / MANIFEST, err.strerror or err)
    if stale:
        console.print(f"removed from {output} what an earlier run wrote and this one did not: {', '.join(stale)}")


def _track_wearable(sources: list[Path], output: Path, *, config: Path | None, seed: int | None) -> None:
    """``track --pipeline wearable``: seed 002's pipeline; per phone the corrected trajectory, boxes and events."""
    from .fusion.wearable import run_wearable

    if len(sources) != 1:
        raise ConfigError(f"wearable: one recording at a time (got {len(sources)})")
    cfg = _load_config(config)
    _check_laser_tables(cfg, config, "any")  # (unused here, but a typo in the file is an error whatever the run)
    _check_sensor_topics(cfg, config, sources, {"imu", "rgbd", "camera"})
    options = {"seed": 0, **cfg.wearable, **({} if seed is None else {"seed": seed})}  # --seed wins
    model = options.get("step_model")
    if isinstance(model, str) and model and config is not None:  # a file named by the pipeline file: relative to it,
        path = config.parent / model  # as [traffic] calibration is (it was read relative to the working directory)
        if not path.is_file():
            raise ConfigError(f"{config}: [wearable] step_model: {path}: no such file")
        options["step_model"] = str(path)
    with progress() as bar:
        task = bar.add_task("tracking (wearable)", total=None)
        summary = run_wearable(sources[0], output, **options)
        bar.update(task, completed=1, total=1)
    table = Table(title="people by phone")
    for col in ("phone", "status", "steps", "distance m", "RGB-D fixes", "corrected from s", "visual failures",
                "recoveries"):
        table.add_column(col, justify="left" if col in ("phone", "status") else "right")
    for phone, p in summary["people"].items():
        fails = sum(c["failures"] for c in p["cameras"].values())
        recs = sum(c["recoveries"] for c in p["cameras"].values())
        table.add_row(phone, p["status"], str(p["steps"]), f"{p['distance_m']:.1f}", str(p["fixes"]),
                      "–" if p["corrected_from_s"] is None else f"{p['corrected_from_s']:.1f}", str(fails), str(recs))
    console.print(table)
    console.print(f"events: {_counts(summary['events'])} -> {output}")


def _track_traffic(sources: list[Path], output: Path, *, config: Path | None, geometry: Path | None,
                   rules: Path | None, compare: bool, video: bool, time_source: str, seed: int | None,
                   calibration: Path | None, scene: str, workers: int | None = None) -> None:
    """``track --pipeline traffic``: seed 003's pipeline; writes tracks, events, summary and report.html."""
    from .fusion.traffic import TrafficParams
    from .fusion.traffic_run import run_traffic

    if len(sources) != 1:
        raise ConfigError(f"traffic: one recording at a time (got {len(sources)})")
    cfg = _load_config(config)
    _check_laser_tables(cfg, config, "any")  # (unused here, but a typo in the file is an error whatever the run)
    _check_sensor_topics(cfg, config, sources, {"laser", "camera"})
    table = dict(cfg.traffic or {})
    in_file = table.pop("calibration", None)
    if calibration is None and in_file is not None:  # relative to the pipeline file
        if not isinstance(in_file, str) or not in_file:
            raise ConfigError(f"{config}: [traffic] calibration: expected a file name, got {in_file!r}")
        calibration = config.parent / in_file if config is not None else Path(in_file)
    params = TrafficParams.from_mapping(table, f"{config}: [traffic]") if table else TrafficParams()
    if seed is not None:  # --seed wins over the pipeline file's [traffic.tracker] seed
        from dataclasses import replace

        params = replace(params, tracker=replace(params.tracker, seed=seed))
    if workers is not None:  # --workers wins over the pipeline file's [traffic] workers
        from dataclasses import replace

        params = replace(params, workers=workers)
    with progress() as bar:
        task = bar.add_task("tracking (traffic)", total=1.0)
        summary = run_traffic(sources[0], output, geometry=geometry, rules=rules, params=params, compare=compare,
                              video=video, time_source=time_source, progress=lambda f: bar.update(task, completed=f),
                              calibration=calibration, scene_engine=scene)
    console.print(f"{summary['tracks']} tracks over {summary['duration_s']:.1f} s at {summary['x_real_time']:.1f}x "
                  f"real time ({summary['workers']} camera worker(s)); events: {_counts(summary['events'])} -> "
                  f"{output}")
    if "metrics" in summary:
        table = Table(title="vehicles against ground truth (match within 2 m)")
        for col in ("variant", "MOTA", "IDF1", "HOTA", "IDSW", "FP", "FN"):
            table.add_column(col, justify="left" if col == "variant" else "right")
        for v, m in summary["metrics"].items():
            table.add_row(v, *(f"{m[k]:.3f}" if isinstance(m[k], float) else str(m[k])
                               for k in ("MOTA", "IDF1", "HOTA", "IDSW", "FP", "FN")))
        console.print(table)
    if "incidents" in summary:
        table = Table(title="incidents against the simulator's labels")
        for col in ("kind", "true", "detections", "hits", "false alarms", "onset latency s", "alarm latency s"):
            table.add_column(col, justify="left" if col == "kind" else "right")
        for k, v in summary["incidents"].items():
            table.add_row(k, str(v["true"]), str(v["detections"]), str(v["hits"]), str(v["false_alarms"]),
                          *("–" if v[x] is None else f"{v[x]:.2f}" for x in ("onset_latency_s", "alarm_latency_s")))
        console.print(table)
    console.print(f"report: {output / 'report.html'}")


@app.command()
def events(
    tracks: Annotated[Path, typer.Argument(help="tracks.csv / tracks.jsonl (or the folder of `fusiontrack track`).")],
    geometry: Annotated[Path | None, typer.Option(help="Road geometry TOML (roads, lanes, zones).")] = None,
    world: Annotated[Path | None, typer.Option(help="Or the simulator's world.json (or its run folder).")] = None,
    rules: Annotated[Path | None, typer.Option(help="Incident rules TOML (default: the shipped D8 rules).")] = None,
    learned: Annotated[bool, typer.Option(help="Use the learned behaviour model instead of the rules.")] = False,
    truth: Annotated[Path | None, typer.Option(help="A simulated run folder: score the events against its "
                                               "incidents.")] = None,
    output: Annotated[Path | None, typer.Option("--output", "-o", help="Write the events here (JSONL).")] = None,
) -> None:
    """Re-run scene understanding (seed 003 D7/D8) on saved tracks: incidents as JSONL, scored if --truth."""
    from .io.tracks import write_jsonl
    from .scene import detect_events, detect_events_learned, load_road_geometry, load_rules, road_geometry_from_world

    if (geometry is None) == (world is None):
        raise ConfigError("events: give the road as --geometry FILE.toml or --world world.json (exactly one)")
    if output is not None:
        truth_files = [truth]
        if truth is not None and truth.is_dir():  # a run folder: the files read in it
            truth_files = [truth / sub / name for sub in ("ground_truth", ".") for name in ("incidents.jsonl",
                                                                                            "agents.csv")]
        world_file = world / "ground_truth" / "world.json" if world is not None and world.is_dir() else world
        _out_file(output, "events.jsonl", reads=[*_track_files(tracks), geometry, world_file, rules, *truth_files])
    if geometry is not None:
        geo = load_road_geometry(geometry)
    else:
        w = world / "ground_truth" / "world.json" if world.is_dir() else world
        if not w.is_file():
            raise ConfigError(f"--world {world}: no such file (expected the simulator's world.json)")
        geo = road_geometry_from_world(w)
    states, _ = _read_tracks(tracks)
    if not states:
        raise ConfigError(f"{tracks}: no track states")
    if learned:
        if rules is not None:
            raise ConfigError("--rules: the learned model takes no rules file")
        found = detect_events_learned(states, geo)
    else:
        found = detect_events(states, geo, load_rules(rules) if rules is not None else None)
    kinds: dict[str, int] = {}
    for e in found:
        kinds[e.kind] = kinds.get(e.kind, 0) + 1
    console.print(f"{len(found)} events from {len({s.track_id for s in states})} tracks: {_counts(kinds)}")
    if output is not None:
        write_jsonl(output, found)
        console.print(f"events: {output}")
    if truth is not None:
        from .eval.events import event_table, read_agents_csv, read_incidents, score_events

        scores = score_events(read_incidents(truth), found, read_agents_csv(truth))
        console.print(event_table(scores, title="incidents against the simulator's labels"))


def _track_camera(sources: list[Path], output: Path, *, detections: Path | None, detection_scale: float,
                  min_score: float | None, camera_topic: str | None, max_frames: int | None, time_source: str,
                  video: bool) -> None:
    """``track --pipeline people-camera``: the vision-only tracker over a video or a recording's camera."""
    from .errors import RecordingError
    from .io.tracks import write_jsonl, write_mot, write_tracks_csv
    from .vision.people import VIDEO_SUFFIXES, track_camera

    videos = [p for p in sources if p.suffix.lower() in VIDEO_SUFFIXES]
    if videos and len(sources) > 1:
        raise ConfigError(f"people-camera: one video at a time, or recordings only (got {len(sources)} inputs "
                          f"including {videos[0]})")
    if detections is not None and not detections.is_file():
        raise RecordingError(f"--detections {detections}: no such file (expected MOTChallenge rows "
                             "frame,-1,left,top,width,height,conf,...)")
    created = not output.exists()
    output.mkdir(parents=True, exist_ok=True)
    overlay = output / "overlay.mp4" if video else None
    try:
        with progress() as bar:
            task = bar.add_task("tracking (camera)", total=1.0)
            states, events, stats = track_camera(
                sources, detections=detections, detection_scale=detection_scale,
                min_score=-float("inf") if min_score is None else min_score, camera_topic=camera_topic,
                overlay=overlay, max_frames=max_frames, time_source=time_source,
                progress=lambda f: bar.update(task, completed=f))
    except BaseException:
        if created and not any(output.iterdir()):  # a wrong topic or an empty video: no empty folder left behind
            output.rmdir()
        raise
    write_tracks_csv(output / "tracks.csv", states)
    write_jsonl(output / "tracks.jsonl", [*states, *events])
    write_mot(output / "tracks_mot.txt", states, frame_of=stats.frame_of())
    kinds: dict[str, int] = {}
    for ev in events:
        kinds[ev.kind] = kinds.get(ev.kind, 0) + 1
    source = f"detections {detections.name}" if detections is not None else "foreground blobs"
    floor = "floor positions from the calibrated camera" if stats.calibrated else "no camera calibration: x, y NaN"
    console.print(f"{stats.n_tracks} tracks, {len(states)} states over {stats.n_frames} frames of {stats.width}x"
                  f"{stats.height} from {source}, events: {_counts(kinds)}; {stats.fps:.1f} fps "
                  f"(decode + detection + tracking); {floor} -> {output}")
    if overlay is not None:
        console.print(f"overlay: {overlay} ({stats.n_frames} frames)")


def _tracks_file(path: Path) -> Path:
    """The tracks file ``path`` names: itself, or in a folder of `fusiontrack track` its tracks.jsonl (else
    tracks.csv)."""
    if path.is_dir():
        return path / "tracks.jsonl" if (path / "tracks.jsonl").exists() else path / "tracks.csv"
    return path


def _track_files(path: Path) -> list[Path]:
    """The tracks file ``path`` names, or the tracks files of a `fusiontrack track` folder (outputs must not
    overwrite them)."""
    return [path / "tracks.jsonl", path / "tracks.csv", path / "tracks_mot.txt"] if path.is_dir() else [path]


def _read_tracks(path: Path) -> tuple[list[Any], list[Any]]:
    from .io.tracks import read_jsonl, read_tracks_csv
    from .types import Event, TrackState

    path = _tracks_file(path)
    if path.suffix == ".csv":
        return read_tracks_csv(path), []
    records = read_jsonl(path)
    return [r for r in records if isinstance(r, TrackState)], [r for r in records if isinstance(r, Event)]


def _read_truth(path: Path, topic: str | None, time_source: str) -> tuple[list[Any], str]:
    import numpy as np

    from .io.recording import Recording
    from .types import GroundTruth

    if path.suffix.lower() == ".csv":
        from .io.tracks import read_ground_truth_csv

        if topic is not None:
            raise ConfigError(f"--topic {topic}: {path} is a CSV file, not a recording (it has no topics)")
        return read_ground_truth_csv(path), path.name
    with Recording(path) as rec:
        info = rec.topic_types()
        if topic is None:
            candidates = [t for t, msgtype in info.items() if msgtype in ("fusiontrack_msgs/msg/GroundTruth",
                                                                          "leg_tracker/msg/Person")]
            topic = "/ground_truth" if "/ground_truth" in candidates else (candidates[0] if len(candidates) == 1
                                                                           else None)
            if topic is None and not candidates:
                raise ConfigError(f"{path}: no ground-truth topic (fusiontrack_msgs/msg/GroundTruth or "
                                  f"leg_tracker/msg/Person); give the truth as a CSV file (t or t_ns, id, x, y)")
            if topic is None:
                raise ConfigError(f"{path}: say which ground-truth topic to use with --topic "
                                  f"(found {', '.join(candidates)})")
        if topic not in info:
            raise ConfigError(f"--topic {topic}: {path} has no such topic; it has: {', '.join(sorted(info))}")
        if info[topic] == "leg_tracker/msg/Person":
            # leg_tracker's annotators' rule: the Person messages that follow scan k belong to scan k
            from .io.recording import LASERSCAN
            from .io.sync import with_time

            lasers = [t for t, msgtype in info.items() if msgtype == LASERSCAN]
            frames, scan_t = [], None
            for m in rec.messages([*lasers, topic], time_source="log"):
                if isinstance(m, GroundTruth):
                    if scan_t is not None:
                        frames.append(with_time(m, scan_t))
                else:
                    scan_t = m.t_ns  # log order decides which scan an annotation follows
            if time_source == "header":  # restamp with the scans' header times
                by_log = {s_log: s.t_ns for s_log, s in zip(
                    (x.t_ns for x in rec.messages(lasers, time_source="log")), rec.messages(lasers), strict=True)}
                frames = [with_time(f, by_log[f.t_ns]) for f in frames]
        else:
            frames = [m for m in rec.messages([topic], time_source=time_source) if isinstance(m, GroundTruth)]
            if not frames:
                raise ConfigError(f"--topic {topic}: {info[topic]} is not ground truth; eval reads "
                                  f"fusiontrack_msgs/msg/GroundTruth or leg_tracker/msg/Person topics, or a CSV "
                                  f"file (t or t_ns, id, x, y)")
            if all(not len(f.ids) for f in frames):
                raise ConfigError(f"--topic {topic}: its {len(frames)} frames hold nobody")
            if all("foot" in f.attributes for f in frames):  # the simulator's /ground_truth/steps
                raise ConfigError(f"--topic {topic}: holds heel strikes (one per step), not where people are at each "
                                  f"instant; eval scores tracks against "
                                  f"{'/ground_truth' if '/ground_truth' in info else 'a topic of people positions'}")
            if all((np.asarray(f.ids) < 0).all() for f in frames if len(f.ids)):
                raise ConfigError(f"--topic {topic}: its {info[topic]} positions carry no identities, "
                                  f"which scoring tracks needs; give the truth as a CSV file (t or t_ns, id, x, y)")
    return frames, topic


@app.command()
def appearance(
    video: Annotated[Path, typer.Argument(help="A video file (mp4, avi, ...).")],
    detections: Annotated[Path, typer.Option(help="Person boxes in it: MOTChallenge rows "
                                             "frame,-1,left,top,width,height,conf,... (frames from 1).")],
    detection_scale: Annotated[float, typer.Option(help="Multiply the boxes by this (e.g. 0.625 for 768x576 boxes "
                                                   "on a 480x360 video).")] = 1.0,
    min_score: Annotated[float | None, typer.Option(help="Drop detections with a lower conf.")] = None,
    max_frames: Annotated[int | None, typer.Option(help="Only the first N frames.")] = None,
    output: Annotated[Path | None, typer.Option("--output", "-o", help="Write the figures as JSON here.")] = None,
) -> None:
    """How well seed 001's per-person classifiers tell the people of a video apart: before trusting the fused
    pipeline's identity checks with this camera.

    The classifiers learn and are tested as the fused tracker uses them (test then train: a person learns while
    somebody is near, with them as negatives, and scores its own box against its neighbours'), with identities
    from unambiguous box continuity, so no annotation is needed (fusiontrack.eval.appearance). Prints the share
    of scores the right way round, the evidence, and the verdicts identity checks would have given.
    """
    import numpy as np

    from .eval.appearance import neighbour_evidence
    from .io.tracks import read_mot
    from .io.video import VideoReader
    from .vision.people import _check_detections

    if not detections.is_file():
        raise RecordingError(f"--detections {detections}: no such file (expected MOTChallenge rows "
                             "frame,-1,left,top,width,height,conf,...)")
    if not (math.isfinite(detection_scale) and detection_scale > 0):
        raise ConfigError(f"--detection-scale: expected a number > 0, got {detection_scale!r}")
    if max_frames is not None and max_frames < 1:
        raise ConfigError(f"--max-frames: expected a number of frames >= 1, got {max_frames!r}")
    if min_score is not None and not math.isfinite(min_score):
        raise ConfigError(f"--min-score: expected a finite detection score, got {min_score}")
    det = read_mot(detections).scaled(detection_scale)
    if min_score is not None:
        keep = det.conf >= min_score
        if not keep.any():
            raise ConfigError(f"--min-score {min_score:g}: above every detection's score in {detections} "
                              f"({det.conf.min():g} to {det.conf.max():g})")
        det = det.select(keep)
    reader = VideoReader(video, "camera", fps=1.0)  # (times are not used: frames are counted)
    with reader:
        _check_detections(det, reader.width, reader.height, video)
        with progress() as bar:
            total = reader.frame_count if max_frames is None else min(max_frames, reader.frame_count or max_frames)
            task = bar.add_task("classifiers (test then train)", total=total or None)

            def frames():
                for k, img in enumerate(reader, start=1):
                    if max_frames is not None and k > max_frames:
                        return
                    bar.update(task, completed=k)
                    yield k, img.pixels

            ne = neighbour_evidence(frames(), det)
    e = ne.evidence
    v = ne.verdicts()
    result = {"video": str(video), "detections": str(detections), "detection_scale": detection_scale,
              "min_score": min_score, "max_frames": max_frames, "frames": ne.frames,
              "detections_read": ne.detections, "empty_boxes": ne.dropped, "tracklets": ne.tracklets,
              "scores": int(e.size), "right_sign": ne.right_sign(),
              "mean_evidence": float(e.mean()) if e.size else math.nan,
              "evidence_p10": float(np.percentile(e, 10)) if e.size else math.nan,
              "evidence_over_0_6": float(np.mean(e > 0.6)) if e.size else math.nan, "verdicts": v}

    def shown(x: float, fmt: str) -> str:
        return format(x, fmt) if math.isfinite(x) else "-"

    table = Table(title=f"seed 001's classifiers on {video.name} (neighbours, test then train)", header_style="bold")
    table.add_column("figure")
    table.add_column("value", justify="right")
    for label, value in (("frames read / detections in them", f"{ne.frames} / {ne.detections}"),
                         ("tracklets (identities from box continuity)", str(ne.tracklets)),
                         ("scores (a person's classifier on its box and a neighbour's)", str(e.size)),
                         ("right way round (own box higher)", shown(result["right_sign"], ".1%")),
                         ("mean evidence (own - neighbour, in [-2, 2])", shown(result["mean_evidence"], ".2f")),
                         ("10th percentile of the evidence", shown(result["evidence_p10"], ".2f")),
                         ("evidence > 0.6", shown(result["evidence_over_0_6"], ".1%")),
                         ("identity checks: kept (right)", str(v["keep"])),
                         ("identity checks: exchanged (wrong)", str(v["exchange"])),
                         ("identity checks: undecided", str(v["undecided"]))):
        table.add_row(label, value)
    console.print(table)
    if ne.dropped:
        console.print(f"[yellow]{ne.dropped} empty or non-finite boxes left out[/yellow]")
    if not ne.detections:
        console.print(f"[yellow]no detection of {detections} falls in the {ne.frames} frames read (frames are "
                      "counted from 1)[/yellow]")
    elif not e.size:
        console.print("[yellow]no person was ever scored against a neighbour: nobody was near anybody long enough "
                      "for a classifier to learn first (or the frames read are too few)[/yellow]")
    if output is not None:
        output.parent.mkdir(parents=True, exist_ok=True)
        finite = {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in result.items()}
        output.write_text(json.dumps(finite, indent=2) + "\n")
        console.print(f"figures: {output}")


@app.command(name="eval")
def eval_(
    tracks: Annotated[Path, typer.Argument(help="tracks.csv / tracks.jsonl (or the folder of `fusiontrack track`),"
                                                " or a MOTChallenge result file.")],
    ground_truth: Annotated[Path, typer.Argument(help="Recording with ground truth; a CSV of floor positions "
                                                      "(header: t or t_ns, id, x, y[, class]; metres); or a "
                                                      "MOTChallenge gt file.")],
    threshold: Annotated[float, typer.Option(help="Floor-plane match distance in metres.")] = 0.5,
    topic: Annotated[str | None, typer.Option(help="Ground-truth topic (default: /ground_truth, or the only one).")
                     ] = None,
    time_source: Annotated[str, typer.Option("--time", help="Ground-truth times: header or log.")] = "header",
    output: Annotated[Path | None, typer.Option("--output", "-o", help="Write the metrics as JSON here.")] = None,
    camera: Annotated[str | None, typer.Option(help="Score image boxes against this camera's truth boxes "
                                               "(/ground_truth/CAMERA of a simulated recording) by IoU >= 0.5; "
                                               "default for the folder of `track --pipeline people-camera`.")
                      ] = None,
    at: Annotated[str | None, typer.Option("--at", help="Score floor-plane tracks on the ground-truth frames nearest "
                                           "to this topic's messages only (e.g. /camera_0/image for tracks made "
                                           "at a 15 Hz camera's rate against 25 Hz truth: otherwise the truth "
                                           "frames between two of its frames count everybody as missed); its "
                                           "times as --time says.")
                  ] = None,
) -> None:
    """Score tracks against ground truth: MOTA, MOTP, IDF1, ID switches, HOTA, FP, FN, MT/ML (TrackEval).

    Floor-plane tracks are matched within --threshold metres; MOTChallenge box files by IoU >= 0.5.
    Image boxes of one camera (the output of `track --pipeline people-camera`: its folder, tracks.jsonl or
    tracks_mot.txt) are scored against a simulated recording's per-camera truth boxes by IoU >= 0.5 (people
    less than half visible are distractors), with --camera or when the folder's tracks are of one camera.
    For a simulated recording, situation detection (seed 001 Table II) is scored too.
    """
    from .eval import (
        evaluate_floor,
        evaluate_mot_files,
        frame_matches,
        id_switch_causes,
        metrics_table,
        situation_accuracy,
        situation_table,
        switch_cause_counts,
        truth_at,
    )

    _check_time(time_source)
    if not (math.isfinite(threshold) and threshold > 0):  # (named by the option, not the library's threshold_m)
        raise ConfigError(f"--threshold: expected a distance > 0 in metres, got {threshold:g}")
    if output is not None:
        _out_file(output, "metrics.json", reads=[*_track_files(tracks), ground_truth], recordings=[ground_truth])
    result: dict[str, Any] = {}
    boxes_at = ConfigError("--at: only for floor-plane tracks (image boxes are scored at their camera's frames)")
    if at is not None and (camera is not None or tracks.suffix == ".txt"):  # refused before any scoring
        raise boxes_at
    if ground_truth.suffix == ".txt" and tracks.is_dir() and (tracks / "tracks_mot.txt").is_file():
        tracks = tracks / "tracks_mot.txt"  # a people-camera folder scored against a MOTChallenge gt file
    if ground_truth.suffix == ".txt":  # (it was opened as a recording: "Unrecognized storage format '.txt'")
        if camera is not None:
            raise ConfigError(f"--camera: scores against a simulated recording's /ground_truth/CAMERA boxes; "
                              f"{ground_truth} is a MOTChallenge gt file (its boxes are matched frame by frame)")
        if tracks.suffix != ".txt":
            raise ConfigError(f"{ground_truth} is a MOTChallenge gt file (image boxes by frame): it scores "
                              f"MOTChallenge result rows (a .txt, or the tracks_mot.txt of `track --pipeline "
                              f"people-camera`, or its folder); {tracks} is not one (floor tracks are scored against "
                              f"a recording with ground truth or a CSV of floor positions)")
    if ground_truth.suffix.lower() == ".csv" and tracks.suffix == ".txt":
        raise ConfigError(f"{tracks}: MOTChallenge rows (image boxes) are scored against a MOTChallenge gt file or a "
                          f"simulated recording's camera boxes; {ground_truth} is a CSV of floor positions")
    if ground_truth.suffix.lower() == ".csv" and camera is not None:
        raise ConfigError(f"--camera: scores image boxes against a simulated recording's /ground_truth/CAMERA; "
                          f"{ground_truth} is a CSV of floor positions")
    image = _eval_image_boxes(tracks, ground_truth, camera, time_source)
    if at is not None and image is not None:  # a people-camera output found by its folder
        raise boxes_at
    if image is not None:
        metrics, cam = image
        console.print(metrics_table({f"{tracks.name} vs /ground_truth/{cam}": metrics},
                                    title="image boxes, match at IoU >= 0.5"))
        result["camera"] = cam
        result["metrics"] = metrics.to_dict()
    elif tracks.suffix == ".txt":
        floor_only = [o for o, used in (("--threshold", threshold != 0.5), ("--topic", topic is not None),
                                        ("--time", time_source != "header")) if used]
        if floor_only:  # (they were ignored without a word)
            raise ConfigError(f"{', '.join(floor_only)}: only for floor-plane tracks (MOTChallenge boxes are matched "
                              f"by IoU >= 0.5, frame by frame)")
        metrics = evaluate_mot_files(ground_truth, tracks)
        console.print(metrics_table({tracks.name: metrics}))
        result["metrics"] = metrics.to_dict()
    else:
        states, events = _read_tracks(tracks)
        if not states:  # a run that tracked nobody scores, but not silently
            log.warning("no track states in %s: every ground-truth position counts as missed", _tracks_file(tracks))
        frames, gt_topic = _read_truth(ground_truth, topic, time_source)
        scored, label = frames, f"{tracks.name} vs {gt_topic}"
        if at is not None:
            if ground_truth.suffix.lower() == ".csv":
                raise ConfigError(f"--at {at}: takes a topic's times from a recording; {ground_truth} is a CSV file")
            at_times = _topic_times(ground_truth, at, time_source)
            if not at_times:
                raise ConfigError(f"--at {at}: {ground_truth} has no message on it")
            scored = truth_at(frames, at_times)
            if not scored:
                raise ConfigError(f"--at {at}: none of its {len(at_times)} messages is within half a {gt_topic} "
                                  f"period of a {gt_topic} frame (check --time)")
            label += f" at {at}"
            result["at"] = {"topic": at, "frames": len(scored), "of": len(frames)}
        _check_people(ground_truth, scored, tracks, states)
        metrics = evaluate_floor(scored, states, threshold_m=threshold)
        console.print(metrics_table({label: metrics}, title=f"tracking, match within {threshold:g} m"))
        result["metrics"] = metrics.to_dict()
        # what kind of identity errors: where to look, and what would cure them (the JSON has the keys always)
        switches = id_switch_causes(frame_matches(scored, states, threshold_m=threshold), states, truth=scored) \
            if metrics.id_switches else []
        counts = switch_cause_counts(switches)
        if switches:
            console.print("ID switches by cause: " + ", ".join(f"{k.replace('_', ' ')} {v}" for k, v in counts.items())
                          + " (fusiontrack.eval.switches)")
        result["id_switch_causes"] = counts
        result["id_switches"] = [{"t_ns": w.t_ns, "gt_id": w.gt_id, "from_track": w.from_track,
                                  "to_track": w.to_track, "cause": w.cause} for w in switches]
        if events and frames and "situation" in frames[0].attributes:
            from .sim.situations import situation_events

            try:
                bounds = _bounds_of(ground_truth)
            except RecordingError as err:  # (the tracking metrics above stand; only the situations need the area)
                log.warning("%s: situation detection not scored", err)
            else:
                truth_events = situation_events(frames, bounds) if bounds is not None else []
                scores = situation_accuracy(truth_events, events, id_map=metrics.id_map)
                console.print(situation_table(scores, title="situation detection (seed 001 Table II)"))
                result["situations"] = {k: v.to_dict() if hasattr(v, "to_dict") else vars(v)
                                        for k, v in scores.items()}
    if output is not None:
        output.parent.mkdir(parents=True, exist_ok=True)
        from .io.datafile import json_text

        output.write_text(json_text(result))
        console.print(f"metrics: {output}")


def _check_people(ground_truth: Path, frames: Sequence[Any], tracks: Path, states: Sequence[Any]) -> None:
    """``eval`` scores people on the floor: truth without any (a road's vehicles) is an error that says where
    vehicles are scored (it scored GT 0, MOTA 0 without a word); tracks without any person, or without floor
    positions (an uncalibrated camera's), are warned of (every truth position then counts as missed)."""
    import collections

    def counts(c: collections.Counter[str]) -> str:
        return ", ".join(f"{k} {v}" for k, v in c.most_common())

    truth = collections.Counter(c for f in frames for c in (f.classes or ("person",) * len(f.ids)))
    if truth and not truth.get("person"):
        raise ConfigError(f"{ground_truth}: the truth holds no people ({counts(truth)}): eval scores people on the "
                          f"floor; vehicles are scored by `fusiontrack track --pipeline traffic` (its summary.json "
                          f"and report)")
    if not states:
        return
    kinds = collections.Counter(str(s.cls) for s in states)
    if not kinds.get("person"):
        log.warning("%s: no track state is a person (%s): every person in the truth counts as missed",
                    _tracks_file(tracks), counts(kinds))
    lost = sum(1 for s in states if not (math.isfinite(s.position_m[0]) and math.isfinite(s.position_m[1])))
    if lost:
        log.warning("%s: %d of %d track states have no floor position (NaN: tracks of a camera without a "
                    "calibration?); they count as false positives", _tracks_file(tracks), lost, len(states))


def _topic_times(path: Path, topic: str, time_source: str) -> list[int]:
    """The times of the messages on ``topic`` in the recording at ``path``: their header stamps (or log times, as
    ``--time`` says), read without converting the messages (no image is decoded). TopicError, naming the topic,
    when the recording does not have it."""
    from .io.recording import Recording
    from .io.ros import stamp_to_ns

    times = []
    with Recording(path) as rec:
        for _, _, log_ns, msg in rec.raw_messages([topic]):
            header = getattr(msg, "header", None)
            times.append((stamp_to_ns(header.stamp) or log_ns) if time_source == "header" and header is not None
                         else log_ns)
    return times


def _eval_image_boxes(tracks: Path, recording: Path, camera: str | None, time_source: str) -> tuple[Any, str] | None:
    """``eval`` of image boxes against ``/ground_truth/<camera>``; None when no camera is given and ``tracks`` is not
    a people-camera output of one camera (that has tracks_mot.txt beside it).

    Only the states of that camera are scored (an empty ``camera`` field counts as it). MOTChallenge rows (a
    ``.txt``) against a recording need the camera: from ``--camera``, else from the ``tracks.jsonl`` beside them
    (its boxes of one camera); a ConfigError naming ``--camera`` otherwise.
    """
    from .errors import RecordingError
    from .eval.mot import evaluate_camera_boxes
    from .io.recording import Recording
    from .io.tracks import read_jsonl, read_mot
    from .types import CameraInfo, GroundTruth, TrackState

    def cameras_of(states: list[TrackState]) -> set[str]:
        return {s.camera for s in states} - {""}

    folder = tracks if tracks.is_dir() else tracks.parent
    if recording.suffix.lower() == ".csv" and tracks.suffix != ".txt":
        return None  # floor positions as truth: a people-camera folder is scored by its tracks' floor positions
    mot_vs_recording = tracks.suffix == ".txt" and recording.suffix != ".txt"
    if mot_vs_recording and recording.is_dir() and not (recording / "metadata.yaml").is_file():
        raise ConfigError(f"{recording}: a folder that is not a recording (no metadata.yaml); MOTChallenge rows are "
                          "scored against a MOTChallenge gt file (.txt) or a simulated recording's camera boxes")
    if camera is None and not mot_vs_recording and (recording.suffix == ".txt"
                                                    or not (folder / "tracks_mot.txt").is_file()):
        return None  # a MOTChallenge gt file, or not a people-camera output
    source = tracks
    if tracks.is_dir():
        source = tracks / "tracks.jsonl" if (tracks / "tracks.jsonl").is_file() else tracks / "tracks_mot.txt"
    if source.suffix not in (".jsonl", ".txt") or not source.is_file():
        if camera is None:
            return None
        raise ConfigError(f"--camera: {tracks} has no image boxes (expected a people-camera output folder, its "
                          "tracks.jsonl or tracks_mot.txt, or a MOTChallenge result file)")
    states = ([r for r in read_jsonl(source) if isinstance(r, TrackState) and r.box_px is not None]
              if source.suffix == ".jsonl" else None)
    auto = camera is None
    if states is not None and not states and camera is not None:
        log.warning("no track states with image boxes in %s: every truth box counts as missed", source)
    if camera is None and states is None:  # MOT rows: their camera is that of the tracks.jsonl beside them
        sibling = source.parent / "tracks.jsonl"
        cams = cameras_of([r for r in read_jsonl(sibling) if isinstance(r, TrackState) and r.box_px is not None]) \
            if sibling.is_file() else set()
        if len(cams) != 1:
            found = f"the boxes of {sibling.name} beside it are of {sorted(cams)}" if sibling.is_file() else \
                "no tracks.jsonl beside it names their camera"
            raise ConfigError(f"{source}: MOTChallenge rows against the recording {recording} are scored against one "
                              f"camera's truth boxes: give --camera ({found})")
        camera = cams.pop()
        log.info("%s: the boxes are of %s (from %s)", source, camera, sibling)
    if camera is None:  # auto: the one camera of the states, if the recording has its truth boxes
        cams = cameras_of(states or [])
        if len(cams) != 1:
            return None
        camera = cams.pop()
    camera = camera.strip("/").removeprefix("ground_truth/")
    topic = f"/ground_truth/{camera}"
    with Recording(recording) as rec:
        topics = rec.topic_types()
        if topic not in topics:
            if auto and states is not None:
                return None
            found = sorted(t for t in topics if t.startswith("/ground_truth/"))
            raise RecordingError(f"{recording}: no truth boxes {topic} for --camera {camera} (found "
                                 f"{', '.join(found) or 'none'})")
        truth = [m for m in rec.messages([topic], time_source=time_source) if isinstance(m, GroundTruth)]
        info_topic = f"/{camera}/camera_info"
        info = next((m for m in rec.messages([info_topic]) if isinstance(m, CameraInfo)), None) \
            if info_topic in topics else None
    size = (info.width, info.height) if info is not None else (None, None)
    res: Any = states if states is not None else read_mot(source)
    return evaluate_camera_boxes(truth, res, *size, camera=camera, name=f"{source} vs {topic}"), camera


def _bounds_of(recording: Path) -> Any:
    """The area of a recording made by `fusiontrack simulate` (its ground_truth/world.json), else None."""
    world = recording / "ground_truth" / "world.json" if recording.is_dir() else None
    if world is None or not world.exists():
        return None
    try:
        bounds = json.loads(world.read_text(encoding="utf-8"))["bounds_m"]
        if len(bounds) != 4 or not all(math.isfinite(float(v)) for v in bounds):
            raise ValueError(bounds)
    except (OSError, UnicodeDecodeError, ValueError, KeyError, TypeError) as err:  # (JSONDecodeError: ValueError)
        raise RecordingError(f"{world}: not the simulator's world description (expected JSON with bounds_m = "
                             f"[x_min, y_min, x_max, y_max]; {type(err).__name__}: {err})") from None
    return bounds


# --------------------------------------------------------------------------------------------------
# train-classifier, pdr, fit-step-model
# --------------------------------------------------------------------------------------------------


def _parse_intrinsics(text: str) -> tuple[Any, Any]:
    """``--intrinsics fx,fy,cx,cy[,k1,k2,p1,p2[,k3]]`` as (K, distortion or None); a ConfigError naming the option
    for anything but finite numbers with focal lengths fx, fy > 0."""
    import math

    import numpy as np

    try:
        vals = [float(v) for v in text.split(",")]
    except ValueError as err:
        raise ConfigError(f"--intrinsics: expected numbers fx,fy,cx,cy[,...], got {text!r}") from err
    if len(vals) not in (4, 8, 9):
        raise ConfigError(f"--intrinsics: expected 4, 8 or 9 numbers, got {len(vals)}")
    if not all(math.isfinite(v) for v in vals):
        raise ConfigError(f"--intrinsics: expected finite numbers, got {text!r}")
    fx, fy, cx, cy = vals[:4]
    if fx <= 0 or fy <= 0:
        raise ConfigError(f"--intrinsics: expected focal lengths fx, fy > 0 (pixels), got fx={fx:g}, fy={fy:g}")
    return np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1.0]]), np.array(vals[4:]) if len(vals) > 4 else None


@app.command()
def calibrate(
    camera: Annotated[str, typer.Argument(help="The camera's sensor name in the pipeline file.")],
    config: Annotated[Path, typer.Option("--config", "-c", help="Pipeline file: the camera's pose is rewritten "
                                         "there (only that line).")],
    points: Annotated[Path | None, typer.Option(help="Control points CSV: x_m,y_m,z_m,u_px,v_px (PnP).")] = None,
    reference: Annotated[str | None, typer.Option(help="With --points: frame of the control points, world (the "
                                                  "default) or a sensor of the pipeline (e.g. a laser).")] = None,
    recording: Annotated[Path | None, typer.Option(help="With --points: a recording whose CameraInfo gives the "
                                                   "intrinsics (unless --intrinsics does), and whose /tf_static "
                                                   "poses a --reference laser the pipeline file does not.")] = None,
    intrinsics: Annotated[str | None, typer.Option(help="With --points: fx,fy,cx,cy[,k1,k2,p1,p2[,k3]].")] = None,
    ransac: Annotated[bool, typer.Option(help="With --points: RANSAC against mis-clicked points.")] = False,
    adaptive: Annotated[Path | None, typer.Option(help="Instead of points: learn the camera's horizontal bias "
                                                  "from the people seen by camera and lasers in a recording "
                                                  "(seed 000).")] = None,
    rho: Annotated[float | None, typer.Option(help="With --adaptive: learning rate of the bias (A10; default "
                                              "0.1).")] = None,
    history: Annotated[Path | None, typer.Option(help="With --adaptive: write the bias history (CSV).")] = None,
    dry_run: Annotated[bool, typer.Option(help="Report only; leave the pipeline file as it is.")] = False,
) -> None:
    """Calibrate a camera: from control points (PnP) or by seed 000's adaptive horizontal bias."""
    import numpy as np

    from .calibration import calibrate_from_points, calibrate_from_recording
    from .calibration.bias import BiasParams
    from .calibration.bias_run import write_bias_history

    if (points is None) == (adaptive is None):
        raise ConfigError("calibrate: give exactly one of --points CSV or --adaptive RECORDING")
    # the options of the other way are refused, not ignored (a user giving them expects them to act)
    given = {"--rho": rho is not None, "--history": history is not None, "--intrinsics": intrinsics is not None,
             "--recording": recording is not None, "--ransac": ransac, "--reference": reference is not None}
    other = ("--rho", "--history") if points is not None else ("--intrinsics", "--recording", "--ransac", "--reference")
    if unused := [o for o in other if given[o]]:
        raise ConfigError(f"{', '.join(unused)}: only with {'--adaptive' if points is not None else '--points'} "
                          f"(this run calibrates {'from --points' if points is not None else 'by --adaptive'})")
    rho = 0.1 if rho is None else rho
    reference = "world" if reference is None else reference
    if not 0.0 < rho <= 1.0:  # (NaN too)
        raise ConfigError(f"--rho: expected a learning rate in (0, 1], got {rho}")
    if history is not None:  # checked before the pipeline file is rewritten: it must not be an input either
        _out_file(history, "bias.csv", reads=[config], option="--history", recordings=[adaptive])
    cfg = _load_config(config)  # every table checked, as by track (a typo in one is an error whatever the run)
    _check_laser_tables(cfg, config, "any")
    if adaptive is not None:
        _check_sensor_topics(cfg, config, [adaptive], {"laser", "camera"})
    if points is not None:
        intr = _parse_intrinsics(intrinsics) if intrinsics is not None else None
        from .errors import CalibrationError

        try:
            report = calibrate_from_points(config, camera, points, reference=reference, intrinsics=intr,
                                           recording=recording, ransac=ransac, write=not dry_run)
        except CalibrationError as err:  # the library's function name means nothing to a user: name the file
            raise CalibrationError(f"--points {points}: {str(err).removeprefix('solve_pnp: ')}") from None
        except ConfigError as err:
            if str(err).startswith("intrinsics: "):
                raise ConfigError(f"{camera}: its intrinsics are needed: give --intrinsics fx,fy,cx,cy[,k1,k2,p1,p2"
                                  "[,k3]] or --recording with its CameraInfo") from None
            raise
        fit = report.pnp
        n_in = int(fit.inliers.sum())
        console.print(f"PnP on {n_in} of {len(fit.residuals_px)} points: reprojection (of those) "
                      f"rms {fit.rms_px:.2f} px, median {fit.median_px:.2f} px, max {fit.max_px:.2f} px")
        for k in np.flatnonzero(~fit.inliers):  # the rejected ones, by their place in the file (1 = first point)
            console.print(f"[yellow]point {k + 1} rejected as an outlier: {np.hypot(*fit.residuals_px[k]):.1f} px "
                          "off its pixel[/yellow]")
    else:
        with console.status("learning the horizontal bias"):
            report = calibrate_from_recording(config, camera, adaptive, params=BiasParams(rho=rho),
                                              write=not dry_run)
        run = report.bias
        updates = int(np.count_nonzero(run.history.n_used))
        console.print(f"horizontal bias {np.degrees(run.bias_rad):+.3f} deg after {updates} updates over "
                      f"{len(run.history)} frames")
        if history is not None:
            history.parent.mkdir(parents=True, exist_ok=True)
            write_bias_history(history, run.history)
            console.print(f"bias history: {history}")
    before, after = report.previous, report.pose
    console.print(f"{camera}: yaw {before.yaw_deg:.3f} -> {after.yaw_deg:.3f} deg, pitch {before.pitch_deg:.3f} -> "
                  f"{after.pitch_deg:.3f} deg, position ({after.x:.3f}, {after.y:.3f}, {after.z:.3f}) m"
                  + (f"; written to {report.written}" if report.written else " (dry run: not written)"))


@app.command(name="calibrate-road")
def calibrate_road_command(
    points: Annotated[Path, typer.Argument(help="Control points CSV with the header sensor,kind,a,b,x,y: kind camera "
                                           "-> a,b = pixel (u, v); kind laser -> a,b = the point in the laser's "
                                           "frame (m); x,y = its surveyed road coordinates (m).")],
    output: Annotated[Path, typer.Option("--output", "-o", help="Calibration file (JSON) for `track --pipeline "
                                         "traffic --calibration`.")],
    lenses: Annotated[Path | None, typer.Option(help="A recording whose CameraInfo gives each camera's lens (K, "
                                                "distortion): its pixels are undistorted before the fit.")] = None,
    refine: Annotated[bool, typer.Option(help="Refine each camera's homography by Levenberg-Marquardt on the "
                                         "pixel error.")] = True,
) -> None:
    """Calibrate the cameras and lasers of a road into one road frame from surveyed control points (seed 003, D1).

    Cameras get a ground-plane homography (at least 4 points, not collinear), lasers a rigid 2-D transform (at
    least 2 points); the residuals at the control points are printed per sensor and saved with the calibration.
    """
    from .calibration.road import calibrate_road, residual_table
    from .io.recording import Recording
    from .types import CameraInfo

    _out_file(output, "road_calibration.json", reads=[points, lenses])
    lens_models: dict[str, CameraInfo] = {}
    if lenses is not None:
        with Recording(lenses) as rec:
            topics = {rec.sensor_of(t): t for t, m in rec.topic_types().items() if m == "sensor_msgs/msg/CameraInfo"}
            if not topics:
                raise ConfigError(f"--lenses {lenses}: the recording has no CameraInfo topic")
            for name, topic in topics.items():
                info = next((m for m in rec.messages([topic]) if isinstance(m, CameraInfo)), None)
                if info is not None:
                    lens_models[name] = info
    calib = calibrate_road(points, lenses=lens_models, refine=refine)
    if lenses is not None:  # which cameras' pixels were undistorted: a name that matches none was ignored unsaid
        cams = sorted(calib.cameras)
        used = [c for c in cams if c in lens_models]
        if used:
            console.print(f"lenses from {lenses}: {', '.join(used)}")
        unmatched = [c for c in cams if c not in lens_models]
        if unmatched:
            log.warning("--lenses %s: no CameraInfo of %s (its cameras: %s); their pixels are used as they are",
                        lenses, ", ".join(unmatched), ", ".join(sorted(lens_models)) or "none readable")
    saved = calib.save(output)
    table = Table(title=f"road calibration from {points} (residuals at the control points)")
    for col in ("sensor", "kind", "points", "rms m", "max m", "rms px", "max px"):
        table.add_column(col, justify="left" if col in ("sensor", "kind") else "right")
    for r in residual_table(calib):
        values = (r["rms_m"], r["max_m"], r["rms_px"], r["max_px"])
        table.add_row(r["sensor"], r["kind"], str(r["n"]), *("-" if v != v else f"{v:.3f}" for v in values))
    console.print(table)
    console.print(f"calibration of {len(calib.cameras)} camera(s) and {len(calib.lasers)} laser(s) -> {saved}")


@app.command(name="train-classifier")
def train_classifier(
    output: Annotated[Path | None, typer.Option("--output", "-o", help="Where to write the model (JSON); default: "
                                                "object_classifier.json in the working directory.")] = None,
    into_package: Annotated[bool, typer.Option("--into-package", help="Instead of --output, replace the model "
                                               "shipped in the package (laser/models/object_classifier.json), the "
                                               "one the tracker uses.")] = False,
    work: Annotated[Path, typer.Option(help="Folder for the simulated training recordings (reused if there).")]
    = Path("out/classifier"),
    data: Annotated[Path, typer.Option(help="The shared data folder (leg_tracker's training bags).")]
    = Path("../shared/data"),
    crowd_seconds: Annotated[float, typer.Option(help="Length of each simulated crowd / groups run.")] = 40.0,
    road_seconds: Annotated[float, typer.Option(help="Length of each simulated road run.")] = 90.0,
    rounds: Annotated[int, typer.Option(help="Boosting rounds (B18: 100).")] = 100,
) -> None:
    """Train the person / bicycle / car classifier of laser segments (B18) from simulated and real data.

    The tracker classifies with the model shipped in the package; no pipeline-file key loads another. A model
    written to --output is for comparing, or for Python: TrackClassifier(ObjectClassifier.load(FILE)).
    --into-package rebuilds the shipped one (in a source checkout: the file in the repository).
    """
    from .laser.classifier import MODEL_FILE, default_model_path, train_default

    if rounds < 1:
        raise ConfigError(f"--rounds: expected >= 1, got {rounds}")
    if into_package and output is not None:
        raise ConfigError(f"--into-package writes {default_model_path()}: give it or --output, not both")
    target = default_model_path() if into_package else _out_file(output or Path(MODEL_FILE), MODEL_FILE)
    _out_folder(work, "--work")
    with console.status("training") as status:
        model, report = train_default(work, crowd_seconds=crowd_seconds, road_seconds=road_seconds, data_dir=data,
                                      n_rounds=rounds, progress=lambda msg: status.update(msg))
    model.save(target)
    table = Table(show_edge=False, header_style="bold", title="held-out test (simulator seed 2; real: last 30 %)")
    for col in ("source / class", "train", "test", "accuracy / recall"):
        table.add_column(col, justify="right" if col != "source / class" else "left")
    for name, r in report["sources"].items():
        table.add_row(name, str(r["train"]), str(r["test"]), f"{r['accuracy']:.3f}")
    for name, r in report["classes"].items():
        table.add_row(f"class {name}", str(r["train"]), str(r["test"]), f"{r['recall']:.3f}")
    console.print(table)
    console.print(f"balanced accuracy {report['balanced_accuracy']:.3f}; wrote {target}")


@app.command()
def pdr(
    source: Annotated[Path, typer.Argument(help="Phone IMU: a CSV (Oxford step-counter, or generic with a header "
                                           "t_s|t_ms|t_ns,ax,ay,az[,gx,gy,gz] in m/s^2 and rad/s) or a recording "
                                           "with an Imu topic.")],
    output: Annotated[Path, typer.Option("--output", "-o", help="Folder for steps.csv and trajectory.csv.")],
    step_model: Annotated[Path | None, typer.Option(help="Step-length model (JSON) from "
                                                    "`fusiontrack fit-step-model`.")] = None,
    sensor: Annotated[str | None, typer.Option(help="Imu topic, when a recording holds several.")] = None,
) -> None:
    """Pedestrian dead reckoning from a phone's IMU (seed 002): steps, step lengths, headings, positions."""
    from .inertial import pdr_from_file, write_pdr

    _out_folder(output)
    for name in ("steps.csv", "trajectory.csv"):  # the files it writes: not its inputs, nor in the recording read
        out = output / name
        for r in (source, step_model):
            if r is not None and out.exists() and r.exists() and out.resolve() == r.resolve():
                raise ConfigError(f"--output {output}: its {name} would overwrite the input {r}; give another folder")
        _out_file(out, name, recordings=[source])
    result = pdr_from_file(source, step_model, sensor=sensor)
    paths = write_pdr(result, output)
    gyro = "" if result.has_gyro else " (no gyroscope: headings held constant)"
    console.print(f"{result.n_steps} steps, {result.distance_m:.1f} m walked{gyro} -> "
                  + ", ".join(str(p) for p in paths.values()))


@app.command(name="fit-step-model")
def fit_step_model(
    walks: Annotated[list[Path], typer.Argument(help="IMU files of walks of known length (CSV or recording).")],
    length: Annotated[list[float], typer.Option("--length", "-l", help="Length walked in each file, metres "
                                                "(once per file, in order).")],
    output: Annotated[Path, typer.Option("--output", "-o", help="Where to write the model (JSON).")],
    subject: Annotated[str, typer.Option(help="Whose step model this is.")] = "default",
) -> None:
    """Learn a person's step length against step duration (C3) from walks of known length."""
    from .inertial import step_model_from_files

    if len(length) != len(walks):
        raise ConfigError(f"--length: expected one per walk ({len(walks)}), got {len(length)}")
    if bad := [v for v in length if not (math.isfinite(v) and v > 0)]:
        raise ConfigError(f"--length: expected distances walked > 0 m, got {', '.join(f'{v:g}' for v in bad)}")
    _out_file(output, "step_model.json", reads=walks)
    model = step_model_from_files(walks, length, subject=subject)
    model.save(output)
    console.print(f"step length = {model.intercept_m:.3f} m + {model.slope_mps:.3f} m/s x duration "
                  f"(from {model.n_train} steps, {model.rms_text}) -> {output}")


# --------------------------------------------------------------------------------------------------
# demo
# --------------------------------------------------------------------------------------------------


@app.command()
def demo(
    output: Annotated[Path, typer.Option("--output", "-o", help="Folder for everything the demo writes.")] = Path(
        "out/demo"),
    recording: Annotated[Path, typer.Option(help="Real ROS 1 laser bag to use.")] = DEFAULT_DEMO_BAG,
    seconds: Annotated[float, typer.Option(help="Length of the simulated crowd.")] = 20.0,
) -> None:
    """Run the most complete job fusiontrack has: simulate, track, evaluate, and a real bag.

    Simulates a crowd (lasers, a camera 3 degrees off its calibration, ground truth), tracks the people
    with the lasers, scores the tracks against the truth and renders a video with both; learns the camera's
    bias, tracks the crowd camera-only and fused through the corrected camera and writes ``report.html``
    (metrics, bias convergence, time cost, videos); converts a real
    laser bag into a time-synchronised MCAP, reads it back and renders its preview; writes
    ``summary.json`` with what was measured.
    """
    import shutil

    from .sim.scenario import load_scenario
    from .sim.simulator import simulate as run_simulation
    from .viz.preview import render_preview

    if not recording.exists():
        raise FusiontrackError(f"demo recording not found: {recording} (the demo reads ../shared/data beside the "
                               "repository; run it from the repository root or pass --recording)")
    _out_folder(output)
    output.mkdir(parents=True, exist_ok=True)
    for old in (output / "crowd", output / "recording"):
        if old.exists():
            if not (old / "metadata.yaml").is_file():  # only ever replace a recording the demo wrote
                raise FusiontrackError(f"{old} exists and is not a recording; the demo will not delete it "
                                       "(choose another --output)")
            shutil.rmtree(old)

    scenario = load_scenario("crowd").with_overrides(seconds=seconds)
    with progress() as bar:
        task = bar.add_task("simulating crowd", total=seconds)
        sim = run_simulation(scenario, output / "crowd", progress=lambda t: bar.update(task, completed=t))
    console.print(f"simulated {seconds:g} s of crowd: {sim.n_agents} people ({sim.mean_present:.1f} present on "
                  f"average), {sum(sim.messages.values())} sensor messages -> {output / 'crowd'}")

    from .eval import evaluate_floor, metrics_table
    from .io.recording import Recording
    from .io.tracks import write_jsonl, write_tracks_csv
    from .tracking.tracker import track_recording
    from .types import GroundTruth

    tic = time.perf_counter()
    states, events = track_recording(output / "crowd")
    laser_s = time.perf_counter() - tic
    write_tracks_csv(output / "crowd_tracks.csv", states)
    write_jsonl(output / "crowd_tracks.jsonl", [*states, *events])
    with Recording(output / "crowd") as rec:
        truth = [g for g in rec.messages(["/ground_truth"]) if isinstance(g, GroundTruth)]
    metrics = evaluate_floor(truth, states, threshold_m=0.5)
    console.print(metrics_table({"crowd (laser PF)": metrics}, title="tracking the simulated crowd, 0.5 m"))
    crowd_video = render_preview([output / "crowd"], output / "crowd.mp4", tracks=states)
    from .demo import people_comparison

    with progress() as bar:
        task = bar.add_task("bias, camera-only and fused tracking", total=None)
        people = people_comparison(output / "crowd", output, true_bias_deg=scenario.config.cameras[0].yaw_bias_deg,
                                   laser_video="crowd.mp4", laser_states=states, laser_time_s=laser_s)
        bar.update(task, completed=1, total=1)
    console.print(f"camera bias learnt: {people['bias_deg']:.3f} deg (true "
                  f"{scenario.config.cameras[0].yaw_bias_deg:g}); " + ", ".join(
                      f"{k} MOTA {m['mota']:.3f} IDF1 {m['idf1']:.3f}" for k, m in people['metrics'].items())
                  + f"; report: {output / 'report.html'}")

    desc = describe_recording([recording])
    _print_description(desc)
    mcap_dir = output / "recording"
    convert([recording], mcap_dir)
    round_trip = describe_recording([mcap_dir])
    real_states, _ = track_recording(mcap_dir)
    real_video = render_preview([mcap_dir], output / "preview.mp4", tracks=real_states)
    summary = {
        "simulated": {"scenario": "crowd", "seconds": seconds, "agents": sim.n_agents,
                      "mean_present": sim.mean_present, "messages": sim.messages,
                      "situations": sim.situation_counts, "preview_frames": crowd_video.frames,
                      "tracks": len({s.track_id for s in states}), "metrics": metrics.to_dict()},
        "people_comparison": people,
        "input": desc, "converted": round_trip,
        "preview": {"path": str(output / "preview.mp4"), "frames": real_video.frames,
                    "size_px": list(real_video.size_px), "tracks": len({s.track_id for s in real_states})},
    }
    from .io.datafile import json_text

    (output / "summary.json").write_text(json_text(summary))
    console.print(f"previews: {output / 'crowd.mp4'} ({crowd_video.frames} frames), {output / 'preview.mp4'} "
                  f"({real_video.frames} frames); summary: {output / 'summary.json'}")


def _open_file_of(err: BaseException) -> Any:
    """The file the failing code had open for writing when ``err`` was raised (its innermost such local), or None:
    a write that fails on a full disk raises an OSError without a file name."""
    import io

    frames = []
    tb = err.__traceback__
    while tb is not None:
        frames.append(tb.tb_frame)
        tb = tb.tb_next
    for frame in reversed(frames):
        for value in frame.f_locals.values():
            if isinstance(value, io.IOBase) and isinstance(getattr(value, "name", None), str) \
                    and set(getattr(value, "mode", "")) & set("wax+"):
                return value
    return None


def os_error_line(err: OSError) -> str:
    """One line for an OSError that reached the command line (writing the outputs: a read-only, full or missing
    folder; the readers name their own files): the path, when the error or the failing code's open file gives it,
    and the OS's reason, e.g. ``cannot write out/x/tracks.csv: [Errno 28] No space left on device``."""
    import errno

    reason = f"[Errno {err.errno}] {err.strerror}" if err.errno is not None and err.strerror else str(err)
    if err.filename is not None:
        path = os.fsdecode(err.filename)
        if err.errno == errno.EEXIST and not Path(path).is_dir():  # mkdir(exist_ok=True) on a file
            reason += " and is not a folder"
        if err.filename2 is not None:
            path += f" -> {os.fsdecode(err.filename2)}"
        return f"{path}: {reason}"
    file = _open_file_of(err)
    return f"cannot write {file.name}: {reason}" if file is not None else reason


_TERMINATED: list[int] = []  # the signals that stopped the run (SIGTERM)


def _terminated(signum: int, frame: Any) -> None:
    """SIGTERM (a job scheduler's stop, ``kill``) stops a run as Ctrl-C does, through the same clean-up: a recording
    being written is removed, a video being written leaves the earlier one (a stopped simulate left a half folder
    that the next run refused as existing). The exit code is the shell's for SIGTERM, 143 (Ctrl-C's: 130), so that a
    scheduler or script sees which stopped the run."""
    _TERMINATED.append(signum)
    raise KeyboardInterrupt  # (typer turns it into exit code 130: main() makes that 128 + SIGTERM)


def main() -> None:
    """Entry point: run the app, turning fusiontrack's errors (and the OS's, writing the outputs) into one clear
    line and exit code 2."""
    import signal

    signal.signal(signal.SIGTERM, _terminated)
    try:
        app()
    except FusiontrackError as err:
        if os.environ.get("FUSIONTRACK_DEBUG"):
            raise
        err_console.print(f"[bold red]error:[/] {escape(str(err))}", highlight=False, soft_wrap=True)
        sys.exit(2)
    except OSError as err:
        if os.environ.get("FUSIONTRACK_DEBUG"):
            raise
        err_console.print(f"[bold red]error:[/] {escape(os_error_line(err))}", highlight=False, soft_wrap=True)
        sys.exit(2)
    except KeyboardInterrupt:
        err_console.print("terminated" if _TERMINATED else "interrupted")
        sys.exit(128 + _TERMINATED[0] if _TERMINATED else 130)
    except SystemExit as err:
        if _TERMINATED and err.code not in (0, None):  # (typer exits 130 for a KeyboardInterrupt)
            err_console.print("terminated")
            sys.exit(128 + _TERMINATED[0])
        raise


if __name__ == "__main__":
    main()
