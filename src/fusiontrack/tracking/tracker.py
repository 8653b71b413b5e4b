"""The laser people tracker of seed 001: one stateful object that strings the tracking maths together.

:class:`LaserPeopleTracker` owns every array of a run and its own integer track ids. Each call of
:meth:`LaserPeopleTracker.step` takes the laser detections of one instant (world frame, from
:class:`fusiontrack.laser.LaserPeopleDetector`) and returns one :class:`~fusiontrack.types.TrackState`
per confirmed live track; the situation events of the step are in :attr:`LaserPeopleTracker.events`.
The step follows ARCHITECTURE.md's "Tracker step" (ALGORITHMS.md sections in brackets):

1. **predict** — all walking targets at once, ``(8, n_targets, n_particles)`` particles (column layout): the
   two-feet walking model, or the random walk for people standing still [B8]; merged targets by a
   constant-velocity Kalman filter on their segment centre [B17, X5];
2. **gate** — ``D_kj`` between every predicted centre (particle mean of the feet midpoint) and every
   detection centre, association states ``c``/``r`` [B6];
3. **situations** — B7's rules for every target and detection, every frame [B7];
4. **update** — each walking target's detection is its nearest gated one (B10), made one-to-one with
   the Hungarian algorithm when two targets want the same detection (X2; the laser-only stand-in for
   B16's score map of correlated targets); particles are weighted by the laser likelihood (feet to
   segment × walking pattern) [B9] and resampled every frame [X1, B10]. A target that found nothing may
   take an unclaimed detection within a gate that grows while it coasts (re-acquisition, instead of a new
   identity after an occlusion). A tenth of each walking target's particles get their heading redrawn
   about the track's velocity every step, so that the filter follows turns (B8's heading noise alone is
   3° per frame);
5. **merge / split** — targets that share one detection become one merged target [B7 rule 1, B17]: a
   constant-velocity Kalman filter on the segment centre, holding every member's id, gait snapshot
   (T, S, ψ), body position and velocity. Inside it each member is predicted with a velocity that relaxes
   to the group's and corrected, with small alpha-beta gains, towards the mean of the segment points
   nearest to it (k-means from the predictions; members kept ``member_min_gap_m`` apart); a merged target
   gates detections with each of its members. When it sees two or more detections each found by it alone
   (B7 rule 2), at least ``split_min_m`` apart, for ``n_split`` frames, it splits and the members are
   recovered *by motion*: their predicted positions are assigned to the detections by the Hungarian
   algorithm [X2] and each recovered member's particle filter restarts at its detection with its
   pre-merge T, S and ψ (members left over stay merged). A merged target whose segments show at most two
   leg blobs for ``single_s`` seconds holds one person: the member nearest to it goes on, the others end;
6. **vehicles** — the detector's rigid objects (feature ``"rigid"``: the whole side of a bicycle or a car) are
   not walkers: they go to constant-velocity Kalman filters on their position (B18, X5;
   :class:`~fusiontrack.tracking.baseline.CVKalmanTracker` with ``vehicle_*`` parameters), in the same id space,
   never merged with people. (Walking particle filters cannot follow them: the walking model's top speed is
   S / T = 2.5 m/s, a bicycle's 4 m/s and a car's 8 m/s);
7. **lifecycle** — unclaimed detections become candidates, confirmed after ``n_confirm`` frames on the edge
   of the covered area or ``n_confirm_interior`` inside it; so do the detections an unmerged target found alone
   beside its nearest one and nobody took (B7 rule 2's split candidates; also when its nearest is shared with
   another target: a third person walking beside a correlated pair was never born, 72 simulated runs of
   ``crowd`` lost 1.1 points of MOTA to it); a target with no detection coasts, and ends
   after ``n_miss_edge`` frames on the edge (once it is ``edge_min_age_s`` old, and with ``edge_leave_s`` only
   if it is heading out) or ``n_miss`` frames elsewhere [B7]. Standing people switch to the random-walk model
   (B8, :func:`update_standing`) from the speed of the estimated body position.

The output position of a walking target is the particle mean of the feet midpoint (B10), of a merged
member its own body position; velocities come from the estimated positions (time constant
``velocity_tau_s``).

Frame counts and time
---------------------
B7 counts frames of seed 001's integrated 25 Hz stream. The tracker is stepped once per laser scan, so
with two scanners at 25 Hz it runs at 50 Hz, and on a 10 Hz bag at 10 Hz. Every count ``N`` is therefore
taken as ``N · frame_s`` seconds of the tracker's own clock (``frame_s`` = 40 ms): "seen for ``N_confirm``
frames" means "seen without a gap for ``(N_confirm - 1) · frame_s`` seconds, in at least two steps", and
"missing for ``N_miss`` frames" means "no detection for ``N_miss · frame_s`` seconds". Process noise is
scaled the same way (``dt_ref_s = frame_s``).

Events
------
``Event.kind`` is one of ``merge``, ``split`` (``track_ids`` = the members), ``correlated`` (one per
track and run of the correlated state, which changes after ``n_confirm`` frames of the other label; emitted when
the run ends),
``appear`` (a track born from a candidate first seen on the edge; ``t_ns`` = first seen, ``t_end_ns`` =
confirmation), ``disappear`` (a track ended on the edge; ``t_ns`` = last detection, ``t_end_ns`` = the
end), and two kinds that seed 001 does not score: ``born`` (a track confirmed inside the area) and
``lost`` (a track ended by ``N_miss`` inside the area, or a member dropped from a merged target that held
one person). Events carry their own times and may be reported a step or more after them (a correlated
run when it ends). Call :meth:`LaserPeopleTracker.finish` at the end of a run for the events still open.

Situations of the states: B7's label of the target (:data:`~fusiontrack.tracking.situations.SITUATION_OF_LABEL`;
coasting is ``noncorrelated``), ``appearing`` for ``appear_window_s`` after a birth on the edge, ``merged``
for the members of a merged target, except while they are seen apart: while it is splitting (its gate holds two
detections, each found by it alone, and the split waits for ``n_split`` frames or for ``split_min_m``), or while
its gate holds as many detections nearer to it than to any other target as it has members (one of them found by
another target too, so B7 rule 2's split condition fails). Then its members are ``correlated``, as B7 rule 3 labels
two people near each other that are each detected. Members' correlated runs go on as a walking target's do, and a
merge does not end them at once: the merged label must hold ``n_confirm`` frames, as any other change of state (the
measurement truth's rule) [RECON: on crowd seeds 0-2 (60 s, after 3 s, measurement truth), the person-frames the
truth calls correlated whose track says so went from 34 % to 59 % with the splitting rule (merged: 70 % to 63 %),
correlated episodes detected from 101/161 with 59 false alarms to 136/161 with 130; the second rule: 65 % and
141/161 with 128 (merged 62 %), groups seeds 0-2 75 % -> 80 % (merged 78 %), tracks unchanged. Counting every
detection in the gate instead gave 69 % and 144/161, but calls a merged pair passing a bystander correlated].

Also here: :func:`track_recording`, which builds the detector from a recording's laser topics and
``/tf_static`` and runs a tracker over it, and :func:`area_from_backgrounds`, the covered area inferred
from what the scanners see. The constant-velocity Kalman baseline is
:class:`fusiontrack.tracking.baseline.CVKalmanTracker`.
"""

from __future__ import annotations

import dataclasses
import itertools
import logging
import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ConfigError
from ..types import Detection, Event, ObjectClass, Situation, TrackState
from . import _jit, kalman
from .association import association_states, gate_distances, hungarian
from .likelihood import laser_log_likelihood_cols
from .pf import resample_where_cols, reweight, standard_normal
from .situations import SITUATION_OF_LABEL, TargetLabel, boundary_distance, classify_situations
from .walking import (
    PERIOD,
    PSI,
    STRIDE,
    STRIDE_RANGE_M,
    StandingNoise,
    WalkingNoise,
    init_walking,
    predict_people_cols,
)

__all__ = [
    "CandidateSet",
    "DetectionArrays",
    "LaserPeopleTracker",
    "TrackerParams",
    "area_from_backgrounds",
    "area_polygon",
    "count_blobs",
    "detection_arrays",
    "track_recording",
]

log = logging.getLogger(__name__)

_SITUATION_NAMES = {int(label): str(sit) for label, sit in SITUATION_OF_LABEL.items()}
_APPEARING, _MERGED_S = str(Situation.APPEARING), str(Situation.MERGED)
_DISAPPEARING_S, _NONCORRELATED_S = str(Situation.DISAPPEARING), str(Situation.NONCORRELATED)
_CORRELATED_S = str(Situation.CORRELATED)
_NONCORRELATED, _CORRELATED = int(TargetLabel.NONCORRELATED), int(TargetLabel.CORRELATED)
_MERGING, _MERGED, _SPLITTING = int(TargetLabel.MERGING), int(TargetLabel.MERGED), int(TargetLabel.SPLITTING)
_COASTING, _DISAPPEARING = int(TargetLabel.COASTING), int(TargetLabel.DISAPPEARING)
_NO_INDEX = np.zeros(0, np.int64)
_NO_INDEX.setflags(write=False)
_WANTS_DETECTION = np.zeros(256, bool)  # by target label: the labels that take their nearest detection
_WANTS_DETECTION[[_NONCORRELATED, _CORRELATED, _MERGED]] = True


def _starts(sizes: list[int]) -> list[int]:
    """Start index of each block of the given sizes (``np.minimum.reduceat``'s indices)."""
    out, k = [], 0
    for n in sizes:
        out.append(k)
        k += n
    return out


def _rigid(d: Detection) -> bool:
    """A rigid object of the detector (a bicycle or a car), not a two-feet segment."""
    r = d.features.get("rigid")
    return r is not None and bool(r)


def _all(a: np.ndarray) -> bool:
    """``a.all()`` of an array (``count_nonzero`` is a plain C call; ``ndarray.all`` goes through Python wrappers:
    a few µs per call on the hot path)."""
    return np.count_nonzero(a) == a.size


# --------------------------------------------------------------------------------------------------
# Parameters
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class TrackerParams:
    """Every parameter of :class:`LaserPeopleTracker` (ALGORITHMS.md defaults; RECON where marked).

    Attributes
    ----------
    n_particles : int
        Particles per target (B10: 100).
    bandwidth_m, gate : float
        B6's gate: ``σ_x = σ_y = h`` (0.40 m) and ``G = 4``, a circle of radius 2h.
    d_edge_m : float
        Width of the edge band of the covered area (B7: 0.5 m).
    frame_s : float
        Duration of one of B7's frames (40 ms, 25 Hz); the frame counts below are multiples of it.
    n_confirm, n_confirm_interior, n_miss : int
        B7: 3 frames on the edge, 10 inside, 25 frames of coasting.
    n_miss_edge : int
        Frames without a detection on the edge before a target disappears (B7 says at once; 3 frames of
        grace keep a target whose feet blink out for one scan near a wall) [RECON].
    edge_min_age_s : float
        A target younger than this does not disappear on the edge (it coasts as inside): people seen in a
        doorway flicker in and out of view as they come in [RECON].
    edge_leave_s : float
        A target on the edge without a detection disappears (after ``n_miss_edge`` frames) only if it is
        heading out: its position ``edge_leave_s`` ahead at its velocity lies outside the area (a merged
        target: every member's). Otherwise it coasts as inside (``n_miss``) and ends there as a disappear if it
        is still on the edge. People crossing in a doorway hide one another or share one segment for a few
        scans; B7's rule ended the track of one still in the room and a new track took the person back (an ID
        switch). 0 (the default) keeps B7's rule (every target on the edge with ``c = 0``) [RECON]. Laser only,
        0 -> 0.5:
        60 s crowd seeds 0-2 (measurement truth) IDSW 18/9/14 -> 13/9/16, MOTA 0.854/0.928/0.864 ->
        0.854/0.928/0.885, IDF1 0.829/0.940/0.894 -> 0.852/0.940/0.905, appear (detected/true/false alarms)
        52/57/5 -> 53/57/4, disappear 61/64/10 -> 62/64/8; 30 s crowd seeds 0-11: IDSW 81 -> 80 (switches
        after a disappear while the person stayed 12 -> 10), mean MOTA 0.8651 -> 0.8656, IDF1 0.8746 ->
        0.8733; 30 s groups seeds 0-11: unchanged (IDSW 36, MOTA 0.9059/0.9060, IDF1 0.8584/0.8585). From
        the 217 disappear events of those 24 runs (B7's rule): with 0.5 s, 4 of the 5 whose person was still in
        the room 0.6 s later would have coasted, and 6 of the 212 others. Fused (``benchmarks/fusion.py``'s
        runs, 30 s crowd + groups seeds 0-11): IDSW 99 -> 104, mean IDF1 unchanged within 0.002; laser only on the
        same runs 117 -> 116. It does not pay, so it is off [RECON].
    n_merge : int
        Frames B7 rule 1 (one detection shared by targets that found only it) must hold for the same targets before
        they merge, as ``N_confirm`` for a new detection (B7 rule 6); gaps up to ``candidate_gap_s`` in which
        they do not each have a detection of their own do not restart the count. Until then they are
        ``correlated`` (B7 rule 3's completion: they interact). One frame's fused segment is no merge: the
        measurement truth (:func:`~fusiontrack.sim.situations.segment_situation_events`) asks ``N_confirm``
        frames of a state too [RECON]. 1 (the default) merges at once, as B7 is written. With 3, on crowd seeds 0-2
        (measurement truth): merge 16/17 FA 204 -> 14/17 FA 72, split 17/18 FA 188 -> 15/18 FA 63; MOTA / IDF1 /
        IDSW over tracker seeds 0-2: crowd 0.886/0.874/43 -> 0.877/0.873/50, groups 0.927/0.903/4.7 ->
        0.942/0.938/3.3; but the fusion tests built on the laser tracker's splits of one side-by-side pair
        (appearance-decided splits, the identity check) lose the splits they need, so it is off until they are
        looked at. In ``benchmarks/laser_people.py``'s scaling hall (crowd, 20 s, seed 0), before the detector
        kept rigid objects whole, MOTA with 35 / 72 people present was 0.867 / 0.456 with 1 and 0.825 / 0.566
        with 3 (our CV Kalman: 0.866 / 0.659); now 0.903 / 0.531 with 1 and 0.858 / 0.617 with 3 (Kalman
        0.896 / 0.688). At 72 most shared detections are a neighbour occluding a person, and merged targets place
        their members badly [RECON]; ``cap_merges`` does better there (very dense crowds: use it instead). (These
        figures are with the detector's ``min_cluster_points`` 1; with 2, which lost far legs, 3 helped from 35
        people on: 0.735 -> 0.749.) The other figures above were measured with ``min_cluster_points`` 2.
    cap_merges : bool
        A merge takes at most as many people as its shared segment shows: ``⌈leg blobs / 2⌉`` (blobs as
        ``blob_radius_m``), at least 2, a merged target counting its members. The targets nearest to the segment
        (gate distance) join first, each if it still fits (a farther walker may join where a nearer merged target
        did not fit); the others stay ``correlated`` (a merged target: ``merged``) and take their nearest
        detection as such [RECON: B7 rule 1 has no limit; in a dense crowd a person hidden behind a
        neighbour finds only the neighbour's segment, and merged targets, gating with every member, absorbed
        chains of such people: merges of 5 to 16 people at 72 present, their members placed far from anyone].
        **Very dense crowds: switch it on.** In ``benchmarks/laser_people.py``'s scaling hall (crowd, 20 s),
        MOTA with 72 people present, seed 0 / 1: 0.531 / 0.522 -> 0.646 / 0.631 (our CV Kalman: 0.688 / 0.713;
        ``n_merge`` 3 instead: 0.617 on seed 0); with 35: 0.903 / 0.881 -> 0.907 / 0.893; with 17 (seed 0): the same.
        Since a person beside a correlated pair can be born (B7 rule 2's completion): 72 present 0.502 / 0.559 ->
        0.644 / 0.666, 35 present 0.877 / 0.874 -> 0.905 / 0.880, 17 present 0.920 / 0.940 -> 0.946 / 0.940 (the
        same code before that change, rerun on these recordings: 0.533 / 0.524 at 72, 0.877 / 0.863 at 35).
        Off by default: where people walk in groups of three, or one hides behind a pair, their merges are real.
        On the fusion benchmark's 72 runs (crowd + groups, seeds 0-35, 30 s, laser only) with the particle
        filters' seeds 0 / 1 / 2: crowd 176 / 154 / 167 -> 155 / 153 / 154 ID switches (IDF1 +0.002), groups
        86 / 85 / 80 -> 97 / 84 / 82 (IDF1 -0.007 on average); on ``benchmarks/laser_people.py``'s scenes (crowd
        60 s, seeds 0-2) MOTA 0.936 -> 0.931, ID switches 22 -> 28, merges detected 39 -> 34 of 47.
    n_split : int
        Frames the split condition must hold before a merged target splits (hysteresis: two people side by
        side are one segment in one scan and two in the next; gaps up to ``candidate_gap_s`` do not restart
        the count) [RECON].
    split_min_m : float
        ... and the two farthest of its detections must be at least this far apart (the simulator's truth
        calls people closer than 0.6 m merged) [RECON].
    split_birth_m : float
        A new track confirmed within this distance of a merged target's detection, and first seen after the merged
        target formed and within this distance of where it was then, is a member leaving it: the merged target
        splits instead (0: never) [RECON]. Issue 4's crowd scenes: ID switches 26 -> 21, splits found 44 -> 45 of
        50; the 72 fusion-benchmark runs, laser only: the same within noise.
    candidate_gate_m, candidate_gap_s : float
        A candidate takes the nearest unclaimed detection within this distance, and is dropped after this
        long without one [RECON].
    sigma_f_m, sigma_w_m, sigma_f_one_m, kappa, lateral_m : float
        B9's likelihood; ``lateral_m`` is the side-by-side distance of the feet (0 in B8; 0.2 m for the
        simulator's walkers).
    walking_noise, standing_noise : WalkingNoise, StandingNoise
        Process noise (B8 values per 40 ms frame, scaled with ``sqrt(Δt / frame_s)``).
    standing_speed_mps, standing_frames, resume_speed_mps :
        B8's standing switch (:func:`~fusiontrack.tracking.walking.update_standing`); frames are steps.
    velocity_tau_s : float
        Time constant of the track velocity estimate (from the estimated body positions) [RECON].
    init_feet_sigma_m, init_heading_sigma_rad, init_period_sigma_s, init_stride_sigma_m : float
        Spread of a new target's particles around B8's initialisation [RECON].
    merged_q, merged_r_m : float
        Constant-velocity Kalman filter of a merged target: ``q`` (m²/s³) and the σ of its centre (m) [X5].
    member_tau_s : float
        How long a member's velocity relative to its merged target is extrapolated (decay time) [RECON].
    member_alpha, member_beta : float
        Gains of the alpha-beta filter that follows each member inside a merged target: the member's
        predicted position is moved by ``alpha`` times, and its velocity by ``beta / Δt`` times, the residual
        to the mean of the segment points nearest to it (k-means over the merged segment) [RECON].
    member_min_gap_m : float
        Members of a merged target are kept at least this far apart [RECON].
    blob_radius_m : float
        Leg blobs: the points of a segment linked by distances below this. A segment of one person shows at
        most two; a merged target whose segments show at most two for ``single_s`` seconds holds one person (the
        member nearest to it goes on as a walking target, the others end as ``lost``), and a candidate whose
        segment shows three or more in ``multi_fraction`` of its frames is born as a merged target of two
        people (three for five or more blobs; ``multi_fraction=None``, the default, switches this off: on the
        simulated crowds it did not pay. Measured again with ``fusiontrack.eval.switches``' ``shared`` cause, on the
        fusion benchmark's 144 runs (crowd and groups, seeds 0-35, 30 s, draws 0 / 1, laser only): 0.5 gave crowd
        82 / 77 -> 89 / 90 ID switches, groups 23 / 26 -> 19 / 28, and the ``shared`` ones, which it is meant for,
        16 / 14 -> 15 / 14 in the crowds) [RECON].
    multi_fraction, single_s : float or None
        See ``blob_radius_m``.
    reacquire_speed_mps, reacquire_max_m : float
        A target that found no detection may take an unclaimed detection (found by nobody) within
        ``2h + reacquire_speed_mps · t_missing`` (at most ``reacquire_max_m``) instead of losing it to a
        new track: its particles restart there with its gait [RECON].
    reseed_fraction : float
        Fraction of a walking target's particles whose heading is redrawn about the track's velocity each
        step (keeps up with turns; 0 = pure B8) [RECON].
    max_dt_s : float
        Longest prediction step; a longer gap (every scanner silent) is predicted as this [RECON].
    correlated_gap_s, min_correlated_s : float
        A track's correlated state starts and ends when B7's label has held for ``n_confirm`` frames (in every
        step with a detection: the measurement truth's rule, ``min_state_s``); runs up to ``correlated_gap_s`` apart
        (default 0: none) are joined unless a merge came between; runs shorter than ``min_correlated_s`` (default
        0: every run) make no event [RECON]. (Before: every correlated step counted and gaps up to 0.4 s were
        bridged; on the simulated crowds one-step labels and 0.4 s bridges cut and joined runs where the truth
        does not, about 2 false alarms per true run.)
    split_hold_s : float
        A ``split`` event is held back this long, and dropped (with the merge that undoes it) when the same
        people merge again in the meantime: one segment that flickers into two is no split. Off (0) by
        default: on the simulated crowds 1 s cut the false merge/split alarms by ~4x but also halved the true
        ones detected [RECON].
    appear_window_s : float
        A target born on the edge is reported ``appearing`` for this long.
    appear_latency_s : float
        A candidate first seen inside the area is still born on the edge (``appear``) when, at its velocity,
        it was on the edge this long before: people coming through a door are first seen up to ~1 m in
        (in the doorway the frame hides their legs from scanners along the wall; then they need a few scans
        to stand out of the background) [RECON]. 0 keeps B7's rule (first position only).
    glimpse_s, glimpse_speed_mps : float
        A candidate first seen on the edge and dropped before it was confirmed (a person glimpsed in a doorway,
        then hidden by the frame or by the people ahead) is remembered for ``glimpse_s``; a candidate confirmed
        inside within ``2h + glimpse_speed_mps`` per second since the glimpse ended is that person: born on the
        edge (``appear``, dated by the glimpse). The measurement truth dates an appear by the first glimpse on
        the edge and confirms it by a later sighting anywhere [RECON]. 0 forgets glimpses.
    vehicles : bool
        Track the detector's rigid objects (detections with feature ``"rigid"``: bicycles and cars, B18) with
        constant-velocity Kalman filters (X5) on their position, apart from the walking people; their tracks share
        the id space and the events. False: rigid objects are detections like any other (walking model).
    vehicle_q : float
        X5's ``q`` of those filters, m²/s³ (B18: 1 for cars, 0.5 for bicycles; one filter for both, as the class
        is known only after a window of frames).
    vehicle_sigma_m : float
        σ of a rigid object's position (B18: 0.15 m; the detector gives the centre of the smallest rectangle
        around its points).
    vehicle_gate_m : float
        Largest distance of a vehicle track to its detection (2 m: the centre of the visible sides moves
        along the vehicle as it passes a scanner).
    vehicle_candidate_gate_m : float
        As ``candidate_gate_m``, for new vehicle tracks (1 m: 8 m/s is 0.32 m a frame).
    vehicle_n_confirm : int
        Frames a rigid object must be seen to start a vehicle track (10, 0.4 s): people whose legs a scan strings
        together can make a rigid object for a frame or two (2 detections in the 9000 frames of the 60 s simulated
        crowds, seeds 0-2; without the detector's one-piece test, 26 in bursts of up to 6 frames).
    vehicle_n_miss : int
        Frames a vehicle track coasts without a detection (25).
    sensor : str
        ``TrackState.sensor`` and ``Event.sensor``. ``TrackState.sensors`` names the scanners whose points the
        detections that confirmed the step hold (the :class:`~fusiontrack.laser.LaserPeopleDetector`'s
        ``scanners`` feature: with two scanners, which of them saw the person), and this name for a detection
        without that feature.
    """

    n_particles: int = 100
    bandwidth_m: float = 0.40
    gate: float = 4.0
    d_edge_m: float = 0.5
    frame_s: float = 0.04
    n_confirm: int = 3
    n_confirm_interior: int = 10
    n_miss: int = 25
    n_miss_edge: int = 3
    edge_min_age_s: float = 1.0
    edge_leave_s: float = 0.0
    n_merge: int = 1
    cap_merges: bool = False
    n_split: int = 5
    candidate_gate_m: float = 0.5
    candidate_gap_s: float = 0.25
    sigma_f_m: float = 0.10
    sigma_w_m: float = 0.10
    sigma_f_one_m: float = 0.15
    kappa: float = 1.0 / math.pi
    lateral_m: float = 0.0
    walking_noise: WalkingNoise = field(default_factory=lambda: WalkingNoise(dt_ref_s=0.04))
    standing_noise: StandingNoise = field(default_factory=lambda: StandingNoise(dt_ref_s=0.04))
    standing_speed_mps: float = 0.1
    standing_frames: int = 10
    resume_speed_mps: float = 0.2
    velocity_tau_s: float = 0.3
    init_feet_sigma_m: float = 0.03
    init_heading_sigma_rad: float = 0.3
    init_period_sigma_s: float = 0.1
    init_stride_sigma_m: float = 0.15
    merged_q: float = 1.0
    merged_r_m: float = 0.08
    member_tau_s: float = 1.0
    member_alpha: float = 0.2
    member_min_gap_m: float = 0.35
    split_min_m: float = 0.6
    split_birth_m: float = 1.5
    blob_radius_m: float = 0.15
    single_s: float = 2.0
    multi_fraction: float | None = None
    member_beta: float = 0.02
    reacquire_speed_mps: float = 1.0
    reacquire_max_m: float = 2.0
    reseed_fraction: float = 0.1
    max_dt_s: float = 0.5
    correlated_gap_s: float = 0.0
    min_correlated_s: float = 0.0
    split_hold_s: float = 0.0
    appear_window_s: float = 1.0
    appear_latency_s: float = 0.75
    glimpse_s: float = 5.0
    glimpse_speed_mps: float = 1.5
    vehicles: bool = True
    vehicle_q: float = 1.0
    vehicle_sigma_m: float = 0.15
    vehicle_gate_m: float = 2.0
    vehicle_candidate_gate_m: float = 1.0
    vehicle_n_confirm: int = 10
    vehicle_n_miss: int = 25
    sensor: str = "laser"

    def __post_init__(self) -> None:
        positive = ("bandwidth_m", "gate", "frame_s", "candidate_gate_m", "candidate_gap_s", "sigma_f_m",
                    "sigma_w_m", "sigma_f_one_m", "velocity_tau_s", "merged_r_m", "member_tau_s", "max_dt_s",
                    "member_alpha", "vehicle_q", "vehicle_sigma_m", "vehicle_gate_m", "vehicle_candidate_gate_m")
        for name in positive:
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
                raise ConfigError(f"tracker parameter {name}: expected a finite value > 0, got {v!r}")
        non_negative = ("d_edge_m", "kappa", "lateral_m", "standing_speed_mps", "resume_speed_mps",
                        "init_feet_sigma_m", "init_heading_sigma_rad", "init_period_sigma_s", "init_stride_sigma_m",
                        "merged_q", "correlated_gap_s", "appear_window_s", "member_beta", "member_min_gap_m",
                        "split_min_m", "blob_radius_m", "single_s", "reacquire_speed_mps", "min_correlated_s",
                        "split_hold_s", "reacquire_max_m", "edge_min_age_s", "edge_leave_s", "appear_latency_s",
                        "glimpse_s", "glimpse_speed_mps", "split_birth_m")
        for name in non_negative:
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v >= 0):
                raise ConfigError(f"tracker parameter {name}: expected a finite value >= 0, got {v!r}")
        for name in ("n_particles", "n_confirm", "n_confirm_interior", "n_miss", "n_miss_edge", "n_merge", "n_split",
                     "standing_frames", "vehicle_n_confirm", "vehicle_n_miss"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | np.integer) or v < 1:
                raise ConfigError(f"tracker parameter {name}: expected an integer >= 1, got {v!r}")
        if self.multi_fraction is not None and not 0.0 <= self.multi_fraction <= 1.0:
            raise ConfigError(f"tracker parameter multi_fraction: expected 0..1 or None, got {self.multi_fraction!r}")
        if not 0.0 <= self.reseed_fraction <= 1.0:
            raise ConfigError(f"tracker parameter reseed_fraction: expected 0..1, got {self.reseed_fraction!r}")
        if not isinstance(self.cap_merges, bool):
            raise ConfigError(f"tracker parameter cap_merges: expected true or false, got {self.cap_merges!r}")
        if not isinstance(self.vehicles, bool):
            raise ConfigError(f"tracker parameter vehicles: expected true or false, got {self.vehicles!r}")

    def replace(self, **changes: Any) -> TrackerParams:
        """A copy with some fields changed (unknown names are a :class:`ConfigError`)."""
        names = {f.name for f in dataclasses.fields(self)}
        unknown = sorted(set(changes) - names)
        if unknown:
            raise ConfigError(f"unknown tracker parameter(s) {', '.join(unknown)}; known: {', '.join(sorted(names))}")
        return dataclasses.replace(self, **changes)


def _params(params: TrackerParams | Mapping[str, Any] | None, overrides: Mapping[str, Any]) -> TrackerParams:
    base = TrackerParams() if params is None else params
    if isinstance(base, Mapping):
        base = TrackerParams().replace(**base)
    if not isinstance(base, TrackerParams):
        raise ConfigError(f"params: expected TrackerParams, a mapping or None, got {type(base).__name__}")
    return base.replace(**overrides) if overrides else base


def _rng(rng: np.random.Generator | int | None) -> np.random.Generator:
    return rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)


def area_polygon(area_m: Any) -> np.ndarray | None:
    """The covered area as polygon vertices ``(m, 2)``: from a rectangle ``(x_min, y_min, x_max, y_max)``,
    from vertices ``(m >= 3, 2)``, or ``None`` (no boundary: every place is interior)."""
    if area_m is None:
        return None
    a = np.asarray(area_m, dtype=np.float64)
    if a.shape == (4,):
        x0, y0, x1, y1 = a
        if not (x1 > x0 and y1 > y0):
            raise ConfigError(f"area: expected a rectangle (x_min, y_min, x_max, y_max), got {a.tolist()}")
        a = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])
    if a.ndim != 2 or a.shape[1] != 2 or a.shape[0] < 3 or not np.all(np.isfinite(a)):
        raise ConfigError(f"area: expected a rectangle (4,) or polygon vertices (m >= 3, 2), got shape {a.shape}")
    a = a.copy()
    a.setflags(write=False)
    return a


# --------------------------------------------------------------------------------------------------
# Detections as arrays
# --------------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class DetectionArrays:
    """The laser detections of one step as arrays: ``centres (n, 2)``, ``feet (n, 2, 2)``, ``inter_feet (n,)``,
    ``one_foot (n,)``, ``points`` (each detection's ``points_m`` feature ``(k, 2)``, or ``None``) and ``scanners``
    (each detection's ``scanners`` feature as a tuple of names, or ``None``; ``()`` when no detection has one). A
    detection without feet features has both feet at its centre (one foot)."""

    centres: np.ndarray
    feet: np.ndarray
    inter_feet: np.ndarray
    one_foot: np.ndarray
    points: tuple[np.ndarray | None, ...] = ()
    scanners: tuple[tuple[str, ...] | None, ...] = ()

    def __len__(self) -> int:
        return int(self.centres.shape[0])


def detection_arrays(detections: Sequence[Detection]) -> DetectionArrays:
    """Pack floor detections; detections without ``position_m`` or with non-finite values are left out.

    ``inter_feet_m`` defaults to the distance of the two feet and ``one_foot`` to ``False``; a detection
    without ``feet_m`` is one foot at its centre; a non-finite ``inter_feet_m`` makes it one foot.
    """
    centres_l: list[Any] = []
    feet_list: list[Any] = []
    inter_l: list[Any] = []
    one_l: list[Any] = []
    points: list[np.ndarray | None] = []
    scanners: list[tuple[str, ...] | None] = []
    all_feet = True
    for d in detections:  # one pass over the detections (hot path)
        if d.position_m is None:
            continue
        f = d.features
        centres_l.append(d.position_m)
        fm = f.get("feet_m")
        if all_feet and (fm is None or fm.shape != (2, 2)):
            all_feet = False
        feet_list.append(fm)
        inter_l.append(f.get("inter_feet_m", np.nan))
        one_l.append(f.get("one_foot", False))
        pts = f.get("points_m")
        points.append(pts if pts is not None and pts.ndim == 2 and pts.shape[1] == 2 else None)
        sc = f.get("scanners")
        scanners.append(tuple(map(str, sc.reshape(-1).tolist())) if sc is not None and sc.size else None)
    k = len(centres_l)
    by = tuple(scanners) if any(s is not None for s in scanners) else ()
    if k == 0:
        return _NO_DETECTIONS
    centres = np.array(centres_l)
    if all_feet:
        feet = np.array(feet_list, dtype=np.float64)
    else:
        has_feet = np.array([f is not None and f.shape == (2, 2) for f in feet_list])
        feet = np.array([f if ok else np.stack([c, c]) for f, ok, c in zip(feet_list, has_feet, centres, strict=True)],
                        dtype=np.float64)
    inter = np.array(inter_l, dtype=np.float64)
    one = np.array(one_l, dtype=bool)
    if not (all_feet and math.isfinite(np.add.reduce(inter))):  # (a finite sum: every value finite, the usual case)
        missing = np.isnan(inter) if all_feet else np.isnan(inter) & has_feet
        if np.count_nonzero(missing):
            inter[missing] = np.hypot(*(feet[missing, 0] - feet[missing, 1]).T)
        one |= ~np.isfinite(inter) if all_feet else ~has_feet | ~np.isfinite(inter)
    if np.count_nonzero(one):
        inter = np.where(one, 0.0, inter)
    if (math.isfinite(np.add.reduce(centres, axis=None)) and math.isfinite(np.add.reduce(feet, axis=None))) or (
            _all(np.isfinite(centres)) and _all(np.isfinite(feet))):  # the usual case: every row ok
        return DetectionArrays(centres, feet, inter, one, tuple(points), by)
    ok = np.isfinite(centres).all(axis=1) & np.isfinite(feet).all(axis=(1, 2))
    if ok.all():
        return DetectionArrays(centres, feet, inter, one, tuple(points), by)
    return DetectionArrays(centres[ok], feet[ok], inter[ok], one[ok],
                           tuple(pt for pt, good in zip(points, ok, strict=True) if good),
                           tuple(s for s, good in zip(by, ok, strict=True) if good) if by else ())


_NO_DETECTIONS = DetectionArrays(np.zeros((0, 2)), np.zeros((0, 2, 2)), np.zeros(0), np.zeros(0, bool), ())


# --------------------------------------------------------------------------------------------------
# Birth candidates (shared with the baseline)
# --------------------------------------------------------------------------------------------------


class CandidateSet:
    """Tentative targets: unclaimed detections followed from step to step until confirmed or dropped.

    A candidate takes the nearest unclaimed detection within ``gate_m`` (Hungarian, one-to-one) and is
    dropped once it has gone ``gap_s`` without one. Arrays, one row per candidate: ``first_t``, ``last_t``
    (ns), ``hits``, ``first_pos``, ``pos`` (m), ``edge`` (first seen on the edge), ``det`` (the detection it
    took this step, -1 if none).
    """

    def __init__(self, gate_m: float, gap_s: float) -> None:
        self.gate_m = float(gate_m)
        self.gap_ns = round(gap_s * 1e9)
        self.first_t = np.zeros(0, np.int64)
        self.last_t = np.zeros(0, np.int64)
        self.hits = np.zeros(0, np.int64)
        self.first_pos = np.zeros((0, 2))
        self.pos = np.zeros((0, 2))
        self.edge = np.zeros(0, bool)
        self.det = np.zeros(0, np.int64)
        self.n_multi = np.zeros(0, np.int64)  # frames whose segment showed >= 3 leg blobs
        self.n_many = np.zeros(0, np.int64)  # ... >= 5 leg blobs
        # edge candidates dropped unconfirmed: (first_t, last_t, first_pos, last_pos), oldest first
        self.glimpses: list[tuple[int, int, np.ndarray, np.ndarray]] = []

    _ARRAYS = ("first_t", "last_t", "hits", "first_pos", "pos", "edge", "det", "n_multi", "n_many")

    def __len__(self) -> int:
        return int(self.hits.size)

    def update(self, t_ns: int, positions: np.ndarray, on_edge_dets: np.ndarray,
               blobs: np.ndarray | None = None) -> None:
        """Follow the candidates with the unclaimed detections ``positions (k, 2)``; new ones start candidates.

        ``blobs (k,)``: leg blobs of each detection's segment (optional), counted into ``n_multi``/``n_many``.
        """
        k = positions.shape[0]
        nb = np.zeros(k, np.int64) if blobs is None else np.asarray(blobs, np.int64)
        n = len(self)
        self.det = np.full(n, -1, np.int64)
        taken = np.zeros(k, bool)
        if n and k:
            d = np.linalg.norm(self.pos[:, None, :] - positions[None, :, :], axis=2)
            pairs, _, _ = hungarian(d, gate=self.gate_m)
            if len(pairs):
                r, c = pairs[:, 0], pairs[:, 1]
                self.det[r] = c
                self.pos[r] = positions[c]
                self.last_t[r] = t_ns
                self.hits[r] += 1
                self.n_multi[r] += nb[c] >= 3
                self.n_many[r] += nb[c] >= 5
                taken[c] = True
        keep = (t_ns - self.last_t) <= self.gap_ns
        if not _all(keep):
            for q in (~keep & self.edge).nonzero()[0].tolist():
                self.glimpses.append((int(self.first_t[q]), int(self.last_t[q]), self.first_pos[q].copy(),
                                      self.pos[q].copy()))
            self._select(keep)
        new = (~taken).nonzero()[0]
        if new.size:
            m = new.size
            self.first_t = np.concatenate([self.first_t, np.full(m, t_ns, np.int64)])
            self.last_t = np.concatenate([self.last_t, np.full(m, t_ns, np.int64)])
            self.hits = np.concatenate([self.hits, np.ones(m, np.int64)])
            self.first_pos = np.concatenate([self.first_pos, positions[new]])
            self.pos = np.concatenate([self.pos, positions[new]])
            self.edge = np.concatenate([self.edge, np.asarray(on_edge_dets, bool)[new]])
            self.det = np.concatenate([self.det, new.astype(np.int64)])
            self.n_multi = np.concatenate([self.n_multi, (nb[new] >= 3).astype(np.int64)])
            self.n_many = np.concatenate([self.n_many, (nb[new] >= 5).astype(np.int64)])

    def _select(self, keep: np.ndarray) -> None:
        for name in self._ARRAYS:
            setattr(self, name, getattr(self, name)[keep])

    def ready(self, t_ns: int, need_edge_ns: int, need_interior_ns: int) -> np.ndarray:
        """Indices of candidates seen this step, for long enough (edge or interior rule), in >= 2 steps."""
        need = np.where(self.edge, need_edge_ns, need_interior_ns)
        return ((self.det >= 0) & (self.hits >= 2) & (t_ns - self.first_t >= need)).nonzero()[0]

    def pop(self, idx: np.ndarray) -> None:
        keep = np.ones(len(self), bool)
        keep[idx] = False
        self._select(keep)


# --------------------------------------------------------------------------------------------------
# Merged targets
# --------------------------------------------------------------------------------------------------


@dataclass(slots=True)
class _MemberInfo:
    """What identity recovery keeps of a target suspended inside a merged target (B17 snapshot)."""

    track_id: int
    period_s: float
    stride_m: float
    heading_rad: float
    standing: bool
    born_ns: int
    born_edge: bool


@dataclass(slots=True)
class _Merged:
    """A merged target M (B17): a constant-velocity Kalman state on its segment centre, and its members.

    Each member keeps its own body position and velocity (``pos``, ``vel``, ``(m, 2)``), predicted with a
    velocity that relaxes towards M's and corrected by the segment points nearest to it: that is what
    identity recovery "by motion" compares with the detections when M splits.
    """

    x: np.ndarray  # (4,) x, y, vx, vy
    P: np.ndarray  # (4, 4)
    seen: int  # time of the last detection
    pos: np.ndarray  # (m, 2)
    vel: np.ndarray  # (m, 2)
    info: list[_MemberInfo]
    split_since: int = 0  # start of the current run of split conditions (0: none)
    split_last: int = 0  # last time the split condition held
    multi_last: int = 0  # last time its segments showed more than one person (>= 3 leg blobs, or 2 segments)
    formed_ns: int = 0  # when it was made (a merge, a split leaving two or more together, a birth)
    # One-segment frames since multi_last whose leg blobs are not counted yet: (time, points), oldest first.
    # They are counted only when multi_last is old enough for the single-person rule (see _settle_multi).
    unchecked: list[tuple[int, np.ndarray]] = field(default_factory=list)
    seen_by: tuple[str, ...] = ()  # the sensors of the detections that last confirmed it (TrackState.sensors)
    # seen as several detections: each member's, those of the detection nearest to it (else None: seen_by)
    member_seen: list[tuple[str, ...]] | None = None

    @property
    def ids(self) -> list[int]:
        return [m.track_id for m in self.info]

    def predict(self, dt: float, tau_s: float) -> None:
        v = self.x[2:4]
        self.vel = v + (self.vel - v) * math.exp(-dt / tau_s)
        self.pos = self.pos + self.vel * dt

    def correct(self, points: np.ndarray | None, centre: np.ndarray, dt: float, alpha: float, beta: float,
                min_gap_m: float, max_step_m: float = 0.3, frame_s: float = 0.04) -> None:
        """Alpha-beta correction of the members from the segment points (k-means from the predictions), or,
        without points, by moving them together onto the segment centre. Members closer than ``min_gap_m``
        are then pushed apart to it: the points of one person must not pull two members onto its two feet.

        The velocity gain is ``beta / max(dt, frame_s)``: two scanners' scans a millisecond apart make steps of
        ``dt`` = 1 ms, and ``beta / dt`` turned a centimetre of noise into 1 m/s at each such step; members flew
        off at tens of m/s (crowd seed 24: a member farther than 3 m from its merged target in 32 % of the
        merged frames, 65 m at the 99th percentile) and merged targets gated with them far away."""
        pred = self.pos
        m = pred.shape[0]
        if points is not None and points.shape[0] >= 2 * m:
            c = pred.copy()
            px, py = points[:, 0], points[:, 1]
            pxc, pyc = px[:, None], py[:, None]
            for _ in range(2):
                # _pair_d2(points, c) written out on the columns taken once: dx² + dy²
                d2 = pxc - c[:, 0]
                d2 *= d2
                dy = pyc - c[:, 1]
                dy *= dy
                d2 += dy
                lab = d2.argmin(axis=1)
                cnt = np.bincount(lab, minlength=m)
                sx = np.bincount(lab, px, minlength=m)
                sy = np.bincount(lab, py, minlength=m)
                if np.minimum.reduce(cnt) >= 2:  # every member has 2 points or more
                    c[:, 0] = sx / cnt
                    c[:, 1] = sy / cnt
                else:
                    has = cnt >= 2
                    c[has, 0] = sx[has] / cnt[has]
                    c[has, 1] = sy[has] / cnt[has]
            res = c - pred
        else:
            res = np.broadcast_to(centre - pred.mean(axis=0), pred.shape)
        norm = np.sqrt(np.add.reduce(res * res, axis=1, keepdims=True))  # (res**2 is res * res; = .sum)
        res = res * np.minimum(1.0, max_step_m / np.maximum(norm, 1e-12))
        pos = pred + alpha * res
        if m >= 2 and min_gap_m > 0:
            pl = pos.tolist()  # (the differences of Python floats: the values of pos[b] - pos[a])
            for a, b in itertools.combinations(range(m), 2):
                n = float(np.hypot(pl[b][0] - pl[a][0], pl[b][1] - pl[a][1]))
                if n < min_gap_m:
                    d = pos[b] - pos[a]
                    u = d / n if n > 1e-9 else np.array([1.0, 0.0])
                    push = 0.5 * (min_gap_m - n) * u
                    pos[a] -= push
                    pos[b] += push
                    pl = pos.tolist()
            res = pos - pred
        self.pos = pos
        if dt > 0:
            self.vel = self.vel + (beta / max(dt, frame_s)) * res


def _settle_multi(m: _Merged, t_ns: int, radius_m: float) -> bool:
    """Count the leg blobs of ``m``'s unchecked frames, newest first, up to the first with 3 or more: its time
    becomes ``m.multi_last``. Returns whether that is the frame ``t_ns``.

    The same ``multi_last`` as counting every frame when it comes (``multi_last`` is the last frame with >= 3
    blobs), but counted only when the single-person rule needs it: while ``multi_last`` is recent, a newer
    frame with more blobs would not change the decision (a merged target of two people walking together shows
    >= 3 blobs most of the time, and counting once per ``single_s`` replaces counting every scan).
    """
    found = False
    for t, points in reversed(m.unchecked):
        if count_blobs(points, radius_m) >= 3:
            m.multi_last = t
            found = t == t_ns
            break
    m.unchecked.clear()
    return found


def count_blobs(points: np.ndarray, radius_m: float) -> int:
    """Number of groups of ``points (k, 2)`` linked by distances below ``radius_m`` (leg blobs of a segment)."""
    k = points.shape[0]
    if k <= 1:
        return k
    reach = _pair_d2(points, points) < radius_m * radius_m
    a = reach.astype(np.float32)
    for _ in range(k):  # transitive closure by squaring: log2(k) steps suffice
        nxt = (a @ a) > 0
        if _all(nxt == reach):
            break
        reach = nxt
        a = reach.astype(np.float32)
    first = reach.argmax(axis=1)  # the first point each one reaches
    if _all(reach.diagonal()):  # every point reaches itself: first == own index at one point per group
        return int(np.count_nonzero(first == np.arange(k)))
    return int(np.unique(first).size)


def _pair_d2(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Squared distances ``(len(a), len(b))`` between 2-D points: ``dx² + dy²``, the values of
    ``((a[:, None] - b[None]) ** 2).sum(axis=2)`` (a reduction over 2 is one addition) without numpy's slow
    reduction over a length-2 inner axis."""
    dx = a[:, 0, None] - b[None, :, 0]
    dy = a[:, 1, None] - b[None, :, 1]
    dx *= dx
    dy *= dy
    dx += dy
    return dx


def _own_detections(D: np.ndarray, found: np.ndarray, row: int) -> np.ndarray:
    """The detections target ``row`` found that are nearer to it than to any other target that found them, in
    index order (``D``: gate distances, targets x detections; ``found``: ``D < G``, so a NaN distance is no
    candidate)."""
    js = found[row].nonzero()[0]
    if not js.size:
        return js
    return js[np.where(found[:, js], D[:, js], np.inf).argmin(axis=0) == row]


def _max_pair_distance(points: np.ndarray) -> float:
    if points.shape[0] < 2:
        return 0.0
    return float(np.sqrt(_pair_d2(points, points).max()))


def _fast_state(t_ns: int, sensor: str, track_id: int, position: np.ndarray, velocity: np.ndarray, situation: str,
                sensors: tuple[str, ...], covariance: np.ndarray | None = None, *, frozen: bool = False,
                cls: str | None = None) -> TrackState:
    """A :class:`TrackState` built without re-validating values the tracker already guarantees (hot path).

    Equivalent to ``TrackState(t_ns, sensor, track_id, position, velocity, situation=situation,
    sensors=sensors)`` for an int time and id, finite (2,) float arrays, a valid situation string and a
    tuple of str (and a finite (4, 4) ``covariance`` or None): the arrays are copied and made read-only
    exactly as the constructor does. ``frozen``: ``position`` and ``velocity`` are already such read-only
    float64 copies (rows of a :func:`_frozen_copy`, which nobody writes), taken as they are. ``cls``: an
    :class:`~fusiontrack.types.ObjectClass` value (default ``person``).
    """
    st = object.__new__(TrackState)
    if frozen:
        pos, vel = position, velocity
    else:
        pos = np.array(position, dtype=np.float64)
        vel = np.array(velocity, dtype=np.float64)
        pos.setflags(write=False)
        vel.setflags(write=False)
    if covariance is not None:
        covariance = np.array(covariance, dtype=np.float64)
        covariance.setflags(write=False)
    # the slots' own setters (what object.__setattr__ ends up calling), without the per-name lookups
    (set_t, set_sensor, set_id, set_pos, set_vel, set_cov, set_cls, set_situation, set_sensors, set_score, set_box,
     set_camera) = _STATE_SETTERS
    set_t(st, t_ns)
    set_sensor(st, sensor)
    set_id(st, track_id)
    set_pos(st, pos)
    set_vel(st, vel)
    set_cov(st, covariance)
    set_cls(st, _PERSON if cls is None else cls)
    set_situation(st, situation)
    set_sensors(st, sensors)
    set_score(st, 1.0)
    set_box(st, None)
    set_camera(st, "")
    return st


def _frozen_copy(a: np.ndarray) -> np.ndarray:
    """A read-only float64 copy of ``a``; its rows (read-only views) are the states' arrays of one step: one copy
    per array instead of one per state."""
    out = np.array(a, dtype=np.float64)
    out.setflags(write=False)
    return out


_PERSON = str(ObjectClass.PERSON)
_STATE_SETTERS = tuple(TrackState.__dict__[name].__set__ for name in (
    "t_ns", "sensor", "track_id", "position_m", "velocity_mps", "covariance", "cls", "situation", "sensors", "score",
    "box_px", "camera"))
assert len(_STATE_SETTERS) == len(TrackState.__slots__)  # every field is set


_CV_MATRICES: dict[tuple[float, float], tuple[np.ndarray, np.ndarray]] = {}
_EYE4 = np.eye(4)


def _merged_kalman_update(x: np.ndarray, P: np.ndarray, z: np.ndarray, r2: float) -> tuple[np.ndarray, np.ndarray]:
    """``kalman.update(x[None], P[None], z[None], R=r2)`` of one merged target, returned as ``(x (4,), P (4, 4))``
    (hot path; ``z`` is a finite detection centre, ``P`` a finite covariance).

    The same values as the general update, bit for bit, at half the cost: with ``H = [I 0]`` the products
    ``H x``, ``H P Hᵀ`` and ``P Hᵀ`` are slices (a product with 0/1 entries is exact), and the gain
    ``K = P Hᵀ S⁻¹`` is LAPACK's ``gesv`` on the 2 x 2 innovation covariance written out: LU with partial
    pivoting, divisions as multiplications by the pivots' reciprocals, as OpenBLAS computes them (checked equal
    to ``np.linalg.solve`` on every merged-target update of crowd and groups seeds 0-2); a ``numpy.linalg`` call
    costs more than the rest of the update.
    """
    y = z - x[0:2]
    a00, a01, a10, a11 = P[0, 0] + r2, P[0, 1], P[1, 0], P[1, 1] + r2  # S = H P Hᵀ + r² I
    b0, b1 = P[:, 0], P[:, 1]  # the right-hand sides: the rows of (P Hᵀ)ᵀ
    if abs(a10) > abs(a00):  # partial pivoting (the first of equal magnitudes stays)
        a00, a01, a10, a11, b0, b1 = a10, a11, a00, a01, b1, b0
    r = 1.0 / a00
    low = a10 * r
    k1 = (b1 - low * b0) * (1.0 / (a11 - low * a01))
    k0 = (b0 - a01 * k1) * r
    K = np.empty((4, 2))
    K[:, 0] = k0
    K[:, 1] = k1
    x_new = x + np.einsum("ij,j->i", K, y)
    IKH = _EYE4.copy()  # I - K H
    IKH[:, 0:2] -= K
    P_new = IKH @ P @ IKH.T + (r2 * K) @ K.T  # K R Kᵀ with R = r² I: K R is exactly r² K
    P_new = 0.5 * (P_new + P_new.T)
    return x_new, P_new


# --------------------------------------------------------------------------------------------------
# The tracker
# --------------------------------------------------------------------------------------------------


class LaserPeopleTracker:
    """Seed 001's laser people tracker (module docstring): walking-model particle filters, B7's situation
    switch, merged targets split back by motion, births and deaths at the edge of the covered area.

    Parameters
    ----------
    params : TrackerParams or mapping, optional
        Defaults: :class:`TrackerParams` (ALGORITHMS.md values).
    area_m : rectangle ``(x_min, y_min, x_max, y_max)`` or polygon ``(m, 2)``, optional
        The covered area (world frame). ``None``: no edge, every birth and death is an interior one. It
        may be set later through :attr:`area_m` (e.g. once the scanners' backgrounds are learnt).
    rng : numpy.random.Generator or int, optional
        Source of all randomness (particles, resampling).
    extra_log_likelihood : callable, optional
        Fusion hook (seed 001 B16; :mod:`fusiontrack.fusion`): ``f(t_ns, track_ids (n,), centres_m (n, n_p, 2))
        -> (n, n_p) log-likelihood or None``, added to the laser log-likelihood of the particles (feet midpoints)
        of the *correlated* walking targets that have a detection. ``None`` (default): laser only.
    split_scores : callable, optional
        Fusion hook (seed 001 B17): ``f(t_ns, member_ids (m,), detection_centres_m (n_d, 2)) -> (n_d, m) scores
        or None``; when it gives finite scores, a splitting merged target's members go to the detections by the
        Hungarian algorithm on ``-score`` (appearance) instead of on their predicted positions (motion). The split
        event's attributes say which decided (``"identity"``) and whether it differed from motion
        (``"overrode_motion"``). ``None`` (default): motion only.
    **overrides
        Any :class:`TrackerParams` field, e.g. ``lateral_m=0.2``.

    Attributes
    ----------
    events : list of Event
        The events of the last :meth:`step`.
    dropped_steps : int
        Steps ignored because their time was not after the previous step's (out of order).
    """

    _WALKING_ARRAYS = ("_w", "_id", "_seen", "_pos", "_lag", "_vel", "_slow", "_standing", "_born",
                       "_born_edge")

    def __init__(self, params: TrackerParams | Mapping[str, Any] | None = None, *, area_m: Any = None,
                 rng: np.random.Generator | int | None = None,
                 extra_log_likelihood: Callable[[int, np.ndarray, np.ndarray], np.ndarray | None] | None = None,
                 split_scores: Callable[[int, tuple[int, ...], np.ndarray], np.ndarray | None] | None = None,
                 **overrides: Any) -> None:
        self.params = p = _params(params, overrides)
        # fusion hooks (seed 001 B16, B17), off by default: see the class docstring
        self._extra_ll = extra_log_likelihood
        self._split_scores = split_scores
        self._next_id = itertools.count(1)
        self._vehicles: Any = None
        self._vehicle_ids: set[int] = set()
        if p.vehicles:
            from .baseline import CVKalmanTracker

            self._vehicles = CVKalmanTracker(q=p.vehicle_q, r_m=p.vehicle_sigma_m, gate_m=p.vehicle_gate_m,
                                             n_confirm=p.vehicle_n_confirm, n_miss=p.vehicle_n_miss, frame_s=p.frame_s,
                                             candidate_gate_m=p.vehicle_candidate_gate_m,
                                             candidate_gap_s=p.candidate_gap_s, d_edge_m=p.d_edge_m,
                                             sensor=p.sensor, ids=self._next_id,
                                             cls=str(ObjectClass.UNKNOWN))
        self.area_m = area_m
        self.rng = _rng(rng)
        self._t: int | None = None
        self.events: list[Event] = []
        self.dropped_steps = 0
        n_p = p.n_particles
        # walking targets, one row each; the particles in the column layout (8, n_targets, n_particles):
        # self._x[c] is column c (walking.py) of every particle
        self._x = np.zeros((8, 0, n_p))
        self._w = np.zeros((0, n_p))
        self._id = np.zeros(0, np.int64)
        self._seen = np.zeros(0, np.int64)  # time of the last detection
        self._pos = np.zeros((0, 2))  # estimated body position
        self._lag = np.zeros((0, 2))  # lagged body position (velocity estimate)
        self._vel = np.zeros((0, 2))
        self._slow = np.zeros(0, np.int64)
        self._standing = np.zeros(0, bool)
        self._born = np.zeros(0, np.int64)
        self._born_edge = np.zeros(0, bool)
        self._merged: list[_Merged] = []
        self._cand = CandidateSet(p.candidate_gate_m, p.candidate_gap_s)
        # track id -> [correlated (confirmed state), start of a change of state (0: none), last step with a detection,
        # open run [start, last, position] or None, ended run held for correlated_gap_s or None]
        self._corr: dict[int, list[Any]] = {}
        self._held_splits: dict[frozenset[int], Event] = {}
        self._merge_wait: dict[frozenset[int], tuple[int, int]] = {}  # ids -> (first, last step) of rule 1
        self._frame_ns = p.frame_s * 1e9
        self._sensors = (p.sensor,)
        self._reseed_at = 0

    # ---------------------------------------------------------------------------------------------
    @property
    def area_m(self) -> np.ndarray | None:
        """The covered area as polygon vertices ``(m, 2)``, or ``None``."""
        return self._area

    @area_m.setter
    def area_m(self, value: Any) -> None:
        self._area = area_polygon(value)
        self._rect = None
        if self._vehicles is not None:
            self._vehicles.area_m = self._area
        a = self._area
        if a is not None and a.shape == (4, 2):  # an axis-aligned rectangle: a cheaper edge test
            xs, ys = np.unique(a[:, 0]), np.unique(a[:, 1])
            if xs.size == 2 and ys.size == 2 and all(
                    ((a[i, 0] == a[(i + 1) % 4, 0]) != (a[i, 1] == a[(i + 1) % 4, 1])) for i in range(4)):
                self._rect = (xs[0], ys[0], xs[1], ys[1])

    @property
    def n_targets(self) -> int:
        """Live targets: walking targets plus the members of merged targets (not the vehicles)."""
        return int(self._id.size) + sum(len(m.info) for m in self._merged)

    @property
    def vehicle_ids(self) -> frozenset[int]:
        """Every id given so far to a vehicle track (a rigid object's, constant velocity), ended ones too."""
        return frozenset(self._vehicle_ids)

    @property
    def n_vehicles(self) -> int:
        """Live vehicle tracks (constant velocity, on the detector's rigid objects)."""
        return 0 if self._vehicles is None else self._vehicles.n_tracks

    @property
    def merged_ids(self) -> frozenset[int]:
        """The ids of the members of merged targets (tracked as one; ``merged`` or, while splitting,
        ``correlated`` in their states)."""
        return frozenset(tid for m in self._merged for tid in m.ids)

    def _frames_ns(self, n: int) -> int:
        return round(n * self._frame_ns)

    def _inside_m(self, points: np.ndarray) -> np.ndarray | None:
        """Signed distance of ``points (n, 2)`` to the boundary of the covered area, positive inside (None without
        an area, or without points)."""
        if self._area is None or points.shape[0] == 0:
            return None
        if self._rect is not None:
            x0, y0, x1, y1 = self._rect
            x, y = points[:, 0], points[:, 1]
            return np.minimum(np.minimum(x - x0, x1 - x), np.minimum(y - y0, y1 - y))
        return boundary_distance(points, self._area)

    def _edge(self, points: np.ndarray) -> np.ndarray:
        """True for points on the edge band or outside the covered area (B7 rules 5-6), ``(n,)`` bool."""
        d = self._inside_m(points)
        return np.zeros(points.shape[0], bool) if d is None else d < self.params.d_edge_m

    def _outside(self, points: np.ndarray) -> np.ndarray:
        """True for points outside the covered area (never without one), ``(n,)`` bool."""
        d = self._inside_m(points)
        return np.zeros(points.shape[0], bool) if d is None else d < 0

    # ---------------------------------------------------------------------------------------------
    def step(self, t_ns: int, detections: Sequence[Detection]) -> list[TrackState]:
        """Advance to ``t_ns`` with the laser detections of that instant (world frame).

        Returns one state per confirmed live track; the events of the step are in :attr:`events`. A step
        whose time is not after the previous one is ignored (counted in :attr:`dropped_steps`; returns
        ``[]``).
        """
        t_ns = int(t_ns)
        self.events = []
        if self._t is not None and t_ns <= self._t:
            self.dropped_steps += 1
            log.debug("tracker: step at %d ns is not after the previous one (%d ns); ignored", t_ns, self._t)
            return []
        dt = 0.0 if self._t is None else min((t_ns - self._t) / 1e9, self.params.max_dt_s)
        self._t = t_ns
        rigid: list[Detection] = []
        if self._vehicles is not None and any(_rigid(d) for d in detections):
            rigid = [d for d in detections if _rigid(d)]
            detections = [d for d in detections if not _rigid(d)]
        det = detection_arrays(detections)
        self._predict(dt)
        states = self._update(t_ns, dt, det)
        if self._vehicles is not None and (rigid or not self._vehicles.idle):
            cars = self._vehicles.step(t_ns, rigid)
            self._vehicle_ids.update(s.track_id for s in cars)
            states.extend(cars)
            self.events.extend(self._vehicles.events)
        return states

    def finish(self) -> list[Event]:
        """End of a run: the events still held back (correlated runs still open, splits waiting to be sure)."""
        self.events = []
        for tid in list(self._corr):
            self._close_correlated(tid)
        self.events.extend(self._held_splits.values())
        self._held_splits.clear()
        out, self.events = self.events, []
        return out

    def exchange_ids(self, a: int, b: int) -> bool:
        """Swap the ids of two live targets from now on (e.g. an identity check found them exchanged).

        Walking targets' ids, merged members' ids, open correlated runs and the keys of held-back splits follow
        the swap; events already emitted keep the ids of their time. Returns False (nothing changed) unless
        ``a`` and ``b`` are two distinct live targets.
        """
        a, b = int(a), int(b)
        if a == b:
            return False
        walking = {a: np.flatnonzero(self._id == a), b: np.flatnonzero(self._id == b)}
        members = {tid: [info for m in self._merged for info in m.info if info.track_id == tid] for tid in (a, b)}
        if any(walking[tid].size + len(members[tid]) != 1 for tid in (a, b)):
            return False
        swap = {a: b, b: a}
        rows_a, rows_b = walking[a], walking[b]
        self._id[rows_a], self._id[rows_b] = b, a
        for tid in (a, b):
            for info in members[tid]:
                info.track_id = swap[tid]
        runs = self._corr
        ra, rb = runs.pop(a, None), runs.pop(b, None)
        if ra is not None:
            runs[b] = ra
        if rb is not None:
            runs[a] = rb
        if self._held_splits:
            self._held_splits = {frozenset(swap.get(t, t) for t in key): ev for key, ev in self._held_splits.items()}
        if self._merge_wait:
            self._merge_wait = {frozenset(swap.get(t, t) for t in key): v for key, v in self._merge_wait.items()}
        return True

    # ---------------------------------------------------------------------------------------------
    def _predict(self, dt: float) -> None:
        p = self.params
        if dt <= 0:
            return
        if self._id.size:
            self._x = predict_people_cols(self._x, self._standing, dt, self.rng, p.walking_noise, p.standing_noise)
        if self._merged:
            fq = _CV_MATRICES.get((dt, p.merged_q))
            if fq is None:  # the same few step lengths over and over: cache them
                if len(_CV_MATRICES) > 256:
                    _CV_MATRICES.clear()
                fq = _CV_MATRICES[(dt, p.merged_q)] = kalman.cv_matrices(dt, p.merged_q)
            F, Q = fq
            for m in self._merged:
                m.x = F @ m.x
                m.P = F @ m.P @ F.T + Q
                m.predict(dt, p.member_tau_s)

    def _walking_centres(self, mid: np.ndarray | None = None) -> np.ndarray:
        """Particle mean of the feet midpoint of every walking target, ``(n_t, 2)``; ``mid`` (``(2, n_t, n_p)``,
        the feet sums of the current particles, :meth:`_feet_sums`) when the caller already has it.

        ``0.5 Σ_p w_tp mid_tp``, summed particle after particle: the products go to a ``(n_p, n_t, 2)`` buffer
        whose reduction over its outer axis adds them in order (the sums ``einsum("tp,tpk->tk")`` makes of the
        row layout, bit for bit; a reduction along a contiguous axis would sum pairwise).
        """
        if _jit.ENABLED:
            out = np.empty((self._w.shape[0], 2))
            _jit.centres(self._x, self._w, out)
            return out
        if mid is None:
            mid = self._feet_sums()
        w = self._w
        prod = np.empty((w.shape[1], w.shape[0], 2))
        np.multiply(w.T[:, :, None], mid.transpose(2, 1, 0), out=prod)
        return 0.5 * np.add.reduce(prod, axis=0)

    def _ll_params(self) -> np.ndarray:
        """The likelihood's constants for :func:`_jit.update`: 1/(2σ_f²), 1/(2σ_f,one²), 1/(2σ_w²), κ, lateral."""
        p = self.params
        cached = self.__dict__.get("_llp")
        if cached is None or cached[0] is not p:
            prm = np.array([1.0 / (2.0 * p.sigma_f_m**2), 1.0 / (2.0 * p.sigma_f_one_m**2),
                            1.0 / (2.0 * p.sigma_w_m**2), p.kappa, p.lateral_m])
            cached = self.__dict__["_llp"] = (p, prm)
        return cached[1]

    def _feet_sums(self) -> np.ndarray:
        """``left + right`` foot position of every particle, ``(2, n_t, n_p)``."""
        x = self._x
        return x[0:2] + x[2:4]

    def _update(self, t_ns: int, dt: float, det: DetectionArrays) -> list[TrackState]:
        p = self.params
        merged = self._merged
        n_w, n_m, n_d = self._id.size, len(merged), len(det)
        n_t = n_w + n_m
        # the particles do not move until the resampling (but for a re-acquisition)
        mid = None if _jit.ENABLED else self._feet_sums()
        cw = self._walking_centres(mid)
        if n_m:
            centres = np.concatenate([cw, np.array([m.x[0:2] for m in merged])])
            # a merged target gates with each of its members: one matrix for every walking target and member,
            # then each merged target's rows reduced to their minimum (the same values as one matrix each)
            sizes = [m.pos.shape[0] for m in merged]
            G = gate_distances(np.concatenate([cw] + [m.pos for m in merged]), det.centres, p.bandwidth_m)
            D = np.concatenate([G[:n_w], np.minimum.reduceat(G[n_w:], _starts(sizes), axis=0)]) if n_d else G[:n_t]
        else:
            centres = cw
            D = gate_distances(cw, det.centres, p.bandwidth_m)
        c, r, found = association_states(D, p.gate)
        if n_d:  # one edge test for targets and detections
            edge = self._edge(np.concatenate([centres, det.centres]))
            edge_t, edge_d = edge[:n_t], edge[n_t:]
        else:
            edge_t, edge_d = self._edge(centres), self._edge(det.centres)
        merged_mask = np.zeros(n_t, bool)
        merged_mask[n_w:] = True
        sf = classify_situations(c, r, found, merged_mask, edge_t, edge_d, D)
        labels = sf.target_labels
        merge_groups = sf.merge_groups
        if p.cap_merges and merge_groups and det.points:
            labels, merge_groups = self._cap_merges(labels, merge_groups, D, det)
        if p.n_merge > 1 and (merge_groups or self._merge_wait):
            labels, merge_groups = self._confirm_merges(sf, labels, merge_groups, t_ns)

        # ---- one detection per target (B10 nearest neighbour, one-to-one by Hungarian when contested)
        want = _WANTS_DETECTION[labels]  # NONCORRELATED, CORRELATED or MERGED
        assigned = np.full(n_t, -1, np.int64)
        rows = want.nonzero()[0]
        if rows.size and n_d:
            nearest = sf.nearest_det[rows]
            ok = nearest >= 0
            near_ok = nearest[ok].tolist()
            if len(set(near_ok)) == len(near_ok):  # no detection wanted twice
                assigned[rows] = nearest
            else:
                cost = np.where(found[rows], D[rows], np.inf)
                pairs, _, _ = hungarian(cost, gate=p.gate)
                assigned[rows[pairs[:, 0]]] = pairs[:, 1]
        claimed = r > 0  # found by a target: no birth, unless B7 rule 2 makes it a split candidate
        if n_d:
            claimed[sf.split_candidates] = False
            claimed[assigned[assigned >= 0]] = True

        # ---- walking targets that found nothing may re-acquire an unclaimed detection nearby
        lost = (c[:n_w] == 0).nonzero()[0]
        if lost.size and n_d and not _all(claimed) and self._reacquire(lost, cw, det, claimed, assigned, t_ns):
            mid = None if _jit.ENABLED else self._feet_sums()  # some targets restarted: new particles

        # ---- walking targets: B9 likelihood with the assigned detection, resample (X1, B10)
        aw = assigned[:n_w]
        upd = aw >= 0
        n_upd = np.count_nonzero(upd)
        if n_upd and _jit.ENABLED and self._extra_ll is None:
            # one kernel: likelihood, reweight, centres, resampling (the resampling's uniforms drawn first: nothing
            # else draws in between)
            u = self.rng.random(n_upd)
            x, w = self._x, self._w
            ll, w_new, out_w, pos = np.empty(w.shape), np.empty(w.shape), np.empty(w.shape), np.empty((n_w, 2))
            out_x = np.empty_like(x)
            if _jit.update(x, w, det.feet, det.inter_feet, det.one_foot, aw, u, self._ll_params(), ll, w_new,
                           out_x, out_w, pos):
                self._x, self._w = out_x, out_w
            else:  # numpy's general reweight (a row with no finite log-weight), then the same resampling
                self._w, _ = reweight(w, ll)
                pos = self._walking_centres(None)
                self._x, self._w = resample_where_cols(x, self._w, upd, u0=u / p.n_particles)
            self._seen[upd] = t_ns
        elif n_upd:
            if n_upd == n_w:  # every walking target has a detection
                feet, sd, one, missing = det.feet[aw], det.inter_feet[aw], det.one_foot[aw], np.zeros(n_w, bool)
            else:  # the others' rows: zeros, flagged missing (log-likelihood 0)
                feet = np.zeros((n_w, 2, 2))
                sd = np.zeros(n_w)
                one = np.zeros(n_w, bool)
                j = aw[upd]
                feet[upd], sd[upd], one[upd] = det.feet[j], det.inter_feet[j], det.one_foot[j]
                missing = ~upd
            ll = laser_log_likelihood_cols(self._x, feet, sd, one, p.sigma_f_m, p.sigma_w_m,
                                           sigma_f_one=p.sigma_f_one_m, kappa=p.kappa, lateral_m=p.lateral_m,
                                           missing=missing)
            if self._extra_ll is not None:  # fusion hook (B16): the camera's score map for correlated targets
                corr = (upd & (labels[:n_w] == _CORRELATED)).nonzero()[0]
                if corr.size:
                    xc = self._x[:, corr]
                    mid_c = np.ascontiguousarray(np.moveaxis(0.5 * (xc[0:2] + xc[2:4]), 0, -1))  # (n, n_p, 2)
                    extra = self._extra_ll(t_ns, self._id[corr].copy(), mid_c)
                    if extra is not None:
                        ll[corr] = ll[corr] + np.asarray(extra, np.float64)
            self._w, _ = reweight(self._w, ll)
            self._seen[upd] = t_ns
            pos = self._walking_centres(mid)
            self._x, self._w = resample_where_cols(self._x, self._w, upd, self.rng)
        else:
            pos = cw
        self._track_velocity(pos, dt)

        # ---- merged targets: members from the segment points, Kalman update on the centre
        split_now: dict[int, np.ndarray] = {}  # merged targets that split now -> the detections they split into
        apart = np.zeros(n_m, bool)  # merged targets seen apart this step (rule 2's split, or its completion)
        dissolve: list[tuple[int, int]] = []
        sensed_m = np.zeros(n_m, bool)
        for i, m in enumerate(merged):
            row = n_w + i
            if m.split_since and t_ns - m.split_last > self._cand.gap_ns:
                m.split_since = 0  # the split condition has been gone for a while: start again
            js = None
            if labels[row] == _SPLITTING:
                js = found[row].nonzero()[0]
            elif labels[row] == _MERGED and c[row] == 2 and len(m.info) >= 2:
                # seen apart [RECON]: as many detections nearer to it than to any other target (and assigned to no
                # other) as it has members splits it as B7 rule 2's do. Rule 2 wants them found by it alone, but a
                # neighbour's gate often holds one: two people standing 0.6 m apart stayed merged for seconds, one
                # member's estimate left behind while the neighbour's track took its person's legs (72 runs, 30 s,
                # laser-only: groups ID switches 86 -> 23, crowd 176 -> 146)
                others = set(np.delete(assigned, row).tolist())
                own = [j for j in _own_detections(D, found, row).tolist() if j not in others]
                if len(own) >= len(m.info):
                    js = np.array(own, np.int64)
            if js is not None:
                apart[i] = True
                if m.split_since == 0:
                    m.split_since = t_ns
                m.split_last = t_ns
                if (t_ns - m.split_since >= self._frames_ns(p.n_split - 1) and len(m.info) >= 2
                        and _max_pair_distance(det.centres[js]) >= p.split_min_m):
                    split_now[i] = js
                    claimed[js] = True
            else:
                a = int(assigned[row])
                js = np.array([a], np.int64) if a >= 0 else _NO_INDEX
            if js.size == 0:
                continue
            js_l = js.tolist()
            # one detection: its centre (the mean of one row is that row); else the mean, as np.mean sums / n
            z = det.centres[js_l[0]].copy() if len(js_l) == 1 else det.centres[js].mean(axis=0)
            pts = [det.points[j] for j in js_l] if det.points else []
            if pts and all(q is not None for q in pts):  # (one segment: its own points, read only)
                points = pts[0] if len(pts) == 1 else np.concatenate(pts)
            else:
                points = None
            m.correct(points, z, dt, p.member_alpha, p.member_beta, p.member_min_gap_m, frame_s=p.frame_s)
            m.x, m.P = _merged_kalman_update(m.x, m.P, z, p.merged_r_m**2)
            m.seen = t_ns
            m.seen_by = self._seen_by(det, js_l)
            m.member_seen = None
            if len(js_l) > 1 and det.scanners:  # seen apart: each member by the detection nearest to it
                near = np.argmin(np.linalg.norm(m.pos[:, None] - det.centres[js][None], axis=2), axis=1)
                m.member_seen = [self._seen_by(det, (js_l[q],)) for q in near.tolist()]
            sensed_m[i] = True
            if points is not None and i not in split_now:  # one person's legs only, for a while: dissolve
                if js.size >= 2:
                    m.multi_last = t_ns
                    m.unchecked.clear()
                else:
                    m.unchecked.append((t_ns, points))
                    # single_s since the last frame with more than one person (leg blobs counted lazily): dissolve
                    if t_ns - m.multi_last >= p.single_s * 1e9 and not _settle_multi(m, t_ns, p.blob_radius_m) \
                            and t_ns - m.multi_last >= p.single_s * 1e9:
                        dissolve.append((i, int(js[0])))

        # ---- deaths: coasting too long, or missing on the edge
        w_labels = labels[:n_w]
        miss = t_ns - self._seen
        settled = t_ns - self._born >= p.edge_min_age_s * 1e9  # who just came in does not leave at once
        leaving_w = w_labels == _DISAPPEARING
        leaving_m = labels[n_w:] == _DISAPPEARING
        if p.edge_leave_s > 0 and (np.any(leaving_w) or np.any(leaving_m)):
            # only who is heading out disappears at once: the position edge_leave_s ahead lies outside the area
            # (a merged target: every member; its centre's velocity follows a segment that grows and shrinks)
            ahead = np.concatenate([self._pos + self._vel * p.edge_leave_s]
                                   + [m.pos + m.vel * p.edge_leave_s for m in merged])
            out = self._outside(ahead)
            leaving_w = leaving_w & out[:n_w]
            if n_m:
                leaving_m = leaving_m & np.logical_and.reduceat(out[n_w:], _starts([len(m.info) for m in merged]))
        dead_w = (leaving_w & settled & (miss > self._frames_ns(p.n_miss_edge))) | (
            (aw < 0) & (miss > self._frames_ns(p.n_miss)))
        dead_m = np.zeros(n_m, bool)
        for i, m in enumerate(merged):
            mmiss = t_ns - m.seen
            dead_m[i] = (leaving_m[i] and mmiss > self._frames_ns(p.n_miss_edge)) or (
                mmiss > self._frames_ns(p.n_miss))
        gone_w = dead_w.copy()
        gone_m = dead_m.copy()
        new_merged: list[_Merged] = []
        new_walkers: list[dict[str, Any]] = []

        # ---- candidates followed; one ready to be born beside a merged target may be a member leaving it
        free = (~claimed).nonzero()[0]
        ready = used = _NO_INDEX
        births_due = bool(free.size or len(self._cand))
        if births_due:
            ready = self._ready_births(t_ns, det, free, edge_d)
            if ready.size and n_m and p.split_birth_m > 0:
                used = self._births_that_split(t_ns, det, free, ready, labels, assigned, dead_m | apart, split_now)

        # ---- merges (B7 rule 1, B17): targets sharing one detection become one merged target
        groups = merge_groups if n_t else {}
        if groups:
            dead = np.concatenate([dead_w, dead_m])
            for j, group in groups.items():
                group = group[~dead[group]]
                if group.size >= 2:
                    new_merged.append(self._merge(group, j, det, t_ns, gone_w, gone_m))

        # ---- splits (B7 rule 2, B17): identity recovery by motion
        for i, js in split_now.items():
            if not gone_m[i]:
                self._split(merged[i], js, det, t_ns, new_merged, new_walkers)
                gone_m[i] = True

        # ---- merged targets that hold one person only: the member nearest to it goes on, the others end
        for i, j in dissolve:
            if gone_m[i]:
                continue
            m = merged[i]
            keep = int(np.argmin(np.linalg.norm(m.pos - det.centres[j], axis=1)))
            info, v = m.info[keep], m.vel[keep]
            new_walkers.append(self._new_walker(
                info.track_id, det, j, v, info.heading_rad, t_ns, period_s=info.period_s, stride_m=info.stride_m,
                standing=info.standing, born_ns=info.born_ns, born_edge=info.born_edge))
            for k, other in enumerate(m.info):
                if k != keep:
                    self._death_event(other.track_id, m.seen, t_ns, m.pos[k], False)
            gone_m[i] = True

        # ---- outputs of the old rows that live on
        states: list[TrackState] = []
        sensor, sensors = p.sensor, self._sensors
        by = det.scanners  # (the scanners of each detection, if the detector names them)
        aw_l = aw.tolist() if by else ()
        appear_ns = p.appear_window_s * 1e9
        # (Python scalars from tolist(): the same values, without numpy scalar indexing per row)
        w_lab_l, id_l, born_edge_l, born_l, upd_l = (w_labels.tolist(), self._id.tolist(), self._born_edge.tolist(),
                                                     self._born.tolist(), upd.tolist())
        leaving_l = leaving_w.tolist()
        pos_w, vel_w = self._pos, self._vel
        pos_f, vel_f = _frozen_copy(pos_w), _frozen_copy(vel_w)
        corr = self._corr
        for row in (~gone_w).nonzero()[0].tolist():
            lab = w_lab_l[row]
            tid = id_l[row]
            sit = _SITUATION_NAMES[lab]
            if lab == _DISAPPEARING and not leaving_l[row]:  # (edge_leave_s) not heading out: coasting
                sit = _NONCORRELATED_S
            if lab == _NONCORRELATED and born_edge_l[row] and t_ns - born_l[row] < appear_ns:
                sit = _APPEARING
            if (lab == _CORRELATED or tid in corr) and lab != _COASTING and lab != _DISAPPEARING:
                self._correlated_step(tid, t_ns, lab == _CORRELATED, pos_w[row])
            seen = (by[aw_l[row]] or sensors if by else sensors) if upd_l[row] else ()
            states.append(_fast_state(t_ns, sensor, tid, pos_f[row], vel_f[row], sit, seen, frozen=True))
        for i in (~gone_m).nonzero()[0].tolist():
            m = merged[i]
            lab = int(labels[n_w + i])
            # its gate holds detections enough for its members (B7 rule 2's split condition, or as many detections
            # nearer to it than to any other target, and assigned to no other, as it has members: the same test as
            # its split's above): the members are seen apart, correlated (B7 rule 3), while the merged target holds
            seen_apart = bool(apart[i])
            if seen_apart:
                sit = _CORRELATED_S
            elif lab == _DISAPPEARING and leaving_m[i]:
                sit = _DISAPPEARING_S
            else:
                sit = _MERGED_S
            mpos, mvel = _frozen_copy(m.pos), _frozen_copy(m.vel)
            if sensed_m[i] and lab != _DISAPPEARING:  # members are correlated while they are seen apart
                self._members_correlated(m, t_ns, seen_apart)
            for k, info in enumerate(m.info):
                own = m.member_seen
                seen = (m.seen_by if own is None or len(own) != len(m.info) else own[k]) if sensed_m[i] else ()
                states.append(_fast_state(t_ns, sensor, info.track_id, mpos[k], mvel[k], sit, seen, frozen=True))
        for row in dead_w.nonzero()[0]:
            self._death_event(int(self._id[row]), int(self._seen[row]), t_ns, self._pos[row], bool(edge_t[row]))
        for i in dead_m.nonzero()[0]:
            m = merged[i]
            for k, info in enumerate(m.info):
                self._death_event(info.track_id, m.seen, t_ns, m.pos[k], bool(edge_t[n_w + i]))

        # ---- apply the structure changes
        if np.count_nonzero(gone_w):
            keep = ~gone_w
            self._x = np.ascontiguousarray(self._x[:, keep])
            for name in self._WALKING_ARRAYS:
                setattr(self, name, getattr(self, name)[keep])
        if np.count_nonzero(gone_m) or new_merged:
            self._merged = [m for m, g in zip(merged, gone_m, strict=True) if not g] + new_merged
        for m in new_merged:
            if self._corr:  # the merge step is a merged frame of their correlated runs
                self._members_correlated(m, t_ns, False)
            for k, info in enumerate(m.info):
                states.append(_fast_state(t_ns, sensor, info.track_id, m.pos[k], m.vel[k], _MERGED_S, m.seen_by))
        for spec in new_walkers:
            seen = spec.pop("seen_by")
            self._add_walking(**spec)
            states.append(_fast_state(t_ns, sensor, spec["track_id"], spec["pos"], spec["vel"], _NONCORRELATED_S, seen))

        # ---- births (B7 rule 6): candidates from unclaimed detections
        if births_due:
            states.extend(self._births(t_ns, det, free, ready, used))

        # ---- correlated runs that ended, splits that were not undone
        if self._corr:
            gap = p.correlated_gap_s * 1e9
            for tid in [tid for tid, rec in self._corr.items() if rec[4] is not None and t_ns - rec[4][1] > gap]:
                rec = self._corr[tid]
                self._emit_correlated(tid, rec[4])
                rec[4] = None
                if not rec[0] and not rec[1] and rec[3] is None:
                    del self._corr[tid]
        if self._held_splits:
            hold = p.split_hold_s * 1e9
            for key in [k for k, e in self._held_splits.items() if t_ns - e.t_ns > hold]:
                self.events.append(self._held_splits.pop(key))
        return states

    # ---------------------------------------------------------------------------------------------
    def _cap_merges(self, labels: np.ndarray, groups: dict[int, np.ndarray], D: np.ndarray, det: DetectionArrays
                    ) -> tuple[np.ndarray, dict[int, np.ndarray]]:
        """``cap_merges`` (see :class:`TrackerParams`): each merge group cut to the people its segment shows,
        nearest targets first; the labels with the targets left out ``correlated`` (merged targets ``merged``)."""
        n_w = self._id.size
        labels = labels.copy()
        out: dict[int, np.ndarray] = {}
        for j, rows in groups.items():
            points = det.points[j]
            if points is None:  # no points to count legs on: B7 as written
                out[j] = rows
                continue
            cap = max(2, -(-count_blobs(points, self.params.blob_radius_m) // 2))
            kept: list[int] = []
            people = 0
            for row in rows[np.argsort(D[rows, j], kind="stable")].tolist():
                size = 1 if row < n_w else len(self._merged[row - n_w].info)
                if not kept or people + size <= cap:
                    kept.append(row)
                    people += size
            if len(kept) >= 2:
                out[j] = np.array(sorted(kept), np.int64)
            left = np.setdiff1d(rows, out.get(j, _NO_INDEX))
            labels[left] = np.where(left < n_w, _CORRELATED, _MERGED)
        return labels, out

    def _confirm_merges(self, sf: Any, labels: np.ndarray, groups: dict[int, np.ndarray], t_ns: int
                        ) -> tuple[np.ndarray, dict[int, np.ndarray]]:
        """B7 rule 1 confirmed over ``n_merge`` frames (see :class:`TrackerParams`): the groups that merge now, and
        ``labels`` (a copy) with the waiting groups' walking targets ``correlated`` (merged targets stay
        ``merged``)."""
        n_w = self._id.size
        ids_of = [(int(t),) for t in self._id.tolist()] + [tuple(m.ids) for m in self._merged]
        labels = labels.copy()
        need, gap = self._frames_ns(self.params.n_merge - 1), self._cand.gap_ns
        wait = self._merge_wait
        now, out = set(), {}
        for j, rows in groups.items():
            key = frozenset(i for row in rows.tolist() for i in ids_of[row])
            now.add(key)
            first, last = wait.get(key, (t_ns, t_ns))
            if t_ns - last > gap:
                first = t_ns
            if t_ns - first >= need:
                out[j] = rows
                wait.pop(key, None)
            else:
                wait[key] = (first, t_ns)
                labels[rows] = np.where(rows < n_w, _CORRELATED, _MERGED)
        if len(wait) > len(now):  # waiting groups not sharing a detection this step: apart, or not seen
            row_of = {i: row for row, ids in enumerate(ids_of) for i in ids}
            nearest = sf.nearest_det.tolist()
            for key in [k for k in wait if k not in now]:
                rows = {row_of.get(i, -1) for i in key}
                dets = [nearest[row] for row in rows if row >= 0]
                apart = len(dets) >= 2 and min(dets) >= 0 and len(set(dets)) == len(dets)
                if apart or -1 in rows or t_ns - wait[key][1] > gap:
                    del wait[key]
        return labels, out

    def _reacquire(self, lost: np.ndarray, cw: np.ndarray, det: DetectionArrays, claimed: np.ndarray,
                   assigned: np.ndarray, t_ns: int) -> bool:
        """Targets that found nothing take unclaimed detections within a gate that grows while they coast.
        Returns whether any did (their particles restarted)."""
        p = self.params
        free = (~claimed).nonzero()[0]
        miss_s = (t_ns - self._seen[lost]) / 1e9
        radius = np.minimum(2.0 * p.bandwidth_m + p.reacquire_speed_mps * miss_s, p.reacquire_max_m)
        dist = np.linalg.norm(cw[lost][:, None, :] - det.centres[free][None, :, :], axis=2)
        cost = np.where(dist <= radius[:, None], dist, np.inf)
        pairs, _, _ = hungarian(cost)
        for a, b in pairs:
            row, j = int(lost[a]), int(free[b])
            x, w = self._particles(row), self._w[row]
            v = det.centres[j] - self._pos[row]
            heading = float(np.arctan2(v[1], v[0])) if np.hypot(*v) >= 0.1 else float(
                np.arctan2(w @ np.sin(x[:, PSI]), w @ np.cos(x[:, PSI])))
            spec = self._new_walker(int(self._id[row]), det, j, self._vel[row], heading, t_ns,
                                    period_s=float(w @ x[:, PERIOD]), stride_m=float(w @ x[:, STRIDE]),
                                    standing=bool(self._standing[row]))
            self._x[:, row] = spec["x"].T
            self._w[row] = 1.0 / p.n_particles
            assigned[row] = j
            claimed[j] = True
        return len(pairs) > 0

    def _particles(self, row: int) -> np.ndarray:
        """The particles of walking target ``row`` as rows, ``(n_p, 8)`` C-contiguous (the array the row layout
        held: reductions over it, e.g. ``w @ x[:, PERIOD]``, give the values they gave)."""
        return np.ascontiguousarray(self._x[:, row].T)

    def _merge(self, group: np.ndarray, j: int, det: DetectionArrays, t_ns: int, gone_w: np.ndarray,
               gone_m: np.ndarray) -> _Merged:
        """A merged target from the targets (rows; walking first, then merged) that share detection ``j``."""
        p = self.params
        n_w = self._id.size
        pos, vel, info, parts = [], [], [], []
        for row in group:
            if row < n_w:
                x, w = self._particles(row), self._w[row]
                heading = float(np.arctan2(w @ np.sin(x[:, PSI]), w @ np.cos(x[:, PSI])))
                info.append(_MemberInfo(int(self._id[row]), float(w @ x[:, PERIOD]), float(w @ x[:, STRIDE]),
                                        heading, bool(self._standing[row]), int(self._born[row]),
                                        bool(self._born_edge[row])))
                pos.append(self._pos[row][None])
                vel.append(self._vel[row][None])
                parts.append((int(self._id[row]),))
                gone_w[row] = True
            else:
                m = self._merged[row - n_w]
                info.extend(m.info)
                pos.append(m.pos)
                vel.append(m.vel)
                parts.append(tuple(sorted(m.ids)))
                gone_m[row - n_w] = True
        mpos, mvel = np.concatenate(pos), np.concatenate(vel)
        centre = det.centres[j]
        r2 = p.merged_r_m**2
        out = _Merged(np.concatenate([centre, mvel.mean(axis=0)]), np.diag([r2, r2, 0.5**2, 0.5**2]), t_ns,
                      mpos, mvel, info, multi_last=t_ns, formed_ns=t_ns, seen_by=self._seen_by(det, (j,)))
        ids = tuple(sorted(out.ids))
        if self._held_splits.pop(frozenset(ids), None) is None:  # else: they had not really split
            self.events.append(Event(t_ns, p.sensor, "merge", t_ns, position_m=centre, track_ids=ids,
                                     attributes={"parts": tuple(sorted(parts))}))
        # (their correlated runs go on: a run ends when the merged label has held n_confirm frames, the truth's rule)
        return out

    def _split(self, m: _Merged, dets: np.ndarray, det: DetectionArrays, t_ns: int, new_merged: list[_Merged],
               new_walkers: list[dict[str, Any]]) -> None:
        """B17 identity recovery by motion: members to detections by Hungarian on their predicted positions."""
        p = self.params
        cost = np.linalg.norm(m.pos[:, None, :] - det.centres[dets][None, :, :], axis=2)
        pairs, un_members, _ = hungarian(cost)
        how: dict[str, Any] = {}  # the laser-only event is unchanged
        if self._split_scores is not None:  # fusion hook (B17): the members' classifiers say who is who
            how = {"identity": "motion"}
            scores = self._split_scores(t_ns, tuple(m.ids), det.centres[dets].copy())
            if scores is not None and np.isfinite(scores).all():
                by_look, un_look, _ = hungarian(-np.asarray(scores, np.float64).T)
                how = {"identity": "appearance", "overrode_motion": not np.array_equal(by_look, pairs)}
                pairs, un_members = by_look, un_look
        to_det = np.full(len(m.info), -1, np.int64)
        to_det[pairs[:, 0]] = pairs[:, 1]
        for k in un_members:  # more members than detections: the rest stay together at their nearest
            to_det[k] = int(np.argmin(cost[k]))
        parts = []
        for jj in np.unique(to_det):
            ks = (to_det == jj).nonzero()[0]
            parts.append(tuple(sorted(m.info[k].track_id for k in ks)))
            j = int(dets[jj])
            if ks.size == 1:
                k = int(ks[0])
                info, v = m.info[k], m.vel[k]
                speed = float(np.hypot(*v))
                heading = float(np.arctan2(v[1], v[0])) if speed > 0.2 else info.heading_rad
                new_walkers.append(self._new_walker(
                    info.track_id, det, j, v, heading, t_ns, period_s=info.period_s, stride_m=info.stride_m,
                    standing=info.standing and speed < p.resume_speed_mps, born_ns=info.born_ns,
                    born_edge=info.born_edge))
            else:
                r2 = p.merged_r_m**2
                new_merged.append(_Merged(np.concatenate([det.centres[j], m.vel[ks].mean(axis=0)]),
                                          np.diag([r2, r2, 0.5**2, 0.5**2]), t_ns, m.pos[ks].copy(),
                                          m.vel[ks].copy(), [m.info[k] for k in ks], multi_last=t_ns, formed_ns=t_ns,
                                          seen_by=self._seen_by(det, (j,))))
        ids = tuple(sorted(m.ids))  # held back for split_hold_s: a merge of the same people undoes it
        self._held_splits[frozenset(ids)] = Event(t_ns, p.sensor, "split", t_ns, position_m=m.x[0:2].copy(),
                                                  track_ids=ids, attributes={"parts": tuple(sorted(parts)), **how})

    def _ready_births(self, t_ns: int, det: DetectionArrays, free: np.ndarray, edge_d: np.ndarray) -> np.ndarray:
        """Follow the candidates with the unclaimed detections ``free``; the candidates confirmed now."""
        p = self.params
        cd = self._cand
        blobs = None
        if det.points and p.multi_fraction is not None:
            blobs = np.array([0 if det.points[j] is None else count_blobs(det.points[j], p.blob_radius_m)
                              for j in free], np.int64)
        cd.update(t_ns, det.centres[free], edge_d[free], blobs)
        return cd.ready(t_ns, self._frames_ns(p.n_confirm - 1), self._frames_ns(p.n_confirm_interior - 1))

    def _births_that_split(self, t_ns: int, det: DetectionArrays, free: np.ndarray, ready: np.ndarray,
                           labels: np.ndarray, assigned: np.ndarray, excluded: np.ndarray,
                           split_now: dict[int, np.ndarray]) -> np.ndarray:
        """Confirmed candidates that are a member leaving a merged target [RECON]; each such target (not
        ``excluded``: dead, or seen apart this step) is put in ``split_now`` with its own detection and the
        candidate's. Returns the candidates used so.

        A merged target of two people who came in side by side kept both members on one person once the other
        walked off: the one who left was out of its gate by the time the scanners saw them apart, was born again
        under a new id, and the merged target held a phantom member for seconds (its leg blobs flicker to three
        on one person, so the one-person rule did not end it). A candidate confirmed within ``split_birth_m`` of
        a merged target's detection (at least ``split_min_m`` from it), and first seen after the merged target was
        made and within ``split_birth_m`` of where it was then, is taken as that: the merged target splits onto the two
        detections, identities by motion (or by appearance, with the fusion hook), as B7 rule 2's splits do."""
        p = self.params
        cd = self._cand
        n_w = self._id.size
        hosts = [i for i, m in enumerate(self._merged) if len(m.info) >= 2 and labels[n_w + i] == _MERGED
                 and not excluded[i] and i not in split_now and assigned[n_w + i] >= 0 and m.seen == t_ns]
        used = []
        for k in ready.tolist():
            if not hosts:
                break
            j = int(free[cd.det[k]])
            back_s = (t_ns - int(cd.first_t[k])) / 1e9
            best, best_d = -1, math.inf
            for i in hosts:
                m = self._merged[i]
                if cd.first_t[k] < m.formed_ns:  # there before the merge: not one of its members
                    continue
                a = int(assigned[n_w + i])
                d_now = float(np.hypot(*(det.centres[j] - det.centres[a])))
                d_then = float(np.hypot(*(cd.first_pos[k] - (m.x[0:2] - m.x[2:4] * back_s))))
                if p.split_min_m <= d_now <= p.split_birth_m and d_then <= p.split_birth_m and d_now < best_d:
                    best, best_d = i, d_now
            if best >= 0:
                split_now[best] = np.array([int(assigned[n_w + best]), j], np.int64)
                hosts.remove(best)
                used.append(k)
        return np.array(used, np.int64)

    def _births(self, t_ns: int, det: DetectionArrays, free: np.ndarray, ready: np.ndarray, used: np.ndarray
                ) -> list[TrackState]:
        """New tracks from the candidates ``ready`` (but those ``used`` by a split), which then leave the set."""
        p = self.params
        cd = self._cand
        states = []
        skip = set(used.tolist())
        for k in ready:
            if k in skip:
                continue
            j = int(free[cd.det[k]])
            span = max((t_ns - int(cd.first_t[k])) / 1e9, 1e-3)
            v0 = (cd.pos[k] - cd.first_pos[k]) / span
            heading = float(np.arctan2(v0[1], v0[0])) if np.hypot(*v0) * span >= 0.1 else float("nan")
            edge = bool(cd.edge[k])
            if not edge and p.appear_latency_s > 0 and self.area_m is not None and np.isfinite(heading):
                # First seen inside, walking in: where was it appear_latency_s before it was first seen?
                back = cd.first_pos[k] - v0 * p.appear_latency_s
                edge = bool(self._edge(back[None])[0])
            first_t, first_pos = int(cd.first_t[k]), cd.first_pos[k]
            if not edge and cd.glimpses:
                g = self._glimpse(first_t, first_pos)
                if g is not None:
                    edge, first_t, first_pos = True, g[0], g[2]
            kind = "appear" if edge else "born"
            n_people = 1
            if (p.multi_fraction is not None and det.points and det.points[j] is not None
                    and cd.n_multi[k] >= p.multi_fraction * cd.hits[k]):
                n_people = 3 if cd.n_many[k] >= p.multi_fraction * cd.hits[k] else 2
                n_people = min(n_people, det.points[j].shape[0] // 2)
            if n_people >= 2:  # people who came together: born merged (B17), each with its own identity
                m = self._born_merged(det, j, n_people, v0, heading, t_ns, edge)
                self._merged.append(m)
                for q, info in enumerate(m.info):
                    self.events.append(Event(first_t, p.sensor, kind, t_ns, position_m=m.pos[q].copy(),
                                             track_ids=(info.track_id,)))
                    states.append(_fast_state(t_ns, p.sensor, info.track_id, m.pos[q], m.vel[q], _MERGED_S,
                                              m.seen_by))
                continue
            tid = next(self._next_id)
            spec = self._new_walker(tid, det, j, v0, heading, t_ns, born_edge=edge)
            seen = spec.pop("seen_by")
            self._add_walking(**spec)
            self.events.append(Event(first_t, p.sensor, kind, t_ns, position_m=first_pos.copy(), track_ids=(tid,)))
            states.append(_fast_state(t_ns, p.sensor, tid, spec["pos"], spec["vel"],
                                      _APPEARING if edge else _NONCORRELATED_S, seen))
        if ready.size:
            cd.pop(ready)
        if cd.glimpses and t_ns - cd.glimpses[0][1] > p.glimpse_s * 1e9:
            cd.glimpses = [g for g in cd.glimpses if t_ns - g[1] <= p.glimpse_s * 1e9]
        return states

    def _glimpse(self, first_t: int, first_pos: np.ndarray) -> tuple[int, int, np.ndarray, np.ndarray] | None:
        """The latest remembered edge glimpse (:attr:`TrackerParams.glimpse_s`) that a candidate first seen at
        ``first_t`` at ``first_pos`` can be, taken from the memory; ``None`` if there is none."""
        p = self.params
        gl = self._cand.glimpses
        for q in range(len(gl) - 1, -1, -1):
            _, g1, _, gpos = gl[q]
            dt = (first_t - g1) / 1e9
            if 0 < dt <= p.glimpse_s and float(np.hypot(*(first_pos - gpos))) <= (
                    2.0 * p.bandwidth_m + p.glimpse_speed_mps * dt):
                return gl.pop(q)
        return None

    def _born_merged(self, det: DetectionArrays, j: int, n: int, v0: np.ndarray, heading: float, t_ns: int,
                     edge: bool) -> _Merged:
        """A merged target of ``n`` new people from one segment: members spread along its principal axis,
        refined by k-means on its points."""
        p = self.params
        pts = det.points[j]
        c = pts.mean(axis=0)
        _, _, vt = np.linalg.svd(pts - c, full_matrices=False)
        proj = (pts - c) @ vt[0]
        pos = c + np.linspace(proj.min(), proj.max(), 2 * n + 1)[1::2, None] * vt[0][None, :]
        for _ in range(3):
            lab = np.argmin(_pair_d2(pts, pos), axis=1)
            for q in range(n):
                if np.count_nonzero(lab == q) >= 2:
                    pos[q] = pts[lab == q].mean(axis=0)
        speed = float(np.hypot(*v0))
        stride = float(np.clip(speed * 1.1, 0.8, STRIDE_RANGE_M[1])) if speed > 0.3 else 1.4
        hd = heading if math.isfinite(heading) else 0.0
        info = [_MemberInfo(next(self._next_id), 1.1, stride, hd, speed < p.standing_speed_mps, t_ns, edge)
                for _ in range(n)]
        r2 = p.merged_r_m**2
        return _Merged(np.concatenate([det.centres[j], v0]), np.diag([r2, r2, 0.5**2, 0.5**2]), t_ns, pos,
                       np.repeat(np.asarray(v0, float)[None], n, axis=0), info, multi_last=t_ns, formed_ns=t_ns,
                       seen_by=self._seen_by(det, (j,)))

    # ---------------------------------------------------------------------------------------------
    def _track_velocity(self, pos: np.ndarray, dt: float) -> None:
        """Body position estimate, lagged position and velocity; B8's standing switch."""
        p = self.params
        if self._id.size == 0:
            return
        if _jit.ENABLED and self._track_velocity_jit(pos, dt):
            return
        self._pos = pos
        if dt > 0:
            a = 1.0 - math.exp(-dt / p.velocity_tau_s)
            self._lag += a * (pos - self._lag)
            # steady-state lag of the discrete EMA behind a ramp; after a gap so long that a rounds to 1 the lagged
            # position is the position: no velocity to tell (0, not 0 / 0)
            lag_s = dt * (1.0 - a) / a if a < 1.0 else math.inf
            self._vel = (pos - self._lag) / lag_s
        speed = np.hypot(self._vel[:, 0], self._vel[:, 1])
        was = self._standing
        # update_standing(speed, self._slow, was, ...) written out (the same operations, without its conversions)
        self._slow = np.where(speed < p.standing_speed_mps, self._slow + 1, 0)
        self._standing = np.where(was, ~(speed >= p.resume_speed_mps), self._slow >= p.standing_frames)
        n_p = p.n_particles
        started = was & ~self._standing
        if np.count_nonzero(started):  # walks again: head where the track goes
            psi = np.arctan2(self._vel[started, 1], self._vel[started, 0])
            self._x[PSI, started, :] = psi[:, None] + p.init_heading_sigma_rad * self.rng.standard_normal(
                (int(started.sum()), n_p))
        if p.reseed_fraction > 0 and dt > 0:
            rows = (~self._standing & (speed > p.resume_speed_mps)).nonzero()[0]
            if rows.size:
                k = max(1, round(p.reseed_fraction * n_p))
                start = self._reseed_at
                self._reseed_at = (start + k) % max(n_p - k + 1, 1)
                vel = self._vel if rows.size == self._id.size else self._vel[rows]  # everyone (the usual case)
                psi = np.arctan2(vel[:, 1], vel[:, 0])
                psi = psi[:, None] + p.init_heading_sigma_rad * standard_normal(self.rng, (rows.size, k))
                if rows.size == self._id.size:  # a basic slice: no fancy-index scatter
                    self._x[PSI, :, start:start + k] = psi
                else:
                    self._x[PSI, rows, start:start + k] = psi

    def _track_velocity_jit(self, pos: np.ndarray, dt: float) -> bool:
        """:meth:`_track_velocity` by two kernels (the same draws); False (nothing changed) when a target starts
        walking again this step (its heading is drawn by ``Generator.standard_normal``: the numpy code does it)."""
        p = self.params
        n = self._id.size
        pos = np.ascontiguousarray(pos, dtype=np.float64)
        if dt > 0:
            a = 1.0 - math.exp(-dt / p.velocity_tau_s)
            lag_s = dt * (1.0 - a) / a if a < 1.0 else math.inf  # (as in _track_velocity)
            vel = np.empty((n, 2))
        else:
            a = lag_s = 1.0
            vel = np.array(self._vel, dtype=np.float64)  # (not written)
        lag = self._lag if self._lag.flags.c_contiguous and self._lag.dtype == np.float64 else np.array(self._lag)
        lag_before = lag.copy()
        speed, slow, standing, rows = np.empty(n), np.empty(n, np.int64), np.empty(n, bool), np.empty(n, np.int64)
        reseed = p.reseed_fraction > 0 and dt > 0
        n_started, n_rows = _jit.track_velocity(pos, lag, vel, np.ascontiguousarray(self._slow, dtype=np.int64),
                                                np.ascontiguousarray(self._standing), float(dt), a, lag_s,
                                                float(p.standing_speed_mps), float(p.resume_speed_mps),
                                                int(p.standing_frames), reseed, speed, slow, standing, rows)
        if n_started:
            lag[...] = lag_before  # undo: the numpy code runs this step
            return False
        self._pos, self._lag, self._vel, self._slow, self._standing = pos, lag, vel, slow, standing
        if n_rows:
            n_p = p.n_particles
            k = max(1, round(p.reseed_fraction * n_p))
            start = self._reseed_at
            self._reseed_at = (start + k) % max(n_p - k + 1, 1)
            u = self.rng.random(2 * ((n_rows * k + 1) // 2))
            _jit.reseed_heading(self._x, rows, n_rows, vel, u, float(p.init_heading_sigma_rad), start, k)
        return True

    def _new_walker(self, tid: int, det: DetectionArrays, j: int, v0: np.ndarray, heading: float, t_ns: int, *,
                    period_s: float = 1.1, stride_m: float | None = None, standing: bool | None = None,
                    born_ns: int | None = None, born_edge: bool = False) -> dict[str, Any]:
        """Particles (B8 initialisation, with spreads) and bookkeeping of a target restarting at detection ``j``."""
        p = self.params
        speed = float(np.hypot(*v0))
        if stride_m is None:
            stride_m = float(np.clip(speed * period_s, 0.8, STRIDE_RANGE_M[1])) if speed > 0.3 else 1.4
        x = init_walking(det.feet[j][None], p.n_particles, self.rng, np.array([heading]), period_s=period_s,
                         stride_m=stride_m, feet_sigma_m=p.init_feet_sigma_m,
                         heading_sigma_rad=p.init_heading_sigma_rad if math.isfinite(heading) else 0.0,
                         period_sigma_s=p.init_period_sigma_s, stride_sigma_m=p.init_stride_sigma_m)
        return {"track_id": tid, "x": x[0], "pos": det.centres[j].copy(), "vel": np.array(v0, float),
                "seen": t_ns, "standing": (speed < p.standing_speed_mps) if standing is None else standing,
                "born": t_ns if born_ns is None else born_ns, "born_edge": born_edge,
                "seen_by": self._seen_by(det, (j,))}

    def _seen_by(self, det: DetectionArrays, js: Sequence[int]) -> tuple[str, ...]:
        """``TrackState.sensors`` of a target confirmed by detections ``js``: the scanners whose points they hold
        (their ``scanners`` feature, sorted by name), else :attr:`TrackerParams.sensor`."""
        by = det.scanners
        if not by:
            return self._sensors
        if len(js) == 1:
            return by[js[0]] or self._sensors
        return tuple(sorted({name for j in js for name in (by[j] or self._sensors)}))

    def _add_walking(self, *, track_id: int, x: np.ndarray, pos: np.ndarray, vel: np.ndarray, seen: int,
                     standing: bool, born: int, born_edge: bool) -> None:
        n_p = self.params.n_particles
        self._x = np.concatenate([self._x, x.T[:, None, :]], axis=1)
        self._w = np.concatenate([self._w, np.full((1, n_p), 1.0 / n_p)])
        self._id = np.append(self._id, track_id)
        self._seen = np.append(self._seen, seen)
        self._pos = np.concatenate([self._pos, pos[None]])
        self._lag = np.concatenate([self._lag, (pos - vel * self.params.velocity_tau_s)[None]])
        self._vel = np.concatenate([self._vel, vel[None]])
        self._slow = np.append(self._slow, 0)
        self._standing = np.append(self._standing, standing)
        self._born = np.append(self._born, born)
        self._born_edge = np.append(self._born_edge, born_edge)

    # ---------------------------------------------------------------------------------------------
    def _correlated_step(self, tid: int, t_ns: int, correlated: bool, pos: np.ndarray) -> None:
        """One step with a detection of walking target ``tid``: B7's label is ``correlated`` or not. The state
        (correlated or not) changes when the other label has held for ``n_confirm`` frames in every step with a
        detection (steps without one neither end nor extend a run; after ``n_miss`` frames without one the state
        starts afresh); a run lasts from the first step of its change to its last correlated step. An ended run is
        held for ``correlated_gap_s``: a new run that starts within it continues it [RECON]."""
        corr = self._corr
        rec = corr.get(tid)
        if rec is None or t_ns - rec[2] > self._frames_ns(self.params.n_miss):
            if rec is not None:
                self._close_correlated(tid)
            rec = corr[tid] = [False, 0, t_ns, None, None]
        rec[2] = t_ns
        if correlated == rec[0]:
            rec[1] = 0
        else:
            if not rec[1]:
                rec[1] = t_ns
            if t_ns - rec[1] >= self._frames_ns(self.params.n_confirm - 1):
                start, rec[0], rec[1] = rec[1], correlated, 0
                if correlated:
                    prev, rec[4] = rec[4], None
                    if prev is not None and start - prev[1] <= self.params.correlated_gap_s * 1e9:
                        rec[3] = prev
                    else:
                        if prev is not None:
                            self._emit_correlated(tid, prev)
                        rec[3] = [start, t_ns, pos.copy()]
                else:
                    rec[4], rec[3] = rec[3], None
                    if rec[4] is not None and self.params.correlated_gap_s <= 0:
                        self._emit_correlated(tid, rec[4])
                        rec[4] = None
        if correlated and rec[0]:
            rec[3][1] = t_ns
        elif not rec[0] and not rec[1] and rec[3] is None and rec[4] is None:
            del corr[tid]

    def _members_correlated(self, m: _Merged, t_ns: int, splitting: bool) -> None:
        """One step with a detection of merged target ``m`` for its members' correlated runs: correlated while it
        splits, else merged (a run it ends is emitted at once: no bridge over a merge)."""
        corr = self._corr
        for k, info in enumerate(m.info):
            tid = info.track_id
            if splitting or tid in corr:
                self._correlated_step(tid, t_ns, splitting, m.pos[k])
                rec = corr.get(tid)
                if rec is not None and rec[4] is not None:
                    self._emit_correlated(tid, rec[4])
                    rec[4] = None

    def _close_correlated(self, tid: int) -> None:
        """End the correlated runs of ``tid`` (held and open): one event each."""
        rec = self._corr.pop(tid, None)
        if rec is not None:
            for run in (rec[4], rec[3]):
                if run is not None:
                    self._emit_correlated(tid, run)

    def _emit_correlated(self, tid: int, run: list[Any]) -> None:
        """One ``correlated`` event for a run ``[start, last, position]``, if it lasted ``min_correlated_s``."""
        if run[1] - run[0] >= self.params.min_correlated_s * 1e9:
            self.events.append(Event(int(run[0]), self.params.sensor, "correlated", int(run[1]), position_m=run[2],
                                     track_ids=(tid,)))

    def _death_event(self, tid: int, seen_ns: int, t_ns: int, pos: np.ndarray, edge: bool) -> None:
        self._close_correlated(tid)
        self.events.append(Event(min(seen_ns, t_ns), self.params.sensor, "disappear" if edge else "lost", t_ns,
                                 position_m=np.asarray(pos, float).copy(), track_ids=(tid,)))


# --------------------------------------------------------------------------------------------------
# Area from the scanners' backgrounds
# --------------------------------------------------------------------------------------------------


def area_from_backgrounds(detector: Any, geometries: Mapping[str, tuple[float, float]],
                          poses: Mapping[str, np.ndarray]) -> np.ndarray | None:
    """The covered area inferred from what the scanners see: the convex hull of every background point
    (beams with a static return) and of the scanners themselves, world frame, ``(m, 2)`` vertices.

    Parameters
    ----------
    detector : LaserPeopleDetector
        With learnt backgrounds (:meth:`~fusiontrack.laser.LaserPeopleDetector.background`).
    geometries : mapping of sensor -> (angle_min_rad, angle_increment_rad)
    poses : mapping of sensor -> laser2world ``(3, 3)`` or ``(4, 4)``

    Returns
    -------
    (m, 2) float64 or None
        ``None`` while no scanner has a learnt background with returns.
    """
    from scipy.spatial import ConvexHull, QhullError

    from ..laser.detector import planar_pose

    pts = []
    for name, (a0, inc) in geometries.items():
        bg = detector.background(name)
        if bg is None or not bg.initialised:
            continue
        r = np.asarray(bg.background_m, float)
        ok = np.isfinite(r) & (r < bg.range_max_m * 0.999)
        if not ok.any():
            continue
        a = a0 + np.flatnonzero(ok) * inc
        R, t = planar_pose(poses[name])
        local = np.column_stack([r[ok] * np.cos(a), r[ok] * np.sin(a)])
        pts.append(local @ R.T + t)
        pts.append(t[None])
    if not pts:
        return None
    allp = np.concatenate(pts)
    try:
        hull = ConvexHull(allp)
    except (QhullError, ValueError):
        return None
    return allp[hull.vertices]


# --------------------------------------------------------------------------------------------------
# A whole recording
# --------------------------------------------------------------------------------------------------



def run_tracker(trk: Any, detector: Any, poses: Mapping[str, np.ndarray], stream: Iterable[Any], *, total: int,
                auto_area: bool = False, classify: bool = True, progress: Callable[[float], None] | None = None,
                timings: dict[str, list[float]] | None = None) -> tuple[list[TrackState], list[Event]]:
    """Step a tracker through a time-ordered stream of laser scans (the loop of :func:`track_recording`).

    The scans go one by one through an :class:`~fusiontrack.tracking.online.OnlineLaserTracker` (what a live
    run uses): each scan updates ``detector``; when the next scan has another time stamp, the detections at the
    pending time go to ``trk.step`` (any tracker with ``step(t_ns, detections)``, ``events`` and ``finish()``),
    and the states through a :class:`~fusiontrack.tracking.classify.TrackClassifier` when ``classify``. With
    ``auto_area`` the covered area is read off the learnt backgrounds (:func:`area_from_backgrounds`) once
    there are detections. ``total`` (scans) scales ``progress``; ``timings`` as in :func:`track_recording`.
    """
    from .online import OnlineLaserTracker

    online = OnlineLaserTracker.from_parts(trk, detector, poses, auto_area=auto_area, classify=classify,
                                           timings=timings)
    states: list[TrackState] = []
    events: list[Event] = []
    for done, scan in enumerate(stream, start=1):
        states.extend(online.feed(scan))
        events.extend(online.take_events())
        if progress is not None and done % 100 == 0:
            progress(min(done / max(total, 1), 1.0))
    states.extend(online.close())
    events.extend(online.take_events())
    if progress is not None:
        progress(1.0)
    return states, events


def track_recording(path: str | Path | Sequence[str | Path], *, tracker: str = "pf",
                    params: TrackerParams | Mapping[str, Any] | None = None,
                    progress: Callable[[float], None] | None = None, topics: Iterable[str] | None = None,
                    time_source: str = "header", area_m: Any = "auto",
                    clock_corrections_ns: Mapping[str, int] | None = None,
                    detector_params: Mapping[str, Any] | None = None, rng: np.random.Generator | int | None = 0,
                    world_frame: str = "world", timings: dict[str, list[float]] | None = None,
                    background: str = "prime", classify: bool = True,
                    laser_poses: Mapping[str, Any] | None = None,
                    sync_window_ns: int = 200_000_000) -> tuple[list[TrackState], list[Event]]:
    """Detect and track the people in a recording's laser scans.

    Builds a :class:`~fusiontrack.laser.LaserPeopleDetector` from the laser topics (each scanner posed by
    ``laser_poses`` if given, else by ``/tf_static``: its frame to ``world_frame``; the identity when there is no
    such transform, i.e. tracks in the laser frame), puts the scans on one clock and in time order
    (:func:`fusiontrack.io.sync.synchronize`) and steps the tracker once per scan time.

    Parameters
    ----------
    path : recording path(s)
    tracker : ``"pf"`` or ``"kalman"``
        :class:`LaserPeopleTracker` or :class:`~fusiontrack.tracking.baseline.CVKalmanTracker`.
    params : TrackerParams, mapping or None
        Tracker parameters (for ``"kalman"``: keyword arguments of the baseline).
    progress : callable, optional
        Called with the fraction of scans done (0..1) every 100 scans and at the end.
    topics : iterable of str, optional
        Laser topics to use; default every ``sensor_msgs/msg/LaserScan`` topic.
    time_source : ``"header"`` or ``"log"``
        Scan times from header stamps (default) or from the recording's log time.
    area_m : ``"auto"``, None, rectangle or polygon
        The covered area; ``"auto"`` infers it from the learnt backgrounds (:func:`area_from_backgrounds`).
    clock_corrections_ns : mapping sensor -> ns, optional
        Added to each sensor's stamps (see :class:`~fusiontrack.io.sync.Synchronizer`).
    detector_params : mapping, optional
        Keyword arguments of the detector.
    rng : Generator or int
    world_frame : str
    timings : dict, optional
        Filled with per-step lists ``"detect_s"`` (detector update + detect) and ``"track_s"`` (tracker step), wall
        time, and ``"t_ns"`` (the step's time).
    background : ``"prime"``, ``"learn"`` or ``"none"``
        ``"prime"`` (default): fixed scanners; each scanner's background is first learnt from the recording's
        first ``n_init`` scans (read ahead, :meth:`~fusiontrack.laser.LaserPeopleDetector.prime`), so people
        are detected from the first scan on, then learnt online as with ``"learn"``. ``"learn"``: as a live
        sensor would be, learnt online only: nothing is detected during the first ``n_init`` scans of each
        scanner. ``"none"``: a scanner on a moving platform, whose background cannot be learnt: every return is
        foreground (the background is set to "no return" and never learns, ``alpha = gamma = 0`` unless
        ``detector_params`` say otherwise).
    classify : bool
        Give each track its class (person / bicycle / car) with :class:`~fusiontrack.tracking.classify.
        TrackClassifier` (B18); its time is part of ``"track_s"``.
    laser_poses : mapping of topic -> laser2world, optional
        Scanner poses (``(3, 3)`` 2-D or ``(4, 4)``) that override ``/tf_static``: a pipeline file's
        ``[sensors.<name>] pose`` (:meth:`fusiontrack.config.PipelineConfig.laser_poses`).
    sync_window_ns : int
        How late a scan may arrive and still be put back in time order (the pipeline file's ``[sync] window_ms``;
        :class:`~fusiontrack.io.sync.Synchronizer`).

    Returns
    -------
    states : list of TrackState
        Every state of every step, in time order.
    events : list of Event
    """
    from ..io.recording import LASERSCAN, Recording
    from ..io.sync import synchronize
    from ..laser.detector import detector_for_recording
    from .online import make_tracker

    if tracker not in ("pf", "kalman"):
        raise ConfigError(f"tracker: expected 'pf' or 'kalman', got {tracker!r}")
    with Recording(path) as rec:
        # the topics' types and counts from the connections (index or metadata): Recording.topics would read the
        # whole recording once more for the spans, which nothing here needs (as track_fused)
        types = rec.topic_types()
        lasers = [t for t, msgtype in types.items() if msgtype == LASERSCAN] if topics is None else list(topics)
        if not lasers:
            images = rec.image_topics()
            hint = (f" (it has images on {', '.join(images)}: --pipeline people-camera tracks people in them)"
                    if images else "")
            raise ConfigError(f"{', '.join(str(q) for q in rec.paths)}: no sensor_msgs/LaserScan topic to "
                              f"track{hint}")
        total = sum(c.msgcount for c in rec.connections if c.topic in lasers)
        if background not in ("prime", "learn", "none"):
            raise ConfigError(f"background: expected 'prime', 'learn' or 'none', got {background!r}")
        detector, poses = detector_for_recording(rec, lasers, time_source=time_source, world_frame=world_frame,
                                                 background="none" if background == "none" else "learn",
                                                 detector_params=detector_params, laser_poses=laser_poses)
        if background == "prime":
            detector.prime(synchronize(rec.messages(lasers, time_source=time_source), sync_window_ns,
                                       clock_corrections_ns=clock_corrections_ns))
        trk = make_tracker(tracker, params, area_m, rng)
        auto_area = isinstance(area_m, str)
        stream = synchronize(rec.messages(lasers, time_source=time_source), sync_window_ns,
                             clock_corrections_ns=clock_corrections_ns)
        states, events = run_tracker(trk, detector, poses, stream, total=total, auto_area=auto_area,
                                     classify=classify, progress=progress, timings=timings)
    return states, events
