"""Writing and reading tracker output: world-frame track CSV, MOTChallenge box CSV, JSON lines.

World-frame tracks CSV (:func:`write_tracks_csv`, :func:`read_tracks_csv`)
    Header ``t,id,x,y,vx,vy,class,situation,sensors,score``, one row per :class:`TrackState`, rows
    sorted by ``(t, id)``. ``t`` is in seconds written *exactly* from the integer nanoseconds with
    9 decimals (``1700000000.000000001``; formatted and parsed with integer arithmetic, never through
    a float, so ``t_ns`` round-trips exactly even for Unix-epoch stamps). ``x, y`` (m) and
    ``vx, vy`` (m/s) are world floor-plane coordinates; floats are written with ``repr`` (shortest
    exact form), so they round-trip bit for bit. ``sensors`` is the confirming sensors joined by
    ``|`` (empty while coasting). Covariance, image box and camera are not in this file (use JSON
    lines for full records); reading gives those fields their defaults.

MOTChallenge CSV (:func:`write_mot`, :func:`read_mot`)
    ``frame,id,bb_left,bb_top,bb_width,bb_height,conf,x,y,z`` with 1-based frames, written from
    :attr:`TrackState.box_px` ``(u_min, v_min, u_max, v_max)``. :func:`read_mot` reads any
    MOTChallenge text file with at least six columns: tracker output, ``det.txt`` (id ``-1``) and
    ``gt.txt`` (MOT15: ``...,conf,x,y,z``; MOT16/17: ``...,consider,class,visibility``).

JSON lines (:func:`write_jsonl`, :func:`read_jsonl`)
    One object per line for :class:`TrackState`, :class:`Event` and :class:`GroundTruth` records,
    with a ``"type"`` key and every field by name. Arrays are nested lists; non-finite floats are
    the strings ``"NaN"``, ``"Infinity"``, ``"-Infinity"`` so the file is strict JSON. Free-form
    values (``GroundTruth.attributes``, ``Event.attributes``) keep their type: an array is
    ``{"__ndarray__": [...], "dtype": ..., "shape": [...]}``, a tuple ``{"__tuple__": [...]}``. Reading
    back gives records equal to the written ones (:func:`fusiontrack.types.records_equal`).

Every reader raises :class:`~fusiontrack.errors.RecordingError` naming the file and line of a bad row.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import logging
import math
from collections.abc import Callable, Iterable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from ..errors import ConfigError, RecordingError
from ..types import Event, GroundTruth, ObjectClass, Situation, Track, TrackState
from .csvtable import read_numeric_table

__all__ = [
    "MOT_COLUMNS",
    "TRACKS_CSV_COLUMNS",
    "MotBoxes",
    "format_time_s",
    "group_tracks",
    "parse_time_s",
    "read_ground_truth_csv",
    "read_jsonl",
    "read_mot",
    "read_tracks_csv",
    "write_jsonl",
    "write_mot",
    "write_tracks_csv",
]

logger = logging.getLogger(__name__)

TRACKS_CSV_COLUMNS = ("t", "id", "x", "y", "vx", "vy", "class", "situation", "sensors", "score")
MOT_COLUMNS = ("frame", "id", "bb_left", "bb_top", "bb_width", "bb_height", "conf", "x", "y", "z")

JsonRecord = TrackState | Event | GroundTruth
_CLASSES = tuple(c.value for c in ObjectClass)


def _open_for_writing(path: Path) -> TextIO:
    try:
        return path.open("w", encoding="utf-8", newline="")
    except OSError as err:
        raise RecordingError(f"{path}: cannot be written ({err.strerror or err})") from err


@contextmanager
def _open_for_reading(path: Path, what: str) -> Iterator[TextIO]:
    """``with _open_for_reading(path, what) as f``: the text file, its errors named as RecordingErrors: missing,
    unreadable, or not UTF-8 text (a binary file given for a text one, found while its lines are read)."""
    try:
        f = path.open(encoding="utf-8-sig", newline="")  # (a spreadsheet's byte-order mark is not a column)
    except FileNotFoundError as err:
        raise RecordingError(f"{path}: no such file (expected {what})") from err
    except OSError as err:
        raise RecordingError(f"{path}: cannot be read ({err.strerror or err}; expected {what})") from err
    with f:
        try:
            yield f
        except UnicodeDecodeError as err:
            raise RecordingError(f"{path}: not a UTF-8 text file (expected {what})") from err


def flatten_states(items: Iterable[TrackState | Track]) -> list[TrackState]:
    """Track states from a mix of TrackState and Track records, in the given order."""
    states: list[TrackState] = []
    for item in items:
        if isinstance(item, Track):
            states.extend(item.states)
        elif isinstance(item, TrackState):
            states.append(item)
        else:
            raise ConfigError(f"tracks: expected TrackState or Track records, got {type(item).__name__}")
    return states


def group_tracks(states: Iterable[TrackState]) -> list[Track]:
    """Group track states by ``track_id`` into :class:`Track` records (states sorted by time, ids ascending)."""
    by_id: dict[int, list[TrackState]] = {}
    for s in states:
        by_id.setdefault(s.track_id, []).append(s)
    return [Track(i, tuple(sorted(by_id[i], key=lambda s: s.t_ns))) for i in sorted(by_id)]


# --------------------------------------------------------------------------------------------------
# World-frame tracks CSV
# --------------------------------------------------------------------------------------------------


def format_time_s(t_ns: int) -> str:
    """Integer nanoseconds as exact decimal seconds with 9 decimals (``1500000001`` -> ``"1.500000001"``)."""
    sign = "-" if t_ns < 0 else ""
    sec, frac = divmod(abs(int(t_ns)), 1_000_000_000)
    return f"{sign}{sec}.{frac:09d}"


def parse_time_s(text: str) -> int:
    """Decimal seconds to integer nanoseconds without going through a float (exact up to 9 decimals).

    Raises
    ------
    ValueError
        Not a decimal number, or more than 9 non-zero decimals.
    """
    s = text.strip()
    sign = -1 if s.startswith("-") else 1
    s = s.lstrip("+-")
    whole, _, frac = s.partition(".")
    if not (whole or frac) or not (whole.isdigit() or not whole) or not (frac.isdigit() or not frac):
        raise ValueError(f"not a decimal number of seconds: {text!r}")
    if len(frac) > 9 and frac[9:].strip("0"):
        raise ValueError(f"more than nanosecond precision: {text!r}")
    return sign * (int(whole or "0") * 1_000_000_000 + int((frac[:9] or "0").ljust(9, "0")))


_NS_LIMIT = 2**63  # int64 nanoseconds: up to the year 2262 from 1970


def _time_ns(text: str, column: str) -> int:
    """A CSV time cell as integer nanoseconds: ``t`` in decimal seconds (exact to 9 decimals; a float's noise such
    as ``0.30000000000000004`` rounded to the nearest ns), ``t_ns`` in whole nanoseconds. ValueError naming the
    column for what is not a time, and for a value past int64 nanoseconds (year 2262): in ``t``, most likely
    milliseconds or nanoseconds."""
    text = text.strip()
    if column == "t_ns":
        t_ns = int(text)
    else:
        try:
            t_ns = parse_time_s(text)
        except ValueError:
            try:
                value = float(text)
            except ValueError:
                raise ValueError(f"t: not a number of seconds: {text!r}") from None
            if not math.isfinite(value):
                raise ValueError(f"t: expected finite seconds, got {text!r}") from None
            t_ns = round(value * 1e9) if abs(value) < _NS_LIMIT / 1e9 else _NS_LIMIT
        if abs(t_ns) >= _NS_LIMIT:
            raise ValueError(f"t = {text} s is past the year 2262: milliseconds or nanoseconds? t is in seconds "
                             f"(name a column of nanoseconds t_ns)")
    if abs(t_ns) >= _NS_LIMIT:
        raise ValueError(f"t_ns = {text} is beyond 64-bit nanoseconds (the year 2262)")
    return t_ns


def write_tracks_csv(path: str | Path, tracks: Iterable[TrackState | Track]) -> int:
    """Write track states as the world-frame tracks CSV (see the module docstring).

    Parameters
    ----------
    path : str or Path
    tracks : iterable of TrackState or Track
        States (a Track contributes all its states); written sorted by ``(t_ns, track_id)``.

    Returns
    -------
    int
        Number of rows written.

    Raises
    ------
    ConfigError
        An item is not a TrackState/Track, or a sensor name contains ``|``.
    RecordingError
        The file cannot be written.
    """
    path = Path(path)
    states = sorted(flatten_states(tracks), key=lambda s: (s.t_ns, s.track_id))
    rows = []
    for s in states:
        if any("|" in name for name in s.sensors):
            raise ConfigError(f"TrackState {s.track_id} at {s.t_ns} ns: sensor names must not contain '|', "
                              f"got {s.sensors}")
        x, y = s.position_m.tolist()
        vx, vy = s.velocity_mps.tolist()
        rows.append((format_time_s(s.t_ns), s.track_id, repr(x), repr(y), repr(vx), repr(vy), s.cls,
                     s.situation, "|".join(s.sensors), repr(s.score)))
    with _open_for_writing(path) as f:
        writer = csv.writer(f, lineterminator="\n")
        writer.writerow(TRACKS_CSV_COLUMNS)
        writer.writerows(rows)
    logger.debug("%s: wrote %d track states", path, len(rows))
    return len(rows)


def _data_rows(reader: Any, path: Path, n_fields: int) -> Iterator[tuple[int, list[str]]]:
    """``(line, fields)`` of a CSV reader's rows after the header, blank rows skipped; a row with another number
    of fields than the header is an error naming the line."""
    for row in reader:
        if not row or not "".join(row).strip():
            continue
        if len(row) != n_fields:
            raise RecordingError(f"{path}, line {reader.line_num}: {len(row)} fields, expected {n_fields} like the "
                                 f"header")
        yield reader.line_num, row


def read_tracks_csv(path: str | Path, sensor: str = "tracker") -> list[TrackState]:
    """Read a world-frame tracks CSV back into :class:`TrackState` records, in file order.

    A ``tracks.csv`` of ``fusiontrack track`` (:data:`TRACKS_CSV_COLUMNS`), or another tracker's output with at
    least ``t`` (s) or ``t_ns`` (which wins when both are there, as for ground truth), ``id``, ``x``, ``y`` (m): the
    other columns are optional (``vx``, ``vy`` 0;
    ``class`` person; ``situation`` noncorrelated; ``sensors`` none; ``score`` 1), names in any case, others ignored.

    Parameters
    ----------
    path : str or Path
    sensor : str
        The ``sensor`` of every state (the file does not store it).

    Raises
    ------
    RecordingError
        Missing file, missing columns, or a bad row (file and line named).
    """
    path = Path(path)
    what = "a tracks CSV with header " + ",".join(TRACKS_CSV_COLUMNS) + " (at least t or t_ns, id, x, y)"
    states: list[TrackState] = []
    with _open_for_reading(path, what) as f:
        reader = csv.reader(f)
        header = next(reader, None)
        if header is None:
            raise RecordingError(f"{path}: empty file (expected {what})")
        names = [h.strip().lower() for h in header]
        time_col = "t_ns" if "t_ns" in names else "t"  # (both: t_ns, exact; as read_ground_truth_csv does)
        missing = [c for c in (time_col, "id", "x", "y") if c not in names]
        if missing:
            raise RecordingError(f"{path}, line 1: header lacks {missing} (expected {what})")
        col = {c: names.index(c) for c in (time_col, *TRACKS_CSV_COLUMNS[1:]) if c in names}

        def get(row: list[str], name: str, default: str) -> str:
            k = col.get(name)
            return row[k].strip() if k is not None else default

        for lineno, row in _data_rows(reader, path, len(names)):
            try:
                sensors = get(row, "sensors", "")
                states.append(TrackState(
                    t_ns=_time_ns(row[col[time_col]], time_col),
                    sensor=sensor,
                    track_id=int(row[col["id"]]),
                    position_m=(float(row[col["x"]]), float(row[col["y"]])),
                    velocity_mps=(float(get(row, "vx", "0")), float(get(row, "vy", "0"))),
                    cls=get(row, "class", ObjectClass.PERSON),
                    situation=get(row, "situation", Situation.NONCORRELATED),
                    sensors=tuple(sensors.split("|")) if sensors else (),
                    score=float(get(row, "score", "1")),
                ))
            except (ValueError, TypeError) as err:
                raise RecordingError(f"{path}, line {lineno}: {err}") from err
    return states


def _whole_number(text: str) -> int | None:
    """``"7"`` or ``"7.0"`` -> 7; None for anything else."""
    try:
        v = float(text)
    except ValueError:
        return None
    return int(v) if math.isfinite(v) and v == int(v) else None


def read_ground_truth_csv(path: str | Path, sensor: str = "ground_truth") -> list[GroundTruth]:
    """Floor-plane ground truth from a CSV file: one row per person and time, grouped into frames.

    The header names the columns (in any case); these are read, any others ignored: ``t`` (seconds) or ``t_ns``
    (integer nanoseconds), on the tracks' clock (a ``tracks.csv``'s ``t``: e.g. seconds since 1970 for a
    recording's header stamps), ``id`` (a whole number >= 0), ``x`` and ``y`` (metres, in the tracks' world
    frame), and optionally ``class`` (person, bicycle, car, group or unknown; empty: person). So a ``tracks.csv``
    of ``fusiontrack track``, the simulator's ``ground_truth/agents.csv`` (read by its ``t_ns``: its ``t`` counts
    from the start of the simulation) and a hand-made ``t,id,x,y`` file all read. Times need not be sorted.

    Raises
    ------
    RecordingError
        Missing file or columns, a bad value, or an id twice at one time (file and line named).
    """
    path = Path(path)
    what = "a ground-truth CSV with a header holding t (s) or t_ns, id, x, y (m) and optionally class"
    rows: dict[int, list[tuple[int, float, float, str, int]]] = {}
    with _open_for_reading(path, what) as f:
        reader = csv.reader(f)
        header = next(reader, None)
        if header is None:
            raise RecordingError(f"{path}: empty file (expected {what})")
        names = [h.strip().lower() for h in header]
        time_col = "t_ns" if "t_ns" in names else "t"
        missing = [c for c in (time_col, "id", "x", "y") if c not in names]
        if missing:
            raise RecordingError(f"{path}, line 1: header {','.join(names)} lacks {', '.join(missing)} "
                                 f"(expected {what})")
        col = {c: names.index(c) for c in (time_col, "id", "x", "y", "class") if c in names}
        for lineno, row in _data_rows(reader, path, len(names)):
            try:
                t_ns = _time_ns(row[col[time_col]], time_col)
                tid_text = row[col["id"]].strip()
                tid = _whole_number(tid_text)
                if tid is None or tid < 0:
                    raise ValueError(f"id: expected a whole number >= 0, got {tid_text!r}")
                x, y = float(row[col["x"]]), float(row[col["y"]])
                if not (math.isfinite(x) and math.isfinite(y)):
                    raise ValueError(f"x, y: expected finite metres, got {x}, {y}")
                cls = (row[col["class"]].strip() if "class" in col else "") or "person"
                if cls not in _CLASSES:
                    raise ValueError(f"class: expected one of {', '.join(_CLASSES)}, got {cls!r}")
            except (ValueError, TypeError, OverflowError) as err:
                raise RecordingError(f"{path}, line {lineno}: {err}") from err
            rows.setdefault(t_ns, []).append((int(tid), x, y, cls, lineno))
    frames = []
    for t_ns in sorted(rows):
        people = rows[t_ns]
        ids = [r[0] for r in people]
        if len(set(ids)) != len(ids):
            twice = next(r for k, r in enumerate(people) if r[0] in ids[:k])
            raise RecordingError(f"{path}, line {twice[4]}: id {twice[0]} twice at t = {format_time_s(t_ns)} s")
        frames.append(GroundTruth(t_ns, sensor, "world", np.array(ids, np.int64),
                                  np.array([[r[1], r[2]] for r in people], np.float64),
                                  classes=tuple(r[3] for r in people)))
    if not frames:
        raise RecordingError(f"{path}: no rows (expected {what})")
    return frames


# --------------------------------------------------------------------------------------------------
# MOTChallenge CSV
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class MotBoxes:
    """Boxes of a MOTChallenge file, one row per box, as arrays.

    Attributes
    ----------
    frame : (n,) int64
        1-based frame number.
    id : (n,) int64
        Track or ground-truth id; ``-1`` for detections.
    boxes_ltwh : (n, 4) float64
        ``(bb_left, bb_top, bb_width, bb_height)`` in pixels.
    conf : (n,) float64
        Column 7: detection score, or the "consider" flag in MOT16/17 gt (1 when the file has 6 columns).
    extra : (n, k) float64
        Columns 8 onwards as written: ``x, y, z`` (MOT15), ``class, visibility`` (MOT16/17 gt).
    """

    frame: np.ndarray
    id: np.ndarray
    boxes_ltwh: np.ndarray
    conf: np.ndarray
    extra: np.ndarray

    def __len__(self) -> int:
        return int(self.frame.size)

    @property
    def boxes_xyxy(self) -> np.ndarray:
        """Boxes as ``(u_min, v_min, u_max, v_max)``, ``(n, 4) float64`` pixels (fusiontrack's convention)."""
        b = self.boxes_ltwh
        return np.concatenate([b[:, :2], b[:, :2] + b[:, 2:]], axis=1)

    def scaled(self, factor: float) -> MotBoxes:
        """The same boxes in an image resized by ``factor`` (e.g. 0.625 for PETS 768x576 -> 480x360)."""
        return dataclasses.replace(self, boxes_ltwh=self.boxes_ltwh * factor)

    def select(self, rows: np.ndarray) -> MotBoxes:
        """The boxes of ``rows`` (a boolean mask or indices), every column kept with them."""
        return dataclasses.replace(self, frame=self.frame[rows], id=self.id[rows], boxes_ltwh=self.boxes_ltwh[rows],
                                   conf=self.conf[rows], extra=self.extra[rows])

    def rows_at(self, frame: int) -> np.ndarray:
        """Indices of the rows of one frame, ``(k,) int64``."""
        return np.flatnonzero(self.frame == frame)


def read_mot(path: str | Path, *, allow_empty: bool = False) -> MotBoxes:
    """Read a MOTChallenge text file (tracker output, ``det.txt`` or ``gt.txt``; see :class:`MotBoxes`).

    ``allow_empty``: an empty file (nothing but blank lines) is no boxes, e.g. a tracker's output on a sequence
    where it found nobody; else it is an error.

    Raises
    ------
    RecordingError
        Missing file, no rows (unless ``allow_empty``), fewer than 6 columns, a row of another length or with a
        non-number, or a frame/id that is not a whole number (file and line named).
    """
    path = Path(path)
    if allow_empty and path.is_file() and path.stat().st_size < 1 << 16 and \
            not path.read_bytes().decode("utf-8", "replace").strip():
        return MotBoxes(frame=np.zeros(0, np.int64), id=np.zeros(0, np.int64), boxes_ltwh=np.zeros((0, 4)),
                        conf=np.zeros(0), extra=np.zeros((0, 0)))
    what = "MOTChallenge rows frame,id,bb_left,bb_top,bb_width,bb_height[,conf,...]"
    table = read_numeric_table(path, what=what)
    v = table.values
    if v.shape[1] < 6:
        raise RecordingError(f"{path}, line {int(table.line_numbers[0])}: {v.shape[1]} columns, "
                             f"expected at least 6 ({what})")
    for c, name in ((0, "frame"), (1, "id")):
        bad = np.flatnonzero(v[:, c] != np.round(v[:, c]))
        if bad.size:
            i = int(bad[0])
            raise RecordingError(f"{path}, line {int(table.line_numbers[i])}: {name} {float(v[i, c])!r} is not "
                                 "a whole number")
    low = np.flatnonzero(v[:, 0] < 1)
    if low.size:  # read as 1-based, a 0-based file would put every box one image early
        i = int(low[0])
        raise RecordingError(f"{path}, line {int(table.line_numbers[i])}: frame {int(v[i, 0])}: MOTChallenge frames "
                             f"are numbered from 1 (a file numbered from 0: add 1 to every frame)")
    bad = np.flatnonzero(~np.isfinite(v[:, 2:6]).all(axis=1) | (v[:, 4] < 0) | (v[:, 5] < 0))
    if bad.size:  # (a negative size was scored as a box of its own)
        i = int(bad[0])
        raise RecordingError(f"{path}, line {int(table.line_numbers[i])}: box {v[i, 2:6].tolist()}: expected a finite "
                             f"bb_left, bb_top and a width and height >= 0")
    n = v.shape[0]
    conf = v[:, 6].copy() if v.shape[1] > 6 else np.ones(n)
    boxes = MotBoxes(frame=v[:, 0].astype(np.int64), id=v[:, 1].astype(np.int64), boxes_ltwh=v[:, 2:6].copy(),
                     conf=conf, extra=v[:, 7:].copy())
    logger.debug("%s: %d MOT boxes in frames %d..%d", path, n, boxes.frame.min(), boxes.frame.max())
    return boxes


def write_mot(
    path: str | Path,
    tracks: Iterable[TrackState | Track],
    *,
    frame_of: Mapping[int, int] | Callable[[int], int] | None = None,
    fps: float | None = None,
    start_ns: int = 0,
    world_xy: bool = False,
) -> int:
    """Write the image boxes of track states as a MOTChallenge CSV (``frame,id,l,t,w,h,conf,x,y,z``).

    States without ``box_px`` are skipped. Rows are sorted by ``(frame, id)``.

    Parameters
    ----------
    path : str or Path
    tracks : iterable of TrackState or Track
    frame_of : mapping or callable t_ns -> frame, optional
        The 1-based frame number of each state time (e.g. from the video's frame times).
    fps, start_ns : float, int
        Used when ``frame_of`` is not given: ``frame = round((t_ns - start_ns) * fps / 1e9) + 1``.
    world_xy : bool
        Write the world position as ``x, y`` (and ``z = 0``) instead of ``-1, -1, -1``.

    Returns
    -------
    int
        Number of rows written. ``conf`` is the state's ``score``.

    Raises
    ------
    ConfigError
        Neither ``frame_of`` nor a positive ``fps``, or a state time missing from ``frame_of``.
    RecordingError
        The file cannot be written.
    """
    path = Path(path)
    if frame_of is None and (fps is None or not fps > 0):
        raise ConfigError(f"write_mot: give frame_of or a positive fps (got fps={fps!r})")
    all_states = flatten_states(tracks)
    states = [s for s in all_states if s.box_px is not None]
    t_ns = np.array([s.t_ns for s in states], dtype=np.int64)
    if frame_of is None:
        frames = np.rint((t_ns - int(start_ns)) * (float(fps or 0.0) / 1e9)).astype(np.int64) + 1
    else:
        lookup = frame_of.__getitem__ if isinstance(frame_of, Mapping) else frame_of
        try:
            frames = np.array([int(lookup(int(t))) for t in t_ns], dtype=np.int64)
        except (KeyError, IndexError) as err:
            raise ConfigError(f"frame_of: no frame for state time {err.args[0] if err.args else '?'} ns") from err
    ids = np.array([s.track_id for s in states], dtype=np.int64)
    boxes = np.array([s.box_px for s in states], dtype=np.float64).reshape(-1, 4)
    ltwh = np.concatenate([boxes[:, :2], boxes[:, 2:] - boxes[:, :2]], axis=1)
    conf = np.array([s.score for s in states], dtype=np.float64)
    if world_xy:
        xyz = np.array([[*s.position_m.tolist(), 0.0] for s in states], dtype=np.float64).reshape(-1, 3)
    else:
        xyz = np.full((len(states), 3), -1.0)
    order = np.lexsort((ids, frames))
    with _open_for_writing(path) as f:
        for i in order:
            f.write(",".join([str(frames[i]), str(ids[i]), *map(repr, ltwh[i].tolist()), repr(float(conf[i])),
                              *map(_mot_number, xyz[i].tolist())]) + "\n")
    logger.debug("%s: wrote %d MOT rows (%d states without box skipped)", path, len(states),
                 len(all_states) - len(states))
    return len(states)


def _mot_number(v: float) -> str:
    return "-1" if v == -1.0 else repr(v)


# --------------------------------------------------------------------------------------------------
# JSON lines
# --------------------------------------------------------------------------------------------------

_NONFINITE = {"NaN": math.nan, "Infinity": math.inf, "-Infinity": -math.inf}


def _float_json(x: float) -> float | str:
    if math.isfinite(x):
        return x
    return "NaN" if math.isnan(x) else ("Infinity" if x > 0 else "-Infinity")


def _array_json(arr: np.ndarray) -> Any:
    """An array as nested lists, non-finite floats as strings."""
    if arr.dtype.kind == "f" and not np.isfinite(arr).all():
        obj = arr.astype(object)
        obj[np.isnan(arr)] = "NaN"
        obj[np.isposinf(arr)] = "Infinity"
        obj[np.isneginf(arr)] = "-Infinity"
        return obj.tolist()
    return arr.tolist()


def _array_from_json(value: Any, dtype: Any, shape: tuple[int, ...] | None = None) -> np.ndarray:
    arr = np.array(value, dtype=dtype)
    return arr.reshape(shape) if shape is not None else arr


def _tagged(value: Any) -> Any:
    """A free-form value as JSON that keeps arrays (with dtype and shape), tuples and non-finite floats."""
    if isinstance(value, np.ndarray):
        if value.dtype.kind not in "biufUS":
            raise ConfigError(f"cannot write an array of dtype {value.dtype} to JSON")
        return {"__ndarray__": _array_json(value), "dtype": value.dtype.str, "shape": list(value.shape)}
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float):
        return value if math.isfinite(value) else {"__float__": _float_json(value)}
    if value is None or isinstance(value, bool | int | str):
        return value
    if isinstance(value, tuple):
        return {"__tuple__": [_tagged(v) for v in value]}
    if isinstance(value, list):
        return [_tagged(v) for v in value]
    if isinstance(value, Mapping):
        if not all(isinstance(k, str) for k in value):
            raise ConfigError(f"cannot write a mapping with non-string keys to JSON: {list(value)[:5]}")
        return {k: _tagged(v) for k, v in value.items()}
    raise ConfigError(f"cannot write a value of type {type(value).__name__} to JSON")


def _untagged(value: Any) -> Any:
    if isinstance(value, list):
        return [_untagged(v) for v in value]
    if isinstance(value, dict):
        if "__ndarray__" in value:
            arr = np.array(value["__ndarray__"], dtype=object if value["dtype"][1] in "fc" else None)
            return arr.astype(np.dtype(value["dtype"])).reshape(value["shape"])
        if "__tuple__" in value:
            return tuple(_untagged(v) for v in value["__tuple__"])
        if "__float__" in value:
            return _NONFINITE[value["__float__"]]
        return {k: _untagged(v) for k, v in value.items()}
    return value


def _opt(arr: np.ndarray | None) -> Any:
    return None if arr is None else _array_json(arr)


def _record_json(rec: JsonRecord) -> dict[str, Any]:
    if isinstance(rec, TrackState):
        return {"type": "TrackState", "t_ns": rec.t_ns, "sensor": rec.sensor, "track_id": rec.track_id,
                "position_m": _array_json(rec.position_m), "velocity_mps": _array_json(rec.velocity_mps),
                "covariance": _opt(rec.covariance), "cls": rec.cls, "situation": rec.situation,
                "sensors": list(rec.sensors), "score": _float_json(rec.score), "box_px": _opt(rec.box_px),
                "camera": rec.camera}
    if isinstance(rec, Event):
        return {"type": "Event", "t_ns": rec.t_ns, "sensor": rec.sensor, "kind": rec.kind,
                "t_end_ns": rec.t_end_ns, "position_m": _opt(rec.position_m), "track_ids": list(rec.track_ids),
                "attributes": _tagged(dict(rec.attributes))}
    if isinstance(rec, GroundTruth):
        return {"type": "GroundTruth", "t_ns": rec.t_ns, "sensor": rec.sensor, "frame_id": rec.frame_id,
                "ids": _array_json(rec.ids), "positions_m": _array_json(rec.positions_m),
                "velocities_mps": _array_json(rec.velocities_mps), "classes": list(rec.classes),
                "attributes": _tagged(dict(rec.attributes))}
    raise ConfigError(f"records: expected TrackState, Event or GroundTruth, got {type(rec).__name__}")


def _float(value: Any) -> float:
    return _NONFINITE[value] if isinstance(value, str) else float(value)


def _record_from_json(obj: dict[str, Any]) -> JsonRecord:
    kind = obj.get("type")
    f64 = np.float64
    if kind == "TrackState":
        cov = obj.get("covariance")
        box = obj.get("box_px")
        return TrackState(
            t_ns=obj["t_ns"], sensor=obj["sensor"], track_id=obj["track_id"],
            position_m=_array_from_json(obj["position_m"], f64),
            velocity_mps=_array_from_json(obj["velocity_mps"], f64),
            covariance=None if cov is None else _array_from_json(cov, f64),
            cls=obj["cls"], situation=obj["situation"], sensors=tuple(obj["sensors"]),
            score=_float(obj["score"]), box_px=None if box is None else _array_from_json(box, f64),
            camera=obj.get("camera", ""),
        )
    if kind == "Event":
        pos = obj.get("position_m")
        return Event(t_ns=obj["t_ns"], sensor=obj["sensor"], kind=obj["kind"], t_end_ns=obj.get("t_end_ns"),
                     position_m=None if pos is None else _array_from_json(pos, f64),
                     track_ids=tuple(obj.get("track_ids", ())), attributes=_untagged(obj.get("attributes", {})))
    if kind == "GroundTruth":
        n = len(obj["ids"])
        return GroundTruth(
            t_ns=obj["t_ns"], sensor=obj["sensor"], frame_id=obj["frame_id"],
            ids=_array_from_json(obj["ids"], np.int64),
            positions_m=_array_from_json(obj["positions_m"], f64, (n, 2)),
            velocities_mps=_array_from_json(obj["velocities_mps"], f64, (n, 2)),
            classes=tuple(obj.get("classes", ())), attributes=_untagged(obj.get("attributes", {})),
        )
    raise ValueError(f"unknown record type {kind!r} (expected TrackState, Event or GroundTruth)")


def _checked_times(obj: dict[str, Any]) -> None:
    """ValueError for a ``t_ns`` / ``t_end_ns`` beyond int64 nanoseconds (numpy's time arrays overflowed on it)."""
    for key in ("t_ns", "t_end_ns"):
        v = obj.get(key)
        if v is None or isinstance(v, bool) or not isinstance(v, int | float):
            continue  # (missing, or not a number: the record says so)
        if abs(v) >= _NS_LIMIT:
            raise ValueError(f"{key} = {v} is beyond 64-bit nanoseconds (the year 2262)")


def write_jsonl(path: str | Path, records: Iterable[JsonRecord]) -> int:
    """Write TrackState, Event and GroundTruth records as JSON lines, one object per record, in order.

    Returns
    -------
    int
        Number of records written.

    Raises
    ------
    ConfigError
        A record of another type, or a free-form attribute JSON cannot hold.
    RecordingError
        The file cannot be written.
    """
    path = Path(path)
    lines = [json.dumps(_record_json(r), allow_nan=False, separators=(",", ":")) for r in records]
    with _open_for_writing(path) as f:
        f.writelines(line + "\n" for line in lines)
    logger.debug("%s: wrote %d records", path, len(lines))
    return len(lines)


def read_jsonl(path: str | Path) -> list[JsonRecord]:
    """Read the records of a JSON-lines file written by :func:`write_jsonl` (blank lines skipped).

    Raises
    ------
    RecordingError
        Missing file, a line that is not JSON, or an object that is not a valid record (file and line named).
    """
    path = Path(path)
    records: list[JsonRecord] = []
    with _open_for_reading(path, "JSON lines of TrackState/Event/GroundTruth records") as f:
        for lineno, line in enumerate(f, start=1):
            if not line.strip():
                continue
            try:
                obj = json.loads(line, parse_constant=lambda c: _NONFINITE[c])
                if not isinstance(obj, dict):
                    raise ValueError(f"expected a JSON object, got {type(obj).__name__}")
                _checked_times(obj)
                records.append(_record_from_json(obj))
            except json.JSONDecodeError as err:
                whole = ""
                if lineno == 1 and line.strip() in ("{", "["):  # a JSON document spread over lines, not JSON lines
                    whole = ("; the file looks like one JSON document, not JSON lines (one record per line), e.g. a "
                             "summary.json: give the run's tracks.jsonl")
                raise RecordingError(f"{path}, line {lineno}: not JSON ({err.msg} at column {err.colno}){whole}"
                                     ) from err
            except KeyError as err:
                raise RecordingError(f"{path}, line {lineno}: missing key {err.args[0]!r}") from err
            except (ValueError, TypeError) as err:
                raise RecordingError(f"{path}, line {lineno}: {err}") from err
    return records
