"""Built-in static worlds: a room with doors, pillars and benches; a corridor loop; a two-way road.

Each function returns a :class:`~fusiontrack.sim.model.StaticWorld` centred on the origin. Doors are
gaps in the walls that lie on the edges of ``bounds_m``; :func:`doors` finds them again, so the plan
generators (``plans.py``) need nothing but the world.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from fusiontrack.errors import ConfigError
from fusiontrack.sim.model import StaticWorld, rect_sides

BENCH_SIZE_M = (1.6, 0.45, 0.45)
"""Length, width and height of a bench box."""


class Doors(NamedTuple):
    """Gaps in the boundary walls where people enter and leave.

    Attributes
    ----------
    centre_m : (n, 2) float64 — middle of the gap, on the boundary line
    inward : (n, 2) float64 — unit normal pointing into the area
    width_m : (n,) float64
    """

    centre_m: np.ndarray
    inward: np.ndarray
    width_m: np.ndarray


def _check(value: float, name: str, low: float, high: float = np.inf) -> float:
    value = float(value)
    if not low <= value <= high:
        raise ConfigError(f"{name}: expected a value in [{low}, {high}], got {value}")
    return value


def _edge_walls(start: np.ndarray, end: np.ndarray, gaps: list[tuple[float, float]]) -> list[np.ndarray]:
    """Wall segments along ``start -> end`` leaving out ``gaps``, each ``(centre, width)`` in metres from ``start``."""
    length = float(np.linalg.norm(end - start))
    u = (end - start) / length
    cuts = [0.0]
    for centre, width in sorted(gaps):
        cuts += [centre - width / 2, centre + width / 2]
    cuts.append(length)
    return [np.array([start + a * u, start + b * u]) for a, b in zip(cuts[::2], cuts[1::2], strict=True) if b > a]


def _box_walls(x0: float, y0: float, x1: float, y1: float) -> list[np.ndarray]:
    c = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])
    return [np.array([c[i], c[(i + 1) % 4]]) for i in range(4)]


def room(width_m: float = 16.0, depth_m: float = 12.0, rng: np.random.Generator | int | None = None,
         n_pillars: int | None = None) -> StaticWorld:
    """A hall ``width_m`` x ``depth_m`` with eight doors, 2-4 pillars and two benches.

    Doors: the middle of every edge (2.0 m wide) and two more on each x edge at ``x = ±0.3 width``
    (1.6 m). Pillars stand in the four quadrants off the door-to-door lines; benches stand along the
    left and right walls, away from the doors.

    Parameters
    ----------
    width_m, depth_m : float
        Size along x and y (at least 8 x 6 m).
    rng : numpy Generator, int or None
        Draws the pillar count, positions and radii, bench positions and the floor texture seed.
    n_pillars : int or None
        2-4; drawn when None.
    """
    w = _check(width_m, "width_m", 8.0, 500.0)
    d = _check(depth_m, "depth_m", 6.0, 500.0)
    rng = np.random.default_rng(rng)
    hw, hd = w / 2, d / 2
    x_doors = [(hw - 0.3 * w, 1.6), (hw, 2.0), (hw + 0.3 * w, 1.6)]
    corners = np.array([[-hw, -hd], [hw, -hd], [hw, hd], [-hw, hd]])
    walls = (_edge_walls(corners[0], corners[1], x_doors) + _edge_walls(corners[1], corners[2], [(hd, 2.0)])
             + _edge_walls(corners[2], corners[3], x_doors) + _edge_walls(corners[3], corners[0], [(hd, 2.0)]))
    n = int(rng.integers(2, 5)) if n_pillars is None else int(n_pillars)
    if not 0 <= n <= 4:
        raise ConfigError(f"n_pillars: expected 0-4, got {n}")
    slots = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], np.float64) * [0.15 * w, 0.25 * d]
    chosen = slots[np.sort(rng.choice(4, size=n, replace=False))]
    pillars = np.column_stack([chosen + rng.uniform(-0.3, 0.3, (n, 2)), rng.uniform(0.2, 0.35, n)])
    length, width, height = BENCH_SIZE_M
    bench_y = 0.3 * d + rng.uniform(-0.4, 0.4, 2)
    boxes = np.array([[-hw + 0.7, bench_y[0], length, width, np.pi / 2, height],
                      [hw - 0.7, -bench_y[1], length, width, np.pi / 2, height]])
    return StaticWorld(walls=np.array(walls), pillars=pillars, boxes=boxes, bounds_m=np.array([-hw, -hd, hw, hd]),
                       floor_seed=int(rng.integers(2**31)))


def corridor_loop(length_m: float = 40.0, width_m: float = 20.0, corridor_m: float = 2.5,
                  rng: np.random.Generator | int | None = None) -> StaticWorld:
    """A building corridor: a rectangular ring ``length_m`` x ``width_m`` with a cross corridor at ``x = 0``.

    The two inner blocks are walled, so the corridors form two loops sharing the middle corridor (a
    figure-eight route goes round one loop one way and round the other the other way; seed 002).
    Four doors (1.4 m) in the outer wall at ``x = ±length/4`` lead to rooms, for passers-by.

    Parameters
    ----------
    length_m, width_m : float — outer size along x and y.
    corridor_m : float — clear width of every corridor.
    rng : numpy Generator, int or None — draws the floor texture seed.
    """
    c = _check(corridor_m, "corridor_m", 1.2, 10.0)
    lx = _check(length_m, "length_m", 6 * c, 1000.0)
    ly = _check(width_m, "width_m", 4 * c, 1000.0)
    rng = np.random.default_rng(rng)
    hx, hy = lx / 2, ly / 2
    corners = np.array([[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]])
    x_doors = [(hx - lx / 4, 1.4), (hx + lx / 4, 1.4)]
    walls = (_edge_walls(corners[0], corners[1], x_doors) + _edge_walls(corners[1], corners[2], [])
             + _edge_walls(corners[2], corners[3], x_doors) + _edge_walls(corners[3], corners[0], [])
             + _box_walls(-hx + c, -hy + c, -c / 2, hy - c) + _box_walls(c / 2, -hy + c, hx - c, hy - c))
    return StaticWorld(walls=np.array(walls), bounds_m=np.array([-hx, -hy, hx, hy]),
                       floor_seed=int(rng.integers(2**31)))


def corridor_nodes(world: StaticWorld) -> np.ndarray:
    """Corridor crossings of a :func:`corridor_loop` world on the corridor centre lines, ``(2, 3, 2)``.

    ``nodes[row, col]``: row 0 = bottom corridor, 1 = top; col 0 = left end, 1 = middle, 2 = right end.
    """
    x0, y0, x1, y1 = world.bounds_m
    xs = world.walls[:, :, 0].ravel()
    inner = xs[(xs > x0 + 1e-6) & (xs < x1 - 1e-6)]
    c = float(inner.min() - x0) if inner.size else 2.5  # the corridor width: the first inner wall
    cols = np.array([x0 + c / 2, 0.0, x1 - c / 2])
    rows = np.array([y0 + c / 2, y1 - c / 2])
    return np.stack(np.meshgrid(cols, rows), axis=-1)


def road(length_m: float = 120.0, n_lanes: int = 2, lane_width_m: float = 3.5, verge_m: float = 5.0,
         rng: np.random.Generator | int | None = None) -> StaticWorld:
    """A straight two-way road along x with ``n_lanes`` lanes per direction, verges, poles and a roadside wall.

    The road runs from ``x = -length/2`` to ``+length/2`` on ``y = 0``; traffic in the road's direction
    (+x) keeps to the right (``y < 0``). Poles (0.12 m radius) stand 4 m off both road edges every
    ~20 m; a building wall runs along the far verge for half the length.

    Parameters
    ----------
    length_m : float; n_lanes : int (per direction, 1-4); lane_width_m, verge_m : float
    rng : numpy Generator, int or None — draws the pole positions and the floor texture seed.
    """
    length = _check(length_m, "length_m", 30.0, 5000.0)
    lanes = int(_check(n_lanes, "n_lanes", 1, 4))
    lw = _check(lane_width_m, "lane_width_m", 2.0, 5.0)
    verge = _check(verge_m, "verge_m", 4.5, 50.0)
    rng = np.random.default_rng(rng)
    half = lanes * lw
    hx, hy = length / 2, half + verge
    xs = np.arange(-hx + 10.0, hx - 5.0, 20.0)
    xs = np.concatenate([xs + rng.uniform(-2, 2, xs.size), xs + 10.0 + rng.uniform(-2, 2, xs.size)])
    ys = np.concatenate([np.full(xs.size // 2, half + 4.0), np.full(xs.size - xs.size // 2, -half - 4.0)])
    keep = np.abs(xs) < hx - 1.0
    pillars = np.column_stack([xs[keep], ys[keep], np.full(int(keep.sum()), 0.12)])
    walls = np.array([[[-length / 4, hy], [length / 4, hy]]])
    return StaticWorld(walls=walls, pillars=pillars, bounds_m=np.array([-hx, -hy, hx, hy]),
                       roads=np.array([[-hx, 0.0, hx, 0.0, 2 * half]]), lane_width_m=lw,
                       floor_seed=int(rng.integers(2**31)))


def doors(world: StaticWorld, min_width_m: float = 0.8) -> Doors:
    """Gaps at least ``min_width_m`` wide in the walls lying on the edges of ``world.bounds_m``.

    An edge with no wall on it at all counts as one door as wide as the edge.
    """
    x0, y0, x1, y1 = world.bounds_m
    # (fixed axis, fixed value, inward normal) of the bottom, right, top and left edges
    edges = ((1, y0, (0.0, 1.0)), (0, x1, (-1.0, 0.0)), (1, y1, (0.0, -1.0)), (0, x0, (1.0, 0.0)))
    centres, inwards, widths = [], [], []
    for axis, value, inward in edges:
        along = 1 - axis
        lo, hi = world.bounds_m[along], world.bounds_m[along + 2]
        on = np.all(np.abs(world.walls[:, :, axis] - value) < 1e-6, axis=1)
        spans = np.sort(world.walls[on][:, :, along], axis=1)
        spans = spans[np.argsort(spans[:, 0])]
        cursor = lo
        for a, b in [*spans.tolist(), [hi, hi]]:
            if a - cursor >= min_width_m:
                centre = np.empty(2)
                centre[axis], centre[along] = value, (a + cursor) / 2
                centres.append(centre)
                inwards.append(inward)
                widths.append(a - cursor)
            cursor = max(cursor, b)
    return Doors(np.array(centres).reshape(-1, 2), np.array(inwards).reshape(-1, 2), np.array(widths))


def obstacle_segments(world: StaticWorld) -> np.ndarray:
    """Walls and the sides of every box (benches included: people walk round them), ``(n, 2, 2)``."""
    corners = world.box_corners()
    sides = rect_sides(corners).reshape(-1, 2, 2)
    return np.concatenate([world.walls, sides], axis=0)


def segment_distances(points_m: np.ndarray, segments_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distance from points to segments and the unit normal pointing from the segment to the point.

    Parameters
    ----------
    points_m : (n, 2); segments_m : (m, 2, 2) — a zero-length segment is a point

    Returns
    -------
    dist_m : (n, m); normal : (n, m, 2) (zero where a point lies on a segment)
    """
    ax, ay = segments_m[:, 0, 0], segments_m[:, 0, 1]
    bx, by = segments_m[:, 1, 0] - ax, segments_m[:, 1, 1] - ay
    px, py = points_m[:, 0:1] - ax, points_m[:, 1:2] - ay
    t = np.clip((px * bx + py * by) / np.maximum(bx * bx + by * by, 1e-12), 0.0, 1.0)
    dx, dy = px - t * bx, py - t * by
    dist = np.sqrt(dx * dx + dy * dy)
    inv = 1.0 / np.maximum(dist, 1e-9)
    return dist, np.stack([dx * inv, dy * inv], axis=-1)


def obstacles(world: StaticWorld) -> tuple[np.ndarray, np.ndarray]:
    """Every obstacle a walker keeps away from as a segment with a radius: walls and box sides (radius 0)
    and pillars (zero-length segments with the pillar's radius), ``(m, 2, 2)`` and ``(m,)``."""
    pillars = np.repeat(world.pillars[:, None, :2], 2, axis=1)
    segments = np.concatenate([obstacle_segments(world), pillars], axis=0)
    return segments, np.concatenate([np.zeros(segments.shape[0] - pillars.shape[0]), world.pillars[:, 2]])


def clearance(world: StaticWorld, points_m: np.ndarray) -> np.ndarray:
    """Distance from each point to the nearest wall, box side or pillar surface, ``(n,)`` metres."""
    pts = np.asarray(points_m, np.float64).reshape(-1, 2)
    segments, radii = obstacles(world)
    if segments.shape[0] == 0:
        return np.full(pts.shape[0], np.inf)
    return (segment_distances(pts, segments)[0] - radii).min(axis=1)
