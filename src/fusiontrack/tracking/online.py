"""People tracking from laser scans as they arrive: a live scanner, a driver's callback, a ROS 2 node.

:class:`OnlineLaserTracker` is the loop of :func:`~fusiontrack.tracking.track_recording` turned inside out:
instead of reading a recording it is fed one :class:`~fusiontrack.types.LaserScan` at a time and returns the
track states as soon as a step is complete. :func:`~fusiontrack.tracking.tracker.run_tracker` (what
``track_recording`` and ``fusiontrack track`` run) feeds a recording's scans through it, so a live run and a
recorded one are the same code.

A step is the set of scans with one time stamp. Scanners are not synchronised, so a step is complete when a scan
with a later stamp arrives: :meth:`OnlineLaserTracker.feed` returns the states of the step before, one scan period
after it (40 ms at 25 Hz); :meth:`OnlineLaserTracker.close` runs the last one. A scan that arrives late (older
than the step in progress, e.g. one scanner's messages delayed on the network) still updates its scanner's
background and foreground, and its points join the step in progress; steps never go back in time. (A scan older
than its own scanner's last one is dropped by the detector, counted in its ``dropped_scans``.) The backgrounds
are learnt online, as ``track_recording(..., background="learn")`` does.
"""

from __future__ import annotations

import inspect
import logging
import time
from collections.abc import Mapping
from typing import Any

import numpy as np

from ..errors import ConfigError
from ..types import Event, LaserScan, TrackState

__all__ = ["OnlineLaserTracker"]

log = logging.getLogger(__name__)


class OnlineLaserTracker:
    """Detect and track people in laser scans fed one at a time.

    Parameters
    ----------
    scanners : mapping of sensor name -> laser2world
        The scanners (the ``sensor`` of their scans) and their poses in the world frame: a ``(3, 3)`` 2-D pose
        (:func:`~fusiontrack.geometry.pose2d_to_matrix`) or a ``(4, 4)`` transform (the identity: tracks in the
        laser frame).
    tracker : ``"pf"`` or ``"kalman"``
        :class:`~fusiontrack.tracking.LaserPeopleTracker` (seed 001's walking-model particle filters) or the
        constant-velocity Kalman baseline.
    params : TrackerParams, mapping or None
        Tracker parameters (for ``"kalman"``: keyword arguments of the baseline).
    detector_params : mapping, optional
        Keyword arguments of :class:`~fusiontrack.laser.LaserPeopleDetector` (the ``[laser]`` table).
    area_m : ``"auto"``, None, rectangle or polygon
        The covered area, where people enter and leave. ``"auto"``: the hull of what the scanners see, once
        their backgrounds are learnt.
    background : ``"learn"`` or ``"none"``
        ``"learn"``: fixed scanners; each learns its background over its first ``n_init`` scans (nothing is
        detected before). ``"none"``: a scanner on a moving platform: every return is foreground.
    classify : bool
        Give each track its class (person / bicycle / car, B18).
    rng : Generator or int

    Attributes
    ----------
    late_scans : int
        Scans that arrived older than the step in progress (used in that step, unless older than their own
        scanner's last scan: those the detector drops).
    """

    def __init__(self, scanners: Mapping[str, Any], *, tracker: str = "pf", params: Any = None,
                 detector_params: Mapping[str, Any] | None = None, area_m: Any = "auto", background: str = "learn",
                 classify: bool = True, rng: np.random.Generator | int | None = 0) -> None:
        from ..laser.detector import UNLEARNT_BACKGROUND, LaserPeopleDetector, check_detector_params

        if not isinstance(scanners, Mapping) or not scanners:
            raise ConfigError("scanners: expected a non-empty mapping of sensor name -> laser2world pose")
        if background not in ("learn", "none"):
            raise ConfigError(f"background: expected 'learn' or 'none', got {background!r}")
        dparams = check_detector_params(detector_params)
        if background == "none":
            dparams = {**UNLEARNT_BACKGROUND, **dparams}
        poses = {str(name): np.asarray(pose, dtype=np.float64) for name, pose in scanners.items()}
        try:
            detector = LaserPeopleDetector(poses, **dparams)
        except ValueError as err:  # a bad pose, named by the detector
            raise ConfigError(str(err)) from err
        self._init(make_tracker(tracker, params, area_m, rng), detector, poses, auto_area=isinstance(area_m, str),
                   classify=classify)
        self._no_return = dparams if background == "none" else None  # scanners still to be set to "no return"

    @classmethod
    def from_parts(cls, tracker: Any, detector: Any, poses: Mapping[str, np.ndarray], *, auto_area: bool = False,
                   classify: bool = True, timings: dict[str, list[float]] | None = None) -> OnlineLaserTracker:
        """From a built tracker (``step(t_ns, detections)``, ``events``, ``finish()``) and detector (``update``,
        ``detect``); ``timings`` as in :func:`~fusiontrack.tracking.track_recording`."""
        out = cls.__new__(cls)
        out._init(tracker, detector, poses, auto_area=auto_area, classify=classify, timings=timings)
        return out

    def _init(self, tracker: Any, detector: Any, poses: Mapping[str, np.ndarray], *, auto_area: bool,
              classify: bool, timings: dict[str, list[float]] | None = None) -> None:
        from .classify import TrackClassifier

        self.tracker, self.detector, self.poses = tracker, detector, dict(poses)
        self._auto_area = auto_area
        self._classifier = TrackClassifier() if classify else None
        self._timings = timings
        self._geometries: dict[str, tuple[float, float]] = {}
        self._pending_t: int | None = None
        self._t_det = 0.0
        self._events: list[Event] = []
        self.late_scans = 0
        self._closed = False
        self._no_return: dict[str, Any] | None = None

    def feed(self, scan: LaserScan) -> list[TrackState]:
        """Take one scan. Returns the states of the step this scan completed (the scans of an earlier time
        stamp), or ``[]``.

        Raises
        ------
        ConfigError
            The scan's ``sensor`` is not one of the scanners, or the tracker was closed.
        """
        if self._closed:
            raise ConfigError("OnlineLaserTracker: closed; make a new one to track again")
        if scan.sensor not in self.poses:  # before stepping: the step's states are not lost with the error
            raise ConfigError(f"laser {scan.sensor!r}: not one of the scanners ({', '.join(sorted(self.poses))})")
        out: list[TrackState] = []
        pending = self._pending_t
        if pending is not None and scan.t_ns > pending:
            out = self._step(pending)
            pending = None
        elif pending is not None and scan.t_ns < pending:
            self.late_scans += 1
            if self.late_scans == 1:
                log.warning("laser %s: a scan arrived %.1f ms older than the step in progress; late scans update "
                            "their scanner and join the next step (counted in late_scans)", scan.sensor,
                            (pending - scan.t_ns) / 1e6)
        t0 = time.perf_counter()
        if self._no_return is not None and scan.sensor in self.poses and scan.sensor not in self._geometries:
            from ..laser.detector import learn_no_return

            learn_no_return(self.detector, scan, self._no_return)
        self.detector.update(scan)
        self._t_det += time.perf_counter() - t0
        self._geometries[scan.sensor] = (scan.angle_min_rad, scan.angle_increment_rad)
        self._pending_t = max(scan.t_ns, pending) if pending is not None else scan.t_ns
        return out

    def take_events(self) -> list[Event]:
        """The events (births, deaths, situations) since the last call."""
        out, self._events = self._events, []
        return out

    def close(self) -> list[TrackState]:
        """End of the run: the states of the last step; the events still held back go to :meth:`take_events`."""
        if self._closed:
            return []
        out = self._step(self._pending_t) if self._pending_t is not None else []
        self._pending_t = None
        self._events.extend(self.tracker.finish())
        self._closed = True
        return out

    def _step(self, t: int) -> list[TrackState]:
        from .tracker import area_from_backgrounds

        t0 = time.perf_counter()
        dets = self.detector.detect(t)
        t1 = time.perf_counter()
        if self._auto_area and dets:
            polygon = area_from_backgrounds(self.detector, self._geometries, self.poses)
            if polygon is not None:
                self.tracker.area_m = polygon
                self._auto_area = False
        t2 = time.perf_counter()
        new = self.tracker.step(t, dets)
        states = self._classifier.update(t, new, dets) if self._classifier is not None else new
        t3 = time.perf_counter()
        self._events.extend(self.tracker.events)
        if self._timings is not None:
            self._timings.setdefault("detect_s", []).append(self._t_det + (t1 - t0))
            self._timings.setdefault("track_s", []).append(t3 - t2)
            self._timings.setdefault("t_ns", []).append(t)
        self._t_det = 0.0
        self._pending_t = None
        return states


def kalman_keys() -> set[str]:
    """The ``[tracking]`` keys the CV Kalman baseline (``--tracker kalman``) takes."""
    from .baseline import CVKalmanTracker

    return set(inspect.signature(CVKalmanTracker).parameters) - {"area_m", "ids"}


def make_tracker(tracker: str, params: Any, area_m: Any, rng: np.random.Generator | int | None) -> Any:
    """:class:`~fusiontrack.tracking.LaserPeopleTracker` (``"pf"``) or the CV Kalman baseline (``"kalman"``)
    over ``area_m`` (``"auto"``: none yet; the caller sets it from the backgrounds)."""
    from .baseline import CVKalmanTracker
    from .tracker import LaserPeopleTracker

    if tracker not in ("pf", "kalman"):
        raise ConfigError(f"tracker: expected 'pf' or 'kalman', got {tracker!r}")
    if isinstance(area_m, str) and area_m != "auto":
        raise ConfigError(f"area_m: expected 'auto', None, a rectangle or a polygon, got {area_m!r}")
    area = None if isinstance(area_m, str) else area_m
    if tracker == "pf":
        return LaserPeopleTracker(params, area_m=area, rng=rng)
    kw = dict(params or {})
    allowed = kalman_keys()
    unknown = sorted(set(kw) - allowed)
    if unknown:  # e.g. a pipeline file's [tracking] table written for the particle filter
        raise ConfigError(f"unknown CV Kalman parameter(s) {unknown} (the particle filter's?); the Kalman baseline "
                          f"takes {sorted(allowed)}")
    return CVKalmanTracker(**{"area_m": area, **kw})
