"""Tracking metrics (eval/mot.py) against published values and hand-built floor-plane cases.

Published numbers: ../shared/data/mot_reference/README.md (TUD: MOTChallenge devkit / py-motmetrics;
MOT17: TrackEval 1.3.0's own MotChallenge2DBox pipeline). Floor-plane answers are worked out by hand
in each test from the documented similarity ``1 - d / (2 threshold_m)``.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from fusiontrack.eval import (
    EvaluationError,
    Metrics,
    combine_metrics,
    evaluate_floor,
    evaluate_mot_files,
    floor_similarity,
    metrics_table,
)
from fusiontrack.io.tracks import read_mot
from fusiontrack.types import GroundTruth, Track, TrackState

DT_NS = 100_000_000  # ground truth at 10 Hz
T0_NS = 1_700_000_000_000_000_000  # a Unix-epoch start, as in recordings

def _trackeval_reference(dataset_config: dict, tracker: str) -> dict[str, Metrics]:
    """TrackEval's own pipeline (Evaluator + MotChallenge2DBox), quiet, per sequence and ``"combined"``."""
    import trackeval

    evaluator = trackeval.Evaluator({"USE_PARALLEL": False, "PRINT_RESULTS": False, "PRINT_CONFIG": False,
                                     "TIME_PROGRESS": False, "OUTPUT_SUMMARY": False, "OUTPUT_DETAILED": False,
                                     "PLOT_CURVES": False, "LOG_ON_ERROR": None})
    dataset = trackeval.datasets.MotChallenge2DBox({"SPLIT_TO_EVAL": "train", "TRACKERS_TO_EVAL": [tracker],
                                                    "PRINT_CONFIG": False, **dataset_config})
    metrics = [trackeval.metrics.HOTA(), trackeval.metrics.CLEAR({"PRINT_CONFIG": False}),
               trackeval.metrics.Identity({"PRINT_CONFIG": False})]
    res, msg = evaluator.evaluate([dataset], metrics)
    assert msg["MotChallenge2DBox"][tracker] == "Success"
    return {("combined" if seq == "COMBINED_SEQ" else seq): Metrics.from_trackeval(r["pedestrian"], num_frames=0)
            for seq, r in res["MotChallenge2DBox"][tracker].items()}


def _same_numbers(ours: Metrics, ref: Metrics) -> None:
    expected = ref.to_dict()
    for key, value in ours.to_dict().items():
        if key not in ("num_frames", "max_matches", "idf1_ceiling"):  # TrackEval does not report them
            assert value == pytest.approx(expected[key], abs=1e-12), key


# ---------------------------------------------------------------------------------------------------
# TUD-Campus / TUD-Stadtmitte (2D MOT 2015): MOTChallenge devkit values as asserted by py-motmetrics
# ---------------------------------------------------------------------------------------------------

TUD = {  # IDF1 IDP IDR Rcll Prcn GT MT PT ML FP FN IDs FM MOTA MOTP(devkit, IoU %) motmetrics motp (1 - IoU)
    "TUD-Campus": (55.8, 73.0, 45.1, 58.2, 94.1, 8, 1, 6, 1, 13, 150, 7, 7, 52.6, 72.3, 0.277201),
    "TUD-Stadtmitte": (64.5, 82.0, 53.1, 60.9, 94.0, 10, 5, 4, 1, 45, 452, 7, 6, 56.4, 65.4, 0.345904),
    "OVERALL": (62.4, 79.9, 51.2, 60.3, 94.0, 18, 6, 10, 2, 58, 602, 14, 13, 55.5, 67.0, 0.330177),
}
TUD_EXACT = {  # motmetrics' exact idf1 and mota
    "TUD-Campus": (0.557659, 0.526462), "TUD-Stadtmitte": (0.644619, 0.564014), "OVERALL": (0.624296, 0.555116),
}
TUD_HOTA = {  # HOTA, DetA, AssA, LocA (TrackEval 1.3.0); LocA not given for the combination
    "TUD-Campus": (0.3914, 0.4180, 0.3691, 0.7701),
    "TUD-Stadtmitte": (0.3978, 0.3923, 0.4088, 0.7375),
    "OVERALL": (0.4000, 0.3977, 0.4124, None),
}


@pytest.fixture(scope="module")
def tud(shared_data: Path) -> dict[str, Metrics]:
    root = shared_data / "mot_reference" / "motmetrics_tud"
    res = {seq: evaluate_mot_files(root / seq / "gt.txt", root / seq / "test.txt")
           for seq in ("TUD-Campus", "TUD-Stadtmitte")}
    res["OVERALL"] = combine_metrics(res)
    return res


def test_results_in_frames_the_truth_lacks_are_warned_of(shared_data: Path, tmp_path: Path, caplog) -> None:
    # TUD-Campus's own result with its frames shifted by 1000: scored (every box missed / false), but said
    root = shared_data / "mot_reference" / "motmetrics_tud" / "TUD-Campus"
    shifted = tmp_path / "shifted.txt"
    rows = [r.split(",") for r in (root / "test.txt").read_text().split()]
    shifted.write_text("".join(",".join([str(int(float(r[0])) + 1000), *r[1:]]) + "\n" for r in rows))
    with caplog.at_level("WARNING"):
        m = evaluate_mot_files(root / "gt.txt", shifted)
    assert "shifted.txt: 0 % of its boxes are in frames of" in caplog.text
    assert m.tp == 0
    caplog.clear()
    with caplog.at_level("WARNING"):
        evaluate_mot_files(root / "gt.txt", root / "test.txt")
    assert "of its boxes are in frames" not in caplog.text


def test_ground_truth_whose_consider_flags_drop_boxes_is_said(shared_data: Path, tmp_path: Path, caplog) -> None:
    """Column 7 of ground truth is the consider flag, read as an integer (TrackEval): fractions there (a detection
    file's confidences given as the truth) drop their boxes. All dropped: an error naming the file (it scored GT 0,
    MOTA 0 without a word); some: a warning with their number, and the scores are those of the file without them."""
    root = shared_data / "mot_reference" / "motmetrics_tud" / "TUD-Campus"
    rows = [r.split(",") for r in (root / "gt.txt").read_text().split()]
    assert len(rows) > 100
    fractions = tmp_path / "fractions.txt"
    fractions.write_text("".join(",".join([*r[:6], "0.9", *r[7:]]) + "\n" for r in rows))
    with pytest.raises(EvaluationError, match=r"fractions.txt: column 7 of the ground truth .* drops every one of "
                                              rf"its {len(rows)} boxes \(its values are fractions"):
        evaluate_mot_files(fractions, root / "test.txt")
    some = tmp_path / "some.txt"
    some.write_text("".join(",".join([*r[:6], "0.5" if k % 3 == 0 else r[6], *r[7:]]) + "\n"
                            for k, r in enumerate(rows)))
    without = tmp_path / "without.txt"
    without.write_text("".join(",".join(r) + "\n" for k, r in enumerate(rows) if k % 3))
    with caplog.at_level("WARNING"):
        m = evaluate_mot_files(some, root / "test.txt")
    n_dropped = len(range(0, len(rows), 3))
    assert f"some.txt: {n_dropped} of the ground truth's {len(rows)} boxes have a fraction" in caplog.text
    assert m.to_dict() == evaluate_mot_files(without, root / "test.txt").to_dict()


def test_an_empty_result_file_misses_every_truth_box(shared_data: Path, tmp_path: Path) -> None:
    """A tracker that found nobody writes an empty file: scored (TrackEval does), every truth box a miss."""
    root = shared_data / "mot_reference" / "motmetrics_tud" / "TUD-Campus"
    empty = tmp_path / "empty.txt"
    empty.write_text("")
    m = evaluate_mot_files(root / "gt.txt", empty)
    n_gt = len(read_mot(root / "gt.txt"))
    assert (m.tp, m.fp, m.fn, m.id_switches) == (0, 0, n_gt, 0)
    assert m.mota == 0.0
    assert m.idf1 == 0.0
    with pytest.raises(Exception, match="no data rows"):  # as ground truth, an empty file is an error
        evaluate_mot_files(empty, root / "test.txt")


def test_a_result_frame_past_the_sequence_names_the_file_and_its_length(shared_data: Path, tmp_path: Path) -> None:
    seq = shared_data / "mot_reference/trackeval_mot17/gt/mot_challenge/MOT17-train/MOT17-05-FRCNN"
    res = shared_data / "mot_reference/trackeval_mot17/trackers/mot_challenge/MOT17-train/MPNTrack/data" / \
        "MOT17-05-FRCNN.txt"
    length = int(next(ln for ln in (seq / "seqinfo.ini").read_text().splitlines() if ln.startswith("seqLength"))
                 .split("=")[1])
    late = tmp_path / "late.txt"
    late.write_text(res.read_text() + f"{length + 1},999,10,10,20,40,1,-1,-1,-1\n")
    with pytest.raises(EvaluationError) as err:
        evaluate_mot_files(seq / "gt" / "gt.txt", late)
    # the file, its frame, and the seqinfo.ini the length was read from (the one this test read)
    assert f"late.txt: frame {length + 1} is past the sequence's last, {length} (seqLength in " \
           f"{seq / 'seqinfo.ini'})" in str(err.value)


def _pct(x: float) -> float:
    """A fraction as the devkit prints it: percent with one decimal."""
    return round(100 * x, 1)


@pytest.mark.parametrize("seq", list(TUD))
def test_tud_reproduces_published_clear_and_identity(tud: dict[str, Metrics], seq: str) -> None:
    m = tud[seq]
    idf1, idp, idr, rcll, prcn, gt, mt, pt, ml, fp, fn, ids, fm, mota, motp, motp_mm = TUD[seq]
    assert (_pct(m.idf1), _pct(m.idp), _pct(m.idr), _pct(m.recall), _pct(m.precision)) == (idf1, idp, idr, rcll, prcn)
    assert (m.num_gt_ids, m.mostly_tracked, m.partially_tracked, m.mostly_lost) == (gt, mt, pt, ml)
    assert (m.fp, m.fn, m.id_switches, m.fragmentations) == (fp, fn, ids, fm)
    assert (_pct(m.mota), _pct(m.motp)) == (mota, motp)
    assert 1 - m.motp == pytest.approx(motp_mm, abs=1e-6)
    assert (m.idf1, m.mota) == pytest.approx(TUD_EXACT[seq], abs=1e-6)
    assert all(isinstance(getattr(m, f), int) for f in ("fp", "fn", "id_switches", "mostly_lost"))


@pytest.mark.parametrize("seq", list(TUD_HOTA))
def test_tud_reproduces_trackeval_hota(tud: dict[str, Metrics], seq: str) -> None:
    m = tud[seq]
    hota, deta, assa, loca = TUD_HOTA[seq]
    assert (m.hota, m.deta, m.assa) == pytest.approx((hota, deta, assa), abs=1e-4)
    if loca is not None:
        assert m.loca == pytest.approx(loca, abs=1e-4)


def test_tud_equals_trackevals_own_mot15_pipeline(shared_data: Path, tud: dict[str, Metrics], tmp_path: Path) -> None:
    """TrackEval's MotChallenge2DBox with BENCHMARK='MOT15' (no distractor preprocessing) gives the same numbers."""
    src = shared_data / "mot_reference" / "motmetrics_tud"
    seqs = ("TUD-Campus", "TUD-Stadtmitte")
    split = tmp_path / "gt" / "MOT15-train"
    for seq in seqs:
        (split / seq / "gt").mkdir(parents=True)
        (split / seq / "gt" / "gt.txt").write_text((src / seq / "gt.txt").read_text())
        n = max(int(read_mot(src / seq / f).frame.max()) for f in ("gt.txt", "test.txt"))
        (split / seq / "seqinfo.ini").write_text(f"[Sequence]\nname={seq}\nseqLength={n}\n")
        out = tmp_path / "trackers" / "MOT15-train" / "demo" / "data"
        out.mkdir(parents=True, exist_ok=True)
        (out / f"{seq}.txt").write_text((src / seq / "test.txt").read_text())
    (tmp_path / "seqmap.txt").write_text("name\n" + "\n".join(seqs) + "\n")
    ref = _trackeval_reference({"GT_FOLDER": str(tmp_path / "gt"), "TRACKERS_FOLDER": str(tmp_path / "trackers"),
                                "OUTPUT_FOLDER": str(tmp_path / "out"), "SEQMAP_FILE": str(tmp_path / "seqmap.txt"),
                                "BENCHMARK": "MOT15"}, "demo")
    for seq in seqs:
        _same_numbers(tud[seq], ref[seq])
    _same_numbers(tud["OVERALL"], ref["combined"])


# ---------------------------------------------------------------------------------------------------
# MOT17 (MPNTrack on three train sequences): TrackEval's own pipeline, then our wrapper, vs the README
# ---------------------------------------------------------------------------------------------------

MOT17_SEQS = ("MOT17-05-FRCNN", "MOT17-09-FRCNN", "MOT17-11-FRCNN")
MOT17 = {  # HOTA DetA AssA MOTA MOTP IDF1 (percent, 3 decimals) | IDSW FP FN MT ML Frag
    "MOT17-05-FRCNN": (53.255, 51.028, 55.627, 56.600, 85.133, 63.228, 20, 380, 2602, 42, 34, 33),
    "MOT17-09-FRCNN": (61.439, 64.786, 58.284, 70.160, 90.088, 72.698, 9, 168, 1412, 14, 2, 8),
    "MOT17-11-FRCNN": (67.251, 65.441, 69.137, 70.157, 91.481, 76.513, 10, 146, 2660, 30, 18, 17),
    "combined": (61.595, 60.457, 62.826, 65.832, 89.292, 71.426, 39, 694, 6674, 86, 54, 58),
}


@pytest.fixture(scope="module")
def mot17_root(shared_data: Path) -> Path:
    return shared_data / "mot_reference" / "trackeval_mot17"


@pytest.fixture(scope="module")
def mot17_trackeval(mot17_root: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Metrics]:
    """The reference pipeline: TrackEval's Evaluator on its MotChallenge2DBox dataset, preprocessing on."""
    return _trackeval_reference({
        "GT_FOLDER": str(mot17_root / "gt" / "mot_challenge"),
        "TRACKERS_FOLDER": str(mot17_root / "trackers" / "mot_challenge"),
        "OUTPUT_FOLDER": str(tmp_path_factory.mktemp("trackeval_out")), "SEQMAP_FILE": str(mot17_root / "seqmap.txt"),
        "BENCHMARK": "MOT17"}, "MPNTrack")


@pytest.fixture(scope="module")
def mot17_ours(mot17_root: Path) -> dict[str, Metrics]:
    res = {seq: evaluate_mot_files(mot17_root / "gt" / "mot_challenge" / "MOT17-train" / seq / "gt" / "gt.txt",
                                   mot17_root / "trackers" / "mot_challenge" / "MOT17-train" / "MPNTrack" / "data"
                                   / f"{seq}.txt")
           for seq in MOT17_SEQS}
    res["combined"] = combine_metrics(res)
    return res


def _check_mot17_row(m: Metrics, row: tuple) -> None:
    pct = tuple(round(100 * x, 3) for x in (m.hota, m.deta, m.assa, m.mota, m.motp, m.idf1))
    assert pct == pytest.approx(row[:6], abs=1e-9)
    assert (m.id_switches, m.fp, m.fn, m.mostly_tracked, m.mostly_lost, m.fragmentations) == row[6:]


@pytest.mark.parametrize("seq", list(MOT17))
def test_mot17_reference_pipeline_matches_readme(mot17_trackeval: dict[str, Metrics], seq: str) -> None:
    _check_mot17_row(mot17_trackeval[seq], MOT17[seq])


@pytest.mark.parametrize("seq", list(MOT17))
def test_mot17_our_wrapper_matches_readme_and_reference(mot17_ours: dict[str, Metrics],
                                                        mot17_trackeval: dict[str, Metrics], seq: str) -> None:
    ours = mot17_ours[seq]
    _check_mot17_row(ours, MOT17[seq])
    _same_numbers(ours, mot17_trackeval[seq])


def test_mot17_preprocessing_matches_trackeval_on_distractors(mot17_root: Path, tmp_path: Path) -> None:
    """MPNTrack never covers a distractor, so the README check does not exercise the removal step: add
    tracker boxes on every distractor (person on vehicle, static person, distractor, reflection) of
    MOT17-05 and check TrackEval's pipeline and ours agree, removing them."""
    seq = "MOT17-05-FRCNN"
    src_gt = mot17_root / "gt" / "mot_challenge" / "MOT17-train" / seq
    gt_dir = tmp_path / "gt" / "MOT17-train" / seq
    (gt_dir / "gt").mkdir(parents=True)
    (gt_dir / "gt" / "gt.txt").write_text((src_gt / "gt" / "gt.txt").read_text())
    (gt_dir / "seqinfo.ini").write_text((src_gt / "seqinfo.ini").read_text())
    (tmp_path / "seqmap.txt").write_text(f"name\n{seq}\n")
    rows = (mot17_root / "trackers" / "mot_challenge" / "MOT17-train" / "MPNTrack" / "data" / f"{seq}.txt") \
        .read_text().splitlines()
    gt = np.loadtxt(src_gt / "gt" / "gt.txt", delimiter=",")
    distractor = gt[np.isin(gt[:, 7], [2, 7, 8, 12])]
    extra = [f"{int(r[0])},{10000 + int(r[1])},{r[2] + 1},{r[3] - 1},{r[4]},{r[5]},1,-1,-1,-1" for r in distractor]
    res_dir = tmp_path / "trackers" / "MOT17-train" / "plus" / "data"
    res_dir.mkdir(parents=True)
    (res_dir / f"{seq}.txt").write_text("\n".join(rows + extra) + "\n")

    ref = _trackeval_reference({"GT_FOLDER": str(tmp_path / "gt"), "TRACKERS_FOLDER": str(tmp_path / "trackers"),
                                "OUTPUT_FOLDER": str(tmp_path / "out"), "SEQMAP_FILE": str(tmp_path / "seqmap.txt"),
                                "BENCHMARK": "MOT17"}, "plus")
    ours = evaluate_mot_files(gt_dir / "gt" / "gt.txt", res_dir / f"{seq}.txt")
    assert ours.num_frames == 837  # seqLength from seqinfo.ini
    _same_numbers(ours, ref[seq])
    assert ours.fp == MOT17[seq][7]  # every added box was removed
    assert ours.num_tracker_dets == len(rows)
    raw = evaluate_mot_files(gt_dir / "gt" / "gt.txt", res_dir / f"{seq}.txt", preprocess=False)
    assert raw.fp == MOT17[seq][7] + len(extra)  # without preprocessing they are false positives


# ---------------------------------------------------------------------------------------------------
# Floor plane: hand-built cases
# ---------------------------------------------------------------------------------------------------


def _gt(xy: np.ndarray, ids=None, t0: int = T0_NS, classes=None) -> list[GroundTruth]:
    """Ground-truth frames from ``xy`` of shape (T, n, 2) (NaN rows = object absent)."""
    xy = np.asarray(xy, float)
    ids = np.arange(1, xy.shape[1] + 1) if ids is None else np.asarray(ids)
    frames = []
    for k in range(xy.shape[0]):
        present = ~np.isnan(xy[k, :, 0])
        cls = None if classes is None else tuple(np.asarray(classes)[present])
        frames.append(GroundTruth(t_ns=t0 + k * DT_NS, sensor="sim", frame_id="world", ids=ids[present],
                                  positions_m=xy[k, present], classes=cls or ()))
    return frames


def _states(xy: np.ndarray, track_ids: np.ndarray, t0: int = T0_NS, dt_ns: int = DT_NS,
            cls: str = "person") -> list[TrackState]:
    """Track states from ``xy`` (T, n, 2) and ``track_ids`` (T, n) (-1 or NaN position = no state)."""
    xy, track_ids = np.asarray(xy, float), np.asarray(track_ids)
    return [TrackState(t_ns=t0 + k * dt_ns, sensor="tracker", track_id=int(track_ids[k, j]), position_m=xy[k, j],
                       cls=cls)
            for k in range(xy.shape[0]) for j in range(xy.shape[1])
            if track_ids[k, j] >= 0 and not np.isnan(xy[k, j, 0])]


def _walk(n_frames: int = 10) -> np.ndarray:
    """Two people 5 m apart walking in parallel at 1 m/s, (T, 2, 2)."""
    k = np.arange(n_frames) * 0.1
    return np.stack([np.stack([k, np.zeros_like(k)], 1), np.stack([k, np.full_like(k, 5.0)], 1)], axis=1)


def test_perfect_tracker_scores_one() -> None:
    xy = _walk()
    m = evaluate_floor(_gt(xy), _states(xy, np.tile([100, 200], (10, 1))))
    assert (m.mota, m.motp, m.idf1, m.hota, m.deta, m.assa, m.loca) == (1.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0)
    assert (m.tp, m.fp, m.fn, m.id_switches, m.fragmentations) == (20, 0, 0, 0, 0)
    assert (m.mostly_tracked, m.partially_tracked, m.mostly_lost, m.num_gt_ids, m.num_tracker_ids) == (2, 0, 0, 2, 2)
    assert m.motp_m == 0.0
    assert dict(m.id_map) == {100: 1, 200: 2}


def test_one_id_switch_halfway() -> None:
    """One person; the track is replaced by a new id after 5 of 10 frames."""
    xy = _walk()[:, :1]
    ids = np.array([[10]] * 5 + [[20]] * 5)
    m = evaluate_floor(_gt(xy), _states(xy, ids))
    assert m.id_switches == 1
    assert m.mota == pytest.approx((10 - 0 - 1) / 10)
    # IDF1: best one-to-one pairing keeps 5 of the 10 frames: IDTP 5, IDFN 5, IDFP 5 -> 2*5 / (10 + 10)
    assert (m.idtp, m.idfn, m.idfp) == (5, 5, 5)
    assert m.idf1 == pytest.approx(0.5)
    # HOTA: DetA 1; each match's association is 5 / (5 + 5 + 0) -> AssA 0.5, HOTA sqrt(0.5)
    assert (m.deta, m.assa, m.hota) == pytest.approx((1.0, 0.5, math.sqrt(0.5)))
    assert m.fragmentations == 0


def test_two_people_swapping_ids() -> None:
    """Two people, the two tracks swap identities halfway: one switch per person."""
    xy = _walk()
    ids = np.array([[10, 20]] * 5 + [[20, 10]] * 5)
    m = evaluate_floor(_gt(xy), _states(xy, ids))
    assert m.id_switches == 2
    assert m.mota == pytest.approx((20 - 2) / 20)
    assert (m.idtp, m.idfn, m.idfp, m.idf1) == (10, 10, 10, pytest.approx(0.5))


def test_idf1_ceiling_separates_identity_from_detection_errors() -> None:
    """The ceiling is IDF1 with perfect identities on the same positions: 1 for a pure swap (IDF1 0.5), and
    equal to IDF1 when the only errors are detection errors."""
    xy = _walk()
    swap = evaluate_floor(_gt(xy), _states(xy, np.array([[10, 20]] * 5 + [[20, 10]] * 5)))
    assert (swap.idf1, swap.max_matches, swap.idf1_ceiling) == (pytest.approx(0.5), 20, 1.0)
    # one person tracked well plus a spurious track far away: 10 matches of 10 + 20 detections
    both = np.concatenate([xy[:, :1], xy[:, :1] + np.array([0.0, 50.0])], axis=1)
    spurious = evaluate_floor(_gt(xy[:, :1]), _states(both, np.tile([1, 2], (10, 1))))
    assert spurious.max_matches == 10
    assert spurious.idf1_ceiling == pytest.approx(2 * 10 / 30)
    assert spurious.idf1 == pytest.approx(spurious.idf1_ceiling)
    assert evaluate_floor(_gt(xy), []).idf1_ceiling == 0.0


def test_idf1_ceiling_takes_the_largest_matching() -> None:
    """People A (x = 0) and B (x = 0.8); track 1 at 0.4 is within 0.5 m of both, track 2 at 1.2 of B only. The
    nearest-first pairing (track 1 - A or B, a tie) can leave one match; the largest matching has two."""
    gt_xy = np.tile(np.array([[[0.0, 0.0], [0.8, 0.0]]]), (4, 1, 1))
    tr_xy = np.tile(np.array([[[0.4, 0.0], [1.2, 0.0]]]), (4, 1, 1))
    m = evaluate_floor(_gt(gt_xy), _states(tr_xy, np.tile([1, 2], (4, 1))), threshold_m=0.5)
    assert m.max_matches == 8
    assert m.idf1_ceiling == 1.0


@pytest.mark.parametrize("seed", range(6))
def test_idf1_never_exceeds_its_ceiling(seed: int) -> None:
    """Random crowds with noisy, swapping, missing and spurious tracks: IDTP <= max_matches (hence IDF1 <= the
    ceiling), and CLEAR's matches are a matching too (TP <= max_matches)."""
    rng = np.random.default_rng(seed)
    n_t, n = 40, 6
    gt_xy = np.cumsum(rng.normal(0, 0.15, (n_t, n, 2)), axis=0) + rng.uniform(0, 3, (1, n, 2))
    tr_xy = gt_xy + rng.normal(0, 0.3, gt_xy.shape)
    ids = np.tile(np.arange(n), (n_t, 1))
    for k in rng.integers(1, n_t, 6):  # identity swaps between random pairs from frame k on
        i, j = rng.choice(n, 2, replace=False)
        ids[k:, [i, j]] = ids[k:, [j, i]]
    ids[rng.random(ids.shape) < 0.1] = -1  # missed states
    extra = rng.uniform(0, 3, (n_t, 2, 2))  # two spurious tracks
    tr_xy = np.concatenate([tr_xy, extra], axis=1)
    ids = np.concatenate([ids, np.tile([100, 101], (n_t, 1))], axis=1)
    m = evaluate_floor(_gt(gt_xy), _states(tr_xy, ids))
    assert m.idtp <= m.max_matches
    assert m.tp <= m.max_matches
    assert m.idf1 <= m.idf1_ceiling + 1e-12
    assert 0.0 < m.idf1_ceiling < 1.0


def test_constant_offset_inside_threshold() -> None:
    """0.3 m offset, threshold 0.5 m: all matched; MOTP = 1 - 0.3 / (2 * 0.5) = 0.7."""
    xy = _walk()
    m = evaluate_floor(_gt(xy), _states(xy + np.array([0.0, 0.3]), np.tile([7, 8], (10, 1))), threshold_m=0.5)
    assert (m.tp, m.fp, m.fn, m.mota, m.idf1) == (20, 0, 0, 1.0, 1.0)
    assert m.motp == pytest.approx(0.7)
    assert m.motp_m == pytest.approx(0.3)
    # the same offset against a 0.25 m threshold: nothing matches
    m = evaluate_floor(_gt(xy), _states(xy + np.array([0.0, 0.3]), np.tile([7, 8], (10, 1))), threshold_m=0.25)
    assert (m.tp, m.fp, m.fn, m.mota) == (0, 20, 20, -1.0)


def test_hota_alpha_sweep_for_an_offset() -> None:
    """0.275 m offset at 0.5 m: similarity 0.725 matches for alpha 0.05 .. 0.70 (14 of 19) only."""
    xy = _walk()
    m = evaluate_floor(_gt(xy), _states(xy + np.array([0.275, 0.0]), np.tile([7, 8], (10, 1))))
    assert (m.hota, m.deta, m.assa) == pytest.approx((14 / 19, 14 / 19, 14 / 19))
    assert m.mota == 1.0


def test_match_is_exactly_distance_at_most_threshold() -> None:
    xy = _walk(4)
    at = evaluate_floor(_gt(xy), _states(xy + np.array([0.0, 0.5]), np.tile([7, 8], (4, 1))), threshold_m=0.5)
    assert (at.tp, at.motp) == (8, 0.5)
    beyond_xy = xy + np.array([0.0, 0.5 + 1e-12])
    beyond = evaluate_floor(_gt(xy), _states(beyond_xy, np.tile([7, 8], (4, 1))), threshold_m=0.5)
    assert (beyond.tp, beyond.fp, beyond.fn, beyond.idtp) == (0, 8, 8, 0)
    s = floor_similarity([[0.0, 0.0]], [[0.0, 0.5], [0.0, 0.5 + 1e-15], [0.0, 0.0], [3.0, 0.0]], 0.5)
    assert (s[0, 0], s[0, 2], s[0, 3]) == (0.5, 1.0, 0.0)
    assert s[0, 1] < 0.5 - np.finfo(float).eps  # just beyond the threshold: below TrackEval's match test


def test_a_track_without_a_floor_position_matches_nobody() -> None:
    """States whose position is NaN or infinite (a camera track with no floor calibration) are scored as false
    positives beside the others, not a crash of the assignment."""
    xy = _walk()
    states = _states(xy, np.tile([100, 200], (10, 1)))
    lost = [TrackState(t_ns=T0_NS + k * DT_NS, sensor="tracker", track_id=99,
                       position_m=(np.nan, np.nan) if k % 2 else (np.inf, 0.0)) for k in range(3, 7)]
    m = evaluate_floor(_gt(xy), states + lost)
    ref = evaluate_floor(_gt(xy), states)
    assert (m.tp, m.fn, m.id_switches) == (ref.tp, ref.fn, ref.id_switches)
    assert m.fp == ref.fp + 4


def test_spurious_track_counts_as_false_positives() -> None:
    xy = _walk()
    states = _states(xy, np.tile([100, 200], (10, 1)))
    ghost = [TrackState(t_ns=T0_NS + k * DT_NS, sensor="tracker", track_id=99, position_m=(20.0, 20.0))
             for k in range(3, 7)]
    m = evaluate_floor(_gt(xy), states + ghost)
    assert (m.tp, m.fp, m.fn, m.id_switches) == (20, 4, 0, 0)
    assert m.mota == pytest.approx((20 - 4) / 20)
    assert m.precision == pytest.approx(20 / 24)
    assert m.idf1 == pytest.approx(2 * 20 / (2 * 20 + 4))  # IDFP 4
    assert 99 not in m.id_map


def test_missed_person_counts_as_false_negatives_and_mostly_lost() -> None:
    xy = _walk()
    m = evaluate_floor(_gt(xy), _states(xy[:, :1], np.tile([100], (10, 1))))
    assert (m.tp, m.fn, m.fp, m.mostly_tracked, m.mostly_lost) == (10, 10, 0, 1, 1)
    assert m.recall == pytest.approx(0.5)


def test_order_of_records_changes_nothing() -> None:
    """Shuffling the track states and the objects within each frame leaves every number unchanged."""
    rng = np.random.default_rng(7)
    n_t, n = 30, 6
    xy = np.cumsum(rng.normal(0.0, 0.1, (n_t, n, 2)), axis=0) + rng.uniform(0, 4, (1, n, 2))
    ids = np.tile(np.arange(n) + 50, (n_t, 1))
    ids[15:, [0, 1]] = ids[15:, [1, 0]]  # a swap
    ids[rng.random((n_t, n)) < 0.1] = -1  # misses
    noisy = xy + rng.normal(0.0, 0.15, xy.shape)
    gt, states = _gt(xy), _states(noisy, ids)
    ref = evaluate_floor(gt, states)
    assert 0 < ref.mota < 1
    assert ref.id_switches >= 1
    perm = [gt[k] for k in rng.permutation(n_t)]
    shuffled_gt = []
    for f in perm:
        p = rng.permutation(len(f))
        shuffled_gt.append(GroundTruth(t_ns=f.t_ns, sensor=f.sensor, frame_id=f.frame_id, ids=f.ids[p],
                                       positions_m=f.positions_m[p]))
    shuffled_states = [states[i] for i in rng.permutation(len(states))]
    assert evaluate_floor(shuffled_gt, shuffled_states).to_dict() == ref.to_dict()


def test_tracker_faster_than_ground_truth_uses_nearest_state() -> None:
    """Tracker at 40 Hz, ground truth at 10 Hz: each frame scores the state nearest in time."""
    xy = _walk()
    t_fast = np.arange(40) * (DT_NS // 4)
    fast_xy = np.stack([np.stack([t_fast / 1e9, np.zeros(40)], 1), np.stack([t_fast / 1e9, np.full(40, 5.0)], 1)],
                       axis=1)
    fast = _states(fast_xy, np.tile([1, 2], (40, 1)), dt_ns=DT_NS // 4)
    m = evaluate_floor(_gt(xy), fast)
    assert (m.tp, m.fp, m.fn, m.motp) == (20, 0, 0, 1.0)
    assert m.num_tracker_dets == 20


def test_time_tolerance() -> None:
    xy = _walk()
    late = _states(xy, np.tile([1, 2], (10, 1)), t0=T0_NS + 20_000_000)  # stamped 20 ms after the frames
    assert evaluate_floor(_gt(xy), late).tp == 20  # default: half the 100 ms period
    m = evaluate_floor(_gt(xy), late, time_tolerance_ns=10_000_000)
    assert (m.tp, m.fp, m.fn, m.num_tracker_dets) == (0, 0, 20, 0)  # states not within 10 ms are not scored
    with pytest.raises(EvaluationError, match="time_tolerance_ns"):
        evaluate_floor(_gt(xy), late, time_tolerance_ns=-1)


def test_classes_filter_ground_truth_and_tracks() -> None:
    xy = _walk()
    gt = _gt(xy, classes=["person", "car"])
    tracks = _states(xy[:, :1], np.tile([1], (10, 1))) + _states(xy[:, 1:], np.tile([2], (10, 1)), cls="car")
    person = evaluate_floor(gt, tracks)
    assert (person.tp, person.fp, person.fn, person.num_gt_ids) == (10, 0, 0, 1)
    both = evaluate_floor(gt, tracks, classes=("person", "car"))
    assert (both.tp, both.num_gt_ids) == (20, 2)
    assert evaluate_floor(gt, tracks, classes=None).tp == 20
    with pytest.raises(EvaluationError, match="classes"):
        evaluate_floor(gt, tracks, classes=("pedestrian",))


def test_tracks_accepted_as_track_records() -> None:
    xy = _walk()
    states = _states(xy, np.tile([100, 200], (10, 1)))
    tracks = [Track(i, tuple(s for s in states if s.track_id == i)) for i in (100, 200)]
    assert evaluate_floor(_gt(xy), tracks).to_dict() == evaluate_floor(_gt(xy), states).to_dict()


def test_combining_floor_sequences_sums_counts() -> None:
    xy = _walk()
    a = evaluate_floor(_gt(xy), _states(xy, np.array([[10, 20]] * 5 + [[20, 10]] * 5)))
    b = evaluate_floor(_gt(xy), _states(xy[:, :1], np.tile([1], (10, 1))))
    c = combine_metrics({"a": a, "b": b})
    assert (c.tp, c.fn, c.fp, c.id_switches, c.num_gt_ids) == (30, 10, 0, 2, 4)
    assert c.mota == pytest.approx((30 - 0 - 2) / 40)
    assert c.idf1 == pytest.approx(2 * (a.idtp + b.idtp) / (2 * (a.idtp + b.idtp) + a.idfp + a.idfn + b.idfn))
    assert c.distance_scale_m == 1.0
    assert not c.id_map
    assert c.max_matches == a.max_matches + b.max_matches == 30
    assert c.idf1_ceiling == pytest.approx(2 * 30 / (c.num_gt_dets + c.num_tracker_dets))


def test_bad_inputs_raise_named_errors() -> None:
    xy = _walk(3)
    gt = _gt(xy)
    with pytest.raises(EvaluationError, match="threshold_m"):
        evaluate_floor(gt, [], threshold_m=0.0)
    with pytest.raises(EvaluationError, match="at least one"):
        evaluate_floor([], [])
    with pytest.raises(EvaluationError, match="two GroundTruth frames"):
        evaluate_floor([gt[0], gt[0]], [])
    with pytest.raises(EvaluationError, match="two states of track 5"):
        evaluate_floor(gt, _states(xy, np.full((3, 2), 5)))
    dup = GroundTruth(t_ns=T0_NS, sensor="sim", frame_id="world", ids=[1, 1], positions_m=[[0, 0], [1, 1]])
    with pytest.raises(EvaluationError, match="ground-truth id 1 appears more than once"):
        evaluate_floor([dup], [])
    with pytest.raises(ValueError, match="at least one"):  # also a ValueError
        combine_metrics([])


def test_empty_tracker_output() -> None:
    m = evaluate_floor(_gt(_walk()), [])
    assert (m.tp, m.fn, m.fp, m.mota, m.mostly_lost, m.hota) == (0, 20, 0, 0.0, 2, 0.0)


def test_evaluation_prints_nothing(capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch) -> None:
    """Not even after a TrackEval Evaluator has switched TrackEval's global timing printout on."""
    from trackeval import _timing

    monkeypatch.setattr(_timing, "DO_TIMING", True)
    monkeypatch.setattr(_timing, "DISPLAY_LESS_PROGRESS", False)
    xy = _walk()
    m = evaluate_floor(_gt(xy), _states(xy, np.tile([1, 2], (10, 1))))
    combine_metrics([m, m])
    assert capsys.readouterr() == ("", "")


def test_metrics_table_and_dict() -> None:
    from rich.console import Console

    xy = _walk()
    m = evaluate_floor(_gt(xy), _states(xy + np.array([0.0, 0.3]), np.tile([7, 8], (10, 1))))
    d = m.to_dict()
    assert (d["mota"], d["fp"], d["motp_m"]) == (1.0, 0, pytest.approx(0.3))
    assert "raw" not in d
    assert "id_map" not in d
    console = Console(width=200, record=True)
    console.print(metrics_table({"walk": m}, title="floor"))
    text = console.export_text()
    assert all(cell in text for cell in ("walk", "100.0", "0.300", "MOTP m", "IDF1max"))
    assert "sequence" in text  # wide: one row per result
    # a terminal too narrow for 22 columns gets one row per metric, every header and number whole
    narrow = Console(width=80, record=True)
    narrow.print(metrics_table({"walk": m, "run 2": m}))
    lines = narrow.export_text().splitlines()
    assert max(len(line) for line in lines) <= 80
    assert "…" not in "".join(lines)
    headers = ["HOTA", "MOTA", "IDF1", "IDF1max", "IDSW", "FP", "FN", "MOTP m"]
    rows = {line.split("│")[1].strip(): line for line in lines if line.count("│") >= 3}
    assert all(h in rows for h in headers)
    assert rows["MOTA"].count("100.0") == 2
    assert rows["MOTP m"].count("0.300") == 2


def test_a_slower_tracker_is_scored_at_its_own_rate(caplog: pytest.LogCaptureFixture) -> None:
    """Truth at 25 Hz, a perfect tracker at 15 Hz (a camera): against every truth frame it misses everybody in the
    frames between its reports (6 of 15 in each 0.6 s, 40 %), and the evaluation says why; on the truth frames
    nearest to its own frames it scores 1."""
    from fusiontrack.eval import truth_at

    gt_dt, cam_dt = 40_000_000, 200_000_000 // 3  # 25 Hz and 15 Hz
    n_gt = 150  # 6 s
    t_gt = T0_NS + gt_dt * np.arange(n_gt)

    def walk(t_ns: int, k: int) -> np.ndarray:  # person k (0, 1) walks along x at 1.3 m/s, 2 m from the other
        return np.array([1.3e-9 * (t_ns - T0_NS), 2.0 * k])

    gt = [GroundTruth(t_ns=int(t), sensor="sim", frame_id="world", ids=np.array([1, 2]),
                      positions_m=np.array([walk(t, 0), walk(t, 1)])) for t in t_gt]
    t_cam = T0_NS + np.round(cam_dt * np.arange(90)).astype(np.int64)  # 6 s of images
    states = [TrackState(t_ns=int(t), sensor="camera", track_id=k + 10, position_m=walk(t, k), cls="person")
              for t in t_cam for k in range(2)]
    with caplog.at_level("WARNING", logger="fusiontrack.eval.mot"):
        every = evaluate_floor(gt, states, 0.5)
    # the images miss 2 truth frames of every 5: those at 40 and 160 ms of each 200 ms are > 20 ms from an image
    assert (every.fn, every.fp) == (2 * 60, 0)
    assert every.mota == pytest.approx(1 - 120 / 300)
    assert "every 67 ms, the ground truth every 40 ms" in caplog.text
    caplog.clear()
    at_camera = truth_at(gt, t_cam)
    assert len(at_camera) == 90  # each image has its own truth frame within 20 ms
    assert [f.t_ns for f in at_camera] == sorted({f.t_ns for f in at_camera})
    assert np.abs(np.array([f.t_ns for f in at_camera]) - t_cam).max() <= gt_dt // 2
    with caplog.at_level("WARNING", logger="fusiontrack.eval.mot"):
        own = evaluate_floor(at_camera, states, 0.5)
    assert (own.mota, own.fn, own.fp, own.id_switches) == (1.0, 0, 0, 0)
    assert caplog.text == ""
    # times far from every truth frame select none; each frame is selected once however many times are near it
    assert truth_at(gt, [T0_NS - 10**9, int(t_gt[-1]) + 10**9]) == []
    assert [f.t_ns for f in truth_at(gt, [int(t_gt[3]) + 1, int(t_gt[3]) - 1, int(t_gt[1])])] == [t_gt[1], t_gt[3]]
    with pytest.raises(EvaluationError, match="at least one"):
        truth_at([], t_cam)
    with pytest.raises(EvaluationError, match="two GroundTruth frames"):
        truth_at([*gt, gt[5]], t_cam)


def test_tracks_on_another_clock_are_named(caplog: pytest.LogCaptureFixture) -> None:
    """A bag's header stamps and log times can differ by minutes (the leg_tracker outdoor bag: 130 s). Tracks made on
    one and truth read on the other overlap in time, so nothing is dropped, yet each track is compared with where its
    person was 130 s before: the evaluation warns. A tracker that starts 2 s late (learning its backgrounds) but ends
    with the truth is on the truth's clock: no warning."""
    dt = 100_000_000  # 10 Hz, 300 s
    t_gt = T0_NS + dt * np.arange(3000)

    def walk(t_ns: int) -> np.ndarray:  # a person walking along x at 1 m/s
        return np.array([1e-9 * (t_ns - T0_NS), 0.0])

    gt = [GroundTruth(t_ns=int(t), sensor="sim", frame_id="world", ids=np.array([1]), positions_m=walk(t)[None])
          for t in t_gt]
    shift = 130 * 10**9
    shifted = [TrackState(t_ns=int(t - shift), sensor="laser", track_id=7, position_m=walk(t), cls="person")
               for t in t_gt]
    with caplog.at_level("WARNING", logger="fusiontrack.eval.mot"):
        evaluate_floor(gt, shifted, 0.5)
    assert "the tracks start -130.0 s and end -130.0 s from the ground truth's start and end" in caplog.text
    caplog.clear()
    late = [TrackState(t_ns=int(t), sensor="laser", track_id=7, position_m=walk(t), cls="person")
            for t in t_gt[20:]]
    with caplog.at_level("WARNING", logger="fusiontrack.eval.mot"):
        m = evaluate_floor(gt, late, 0.5)
    assert caplog.text == ""
    assert (m.fn, m.fp) == (20, 0)
    # truth that covers only the first 100 s of a 300 s run: both ends are after the truth's, by 3 s and 200 s; that
    # is no single shift of a clock
    with caplog.at_level("WARNING", logger="fusiontrack.eval.mot"):
        evaluate_floor(gt[:1000], late, 0.5)
    assert "the tracks start" not in caplog.text
    assert "cover only part" in caplog.text  # most states have no truth frame near them: why, in the warning
    caplog.clear()
    # a late start and a late end by one shift (60 s, 2 % of the span or more) is a clock problem again
    later = [TrackState(t_ns=int(t + 60 * 10**9), sensor="laser", track_id=7, position_m=walk(t), cls="person")
             for t in t_gt]
    with caplog.at_level("WARNING", logger="fusiontrack.eval.mot"):
        evaluate_floor(gt, later, 0.5)
    assert "the tracks start +60.0 s and end +60.0 s" in caplog.text
