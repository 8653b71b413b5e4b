"""The RGB-D detector and C7 on real data: five TUe RoboCup snapshots (../shared/data/rgbd/tue_rgbd_people).

Outside truth: the dataset README ("one man standing ~2 m in front of the robot") and, per frame, a point on
the man's torso marked by hand on the colour image (full-resolution pixels, looked up once by eye).
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pytest

from fusiontrack.io.recording import Recording
from fusiontrack.types import CameraInfo, DepthImage, Image
from fusiontrack.vision.rgbd import RgbdParticleFilter, detect_people_rgbd, target_position

log = logging.getLogger(__name__)

# bag stem -> a pixel (u, v) on the standing man's torso, marked by hand
TORSO_PX = {
    "2019-05-03-12-41-38": (310, 220),
    "2019-05-03-12-42-18": (370, 220),
    "2019-05-03-12-42-25": (370, 220),
    "2019-05-03-12-42-30": (350, 220),
    "2019-05-03-12-42-34": (350, 220),
}
# "~2 m" in the README is a rounded figure: we accept what rounds to 2 m, [1.5, 2.5) m.
DISTANCE_RANGE_M = (1.5, 2.5)


@pytest.fixture(scope="module")
def tue_frames(shared_data: Path) -> dict[str, tuple[Image, DepthImage, CameraInfo]]:
    folder = shared_data / "rgbd" / "tue_rgbd_people"
    out = {}
    for bag in sorted(folder.glob("*.bag")):
        with Recording(bag) as rec:
            msgs = {type(m).__name__: m for m in rec.messages()}
        out[bag.stem] = (msgs["Image"], msgs["DepthImage"], msgs["CameraInfo"])
    assert sorted(out) == sorted(TORSO_PX)
    return out


def _the_man(frame: tuple[Image, DepthImage, CameraInfo], torso: tuple[int, int]):
    _, depth, info = frame
    det = detect_people_rgbd(depth.depth_m, info, rng=0)
    u, v = torso
    inside = (det.boxes_px[:, 0] <= u) & (u < det.boxes_px[:, 2]) & (det.boxes_px[:, 1] <= v) & (v < det.boxes_px[:, 3])
    assert inside.any(), f"no detection contains the man's torso at {torso}: {det.boxes_px.tolist()}"
    return det, int(np.flatnonzero(inside)[0])  # detections are nearest first


def test_the_standing_man_is_found_at_about_two_metres(tue_frames):
    distances = {}
    for stem, frame in tue_frames.items():
        image, depth, info = frame
        assert (image.width, image.height) == (640, 480)
        assert depth.depth_m.shape == (480, 640)
        det, i = _the_man(frame, TORSO_PX[stem])
        # the blob is person-sized (not a wall or a merge with the seated crowd)
        assert 0.25 <= det.width_m[i] <= 0.8
        assert det.height_m[i] >= 1.0  # visible vertical extent (his feet are at the image border)
        fix = target_position(depth.depth_m, det.boxes_px[i], info)
        assert fix.valid
        distances[stem] = (fix.depth_m, fix.range_m)
        assert DISTANCE_RANGE_M[0] <= fix.depth_m < DISTANCE_RANGE_M[1]
        assert DISTANCE_RANGE_M[0] <= fix.range_m < DISTANCE_RANGE_M[1]
        # the detector's own C7 point and target_position agree
        assert det.depth_m[i] == pytest.approx(fix.depth_m, abs=0.05)
        # he stands in front of the robot: within 0.5 m of the optical axis sideways
        assert abs(fix.position_cam_m[0]) < 0.5
    log.info("TUe man, depth Z and range per frame (m): %s",
             {k: (round(z, 3), round(r, 3)) for k, (z, r) in distances.items()})


def test_rgbd_filter_starts_on_the_man_and_holds_on_the_next_snapshot(tue_frames):
    # 12:42:25 and 12:42:30 are 5 s apart, the man has turned and moved his arms: the filter started on the
    # first must stay on him (the box centre within his torso's width) rather than jump to the seated crowd
    a, b = tue_frames["2019-05-03-12-42-25"], tue_frames["2019-05-03-12-42-30"]
    det, i = _the_man(a, TORSO_PX["2019-05-03-12-42-25"])
    pf = RgbdParticleFilter(a[0].bgr(), a[1].depth_m, det.boxes_px[i], rng=0)
    for _ in range(5):  # a few iterations on the second snapshot (a slow frame rate)
        est = pf.step(b[0].bgr(), b[1].depth_m)
    assert not est.lost
    assert abs(est.centre_px[0] - TORSO_PX["2019-05-03-12-42-30"][0]) < 60
    fix = target_position(b[1].depth_m, est.box_px, b[2], reference_depth_m=est.depth_m)
    assert DISTANCE_RANGE_M[0] <= fix.depth_m < DISTANCE_RANGE_M[1]
