"""What the simulator's parts exchange: the static world, agent plans and the agents' state at an instant.

Sensors (``laser.py``, ``camera.py``, ``imu.py``) render from a :class:`StaticWorld` and an
:class:`AgentSnapshot`; the agents' motion (``agents.py``) executes :class:`PedestrianPlan` and
:class:`VehiclePlan` records that the scenario generators (``plans.py``) draw from a scenario's
parameters. Everything is metres, seconds, radians, world frame ``(X, Y)`` on the floor, ``Z`` up.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

LEG_RADIUS_M = 0.06
"""Radius of a leg at laser height (issue 3: legs are ~6 cm radius circles)."""

KIND_PERSON, KIND_BICYCLE, KIND_CAR = 0, 1, 2
KIND_NAMES = ("person", "bicycle", "car")
"""``AgentSnapshot.kinds`` codes -> :class:`fusiontrack.types.ObjectClass` values."""

PATTERN_PLAIN, PATTERN_HSTRIPES, PATTERN_VSTRIPES, PATTERN_CHECKS = 0, 1, 2, 3


@dataclass(frozen=True, slots=True, eq=False)
class StaticWorld:
    """Walls, pillars and boxes (benches, kiosks): the laser background, occluders for every sensor.

    Attributes
    ----------
    walls : (n_w, 2, 2) float64
        Segments ``[[x0, y0], [x1, y1]]``, ``wall_height_m`` tall, opaque to lasers and cameras.
    pillars : (n_p, 3) float64
        ``(x, y, radius)`` vertical cylinders, ``pillar_height_m`` tall.
    boxes : (n_b, 6) float64
        ``(cx, cy, length, width, yaw, height)`` boxes standing on the floor (benches are ~0.45 m
        tall, so a laser mounted above them does not see them but a camera does).
    bounds_m : (4,) float64
        ``(x_min, y_min, x_max, y_max)`` of the simulated area; people enter and leave at its edges.
    roads : (n_r, 5) float64
        Straight roads ``(x0, y0, x1, y1, width)``: centre line and total width (``road`` scenario).
    lane_width_m : float
        Width of one lane on the roads.
    floor_seed : int
        Seed of the floor and backdrop texture (rendered by the camera).
    """

    walls: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 2)))
    pillars: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    boxes: np.ndarray = field(default_factory=lambda: np.zeros((0, 6)))
    bounds_m: np.ndarray = field(default_factory=lambda: np.array([-10.0, -10.0, 10.0, 10.0]))
    roads: np.ndarray = field(default_factory=lambda: np.zeros((0, 5)))
    lane_width_m: float = 3.5
    wall_height_m: float = 2.5
    pillar_height_m: float = 3.0
    floor_seed: int = 0

    def __post_init__(self) -> None:
        for name, shape in (("walls", (-1, 2, 2)), ("pillars", (-1, 3)), ("boxes", (-1, 6)), ("roads", (-1, 5))):
            arr = np.asarray(getattr(self, name), np.float64).reshape(shape)
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        bounds = np.asarray(self.bounds_m, np.float64).reshape(4)
        bounds.setflags(write=False)
        object.__setattr__(self, "bounds_m", bounds)

    def box_corners(self) -> np.ndarray:
        """Floor corners of every box, ``(n_b, 4, 2)`` counter-clockwise."""
        return rect_corners(self.boxes[:, :2], self.boxes[:, 2], self.boxes[:, 3], self.boxes[:, 4])

    def laser_segments(self, height_m: float) -> np.ndarray:
        """Every static segment a laser scanning at ``height_m`` hits: walls and the sides of tall boxes,
        ``(n, 2, 2)``."""
        tall = self.boxes[:, 5] > height_m
        corners = self.box_corners()[tall]
        sides = rect_sides(corners).reshape(-1, 2, 2)
        walls = self.walls if self.wall_height_m > height_m else np.zeros((0, 2, 2))
        return np.concatenate([walls, sides], axis=0)


def rect_corners(centre: np.ndarray, length: np.ndarray, width: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """Corners of oriented rectangles, ``(n, 4, 2)`` counter-clockwise from the rear right.

    Parameters
    ----------
    centre : (n, 2); length, width, yaw : (n,) — length along the heading ``yaw``.
    """
    centre = np.asarray(centre, np.float64).reshape(-1, 2)
    n = centre.shape[0]
    hl = np.broadcast_to(np.asarray(length, np.float64), (n,)) / 2
    hw = np.broadcast_to(np.asarray(width, np.float64), (n,)) / 2
    local = np.stack([np.stack([-hl, -hw], 1), np.stack([hl, -hw], 1), np.stack([hl, hw], 1),
                      np.stack([-hl, hw], 1)], axis=1)  # (n, 4, 2)
    c, s = np.cos(yaw), np.sin(yaw)
    rot = np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], axis=-2).reshape(-1, 2, 2)
    return np.einsum("nij,nkj->nki", rot, local) + centre[:, None, :]


def rect_sides(corners_m: np.ndarray) -> np.ndarray:
    """The four sides of polygons given by their corners.

    Parameters
    ----------
    corners_m : (n, 4, 2) float
        Corners in order (as :func:`fusiontrack.sim.model.rect_corners` gives them, counter-clockwise).

    Returns
    -------
    (n, 4, 2, 2) float64
        Side ``k`` of polygon ``i`` runs from corner ``k`` to corner ``k + 1 (mod 4)``.
    """
    corners_m = np.asarray(corners_m, np.float64)
    return np.stack([corners_m, np.roll(corners_m, -1, axis=1)], axis=2)


@dataclass(frozen=True, slots=True, eq=False)
class Appearance:
    """Clothing of a person (BGR colours of the upper and lower body and a pattern) or a vehicle's paint."""

    upper_bgr: tuple[int, int, int]
    lower_bgr: tuple[int, int, int]
    pattern: int = PATTERN_PLAIN


@dataclass(frozen=True, slots=True, eq=False)
class PedestrianPlan:
    """What one person will do: when they appear, where they go, how fast, where they wait.

    Attributes
    ----------
    agent_id : int
        Identity, unique among all agents of a run (vehicles included).
    t_start_s : float
        When the person appears at ``waypoints_m[0]`` (an edge of the area, or inside it at t = 0).
    waypoints_m : (k, 2) float64
        Route; the person walks to each in turn and leaves the simulation at the last one when
        ``leave_at_end`` (it should then be on an edge), else stays there.
    speed_mps : float
        Preferred walking speed (0.8-1.6 m/s).
    waits_s : (k,) float64
        How long to stand still on reaching each waypoint (0 = walk on; stop-and-go).
    height_m : float
    appearance : Appearance
    group_id : int
        People with the same non-negative group id walk together (side by side) between
        ``group_from_waypoint`` and ``group_until_waypoint`` of their routes; -1 = alone.
    stride_m, period_s : float
        Gait: stride length S (one full cycle = two steps) and walking period T (ALGORITHMS.md B8);
        the simulator keeps ``S / T`` equal to the current speed by adapting the period.
    phone : str
        Name of the phone (IMU sensor) this person carries, or "".
    """

    agent_id: int
    t_start_s: float
    waypoints_m: np.ndarray
    speed_mps: float
    waits_s: np.ndarray
    height_m: float
    appearance: Appearance
    group_id: int = -1
    group_from_waypoint: int = 0
    group_until_waypoint: int = -1
    stride_m: float = 1.4
    period_s: float = 1.1
    leave_at_end: bool = True
    phone: str = ""


@dataclass(frozen=True, slots=True, eq=False)
class VehiclePlan:
    """A car or bicycle driving along a road lane, with an optional scripted incident.

    ``incident`` is one of ``""``, ``"stop"`` (decelerate to a standstill at ``incident_t_s`` and
    stay stopped ``incident_duration_s``), ``"leave"`` (steer off the road at ``incident_t_s``
    and stop on the verge), ``"slow"`` (drive at ``slow_speed_mps`` from ``incident_t_s`` for
    ``incident_duration_s``, which builds a queue behind: a jam).
    """

    agent_id: int
    kind: int  # KIND_CAR or KIND_BICYCLE
    t_start_s: float
    road: int
    lane: int  # 0 = rightmost lane in the road's direction; negative = the opposite direction
    speed_mps: float
    length_m: float
    width_m: float
    height_m: float
    appearance: Appearance
    incident: str = ""
    incident_t_s: float = 0.0
    incident_duration_s: float = 0.0
    slow_speed_mps: float = 1.0


@dataclass(frozen=True, slots=True, eq=False)
class AgentSnapshot:
    """Every agent present in the scene at one instant (absent agents are not listed).

    Attributes
    ----------
    ids : (n,) int64
    kinds : (n,) int8 — :data:`KIND_PERSON`, :data:`KIND_BICYCLE`, :data:`KIND_CAR`
    position_m : (n, 2) — body centre (feet midpoint) or vehicle footprint centre
    velocity_mps : (n, 2)
    heading_rad : (n,)
    feet_m : (n, 2, 2) — left and right foot (leg) centres at laser height; NaN for vehicles
    size_m : (n, 3) — length (along heading), width, height; a person is ~0.30 x 0.50 x height
    upper_bgr, lower_bgr : (n, 3) uint8; pattern : (n,) int8
    group_ids : (n,) int64 (-1 = alone)
    gait_phase_rad : (n,) — walking phase φ of ALGORITHMS.md B8 (0 for vehicles). The left heel
        strikes at φ ≡ π (left foot furthest ahead), the right at φ ≡ 0; the phase advances by
        2π per stride S walked, so a standing person's phase does not move.
    """

    t_ns: int
    ids: np.ndarray
    kinds: np.ndarray
    position_m: np.ndarray
    velocity_mps: np.ndarray
    heading_rad: np.ndarray
    feet_m: np.ndarray
    size_m: np.ndarray
    upper_bgr: np.ndarray
    lower_bgr: np.ndarray
    pattern: np.ndarray
    group_ids: np.ndarray
    gait_phase_rad: np.ndarray

    def __len__(self) -> int:
        return int(self.ids.size)

    @property
    def persons(self) -> np.ndarray:
        """Boolean mask of the people, ``(n,)``."""
        return self.kinds == KIND_PERSON

    def footprints(self) -> np.ndarray:
        """Floor rectangles of the vehicles (and people), ``(n, 4, 2)``."""
        return rect_corners(self.position_m, self.size_m[:, 0], self.size_m[:, 1], self.heading_rad)

    @staticmethod
    def empty(t_ns: int) -> AgentSnapshot:
        z = np.zeros
        return AgentSnapshot(t_ns, z(0, np.int64), z(0, np.int8), z((0, 2)), z((0, 2)), z(0), z((0, 2, 2)),
                             z((0, 3)), z((0, 3), np.uint8), z((0, 3), np.uint8), z(0, np.int8), z(0, np.int64),
                             z(0))


@dataclass(frozen=True, slots=True)
class StepEvent:
    """A heel strike of a person (ground truth for step detection and dead reckoning)."""

    t_ns: int
    agent_id: int
    foot: int  # 0 = left, 1 = right
    position_m: tuple[float, float]


@dataclass(frozen=True, slots=True)
class Incident:
    """A scripted traffic incident (ground truth for scene understanding, seed 003 D8)."""

    kind: str  # "stopped_vehicle", "road_leaving", "jam"
    t_start_ns: int
    t_end_ns: int
    agent_ids: tuple[int, ...]


# --------------------------------------------------------------------------------------------------
# Sensor specifications (the scenario file's sensor sections, validated, in SI units)
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Timing:
    """When a sensor produces messages and how its clock and link misbehave.

    ``clock_offset_s`` is added to the true time in the header stamps it writes; ``jitter_s`` is the
    standard deviation of a per-message stamp error; ``drop_probability`` loses messages at random;
    ``outages_s`` are ``(start, end)`` windows of true time with no messages at all.
    """

    rate_hz: float
    clock_offset_s: float = 0.0
    jitter_s: float = 0.0
    drop_probability: float = 0.0
    outages_s: tuple[tuple[float, float], ...] = ()


@dataclass(frozen=True, slots=True)
class LaserSpec:
    """A 2D laser scanner at ``(x_m, y_m)`` with heading ``yaw_rad``, scanning ``height_m`` above the floor.

    Beam ``i`` points at ``yaw_rad + angle_min_rad + i * angle_increment_rad`` in the world frame.
    A beam without a return in range reads ``+inf`` (REP 117).
    """

    name: str
    x_m: float
    y_m: float
    yaw_rad: float
    timing: Timing
    height_m: float = 0.2
    angle_min_rad: float = -2.356194490192345  # -135 deg
    angle_increment_rad: float = 0.006544984694978735  # 0.375 deg -> 720 beams over 270 deg
    n_beams: int = 720
    range_min_m: float = 0.05
    range_max_m: float = 30.0
    range_noise_m: float = 0.01


@dataclass(frozen=True, slots=True)
class CameraSpec:
    """A camera (optionally RGB-D) on a pole: true pose, intrinsics, and the calibration it is believed to have.

    ``yaw_bias_rad`` is seed 000's horizontal misalignment: the image is rendered from the true
    pose; the calibration written to the recording (CameraInfo + tf_static ``<name>_calibrated``) is
    the true pose turned by ``-yaw_bias_rad`` about the vertical, i.e. what the user believes.
    ``illumination`` is a schedule of ``(t_s, gain)``: from ``t_s`` on, the scene's brightness is
    multiplied by ``gain`` (lights off ~ 0.35, back on = 1.0).
    """

    name: str
    position_m: tuple[float, float, float]
    yaw_rad: float
    pitch_rad: float  # tilt down from horizontal, positive looks down
    timing: Timing
    width: int = 640
    height: int = 480
    fx: float = 500.0
    fy: float = 500.0
    cx: float | None = None
    cy: float | None = None
    dist: tuple[float, ...] = ()
    roll_rad: float = 0.0
    yaw_bias_rad: float = 0.0
    noise_sigma: float = 2.0
    illumination: tuple[tuple[float, float], ...] = ()
    shadows: bool = True
    labels: bool = False  # also write a per-pixel agent label image (uint16: agent id + 1, 0 = none)
    depth: bool = False  # RGB-D: also write a metric depth image aligned with the colour image
    depth_range_m: tuple[float, float] = (0.5, 4.5)
    depth_noise_m: float = 0.01


@dataclass(frozen=True, slots=True)
class ImuSpec:
    """A phone carried by a person: accelerometer + gyroscope in the phone's frame.

    ``mount_rpy_rad`` is the phone's orientation relative to the walker's body frame (x forward,
    y left, z up); ``accel_bias_mps2`` and ``gyro_bias_radps`` are constant biases; noises are per
    sample standard deviations.
    """

    name: str
    carrier_id: int
    timing: Timing
    mount_rpy_rad: tuple[float, float, float] = (0.0, 0.0, 0.0)
    accel_bias_mps2: tuple[float, float, float] = (0.05, -0.03, 0.04)
    gyro_bias_radps: tuple[float, float, float] = (0.0087, -0.0052, 0.0070)  # (0.5, -0.3, 0.4) deg/s
    accel_noise_mps2: float = 0.05
    gyro_noise_radps: float = 0.003
    step_accel_mps2: float = 2.5  # amplitude of the vertical acceleration pattern of a step
