"""OpenCV's worker threads, set for a block of work."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

__all__ = ["opencv_threads"]


@contextmanager
def opencv_threads(n: int) -> Iterator[None]:
    """OpenCV's thread count set to ``n`` for the block, restored after it.

    The pipelines run OpenCV on one thread: their images are small (a camera frame of 640 x 480 or its road
    window), and OpenCV's worker threads cost more CPU than they save (0.7-0.8 ms of CPU per traffic camera frame
    of 9-10 ms; ``extract_blobs`` at 320 x 240 0.68 ms with 2 threads, 0.30 ms with one).
    """
    import cv2

    before = cv2.getNumThreads()
    cv2.setNumThreads(n)
    try:
        yield
    finally:
        cv2.setNumThreads(before)
