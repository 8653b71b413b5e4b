"""Plan generators: who walks or drives where and when in each built-in scenario.

Every generator takes the world, the run's ``duration_s`` and an explicit ``rng`` and returns
``(pedestrian_plans, vehicle_plans)`` (:data:`Plans`), ids counted up from ``first_id``;
``agents.Population(world, *plans, rng)`` executes them.
People enter and leave at the doors of the world (``worlds.doors``); their heights are 1.55-1.95 m,
speeds 0.8-1.6 m/s, stride 0.75 x height and walking period stride / speed (ALGORITHMS.md B8).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np

from fusiontrack.errors import ConfigError
from fusiontrack.sim.model import KIND_BICYCLE, KIND_CAR, Appearance, PedestrianPlan, StaticWorld, VehiclePlan
from fusiontrack.sim.worlds import clearance, corridor_nodes, doors

PALETTE_BGR = ((40, 40, 200), (200, 60, 30), (40, 160, 40), (40, 210, 230), (30, 130, 240), (150, 50, 130),
               (210, 200, 40), (190, 60, 220), (235, 235, 235), (30, 30, 30), (128, 128, 128), (40, 70, 120),
               (100, 30, 20), (40, 120, 120), (180, 150, 250), (120, 120, 20), (170, 210, 230), (30, 20, 110))
"""Clothing colours (BGR): red, blue, green, yellow, orange, purple, cyan, magenta, white, black, grey,
brown, navy, olive, pink, teal, beige, maroon."""
PAINT_BGR = ((230, 230, 230), (25, 25, 25), (150, 150, 150), (40, 40, 180), (150, 80, 30), (190, 190, 200),
             (40, 90, 40))
GROUP_SPACING_M = 0.75
Plans = tuple[list[PedestrianPlan], list[VehiclePlan]]
"""What every generator returns: ``(pedestrian_plans, vehicle_plans)``."""


def _rng(rng: np.random.Generator | int | None) -> np.random.Generator:
    return np.random.default_rng(rng)


def draw_appearances(n: int, rng: np.random.Generator) -> list[Appearance]:
    """Clothes for ``n`` people: two different palette colours (jittered ±12 per channel) and a pattern,
    no two people with the same colours and pattern."""
    out: list[Appearance] = []
    used: set[tuple[int, int, int]] = set()
    for _ in range(n):
        while True:
            upper, lower = (int(c) for c in rng.choice(len(PALETTE_BGR), 2, replace=False))
            pattern = int(rng.choice(4, p=[0.55, 0.15, 0.15, 0.15]))
            if (upper, lower, pattern) not in used or len(used) > 1000:
                break
        used.add((upper, lower, pattern))
        jitter = rng.integers(-12, 13, (2, 3))
        out.append(Appearance(*(tuple(int(v) for v in np.clip(np.add(PALETTE_BGR[c], jit), 0, 255))
                                for c, jit in ((upper, jitter[0]), (lower, jitter[1]))), pattern))
    return out


def draw_lookalike(look: Appearance, rng: np.random.Generator) -> Appearance:
    """Clothes nearly identical to ``look``: the same pattern, each colour channel within ±4."""
    jitter = rng.integers(-4, 5, (2, 3))
    return Appearance(*(tuple(int(v) for v in np.clip(np.add(c, j), 0, 255))
                        for c, j in ((look.upper_bgr, jitter[0]), (look.lower_bgr, jitter[1]))), look.pattern)


def _walker(agent_id: int, t_start: float, route: np.ndarray, waits: np.ndarray, rng: np.random.Generator,
            appearance: Appearance, speed: float | None = None, height: float | None = None, **kw) -> PedestrianPlan:
    h = float(np.clip(rng.normal(1.72, 0.09), 1.55, 1.95)) if height is None else height
    v = float(np.clip(rng.normal(1.25, 0.18), 0.8, 1.6)) if speed is None else speed
    stride = 0.75 * h
    return PedestrianPlan(agent_id=agent_id, t_start_s=float(t_start), waypoints_m=np.asarray(route, np.float64),
                          speed_mps=v, waits_s=np.asarray(waits, np.float64), height_m=h, appearance=appearance,
                          stride_m=stride, period_s=stride / v, **kw)


def _draw_speed(rng: np.random.Generator) -> float:
    return float(np.clip(rng.normal(1.25, 0.18), 0.8, 1.6))


def _clearance_map(world: StaticWorld, resolution_m: float = 0.1) -> Callable[[np.ndarray], np.ndarray]:
    """A fast, slightly pessimistic ``clearance(world, points)``: tabulated on a grid once, looked up after."""
    x0, y0, x1, y1 = world.bounds_m
    xs, ys = np.arange(x0, x1 + resolution_m, resolution_m), np.arange(y0, y1 + resolution_m, resolution_m)
    table = clearance(world, np.stack(np.meshgrid(xs, ys, indexing="ij"), -1).reshape(-1, 2)).reshape(xs.size, ys.size)
    table -= resolution_m * 0.71

    def lookup(points: np.ndarray) -> np.ndarray:
        pts = np.asarray(points, np.float64).reshape(-1, 2)
        i = np.minimum(np.maximum(np.rint((pts[:, 0] - x0) / resolution_m).astype(np.int64), 0), xs.size - 1)
        j = np.minimum(np.maximum(np.rint((pts[:, 1] - y0) / resolution_m).astype(np.int64), 0), ys.size - 1)
        return table[i, j]

    return lookup


def _clear(free: Callable[[np.ndarray], np.ndarray], a: np.ndarray, b: np.ndarray, min_m: float,
           skip_ends_m: float = 1.0) -> bool:
    """Whether the straight walk ``a -> b`` keeps ``min_m`` from every obstacle (its ends near doors excepted)."""
    length = float(np.linalg.norm(b - a))
    s = np.arange(0.0, length + 1e-9, 0.25)
    s = s[(s >= min(skip_ends_m, length / 2)) & (s <= max(length - skip_ends_m, length / 2))]
    return bool(s.size == 0 or free(a + np.outer(s / max(length, 1e-9), b - a)).min() >= min_m)


def _interior_point(world: StaticWorld, free: Callable[[np.ndarray], np.ndarray], rng: np.random.Generator,
                    spread: float = 0.22, margin_m: float = 1.5, min_clear_m: float = 1.0) -> np.ndarray:
    """A point drawn around the centre (``spread`` x the area's size), ``min_clear_m`` from obstacles."""
    x0, y0, x1, y1 = world.bounds_m
    centre, size = np.array([x0 + x1, y0 + y1]) / 2, np.array([x1 - x0, y1 - y0])
    for _ in range(20):
        p = np.clip(centre + rng.normal(0, spread, (16, 2)) * size, [x0 + margin_m, y0 + margin_m],
                    [x1 - margin_m, y1 - margin_m])
        ok = np.flatnonzero(free(p) >= min_clear_m)
        if ok.size:
            return p[ok[0]]
    raise ConfigError("world: found no free interior point for a route (too many obstacles?)")


def _door_points(world: StaticWorld) -> tuple[np.ndarray, np.ndarray]:
    dr = doors(world)
    if dr.centre_m.shape[0] < 2:
        raise ConfigError("world: needs at least two doors (gaps in the boundary walls) for people to use")
    return dr.centre_m, dr.inward


def crossing_plans(world: StaticWorld, n_people: int = 3, duration_s: float = 20.0,
                   rng: np.random.Generator | int | None = None, first_id: int = 0) -> Plans:
    """2-4 people enter through doors on different edges and cross the middle at about the same time.

    Each walks from the middle door of an edge through a point near the centre to the door most nearly
    opposite; start times (0-2 s) are chosen so that everybody reaches the centre together.
    """
    if not 2 <= n_people <= 4:
        raise ConfigError(f"n_people: expected 2-4, got {n_people}")
    rng = _rng(rng)
    centres, inward = _door_points(world)
    x0, y0, x1, y1 = world.bounds_m
    mid = np.array([x0 + x1, y0 + y1]) / 2
    edges = [np.flatnonzero(np.all(np.isclose(inward, n), axis=1)) for n in ((0, 1), (-1, 0), (0, -1), (1, 0))]
    off = centres - mid
    along = np.abs(off[:, 0] * inward[:, 1] - off[:, 1] * inward[:, 0])  # distance from the edge's middle
    edges = [e[np.argmin(along[e])] for e in edges if e.size]
    if len(edges) < n_people:
        raise ConfigError(f"n_people: the world has doors on {len(edges)} edges only")
    starts = [edges[i] for i in rng.permutation(len(edges))[:n_people]]
    speeds = [_draw_speed(rng) for _ in starts]
    t_meet = max(np.linalg.norm(centres[s] - mid) / v for s, v in zip(starts, speeds, strict=True))
    looks = draw_appearances(n_people, rng)
    plans = []
    for k, (s, v) in enumerate(zip(starts, speeds, strict=True)):
        exit_ = int(np.argmin(np.linalg.norm(centres - (2 * mid - centres[s]), axis=1)))
        via = mid + rng.uniform(-0.4, 0.4, 2)
        t0 = max(0.0, t_meet - np.linalg.norm(centres[s] - mid) / v + rng.uniform(0.0, 0.6))
        plans.append(_walker(first_id + k, t0, np.array([centres[s], via, centres[exit_]]), np.zeros(3), rng,
                             looks[k], speed=v))
    return plans, []


def groups_plans(world: StaticWorld, n_groups: int = 2, duration_s: float = 40.0,
                 rng: np.random.Generator | int | None = None, first_id: int = 0,
                 n_singles: int | None = None) -> Plans:
    """Groups of 2-3 whose members come from different doors, meet, walk side by side, then split.

    Members meet at a point on one side of the area (the first to arrive waits for the others), walk
    together to a point on the other side (``group_from_waypoint = 1``, ``group_until_waypoint = 2``)
    and leave by different doors; 1-2 single walkers cross as well.
    """
    if not 1 <= n_groups <= 4:
        raise ConfigError(f"n_groups: expected 1-4, got {n_groups}")
    rng = _rng(rng)
    centres, _ = _door_points(world)
    x0, y0, x1, y1 = world.bounds_m
    w, d = x1 - x0, y1 - y0
    free = _clearance_map(world)
    specs = []
    for g in range(n_groups):
        size = int(rng.integers(2, 4))
        for _ in range(500):
            side = 1 if g % 2 else -1
            mid = np.array([x0 + x1, y0 + y1]) / 2
            meet = mid + np.array([side * rng.uniform(0.15, 0.3) * w, rng.uniform(-0.3, 0.3) * d])
            split = mid + np.array([-side * rng.uniform(0.15, 0.3) * w, rng.uniform(-0.3, 0.3) * d])
            ins = np.argsort(np.linalg.norm(centres - meet, axis=1))[:size]
            outs = [i for i in np.argsort(np.linalg.norm(centres - split, axis=1)) if i not in ins][:size]
            if (len(outs) == size and free(np.array([meet, split])).min() >= 1.2 and _clear(free, meet, split, 1.0)
                    and all(_clear(free, centres[i], meet, 0.6) for i in ins)
                    and all(_clear(free, split, centres[o], 0.6) for o in outs)):
                break
        else:
            raise ConfigError("world: found no obstacle-free meeting and split points for a group")
        specs.append((meet, split, ins, outs))
    n_single = int(rng.integers(1, 3)) if n_singles is None else int(n_singles)
    looks = draw_appearances(sum(len(spec[2]) for spec in specs) + n_single, rng)
    plans: list[PedestrianPlan] = []
    for g, (meet, split, ins, outs) in enumerate(specs):
        speeds = [_draw_speed(rng) for _ in ins]
        t_meet = max(np.linalg.norm(centres[i] - meet) / v for i, v in zip(ins, speeds, strict=True)) + 1.0
        pause = rng.uniform(0.5, 2.0)
        for i, o, v in zip(ins, outs, speeds, strict=True):
            t0 = max(0.0, t_meet - np.linalg.norm(centres[i] - meet) / v + rng.uniform(-0.5, 0.5) + 3.0 * g)
            plans.append(_walker(first_id + len(plans), t0, np.array([centres[i], meet, split, centres[o]]),
                                 np.array([0.0, pause, 0.0, 0.0]), rng, looks[len(plans)], speed=v, group_id=g,
                                 group_from_waypoint=1, group_until_waypoint=2))
    for _ in range(n_single):
        a, b = rng.choice(centres.shape[0], 2, replace=False)
        via = _interior_point(world, free, rng)
        plans.append(_walker(first_id + len(plans), rng.uniform(0, max(duration_s / 3, 1.0)),
                             np.array([centres[a], via, centres[b]]), np.zeros(3), rng, looks[len(plans)]))
    return plans, []


def _route_state(route: np.ndarray, waits: np.ndarray, speed: float, t: float) -> tuple[int, np.ndarray, float] | None:
    """Where a walker following ``route`` from time 0 is at ``t`` (straight lines at ``speed``, waiting
    ``waits``): ``(index of the next waypoint, position, wait left)``, or None once it has finished."""
    clock = 0.0
    for k in range(route.shape[0]):
        if t < clock + waits[k]:
            return k + 1, route[k].copy(), clock + waits[k] - t
        clock += waits[k]
        if k + 1 == route.shape[0]:
            return None
        leg = float(np.linalg.norm(route[k + 1] - route[k])) / speed
        if t < clock + leg:
            return k + 1, route[k] + (t - clock) / leg * (route[k + 1] - route[k]), 0.0
        clock += leg
    return None


def _route_time(route: np.ndarray, waits: np.ndarray, speed: float) -> float:
    return float(np.linalg.norm(np.diff(route, axis=0), axis=1).sum() / speed + waits.sum())


def crowd_plans(world: StaticWorld, mean_present: float = 10.0, duration_s: float = 60.0,
                rng: np.random.Generator | int | None = None, stop_probability: float = 0.2,
                group_fraction: float = 0.3, lookalike_pairs: int = 1, first_id: int = 0,
                interacting_pairs: float = 2.0) -> Plans:
    """A stationary stream of walkers: ~``mean_present`` people and ~``interacting_pairs`` pairs closer
    than 1.5 m per frame, with groups and stop-and-go (seed 001: 10.18 targets, 2.17 interactions).

    Arrivals (single walkers or groups of 2-3 entering together) form a Poisson stream at the doors; the
    stream starts well before t = 0 and whoever is still on their way at t = 0 starts there, inside the
    area, so the count is stationary from the first frame. Routes go through 1-3 interior waypoints drawn
    around the centre to another door; ``stop_probability`` of the walkers (or groups) stand 2-8 s at one
    of them; half of the groups split at their last interior waypoint to different doors. The stream's
    rate (Little's law) and the spread of the waypoints (the tighter, the more close passes) are tuned
    over a few draws on the walkers' nominal tracks (straight lines at their speed) until both means
    are within ~10 % of the targets, as far as the area allows (a 16 x 12 m room with 10 people gives
    2.5-3.5 pairs however wide the routes spread; 20 x 15 m gives ~2). ``lookalike_pairs`` pairs of
    people whose visits overlap most dress nearly identically and are of nearly the same height.
    """
    for name, value, ok, expected in (("mean_present", mean_present, mean_present > 0, "> 0"),
                                      ("duration_s", duration_s, duration_s > 0, "> 0"),
                                      ("interacting_pairs", interacting_pairs, interacting_pairs >= 0, ">= 0"),
                                      ("stop_probability", stop_probability, 0 <= stop_probability <= 1, "in [0, 1]"),
                                      ("group_fraction", group_fraction, 0 <= group_fraction <= 1, "in [0, 1]")):
        if not ok:  # (each named alone: the message must not blame a valid one)
            raise ConfigError(f"{name}: expected {expected}, got {value}")
    rng = _rng(rng)
    free = _clearance_map(world)
    spread, rate, best, ratios = 0.3, None, None, []
    for attempt in range(12):
        walkers, rate = _crowd_stream(world, free, rng, mean_present, duration_s, rate, spread, stop_probability,
                                      group_fraction)
        present, pairs = _nominal_stats(walkers, duration_s)
        # simulated walkers avoid each other: ~0.75 of the nominal close pairs stay closer than 1.5 m
        pairs_error = abs(0.75 * pairs / max(interacting_pairs, 0.1) - 1)
        score = 10 * max(abs(present / mean_present - 1) - 0.06, 0.0) + pairs_error  # the count comes first
        if best is None or score < best[0]:
            best = (score, walkers)
        if score < 0.15 or (attempt >= 5 and best[0] < 0.6):  # good, or as good as this area allows
            break
        ratios.append(present / rate)  # Little's law, averaged over the draws: people present per arrival rate
        rate = mean_present / float(np.mean(ratios))
        density = (0.75 * pairs / max(present, 1.0) ** 2) / max(interacting_pairs / mean_present**2, 1e-6)
        spread = float(np.clip(spread * max(density, 0.2) ** 0.5, 0.1, 0.8))
    plans = sorted((p for p, _ in best[1]), key=lambda p: p.t_start_s)
    for i, j in _overlapping_pairs(plans, lookalike_pairs, rng):  # seed 001's hard case: two alike people
        height = float(np.clip(plans[i].height_m + rng.uniform(-0.03, 0.03), 1.55, 1.95))
        plans[j] = replace(plans[j], appearance=draw_lookalike(plans[i].appearance, rng), height_m=height,
                           stride_m=0.75 * height, period_s=0.75 * height / plans[j].speed_mps)
    return [replace(p, agent_id=first_id + n) for n, p in enumerate(plans)], []


def _crowd_stream(world: StaticWorld, free: Callable[[np.ndarray], np.ndarray], rng: np.random.Generator,
                  mean_present: float, duration_s: float, rate: float | None, spread: float, stop_probability: float,
                  group_fraction: float) -> tuple[list[tuple[PedestrianPlan, float]], float]:
    """One draw of the crowd: ``[(plan, nominal speed)]`` and the arrival rate of people used (1/s)."""
    centres, inward = _door_points(world)

    def draw_route() -> tuple[np.ndarray, np.ndarray, int, int]:
        """Door, 1-3 interior points, another door; each leg clear of obstacles by 0.8 m."""
        for _ in range(100):
            a = int(rng.integers(centres.shape[0]))
            route = [centres[a]]
            for _ in range(int(rng.integers(1, 4))):
                for _ in range(20):
                    q = _interior_point(world, free, rng, spread)
                    if _clear(free, route[-1], q, 0.8):
                        route.append(q)
                        break
            exit_ = next((int(b) for b in rng.permutation(centres.shape[0])
                          if b != a and _clear(free, route[-1], centres[b], 0.8)), None)
            if len(route) > 1 and exit_ is not None:
                route.append(centres[exit_])
                waits = np.zeros(len(route))
                if rng.random() < stop_probability:
                    waits[rng.integers(1, len(route) - 1)] = rng.uniform(2.0, 8.0)
                return np.array(route), waits, a, exit_
        raise ConfigError("world: found no obstacle-free routes between its doors")

    p_group = group_fraction / (2.5 - 1.5 * group_fraction)  # groups of 2 or 3: fraction of people in groups
    if rate is None:  # Little's law on the mean duration of a route
        rate = mean_present / np.mean([_route_time(*draw_route()[:2], 1.25) for _ in range(30)])
    walkers: list[tuple[PedestrianPlan, float]] = []
    x0, y0, x1, y1 = world.bounds_m
    t, group_id = -(3 * np.hypot(x1 - x0, y1 - y0) / 0.8 + 8.0), 0  # warm-up longer than (nearly) any visit
    while True:
        t += rng.exponential((1 + 1.5 * p_group) / rate)
        if t >= duration_s:
            return walkers, rate
        size = int(rng.integers(2, 4)) if rng.random() < p_group else 1
        route, waits, a, b = draw_route()
        speeds = [_draw_speed(rng) for _ in range(size)]
        v_nominal = min(speeds)
        state = (1, route[0], waits[0]) if t >= 0 else _route_state(route, waits, v_nominal, -t)
        if state is None:
            continue
        k, here, wait_left = state
        split = size > 1 and rng.random() < 0.5
        others = np.delete(np.arange(centres.shape[0]), [a, b])
        exits = [b, *rng.choice(others, size - 1, replace=size - 1 > others.size)] if split else [b] * size
        door_side = _left_of(inward[a])
        looks = draw_appearances(size, rng)
        for m in range(size):
            offset = (m - (size - 1) / 2) * GROUP_SPACING_M
            mine = route.copy()
            mine[0] += offset * door_side
            mine[-1] = centres[exits[m]] + (0.0 if split else offset) * _left_of(inward[exits[m]])
            start = here + offset * _left_of(mine[k] - here) if t < 0 else mine[0]
            until = route.shape[0] - 1 - k if split else -1  # the last interior waypoint, renumbered
            group = dict(group_id=group_id, group_from_waypoint=0, group_until_waypoint=until) \
                if size > 1 and until != 0 else {}
            plan = _walker(0, max(t, 0.0), np.vstack([start, mine[k:]]), np.concatenate([[wait_left], waits[k:]]),
                           rng, looks[m], speed=speeds[m], **group)
            walkers.append((plan, v_nominal))
        group_id += int(size > 1)


def _nominal_stats(walkers: list[tuple[PedestrianPlan, float]], duration_s: float) -> tuple[float, float]:
    """Mean count of people present and of pairs closer than 1.5 m over ``[0, duration_s]`` (2 Hz), on the
    nominal tracks: straight lines between waypoints at the nominal speed, waits included."""
    times = np.arange(0.0, duration_s, 0.5)
    tracks = np.full((times.size, len(walkers), 2), np.nan)
    for n, (p, speed) in enumerate(walkers):
        legs = np.linalg.norm(np.diff(p.waypoints_m, axis=0), axis=1) / speed
        arrive = p.t_start_s + np.concatenate([[0.0], np.cumsum(legs + p.waits_s[:-1])])
        knots = np.ravel(np.column_stack([arrive, arrive + p.waits_s]))
        inside = (times >= knots[0]) & (times <= knots[-1])
        for axis in range(2):
            tracks[inside, n, axis] = np.interp(times[inside], knots, np.repeat(p.waypoints_m[:, axis], 2))
    present = ~np.isnan(tracks[:, :, 0])
    pairs = 0
    for k in range(times.size):
        pts = tracks[k, present[k]]
        d = np.hypot(*(pts[:, None, :] - pts[None, :, :]).transpose(2, 0, 1))
        pairs += int((d[np.triu_indices(pts.shape[0], 1)] < 1.5).sum())
    return float(present.sum(axis=1).mean()), pairs / max(times.size, 1)


def _left_of(direction: np.ndarray) -> np.ndarray:
    u = direction / max(float(np.linalg.norm(direction)), 1e-9)
    return np.array([-u[1], u[0]])


def _overlapping_pairs(plans: list[PedestrianPlan], n_pairs: int, rng: np.random.Generator) -> list[tuple[int, int]]:
    """Pairs of walkers (not of one group) whose nominal visits overlap longest."""
    spans = np.array([[p.t_start_s, p.t_start_s + _route_time(p.waypoints_m, p.waits_s, p.speed_mps)] for p in plans])
    pairs: list[tuple[int, int]] = []
    used: set[int] = set()
    for _ in range(n_pairs):
        best, best_overlap = None, -np.inf
        for i in rng.permutation(len(plans))[: min(len(plans), 30)]:
            for j in range(len(plans)):
                same_group = plans[i].group_id >= 0 and plans[i].group_id == plans[j].group_id
                if i == j or i in used or j in used or same_group:
                    continue
                overlap = min(spans[i, 1], spans[j, 1]) - max(spans[i, 0], spans[j, 0])
                if overlap > best_overlap:
                    best, best_overlap = (int(i), int(j)), overlap
        if best is None:
            break
        pairs.append(best)
        used.update(best)
    return pairs


def corridor_plans(world: StaticWorld, duration_s: float = 200.0, rng: np.random.Generator | int | None = None,
                   phone: str = "phone", n_passers: int = 3, still_s: float = 12.0,
                   first_id: int = 0) -> Plans:
    """Seed 002: one person with a phone walks figure-eights round a :func:`worlds.corridor_loop` for the whole run.

    The subject (``agent_id = first_id``, ``phone`` set) stands still ``still_s`` at the bottom of the
    middle corridor (so the IMU bias can be estimated), then walks at ~1.3 m/s up the middle corridor,
    round the left loop anticlockwise, up the middle again and round the right loop clockwise, and so
    on; ``n_passers`` people walk from one door to another meanwhile.
    """
    rng = _rng(rng)
    nodes = corridor_nodes(world)
    (bl, bm, br), (tl, tm, tr) = nodes
    eight = np.array([tm, tl, bl, bm, tm, tr, br, bm])
    loop_m = float(np.linalg.norm(np.diff(np.vstack([bm, eight]), axis=0), axis=1).sum())
    speed = float(rng.uniform(1.25, 1.35))
    n_loops = int(np.ceil(speed * max(duration_s - still_s, 0.0) / loop_m)) + 1
    route = np.vstack([bm, *([eight] * n_loops)])
    waits = np.zeros(route.shape[0])
    waits[0] = still_s
    looks = draw_appearances(1 + n_passers, rng)
    plans = [_walker(first_id, 0.0, route, waits, rng, looks[0], speed=speed, leave_at_end=False, phone=phone)]
    centres, _ = _door_points(world)
    for k in range(n_passers):
        a, b = rng.choice(centres.shape[0], 2, replace=False)
        row_a, row_b = int(centres[a, 1] > 0), int(centres[b, 1] > 0)
        enter, leave = np.array([centres[a, 0], nodes[row_a, 0, 1]]), np.array([centres[b, 0], nodes[row_b, 0, 1]])
        via = [] if row_a == row_b else [nodes[row_a, 1], nodes[row_b, 1]]
        r = np.array([centres[a], enter, *via, leave, centres[b]])
        plans.append(_walker(first_id + 1 + k, rng.uniform(0, max(duration_s - 40.0, 1.0)), r, np.zeros(len(r)),
                             rng, looks[1 + k]))
    return plans, []


def road_plans(world: StaticWorld, duration_s: float = 120.0, rng: np.random.Generator | int | None = None,
               rate_veh_per_min: float = 10.0, bicycle_fraction: float = 0.2,
               incidents: tuple[str, ...] = ("stop", "leave", "slow"), first_id: int = 0,
               road: int = 0) -> Plans:
    """Seed 003: cars and bicycles on a two-way road, with a vehicle that stops, one that leaves the road
    and one that drives slowly and builds a jam.

    Arrivals are Poisson, ``rate_veh_per_min`` over both directions; bicycles ride in the rightmost lane.
    Incidents (times scale with ``duration_s``, which should be >= 90 s): "stop" (a car in the
    inner lane of the +x direction stops ~20 s near the middle; later cars keep to the other lane),
    "leave" (a car of the -x direction steers onto its right verge and parks there), "slow" (a car in the
    rightmost +x lane drives at 1 m/s for 40-70 s with a platoon of 7 cars behind it: a queue of >= 5).
    """
    unknown = set(incidents) - {"stop", "leave", "slow"}
    if unknown:
        raise ConfigError(f"incidents: unknown {sorted(unknown)}; expected 'stop', 'leave', 'slow'")
    if not 0 <= bicycle_fraction <= 1:
        raise ConfigError(f"bicycle_fraction: expected a value in [0, 1], got {bicycle_fraction}")
    if not rate_veh_per_min >= 0:
        raise ConfigError(f"rate_veh_per_min: expected >= 0, got {rate_veh_per_min}")
    if not 0 <= road < world.roads.shape[0]:
        raise ConfigError(f"road: expected an index of the world's {world.roads.shape[0]} road(s), got {road}"
                          + ("; this world has no road (use world.setting = 'road')" if not world.roads.size else ""))
    rng = _rng(rng)
    x0, y0, x1, y1, width = world.roads[road]
    length = float(np.hypot(x1 - x0, y1 - y0))
    n_lanes = max(1, round(width / (2 * world.lane_width_m)))
    d = float(duration_s)
    stop_start, stop_end = 0.06 * d, 0.06 * d + length * 0.2 / 12 + 6 + min(max(0.18 * d, 12.0), 25.0)
    entries: list[dict] = []
    for direction in (1, -1):
        t = rng.exponential(120 / max(rate_veh_per_min, 1e-9))
        while t < d and rate_veh_per_min > 0:
            bike = rng.random() < bicycle_fraction
            k = 0 if bike else int(rng.integers(n_lanes))
            if "stop" in incidents and direction == 1 and k == 1 and stop_start <= t <= stop_end + 3:
                k = 0  # drivers keep away from the lane of the stopped car
            entries.append(dict(t=t, kind=KIND_BICYCLE if bike else KIND_CAR, lane=k if direction > 0 else -1 - k))
            t += rng.exponential(120 / rate_veh_per_min)
    if "stop" in incidents:
        entries.append(dict(t=stop_start, kind=KIND_CAR, lane=min(1, n_lanes - 1), incident="stop", at=0.2,
                            duration=min(max(0.18 * d, 12.0), 25.0)))
    if "leave" in incidents:
        entries.append(dict(t=0.25 * d, kind=KIND_CAR, lane=-1, incident="leave", at=0.2, duration=d))
    if "slow" in incidents:
        entries.append(dict(t=0.35 * d, kind=KIND_CAR, lane=0, incident="slow", at=0.25,
                            duration=min(max(0.45 * d, 40.0), 70.0)))
        entries += [dict(t=0.35 * d + 2.0 + 2.5 * k, kind=KIND_CAR, lane=0) for k in range(7)]
    entries.sort(key=lambda e: e["t"])
    plans = []
    for n, e in enumerate(entries):
        car = e["kind"] == KIND_CAR
        speed = float(rng.uniform(11.0, 15.0) if car else rng.uniform(4.0, 6.0))
        size = (rng.uniform(4.2, 4.9), rng.uniform(1.7, 1.9), rng.uniform(1.4, 1.6)) if car else \
            (rng.uniform(1.6, 1.8), 0.6, rng.uniform(1.6, 1.8))
        paint = PAINT_BGR[int(rng.integers(len(PAINT_BGR)))]
        look = Appearance(paint, paint) if car else draw_appearances(1, rng)[0]
        incident = e.get("incident", "")
        plans.append(VehiclePlan(
            agent_id=first_id + n, kind=e["kind"], t_start_s=float(e["t"]), road=road, lane=e["lane"],
            speed_mps=speed, length_m=float(size[0]), width_m=float(size[1]), height_m=float(size[2]),
            appearance=look, incident=incident,
            incident_t_s=float(e["t"] + e.get("at", 0.0) * length / speed) if incident else 0.0,
            incident_duration_s=float(e.get("duration", 0.0)), slow_speed_mps=1.0))
    return [], plans


WEARABLE_LAYOUTS = ("face_to_face", "four_corners", "loop")


def wearable_plans(world: StaticWorld, duration_s: float = 20.0, rng: np.random.Generator | int | None = None,
                   layout: str = "face_to_face", phones: tuple[str, ...] = ("phone_a", "phone_b"),
                   still_s: float = 6.0, stagger_s: float = 1.5, first_id: int = 0) -> Plans:
    """Seed 002's second and third experiments: phone carriers in a room, each standing still first (C1).

    Person ``k`` (``agent_id = first_id + k``) carries ``phones[k]``; everybody stands ``still_s`` (plus a
    stagger: the k-th to leave waits ``k x stagger_s`` longer, ±0.3 s, in a random order) where they start,
    then walks, and stays at the end of their route.

    * ``"face_to_face"`` (2 people, P002 Fig. 11): they start on a line across the room at ``x = ±0.32 x``
      the room's width, 0.4 m either side of the middle line, walk towards each other past the middle to
      ``∓0.2 x`` the width, turn and walk back to where they started: they meet twice.
    * ``"four_corners"`` (4 people, Figs. 12-13): they start at ``(±0.32 width, ±0.25 depth)`` and walk to
      the diagonally opposite start through points near the middle: many occlusions.
    * ``"loop"`` (1-4 people, Fig. 14): a rectangle of 0.5 x 0.45 of the room round its middle, walked
      anticlockwise from evenly spaced starting corners for the whole run.
    """
    if layout not in WEARABLE_LAYOUTS:
        raise ConfigError(f"layout: expected one of {', '.join(WEARABLE_LAYOUTS)}, got {layout!r}")
    phones = tuple(str(p) for p in phones)
    n = len(phones)
    sizes = {"face_to_face": (2, 2), "four_corners": (4, 4), "loop": (1, 4)}[layout]
    if not sizes[0] <= n <= sizes[1] or len(set(phones)) != n or not all(phones):
        raise ConfigError(f"phones: layout {layout!r} needs {sizes[0]}-{sizes[1]} distinct non-empty phone names, "
                          f"got {list(phones)}")
    for name, value in (("still_s", still_s), ("stagger_s", stagger_s)):
        if not value >= 0:
            raise ConfigError(f"{name}: expected a value >= 0, got {value}")
    rng = _rng(rng)
    x0, y0, x1, y1 = world.bounds_m
    mid = np.array([x0 + x1, y0 + y1]) / 2
    w, d = x1 - x0, y1 - y0
    if layout == "face_to_face":
        a, b, off = 0.32 * w, 0.2 * w, 0.4
        routes = [np.array([[-a, off], [b, off], [-a, off]]), np.array([[a, -off], [-b, -off], [a, -off]])]
        turn = 0.5
    elif layout == "four_corners":
        sx, sy = np.array([-1, 1, 1, -1]), np.array([-1, 1, -1, 1])
        routes = [np.array([[s * 0.32 * w, t * 0.25 * d], [-s * 0.05 * w, t * 0.04 * d],
                            [-s * 0.32 * w, -t * 0.25 * d]]) for s, t in zip(sx, sy, strict=True)]
        turn = 0.0
    else:
        hx, hy = 0.25 * w, 0.225 * d
        corners = np.array([[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]])
        loop_m = 2 * (2 * hx + 2 * hy)
        laps = int(np.ceil(1.6 * max(duration_s, 1.0) / loop_m)) + 1
        routes = []
        for k in range(n):
            start = (k * 4) // n
            order = np.roll(corners, -start, axis=0)
            routes.append(np.vstack([order] * laps + [order[:1]]))
        turn = 0.0
    order = rng.permutation(n)
    looks = draw_appearances(n, rng)
    plans = []
    for k in range(n):
        route = routes[k] + mid
        waits = np.zeros(route.shape[0])
        waits[0] = still_s + stagger_s * int(np.flatnonzero(order == k)[0]) + rng.uniform(-0.3, 0.3) * (stagger_s > 0)
        if layout == "face_to_face":
            waits[1] = turn
        plans.append(_walker(first_id + k, 0.0, route, waits, rng, looks[k],
                             speed=float(np.clip(_draw_speed(rng), 0.95, 1.45)), leave_at_end=False,
                             phone=phones[k]))
    return plans, []
