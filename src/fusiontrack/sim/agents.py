"""Agents in motion: social-force walkers with two feet, IDM vehicles with scripted incidents.

:class:`Population` executes the plans of ``plans.py`` on a fixed internal grid of ``dt_s`` (0.02 s):
the motion does not depend on when sensors ask for it, and :meth:`Population.snapshot` interpolates
between the two grid states around the asked time. Pedestrians follow a vectorised social-force model
(Helbing & Molnár 1995, with the collision-prediction term of Zanlungo et al. 2011 and group slots in
the spirit of Moussaïd et al. 2010); their feet follow the two-feet kinematics of ALGORITHMS.md B8.
Vehicles follow their lane with the Intelligent Driver Model (Treiber et al. 2000) and act out the
incidents of ALGORITHMS.md D8 (stopped vehicle, road leaving, jam), recorded as :class:`Incident`.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from fusiontrack.errors import ConfigError
from fusiontrack.sim.model import (
    KIND_BICYCLE,
    KIND_CAR,
    KIND_PERSON,
    AgentSnapshot,
    Incident,
    PedestrianPlan,
    StaticWorld,
    StepEvent,
    VehiclePlan,
)
from fusiontrack.sim.worlds import obstacles, segment_distances

DT_S = 0.02
FOOT_HALF_WIDTH_M = 0.1  # lateral half-distance of the feet, w/2 of B8
PERSON_SIZE_M = (0.30, 0.50)  # length along the heading, width
# social force (accelerations in m/s^2, lengths in m, times in s)
TAU_S, BODY_RADIUS_M, SPEED_CAP = 0.5, 0.25, 1.3
A_PERSON, B_PERSON, ANISOTROPY = 4.0, 0.12, 0.3
A_PREDICT, B_PREDICT, HORIZON_S = 1.2, 0.5, 3.0
A_WALL, B_WALL, A_SLIDE, B_SLIDE, HARD_CLEARANCE_M = 4.0, 0.12, 2.0, 0.6, 0.2
STOP_DECEL, GROUP_SPACING_M, GROUP_GAIN, GROUP_BODY_M = 0.6, 0.5, 1.5, 0.15
TAU_HEADING_S, TAU_AMPLITUDE_S, AMPLITUDE_SPEED = 0.3, 0.25, 0.3
RENDEZVOUS_TIMEOUT_S = 60.0
# IDM per kind (index = KIND_*): max acceleration, comfortable deceleration, time headway, jam distance
IDM_A, IDM_B = np.array([0.0, 1.0, 1.5]), np.array([1.0, 1.5, 2.0])
IDM_T, IDM_S0 = np.array([1.0, 1.0, 1.5]), np.array([1.0, 1.0, 2.0])
STOP_BRAKE, LEAVE_BRAKE, LEAVE_LATERAL_MPS = 2.5, 2.0, 1.2
JAM_ZONE_M, JAM_COUNT, JAM_SPEED_MPS = 50.0, 5, 10 / 3.6
_INCIDENTS = {"": 0, "stop": 1, "leave": 2, "slow": 3}


def feet_positions(position_m: np.ndarray, heading_rad: np.ndarray, phase_rad: np.ndarray, stride_m: np.ndarray,
                   amplitude: np.ndarray | float = 1.0, half_width_m: float = FOOT_HALF_WIDTH_M) -> np.ndarray:
    """Left and right foot of walkers, ``(n, 2, 2)`` (ALGORITHMS.md B8).

    ``left = p + (d/2) u + w n`` and ``right = p - (d/2) u - w n`` with ``d = -amplitude (S/π) cos φ``,
    ``u`` the heading, ``n`` its left normal and ``w = half_width_m``; ``amplitude`` (0-1) brings the
    feet together as a walker stops.

    Parameters
    ----------
    position_m : (n, 2); heading_rad, phase_rad, stride_m : (n,); amplitude : (n,) or float
    """
    u = np.stack([np.cos(heading_rad), np.sin(heading_rad)], axis=-1)
    nrm = u[:, ::-1] * [-1.0, 1.0]
    half_d = (-0.5 / np.pi) * np.asarray(amplitude) * stride_m * np.cos(phase_rad)
    off = half_d[:, None] * u + half_width_m * nrm
    return np.stack([position_m + off, position_m - off], axis=1)


def social_acceleration(pos: np.ndarray, vel: np.ndarray, v_des: np.ndarray, segments: np.ndarray,
                        radii: np.ndarray, group: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Social-force acceleration of walkers and their clearance from obstacles.

    Terms: relaxation towards the desired velocity; anisotropic exponential repulsion between bodies;
    a collision-prediction term pushing apart pairs that will pass closer than comfort within
    ``HORIZON_S`` (a head-on pair dodges to its right); exponential repulsion from walls, box sides
    and pillars plus a sliding force along an obstacle ahead, so a walker rounds a pillar in its way.

    Parameters
    ----------
    pos, vel, v_des : (n, 2) — m, m/s, m/s
    segments, radii : (m, 2, 2), (m,) — obstacles as segments with a radius (``worlds.obstacles``)
    group : (n,) int, optional — walkers sharing a non-negative id walk together: between them the body
        repulsion keeps only ``GROUP_BODY_M`` apart, so friends walk shoulder to shoulder (~0.5 m)

    Returns
    -------
    acc : (n, 2) m/s^2; clearance_m : (n,) distance to the nearest obstacle surface
    """
    px, py, vx, vy = pos[:, 0], pos[:, 1], vel[:, 0], vel[:, 1]
    speed_des = np.hypot(v_des[:, 0], v_des[:, 1])
    inv_speed = np.where(speed_des > 1e-6, 1.0 / np.maximum(speed_des, 1e-6), 0.0)
    ex, ey = v_des[:, 0] * inv_speed, v_des[:, 1] * inv_speed
    ax, ay = (v_des[:, 0] - vx) / TAU_S, (v_des[:, 1] - vy) / TAU_S
    n = pos.shape[0]
    if n > 1:
        dx, dy = px[:, None] - px[None, :], py[:, None] - py[None, :]  # (i, j): from j to i
        dist = np.maximum(np.sqrt(dx * dx + dy * dy), 1e-6)  # two walkers on one spot feel no push
        np.fill_diagonal(dist, np.inf)
        nx, ny = dx / dist, dy / dist
        # cosine of the angle between i's heading and the direction to j -> weight 1 ahead, ANISOTROPY behind
        weight = ANISOTROPY + (1 - ANISOTROPY) * 0.5 * (1 - nx * ex[:, None] - ny * ey[:, None])
        comfort = np.full(dist.shape, 2 * BODY_RADIUS_M)
        if group is not None:
            comfort[(group[:, None] == group[None, :]) & (group[:, None] >= 0)] = GROUP_BODY_M
        push = A_PERSON * np.exp((comfort - dist) / B_PERSON) * weight
        ax += (push * nx).sum(axis=1)
        ay += (push * ny).sum(axis=1)
        rvx, rvy = vx[:, None] - vx[None, :], vy[:, None] - vy[None, :]
        vv = rvx * rvx + rvy * rvy
        tca = -(dx * rvx + dy * rvy) / np.maximum(vv, 1e-9)  # time of closest approach
        soon = (tca > 0) & (tca < HORIZON_S) & (vv > 1e-4)
        if soon.any():
            cx = dx + rvx * tca + 0.05 * ey[:, None]  # separation at closest approach, biased to pass on the right
            cy = dy + rvy * tca - 0.05 * ex[:, None]
            dn = np.maximum(np.sqrt(cx * cx + cy * cy), 1e-9)
            speed = np.hypot(vx, vy)
            mag = np.where(soon, A_PREDICT * speed[:, None] / np.maximum(tca, 0.5)
                           * np.exp(-np.maximum(dn - 2 * BODY_RADIUS_M, 0) / B_PREDICT) * weight / dn, 0.0)
            ax += (mag * cx).sum(axis=1)
            ay += (mag * cy).sum(axis=1)
    clearance = np.full(n, np.inf)
    if segments.shape[0]:
        dist, nrm = segment_distances(pos, segments)
        dist -= radii
        clearance = dist.min(axis=1)
        nx, ny = nrm[..., 0], nrm[..., 1]
        repel = A_WALL * np.exp((BODY_RADIUS_M - dist) / B_WALL)
        # sliding along an obstacle that lies ahead: round a pillar or along a wall on the side of the goal,
        # along a box side (< 2.5 m) towards its nearer end (a goal straight behind a flat face would leave
        # the walker undecided)
        ahead = np.clip(-(nx * ex[:, None] + ny * ey[:, None]), 0.0, 1.0)
        slide = A_SLIDE * np.exp((BODY_RADIUS_M - dist) / B_SLIDE) * ahead
        seg = segments[:, 1] - segments[:, 0]
        length = np.hypot(seg[:, 0], seg[:, 1])
        ux, uy = seg[:, 0] / np.maximum(length, 1e-9), seg[:, 1] / np.maximum(length, 1e-9)
        mid = segments.mean(axis=1)
        beyond = (px[:, None] - dist * nx - mid[:, 0]) * ux + (py[:, None] - dist * ny - mid[:, 1]) * uy
        along_goal = ny * ex[:, None] - nx * ey[:, None]  # heading . (ny, -nx)
        short = (length > 0) & (length < 2.5)
        sx = np.where(short, np.where(beyond >= 0, ux, -ux), np.where(along_goal >= 0, ny, -ny))
        sy = np.where(short, np.where(beyond >= 0, uy, -uy), np.where(along_goal >= 0, -nx, nx))
        ax += (repel * nx + slide * sx).sum(axis=1)
        ay += (repel * ny + slide * sy).sum(axis=1)
    return np.column_stack([ax, ay]), clearance


def _column(plans: tuple) -> Callable[..., np.ndarray]:
    """``col(getter, dtype)``: one attribute of every plan as an array, ``(n,)`` or ``(n, 3)`` for colours."""

    def col(getter: Callable, dtype: type = np.float64) -> np.ndarray:
        values = [getter(p) for p in plans]
        return np.array(values, dtype).reshape((len(plans), -1) if values and np.ndim(values[0]) else (len(plans),))

    return col


def _wrap(a: np.ndarray) -> np.ndarray:
    return (a + np.pi) % (2 * np.pi) - np.pi


class Population:
    """Everybody in a run: executes pedestrian and vehicle plans and records the ground truth.

    Parameters
    ----------
    world : StaticWorld
    pedestrian_plans, vehicle_plans : sequences of plans; agent ids must be unique over both
    rng : numpy Generator, int or None — draws the initial gait phases
    dt_s : float — internal step (at most 0.02 s)
    t0_ns : int — the recording-clock time of the plans' time 0: :meth:`snapshot` takes, and step
        events and incidents carry, ``t0_ns`` + the time since the start; :meth:`advance` takes seconds
        since the start

    Attributes
    ----------
    step_events : list of StepEvent — every heel strike so far, in time order

    Notes
    -----
    - Agents appear at the first internal step at or after their ``t_start_s`` (a walker whose door is
      occupied waits until it is free) and vanish at the step they reach their exit.
    - ``AgentSnapshot.group_ids`` is the plan's group id only while the person walks with the group
      (after the members met, before the split waypoint), else -1.
    - Lanes: ``lane >= 0`` drives in the road's direction, ``lane < 0`` against it, ``0`` and ``-1``
      being the rightmost lanes; bicycles keep to the right edge of their lane, and a car passes a bicycle
      in the same lane without queueing behind it.
    - Incidents: ``stopped_vehicle`` from the moment the speed reaches 0 until it drives on;
      ``road_leaving`` from the moment the centre crosses the road edge (it stays parked on the verge,
      so the incident lasts to the end of the run); ``jam`` while >= 5 vehicles drive slower than
      10 km/h in the 50 m of its lane behind the slow vehicle.
    """

    def __init__(self, world: StaticWorld, pedestrian_plans: list[PedestrianPlan] | tuple = (),
                 vehicle_plans: list[VehiclePlan] | tuple = (), rng: np.random.Generator | int | None = None,
                 dt_s: float = DT_S, t0_ns: int = 0) -> None:
        if not 0 < dt_s <= DT_S:
            raise ConfigError(f"dt_s: expected a step in (0, {DT_S}] s, got {dt_s}")
        self.world, self.dt_s, self.t0_ns = world, float(dt_s), int(t0_ns)
        self.pedestrian_plans, self.vehicle_plans = tuple(pedestrian_plans), tuple(vehicle_plans)
        ids = [p.agent_id for p in self.pedestrian_plans + self.vehicle_plans]
        if len(set(ids)) != len(ids):
            raise ConfigError("agent_id: every plan needs its own agent id (pedestrians and vehicles together)")
        self._plan_by_id = {p.agent_id: p for p in self.pedestrian_plans + self.vehicle_plans}
        self._k = 0
        self._segments, self._radii = obstacles(world)
        self.step_events: list[StepEvent] = []
        self._drained = 0
        self._closed: list[Incident] = []
        self._open: dict[tuple[str, int], list] = {}
        self._init_pedestrians(np.random.default_rng(rng))
        self._init_vehicles()
        self._save_prev()
        self._spawn(0.0)

    # ------------------------------------------------------------------ public API
    @property
    def t_s(self) -> float:
        """Time of the latest internal state."""
        return self._k * self.dt_s

    def _ns(self, t_s: float) -> int:
        return self.t0_ns + round(t_s * 1e9)

    def plan(self, agent_id: int) -> PedestrianPlan | VehiclePlan:
        """The plan of one agent (height, stride, appearance, phone, incident, ...)."""
        return self._plan_by_id[agent_id]

    def advance(self, t_s: float) -> None:
        """Move everybody forward in internal steps until the internal time is at or past ``t_s``."""
        n = math.ceil(t_s / self.dt_s - 1e-6)
        while self._k < n:
            self._step()

    def drain_step_events(self, until_ns: int | None = None) -> list[StepEvent]:
        """Heel strikes not returned before, up to ``until_ns`` (all when None)."""
        end = len(self.step_events)
        if until_ns is not None:
            while end > self._drained and self.step_events[end - 1].t_ns > until_ns:
                end -= 1
        out = self.step_events[self._drained:end]
        self._drained = end
        return out

    @property
    def incidents(self) -> list[Incident]:
        """Incidents so far, by start; one still going on ends at the current internal time."""
        now = self._ns(self.t_s)
        going = [Incident(kind, start, now, tuple(sorted(ids))) for (kind, _), (start, ids) in self._open.items()]
        return sorted(self._closed + going, key=lambda inc: (inc.t_start_ns, inc.kind))

    def snapshot(self, t_ns: int) -> AgentSnapshot:
        """Every present agent at ``t_ns``, interpolated between internal steps (advances if needed).

        Times must not go back further than the previous internal step.
        """
        t = (t_ns - self.t0_ns) * 1e-9
        if t > self.t_s + 1e6:
            raise ConfigError(f"t_ns: {t_ns} is {t:.3g} s after the start; for times on a recording clock, "
                              "create the Population with t0_ns = the clock's time of the start")
        self.advance(t)
        t0, t1 = (self._k - 1) * self.dt_s, self.t_s
        if self._k > 0 and t < t0 - 1e-9:
            raise ConfigError(f"t_ns: {t_ns} is before the previous internal step ({t0:.3f} s); ask in time order")
        w = 0.0 if self._k == 0 else min(max((t - t0) / (t1 - t0), 0.0), 1.0)
        a, b = self._act, self._vact

        def lerp(prev: np.ndarray, cur: np.ndarray) -> np.ndarray:
            return prev + w * (cur - prev)

        pos = lerp(self._ppos[a], self._pos[a])
        head = self._phead[a] + w * _wrap(self._head[a] - self._phead[a])
        phase = lerp(self._pphase[a], self._phase[a])
        feet = feet_positions(pos, head, phase, self._stride[a], lerp(self._pamp[a], self._amp[a]))
        vs, vl = lerp(self._pvs[b], self._vs[b]), lerp(self._pvlat[b], self._vlat[b])
        vv, vlv = lerp(self._pvv[b], self._vv[b]), lerp(self._pvlatv[b], self._vlatv[b])
        vhead = self._pvhead[b] + w * _wrap(self._vhead[b] - self._pvhead[b])
        vpos = self._vorigin[b] + vs[:, None] * self._vdir[b] + vl[:, None] * self._vright[b]
        ids = np.concatenate([self._ids[a], self._vids[b]])
        order = np.argsort(ids, kind="stable")
        grouped = self._grouped(a) & ~self._meet_wait[a]
        return AgentSnapshot(
            t_ns=int(t_ns), ids=ids[order],
            kinds=np.concatenate([np.full(a.size, KIND_PERSON, np.int8), self._vkind[b].astype(np.int8)])[order],
            position_m=np.concatenate([pos, vpos])[order],
            velocity_mps=np.concatenate([lerp(self._pvel[a], self._vel[a]),
                                         vv[:, None] * self._vdir[b] + vlv[:, None] * self._vright[b]])[order],
            heading_rad=_wrap(np.concatenate([head, vhead]))[order],
            feet_m=np.concatenate([feet, np.full((b.size, 2, 2), np.nan)])[order],
            size_m=np.concatenate([self._size[a], self._vsize[b]])[order],
            upper_bgr=np.concatenate([self._upper[a], self._vupper[b]])[order],
            lower_bgr=np.concatenate([self._lower[a], self._vlower[b]])[order],
            pattern=np.concatenate([self._pattern[a], self._vpattern[b]])[order],
            group_ids=np.concatenate([np.where(grouped, self._gid[a], -1), np.full(b.size, -1)])[order],
            gait_phase_rad=np.concatenate([np.mod(phase, 2 * np.pi), np.zeros(b.size)])[order],
        )

    # ------------------------------------------------------------------ set-up
    def _init_pedestrians(self, rng: np.random.Generator) -> None:
        plans = self.pedestrian_plans
        n = len(plans)
        k = max([len(np.asarray(p.waypoints_m).reshape(-1, 2)) for p in plans], default=1)
        self._wp, self._waits = np.zeros((n, k, 2)), np.zeros((n, k))
        self._nwp = np.zeros(n, np.int64)
        for i, p in enumerate(plans):
            wp = np.asarray(p.waypoints_m, np.float64).reshape(-1, 2)
            waits = np.broadcast_to(np.asarray(p.waits_s, np.float64), (wp.shape[0],))
            if wp.shape[0] == 0 or p.speed_mps <= 0 or p.stride_m <= 0:
                raise ConfigError(f"pedestrian plan {p.agent_id}: needs waypoints, speed_mps > 0 and stride_m > 0")
            self._wp[i, : wp.shape[0]], self._wp[i, wp.shape[0]:] = wp, wp[-1]
            self._waits[i, : wp.shape[0]] = waits
            self._nwp[i] = wp.shape[0]
        col = _column(plans)
        self._ids, self._tstart = col(lambda p: p.agent_id, np.int64), col(lambda p: p.t_start_s)
        self._vpref, self._stride = col(lambda p: p.speed_mps), col(lambda p: p.stride_m)
        self._gid, self._gfrom = col(lambda p: p.group_id, np.int64), col(lambda p: p.group_from_waypoint, np.int64)
        self._guntil = col(lambda p: p.group_until_waypoint, np.int64)
        self._guntil = np.where(self._guntil < 0, self._nwp + self._guntil, self._guntil)
        self._leave = col(lambda p: p.leave_at_end, bool)
        self._size = np.column_stack([np.full((n, 2), PERSON_SIZE_M), col(lambda p: p.height_m)])
        self._upper = col(lambda p: p.appearance.upper_bgr, np.uint8).reshape(n, 3)
        self._lower = col(lambda p: p.appearance.lower_bgr, np.uint8).reshape(n, 3)
        self._pattern = col(lambda p: p.appearance.pattern, np.int8)
        kk = np.arange(k)[None, :]
        self._stop_at = ((self._waits > 0) | ((kk == self._nwp[:, None] - 1) & ~self._leave[:, None])
                         | ((kk == self._gfrom[:, None]) & (self._gid[:, None] >= 0) & (kk > 0)))
        self._pos, self._vel, self._vel_s = np.zeros((n, 2)), np.zeros((n, 2)), np.zeros((n, 2))
        self._head, self._amp = np.zeros(n), np.zeros(n)
        self._phase = rng.uniform(0, 2 * np.pi, n)
        self._target = np.ones(n, np.int64)
        self._wait_until = np.full(n, -np.inf)
        self._alive, self._spawned = np.zeros(n, bool), np.zeros(n, bool)
        self._joined, self._arrived, self._meet_wait = np.zeros(n, bool), np.zeros(n, bool), np.zeros(n, bool)
        self._pending = sorted(range(n), key=lambda i: (plans[i].t_start_s, i))
        self._act = np.zeros(0, np.int64)

    def _init_vehicles(self) -> None:
        plans, world = self.vehicle_plans, self.world
        m = len(plans)
        col = _column(plans)
        self._vids, self._vkind = col(lambda p: p.agent_id, np.int64), col(lambda p: p.kind, np.int64)
        if np.any((self._vkind != KIND_CAR) & (self._vkind != KIND_BICYCLE)):
            raise ConfigError("VehiclePlan.kind: expected KIND_CAR or KIND_BICYCLE")
        road_idx, lane = col(lambda p: p.road, np.int64), col(lambda p: p.lane, np.int64)
        if m and (road_idx.max() >= world.roads.shape[0] or road_idx.min() < 0):
            raise ConfigError(f"VehiclePlan.road: the world has {world.roads.shape[0]} road(s)")
        roads = world.roads[road_idx].reshape(m, 5)
        start, end = roads[:, :2], roads[:, 2:4]
        self._vlen_road = np.hypot(*(end - start).T)
        u = (end - start) / np.maximum(self._vlen_road, 1e-9)[:, None]
        forward = lane >= 0
        self._vdir = np.where(forward[:, None], u, -u)
        self._vright = self._vdir[:, ::-1] * [1.0, -1.0]
        self._vorigin = np.where(forward[:, None], start, end)
        self._vhalf, lw = roads[:, 4] / 2, world.lane_width_m
        self._vsize = np.column_stack([col(lambda p: p.length_m), col(lambda p: p.width_m), col(lambda p: p.height_m)])
        k = np.where(forward, lane, -1 - lane)
        bike_shift = np.where(self._vkind == KIND_BICYCLE, lw / 2 - self._vsize[:, 1] / 2 - 0.1, 0.0)
        self._vlat0 = self._vhalf - (k + 0.5) * lw + bike_shift
        self._vkey = road_idx * 64 + lane
        self._vv0, self._vt0 = col(lambda p: p.speed_mps), col(lambda p: p.t_start_s)
        self._vupper = col(lambda p: p.appearance.upper_bgr, np.uint8).reshape(m, 3)
        self._vlower = col(lambda p: p.appearance.lower_bgr, np.uint8).reshape(m, 3)
        self._vpattern = col(lambda p: p.appearance.pattern, np.int8)
        self._vinc = col(lambda p: _INCIDENTS.get(p.incident, -1), np.int64)
        if np.any(self._vinc < 0):
            raise ConfigError(f"VehiclePlan.incident: expected one of {sorted(_INCIDENTS)}")
        self._vs, self._vlat, self._vv, self._vlatv = np.zeros(m), self._vlat0.copy(), np.zeros(m), np.zeros(m)
        self._vhead = np.arctan2(self._vdir[:, 1], self._vdir[:, 0])
        self._v0_eff, self._vbrake, self._vfrozen = self._vv0.copy(), np.zeros(m), np.zeros(m, bool)
        self._vstate = np.zeros(m, np.int64)  # incident progress, see _incident_modes
        self._vstop_end = np.full(m, np.inf)
        self._valive = np.zeros(m, bool)
        self._vpending = sorted(range(m), key=lambda i: (plans[i].t_start_s, i))
        self._vact = np.zeros(0, np.int64)
        self._vinc_idx = np.flatnonzero(self._vinc > 0)

    def _save_prev(self) -> None:
        self._ppos, self._pvel, self._phead = self._pos.copy(), self._vel.copy(), self._head.copy()
        self._pphase, self._pamp = self._phase.copy(), self._amp.copy()
        self._pvs, self._pvlat, self._pvv = self._vs.copy(), self._vlat.copy(), self._vv.copy()
        self._pvlatv, self._pvhead = self._vlatv.copy(), self._vhead.copy()

    # ------------------------------------------------------------------ stepping
    def _step(self) -> None:
        t, dt = self.t_s, self.dt_s
        self._save_prev()
        if self._act.size:
            self._step_pedestrians(t, dt)
        if self._vact.size:
            self._step_vehicles(t, dt)
        self._k += 1
        self._spawn(self.t_s)

    def _spawn(self, t: float) -> None:
        due = 0
        while due < len(self._pending) and self._tstart[self._pending[due]] <= t + 1e-9:
            due += 1
        blocked = []
        for i in self._pending[:due]:
            wp, nwp = self._wp[i], self._nwp[i]
            if t > 0 and self._act.size and np.min(np.hypot(*(self._pos[self._act] - wp[0]).T)) < 0.5:
                blocked.append(i)  # somebody stands in the door: enter a moment later
                continue
            heading = wp[min(1, nwp - 1)] - wp[0]
            self._head[i] = math.atan2(heading[1], heading[0]) if np.any(heading) else 0.0
            self._pos[i], self._alive[i], self._spawned[i], self._target[i] = wp[0], True, True, min(1, nwp - 1)
            walking = nwp > 1 and self._waits[i, 0] <= 0
            self._wait_until[i] = np.inf if nwp == 1 else t + self._waits[i, 0]
            u = np.array([np.cos(self._head[i]), np.sin(self._head[i])])
            self._vel[i] = self._vel_s[i] = self._vpref[i] * u * walking
            self._amp[i] = float(walking)
            self._joined[i] = self._gid[i] >= 0 and self._gfrom[i] == 0
            for arr, prev in ((self._pos, self._ppos), (self._vel, self._pvel), (self._head, self._phead),
                              (self._phase, self._pphase), (self._amp, self._pamp)):
                prev[i] = arr[i]
            self._act = np.flatnonzero(self._alive)
        self._pending[:due] = blocked
        still = []
        for i in self._vpending:
            if self._vt0[i] > t + 1e-9:
                still.append(i)
                continue
            gap, v_lead = self._lane_gap(i)
            kind = self._vkind[i]
            v = self._vv0[i] if gap > 2 * self._vv0[i] * IDM_T[kind] + IDM_S0[kind] else min(self._vv0[i], v_lead)
            if gap < IDM_S0[kind] + 1.0 + 0.8 * v:
                still.append(i)  # the lane entry is blocked: enter later
                continue
            self._valive[i], self._vs[i], self._vv[i] = True, 0.0, v
            self._pvs[i], self._pvv[i], self._pvlat[i] = 0.0, v, self._vlat[i]
            self._vact = np.flatnonzero(self._valive)
        self._vpending = still

    def _lane_gap(self, i: int) -> tuple[float, float]:
        """Free distance from a vehicle entering at ``s = 0`` to the last vehicle ahead in its lane, and its speed."""
        b = self._vact
        same = (self._vkey[b] == self._vkey[i]) & (np.abs(self._vlat[b] - self._vlat0[i])
                                                   < (self._vsize[b, 1] + self._vsize[i, 1]) / 2 + 0.05)
        if not same.any():
            return np.inf, 0.0
        j = b[same][np.argmin(self._vs[b[same]])]
        return float(self._vs[j] - (self._vsize[j, 0] + self._vsize[i, 0]) / 2), float(self._vv[j])

    def _grouped(self, a: np.ndarray) -> np.ndarray:
        last = self._target[a] - 1
        return (self._gid[a] >= 0) & self._joined[a] & (last >= self._gfrom[a]) & (last < self._guntil[a])

    def _step_pedestrians(self, t: float, dt: float) -> None:
        a = self._act
        p, v, tgt = self._pos[a], self._vel[a], self._target[a]
        goal = self._wp[a, tgt]
        g = goal - p
        dist = np.hypot(g[:, 0], g[:, 1])
        e = g / np.maximum(dist, 1e-9)[:, None]
        waiting = self._wait_until[a] > t
        vpref = self._vpref[a]
        v0 = np.where(self._stop_at[a, tgt], np.minimum(vpref, np.sqrt(2 * STOP_DECEL * np.maximum(dist - 0.05, 0))),
                      vpref)
        v_des = v0[:, None] * e
        grouped = self._grouped(a) & ~waiting
        if grouped.any():
            v_des[grouped] = self._group_velocity(self._gid[a][grouped], p[grouped], e[grouped], v0[grouped])
        v_des[waiting] = 0.0
        acc, clear = social_acceleration(p, v, v_des, self._segments, self._radii,
                                         np.where(grouped, self._gid[a], -1))
        v_new = v + acc * dt
        speed = np.hypot(v_new[:, 0], v_new[:, 1])
        v_new *= np.minimum(1.0, SPEED_CAP * vpref / np.maximum(speed, 1e-9))[:, None]
        v_new[waiting] = 0.0
        p_new = p + v_new * dt
        near = np.flatnonzero(clear < HARD_CLEARANCE_M + 0.1)
        if near.size:  # contact: walkers do not enter walls, pillars or benches
            p_new[near], v_new[near] = self._push_out(p_new[near], v_new[near])
        step = p_new - p
        phase_old = self._phase[a]
        phase_new = phase_old + 2 * np.pi * np.hypot(step[:, 0], step[:, 1]) / self._stride[a]
        vel_s = self._vel_s[a] + (v_new - self._vel_s[a]) * (dt / TAU_HEADING_S)
        moving = np.hypot(vel_s[:, 0], vel_s[:, 1]) > 0.05
        head = np.where(moving, np.arctan2(vel_s[:, 1], vel_s[:, 0]), self._head[a])
        amp_target = np.minimum(np.hypot(v_new[:, 0], v_new[:, 1]) / AMPLITUDE_SPEED, 1.0)
        amp = self._amp[a] + (amp_target - self._amp[a]) * (dt / TAU_AMPLITUDE_S)
        amp[amp > 0.995] = 1.0
        self._pos[a], self._vel[a], self._vel_s[a], self._head[a] = p_new, v_new, vel_s, head
        self._phase[a], self._amp[a] = phase_new, amp
        self._emit_steps(a, t, dt, p, p_new, head, phase_old, phase_new, amp)
        self._waypoints(a, t + dt, p_new, tgt, waiting)

    def _group_velocity(self, gid: np.ndarray, p: np.ndarray, e: np.ndarray, v0: np.ndarray) -> np.ndarray:
        """Desired velocities keeping group members side by side, ``(m, 2)``: the group walks at its slowest
        member's pace towards the shared waypoint, each member steered to its slot on the line across."""
        _, inv = np.unique(gid, return_inverse=True)
        cnt = np.bincount(inv).astype(np.float64)
        centre = np.column_stack([np.bincount(inv, p[:, 0]), np.bincount(inv, p[:, 1])]) / cnt[:, None]
        eg = np.column_stack([np.bincount(inv, e[:, 0]), np.bincount(inv, e[:, 1])])
        eg /= np.maximum(np.hypot(eg[:, 0], eg[:, 1]), 1e-9)[:, None]
        vg = np.full(cnt.size, np.inf)
        np.minimum.at(vg, inv, v0)
        ng = eg[:, ::-1] * [-1.0, 1.0]
        lat = np.einsum("nk,nk->n", p - centre[inv], ng[inv])
        order = np.lexsort((lat, inv))
        first = np.searchsorted(inv[order], inv[order])
        rank = np.empty(inv.size)
        rank[order] = np.arange(inv.size) - first
        slot = centre[inv] + ((rank - (cnt[inv] - 1) / 2) * GROUP_SPACING_M)[:, None] * ng[inv]
        return vg[inv, None] * eg[inv] + GROUP_GAIN * (slot - p)

    def _push_out(self, p: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        dist, nrm = segment_distances(p, self._segments)
        depth = np.maximum(HARD_CLEARANCE_M - (dist - self._radii), 0.0)
        p = p + np.einsum("nm,nmk->nk", depth, nrm)
        into = np.minimum(np.einsum("nmk,nk->nm", nrm, v), 0.0) * (depth > 0)
        return p, v - np.einsum("nm,nmk->nk", into, nrm)

    def _emit_steps(self, a: np.ndarray, t: float, dt: float, p: np.ndarray, p_new: np.ndarray, head: np.ndarray,
                    phase_old: np.ndarray, phase_new: np.ndarray, amp: np.ndarray) -> None:
        """Heel strikes: the left at φ ≡ π, the right at φ ≡ 0 (B8); time and place interpolated in the step."""
        two_pi = 2 * np.pi
        left = np.floor((phase_new - np.pi) / two_pi) > np.floor((phase_old - np.pi) / two_pi)
        right = np.floor(phase_new / two_pi) > np.floor(phase_old / two_pi)
        for foot, mask, offset in ((0, left, np.pi), (1, right, 0.0)):
            for j in np.flatnonzero(mask):
                crossing = offset + two_pi * math.floor((phase_new[j] - offset) / two_pi)
                f = (crossing - phase_old[j]) / (phase_new[j] - phase_old[j])
                body = p[j] + f * (p_new[j] - p[j])
                u = np.array([math.cos(head[j]), math.sin(head[j])])
                side = (1 - 2 * foot) * FOOT_HALF_WIDTH_M * np.array([-u[1], u[0]])
                pos = body + amp[j] * self._stride[a[j]] / two_pi * u + side
                self.step_events.append(StepEvent(self._ns(t + f * dt), int(self._ids[a[j]]), foot,
                                                  (float(pos[0]), float(pos[1]))))

    def _waypoints(self, a: np.ndarray, t: float, p: np.ndarray, tgt: np.ndarray, waiting: np.ndarray) -> None:
        """Arrivals: walk on, wait, meet the group, stay, or leave the scene."""
        goal, prev = self._wp[a, tgt], self._wp[a, np.maximum(tgt - 1, 0)]
        g = p - goal
        dist = np.hypot(g[:, 0], g[:, 1])
        last = tgt == self._nwp[a] - 1
        x0, y0, x1, y1 = self.world.bounds_m
        outside = (p[:, 0] < x0) | (p[:, 0] > x1) | (p[:, 1] < y0) | (p[:, 1] > y1)
        radius = np.where(self._grouped(a), 1.2, 0.6)
        passed = (dist < radius) | ((dist < 2.0) & (np.einsum("nk,nk->n", g, goal - prev) > 0))
        leave = last & self._leave[a]
        # a stop is reached on the spot, or nearby when others stand there and block the way
        v = self._vel[a]
        blocked = (dist < 1.2) & (np.einsum("nk,nk->n", v, g) > -0.15 * dist)
        reached = np.where(self._stop_at[a, tgt], (dist < 0.3) | blocked,
                           np.where(leave, (dist < 0.2) | outside, passed))
        reached &= ~waiting
        if not reached.any():
            return
        grouped = self._grouped(a)
        if np.any(reached & grouped):  # a group passes or stops at its shared waypoints together
            key = self._gid[a] * 1024 + tgt
            reached |= grouped & np.isin(key, key[reached & grouped])
        for i in a[reached]:
            k = self._target[i]
            if k == self._nwp[i] - 1:
                if self._leave[i]:
                    self._alive[i] = False
                else:
                    self._wait_until[i], self._vel[i] = np.inf, 0.0
                continue
            self._target[i] = k + 1
            if self._gid[i] >= 0 and k == self._gfrom[i] and k > 0:
                self._vel[i], self._arrived[i], self._joined[i], self._meet_wait[i] = 0.0, True, True, True
                self._wait_until[i] = t + RENDEZVOUS_TIMEOUT_S
                members = np.flatnonzero(self._gid == self._gid[i])
                if np.all(self._arrived[members] | (self._spawned[members] & ~self._alive[members])):
                    self._meet_wait[members] = False
                    self._wait_until[members] = t + self._waits[members, self._gfrom[members]]
            elif self._waits[i, k] > 0:
                self._wait_until[i], self._vel[i] = t + self._waits[i, k], 0.0
        self._act = np.flatnonzero(self._alive)

    def _step_vehicles(self, t: float, dt: float) -> None:
        self._incident_modes(t)
        b = self._vact
        s, lat, v, kind = self._vs[b], self._vlat[b], self._vv[b], self._vkind[b]
        length, width = self._vsize[b, 0], self._vsize[b, 1]
        same = (self._vkey[b][:, None] == self._vkey[b][None, :]) & (
            np.abs(lat[:, None] - lat[None, :]) < (width[:, None] + width[None, :]) / 2 + 0.05)
        ds = s[None, :] - s[:, None]
        gap = np.where(same & (ds > 0), ds - (length[:, None] + length[None, :]) / 2, np.inf)
        lead = np.argmin(gap, axis=1)
        g = gap[np.arange(b.size), lead]
        has = np.isfinite(g)
        a_max, b_cf = IDM_A[kind], IDM_B[kind]
        s_star = IDM_S0[kind] + np.maximum(0.0, v * IDM_T[kind] + v * (v - v[lead]) / (2 * np.sqrt(a_max * b_cf)))
        interaction = np.where(has, -a_max * (s_star / np.maximum(g, 0.1)) ** 2, 0.0)
        free = np.maximum(a_max * (1 - (v / np.maximum(self._v0_eff[b], 0.1)) ** 4), -3.0)
        acc = np.clip(free + interaction, -9.0, a_max)
        brake = self._vbrake[b]
        acc = np.where(brake > 0, np.minimum(acc, -brake), acc)
        v_raw = v + acc * dt
        v_new = np.where(self._vfrozen[b], 0.0, np.maximum(v_raw, 0.0))
        s_new = s + (v + v_new) / 2 * dt
        for _ in range(2):  # never closer than 0.3 m to the vehicle ahead, whatever the model says
            limit = np.where(has, s_new[lead] - (length + length[lead]) / 2 - 0.3, np.inf)
            over = s_new > limit
            s_new[over] = np.maximum(limit[over], s[over])
            v_new[over] = np.minimum(v_new[over], v_new[lead][over])
        lat_v = self._vlatv[b]
        lat_new = lat + lat_v * dt
        heading = np.arctan2(self._vdir[b, 1], self._vdir[b, 0]) - np.arctan2(lat_v, np.maximum(v_new, 1e-9))
        self._vhead[b] = np.where((v_new > 0.1) | (np.abs(lat_v) > 0.05), heading, self._vhead[b])
        self._vs[b], self._vv[b], self._vlat[b] = s_new, v_new, lat_new
        self._incident_events(t, dt, v, v_raw, lat)
        gone = b[s_new > self._vlen_road[b] + length / 2]
        if gone.size:
            self._valive[gone] = False
            self._vact = np.flatnonzero(self._valive)

    def _incident_modes(self, t: float) -> None:
        """Desired speed, braking and lateral speed of the vehicles with a scripted incident."""
        for i in self._vinc_idx:
            if not self._valive[i]:
                continue
            plan, state, kind = self.vehicle_plans[i], self._vstate[i], self._vinc[i]
            started = t >= plan.incident_t_s
            if kind == 1:  # stop: 0 driving, 1 braking, 2 stopped, 3 driving on
                if state == 0 and started:
                    self._vstate[i], self._vbrake[i] = 1, STOP_BRAKE
                elif state == 2 and t >= self._vstop_end[i]:
                    self._vstate[i], self._vfrozen[i], self._vbrake[i] = 3, False, 0.0
                    self._close(("stopped_vehicle", i), t)
            elif kind == 2:  # leave: 0 driving, 1 waiting for a clear verge side, 2 steering off, 3 parked
                if state == 0 and started:
                    self._vstate[i] = state = 1
                if state == 1 and self._right_side_clear(i):
                    self._vstate[i], self._vbrake[i] = 2, LEAVE_BRAKE
                if self._vstate[i] == 2:
                    target = self._vhalf[i] + 0.9 + self._vsize[i, 1] / 2
                    self._vlatv[i] = max(min(LEAVE_LATERAL_MPS, 2.0 * (target - self._vlat[i]), 0.35 * self._vv[i]),
                                         0.0)
            elif kind == 3:  # slow: 0 driving, 1 slow, 2 driving on
                if state == 0 and started:
                    self._vstate[i], self._v0_eff[i] = 1, plan.slow_speed_mps
                elif state == 1 and t >= plan.incident_t_s + plan.incident_duration_s:
                    self._vstate[i], self._v0_eff[i] = 2, self._vv0[i]

    def _right_side_clear(self, i: int) -> bool:
        b = self._vact
        near = ((self._vkey[b] == self._vkey[i]) & (b != i) & (self._vlat[b] > self._vlat[i])
                & (np.abs(self._vs[b] - self._vs[i]) < (self._vsize[b, 0] + self._vsize[i, 0]) / 2 + 3.0))
        return not near.any()

    def _incident_events(self, t: float, dt: float, v_old: np.ndarray, v_raw: np.ndarray, lat_old: np.ndarray) -> None:
        """Open and close the :class:`Incident` records from what the vehicles just did."""
        b = self._vact
        t_new = t + dt
        for i in self._vinc_idx:
            if not self._valive[i]:
                continue
            j = int(np.searchsorted(b, i))
            kind, state = self._vinc[i], self._vstate[i]
            if kind == 1 and state == 1 and self._vv[i] <= 0.0:
                f = v_old[j] / max(v_old[j] - v_raw[j], 1e-12)
                t_stop = t + min(max(f, 0.0), 1.0) * dt
                self._vstate[i], self._vfrozen[i], self._vstop_end[i] = 2, True, t_stop + \
                    self.vehicle_plans[i].incident_duration_s
                self._open[("stopped_vehicle", i)] = [self._ns(t_stop), {int(self._vids[i])}]
            elif kind == 2 and state == 2:
                edge = self._vhalf[i]
                if lat_old[j] <= edge < self._vlat[i]:
                    f = (edge - lat_old[j]) / (self._vlat[i] - lat_old[j])
                    self._open[("road_leaving", i)] = [self._ns(t + f * dt), {int(self._vids[i])}]
                if self._vv[i] <= 0.0:
                    self._vstate[i], self._vfrozen[i], self._vlatv[i] = 3, True, 0.0
            elif kind == 3 and state >= 1:
                queue = b[(self._vkey[b] == self._vkey[i]) & (self._vs[b] < self._vs[i])
                          & (self._vs[b] >= self._vs[i] - JAM_ZONE_M) & (self._vv[b] < JAM_SPEED_MPS)]
                key = ("jam", i)
                if queue.size >= JAM_COUNT:
                    if key not in self._open:
                        self._open[key] = [self._ns(t_new), {int(self._vids[i])}]
                    self._open[key][1].update(int(x) for x in self._vids[queue])
                elif key in self._open:
                    self._close(key, t_new)

    def _close(self, key: tuple[str, int], t: float) -> None:
        start, ids = self._open.pop(key)
        self._closed.append(Incident(key[0], start, self._ns(t), tuple(sorted(ids))))
