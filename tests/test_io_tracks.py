"""Track output files: write/read round trips, and the MOT reader on real MOTChallenge files."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from fusiontrack.errors import ConfigError, RecordingError
from fusiontrack.io.tracks import (
    TRACKS_CSV_COLUMNS,
    format_time_s,
    group_tracks,
    parse_time_s,
    read_ground_truth_csv,
    read_jsonl,
    read_mot,
    read_tracks_csv,
    write_jsonl,
    write_mot,
    write_tracks_csv,
)
from fusiontrack.types import Event, GroundTruth, Track, TrackState, records_equal

SHARED_DATA = (Path(__file__).resolve().parents[1] / ".." / "shared" / "data").resolve()  # as conftest.py
PETS_DET = SHARED_DATA / "video/pets09_s2l1/PETS09-S2L1_det_MOT15.txt"
TUD = SHARED_DATA / "mot_reference/motmetrics_tud"
T0 = 1_700_000_000_000_000_001  # a Unix-epoch stamp with an odd last nanosecond


def _states(rng: np.random.Generator, n_steps: int = 5, n_ids: int = 3) -> list[TrackState]:
    """Time-ordered states of a few tracks with awkward values (full-precision floats, NaN, no sensors)."""
    out = []
    for k in range(n_steps):
        for i in range(n_ids):
            out.append(TrackState(
                t_ns=T0 + k * 33_333_333, sensor="tracker", track_id=i + 1,
                position_m=rng.normal(size=2) * 10, velocity_mps=rng.normal(size=2),
                cls=["person", "bicycle", "car"][i], situation=["noncorrelated", "merged", "appearing"][k % 3],
                sensors=(("laser_front", "cam_0") if k % 2 else ()), score=float(rng.random()),
                box_px=np.array([10.5, 20.0, 60.25, 180.0]) + k + 100 * i,
            ))
    return out


def _csv_fields(s: TrackState) -> TrackState:
    """The state as the tracks CSV keeps it (no covariance, box or camera)."""
    return TrackState(s.t_ns, s.sensor, s.track_id, s.position_m, s.velocity_mps, cls=s.cls,
                      situation=s.situation, sensors=s.sensors, score=s.score)


# -- world-frame tracks CSV ----------------------------------------------------------------------------


@pytest.mark.parametrize("t_ns", [0, 1, 999_999_999, 1_000_000_000, T0, -1, -1_500_000_000])
def test_time_text_is_exact(t_ns: int) -> None:
    text = format_time_s(t_ns)
    assert len(text.split(".")[1]) == 9
    assert parse_time_s(text) == t_ns


def test_parse_time_s_forms() -> None:
    assert parse_time_s("1.5") == 1_500_000_000
    assert parse_time_s("2") == 2_000_000_000
    assert parse_time_s(".25") == 250_000_000
    assert parse_time_s("1.0000000010") == 1_000_000_001
    for bad in ("", "1.2.3", "1e9", "abc", "1.0000000001"):
        with pytest.raises(ValueError, match=r"decimal|precision"):
            parse_time_s(bad)


def test_tracks_csv_round_trip(tmp_path: Path) -> None:
    states = _states(np.random.default_rng(1))
    states[4] = _csv_fields(TrackState(T0 + 1, "tracker", 9, [np.nan, 1.0], [np.inf, -0.0], score=0.0))
    states.sort(key=lambda s: (s.t_ns, s.track_id))
    path = tmp_path / "tracks.csv"
    assert write_tracks_csv(path, states) == len(states)
    assert path.read_text().splitlines()[0] == ",".join(TRACKS_CSV_COLUMNS)
    back = read_tracks_csv(path, sensor="tracker")
    assert len(back) == len(states)
    assert all(records_equal(a, _csv_fields(b)) for a, b in zip(back, states, strict=True))
    assert back[0].box_px is None
    assert back[0].covariance is None


def test_tracks_csv_from_tracks_is_time_ordered(tmp_path: Path) -> None:
    states = _states(np.random.default_rng(2))
    tracks = group_tracks(states)
    assert [t.track_id for t in tracks] == [1, 2, 3]
    assert all(isinstance(t, Track) and len(t.states) == 5 for t in tracks)
    path = tmp_path / "tracks.csv"
    write_tracks_csv(path, tracks)
    back = read_tracks_csv(path)
    assert [(s.t_ns, s.track_id) for s in back] == [(s.t_ns, s.track_id) for s in states]
    regrouped = group_tracks(back)
    for a, b in zip(regrouped, tracks, strict=True):
        assert all(records_equal(x, _csv_fields(y)) for x, y in zip(a.states, b.states, strict=True))


def test_another_trackers_minimal_csv_reads(tmp_path: Path) -> None:
    # t (or t_ns), id, x, y is enough (names in any case, extra columns ignored): the rest takes TrackState's defaults
    p = tmp_path / "theirs.csv"
    p.write_text("T,ID,X,Y,confidence\n1.5,7,2.0,-1.0,0.9\n1.6,7,2.1,-1.0,0.8\n")
    a, _ = read_tracks_csv(p)
    assert (a.t_ns, a.track_id, tuple(a.position_m)) == (1_500_000_000, 7, (2.0, -1.0))
    assert (a.cls, a.situation, a.sensors, a.score, tuple(a.velocity_mps)) == ("person", "noncorrelated", (), 1.0,
                                                                                (0.0, 0.0))
    p.write_text("t_ns,id,x,y\n1700000000123456789,3,0,0\n")
    assert read_tracks_csv(p)[0].t_ns == 1_700_000_000_123_456_789  # exact, beyond float64's integers


@pytest.mark.parametrize("reader", ["tracks", "truth"])
def test_times_in_the_wrong_unit_or_beyond_int64_are_named_not_a_traceback(tmp_path: Path, reader: str) -> None:
    # epoch nanoseconds or milliseconds under a ``t`` (seconds) header overflowed numpy's int64 time arrays in eval
    read = read_tracks_csv if reader == "tracks" else read_ground_truth_csv
    p = tmp_path / "times.csv"
    for value in ("1700000000365854208", "1700000000365"):
        p.write_text(f"t,id,x,y\n1.0,1,0,0\n{value},1,0,0\n")
        with pytest.raises(RecordingError, match=rf"times\.csv, line 3: t = {value} s is past the year 2262: "
                                                 r"milliseconds or nanoseconds\?"):
            read(p)
    p.write_text("t_ns,id,x,y\n99999999999999999999,1,0,0\n")
    with pytest.raises(RecordingError, match=r"line 2: t_ns = 99999999999999999999 is beyond 64-bit nanoseconds"):
        read(p)
    # a float's noise (Python's repr, pandas) is read to the nearest nanosecond, by both readers alike
    p.write_text("t,id,x,y\n0.1,1,0,0\n0.30000000000000004,1,0.1,0\n1e-1,2,5,5\n")
    times = [s.t_ns for s in read(p)] if reader == "tracks" else [f.t_ns for f in read(p) for _ in f.ids]
    assert sorted(times) == [100_000_000, 100_000_000, 300_000_000]


def test_jsonl_time_beyond_int64_is_named(tmp_path: Path) -> None:
    p = tmp_path / "t.jsonl"
    write_jsonl(p, [TrackState(1_000, "laser", 1, np.zeros(2))])
    p.write_text(p.read_text().replace('"t_ns":1000', '"t_ns":99999999999999999999'))
    with pytest.raises(RecordingError, match=r"t\.jsonl, line 1: t_ns = 99999999999999999999 is beyond 64-bit"):
        read_jsonl(p)


def test_tracks_csv_errors(tmp_path: Path) -> None:
    p = tmp_path / "tracks.csv"
    with pytest.raises(RecordingError, match="no such file"):
        read_tracks_csv(p)
    p.write_text("t,id,x\n1.0,1,0\n")
    with pytest.raises(RecordingError, match=r"tracks\.csv, line 1: header lacks \['y'\]"):
        read_tracks_csv(p)
    header = ",".join(TRACKS_CSV_COLUMNS) + "\n"
    good = "1.000000000,1,0.5,0.5,0,0,person,noncorrelated,laser|cam,1.0\n"
    p.write_text(header + good + "1.1,2,0.5,zero,0,0,person,noncorrelated,,1.0\n")
    with pytest.raises(RecordingError, match=r"tracks\.csv, line 3: could not convert"):
        read_tracks_csv(p)
    p.write_text(header + good + good.replace("person", "dragon"))
    with pytest.raises(RecordingError, match=r"line 3: 'dragon' is not a valid ObjectClass"):
        read_tracks_csv(p)
    p.write_text(header + "\n" + good + "1.2,2,0.5\n")
    with pytest.raises(RecordingError, match=r"line 4: 3 fields, expected 10"):
        read_tracks_csv(p)
    bad_sensor = TrackState(0, "tracker", 1, [0, 0], sensors=("a|b",))
    with pytest.raises(ConfigError, match="must not contain"):
        write_tracks_csv(tmp_path / "x.csv", [bad_sensor])


# -- MOTChallenge --------------------------------------------------------------------------------------


def test_mot_round_trip_with_fps(tmp_path: Path) -> None:
    states = _states(np.random.default_rng(3))
    states.append(TrackState(T0, "tracker", 99, [0, 0]))  # no box: skipped
    path = tmp_path / "mot.txt"
    assert write_mot(path, states, fps=30.0, start_ns=T0) == 15
    mot = read_mot(path)
    assert len(mot) == 15
    np.testing.assert_array_equal(mot.frame, np.repeat([1, 2, 3, 4, 5], 3))  # 33.333333 ms apart at 30 fps
    np.testing.assert_array_equal(mot.id, np.tile([1, 2, 3], 5))
    with_box = [s for s in states if s.box_px is not None]
    np.testing.assert_array_equal(mot.boxes_xyxy, [s.box_px for s in with_box])  # exact
    np.testing.assert_array_equal(mot.conf, [s.score for s in with_box])
    np.testing.assert_array_equal(mot.extra, -np.ones((15, 3)))
    assert path.read_text().splitlines()[0].startswith("1,1,10.5,20.0,49.75,160.0,")


def test_mot_frame_mapping_and_world_xy(tmp_path: Path) -> None:
    states = _states(np.random.default_rng(4), n_steps=2)
    frame_of = {T0: 7, T0 + 33_333_333: 8}
    path = tmp_path / "mot.txt"
    write_mot(path, reversed(states), frame_of=frame_of, world_xy=True)
    mot = read_mot(path)
    np.testing.assert_array_equal(mot.frame, [7, 7, 7, 8, 8, 8])  # sorted by frame, id
    np.testing.assert_array_equal(mot.extra[:, :2], [s.position_m for s in states])
    np.testing.assert_array_equal(mot.extra[:, 2], 0.0)
    with pytest.raises(ConfigError, match="no frame for state time"):
        write_mot(path, states, frame_of={T0: 1})
    with pytest.raises(ConfigError, match="frame_of or a positive fps"):
        write_mot(path, states)


def test_mot_frames_numbered_from_0_are_refused(tmp_path: Path) -> None:
    # read as 1-based, every box of a 0-based file would land one image early
    path = tmp_path / "det.txt"
    path.write_text("1,-1,10,20,30,40,0.9\n0,-1,10,20,30,40,0.8\n")
    with pytest.raises(RecordingError, match=r"det\.txt, line 2: frame 0: MOTChallenge frames are numbered from 1"):
        read_mot(path)


@pytest.mark.parametrize("row", ["2,1,10,20,-30,40", "2,1,10,20,30,-1", "2,1,nan,20,30,40", "2,1,10,inf,30,40"])
def test_mot_boxes_of_negative_size_or_not_finite_are_refused(tmp_path: Path, row: str) -> None:
    # a negative width was scored as a box of its own (it sits left of bb_left)
    path = tmp_path / "res.txt"
    path.write_text(f"1,1,10,20,30,40\n{row}\n")
    with pytest.raises(RecordingError, match=r"res\.txt, line 2: box .*expected a finite bb_left, bb_top and a "
                                             r"width and height >= 0"):
        read_mot(path)


@pytest.mark.skipif(not TUD.is_dir(), reason="MOT reference data not available")
@pytest.mark.parametrize(("seq", "rows", "n_ids", "first_xyxy"), [
    ("TUD-Campus", 359, 8, [399, 182, 520, 411]),  # first line 1,1,399,182,121,229,1,-1,-1,-1
    ("TUD-Stadtmitte", 1156, 10, [88, 99, 149.08, 317.56]),  # 1,1,88,99,61.08,218.56,1,4.4852,5.5016,0
])
def test_read_mot_tud_gt(seq: str, rows: int, n_ids: int, first_xyxy: list[float]) -> None:
    # README: TUD-Campus gt.txt 359 rows, TUD-Stadtmitte 1156; the metric table gives GT = 8 and 10 objects
    gt = read_mot(TUD / seq / "gt.txt")
    assert len(gt) == rows
    assert np.unique(gt.id).size == n_ids
    assert gt.frame.min() == 1
    assert gt.boxes_ltwh.shape == (rows, 4)
    assert gt.extra.shape == (rows, 3)
    assert np.all(gt.boxes_ltwh[:, 2:] > 0)
    np.testing.assert_allclose(gt.boxes_xyxy[0], first_xyxy, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(gt.rows_at(1), np.flatnonzero(gt.frame == 1))


@pytest.mark.skipif(not PETS_DET.is_file(), reason="PETS detections not available")
def test_read_mot_pets_detections() -> None:
    # README: 4359 boxes, frames 1-795, frame,-1,x,y,w,h,conf,-1,-1,-1 in 768x576 pixels (x 0.625 -> 480x360)
    det = read_mot(PETS_DET)
    assert len(det) == 4359
    assert (det.frame.min(), det.frame.max()) == (1, 795)
    assert np.all(det.id == -1)
    assert np.all((det.conf > 0) & (det.conf <= 1))
    small = det.scaled(0.625)
    np.testing.assert_allclose(small.boxes_ltwh, det.boxes_ltwh * 0.625)
    centres = small.boxes_xyxy.reshape(-1, 2, 2).mean(axis=1)
    assert np.all((centres >= 0) & (centres <= [480, 360]))
    # select keeps every column with its row: the confident boxes are the file's lines with conf >= 0.99
    lines = [ln.split(",") for ln in PETS_DET.read_text().split()]
    sure = det.select(det.conf >= 0.99)
    assert len(sure) == sum(float(ln[6]) >= 0.99 for ln in lines) > 0
    assert np.all(sure.conf >= 0.99)
    assert sure.extra.shape == (len(sure), det.extra.shape[1])
    np.testing.assert_array_equal(sure.boxes_ltwh, det.boxes_ltwh[det.conf >= 0.99])
    np.testing.assert_array_equal(sure.frame, det.frame[det.conf >= 0.99])


def test_read_mot_errors(tmp_path: Path) -> None:
    p = tmp_path / "det.txt"
    p.write_text("1,-1,1,2,3\n")
    with pytest.raises(RecordingError, match=r"det\.txt, line 1: 5 columns, expected at least 6"):
        read_mot(p)
    p.write_text("1,-1,1,2,3,4,0.9\n2,-1,1,2,3,4\n")
    with pytest.raises(RecordingError, match=r"det\.txt, line 2: expected 7 comma-separated"):
        read_mot(p)
    p.write_text("1,-1,1,2,3,4,0.9\n2.5,-1,1,2,3,4,0.9\n")
    with pytest.raises(RecordingError, match=r"det\.txt, line 2: frame 2\.5 is not a whole number"):
        read_mot(p)
    with pytest.raises(RecordingError, match="no such file"):
        read_mot(tmp_path / "none.txt")
    p.write_text("1,2,1,2,3,4\n")
    assert read_mot(p).conf.tolist() == [1.0]


# -- JSON lines ----------------------------------------------------------------------------------------


def _json_records() -> list:
    rng = np.random.default_rng(5)
    cov = rng.normal(size=(4, 4))
    return [
        TrackState(T0, "tracker", 3, rng.normal(size=2), [np.nan, np.inf], covariance=cov @ cov.T,
                   cls="car", situation="merged", sensors=("laser_front",), score=-np.inf,
                   box_px=[1.5, 2, 3, 4], camera="cam_0"),
        TrackState(T0 + 1, "tracker", 4, [0.1, 0.2]),
        Event(T0, "events", "meeting", t_end_ns=T0 + 5, position_m=[1.0, 2.0], track_ids=(3, 4),
              attributes={"zone": "door", "n": 2, "dist_m": np.float64(0.7), "inf": float("inf"),
                          "pair": (3, 4), "path_m": np.arange(6, dtype=np.float32).reshape(3, 2),
                          "nested": {"ok": True, "none": None, "list": [1, "a", 2.5]}}),
        Event(T0 + 9, "events", "track_lost"),
        GroundTruth(T0, "sim", "world", ids=[1, 2, 7], positions_m=rng.normal(size=(3, 2)),
                    velocities_mps=[[0, 1], [np.nan, np.nan], [2, 3]], classes=("person", "car", "bicycle"),
                    attributes={"height_m": np.array([1.7, 1.8, 1.2], np.float32),
                                "label": np.array(["a", "bb", "c"]), "visible": np.array([True, False, True]),
                                "box_px": np.full((3, 4), np.nan)}),
        GroundTruth(T0 + 2, "sim", "world", ids=np.zeros(0), positions_m=np.zeros((0, 2)),
                    attributes={"height_m": np.zeros(0)}),
    ]


def test_jsonl_round_trip(tmp_path: Path) -> None:
    records = _json_records()
    path = tmp_path / "records.jsonl"
    assert write_jsonl(path, records) == len(records)
    lines = path.read_text().splitlines()
    assert len(lines) == len(records)

    def no_constants(token: str) -> None:
        raise AssertionError(f"non-standard JSON constant {token}")

    objs = [json.loads(line, parse_constant=no_constants) for line in lines]  # strict JSON
    assert [o["type"] for o in objs] == ["TrackState", "TrackState", "Event", "Event", "GroundTruth", "GroundTruth"]
    assert objs[0]["position_m"] == records[0].position_m.tolist()  # arrays are plain lists
    back = read_jsonl(path)
    assert all(records_equal(a, b) for a, b in zip(back, records, strict=True))
    attrs = back[2].attributes
    assert isinstance(attrs["pair"], tuple)
    assert attrs["path_m"].dtype == np.float32
    assert attrs["path_m"].shape == (3, 2)
    assert back[4].attributes["height_m"].dtype == np.float32
    assert back[4].attributes["label"].tolist() == ["a", "bb", "c"]
    assert back[5].positions_m.shape == (0, 2)


def test_jsonl_nan_scalar_attribute(tmp_path: Path) -> None:
    # records_equal compares scalars with ==, so a NaN scalar is checked on its own
    path = tmp_path / "nan.jsonl"
    write_jsonl(path, [Event(0, "events", "k", attributes={"x": float("nan"), "y": -np.inf})])
    (event,) = read_jsonl(path)
    assert np.isnan(event.attributes["x"])
    assert event.attributes["y"] == -np.inf


def test_jsonl_errors(tmp_path: Path) -> None:
    p = tmp_path / "r.jsonl"
    good = json.dumps({"type": "Event", "t_ns": 1, "sensor": "e", "kind": "k"})
    p.write_text(good + "\n{not json\n")
    with pytest.raises(RecordingError, match=r"r\.jsonl, line 2: not JSON"):
        read_jsonl(p)
    p.write_text(good + "\n\n" + json.dumps({"type": "Detection", "t_ns": 1}) + "\n")
    with pytest.raises(RecordingError, match=r"line 3: unknown record type 'Detection'"):
        read_jsonl(p)
    p.write_text(json.dumps({"type": "Event", "t_ns": 1, "sensor": "e"}) + "\n")
    with pytest.raises(RecordingError, match=r"line 1: missing key 'kind'"):
        read_jsonl(p)
    p.write_text(json.dumps({"type": "Event", "t_ns": 1.5, "sensor": "e", "kind": "k"}) + "\n")
    with pytest.raises(RecordingError, match=r"line 1: t_ns: expected an integer"):
        read_jsonl(p)
    p.write_text("[1, 2]\n")
    with pytest.raises(RecordingError, match="expected a JSON object"):
        read_jsonl(p)
    with pytest.raises(RecordingError, match="no such file"):
        read_jsonl(tmp_path / "none.jsonl")
    with pytest.raises(ConfigError, match="expected TrackState, Event or GroundTruth"):
        write_jsonl(p, [Track(1, ())])
    with pytest.raises(ConfigError, match="cannot write a value of type object"):
        write_jsonl(p, [Event(0, "e", "k", attributes={"x": object()})])


@pytest.mark.parametrize("name", ["tracks.jsonl", "tracks.csv", "gt.csv", "tracks.png"])
def test_a_binary_file_is_named_as_not_text(tmp_path: Path, name: str) -> None:
    """Random bytes given for a text file (a tracks file, a picture): a RecordingError naming the file, not a
    UnicodeDecodeError from deep in the reader."""
    p = tmp_path / name
    p.write_bytes(bytes(np.random.default_rng(0).integers(0, 256, 2000, dtype=np.uint8)))
    reader = read_ground_truth_csv if name == "gt.csv" else read_tracks_csv if name.endswith(".csv") else read_jsonl
    with pytest.raises(RecordingError, match=rf"{name}: not a UTF-8 text file \(expected "):
        reader(p)


def test_a_csv_with_both_t_and_t_ns_is_read_by_t_ns_as_tracks_and_as_truth(tmp_path: Path) -> None:
    """The simulator's agents.csv has both: ``t`` seconds from the start, ``t_ns`` the clock. Read as tracks it was
    read by ``t`` (1.7e9 s before the truth, everything missed), as truth by ``t_ns``: one file, two clocks."""
    t0 = 1_700_000_000_000_000_000
    path = tmp_path / "agents.csv"
    path.write_text("t,t_ns,id,x,y\n" + "".join(f"{k * 0.1:.1f},{t0 + k * 100_000_000},{i},{i + 0.5 * k},0\n"
                                                 for k in range(3) for i in (1, 2)))
    tracks = read_tracks_csv(path)
    truth = read_ground_truth_csv(path)
    assert sorted({s.t_ns for s in tracks}) == [g.t_ns for g in truth] == [t0 + k * 100_000_000 for k in range(3)]
    for g in truth:
        for i, xy in zip(g.ids, g.positions_m, strict=True):
            (s,) = [s for s in tracks if s.t_ns == g.t_ns and s.track_id == i]
            np.testing.assert_array_equal(s.position_m, xy)


def test_a_pretty_printed_json_document_is_told_from_json_lines(tmp_path: Path) -> None:
    """A run's summary.json given where tracks (JSON lines) are read: "line 1: not JSON" of a valid JSON file
    misled; the message says what the file is and what to give."""
    path = tmp_path / "summary.json"
    path.write_text(json.dumps({"tracks": 3, "metrics": {"mota": 0.7}}, indent=2))
    with pytest.raises(RecordingError, match=r"summary.json, line 1: not JSON .*one JSON document, not JSON lines"):
        read_jsonl(path)
    (tmp_path / "bad.jsonl").write_text('{"t_ns": 1, oops}\n')
    with pytest.raises(RecordingError) as err:  # a broken line of JSON lines: no such hint
        read_jsonl(tmp_path / "bad.jsonl")
    assert "bad.jsonl, line 1: not JSON" in str(err.value)
    assert "one JSON document" not in str(err.value)
