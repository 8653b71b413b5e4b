"""Seed 001's appearance classifiers (ALGORITHMS.md B12-B16): cost per target and learning curve.

Cost, on synthetic 640x480 frames with 1, 5 or 10 textured people (40x100 px boxes, ~42 patches each): one
frame of :meth:`AppearanceBank.train` with an update forced for every target (patches of every box, features,
and one B14 update per target), the B14 update alone per target, with the NumPy CART and with scikit-learn's
trees, and the scoring of one target over its interacting region (B16 score map, 300 patches) and over its
box (B17 box score). Each time is the median over ``--frames`` frames, best of ``--repeats`` passes.

Learning curve, on a simulated `crossing` (10 s, seed 0): people 0 and 1 learnt from their true boxes in
frames 40-98 (every other frame), judged on the unseen frames 100-124 (tests/test_vision_appearance_sim.py):
AUC of box scores, AUC of single patches on the person, mean confidence margin, after 1..30 training frames,
averaged over ``--banks`` random streams; for B13's literal mean R, G, B per cell (``colour="rgb"``), for the
default intensity + chromaticity ``(I, r, g)`` per cell, and with twice the learners. Person 2 enters the
training frames only at the 14th, so the first rows also rank a person the classifiers were never shown.

Neighbours through a miscalibrated camera, on simulated `crowd`s (``--crowd-seeds``, 30 s; the camera is 3 degrees
off its calibration): test-then-train over the whole run, as the fused tracker learns (B15: a person learns every
0.2 s while someone is within 1.5 m, negatives their closest others), with B11 boxes at the people's true floor
positions; on every third frame, each trained person's classifier scores its own box and each neighbour's (within
2 m, both boxes clear: at most 30 % inside another box, 90 % in the image). Evidence = own minus neighbour's
confidence (in [-2, 2]; > 0 tells them apart). Through the true camera, through the camera as calibrated, and
through the camera corrected by the horizontal bias learnt first (:func:`fusiontrack.fusion.learn_camera_bias`,
seed 000): how much the classifiers, hence identity checks and score maps, owe to the bias correction.

The same on a real video (:func:`fusiontrack.eval.appearance.neighbour_evidence`): PETS 2009 S2.L1 (480 x 360, people
about 23 x 51 px) with MOTChallenge 2015's public detections, identities from unambiguous box continuity, neighbours
within 1.5 box heights; and the verdicts identity checks would have given the pairs seen on 3 frames or more
(:meth:`~fusiontrack.eval.appearance.NeighbourEvidence.verdicts`: both classifiers' mean evidence, decided when its
running mean passes +-0.6).

    .venv/bin/python benchmarks/appearance.py [--repeats 3] [--frames 20] [--banks 5] [--crowd-seeds 0 1]
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
from rich.console import Console
from rich.table import Table
from sklearn.metrics import roc_auc_score

from fusiontrack.io.recording import Recording
from fusiontrack.sim.scenario import load_scenario
from fusiontrack.sim.simulator import simulate
from fusiontrack.vision.appearance import AppearanceBank, AppearanceParams, BoostParams
from fusiontrack.vision.patches import FeatureParams, extract_features, patch_fraction, sample_patches

H, W = 480, 640
TRAIN = range(40, 100, 2)
TEST = range(100, 125)
CHECKPOINTS = (1, 3, 5, 10, 20, 30)


def synthetic_frames(n_targets: int, n_frames: int, seed: int = 0) -> tuple[list[np.ndarray], dict[int, tuple]]:
    """Frames with ``n_targets`` 40x100 textured people of distinct colours on a textured floor."""
    rng = np.random.default_rng(seed)
    bg = cv2.GaussianBlur(rng.uniform(0, 1, (H, W, 3)).astype(np.float32), (0, 0), 3)
    bg = 130 + (bg - bg.mean()) / bg.std() * 25
    cols, rows = 5, 2
    boxes = {i: (40 + (i % cols) * 120, 60 + (i // cols % rows) * 200,
                 80 + (i % cols) * 120, 160 + (i // cols % rows) * 200) for i in range(n_targets)}
    colours = rng.uniform(30, 230, (n_targets, 3))
    frames = []
    for _ in range(n_frames):
        f = bg.copy()
        for i, (x0, y0, x1, y1) in boxes.items():
            stripes = 0.6 + 0.4 * (np.arange(y1 - y0) // 8 % 2)[:, None, None]
            f[y0:y1, x0:x1] = colours[i] * stripes
        frames.append(np.clip(f + rng.normal(0, 3, (H, W, 3)), 0, 255).astype(np.uint8))
    return frames, boxes


def best_median(run: Callable[[int], float], n: int, repeats: int) -> float:
    """Best over ``repeats`` passes of the median over ``n`` calls of ``run(i)`` (each returns seconds)."""
    return min(float(np.median([run(i) for i in range(n)])) for _ in range(repeats))


def timed(f: Callable[[], object]) -> float:
    t0 = time.perf_counter()
    f()
    return time.perf_counter() - t0


def cost_rows(n_targets: int, n_frames: int, repeats: int) -> list[str]:
    frames, boxes = synthetic_frames(max(n_targets, 2), n_frames + 3)  # a lone learner still needs a confuser
    ids = list(boxes)[:n_targets]
    bank = AppearanceBank(rng=0)
    for f in frames[:3]:  # first updates (AdaBoost from scratch) are not what a running tracker pays
        bank.train(f, boxes, train_ids=ids, force_update=True)
    t_train = best_median(lambda i: timed(lambda: bank.train(frames[3 + i], boxes, train_ids=ids, force_update=True)),
                          n_frames, repeats)
    # one B14 update per target alone: the batch a target gathers in one frame (+ reservoir draw)
    p = bank.params
    img = frames[3]
    patches = sample_patches(np.array(list(boxes.values()), float), img.shape, p.patches, 1)
    feats = extract_features(img, patches, p.features)
    pos = feats[patches.box_index == 0]
    neg = feats[np.isin(patches.box_index, [1, 2])]
    x = np.concatenate([pos, neg])
    y = np.r_[np.ones(len(pos), int), -np.ones(len(neg), int)]
    t_upd = {}
    for backend in ("numpy", "sklearn"):
        bp = AppearanceParams(boost=BoostParams(tree_backend=backend))
        tb = AppearanceBank(bp, rng=0)
        tb.train(frames[0], boxes, train_ids=[0], force_update=True)
        clf = tb.classifier(0)

        def one(_: int, clf=clf) -> float:
            clf.add_samples(x, y)
            return timed(lambda: clf.update(0))

        t_upd[backend] = best_median(one, n_frames, repeats)
    region = np.array([boxes[i] for i in list(boxes)[:2]], float)
    t_map = best_median(lambda i: timed(lambda: bank.score_map(frames[3 + i], [0], boxes_px=region)), n_frames,
                        repeats)
    t_box = best_median(lambda i: timed(lambda: bank.box_scores(frames[3 + i], boxes[0], [0])), n_frames, repeats)
    t_map_all = best_median(lambda i: timed(lambda: bank.score_map(frames[3 + i], ids, boxes_px=region)), n_frames,
                            repeats)
    return [str(n_targets), f"{t_train * 1e3:.1f}", f"{t_train * 1e3 / n_targets:.1f}", f"{t_upd['numpy'] * 1e3:.2f}",
            f"{t_upd['sklearn'] * 1e3:.2f}", f"{t_map * 1e3:.2f}", f"{t_map_all * 1e3:.2f}", f"{t_box * 1e3:.2f}"]


def boxes_of(gt) -> dict[int, np.ndarray]:
    box, vis = gt.attributes["box_px"], gt.attributes["visibility"]
    return {int(i): box[j] for j, i in enumerate(gt.ids) if vis[j] > 0.5}


def crossing() -> tuple[list[np.ndarray], list[np.ndarray], list[dict[int, np.ndarray]]]:
    """Images, per-pixel labels and visible true boxes of camera 0 in a simulated `crossing` (10 s, seed 0)."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "crossing"
        simulate(load_scenario("crossing").with_overrides(seconds=10, seed=0), out)
        with Recording(out) as rec:
            images = [m.bgr() for m in rec.messages(["/camera_0/image"])]
            labels = [m.pixels for m in rec.messages(["/camera_0/labels"])]
            truth = [boxes_of(m) for m in rec.messages(["/ground_truth/camera_0"])]
    return images, labels, truth


def learning_curve(data: tuple, n_banks: int, params: AppearanceParams) -> dict[int, np.ndarray]:
    """``curve[n]``: (n_banks * 2, 3) box AUC, on-person patch AUC, margin after ``n`` training frames."""
    images, labels, truth = data
    rng = np.random.default_rng(100)
    held = []
    for k in TEST:
        for tid, box in truth[k].items():
            p = sample_patches(box, images[k].shape, params.patches, rng=rng)
            held.append((tid, extract_features(images[k], p, params.features),
                         patch_fraction(labels[k] == tid + 1, p) >= 0.5))
    curve: dict[int, list] = {n: [] for n in CHECKPOINTS}
    for seed in range(n_banks):
        bank = AppearanceBank(params, rng=seed)
        for n, k in enumerate(TRAIN, 1):
            bank.train(images[k], truth[k], train_ids=[i for i in (0, 1) if i in truth[k]])
            if n not in CHECKPOINTS:
                continue
            for tid in (0, 1):
                conf = [bank.confidences(f, [tid])[0] for _, f, _ in held]
                own = np.array([t == tid for t, _, _ in held])
                on = np.concatenate([o for _, _, o in held])
                lab = np.concatenate([np.full(len(c), o) for c, o in zip(conf, own, strict=True)])
                c = np.concatenate(conf)
                curve[n].append([roc_auc_score(own, [x.mean() for x in conf]), roc_auc_score(lab[on], c[on]),
                                 c[on & lab].mean() - c[on & ~lab].mean()])
    return {n: np.array(v) for n, v in curve.items()}


def neighbour_evidence(path: Path, camera: object, scenario: object) -> np.ndarray:
    """Test-then-train evidence (module docstring) of one simulated run through ``camera``."""
    from fusiontrack.fusion.tracker import _occlusion
    from fusiontrack.vision.patches import box_visibility

    with Recording(path) as rec:
        images = list(rec.messages(["/camera_0/image"]))
        gt = list(rec.messages(["/ground_truth"]))
    gt_t = np.array([g.t_ns for g in gt])
    offset = round(scenario.config.cameras[0].clock_offset_ms * 1e6)
    bank, last, ev = AppearanceBank(AppearanceParams(), rng=0), None, []
    for k, im in enumerate(images):
        g = gt[int(np.argmin(np.abs(gt_t - (im.t_ns - offset))))]
        ids = [int(i) for i in g.ids]
        if len(ids) < 2:
            continue
        boxes = camera.person_box(g.positions_m, 1.70, 0.40)
        ok = np.isfinite(boxes).all(axis=1)
        vis = np.zeros(len(ids))
        vis[ok] = box_visibility(boxes[ok], (camera.height, camera.width))
        clear = ok & (_occlusion(boxes, ok) <= 0.3)
        d = np.linalg.norm(g.positions_m[:, None] - g.positions_m[None], axis=2)
        rows = [a for a in range(len(ids)) if clear[a] and vis[a] > 0.9 and bank.is_trained(ids[a])]
        if k % 3 == 0 and len(rows) >= 2:
            sc = bank.box_scores(im.pixels, boxes[rows], [ids[a] for a in rows])
            ev += [sc[x, x] - sc[y, x] for x, a in enumerate(rows) for y, b in enumerate(rows)
                   if a != b and d[a, b] < 2.0 and np.isfinite(sc[x, x] - sc[y, x])]
        if last is None or im.t_ns - last >= 200_000_000:
            near = (d + np.eye(len(ids)) * 1e9).min(axis=1) < 1.5
            learn = [ids[a] for a in range(len(ids)) if near[a] and clear[a] and vis[a] > 0.3]
            if learn:
                bank.train(im.pixels, {ids[a]: boxes[a] for a in np.flatnonzero(ok)}, train_ids=learn,
                           positions_m=dict(zip(ids, g.positions_m, strict=True)),
                           force_update=any(not bank.is_trained(i) for i in learn))
                last = im.t_ns
    return np.array(ev)


def camera_error_table(seeds: list[int]) -> Table:
    from fusiontrack.fusion import learn_camera_bias
    from fusiontrack.sim.simulator import Simulation

    evidence: dict[str, list[np.ndarray]] = {"true camera": [], "as calibrated (3 deg off)": [],
                                             "bias-corrected (seed 000)": []}
    with tempfile.TemporaryDirectory() as tmp:
        for seed in seeds:
            scenario = load_scenario("crowd").with_overrides(seconds=30, seed=seed)
            path = Path(tmp) / f"crowd{seed}"
            simulate(scenario, path)
            cam = Simulation(scenario).cameras[0]
            corr = {c.name: -round(c.clock_offset_ms * 1e6) for c in [*scenario.config.lasers,
                                                                       *scenario.config.cameras]}
            bias = learn_camera_bias(path, "camera_0", camera=cam.calibrated_camera, clock_corrections_ns=corr)
            for name, camera in zip(evidence, (cam.true_camera, cam.calibrated_camera, bias.corrected_camera),
                                    strict=True):
                evidence[name].append(neighbour_evidence(path, camera, scenario))
    t = Table(title=f"neighbours told apart on simulated crowds (seeds {seeds}, 30 s), B11 boxes at the true "
                    f"positions, test-then-train", header_style="bold")
    for col in ("camera", "pairs scored", "mean evidence", "10th percentile", "right sign", "evidence > 0.6"):
        t.add_column(col, justify="right")
    for name, parts in evidence.items():
        e = np.concatenate(parts)
        t.add_row(name, str(e.size), f"{e.mean():.2f}", f"{np.percentile(e, 10):.2f}", f"{np.mean(e > 0):.1%}",
                  f"{np.mean(e > 0.6):.1%}")
    return t


def real_video_table() -> Table:
    from fusiontrack.eval.appearance import neighbour_evidence
    from fusiontrack.io.tracks import read_mot
    from fusiontrack.io.video import VideoReader

    folder = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "video" / "pets09_s2l1"
    det = read_mot(folder / "PETS09-S2L1_det_MOT15.txt").scaled(0.625)

    def frames():
        with VideoReader(folder / "vtest_pets09_s2l1_480x360.avi", "camera", fps=7.0) as video:
            for k, img in enumerate(video, start=1):
                yield k, img.pixels

    t0 = time.perf_counter()
    ne = neighbour_evidence(frames(), det)
    seconds = time.perf_counter() - t0
    e, v = ne.evidence, ne.verdicts()
    t = Table(title=f"neighbours told apart on a real video: PETS09 S2.L1, 795 frames, MOT15 public detections, "
                    f"test-then-train ({seconds:.1f} s)", header_style="bold")
    for col in ("pairs scored", "mean evidence", "10th percentile", "right sign", "evidence > 0.6",
                "checks: kept", "wrongly exchanged", "undecided"):
        t.add_column(col, justify="right")
    t.add_row(str(e.size), f"{e.mean():.2f}", f"{np.percentile(e, 10):.2f}", f"{ne.right_sign():.1%}",
              f"{np.mean(e > 0.6):.1%}", str(v["keep"]), str(v["exchange"]), str(v["undecided"]))
    return t


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--frames", type=int, default=20, help="frames timed per pass")
    parser.add_argument("--banks", type=int, default=5, help="random streams averaged in the learning curve")
    parser.add_argument("--crowd-seeds", type=int, nargs="*", default=[0, 1],
                        help="crowds for the camera-error table (none: skip it)")
    args = parser.parse_args()
    console = Console(width=140)
    load = os.getloadavg()
    table = Table(title=f"appearance cost at 640x480, median of {args.frames} frames, best of {args.repeats} "
                        f"(load average {load[0]:.1f} on {os.cpu_count()} cores)", header_style="bold")
    for col in ("targets", "train frame ms (all)", "per target ms", "B14 update ms (NumPy CART)",
                "B14 update ms (sklearn)", "score map 1 target ms", "score map all targets ms", "box score ms"):
        table.add_column(col, justify="right")
    for n in (1, 5, 10):
        table.add_row(*cost_rows(n, args.frames, args.repeats))
    console.print(table)
    console.print("train frame = B12 patches of every box + B13 features + one forced B14 update per target; "
                  "B14 update = 3 new depth-3 trees on one frame's batch (~42 positives, ~84 negatives) + the "
                  "reservoir draw; score map = 300 patches in the dilated union of two boxes (B16).")
    data = crossing()
    for name, params in (("B13 mean R, G, B per cell (colour='rgb'), M = 10, K_keep = 7",
                          AppearanceParams(features=FeatureParams(colour="rgb"))),
                         ("defaults: (I, r, g) per cell, M = 10, K_keep = 7", AppearanceParams()),
                         ("(I, r, g) per cell, M = 20, K_keep = 14",
                          AppearanceParams(boost=BoostParams(n_learners=20, n_keep=14)))):
        curve = learning_curve(data, args.banks, params)
        t = Table(title=f"learning curve on the simulated crossing, {name} (unseen frames 100-124; mean (min) over "
                        f"{args.banks} banks x 2 people)", header_style="bold")
        for col in ("training frames", "box AUC", "patch AUC (on person)", "margin"):
            t.add_column(col, justify="right")
        for n, v in curve.items():
            t.add_row(str(n), *(f"{v[:, j].mean():.3f} ({v[:, j].min():.3f})" for j in range(3)))
        console.print(t)
    console.print(real_video_table())
    if args.crowd_seeds:
        console.print(camera_error_table(args.crowd_seeds))


if __name__ == "__main__":
    main()
