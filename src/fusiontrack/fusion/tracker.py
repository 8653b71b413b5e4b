"""Seed 001's tracking-learning loop: laser particle filters and per-target camera classifiers, each helping the other.

:class:`FusionTracker` owns a :class:`~fusiontrack.tracking.tracker.LaserPeopleTracker` and an
:class:`~fusiontrack.vision.appearance.AppearanceBank` and, per laser step (ALGORITHMS.md sections in brackets):

1. **tracking** — the laser tracker steps as on its own; two hooks let the camera in only where the laser
   is weak:

   * correlated targets (B7 rule 3): the score map of the classifiers of the targets close to each other
     (one map per group, over their projected boxes dilated by 20 %, B16) weights their particles,
     ``β · log p(z | x)`` with the box centre ``d(x)`` of each particle's feet midpoint (B11); at most once
     per camera frame and target;
   * a merged target that splits (B17): each piece's box is scored by the members' classifiers
     (:meth:`~fusiontrack.vision.appearance.AppearanceBank.box_scores`) and the members are given to the
     pieces by the Hungarian algorithm on ``−score``, when every member has a trained classifier and the
     best assignment beats the second best by ``split_margin`` and gives every member a piece it scores at least
     B17's ``s_min`` (``AppearanceParams.min_score``), each piece scored outside the other pieces' boxes; by
     motion otherwise. Both are off by default: the score maps (``FusionParams.score_map``) cost identities once
     the laser tracker split merged targets it sees apart, and appearance at splits (``split_identity``) cost
     more identities than it saved on the simulated scenes (motion names 9 pieces in 10 right, the classifiers
     of people side by side about 6); the identity checks correct what motion gets wrong;
2. **re-identification** [RECON, extends B17] — the laser loses a track and a new one is born within a few seconds
   and within walking reach of where it was lost: the lost track's classifier (kept a few seconds) scores the
   new track's box on clear images, beside the other candidates' and the nearby tracks' classifiers, and when it
   is confident the new track takes the lost identity, back to its birth (:attr:`FusionTracker.relabels`).
   The laser tracker keeps its own ids; the fused tracker's states, events and hooks use the identities given
   back;
3. **identity checks** [RECON, extends B17] — at a split the people are still side by side and their boxes
   overlap, and a close pass without a merge never asks the camera at all. So every pair of tracks that comes
   within ``d_contact_m`` (or merges or splits together) is *checked*: on the next camera images on which both
   are walking targets with boxes clear of every other box, each classifier of the pair that was trained at the
   contact (its *voters*; one trained later may have learnt the other person) compares its own track's box with
   the other one. When the mean evidence over ``check_frames`` images or more passes ``check_margin``, the
   identities are confirmed or exchanged (an exchange needs, by default, both tracks' classifiers: ``check_voters``):
   the laser tracker's two ids are swapped from then on (at most one exchange per track and step: another check of
   the same track waits for the next image), and :attr:`FusionTracker.relabels` records the exchange back to where it
   most likely happened, the two tracks' closest approach since the check opened [RECON: the tracks of two people
   walking side by side drift over to each other's person while they are close, merged or not, often well before the
   laser's split; dated at the pair's last split, as first written, the relabel left that stretch exchanged: on 72
   simulated runs (crowd and groups, seeds 0-35, 30 s, particle-filter draws 0 and 1) the 11 runs with an exchange
   had 42 ID switches with it dated at the last split, 22 at the closest approach]; :func:`track_fused` applies it to
   the states already returned (:func:`relabel_states`, like B17's re-linking of the merged interval). The evidence
   counts from that closest approach on: what the images showed before it was of the identities before it [RECON:
   summed in, weak evidence from before a pass outvoted an exchange at the pass for as long as the pair stayed in
   contact (groups seed 30, draw 1: two people exchanged at 11 s stayed so to the end; now exchanged back at
   18.9 s). On the 72 runs, draws 0 / 1: groups 25 / 26 -> 22 / 23 ID
   switches, IDF1 0.968 / 0.968 -> 0.970 / 0.967 (three exchanges made right, one made wrong: groups seed 26,
   draw 1, at mean evidence -0.65); crowd unchanged, no check exchanges there. Dated instead at the pair's first
   merge since the check opened (the laser cannot tell merged people apart): groups 21 / 19 -> 27 / 27 on the same
   runs, the merge was mostly not where the tracks were exchanged. The date counts to the frame: groups seed 0's pair
   came within 0.31 m at 14.33 s, where the laser exchanged them, and within 0.30 m at 16.6 s, the date taken; the
   earliest approach within 0.1 m of the closest mends that one and breaks groups seed 10's]. Where the tracks'
   motion shows the exchange, it dates it instead: the step where each track jumped onto the course of the other
   (:func:`_exchange_date`) [RECON: a laser exchange of two tracks is a jump of both against their motion; two
   people walking side by side show none, and their closest approach dates it as before. On the 72 runs, draws 0 /
   1: groups 21 / 19 -> 17 / 15 ID switches (groups seeds 0 and 5, each 4 -> 0: the exchange dated to the frame),
   crowd 74 / 73 unchanged, no run worse];
4. **learning** [B15] — a noncorrelated target with another target within ``d_train_m`` (1.5 m) learns from
   the camera image nearest in time: positives from its projected box (B11), negatives from the boxes of
   its ``L`` closest targets (patches centred in another box are dropped, unless the laser puts the box's own
   target in front: ``FusionParams.depth_order``); at most once every
   ``train_interval_s``; merged targets' classifiers are frozen. B15 freezes correlated targets' classifiers too,
   and a voter of a pending identity check (its track could be following the other person); here
   (``FusionParams.contact_learn_s``) correlated targets learn at most every 0.4 s, voters learn on, and a check
   votes with copies of its voters frozen when it opened. And (``FusionParams.learn_all_s``) the targets B15 never
   trains, nobody ever near them, learn alone now and then, for re-identification only.

The camera image is converted only when one of these needs it (:class:`~fusiontrack.fusion.frames.LazyFrames`):
with no interaction, only now and then for the lone targets' learning (``learn_all_s``; None: never, and the fused
tracker then costs what the laser one costs). Each output state names the sensors
that confirmed its step: the laser's, plus the camera's when the image was used for that target.

:func:`track_fused` runs it over a recording (laser scans + one camera). The boxes are only as good as the camera's
calibration: a yaw error of 3 degrees puts them beside the people 10 m away, and the classifiers learn the wrong
pixels. So it first learns the camera's horizontal bias against the lasers over the beginning of the recording
(seed 000, :func:`learn_camera_bias`, until the bias settles: a few seconds) and fuses through the corrected
camera; without a usable camera it tracks with the lasers alone.
"""

from __future__ import annotations

import contextlib
import dataclasses
import itertools
import logging
import math
import time
from collections import deque
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from ..calibration.bias import BiasHistory, BiasParams
from ..calibration.bias_run import check_background
from ..errors import ConfigError, RecordingError
from ..geometry import PinholeCamera
from ..tracking.tracker import LaserPeopleTracker, TrackerParams, run_tracker
from ..types import Detection, Event, Image, ObjectClass, Situation, TrackState
from ..vision.appearance import AppearanceBank, AppearanceParams
from ..vision.cvthreads import opencv_threads
from ..vision.patches import box_visibility

if TYPE_CHECKING:
    from ..io.recording import Recording

__all__ = ["BiasLearning", "CameraBias", "FrameSource", "FusionParams", "FusionStats", "FusionTracker", "Relabel",
           "camera_boxes", "learn_camera_bias", "relabel_states", "track_fused"]

log = logging.getLogger(__name__)

_LEARNING = (str(Situation.NONCORRELATED), str(Situation.APPEARING))
_CORRELATED = str(Situation.CORRELATED)
_OPTIONAL = ("learn_all_s", "reid_min_alone", "contact_learn_s")  # FusionParams numbers that None turns off


class FrameSource(Protocol):
    """Camera images by time (e.g. :class:`~fusiontrack.fusion.frames.LazyFrames`)."""

    def nearest_time(self, t_ns: int) -> int | None:
        """Time of the image nearest to ``t_ns`` if one is close enough, without reading it."""

    def at(self, t_ns: int) -> Image | None:
        """That image (BGR), or None."""


@dataclass(frozen=True, slots=True)
class FusionParams:
    """Parameters of :class:`FusionTracker` (ALGORITHMS.md values unless marked).

    Attributes
    ----------
    d_train_m : float
        B15: a target learns while another target is closer than this (seed 001: 1.5 m).
    train_interval_s : float
        At most one training frame per target group every this many seconds (and a re-identification claim is
        scored at most this often) [RECON: the camera's 15 Hz frames are highly correlated]. A target's first
        classifier, fitted on one image, is its weakest (``check_min_updates``): 0.1 s gives it its second and
        third updates sooner. Over 72 runs (crowd + groups, seeds 0-35, 30 s) and four seeds of the particle
        filters' draws (rng 0 / 1 / 2 / 3): ID switches 242 / 218 / 252 / 245 with 0.1 s against 253 / 244 / 260 /
        256 with 0.2 s (fewer with every seed; laser-only: 262 / 239 / 247 / 259), 241 / 244 / 248 (rng 0-2) with
        0.05 s; IDF1 within the seeds' spread (means: crowd 0.935 against 0.934, groups 0.912 against 0.912); the
        same CPU time (crowd and groups seeds 0-2: 1.39x / 1.59x laser-only's with 0.1 s, 1.39x / 1.63x with 0.2).
    score_map : bool
        B16 on (score-map observation of correlated targets). Off by default since the laser tracker splits a
        merged target seen apart (:class:`~fusiontrack.tracking.LaserPeopleTracker`): over 72 runs (crowd and
        groups, seeds 0-35, 30 s) with rng 0 / 1, ID switches crowd 154 / 161 with the maps, 145 / 150 without;
        groups 56 / 40 with, 27 / 35 without (laser-only 23 with rng 0); IDF1 crowd 0.929 / 0.934 with, 0.933 /
        0.935 without, groups 0.948 / 0.961 with, 0.968 / 0.958 without; and the maps cost about 0.1x
        laser-only's time. The maps' small pulls on a target's particles change which draws survive, and the
        tracker, now steady on its own, loses more to that than the maps win back. Before that change (the
        figures below) the maps helped groups. With the laser detector's
        ``min_cluster_points`` 2 (before session 25), on ``benchmarks/fusion.py``'s scenes (crowd and groups, seeds
        0-11, 30 s each, paired with the same runs without it) it cut ID switches from 117 to 99 and raised IDF1
        from 0.880 to 0.898 and MOTA from 0.885 to 0.899 (IDF1 better in 14 runs of 24, worse in 8; the largest
        gains on groups walking side by side), for about 0.1x laser-only's time (the maps and the camera images
        they read). With ``min_cluster_points`` 1 (one-beam legs are detected, the laser loses far fewer people)
        the same 24 runs no longer tell them apart: 48 ID switches with the maps, 49 without, IDF1 0.930 / 0.932,
        MOTA 0.922 / 0.925 (laser-only: 44, 0.936, 0.925). With the classifier of laser segments retrained on the
        detector's segments of people (people walking in pairs are no longer called car, and so are scored):
        54 ID switches with the maps, 50 without, IDF1 0.938 / 0.940, MOTA 0.942 / 0.940 (laser-only: 46, 0.943,
        0.940); the maps still swing single runs both ways (groups seed 9 MOTA 0.890 -> 0.963, crowd seed 11
        0.928 -> 0.887, groups seed 10 2 -> 8 switches). It was off while the classifiers learnt mean R, G, B
        (before B13's chromaticity colour, ``FeatureParams.colour``): the map then pulled particles towards the
        neighbour's look-alike patches and cost identities. Old detector: ``score_beta`` 1.0 instead of 0.5, the
        same switches, MOTA 0.890; 150 ``map_patches`` instead of 300: 109 switches. Over 72 runs (crowd and
        groups, seeds 0-35) and three seeds of the particle filters' draws (rng 0, 1, 2), ``train_interval_s``
        0.2: ID switches 253 / 244 / 260 with the maps, 270 / 244 / 257 without (within the draws' own spread),
        groups IDF1 0.914 / 0.915 / 0.910 with, 0.902 / 0.912 / 0.901 without (better with each rng), crowd IDF1
        the same (0.933). The maps
        move little per image: over crowd and groups seeds 0-2 the median spread of a target's particles is 1.6 px
        in the image against the kernel's 12 px, and the map changes their log-weights by at most 0.07 (median;
        0.19 at the 90th percentile), a nudge that adds up over frames.
    score_beta : float
        Exponent of the score-map likelihood (the last annealing level's weight would be 1; the laser
        likelihood is kept, so the camera term is tempered) [RECON].
    group_m : float
        Correlated targets closer than this share one score map [RECON].
    split_identity : bool
        B17 on (classifiers decide identities at splits). Off by default: with the score maps on, seeds 0-11 gave
        116 ID switches against 99 without it and IDF1 0.888 against 0.898. Before the score maps: on
        ``benchmarks/fusion.py``'s scenes (crowd and groups, seeds 0-5, 30 s) it gave 56 ID switches against 40
        without it (laser-only: 41) and IDF1 0.883 against 0.886: the classifiers of people walking side by
        side, trained on their overlapping boxes, named the pieces of their splits right only about 6 times in 10
        (fewer than motion does); the identity checks then correct what motion gets wrong.
    split_margin : float
        Appearance decides a split only if its best assignment of members to pieces beats the second best by
        this much summed confidence [RECON], and every member's score on its piece is at least B17's ``s_min``
        (``appearance.min_score``); motion otherwise (rather than B17's "the piece becomes a new target": a
        classifier trained on boxes overlapping its neighbour's is often unsure of its own person).
    split_exclusive : bool
        At a split, each piece is scored on its patches outside the other pieces' boxes only (B15's rule for
        training samples; the people are still side by side, their boxes overlap) [RECON]; a piece left without
        any gives no appearance decision.
    check_identity : bool
        Identity checks after close contacts (see the module docstring) [RECON].
    d_contact_m : float
        Two tracks closer than this (B6's gate, 2h), or in one merge or split, may have exchanged identities:
        their pair is checked [RECON].
    check_margin : float
        A check decides once the mean evidence per classifier (own box's confidence minus the other box's) is
        at least this far from 0 over ``check_frames`` clear images or more: keep (> 0) or exchange (< 0) [RECON:
        on ``benchmarks/fusion.py``'s scenes (seeds 0-5) the exchanges decided at 0.4-0.6 were wrong: classifiers
        trained on side-by-side people are unsure of their own person; deciding also on weaker evidence held
        longer, a mean of 0.25 over 10 images or more, 90 % of them pointing the same way, made more wrong
        exchanges than it mended: on 72 simulated runs (crowd and groups, seeds 0-35, 30 s, particle-filter draws
        0 / 1) groups 21 / 19 -> 27 / 25 ID switches, 28 / 29 without the 90 %].
    check_frames : int
        Clear camera images a check needs before it decides [RECON].
    check_s : float
        A pair's check (decided or not) is dropped this long after the pair was last within ``d_train_m``
        [RECON].
    check_min_updates : int
        A check exchanges the pair's identities only if every voter's classifier has been updated (B14) at
        least this many times; otherwise its decision is to keep them [RECON: a target's first classifier is
        fitted at once on one image, often of the two people side by side; on 72 simulated runs (crowd and
        groups, seeds 0-35, 30 s) all 7 exchanges voted by such a classifier were wrong or unclear, and
        requiring 2 updates took the fused ID switches of those runs from 70 to 60 (no other run changes); checked
        again later over 144 runs (crowd and groups, seeds 0-35, 30 s, draws 0 / 1): 1 instead of 2 gave 177 ID
        switches against 173, three runs changed, two for the worse].
    check_voters : int
        A check exchanges the pair's identities only if at least this many of its two tracks' classifiers voted
        (were trained when it opened); otherwise its decision is to keep them [RECON: one classifier alone,
        trained on the two people side by side, is too often sure of the wrong one. On 72 simulated runs (crowd
        and groups, seeds 0-35, 30 s) and the particle filters' draws 0 and 1, all 3 exchanges voted by one
        classifier were wrong (their runs' ID switches 2 -> 0, 7 -> 5, 5 -> 3 without them); of the 9 voted by
        two, 7 were right, and one wrong one was undone by the pair's next check].
    max_overlap : float
        An image is clear for a check when neither box of the pair has more than this fraction of its area
        inside another target's box (occlusion) [RECON].
    check_visible : float
        ... and at least this fraction of each box of the pair is inside the image [RECON: a box mostly off the
        image shows its classifier a sliver of the person; ``benchmarks/fusion.py``'s wrong exchanges were made
        on such slivers].
    reid : bool
        Re-identification of reborn tracks [RECON, extends B17]: when the laser loses a track and a new one is
        born within ``reid_s`` (before or after) of its last sighting, within reach of where it was lost
        (``reid_slack_m`` + ``reid_speed_mps`` x (the gap + how long the laser coasted the lost track before giving
        it up: the position it reports is where it coasted it to)), the lost track's classifier (kept ``reid_s``
        after the loss) scores the new track's box on clear camera images (as for a check: ``max_overlap``,
        ``check_visible``), beside the other
        candidates' and the nearby live tracks' classifiers; the new track takes the lost identity (back to its
        birth, :attr:`FusionTracker.relabels`) once, over ``reid_frames`` images or more, the lost classifier's
        mean confidence is at least ``reid_min`` and beats every other's by ``reid_margin``.
    reid_s, reid_speed_mps, reid_slack_m : float
        See ``reid`` [RECON: ``benchmarks/fusion.py``'s losses are re-born within a second or two, a metre or
        two away].
    reid_frames : int
        Clear images a re-identification needs [RECON].
    reid_min, reid_margin : float
        See ``reid`` (confidences are in [-1, 1]) [RECON].
    learn_all_s : float or None
        Targets that never had anybody within ``d_train_m`` (so B15 never trains them) learn alone now and then
        [RECON, extends B15], so that when the laser loses such a person its reborn track can be re-identified:
        a noncorrelated target with a clear box (``max_overlap``) mostly in the image (``check_visible``) learns
        at most about once every ``learn_all_s`` (not before ``learn_all_s / 2`` since its last time: on an image
        read at that step anyway; an image is read for them only when one of them is ``learn_all_s`` overdue);
        negatives: its ``L`` closest targets in the image, wherever they are. Its classifier only serves
        re-identification (a lost candidate, or a live alternative): it never votes in an identity check, it
        draws its patches from a random stream of its own, and it is dropped when the target first learns as
        B15's learner (B15's starts afresh), so B15's classifiers and the checks are what they are without it.
        (Kept instead, B15 training on from it, the crowds' exchanges were not fewer: over 72 runs (crowd, seeds
        0-35, 30 s, draws 0 / 1) ID switches 70 / 71 -> 72 / 74, exchanges 10 / 28 -> 12 / 30; kept and voting in
        the checks, 70 / 73, exchanges 10 / 30.)
        None: only B15's learners learn (seed 001: the camera is read only for targets that need it). Default 1.5 s,
        since the identity checks date an exchange by the tracks' motion: on ``benchmarks/fusion.py`` (seeds 0-2) it
        re-identifies the two reborn tracks left (crowd seed 0, groups seed 2), ID switches 6 -> 4 against
        laser-only's 8 (seed 001's target, at most half, is met with it and not without), IDF1 0.965 -> 0.973; on
        72 runs (crowd + groups, seeds 0-35, 30 s, draws 0 / 1) crowd 74 / 73 -> 72 / 72 and groups 17 / 15 -> 16 /
        15 ID switches, four runs changed, each a reborn track re-identified, none for the worse. Its cost, when it
        became the default: +0.035x laser-only's time (seeds 0-2: 1.43x -> 1.47x, least of 4 runs each; less since
        the lone targets that cannot learn are passed over cheaply). History: 1.5 s with ``reid_min_alone``
        0.25 first gave ID switches 17 -> 16 on seeds 0-2 and 22 -> 21 on seeds 3-5 (laser-only: 18, 20), within
        the runs' noise, and over 72 runs and draws 0 / 1 / 2 (``train_interval_s`` 0.2) 249 / 239 / 259 against 253
        / 244 / 260; it was off by default then, and later (``contact_learn_s``, checks dated at the closest approach)
        10 -> 8 on seeds 0-2 at 1.49x -> 1.58x laser-only's time (since halved: learning alone computed every
        target's boxes at every step while a lone person out of the camera's view was overdue).
    reid_min_alone : float or None
        ``reid_min`` for a lost candidate whose classifier learnt alone (``learn_all_s``; fewer, less varied
        training images: its confidence on its own person is lower) [RECON]; None: ``reid_min``.
    height_m, width_ratio : float
        B11's person box (``H_p``, ``r_w``).
    max_frame_dt_s : float
        An image is used for a laser step only if this close in time.
    depth_order : bool
        The laser says who is in front [RECON, extends B15]: where two targets' boxes overlap, the patches there
        show the one nearer the camera (by ``appearance.depth_margin_m``); they are learnt for it instead of for
        neither (B15). (A group walking side by side along the camera's line of sight: B15 learnt only the front
        person's feet and the head of the one behind.) Alone it changes nothing measurable: on 72 simulated runs
        (crowd and groups, seeds 0-35, 30 s), particle-filter draws 0 / 1, crowd 75 / 75 -> 76 / 75 and groups
        22 / 23 -> 21 / 23 ID switches, IDF1 within 0.001; it is the rule ``contact_learn_s`` learns by, while
        people overlap.
    contact_learn_s : float or None
        People in contact learn on [RECON, extends B15]: correlated targets learn too (a trained one at most every
        ``contact_learn_s``, 0.4), voters of a pending identity check go on learning, and a check votes with copies
        of its voters frozen when it opened (:meth:`~fusiontrack.vision.appearance.AppearanceBank.freeze`),
        refreshed when the check keeps the identities and none of the voter's other checks is undecided, and
        restored (what was learnt since undone) when it finds them exchanged, whether it exchanges them back or
        not (withheld); at an exchange, a classifier of the pair first trained during the contact is dropped.
        Members of a merged target never learn (seen apart, they are correlated, where the tracker guesses
        them). None: B15 as seed 001 words it, only
        noncorrelated targets learn, and a voter of a pending check does not (its track could be following the
        other person). People who walk together are correlated for most of their walk, and B15 froze their
        classifiers after one or two updates: on ``groups`` seed 0, five classifiers had 2-3 updates each over 8 s
        together. On 72 simulated runs (crowd and groups, seeds 0-35, 30 s), particle-filter draws 0 / 1, against
        None: groups 22 / 23 -> 21 / 19 ID switches and IDF1 0.970 / 0.967 -> 0.975 / 0.975, crowd 75 / 75 -> 74 /
        73 and IDF1 0.958 / 0.955 -> 0.957 / 0.956. On ``benchmarks/fusion.py`` (seeds 0-2) it repairs groups seed
        0's exchange of 14.3 s at 21.4 s (mean evidence -0.60, just at ``check_margin``; dated from the pair's
        closest approach at 16.7 s): IDF1 0.857 -> 0.956 there, 0.943 -> 0.959 over the six runs, and 2 -> 4 ID
        switches (the repair counts as two; dated since by the tracks' motion, at 14.31 s: 0 there); the camera
        is read for 1077 images instead of 894 and trained on 1017 instead of 624, and the fused time per frame
        goes from 1.38x laser-only's to 1.49x (seed 001's target: at most 1.5x; every 0.1 s it was about 1.6x).
    appearance : AppearanceParams
        The classifiers (B12-B14).
    """

    d_train_m: float = 1.5
    train_interval_s: float = 0.1
    score_map: bool = False
    score_beta: float = 0.5
    group_m: float = 1.0
    split_identity: bool = False
    split_margin: float = 1.0
    split_exclusive: bool = True
    check_identity: bool = True
    d_contact_m: float = 0.8
    check_margin: float = 0.6
    check_frames: int = 3
    check_s: float = 4.0
    check_min_updates: int = 2
    check_voters: int = 2
    max_overlap: float = 0.3
    check_visible: float = 0.5
    reid: bool = True
    reid_s: float = 4.0
    reid_speed_mps: float = 2.0
    reid_slack_m: float = 1.0
    reid_frames: int = 3
    reid_min: float = 0.4
    reid_margin: float = 0.3
    learn_all_s: float | None = 1.5
    reid_min_alone: float | None = 0.25
    height_m: float = 1.70
    width_ratio: float = 0.40
    max_frame_dt_s: float = 0.05
    depth_order: bool = True
    contact_learn_s: float | None = 0.4
    appearance: AppearanceParams = field(default_factory=AppearanceParams)

    def __post_init__(self) -> None:
        if not isinstance(self.appearance, AppearanceParams):
            raise ConfigError(f"FusionParams.appearance: expected AppearanceParams (FusionParams.from_mapping reads a "
                              f"table), got {type(self.appearance).__name__}")
        for name in ("check_frames", "reid_frames", "check_min_updates"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ConfigError(f"FusionParams.{name}: expected an integer >= 1, got {v!r}")
        v = self.check_voters
        if isinstance(v, bool) or not isinstance(v, int) or v not in (1, 2):
            raise ConfigError(f"FusionParams.check_voters: expected 1 or 2 (a check has two tracks), got "
                              f"{self.check_voters!r}")
        if not 0 < self.max_overlap <= 1:
            raise ConfigError(f"FusionParams.max_overlap: expected a fraction in (0, 1], got {self.max_overlap!r}")
        if not (isinstance(self.check_visible, int | float) and 0 <= self.check_visible <= 1):
            raise ConfigError(f"FusionParams.check_visible: expected a fraction in [0, 1], got {self.check_visible!r}")
        for name in ("d_train_m", "train_interval_s", "score_beta", "group_m", "split_margin", "height_m",
                     "width_ratio", "max_frame_dt_s", "d_contact_m", "check_margin", "check_s", "reid_s",
                     "reid_speed_mps", "reid_slack_m", "reid_margin"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and np.isfinite(v) and v >= 0):
                raise ConfigError(f"FusionParams.{name}: expected a finite value >= 0, got {v!r}")
        if self.height_m <= 0 or self.width_ratio <= 0:
            raise ConfigError("FusionParams.height_m, width_ratio: expected values > 0")
        if self.learn_all_s is not None and not (isinstance(self.learn_all_s, int | float)
                                                 and not isinstance(self.learn_all_s, bool)
                                                 and np.isfinite(self.learn_all_s) and self.learn_all_s > 0):
            raise ConfigError(f"FusionParams.learn_all_s: expected None or a finite value > 0, got "
                              f"{self.learn_all_s!r}")
        v = self.contact_learn_s
        if v is not None and not (isinstance(v, int | float) and not isinstance(v, bool) and np.isfinite(v) and v > 0):
            raise ConfigError(f"FusionParams.contact_learn_s: expected None or a finite value > 0, got {v!r}")
        if self.reid_min_alone is not None and not (isinstance(self.reid_min_alone, int | float)
                                                    and not isinstance(self.reid_min_alone, bool)
                                                    and -1 <= self.reid_min_alone <= 1):
            raise ConfigError(f"FusionParams.reid_min_alone: expected None or a confidence in [-1, 1], got "
                              f"{self.reid_min_alone!r}")
        if not (isinstance(self.reid_min, int | float) and -1 <= self.reid_min <= 1):
            raise ConfigError(f"FusionParams.reid_min: expected a confidence in [-1, 1], got {self.reid_min!r}")

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any], source: str = "fusion") -> FusionParams:
        """From a pipeline file's ``[fusion]`` table: field names as keys, ``appearance`` a nested table
        (``patches``, ``features``, ``boost``, ... of :class:`~fusiontrack.vision.appearance.AppearanceParams`);
        ``false`` for an option that None turns off (``contact_learn_s``, ``learn_all_s``, ``reid_min_alone``).

        Raises
        ------
        ConfigError
            An unknown key or a bad value, naming ``source`` and the key.
        """
        _check_keys(values, {f.name for f in dataclasses.fields(cls)}, source)
        vals = dict(values)
        flags = [f.name for f in dataclasses.fields(cls) if isinstance(f.default, bool)]
        bad = sorted(k for k in flags if k in vals and not isinstance(vals[k], bool))
        if bad:
            raise ConfigError(f"{source}: {bad[0]}: expected true or false, got {vals[bad[0]]!r}")
        for name in _OPTIONAL:  # TOML has no null: false turns such an option off
            if vals.get(name) is False:
                vals[name] = None
        if "appearance" in vals:
            app = vals["appearance"]
            if not isinstance(app, Mapping):
                raise ConfigError(f"{source}.appearance: expected a table, got {app!r}")
            vals["appearance"] = _appearance_from_mapping(app, f"{source}.appearance")
        try:
            return cls(**vals)
        except ConfigError as err:
            raise ConfigError(f"{source}: {err}") from err
        except (TypeError, ValueError) as err:  # a value of the wrong type met by a check that assumed numbers
            raise ConfigError(f"{source}: {err}") from err


def _check_keys(values: Mapping[str, Any], known: set[str], source: str) -> None:
    """A ConfigError naming ``source``, the unknown keys of a table and the known ones, if it has any."""
    unknown = sorted(str(k) for k in set(values) - known)
    if unknown:
        raise ConfigError(f"{source}: unknown key(s) {', '.join(unknown)}; known: {', '.join(sorted(known))}")


def _appearance_from_mapping(values: Mapping[str, Any], source: str) -> AppearanceParams:
    """AppearanceParams from a ``[fusion.appearance]`` table, its keys and those of its sub-tables ``patches``,
    ``features`` and ``boost`` checked by name first (``source``: e.g. ``"site.toml: fusion.appearance"``)."""
    default = AppearanceParams()
    _check_keys(values, {f.name for f in dataclasses.fields(default)}, source)
    for name in ("patches", "features", "boost"):
        if name in values:
            sub = values[name]
            if not isinstance(sub, Mapping):
                raise ConfigError(f"{source}.{name}: expected a table, got {sub!r}")
            _check_keys(sub, {f.name for f in dataclasses.fields(getattr(default, name))}, f"{source}.{name}")
    try:
        return AppearanceParams.from_dict(values)
    except (TypeError, ValueError) as err:  # a bad value: the check names the field
        raise ConfigError(f"{source}: {err}") from err


@dataclass(frozen=True, slots=True)
class BiasLearning:
    """How :func:`track_fused` learns its camera's horizontal bias before fusing (seed 000, ALGORITHMS.md A10).

    The bias is learnt over the beginning of the recording only: every camera image goes through seed 000's
    vision path (A1–A5) while it learns, which costs more than the fused tracker itself, and a fixed camera's
    error does not change within a recording. Learning stops once the bias has settled, or after ``max_s``;
    a bias that has not settled by then is applied only if it stands out from its own wander (at least
    ``settle_updates`` updates, and larger than twice the span of the last ``settle_updates`` values) [RECON]:
    with two people always side by side, the bias wanders by a degree on wrong matches.

    Attributes
    ----------
    params : BiasParams
        A6–A10 (``rho`` 0.1) with A10's warm start (``warm_start``): the bias is the mean of its first
        ``1 / rho`` targets, then smoothed at ``rho``. Over 36 simulated 30 s crowds (a 3-degree error) and 36
        groups (none) the pass then stops after 48 and 90 camera frames on average, against 76 and 128 with A10's
        fixed rate and 40 updates, and ends closer to the simulator's bias: mean error 0.034 / 0.041 degree
        against 0.046 / 0.049, with 34 of the 36 groups settled against 28. (In the groups, whose camera is
        not turned, there is no start to forget: A10 stopped at 20 updates does as well; on the crowds it ends
        0.056 degree off, after 73 frames.)
    min_updates : int or None
        Updates (frames whose objects moved the bias) before the bias may be called settled [RECON]. None
        (default): 20, the ``settle_updates`` window, with ``params.warm_start``; 40 without it, which a 3-degree
        error at ``rho = 0.1`` needs to come within 0.05 degree (:attr:`required_updates`).
    settle_updates : int
        Over its last ``settle_updates`` values it has settled when they span at most ``tol_deg``, or when it is
        within ``tol_deg`` of the mean of those updates' targets, two standard errors counted against it
        (:func:`~fusiontrack.calibration.bias_run.bias_settled`) [RECON].
    tol_deg : float
        See ``settle_updates`` (0.1 degrees: about the wander of the settled bias, ``benchmarks/bias.py``).
    max_s : float
        Learning stops this long after the first camera frame even if not settled [RECON].
    """

    params: BiasParams = field(default_factory=lambda: BiasParams(warm_start=True))
    min_updates: int | None = None
    settle_updates: int = 20
    tol_deg: float = 0.1
    max_s: float = 12.0

    def __post_init__(self) -> None:
        for name in ("min_updates", "settle_updates"):
            v = getattr(self, name)
            if name == "min_updates" and v is None:
                continue
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ConfigError(f"BiasLearning.{name}: expected an integer >= 1, got {v!r}")
        for name in ("tol_deg", "max_s"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and np.isfinite(v) and v > 0):
                raise ConfigError(f"BiasLearning.{name}: expected a finite value > 0, got {v!r}")
        if not isinstance(self.params, BiasParams):
            raise ConfigError(f"BiasLearning.params: expected BiasParams, got {type(self.params).__name__}")

    @property
    def required_updates(self) -> int:
        """``min_updates``, or its default for ``params`` (20 with the warm start, 40 without)."""
        if self.min_updates is not None:
            return self.min_updates
        return 20 if self.params.warm_start else 40


@dataclass(frozen=True, slots=True, eq=False)
class CameraBias:
    """The horizontal bias learnt by :func:`learn_camera_bias`.

    Attributes
    ----------
    history : BiasHistory
        The bias after every camera frame read (its CSV: :func:`~fusiontrack.calibration.bias_run.
        write_bias_history`).
    camera : PinholeCamera
        The camera as calibrated.
    corrected_camera : PinholeCamera
        ``camera`` turned by the final bias if ``applied``, else ``camera``: what the fused tracker uses.
    settled : bool
        Learning stopped because the bias had settled (else: end of ``max_s`` or of the recording).
    spread_rad : float
        Span of the bias over its last ``settle_updates`` updates (NaN with fewer).
    applied : bool
        The bias corrects the camera: settled, or standing out from its spread (:class:`BiasLearning`).
    seconds : float
        Processing time of the learning.
    targets_rad : (updates,) float64
        Each update's target ``b + ē`` (A10: the bias before it plus its mean residual), what that frame's
        people said the bias was; the rule that stopped learning judges them (:func:`~fusiontrack.calibration.
        bias_run.bias_settled`).
    """

    history: BiasHistory
    camera: PinholeCamera
    corrected_camera: PinholeCamera
    settled: bool
    spread_rad: float
    applied: bool
    seconds: float
    targets_rad: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @property
    def bias_rad(self) -> float:
        """The final bias (0 without any update)."""
        return float(self.history.bias_rad[-1]) if len(self.history) else 0.0

    @property
    def updates(self) -> int:
        """Frames whose objects moved the bias."""
        return int(np.count_nonzero(self.history.n_used))


@dataclass(slots=True)
class FusionStats:
    """What the camera was used for during a run."""

    steps: int = 0
    frames_used: int = 0  # distinct camera images read
    train_frames: int = 0  # (step, image) pairs the bank learnt from
    train_alone: int = 0  # (target, image) samples of targets learning with nobody near (learn_all_s)
    frames_alone: int = 0  # images read for those targets alone
    train_updates: int = 0  # classifier ensemble updates
    score_maps: int = 0  # B16 score maps computed
    splits: int = 0  # splits seen
    splits_by_appearance: int = 0
    overrides: int = 0  # splits where appearance gave another assignment than motion
    checks: int = 0  # identity checks decided
    exchanges: int = 0  # ... that exchanged the identities of a pair
    withheld: int = 0  # ... that found them exchanged but kept them: one voter (check_voters), or a classifier too new
    # (check_min_updates)
    reid_claims: int = 0  # new tracks born near a recently lost one (re-identification candidates)
    reids: int = 0  # ... given the lost identity
    camera_s: float = 0.0  # time spent on the camera side (reading, learning, scoring)
    camera: str = ""  # the camera fused ("": none, the lasers alone)
    # ... as calibrated (the pipeline file's pose, camera_poses, or /tf_static), before the bias learnt on it
    camera_model: PinholeCamera | None = field(default=None, compare=False, repr=False)
    bias: CameraBias | None = None  # the camera's horizontal bias learnt before fusing (None: not learnt)


class _NoFrames:
    """The frame source of a tracker without a camera: never an image."""

    def nearest_time(self, t_ns: int) -> int | None:
        return None

    def at(self, t_ns: int) -> Image | None:
        return None


def _assignment_gap(scores: np.ndarray) -> float:
    """Summed score of the best one-to-one assignment of rows to columns minus that of the second best (the
    evidence appearance has for its choice); inf with a single possible assignment.

    The best assignment is :func:`scipy.optimize.linear_sum_assignment`'s; the second best differs from it in at
    least one pair, so it is the best of the ``k`` problems with one of the best's pairs forbidden (the first level
    of Murty's ranking): ``k + 1`` assignments of ``O(n^3)`` instead of ``n! / (n - k)!`` enumerated ones.
    """
    from scipy.optimize import linear_sum_assignment

    s = np.asarray(scores, np.float64)
    if min(s.shape) == 0:
        return 0.0
    s = s if s.shape[0] <= s.shape[1] else s.T  # k rows, each given a distinct column
    rows, cols = linear_sum_assignment(s, maximize=True)
    best = float(s[rows, cols].sum())
    second = -np.inf
    cost = -s
    for r, c in zip(rows, cols, strict=True):
        forbidden = cost.copy()
        forbidden[r, c] = np.inf
        try:
            rr, cc = linear_sum_assignment(forbidden)
        except ValueError:  # no assignment without this pair
            continue
        second = max(second, float(s[rr, cc].sum()))
    return best - second if np.isfinite(second) else float("inf")


def _assigned_min(scores: np.ndarray) -> float:
    """The lowest score of the best one-to-one assignment of rows to columns (B17 rejects a pair below ``s_min``)."""
    from scipy.optimize import linear_sum_assignment

    s = np.asarray(scores, np.float64)
    if min(s.shape) == 0:
        return -np.inf
    rows, cols = linear_sum_assignment(s, maximize=True)
    return float(s[rows, cols].min())


@dataclass(slots=True)
class _Check:
    """A pair of tracks that came into contact: their identities wait for the camera's evidence."""

    swap_from_ns: int  # where an exchange would have begun: the two tracks' closest approach since the check opened
    closest_m: float
    near_ns: int  # last step the two were within d_train_m
    voters: frozenset[int]  # the ids whose classifiers were trained at the contact: only they give evidence
    evidence: float = 0.0  # summed per-classifier evidence for the current identities, since the closest approach
    n: int = 0
    image_ns: int = -1  # the last image that gave evidence
    decided: bool = False  # decided since the pair's last contact: waits for the next contact
    exchanged: bool = False  # an exchange was decided: the pair's later checks keep these voters
    path: deque[tuple[int, np.ndarray]] = field(default_factory=lambda: deque(maxlen=DATE_PATH_STEPS))  # (t_ns,
    # the pair's (2, 4) states: x, y, vx, vy) on the steps they were in contact since the check opened (the last
    # DATE_PATH_STEPS): where the laser tracks may have been exchanged


@dataclass(slots=True)
class _Claim:
    """A new track born near recently lost ones: may it take one of their identities?"""

    first_ns: int  # its first detection
    candidates: list[int]  # the lost ids it may be
    sums: dict[int, float] = field(default_factory=dict)  # id -> summed mean box confidence
    counts: dict[int, int] = field(default_factory=dict)
    n: int = 0  # images scored
    image_ns: int = -1


@dataclass(frozen=True, slots=True)
class Relabel:
    """Two ids exchanged in ``[from_ns, to_ns)`` (the tracker's own ids change from ``to_ns`` on): by an identity
    check (``a`` and ``b`` followed each other's person), or by a re-identification (new track ``a`` is lost track
    ``b`` reborn: the exchange names ``a``'s states ``b``; ``b``'s only states in the window are the guesses the
    laser tracker coasted after ``b``'s last detection, and they take ``a``'s id)."""

    from_ns: int
    to_ns: int
    a: int
    b: int


def camera_boxes(states: Sequence[TrackState], stats: FusionStats,
                 params: FusionParams | None = None) -> list[TrackState]:
    """The fused tracks with each person's box in the camera they were fused through (``box_px``, ``camera``): B11's
    box of the floor position, the one the fused tracker reads the camera in, through the camera as the bias pass
    corrected it (``stats`` of the run). People whose box lies wholly outside the image or behind the camera, vehicles,
    and all states of a run without a camera stay as they are. For writing and scoring the tracks in the image
    (``fusiontrack eval --camera``); a projection, not a detection: ``sensors`` says when the camera was used."""
    camera = stats.bias.corrected_camera if stats.bias is not None else stats.camera_model
    out = list(states)
    people = [k for k, s in enumerate(out) if s.cls == ObjectClass.PERSON and s.box_px is None]
    if camera is None or not stats.camera or not people:
        return out
    p = params or FusionParams()
    boxes = camera.person_box(np.array([out[k].position_m for k in people]), p.height_m, p.width_ratio)
    seen = box_visibility(boxes, (camera.height, camera.width)) > 0
    for k, box in zip(np.asarray(people)[seen], boxes[seen], strict=True):
        out[k] = dataclasses.replace(out[k], box_px=box, camera=stats.camera)
    return out


def relabel_states(states: Sequence[TrackState], relabels: Sequence[Relabel]) -> list[TrackState]:
    """``states`` with the identity decisions (exchanges, re-identifications) applied, in the order they were
    decided (each one names tracks by the ids in force once the earlier ones are applied)."""
    if not relabels or not states:
        return list(states)
    t = np.array([st.t_ns for st in states], np.int64)
    ids = np.array([st.track_id for st in states], np.int64)
    new = ids.copy()
    for r in relabels:
        window = (t >= r.from_ns) & (t < r.to_ns)
        is_a, is_b = window & (new == r.a), window & (new == r.b)
        new[is_a], new[is_b] = r.b, r.a
    out = list(states)
    for k in np.flatnonzero(new != ids):
        out[k] = dataclasses.replace(states[k], track_id=int(new[k]))
    return out


DATE_WINDOW_S = 0.2  # half-width of the window in which an exchange of two laser tracks is looked for
DATE_GAIN_M = 0.1  # how much better, in metres, the exchanged tracks must continue each other's motion
DATE_GAP_NS = 100_000_000  # steps further apart than this in a check's path: the pair was out of contact between
DATE_PATH_STEPS = 1500  # a check's path keeps the pair's last contact steps (a minute at 25 Hz), not all of them


def _exchange_date(c: _Check) -> int:
    """When the laser tracks of an exchanged check took each other's person.

    An exchange of two laser tracks shows in their motion: each track's position ``DATE_WINDOW_S`` after it is
    better predicted (constant velocity) from the other track's state ``DATE_WINDOW_S`` before it than from its own.
    Over the steps on which the pair was in contact since the check opened, the window where exchanging the tracks
    shortens the two prediction errors most (by more than ``DATE_GAIN_M``) holds the exchange; it is dated at the
    step within it where exchanging the tracks from then on shortens their one-step prediction errors most (where
    the laser tracks jumped onto each other's person). Without such a window (e.g. two people walking side by side,
    whose tracks continue either person's motion alike) the pair's closest approach since the check opened dates it
    (``c.swap_from_ns``).
    """
    if len(c.path) < 3:
        return c.swap_from_ns
    t = np.array([tk for tk, _ in c.path], np.int64)
    x = np.stack([xk for _, xk in c.path])  # (n, 2, 4)
    w = round(DATE_WINDOW_S * 1e9)
    lo = np.searchsorted(t, t - w)
    hi = np.searchsorted(t, t + w, side="right") - 1
    span = (t[hi] - t[lo]) * 1e-9
    stretch = np.r_[0, np.cumsum(np.diff(t) > DATE_GAP_NS)]  # stretches of contact, split where steps are missing
    ok = (span >= DATE_WINDOW_S) & (stretch[lo] == stretch[hi])  # a full window, not across a gap in the contact
    if not ok.any():
        return c.swap_from_ns
    lo, hi, span = lo[ok], hi[ok], span[ok]
    pred = x[lo, :, :2] + x[lo, :, 2:] * span[:, None, None]  # (m, 2, 2): each track's own prediction
    after = x[hi, :, :2]
    own = np.linalg.norm(after - pred, axis=2).sum(axis=1)
    crossed = np.linalg.norm(after[:, ::-1] - pred, axis=2).sum(axis=1)
    gain = np.where(np.isfinite(own - crossed), own - crossed, -np.inf)  # (a velocity unknown: no evidence)
    k = int(np.argmax(gain))
    if not gain[k] > DATE_GAIN_M:
        return c.swap_from_ns
    j = np.arange(lo[k] + 1, hi[k] + 1)  # the step within it where exchanging the tracks from on shortens most
    step_pred = x[j - 1, :, :2] + x[j - 1, :, 2:] * ((t[j] - t[j - 1]) * 1e-9)[:, None, None]
    step_gain = (np.linalg.norm(x[j, :, :2] - step_pred, axis=2).sum(axis=1)
                 - np.linalg.norm(x[j, ::-1, :2] - step_pred, axis=2).sum(axis=1))
    step_gain = np.where(np.isfinite(step_gain), step_gain, -np.inf)
    return int(t[j[int(np.argmax(step_gain))]])


def _occlusion(boxes: np.ndarray, ok: np.ndarray) -> np.ndarray:
    """``(n,)``: the largest fraction of each box's area that lies inside another (valid) box."""
    b = np.where(ok[:, None], boxes, 0.0)
    lo = np.maximum(b[:, None, :2], b[None, :, :2])
    hi = np.minimum(b[:, None, 2:], b[None, :, 2:])
    inter = np.clip(hi - lo, 0.0, None).prod(axis=2)
    area = np.maximum((b[:, 2:] - b[:, :2]).prod(axis=1), 1e-9)
    frac = inter / area[:, None]
    np.fill_diagonal(frac, 0.0)
    frac[:, ~ok] = 0.0
    return frac.max(axis=1) if len(b) else np.zeros(0)


def _components(points: np.ndarray, radius_m: float) -> np.ndarray:
    """Labels ``(n,)`` of the groups of ``points (n, 2)`` linked by distances below ``radius_m``, numbered in the
    order of their first point (as :func:`scipy.sparse.csgraph.connected_components`; a few targets: a search
    in Python costs a tenth of building its sparse graph)."""
    n = points.shape[0]
    if n < 2:
        return np.arange(n)
    close = (np.linalg.norm(points[:, None] - points[None], axis=2) < radius_m).tolist()
    labels = [-1] * n
    count = 0
    for first in range(n):
        if labels[first] >= 0:
            continue
        labels[first] = count
        stack = [first]
        while stack:
            row = close[stack.pop()]
            for j in range(n):
                if row[j] and labels[j] < 0:
                    labels[j] = count
                    stack.append(j)
        count += 1
    return np.array(labels)


class FusionTracker:
    """Laser people tracker with online per-target appearance classifiers (seed 001; module docstring).

    Parameters
    ----------
    camera : PinholeCamera or None
        The calibrated camera (world frame, B11); None: no camera, the laser tracker alone.
    frames : FrameSource or None
        Its images by time (None: none).
    params : FusionParams, optional
    tracker_params : TrackerParams or mapping, optional
        Of the laser tracker.
    area_m : optional
        Covered area (see :class:`LaserPeopleTracker`).
    rng : Generator, int or None
        The laser tracker's, used as :class:`LaserPeopleTracker` uses it (so a fused run draws the laser-only
        run's particles); the bank gets an independent child stream of it.
    camera_name : str
        The camera's sensor name, added to ``TrackState.sensors`` when its image was used.

    Attributes
    ----------
    relabels : list of Relabel
        The identity exchanges decided so far, in order (apply them with :func:`relabel_states`).
    stats : FusionStats
    """

    def __init__(self, camera: PinholeCamera | None, frames: FrameSource | None, params: FusionParams | None = None,
                 tracker_params: TrackerParams | Mapping[str, Any] | None = None, *, area_m: Any = None,
                 rng: np.random.Generator | int | None = None, camera_name: str = "camera") -> None:
        self.params = p = params or FusionParams()
        self.camera = camera
        self.frames: FrameSource = frames if frames is not None and camera is not None else _NoFrames()
        self.camera_name = camera_name
        # the laser tracker draws exactly the stream laser-only's tracker draws for the same ``rng`` (the two
        # pipelines' runs are paired: where the camera changes nothing, their tracks are identical); the bank gets
        # a child stream (spawning does not advance the parent)
        r_laser = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
        r_bank = r_laser.spawn(1)[0]
        self.bank = AppearanceBank(p.appearance, rng=r_bank)
        self.laser = LaserPeopleTracker(tracker_params, area_m=area_m, rng=r_laser,
                                        extra_log_likelihood=self._score_map_ll if p.score_map else None,
                                        split_scores=self._split_scores if p.split_identity else None)
        self.stats = FusionStats()
        self.events: list[Event] = []
        self._used: set[int] = set()  # ids whose step used the camera
        self._scored: dict[int, int] = {}  # id -> time of the image last used for its score map
        self._learnt_t: dict[int, int] = {}  # id -> time of its last training step
        self._learnt_near: set[int] = set()  # ids that learnt as B15's learners (another target near)
        # learning alone (``learn_all_s``): the ids whose classifier learnt only so, when they last learnt, and the
        # random stream of their patches (B15's learning draws from the bank's own as without it)
        self._alone: set[int] = set()
        self._alone_t: dict[int, int] = {}
        self._rng_alone = r_bank.spawn(1)[0] if p.learn_all_s else None
        self._frames_seen: set[int] = set()
        self._read_ns = -1  # the last laser step that read an image (it is cached: another read is free)
        self._checks: dict[tuple[int, int], _Check] = {}
        self.relabels: list[Relabel] = []
        # re-identification: the laser tracker keeps its own ids; a reborn track's output id is the lost one's
        self._alias: dict[int, int] = {}  # laser id -> output id (only for re-identified tracks)
        self._laser_id: dict[int, int] = {}  # output id -> laser id (its inverse, for live re-identified tracks)
        self._lost: dict[int, tuple[int, int, np.ndarray]] = {}  # lost id -> (last seen, death time, position)
        self._born: dict[int, tuple[int, np.ndarray]] = {}  # recent births: id -> (first detection, position)
        self._claims: dict[int, _Claim] = {}  # new id -> its claim on lost identities
        self._span: dict[int, list[int]] = {}  # output id -> [first, last] time of its states

    @property
    def area_m(self) -> np.ndarray | None:
        return self.laser.area_m

    @area_m.setter
    def area_m(self, value: Any) -> None:
        self.laser.area_m = value

    # ---------------------------------------------------------------------------------------------
    def step(self, t_ns: int, detections: Sequence[Detection]) -> list[TrackState]:
        """One laser step, identity checks, then learning (B15). Returns the states (``sensors`` with the camera
        where used; ids as exchanged by a check decided at this step, earlier states in :attr:`relabels`)."""
        self._used = set()
        self.stats.steps += 1
        states = self.laser.step(t_ns, detections)
        # Vehicles (the laser tracker's constant-velocity tracks of rigid objects) are not people: no camera
        # classifiers, checks or re-identification; their states and events pass through.
        vehicles = self.laser.vehicle_ids
        cars: list[TrackState] = []
        car_events: list[Event] = []
        events = self.laser.events
        if vehicles:
            cars = [s for s in states if s.track_id in vehicles]
            states = [s for s in states if s.track_id not in vehicles]
            car_events = [e for e in events if vehicles.intersection(e.track_ids)]
            events = [e for e in events if not vehicles.intersection(e.track_ids)]
        self.events = self._out_events(events)
        out = self._people_step(t_ns, states)
        if car_events:
            self.events.extend(car_events)
        return out + cars if cars else out

    def _people_step(self, t_ns: int, states: list[TrackState]) -> list[TrackState]:
        """:meth:`step` for the people's states."""
        if self._alias:
            states = [dataclasses.replace(st, track_id=self._alias[st.track_id]) if st.track_id in self._alias
                      else st for st in states]
        if self.params.reid:
            states = self._reidentify(int(t_ns), states)
        if self.params.check_identity and states:
            states = self._check_identities(int(t_ns), states)
        if states:
            self._learn(int(t_ns), states)
        self._forget(self.events)
        if not self._used:
            return states
        cam = self.camera_name
        return [dataclasses.replace(s, sensors=(*s.sensors, cam)) if s.track_id in self._used else s
                for s in states]

    def finish(self) -> list[Event]:
        """The events still held back by the laser tracker (end of a run)."""
        return self._out_events(self.laser.finish())

    def _merged_ids(self) -> set[int]:
        """Output ids of the members of the laser tracker's merged targets (their states say ``merged``, or
        ``correlated`` while splitting)."""
        return {self._out(t) for t in self.laser.merged_ids}

    def _out(self, tid: int) -> int:
        """The output id of laser track ``tid``."""
        return self._alias.get(int(tid), int(tid))

    def _out_events(self, events: Iterable[Event]) -> list[Event]:
        """The laser tracker's events under the output ids."""
        if not self._alias:
            return list(events)
        out = []
        for e in events:
            if any(t in self._alias for t in e.track_ids):
                attrs = e.attributes
                if "parts" in attrs:
                    attrs = {**attrs, "parts": tuple(sorted(tuple(sorted(self._out(t) for t in part))
                                                            for part in attrs["parts"]))}
                e = dataclasses.replace(e, track_ids=tuple(self._out(t) for t in e.track_ids), attributes=attrs)
            out.append(e)
        return out

    # ---------------------------------------------------------------------------------------------
    def _image(self, t_ns: int) -> Image | None:
        t0 = time.perf_counter()
        img = self.frames.at(t_ns)
        self._read_ns = t_ns
        if img is not None:
            # the score maps, checks and learning of a step score the same image: its integral images are reused
            self.bank.cache_image(img.pixels)
            if img.t_ns not in self._frames_seen:
                self._frames_seen.add(img.t_ns)
                self.stats.frames_used += 1
        self.stats.camera_s += time.perf_counter() - t0
        return img

    def _boxes(self, positions_m: np.ndarray) -> np.ndarray:
        """B11 person boxes ``(n, 4)`` of floor positions ``(n, 2)``; NaN rows behind the camera (or without one)."""
        if self.camera is None:
            return np.full((len(positions_m), 4), np.nan)
        return self.camera.person_box(positions_m, self.params.height_m, self.params.width_ratio)

    def _clear_boxes(self, positions_m: np.ndarray, boxes: np.ndarray | None = None,
                     visibility: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(boxes, finite, clear): B11's boxes at ``positions_m``, which are finite, and which a classifier can
        judge: finite, mostly inside the image (``check_visible``) and not largely inside another box
        (``max_overlap``). ``boxes`` and their ``visibility`` (:func:`box_visibility`): if the caller has them."""
        p = self.params
        boxes = self._boxes(positions_m) if boxes is None else boxes
        finite = np.isfinite(boxes).all(axis=1)
        clear = finite & (_occlusion(boxes, finite) <= p.max_overlap)  # largest fraction inside another box
        if p.check_visible > 0 and self.camera is not None:
            if visibility is None:
                visibility = box_visibility(boxes, (self.camera.height, self.camera.width))
            clear &= visibility >= p.check_visible
        return boxes, finite, clear

    def _depths(self, positions_m: Mapping[int, np.ndarray]) -> dict[int, float] | None:
        """Each target's floor distance from the camera, which puts the nearer of two overlapping boxes in front
        (:meth:`AppearanceBank.train`); None when B15's rule (no patch in another box) is asked for."""
        if self.camera is None or not self.params.depth_order:
            return None
        c = self.camera.position_m[:2]
        return {tid: float(np.hypot(*(np.asarray(q, np.float64)[:2] - c))) for tid, q in positions_m.items()}

    def _box_centres(self, positions_m: np.ndarray) -> np.ndarray:
        b = self._boxes(positions_m)
        return 0.5 * (b[:, :2] + b[:, 2:])

    def _forget(self, events: Iterable[Event]) -> None:
        for e in events:
            if e.kind in ("disappear", "lost"):
                self.bank.drop([tid for tid in e.track_ids if tid not in self._lost])  # (kept to re-identify)
                for tid in e.track_ids:
                    self._scored.pop(tid, None)
                    self._learnt_t.pop(tid, None)
                    self._alone_t.pop(tid, None)
                    if tid not in self._lost:
                        self._learnt_near.discard(tid)
                        self._alone.discard(tid)
            elif e.kind == "split":
                self.stats.splits += 1
                if e.attributes.get("identity") == "appearance":
                    self.stats.splits_by_appearance += 1
                    self.stats.overrides += bool(e.attributes.get("overrode_motion"))

    # ---------------------------------------------------------------------------------------------
    def _reidentify(self, t_ns: int, states: list[TrackState]) -> list[TrackState]:
        """Re-identification of reborn tracks (``FusionParams.reid``): note this step's losses and births, open
        claims of new tracks on lost identities within reach, score them on a clear camera image and give the lost
        identity back when its classifier is confident. Returns the states with the identities given back."""
        p = self.params
        horizon = round(p.reid_s * 1e9)
        for st in states:
            span = self._span.get(st.track_id)
            if span is None:
                self._span[st.track_id] = [st.t_ns, st.t_ns]
            else:
                span[1] = st.t_ns
        for e in self.events:
            if e.kind == "disappear" or (e.kind == "lost" and not (len(e.track_ids) == 1
                                                                   and self.bank.is_trained(e.track_ids[0]))):
                for tid in e.track_ids:
                    self._span.pop(tid, None)
            elif e.kind == "lost":  # inside the area (at its edge the person most likely left it)
                tid = e.track_ids[0]
                pos = np.asarray(e.position_m if e.position_m is not None else np.full(2, np.nan), float)
                self._lost[tid] = (int(e.t_ns), t_ns, pos)
                self._claims.pop(tid, None)
                for q, (first, qpos) in self._born.items():  # a track born before the loss was declared
                    self._open_claim(q, first, qpos, tid)
            elif e.kind in ("born", "appear") and len(e.track_ids) == 1 and e.position_m is not None:
                q = e.track_ids[0]
                self._born[q] = (int(e.t_ns), np.asarray(e.position_m, float))
                for tid in self._lost:
                    self._open_claim(q, int(e.t_ns), self._born[q][1], tid)
        # forget what is too old to matter
        for tid in [tid for tid, lost in self._lost.items() if t_ns - lost[1] > horizon]:
            del self._lost[tid]
            self.bank.drop(tid)
            self._learnt_near.discard(tid)
            self._alone.discard(tid)
            self._span.pop(tid, None)
            for c in self._claims.values():
                if tid in c.candidates:
                    c.candidates.remove(tid)
        live = {st.track_id for st in states}
        for q in [q for q, (first, _) in self._born.items() if t_ns - first > horizon or q not in live]:
            del self._born[q]
        for q in [q for q, c in self._claims.items() if not c.candidates or q not in live
                  or t_ns - c.first_ns > 2 * horizon]:
            del self._claims[q]
        if not self._claims:
            return states
        t_img = self.frames.nearest_time(t_ns)
        if t_img is None:
            return states
        interval = round(p.train_interval_s * 1e9)
        row = {st.track_id: k for k, st in enumerate(states)}
        merged = self._merged_ids()
        todo = [q for q, c in self._claims.items() if t_img - c.image_ns >= interval and q not in merged]
        if not todo:
            return states
        t0 = time.perf_counter()
        pos = np.array([st.position_m for st in states])
        boxes, _, clear = self._clear_boxes(pos)
        todo = [q for q in todo if clear[row[q]]]
        img = self._image(t_ns) if todo else None
        given: dict[int, int] = {}
        if img is not None:
            d = np.linalg.norm(pos[:, None] - pos[None], axis=2)
            for q in todo:
                c = self._claims[q]
                k = row[q]
                # the alternatives: the live tracks around it (it could be one of them seen twice, or look alike)
                alts = [states[j].track_id for j in np.flatnonzero(d[k] < p.d_train_m)
                        if j != k and self.bank.is_trained(states[j].track_id)]
                ids = [*c.candidates, *alts]
                sc = self.bank.box_scores(img.pixels, boxes[k][None], ids)[0]
                if not np.isfinite(sc).all():
                    continue
                c.n += 1
                c.image_ns = t_img
                for tid, v in zip(ids, sc, strict=True):
                    c.sums[tid] = c.sums.get(tid, 0.0) + float(v)
                    c.counts[tid] = c.counts.get(tid, 0) + 1
                self._used.add(q)
                best = self._claim_decision(c)
                if best is not None and best not in given.values():
                    given[q] = best
        for q, lost in given.items():
            states = self._give_back(t_ns, q, lost, states)
        self.stats.camera_s += time.perf_counter() - t0
        return states

    def _open_claim(self, q: int, first_ns: int, q_pos: np.ndarray, lost: int) -> None:
        """Let new track ``q`` (first detected at ``first_ns`` at ``q_pos``) claim lost id ``lost`` if within
        reach in time and space."""
        p = self.params
        seen_ns, lost_ns, pos = self._lost[lost]
        gap_s = (first_ns - seen_ns) / 1e9
        span = self._span.get(lost)
        if q == lost or gap_s > p.reid_s or gap_s < -p.reid_s or (span is not None and span[0] >= first_ns):
            return
        # ``pos`` is where the laser tracker had coasted the track to when it gave up on it, ``lost_ns``, not where
        # it was last seen: the person is within walking reach of the last sighting, which is within the coasting's
        # length of ``pos`` [without the coasting's part, a track coasted 1 s away from where a new one was born
        # 0.1 s after the last sighting was out of reach]
        coast_s = max(lost_ns - seen_ns, 0) / 1e9
        if not np.hypot(*(q_pos - pos)) <= p.reid_slack_m + p.reid_speed_mps * (abs(gap_s) + coast_s):
            return
        c = self._claims.get(q)
        if c is None:
            self._claims[q] = _Claim(first_ns, [lost])
            self.stats.reid_claims += 1
        elif lost not in c.candidates:
            c.candidates.append(lost)

    def _claim_decision(self, c: _Claim) -> int | None:
        """The lost id a claim is decided for, or None (not yet)."""
        p = self.params
        if c.n < p.reid_frames:
            return None
        mean = {tid: c.sums[tid] / c.counts[tid] for tid in c.sums}
        best = max(c.candidates, key=lambda tid: mean.get(tid, -np.inf))
        lowest = p.reid_min_alone if p.reid_min_alone is not None and best in self._alone else p.reid_min
        if mean.get(best, -np.inf) < lowest:
            return None
        rest = [v for tid, v in mean.items() if tid != best]
        return best if not rest or mean[best] - max(rest) >= p.reid_margin else None

    def _give_back(self, t_ns: int, q: int, lost: int, states: list[TrackState]) -> list[TrackState]:
        """New track ``q`` is lost track ``lost`` reborn: it takes that id from now on, and back to its birth
        (:attr:`relabels`; from after the lost track's last state where the two overlap)."""
        c = self._claims.pop(q)
        lq = self._laser_id.pop(q, q)
        self._alias[lq] = lost
        self._laser_id[lost] = lq
        seen_ns = self._lost.pop(lost)[0]
        for other in self._claims.values():
            if lost in other.candidates:
                other.candidates.remove(lost)
        self._born.pop(q, None)
        span_q, span_l = self._span.pop(q, [t_ns, t_ns]), self._span.get(lost)
        # back to the new track's birth, but not over the lost track's detected states: its states after its last
        # detection (the laser tracker coasts a track for a while before calling it lost) are guesses, and where
        # they overlap the new track's, the exchange gives them the new track's id (:class:`Relabel` swaps both)
        from_ns = span_q[0] if span_l is None else max(span_q[0], min(span_l[1], seen_ns) + 1)
        self._span[lost] = [span_l[0] if span_l is not None else span_q[0], t_ns]
        if from_ns < t_ns:
            self.relabels.append(Relabel(int(from_ns), int(t_ns), int(q), int(lost)))
        # the lost identity's classifier goes on (it learnt the person longer); the new track's is dropped
        self.bank.drop(q)
        self._learnt_t.pop(q, None)
        self._learnt_near.discard(q)
        self._alone.discard(q)
        self._alone_t.pop(q, None)
        self._scored.pop(q, None)
        for pair in [pair for pair in self._checks if q in pair]:
            del self._checks[pair]
        self._used.discard(q)
        self._used.add(lost)
        self.stats.reids += 1
        mean = c.sums[lost] / c.counts[lost]
        self.events.append(Event(t_ns, self.camera_name, "identity", t_ns, track_ids=(q, lost),
                                 attributes={"reidentified": True, "from_ns": int(from_ns), "evidence": mean}))
        return [dataclasses.replace(st, track_id=lost) if st.track_id == q else st for st in states]

    # ---------------------------------------------------------------------------------------------
    def _learn(self, t_ns: int, states: list[TrackState]) -> None:
        """B15: noncorrelated targets with another target within ``d_train_m`` learn from this image; with
        ``learn_all_s``, the targets that never had anybody near learn alone now and then (:meth:`_learn_alone`)."""
        p = self.params
        pos = np.array([s.position_m for s in states])
        ids = np.array([s.track_id for s in states])
        if len(states) < 2:
            return
        d = np.linalg.norm(pos[:, None] - pos[None], axis=2)
        np.fill_diagonal(d, np.inf)
        near = d.min(axis=1) < p.d_train_m
        interval = p.train_interval_s * 1e9
        # an untrained target learns from every image, a trained one every ``train_interval_s``
        # a voter of a pending identity check does not learn (it could be learning the other one)
        # (a classifier learnt alone does not count: B15 starts the target's own afresh)
        # ``contact_learn_s``: it does (its checks vote with a copy frozen when they opened), and targets learn while
        # correlated too, a trained one every ``contact_learn_s``
        contact = p.contact_learn_s
        waiting = set() if contact is not None else {tid for c in self._checks.values() for tid in c.voters}
        learning = _LEARNING if contact is None else (*_LEARNING, _CORRELATED)
        # (a member of a merged target seen apart is correlated: its position is a guess until the split)
        merged = self._merged_ids() if contact is not None else set()
        learners = [k for k, s in enumerate(states)
                    if near[k] and s.situation in learning and s.sensors and s.track_id not in merged
                    and (not self.bank.is_trained(s.track_id) or s.track_id in self._alone
                         or (t_ns - self._learnt_t.get(s.track_id, -(1 << 62))
                             >= (interval if s.situation != _CORRELATED else max(interval, contact * 1e9))
                             and s.track_id not in waiting))]
        if learners:
            self._learn_near(t_ns, learners, pos, ids, d)
        if p.learn_all_s:
            self._learn_alone(t_ns, states, pos, ids, d, near)

    def _learn_near(self, t_ns: int, learners: list[int], pos: np.ndarray, ids: np.ndarray, d: np.ndarray) -> None:
        """B15's learning of the rows ``learners`` (targets with another one within ``d_train_m``)."""
        p = self.params
        if self.frames.nearest_time(t_ns) is None:
            return  # no image now (camera blackout, or between frames): the laser goes on alone
        if self.camera is None:
            return
        t0 = time.perf_counter()
        boxes = self._boxes(pos)
        ok = np.isfinite(boxes).all(axis=1)
        # a learner whose box is not (enough) in the image gives the bank no patch: it does not learn, its state is
        # not confirmed by the camera, and the image is not read for it
        seen = self.bank.samples_from(boxes, (self.camera.height, self.camera.width))
        learners = [k for k in learners if seen[k]]
        if not learners:
            self.stats.camera_s += time.perf_counter() - t0
            return
        img = self._image(t_ns)
        if img is None:
            return
        # the learners, their confusers (within d_train), and whoever's box overlaps theirs (occluders)
        lb = boxes[learners]
        overlap = ((boxes[:, None, :2] < lb[None, :, 2:]) & (lb[None, :, :2] < boxes[:, None, 2:])).all(axis=2)
        involved = ok & ((d[:, learners] < p.d_train_m).any(axis=1) | overlap.any(axis=1))
        involved[learners] = True
        rows = np.flatnonzero(involved)
        boxes_by_id = {int(ids[k]): boxes[k] for k in rows}
        positions = {int(ids[k]): pos[k] for k in rows}
        train_ids = [int(ids[k]) for k in learners]
        if self._alone:  # B15's classifier of a target that learnt alone so far starts afresh
            fresh = self._alone.intersection(train_ids)
            self.bank.drop(fresh)
            self._alone.difference_update(fresh)
        # a target's first classifier is fitted at once (B15's cadence would wait 5 frames: often too late, the
        # targets are merged by then)
        first = any(not self.bank.is_trained(tid) for tid in train_ids)
        updated = self.bank.train(img.pixels, boxes_by_id, train_ids=train_ids, positions_m=positions,
                                  force_update=first, depth_m=self._depths(positions))
        for tid in train_ids:
            self._learnt_t[tid] = t_ns
        self._learnt_near.update(train_ids)
        self._used.update(train_ids)
        self.stats.train_frames += 1
        self.stats.train_updates += len(updated)
        self.stats.camera_s += time.perf_counter() - t0

    def _learn_alone(self, t_ns: int, states: list[TrackState], pos: np.ndarray, ids: np.ndarray, d: np.ndarray,
                     near: np.ndarray) -> None:
        """``learn_all_s``: the noncorrelated targets that never learnt as B15's learners (nobody was ever within
        ``d_train_m``) learn alone, so that a reborn track of theirs can be re-identified.

        Such a target learns when its box is clear (``max_overlap``) and mostly in the image (``check_visible``),
        at least ``learn_all_s / 2`` after its last time: on an image read at this step anyway, or when one of them
        is ``learn_all_s`` overdue (an image is then read for them). Negatives: its ``L`` closest targets in the
        image (B15's ``n_confusers``), wherever they are, and whoever's box overlaps its own. The patches are drawn
        from a random stream of their own, so that B15's learning and the checks draw what they draw without
        it. Its classifier is dropped when the target first learns as B15's learner (B15's starts afresh)."""
        p = self.params
        every = p.learn_all_s * 1e9
        since = np.array([t_ns - self._alone_t.get(int(tid), -(1 << 62)) for tid in ids])
        rows = [k for k, s in enumerate(states) if not near[k] and s.situation in _LEARNING and s.sensors
                and int(ids[k]) not in self._learnt_near and since[k] >= every / 2]
        if not rows or self.camera is None:
            return
        anyway = self._read_ns == t_ns
        if not (anyway or (since[rows] >= every).any()):
            return
        t_img = self.frames.nearest_time(t_ns)
        if t_img is None:
            return
        t0 = time.perf_counter()
        # first the cheap reasons to stop, before the boxes' overlaps (a lone person out of the camera's view, or
        # alone in it, stays overdue: otherwise every target's boxes were worked out at every step for nothing)
        all_boxes = self.camera.person_box(pos, p.height_m, p.width_ratio)
        vis = box_visibility(all_boxes, (self.camera.height, self.camera.width))
        seen = np.isfinite(all_boxes).all(axis=1) & (vis >= self.bank.params.patches.min_visible)
        overdue = [k for k in rows if since[k] >= every]
        if np.count_nonzero(seen) < 2 or not (anyway or p.check_visible <= 0
                                              or (vis[overdue] >= p.check_visible).any()):
            self.stats.camera_s += time.perf_counter() - t0
            return
        boxes, ok, clear = self._clear_boxes(pos, all_boxes, vis)
        learners = [k for k in rows if clear[k]]
        if not learners or not (anyway or (since[learners] >= every).any()):
            self.stats.camera_s += time.perf_counter() - t0
            return
        img = self._image(t_ns)
        if img is None:  # (unreadable: not again at every step)
            self._alone_t.update((int(ids[k]), t_ns) for k in learners)
            self.stats.camera_s += time.perf_counter() - t0
            return
        self.stats.frames_alone += not anyway
        involved = np.zeros(len(ids), bool)
        lb = boxes[learners]
        overlap = ((boxes[:, None, :2] < lb[None, :, 2:]) & (lb[None, :, :2] < boxes[:, None, 2:])).all(axis=2)
        involved |= ok & overlap.any(axis=1)
        for k in learners:
            others = [j for j in np.argsort(d[k], kind="stable") if seen[j] and j != k]
            involved[others[: self.bank.params.n_confusers]] = True
        involved[learners] = True
        rows_in = np.flatnonzero(involved)
        train_ids = [int(ids[k]) for k in learners]
        first = any(not self.bank.is_trained(tid) for tid in train_ids)
        bank_rng, self.bank.rng = self.bank.rng, self._rng_alone
        try:
            where = {int(ids[k]): pos[k] for k in rows_in}
            updated = self.bank.train(img.pixels, {int(ids[k]): boxes[k] for k in rows_in}, train_ids=train_ids,
                                      positions_m=where, force_update=first, depth_m=self._depths(where))
        finally:
            self.bank.rng = bank_rng
        for tid in train_ids:
            self._alone_t[tid] = t_ns
        self._alone.update(train_ids)
        self._used.update(train_ids)
        self.stats.train_alone += len(train_ids)
        self.stats.train_updates += len(updated)
        self.stats.camera_s += time.perf_counter() - t0

    # ---------------------------------------------------------------------------------------------
    def _check_identities(self, t_ns: int, states: list[TrackState]) -> list[TrackState]:
        """Open, feed and decide the identity checks of pairs of tracks that came into contact.

        A pair is opened when its tracks come within ``d_contact_m`` or merge or split together. On every camera
        image on which both are walking targets (not merged) with clear boxes (``max_overlap``) mostly inside the
        image (``check_visible``), each of the two classifiers that was trained when the check opened (its
        voters; a check without any is reopened at the next contact) gives its evidence, its confidence on its
        own track's box minus that on the other box. After ``check_frames`` images, a mean evidence beyond
        ``± check_margin`` keeps the identities or exchanges them (:meth:`_exchange`; only if ``check_voters``
        classifiers (by default both) gave evidence on the deciding image and each has been updated
        ``check_min_updates`` times, else it keeps them: ``stats.withheld``); the decided check waits for the
        pair's next contact (the next step, while they stay close) and is then run again by the same voters (a
        classifier first trained during the contact may have learnt the other person), until the pair has been
        apart for ``check_s``. A track is exchanged at most once per step (a later check of it waits for the next
        image: its evidence was reset and this step's boxes carry the old ids); the states of this step are
        returned with the exchanges applied one after the other, as the laser tracker's ids were.
        """
        p = self.params
        ids = [int(st.track_id) for st in states]
        pos = np.array([st.position_m for st in states])
        row = {tid: k for k, tid in enumerate(ids)}
        d = np.linalg.norm(pos[:, None] - pos[None], axis=2)
        checks = self._checks
        # contacts: close pairs (row-major, as the checks are then opened and scored), and the members of this
        # step's merges and splits
        contacts: dict[tuple[int, int], None] = {}  # (a dict: in the order found)
        for i, j in zip(*(k.tolist() for k in np.nonzero(d < p.d_contact_m)), strict=True):
            if i < j:
                a, b = ids[i], ids[j]
                contacts[(a, b) if a < b else (b, a)] = None
        for e in self.events:
            if e.kind in ("merge", "split"):
                for a, b in itertools.combinations(sorted(e.track_ids), 2):
                    if a in row and b in row:
                        contacts[(a, b)] = None
        for pair in contacts:
            dist = float(d[row[pair[0]], row[pair[1]]])
            c = checks.get(pair)
            if c is not None and not c.decided and c.voters:
                c.path.append((t_ns, self._pair_state(states, row, pair)))
            if c is None or not c.voters:
                # a classifier trained only after the contact may have learnt the other person: it never votes.
                # A check without voters is (re)opened at each contact until one of the two has a classifier.
                # (a classifier that learnt alone, ``learn_all_s``, never saw a person near its own: no voter)
                voters = frozenset(tid for tid in pair if self.bank.is_trained(tid) and tid not in self._alone)
                checks[pair] = _Check(t_ns, dist, t_ns, voters)
                checks[pair].path.append((t_ns, self._pair_state(states, row, pair)))
                if p.contact_learn_s is not None:  # the voters go on learning; their votes are the classifiers of
                    # now (or of the opening of another check of theirs still undecided, which may hold the person)
                    for tid in voters:
                        if self._undecided_elsewhere(tid, pair) is None:
                            self.bank.freeze(tid)
                continue
            if c.decided:  # a decided pair still or again in contact: checked again, by the same voters (a
                # classifier first trained during the contact, e.g. of a track born beside the other, may have
                # learnt the other person under its id); new voters only once the check is dropped (check_s apart)
                checks[pair] = _Check(t_ns, dist, c.near_ns, c.voters, exchanged=c.exchanged)
                checks[pair].path.append((t_ns, self._pair_state(states, row, pair)))
                continue
            if dist < c.closest_m:  # an exchange, if any, most likely happened where the two tracks came closest;
                # the evidence gathered before it was of the identities before it: it would dilute the evidence of
                # an exchange here (a check undecided on weak evidence never decided after the pair's next merge)
                c.swap_from_ns, c.closest_m = t_ns, dist
                c.evidence, c.n = 0.0, 0
        for pair in list(checks):
            a, b = pair
            if a not in row or b not in row:  # one of them has ended: nothing to check
                del checks[pair]
                continue
            if d[row[a], row[b]] < p.d_train_m:
                checks[pair].near_ns = t_ns
            elif t_ns - checks[pair].near_ns > p.check_s * 1e9:
                del checks[pair]
        if self.bank.frozen_ids:  # a classifier in no check any more votes as it is at its next check
            voting = {tid for c in checks.values() for tid in c.voters}
            for tid in set(self.bank.frozen_ids) - voting:
                self.bank.thaw(tid)
        if not checks:
            return states
        t_img = self.frames.nearest_time(t_ns)
        if t_img is None:
            return states
        merged = self._merged_ids()
        walking = np.array([st.track_id not in merged for st in states])
        todo = [pair for pair, c in checks.items() if not c.decided and c.image_ns != t_img
                and walking[row[pair[0]]] and walking[row[pair[1]]]
                and any(self.bank.is_trained(tid) for tid in c.voters)]
        if not todo:
            return states
        t0 = time.perf_counter()
        boxes, _, clear = self._clear_boxes(pos)
        todo = [pair for pair in todo if clear[row[pair[0]]] and clear[row[pair[1]]]]
        img = self._image(t_ns) if todo else None
        exchanged: list[tuple[int, int]] = []
        busy: set[int] = set()  # ids exchanged at this step
        if img is not None:
            for pair in todo:
                if busy.intersection(pair):
                    # its evidence was reset by the exchange, and this step's boxes are under the old ids:
                    # it waits for the next image (at most one exchange per id and step)
                    continue
                c = checks[pair]
                voters = [tid for tid in pair if tid in c.voters and self.bank.is_trained(tid)]
                sc = self.bank.box_scores(img.pixels, boxes[[row[pair[0]], row[pair[1]]]], voters,
                                          frozen=True)  # (2, n_v)
                own = np.array([pair.index(tid) for tid in voters])
                ev = sc[own, np.arange(len(voters))] - sc[1 - own, np.arange(len(voters))]
                if not np.isfinite(ev).all():
                    continue
                self._used.update(pair)
                c.evidence += float(ev.mean())
                c.n += 1
                c.image_ns = t_img
                mean = c.evidence / c.n
                if c.n >= p.check_frames and abs(mean) >= p.check_margin:
                    c.decided = True
                    if mean > 0 and p.contact_learn_s is not None:  # kept: what the voters learnt since they were
                        # frozen was of their own people, unless a check of theirs with another track is undecided
                        for tid in c.voters:
                            if self._undecided_elsewhere(tid, pair) is None:
                                self.bank.freeze(tid)
                    self.stats.checks += 1
                    reliable = mean >= 0 or self._reliable(voters)
                    self.stats.withheld += not reliable
                    if mean < 0 and reliable and self._exchange(pair[0], pair[1], _exchange_date(c), t_ns, mean):
                        c.exchanged = True
                        exchanged.append(pair)
                        busy.update(pair)
                    elif mean < 0:  # exchanged perhaps, but not exchanged back: what the voters learnt since the
                        # contact may be of the other person
                        for tid in c.voters:
                            if self.bank.is_frozen(tid):
                                self.bank.restore(tid)
        self.stats.camera_s += time.perf_counter() - t0
        for a, b in exchanged:  # in the order the laser tracker's ids were exchanged
            states = [dataclasses.replace(st, track_id=b if st.track_id == a else a)
                      if st.track_id in (a, b) else st for st in states]
        return states

    @staticmethod
    def _pair_state(states: list[TrackState], row: Mapping[int, int], pair: tuple[int, int]) -> np.ndarray:
        """The (2, 4) floor states ``x, y, vx, vy`` of ``pair``'s tracks at this step."""
        return np.array([[*states[row[tid]].position_m, *states[row[tid]].velocity_mps] for tid in pair])

    def _undecided_elsewhere(self, tid: int, pair: tuple[int, int]) -> tuple[int, int] | None:
        """A pair other than ``pair`` whose check ``tid`` votes in and which is undecided (its vote is then the copy
        frozen when that check opened: it is kept), or None."""
        return next((q for q, o in self._checks.items() if q != pair and tid in o.voters and not o.decided), None)

    def _reliable(self, voters: Iterable[int]) -> bool:
        """Whether the classifiers of ``voters`` may exchange identities: there are at least ``check_voters``, and
        each has been updated at least ``check_min_updates`` times."""
        voters = list(voters)
        k = self.params.check_min_updates
        return (len(voters) >= self.params.check_voters
                and all(self.bank.classifier(tid, frozen=True).n_updates >= k for tid in voters))

    def _exchange(self, a: int, b: int, from_ns: int, t_ns: int, evidence: float) -> bool:
        """The laser tracks ``a`` and ``b`` follow each other's person: exchange their ids from now on and
        record the exchange since ``from_ns`` (:attr:`relabels`). False (nothing done) when the laser tracker
        cannot exchange them."""
        if not self.laser.exchange_ids(self._laser_id.get(a, a), self._laser_id.get(b, b)):
            return False
        for pair, c in self._checks.items():  # evidence gathered under the old ids no longer holds
            if a in pair or b in pair:
                c.evidence, c.n = 0.0, 0
                if pair != (a, b) and pair != (b, a):  # nor the approaches of the other track it now names: an
                    # exchange of this pair later is dated from here on (the next contact's distances)
                    c.swap_from_ns, c.closest_m = t_ns, math.inf
                    c.path.clear()
        for tid in (a, b):  # a claim's summed scores would mix two people
            self._claims.pop(tid, None)
            if self.bank.is_frozen(tid):  # what it learnt since its check opened was (partly) of the other person
                self.bank.restore(tid)
            elif self.params.contact_learn_s is not None and self.bank.is_trained(tid) and tid not in self._alone:
                self.bank.drop(tid)  # first trained during the contact (not a voter): perhaps on either person
        self.relabels.append(Relabel(int(from_ns), int(t_ns), int(a), int(b)))
        self.stats.exchanges += 1
        self.events.append(Event(t_ns, self.camera_name, "identity", t_ns, track_ids=(a, b),
                                 attributes={"exchanged": True, "from_ns": int(from_ns), "evidence": evidence}))
        return True

    # ---------------------------------------------------------------------------------------------
    def _score_map_ll(self, t_ns: int, track_ids: np.ndarray, centres_m: np.ndarray) -> np.ndarray | None:
        """B16 hook: ``β · log p(z | x)`` ``(n, n_p)`` of correlated targets' particles from their score maps.

        ``centres_m`` ``(n, n_p, 2)``: the particles' feet midpoints. Targets without a trained classifier,
        or already scored on this image, get 0.
        """
        t_img = self.frames.nearest_time(t_ns)
        if t_img is None:
            return None
        ids = [self._out(i) for i in track_ids]
        todo = [k for k, tid in enumerate(ids) if self.bank.is_trained(tid) and self._scored.get(tid) != t_img]
        if not todo:
            return None
        t0 = time.perf_counter()
        img = self._image(t_ns)
        if img is None:
            return None
        n, n_p = centres_m.shape[:2]
        mean = centres_m.mean(axis=1)
        boxes = self._boxes(mean)
        ok = np.isfinite(boxes).all(axis=1)
        out = np.zeros((n, n_p))
        groups = _components(mean, self.params.group_m)
        beta = self.params.score_beta
        done = False
        for g in np.unique(groups[todo]):
            members = [k for k in np.flatnonzero(groups == g) if ok[k]]
            scored = [k for k in members if k in todo]
            if not scored:
                continue
            try:
                sm = self.bank.score_map(img.pixels, [ids[k] for k in scored], boxes_px=boxes[members])
            except ValueError:  # the region is off the image
                continue
            self.stats.score_maps += 1
            px = self._box_centres(centres_m[scored].reshape(-1, 2)).reshape(len(scored), n_p, 2)
            finite = np.isfinite(px).all(axis=(1, 2))
            like = sm.likelihood(np.where(np.isfinite(px), px, 0.0))  # (len(scored), n_p)
            ll = np.log(like)
            ll -= ll.max(axis=1, keepdims=True)
            for row, k in enumerate(scored):
                if finite[row]:
                    out[k] = beta * ll[row]
                    self._scored[ids[k]] = t_img
                    self._used.add(ids[k])
                    done = True
        self.stats.camera_s += time.perf_counter() - t0
        return out if done else None

    def _split_scores(self, t_ns: int, member_ids: tuple[int, ...], centres_m: np.ndarray) -> np.ndarray | None:
        """B17 hook: mean confidence ``(n_d, m)`` of each member's classifier over each piece's box, or None
        (motion decides) without an image, an untrained member, an invisible piece, too small a margin or a member
        whose piece scores below ``s_min`` (B17 rejects such a pair; the laser tracker then goes by motion)."""
        member_ids = tuple(self._out(tid) for tid in member_ids)
        if not all(self.bank.is_trained(tid) for tid in member_ids):
            return None
        if self.frames.nearest_time(t_ns) is None:
            return None
        t0 = time.perf_counter()
        img = self._image(t_ns)
        if img is None:
            return None
        boxes = self._boxes(centres_m)
        scores = None
        if np.isfinite(boxes).all():
            s = self.bank.box_scores(img.pixels, boxes, member_ids, exclusive=self.params.split_exclusive)
            if (np.isfinite(s).all() and _assignment_gap(s) >= self.params.split_margin
                    and _assigned_min(s) >= self.bank.params.min_score):
                scores = s
        if scores is not None:
            self._used.update(member_ids)
        self.stats.camera_s += time.perf_counter() - t0
        return scores


# --------------------------------------------------------------------------------------------------
# A whole recording
# --------------------------------------------------------------------------------------------------


def _shown(path: str | Path | Sequence[str | Path]) -> str:
    """A recording's path, or several, as a user wrote them (not a list's repr)."""
    return str(path) if isinstance(path, str | Path) else ", ".join(str(p) for p in path)


def learn_camera_bias(path: str | Path, camera_name: str, *, camera: PinholeCamera | None = None,
                      lasers: Mapping[str, Any] | None = None, learning: BiasLearning | None = None,
                      clock_corrections_ns: Mapping[str, int] | None = None, world_frame: str = "world",
                      image_topic: str | None = None, vision_width_px: int | None = 320,
                      background: str = "prime", max_prime_scans: int | None = None,
                      recording: Recording | None = None) -> CameraBias:
    """Learn a camera's horizontal bias against the lasers over the beginning of a recording (seed 000, A0–A10).

    Like :func:`~fusiontrack.calibration.bias_run.bias_from_recording`, but stops as soon as the bias has
    settled, so that only the first seconds of the camera go through seed 000's vision path. Settled: at least
    ``learning.required_updates`` updates, and over the last ``learning.settle_updates`` of them
    :func:`~fusiontrack.calibration.bias_run.bias_settled` with ``tol_deg``: the bias spans at most
    ``tol_deg``, or it is within ``tol_deg`` of the mean of those updates' targets ``b + ē`` (two standard
    errors of the mean counted against it). The second test stops a bias that has caught up with its
    measurements but is still creeping towards them (A10's fixed rate, a 3-degree error at ``rho = 0.1``: after
    40 updates instead of 50 or more). With the warm start (``BiasParams.warm_start``, the default of
    :class:`BiasLearning`) the bias has no start to work off, and the second test mostly asks that the targets'
    standard error be small enough. The pass's foreground is A1 and A3 without A2's stopped-object mask
    (``ForegroundParams(stopped=None)``): A2 starts no stop in its first ``stopped_warmup`` (100) frames, most of
    a pass, and until then leaves the mask as it is at a third of the foreground's cost; in a longer pass a
    person standing still for several seconds fades into MOG2's background and stops feeding the bias.

    Parameters
    ----------
    path : str or Path
        The recording.
    camera_name : str
        Sensor name of the camera (its image topic, ``sensor_msgs/Image`` or ``CompressedImage``, and its
        ``CameraInfo`` are used).
    camera : PinholeCamera, optional
        The camera as calibrated (default: the recording's, ``<camera>_calibrated`` preferred).
    lasers : mapping of laser name -> (4, 4) laser2world, optional
        Default: every laser of the recording, posed by ``/tf_static``.
    learning : BiasLearning, optional
    clock_corrections_ns : mapping of sensor -> int, optional
        Added to each sensor's stamps (as for :func:`track_fused`).
    world_frame : str
    image_topic : str, optional
        The camera's image topic (default: its first one that is not a label or depth image,
        :func:`~fusiontrack.calibration.bias_run.open_bias_inputs`); :func:`track_fused` passes the one it fuses.
    vision_width_px : int or None
        The vision path (A1–A5) runs on the images shrunk by an integer factor to about this width (320:
        seed 000's 320 x 240, a quarter of the pixels of 640 x 480; :func:`~fusiontrack.calibration.bias_run.
        vision_factor`); None for full resolution.
    background : ``"prime"`` or ``"learn"``
        The lasers' A7 backgrounds: ``"prime"`` (default) learns them first from the recording's first scans,
        read ahead (at most ``max_prime_scans``, default ``4 * bg_n_init`` per laser; a laser with fewer scans
        by then learns online), so the bias can move from the first camera frames on
        (:meth:`~fusiontrack.calibration.bias.HorizontalBiasEstimator.prime`); ``"learn"`` learns them online
        only, as live: no update before each laser has sent ``bg_n_init`` scans (2 s at 25 Hz). The camera side
        (A1's MOG2 foreground) learns online either way. The priming's time is part of ``seconds``.
    max_prime_scans : int, optional

    recording : Recording, optional
        An open :class:`~fusiontrack.io.Recording` of ``path`` (or of several files, ``path`` then the first of them,
        for the messages) to read through (the caller closes it) instead of opening ``path`` again for the setup,
        the priming and the pass (:func:`track_fused` passes its own, of all its files).
    Returns
    -------
    CameraBias
        With no update (nobody seen by both), or an unsettled bias within its wander, the corrected camera is
        ``camera``.

    Raises
    ------
    RecordingError
        The recording lacks the camera's images or CameraInfo, the lasers or their poses.
    ConfigError
        ``background`` is neither ``"prime"`` nor ``"learn"``.
    """
    from ..calibration.bias_run import bias_settled, open_bias_inputs
    from ..types import LaserScan
    from ..vision.foreground import ForegroundParams

    laser_background = check_background(background)
    lp = learning or BiasLearning()
    offsets_ms = {k: -v / 1e6 for k, v in (clock_corrections_ns or {}).items()}
    inputs = open_bias_inputs(path, camera_name, None if lasers is None else list(lasers),
                              clock_offsets_ms=offsets_ms, world_frame=world_frame,
                              cam2world=None if camera is None else camera.cam2world, laser2world=lasers,
                              image_topic=image_topic, vision_width_px=vision_width_px,
                              foreground=ForegroundParams(stopped=None), recording=recording)
    if camera is not None:
        inputs = dataclasses.replace(inputs, camera=camera)
    tic = time.perf_counter()
    est = inputs.estimator(lp.params, background=laser_background, max_prime_scans=max_prime_scans)
    tol = np.radians(lp.tol_deg)
    learnt: list[float] = []
    targets: list[float] = []  # b + ē of every update: where it pulled the bias to
    first_ns: int | None = None
    settled = False
    for item in inputs:
        if isinstance(item, LaserScan):
            est.observe_scan(item)
            continue
        before = est.bias_rad
        step = item.update(est)
        first_ns = step.t_ns if first_ns is None else first_ns
        if step.n_used:
            learnt.append(step.bias_rad)
            targets.append(before + step.mean_residual_rad)
            if len(learnt) >= lp.required_updates and bias_settled(learnt, targets, lp.settle_updates, tol):
                settled = True
                break
        if step.t_ns - first_ns >= lp.max_s * 1e9:
            break
    spread = float(np.ptp(learnt[-lp.settle_updates:])) if len(learnt) >= lp.settle_updates else math.nan
    applied = settled or (np.isfinite(spread) and abs(est.bias_rad) > 2.0 * spread)
    return CameraBias(est.history, est.camera, est.corrected_camera if applied else est.camera, settled, spread,
                      bool(applied), time.perf_counter() - tic, np.array(targets, np.float64))


def track_fused(path: str | Path | Sequence[str | Path], *, params: FusionParams | None = None,
                tracker_params: TrackerParams | Mapping[str, Any] | None = None,
                camera_topic: str | None = None, camera: PinholeCamera | None = None,
                adaptive_bias: bool | BiasLearning | BiasParams = True,
                progress: Callable[[float], None] | None = None, topics: Iterable[str] | None = None,
                time_source: str = "header", area_m: Any = "auto",
                clock_corrections_ns: Mapping[str, int] | None = None,
                detector_params: Mapping[str, Any] | None = None, rng: np.random.Generator | int | None = 0,
                world_frame: str = "world", timings: dict[str, list[float]] | None = None,
                classify: bool = True, frames_wrapper: Callable[[Any], FrameSource] | None = None,
                background: str = "prime", laser_poses: Mapping[str, Any] | None = None,
                sync_window_ns: int = 200_000_000, camera_poses: Mapping[str, Any] | None = None,
                ) -> tuple[list[TrackState], list[Event], FusionStats]:
    """Track the people of a recording with its laser scans and one camera (seed 001's fused pipeline).

    Like :func:`~fusiontrack.tracking.tracker.track_recording` (same detector, synchronisation, area and
    classification), with a :class:`FusionTracker` stepped once per scan time. First, unless
    ``adaptive_bias`` is False, the camera's horizontal bias is learnt against the lasers over the beginning of
    the recording (seed 000, :func:`learn_camera_bias`), and the tracker fuses through the corrected camera.

    Parameters
    ----------
    path : recording path(s)
        With several files (e.g. the lasers in one, the camera in another), read as one recording, the bias pass
        too.
    params : FusionParams, optional
    tracker_params : TrackerParams or mapping, optional
    camera_topic : str, optional
        The image topic (default: the recording's only one; labels and depth images are not candidates).
    camera : PinholeCamera, optional
        Default: from the recording's CameraInfo and ``/tf_static`` (``<frame>_calibrated`` preferred,
        :func:`~fusiontrack.vision.people.camera_from_recording`). The bias corrects this camera.
    adaptive_bias : bool, BiasLearning or BiasParams
        Learn the camera's bias first (True: :class:`BiasLearning` defaults); False for a camera calibrated
        well. The result is :attr:`FusionStats.bias` and a ``camera_bias`` event.
    progress, topics, time_source, area_m, clock_corrections_ns, detector_params, rng, world_frame, classify
        As for ``track_recording``; ``clock_corrections_ns`` may also name the camera.
    laser_poses, sync_window_ns
        As for ``track_recording``.
    camera_poses : mapping, optional
        Image topic or camera sensor name -> ``cam2world`` ``(4, 4)`` of the camera's optical frame (a pipeline
        file's poses, e.g. as ``fusiontrack calibrate`` wrote them: :meth:`~fusiontrack.config.PipelineConfig.
        camera_poses`): the camera's pose, instead of the recording's ``/tf_static`` (``camera`` given: unused).
    background : ``"prime"`` or ``"learn"``
        As for ``track_recording``: the laser backgrounds learnt first from the recording's first scans (default),
        or online only; the bias pass's own laser backgrounds likewise (:func:`learn_camera_bias`).
    timings : dict, optional
        Filled with per-step ``"detect_s"`` and ``"track_s"`` (laser tracker + camera side + classification; wall
        time) and ``"t_ns"`` (the step's time), and ``"bias_s"`` (one value: the bias learning).
    frames_wrapper : callable, optional
        Wraps the camera's :class:`~fusiontrack.fusion.frames.LazyFrames` (e.g. to simulate a blackout).

    Returns
    -------
    states : list of TrackState
        With the identity decisions applied (:func:`relabel_states`).
    events : list of Event
        The laser tracker's, plus one ``identity`` event per decision: an exchange (``track_ids`` = the pair,
        ``attributes``: ``exchanged``, ``from_ns``, ``evidence``) or a re-identification (``track_ids`` = (new
        id, the lost id it takes), ``attributes``: ``reidentified``, ``from_ns``, ``evidence``); earlier
        merge/split events keep the ids of their time. With a learnt bias,
        first one ``camera_bias`` event over the frames it was learnt on (``attributes``: ``bias_deg``,
        ``updates``, ``settled``, ``applied``).
    stats : FusionStats
        ``stats.camera`` is "" when the recording has no usable camera: the lasers tracked alone (a warning
        says why). ``stats.bias``: the learnt bias and its history.

    Raises
    ------
    RecordingError
        No laser topic.
    """
    from ..io.recording import LASERSCAN, Recording
    from ..io.sync import synchronize
    from ..laser.detector import detector_for_recording
    from ..vision.people import camera_from_recording
    from .frames import LazyFrames

    if isinstance(adaptive_bias, BiasParams):
        learning: BiasLearning | None = BiasLearning(params=adaptive_bias)
    elif isinstance(adaptive_bias, BiasLearning):
        learning = adaptive_bias
    elif isinstance(adaptive_bias, bool):
        learning = BiasLearning() if adaptive_bias else None
    else:
        raise ConfigError(f"adaptive_bias: expected a bool, BiasLearning or BiasParams, got {adaptive_bias!r}")
    corrections = dict(clock_corrections_ns or {})
    first_path = path if isinstance(path, str | Path) else next(iter(path), None)
    with Recording(path) as rec, contextlib.ExitStack() as stack, opencv_threads(1):
        info = rec.topic_types()
        lasers = [t for t, i in info.items() if i == LASERSCAN] if topics is None else list(topics)
        if not lasers:
            raise RecordingError(f"{', '.join(str(q) for q in rec.paths)}: no sensor_msgs/LaserScan topic to track "
                                 "(the people pipeline fuses lasers with a camera; --pipeline people-camera tracks "
                                 "with the camera alone)")
        image_topic = rec.image_topic(topic=camera_topic, required=False)
        cam_sensor = "" if image_topic is None else rec.sensor_of(image_topic)
        if image_topic is None:
            log.warning("%s: no camera image topic: the people pipeline tracks with the lasers only", _shown(path))
        elif camera is None:
            given = dict(camera_poses or {})
            cam2world = given.get(image_topic, given.get(cam_sensor))
            if given and cam2world is None:
                log.warning("%s: the camera poses given (%s) are not of camera %r (%s): its pose is read from "
                            "/tf_static", _shown(path), ", ".join(sorted(given)), cam_sensor, image_topic)
            first = next((m for m in rec.messages([image_topic]) if isinstance(m, Image)), None)
            if first is not None:
                camera = camera_from_recording(rec, cam_sensor, first.frame_id, world_frame=world_frame,
                                               cam2world=cam2world)
            if camera is None:
                log.warning("%s: %s for camera %r: the people pipeline tracks with the lasers only", path,
                            "no readable image" if first is None else "no CameraInfo or no /tf_static pose",
                            cam_sensor)
        if image_topic is None or camera is None:
            camera, cam_sensor = None, ""
        calibrated = camera
        p = params or FusionParams()
        total = sum(c.msgcount for c in rec.connections if c.topic in lasers)  # from the index or metadata
        check_background(background)
        detector, poses = detector_for_recording(rec, lasers, time_source=time_source, world_frame=world_frame,
                                                 background="learn", detector_params=detector_params,
                                                 laser_poses=laser_poses)
        laser_corrections = {k: v for k, v in corrections.items() if k != cam_sensor}
        if background == "prime":
            detector.prime(synchronize(rec.messages(lasers, time_source=time_source), sync_window_ns,
                                       clock_corrections_ns=laser_corrections))
        bias = None
        if camera is not None and learning is not None and first_path is not None:
            # the bias pass reads through rec (all the files, opened once), before the tracking pass
            bias = _learn_bias(path, cam_sensor, image_topic, camera, poses, learning, corrections, world_frame,
                               background, rec)
            if bias is not None:
                camera = bias.corrected_camera
                if timings is not None:
                    timings.setdefault("bias_s", []).append(bias.seconds)
        frames: Any = None
        lazy: LazyFrames | None = None
        images = None
        if camera is not None and len(rec.paths) == 1:  # one pass over the file for the scans and the images (its
            # chunks hold both: read for each, every chunk was read twice). Not over several files: their log
            # clocks may differ by seconds, and the pass keeps the images nobody took by log time
            scans, images = rec.messages_and_raw(lasers, [image_topic], time_source=time_source)
        else:
            scans = rec.messages(lasers, time_source=time_source)
        if camera is not None:  # (over several files, the images are read by a Recording of their own: two
            # streams at once through one reader are not safe in every storage)
            frames = lazy = LazyFrames(rec if images is not None else stack.enter_context(Recording(path)),
                                       image_topic, round(p.max_frame_dt_s * 1e9), corrections.get(cam_sensor, 0),
                                       raw=images)
            if frames_wrapper is not None:
                frames = frames_wrapper(frames)
        auto_area = isinstance(area_m, str)
        if auto_area and area_m != "auto":
            raise ConfigError(f"area_m: expected 'auto', None, a rectangle or a polygon, got {area_m!r}")
        trk = FusionTracker(camera, frames, p, tracker_params, area_m=None if auto_area else area_m, rng=rng,
                            camera_name=cam_sensor or "camera")
        trk.stats.camera, trk.stats.bias, trk.stats.camera_model = cam_sensor, bias, calibrated
        stream = synchronize(scans, sync_window_ns, clock_corrections_ns=laser_corrections)
        states, events = run_tracker(trk, detector, poses, stream, total=total, auto_area=auto_area,
                                     classify=classify, progress=progress, timings=timings)
        if lazy is not None:
            lazy.warn_unreadable()
    if bias is not None and len(bias.history):
        h = bias.history
        events.insert(0, Event(int(h.t_ns[0]), cam_sensor, "camera_bias", int(h.t_ns[-1]), attributes={
            "bias_deg": float(np.degrees(bias.bias_rad)), "updates": bias.updates, "settled": bias.settled,
            "applied": bias.applied}))
    return relabel_states(states, trk.relabels), events, trk.stats


def _learn_bias(path: str | Path | Sequence[str | Path], cam_sensor: str, image_topic: str | None,
                camera: PinholeCamera, poses: Mapping[str, np.ndarray], learning: BiasLearning,
                corrections: Mapping[str, int], world_frame: str, background: str = "prime",
                recording: Recording | None = None) -> CameraBias | None:
    """:func:`learn_camera_bias` for :func:`track_fused` (``path``: its recording's file or files, read through
    ``recording``): None (with a warning) when it cannot be learnt."""
    first = path if isinstance(path, str | Path) else next(iter(path))
    try:
        bias = learn_camera_bias(first, cam_sensor, camera=camera, lasers=poses, learning=learning,
                                 clock_corrections_ns=corrections, world_frame=world_frame,
                                 image_topic=image_topic, background=background, recording=recording)
    except (RecordingError, ValueError) as err:  # no usable calibration or images: fuse as calibrated
        log.warning("camera bias not learnt (%s): the camera is used as calibrated", err)
        return None
    seconds = (bias.history.t_ns[-1] - bias.history.t_ns[0]) / 1e9 if len(bias.history) else 0.0
    if bias.updates == 0:
        log.warning("%s: camera bias not learnt: nobody was seen by both %s and the lasers in %.1f s; the camera "
                    "is used as calibrated", _shown(path), cam_sensor, seconds)
    elif not bias.settled:
        spread = np.degrees(bias.spread_rad)
        wander = f"wandering by {spread:.2f}" if np.isfinite(spread) else "too few updates"
        log.warning("%s: the bias of %s had not settled after %d updates (%.1f s): %.3f deg, %s; %s", _shown(path),
                    cam_sensor, bias.updates, seconds, np.degrees(bias.bias_rad), wander,
                    "applied" if bias.applied else "the camera is used as calibrated")
    else:
        log.info("%s: bias of %s settled at %.3f deg after %d updates (%.1f s)", _shown(path), cam_sensor,
                 np.degrees(bias.bias_rad), bias.updates, seconds)
    return bias
