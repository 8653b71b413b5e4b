"""Simulated 2D laser scanner: vectorised ray casting against the static world and the agents' legs and vehicles.

A :class:`LaserSim` is built once per scanner from its :class:`~fusiontrack.sim.model.LaserSpec` and the
:class:`~fusiontrack.sim.model.StaticWorld`. The static part of the scene (walls and boxes taller than the
scan plane, pillars) never moves, so its ranges are cast once at construction; each scan only casts the
beams against the dynamic geometry of an :class:`~fusiontrack.sim.model.AgentSnapshot` — every person's
two legs as circles of radius :data:`~fusiontrack.sim.model.LEG_RADIUS_M`, cars as their footprint
rectangle, bicycles as a thin rectangle along their heading (issue 3: "bicycles (thin, line-like laser
profile) and cars (rectangles)") — and keeps, per beam, the nearest positive hit (correct occlusion).

Readings follow sensor_msgs/LaserScan and REP 117: float32 ranges, Gaussian range noise, ``+inf`` for a
beam without a return within ``range_max_m``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from fusiontrack.errors import ConfigError
from fusiontrack.geometry import pose2d_to_matrix
from fusiontrack.sim.model import (
    KIND_BICYCLE,
    KIND_CAR,
    KIND_PERSON,
    LEG_RADIUS_M,
    AgentSnapshot,
    LaserSpec,
    StaticWorld,
    rect_corners,
    rect_sides,
)
from fusiontrack.types import LaserScan

__all__ = ["BICYCLE_LASER_WIDTH_M", "LaserSim", "cast_rays"]

BICYCLE_LASER_WIDTH_M = 0.08
"""Width of the thin rectangle a bicycle shows at laser height (frame and wheels, not the handlebar)."""


def _segment_ranges(origin_m: np.ndarray, dx: np.ndarray, dy: np.ndarray, segments_m: np.ndarray,
                    out: np.ndarray) -> None:
    """Distance along every beam to every segment, ``inf`` where the beam misses; written into ``out``.

    Solves ``o + t d = p0 + u (p1 - p0)`` by 2-D cross products: ``t = (w × e) / (d × e)``,
    ``u = (w × d) / (d × e)`` with ``w = p0 - o``, ``e = p1 - p0``; a hit needs ``0 <= u <= 1`` and ``t > 0``.
    Parallel beams (``d × e = 0``) give NaN or inf and so no hit.

    Parameters
    ----------
    origin_m : (2,); dx, dy : (n_beams,) unit beam directions; segments_m : (n_s, 2, 2);
    out : (n_beams, n_s) float64, overwritten.
    """
    ex = segments_m[:, 1, 0] - segments_m[:, 0, 0]
    ey = segments_m[:, 1, 1] - segments_m[:, 0, 1]
    wx = segments_m[:, 0, 0] - origin_m[0]
    wy = segments_m[:, 0, 1] - origin_m[1]
    w_cross_e = wx * ey - wy * ex  # (n_s,)
    inv_denom = np.multiply.outer(dx, ey)
    inv_denom -= np.multiply.outer(dy, ex)  # d × e
    u = np.multiply.outer(dy, wx)
    u -= np.multiply.outer(dx, wy)  # w × d
    with np.errstate(divide="ignore", invalid="ignore"):
        np.divide(1.0, inv_denom, out=inv_denom)
        u *= inv_denom
        np.multiply(inv_denom, w_cross_e, out=out)
        miss = u < 0.0
        miss |= u > 1.0
        miss |= ~(out > 0.0)  # also NaN
    out[miss] = np.inf


def _circle_ranges(origin_m: np.ndarray, dx: np.ndarray, dy: np.ndarray, circles_m: np.ndarray,
                   out: np.ndarray) -> None:
    """Distance along every beam to every circle, ``inf`` where the beam misses; written into ``out``.

    With ``w = c - o``, ``b = d · w`` and ``q = |w|² - r²``, the hits are ``t = b ∓ sqrt(b² - q)``: the
    nearer root from outside a circle (``q > 0``), the farther one from inside it.

    Parameters
    ----------
    origin_m : (2,); dx, dy : (n_beams,) unit beam directions; circles_m : (n_c, 3) ``(x, y, radius)``;
    out : (n_beams, n_c) float64, overwritten.
    """
    wx = circles_m[:, 0] - origin_m[0]
    wy = circles_m[:, 1] - origin_m[1]
    q = wx * wx + wy * wy - circles_m[:, 2] ** 2  # (n_c,)
    sign = np.where(q > 0.0, -1.0, 1.0)
    np.multiply(dx[:, None], wx, out=out)
    out += np.multiply.outer(dy, wy)  # b
    root = out * out
    root -= q
    with np.errstate(invalid="ignore"):
        np.sqrt(root, out=root)  # NaN where the beam's line misses the circle
        root *= sign
        out += root
        miss = ~(out > 0.0)
    out[miss] = np.inf


def _near(origin_m: np.ndarray, segments_m: np.ndarray, circles_m: np.ndarray,
          reach_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Masks of the segments ``(n_s,)`` and circles ``(n_c,)`` that come within ``reach_m`` of ``origin_m``."""
    p0 = segments_m[:, 0] - origin_m
    e = segments_m[:, 1] - segments_m[:, 0]
    ee = np.einsum("ij,ij->i", e, e)
    with np.errstate(divide="ignore", invalid="ignore"):
        u = np.clip(-np.einsum("ij,ij->i", p0, e) / ee, 0.0, 1.0)
    u = np.where(ee > 0, u, 0.0)
    seg_ok = np.hypot(*(p0 + u[:, None] * e).T) <= reach_m
    circ_ok = np.hypot(circles_m[:, 0] - origin_m[0], circles_m[:, 1] - origin_m[1]) - circles_m[:, 2] <= reach_m
    return seg_ok, circ_ok


def cast_rays(origin_m: Any, directions: Any, segments_m: Any, circles_m: Any) -> tuple[np.ndarray, np.ndarray]:
    """Nearest positive hit of rays from one origin against segments and circles.

    Fully vectorised over ``beams × objects``; the memory used is a few ``(n_beams, n_s + n_c)`` float64
    arrays.

    Parameters
    ----------
    origin_m : (2,) float
        Common start of the rays, metres.
    directions : (n_beams, 2) float
        Unit direction of each ray.
    segments_m : (n_s, 2, 2) float
        Segments ``[[x0, y0], [x1, y1]]``, metres.
    circles_m : (n_c, 3) float
        Circles ``(x, y, radius)``, metres.

    Returns
    -------
    range_m : (n_beams,) float64
        Distance to the first surface along each ray, ``inf`` if none.
    index : (n_beams,) int64
        Which object was hit: ``0 .. n_s - 1`` a segment, ``n_s .. n_s + n_c - 1`` a circle, ``-1`` none.
    """
    origin_m = np.asarray(origin_m, np.float64).reshape(2)
    directions = np.asarray(directions, np.float64).reshape(-1, 2)
    segments_m = np.asarray(segments_m, np.float64).reshape(-1, 2, 2)
    circles_m = np.asarray(circles_m, np.float64).reshape(-1, 3)
    dx, dy = np.ascontiguousarray(directions[:, 0]), np.ascontiguousarray(directions[:, 1])
    return _cast(origin_m, dx, dy, segments_m, circles_m)


def _cast(origin_m: np.ndarray, dx: np.ndarray, dy: np.ndarray, segments_m: np.ndarray,
          circles_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    n_b, n_s, n_c = dx.size, len(segments_m), len(circles_m)
    if n_s + n_c == 0:
        return np.full(n_b, np.inf), np.full(n_b, -1, np.int64)
    t = np.empty((n_b, n_s + n_c))
    if n_s:
        _segment_ranges(origin_m, dx, dy, segments_m, t[:, :n_s])
    if n_c:
        _circle_ranges(origin_m, dx, dy, circles_m, t[:, n_s:])
    index = np.argmin(t, axis=1)
    range_m = np.take_along_axis(t, index[:, None], axis=1)[:, 0]
    return range_m, np.where(np.isfinite(range_m), index, -1)


class LaserSim:
    """One simulated 2D laser scanner in a static world.

    Parameters
    ----------
    spec : LaserSpec
        Pose, field of view, range limits, noise and rate of the scanner.
    world : StaticWorld
        Walls and boxes taller than ``spec.height_m`` and pillars (if taller) are the static background;
        lower boxes (benches under the scan plane) are invisible.

    Attributes
    ----------
    spec : LaserSpec
    angles_rad : (n_beams,) float64
        Beam angles in the sensor frame, ``angle_min_rad + i * angle_increment_rad``.
    directions_world : (n_beams, 2) float64
        Unit beam directions in the world frame (read-only).
    origin_m : (2,) float64
        Sensor position in the world (read-only).
    laser2world : (3, 3) float64
        2-D pose of the sensor, for :func:`fusiontrack.geometry.scan_to_world` (read-only).
    static_segments_m : (n_s, 2, 2) float64
        Static segments the scan plane meets (walls, sides of tall boxes) within reach.
    static_circles_m : (n_c, 3) float64
        Pillars ``(x, y, radius)`` the scan plane meets within reach.
    static_range_m : (n_beams,) float64
        Noise-free range of each beam to the static background, ``inf`` beyond ``range_max_m``.
    """

    def __init__(self, spec: LaserSpec, world: StaticWorld) -> None:
        _validate(spec)
        self.spec = spec
        self.world = world
        self.angles_rad = spec.angle_min_rad + np.arange(spec.n_beams) * spec.angle_increment_rad
        world_angles = spec.yaw_rad + self.angles_rad
        self._dx = np.cos(world_angles)
        self._dy = np.sin(world_angles)
        self.directions_world = np.column_stack([self._dx, self._dy])
        self.origin_m = np.array([spec.x_m, spec.y_m], np.float64)
        self.laser2world = pose2d_to_matrix(spec.x_m, spec.y_m, spec.yaw_rad)
        segments = world.laser_segments(spec.height_m)
        circles = world.pillars if world.pillar_height_m > spec.height_m else np.zeros((0, 3))
        seg_ok, circ_ok = _near(self.origin_m, segments, circles, spec.range_max_m)
        self.static_segments_m = np.ascontiguousarray(segments[seg_ok])
        self.static_circles_m = np.ascontiguousarray(circles[circ_ok])
        static_range, _ = _cast(self.origin_m, self._dx, self._dy, self.static_segments_m, self.static_circles_m)
        static_range[static_range > spec.range_max_m] = np.inf
        self.static_range_m = static_range
        for arr in (self.angles_rad, self.directions_world, self.origin_m, self.laser2world,
                    self.static_segments_m, self.static_circles_m, self.static_range_m):
            arr.setflags(write=False)

    @property
    def n_beams(self) -> int:
        return self.spec.n_beams

    def dynamic_geometry(self, snapshot: AgentSnapshot) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """What the agents of ``snapshot`` show in the scan plane.

        Legs of people (NaN feet skipped); sides of cars (footprint rectangle) and bicycles (rectangle of
        their length and :data:`BICYCLE_LASER_WIDTH_M` along the heading) taller than the scan plane,
        keeping only the sides that face the laser. Objects beyond ``range_max_m`` are left out.

        Returns
        -------
        segments_m : (n_s, 2, 2) float64
        segment_ids : (n_s,) int64 — agent id of each segment
        circles_m : (n_c, 3) float64 — ``(x, y, LEG_RADIUS_M)``
        circle_ids : (n_c,) int64 — agent id of each leg
        """
        kinds = np.asarray(snapshot.kinds)
        ids = np.asarray(snapshot.ids, np.int64)
        feet = np.asarray(snapshot.feet_m, np.float64).reshape(-1, 2, 2)[kinds == KIND_PERSON]
        leg_ids = np.repeat(ids[kinds == KIND_PERSON], 2)
        feet = feet.reshape(-1, 2)
        ok = np.isfinite(feet).all(axis=1)
        circles = np.column_stack([feet[ok], np.full(int(ok.sum()), LEG_RADIUS_M)])
        circle_ids = leg_ids[ok]

        size = np.asarray(snapshot.size_m, np.float64).reshape(-1, 3)
        position = np.asarray(snapshot.position_m, np.float64).reshape(-1, 2)
        heading = np.asarray(snapshot.heading_rad, np.float64).reshape(-1)
        vehicle = ((kinds == KIND_CAR) | (kinds == KIND_BICYCLE)) & (size[:, 2] > self.spec.height_m)
        vehicle &= np.isfinite(position).all(axis=1) & np.isfinite(heading) & np.isfinite(size[:, :2]).all(axis=1)
        width = np.where(kinds[vehicle] == KIND_BICYCLE, BICYCLE_LASER_WIDTH_M, size[vehicle, 1])
        sides = rect_sides(rect_corners(position[vehicle], size[vehicle, 0], width, heading[vehicle]))
        # Back-face culling: a side can be the first hit only if the laser is on its outer side
        # (outward normal of a counter-clockwise side p0 -> p1 is (e_y, -e_x)).
        e = sides[:, :, 1] - sides[:, :, 0]
        to_laser = self.origin_m - sides[:, :, 0]
        facing = to_laser[..., 0] * e[..., 1] - to_laser[..., 1] * e[..., 0] > 0.0  # (n_v, 4)
        segments = sides[facing]
        segment_ids = np.broadcast_to(ids[vehicle][:, None], facing.shape)[facing]

        seg_ok, circ_ok = _near(self.origin_m, segments, circles, self.spec.range_max_m)
        return segments[seg_ok], segment_ids[seg_ok], circles[circ_ok], circle_ids[circ_ok]

    def cast(self, snapshot: AgentSnapshot) -> tuple[np.ndarray, np.ndarray]:
        """Noise-free ranges and which agent each beam hits.

        Returns
        -------
        range_m : (n_beams,) float64
            Distance to the first surface along each beam; ``inf`` without a hit within ``range_max_m``.
        hit_ids : (n_beams,) int64
            Agent id of the surface hit; ``-1`` for the static world or no hit.
        """
        segments, segment_ids, circles, circle_ids = self.dynamic_geometry(snapshot)
        range_m, index = _cast(self.origin_m, self._dx, self._dy, segments, circles)
        hit_ids = np.concatenate([segment_ids, circle_ids, [-1]])[index]  # index -1 -> the appended -1
        static = self.static_range_m <= range_m
        range_m = np.where(static, self.static_range_m, range_m)
        hit_ids[static] = -1
        beyond = range_m > self.spec.range_max_m
        range_m[beyond] = np.inf
        hit_ids[beyond] = -1
        return range_m, hit_ids

    def ranges(self, snapshot: AgentSnapshot, rng: np.random.Generator | int | None) -> np.ndarray:
        """Measured ranges: :meth:`cast` plus Gaussian noise of ``spec.range_noise_m``.

        ``n_beams`` normal numbers are drawn from ``rng`` on every call (hits or not), so the stream of a
        seeded generator does not depend on the scene. Beams without a return read ``+inf`` (REP 117);
        a noisy reading is clipped at 0.

        Returns
        -------
        (n_beams,) float32, metres.
        """
        return self.ranges_and_hits(snapshot, rng)[0]

    def ranges_and_hits(self, snapshot: AgentSnapshot,
                        rng: np.random.Generator | int | None) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`ranges` and the ``hit_ids`` of the same noise-free :meth:`cast` (which agent each beam hit).

        Returns
        -------
        ranges_m : (n_beams,) float32
            As :meth:`ranges` (the same draws from ``rng``).
        hit_ids : (n_beams,) int64
            As :meth:`cast`: agent id, ``-1`` for the static world or no hit.
        """
        rng = np.random.default_rng(rng)
        range_m, hit_ids = self.cast(snapshot)
        noisy = range_m + rng.normal(0.0, self.spec.range_noise_m, self.spec.n_beams)
        np.maximum(noisy, 0.0, out=noisy)
        return noisy.astype(np.float32), hit_ids

    def scan(self, t_ns: int, snapshot: AgentSnapshot, rng: np.random.Generator | int | None,
             stamp_ns: int | None = None) -> LaserScan:
        """One :class:`fusiontrack.types.LaserScan` of ``snapshot`` (taken at true time ``t_ns``).

        Parameters
        ----------
        t_ns : int
            True time of the scan, nanoseconds.
        snapshot : AgentSnapshot
            The agents at that time.
        rng : numpy Generator, seed or None
            Source of the range noise.
        stamp_ns : int, optional
            Header stamp to write instead of ``t_ns`` (clock offset and jitter applied by the caller).

        Returns
        -------
        LaserScan
            ``sensor`` and ``frame_id`` are ``spec.name``; ``scan_time_s = 1 / rate``, ``time_increment_s = 0``
            (no motion distortion is simulated).
        """
        return self.scan_and_hits(t_ns, snapshot, rng, stamp_ns)[0]

    def scan_and_hits(self, t_ns: int, snapshot: AgentSnapshot, rng: np.random.Generator | int | None,
                      stamp_ns: int | None = None) -> tuple[LaserScan, np.ndarray]:
        """:meth:`scan` and, per beam, the agent id it hit (``-1``: static world or nothing; :meth:`cast`)."""
        spec = self.spec
        ranges_m, hit_ids = self.ranges_and_hits(snapshot, rng)
        return LaserScan(
            t_ns=int(t_ns if stamp_ns is None else stamp_ns),
            sensor=spec.name,
            frame_id=spec.name,
            angle_min_rad=spec.angle_min_rad,
            angle_increment_rad=spec.angle_increment_rad,
            range_min_m=spec.range_min_m,
            range_max_m=spec.range_max_m,
            ranges_m=ranges_m,
            time_increment_s=0.0,
            scan_time_s=1.0 / spec.timing.rate_hz,
        ), hit_ids

    def points_world(self, ranges_m: Any) -> np.ndarray:
        """Beam end points in the world, ``(n_beams, 2)`` metres.

        Readings that :meth:`fusiontrack.types.LaserScan.valid_ranges_m` rejects (non-finite,
        ``<= range_min_m`` or ``>= range_max_m``) give NaN rows.
        """
        r = np.asarray(ranges_m, np.float64).reshape(-1)
        if r.size != self.spec.n_beams:
            raise ValueError(f"points_world: ranges_m has {r.size} values, laser {self.spec.name!r} has "
                             f"{self.spec.n_beams} beams")
        with np.errstate(invalid="ignore"):
            bad = ~np.isfinite(r) | (r <= self.spec.range_min_m) | (r >= self.spec.range_max_m)
        r = np.where(bad, np.nan, r)
        return self.origin_m + r[:, None] * self.directions_world


def _validate(spec: LaserSpec) -> None:
    name = f"laser {spec.name!r}"
    pose = (spec.x_m, spec.y_m, spec.yaw_rad, spec.height_m, spec.angle_min_rad, spec.angle_increment_rad)
    if not all(np.isfinite(pose)):
        raise ConfigError(f"{name}: x_m, y_m, yaw_rad, height_m, angle_min_rad and angle_increment_rad must be "
                          f"finite, got {pose}")
    if int(spec.n_beams) != spec.n_beams or spec.n_beams < 1:
        raise ConfigError(f"{name}: n_beams must be a positive integer, got {spec.n_beams}")
    if spec.angle_increment_rad == 0:
        raise ConfigError(f"{name}: angle_increment_rad must not be 0")
    if not 0 <= spec.range_min_m < spec.range_max_m < np.inf:
        raise ConfigError(f"{name}: need 0 <= range_min_m < range_max_m < inf, got range_min_m={spec.range_min_m}, "
                          f"range_max_m={spec.range_max_m}")
    if not 0 <= spec.range_noise_m < np.inf:
        raise ConfigError(f"{name}: range_noise_m must be >= 0, got {spec.range_noise_m}")
    if not 0 < spec.timing.rate_hz < np.inf:
        raise ConfigError(f"{name}: timing.rate_hz must be > 0, got {spec.timing.rate_hz}")
