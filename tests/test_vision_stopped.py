"""A2's augmented mask (vision/stopped.py) takes frames of any memory layout, and refuses other pixel types."""

from __future__ import annotations

import numpy as np
import pytest

from fusiontrack.vision.stopped import AugmentedMask


def test_a_channel_flipped_or_cropped_view_gives_the_mask_of_its_copy():
    rng = np.random.default_rng(0)
    frames = rng.integers(0, 255, (12, 20, 40, 3), dtype=np.uint8)
    fg = np.zeros((20, 30), bool)
    fg[5:12, 8:16] = True  # a still object the MoG keeps calling foreground
    views = [f[:, 5:35, ::-1] for f in frames]  # cropped and RGB <-> BGR, as cv2 / a ROS image gives them
    a, b = AugmentedMask(np.ascontiguousarray(views[0])), AugmentedMask(np.ascontiguousarray(views[0]))
    for v in views[1:]:
        np.testing.assert_array_equal(a.update(v, fg), b.update(np.ascontiguousarray(v), fg))


def test_a_frame_of_another_pixel_type_is_a_clear_error():
    m = AugmentedMask(np.zeros((8, 8, 3), np.uint8))
    with pytest.raises(ValueError, match="uint8"):
        m.update(np.zeros((8, 8, 3), np.uint16), np.zeros((8, 8), bool))
