"""Multi-view silhouette tracking, thesis section 6.2.5: per frame, the pose whose rendered
silhouettes best overlap the image silhouettes (the XOR energy of `tracking.track.energy`).

Per frame, starting from a constant-velocity prediction of the previous two frames:

0. all 26 parameters (`TrackConfig.hold` aside) together against the silhouette outlines
   (`tracking.track.contour`, damped
   Gauss-Newton, a step kept only when the XOR energy drops);
1. root: the 6 global parameters by downhill simplex (Nelder-Mead), coarse pyramid level first;
2. "head and hip": the spine's flexion, side bend and twist and the neck's nod, by simplex;
3. each limb's 4 parameters (ball joint + hinge): a regular grid over the two swing angles and
   the hinge, around the prediction, over a range adapted to the parameter changes of the two
   preceding frames; only valid samples are scored (thesis: the elbow and wrist, or knee and
   ankle, project inside the silhouette in every view and lie at least a minimum distance from
   the torso axis); the best sample is refined by simplex;
4. a final simplex over the root at the finest level. (The thesis' last step, hands and feet,
   has no parameters in our model: wrists and ankles are rigid end sites.)
5. step 0 again; the better of steps 0 and 5 by XOR is the frame's pose.

Steps 1-4 alone drift along directions the silhouettes hardly tell apart (pelvis pitch against
hip flexion and spine bend), and their coarse levels can leave a fine optimum: steps 0 and 5
remove both. A stage only moves part of the body, so the silhouette of the rest is rendered
once per stage and each energy evaluation renders only the moving triangles (`_StageEnergy`).

Initialisation (frame 0, and after a lost frame): automatic from the silhouettes. The visual
hull is carved on a voxel grid around the point where the views' silhouette centroids meet and
its surface fitted by `tracking.fit.body_fit.fit_body` (scale and pose); the height is capped near
the hull's extent along up, since a hull of few views is fatter than the body and the fit grows
to fill it, and when the subject is upright the start below is searched at the hull's own
height too (`start_heights`; the lower XOR keeps its height). A hull cannot tell left from
right limbs: the fit and its left/right swaps of legs and arms (`swap_sides`) are each refined
against the outlines. The best of them competes with
upright stances at `init_headings` headings (`upright_starts`), since the fit can fold a limb
into the trunk or lean the trunk to explain a limb (where the fit is bent over, crouched ones
at those headings too: `crouched_starts`), and with poses whose head, hands and feet
are on the hull's extremities (`tracking.track.extremities`: the best `init_extremity_starts`
by XOR), since neither reaches a body upside down or sideways: each is refined by the whole
hierarchy with the limbs' grids over their whole range, and the lowest XOR wins (where the
start also sets the shape, an extremity start only by a clear lead, `_EXTREMITY_LEAD`: near
ties went the wrong way), and then the winner's own left/right swaps, refined alike, compete
with it (`_winner_swapped`). When the shape is unknown, the shape parameters (the segment
lengths, or the skinned body's macro shape and clothing: `TrackedModel.shape_parameters`)
then come from the outlines, for the winner and each of its swaps, and the lowest XOR after
that wins (`_shaped_winner`; an extremity start lower than the winner without its lead gets
its proportions too, and wins with the lead after them); `calibrate_shape` refines them over
several frames of a first pass. The rotation angles of the root lock at a 90
degree pitch, so an upright body should be tracked in a Y-up frame
(`tracking.rig.cameras.upright_frame`; `mocap track` does). The spine's side bend and twist
stay 0 through this start and the shape pass (`_START_HELD`) and are tracked from then on. A
pose given by the user replaces this ("model alignment", thesis 6.2.4).

A frame whose energy stays above `max_xor_fraction` of the silhouette area (or 1.5 times the
lowest XOR of an initialisation, when real silhouettes with holes and ghosts set a higher
floor) is a divergence; a start over `max_xor_fraction` is one too ("diverged", its XOR no
reference; the search runs again every `_SEARCH_AGAIN_FRAMES` frames while over it). So is one
far above what the model reached on this subject
(`tracking.track.divergence.XorWatch`: `spike_xor_factor` times the median XOR of the recent
tracked frames, or `high_xor_factor` times it for `high_xor_frames` frames in a row), which the
absolute bar lets through when the model fits the subject well. On a divergence the start
search runs again (`_recover`), from the last good pose (with its left/right swaps, the limbs'
grids over their whole range), in the shape pass's frames from the pose the pass gave the frame
(alike), and from the visual hull (`initialise`), each only while the ones before found no pose
that is no divergence, and the candidate of lowest XOR, the tracked pose included, is kept: the
frame is "recovered" when the search found a pose that is no divergence, "diverged" (its best
pose kept, not trusted; its XOR the reference from then on) when only the relative tests still
fail, and "lost" (no joints; never NaN) when the absolute one does. After a "diverged" frame,
the frames still over the high bar of the reference before it are "diverged" too (the track is
not back), and the first tracked frame back under it, its visual hull explained
(`max_unexplained_share`), is "recovered": the track is found again, by the tracking itself.
`FrameResult.status` says which (`STATUSES`). A frame where no camera has a silhouette is
"absent" (the subject left the view): no pose and no search; the next frame with silhouettes
starts afresh from the visual hull and is "recovered" (or "lost" when that start's XOR is over
the absolute bar an earlier start set). A frame whose visual hull has two separate
parts of human size or more (`subjects_in_view`: two subjects apart, both in every camera's
view) is "two-subjects": no pose, rather than a fit to the merged blob. It is looked for where
a second subject shows: at a start from the hull, and on a divergence before the start search
(the other subject's silhouettes are unexplained, so the XOR jumps).

A track runs forwards, so a start gone wrong or a divergence is found only by the frames after
it. Both are tracked again backwards from there (`track_back`: the opening of a track, from its
frame of lowest XOR; `track_back_gap`: the frames before a recovery, from the recovered pose),
and the backward track replaces the forward one where its XOR is clearly lower. The first frame
it replaces in a divergence or loss is then "recovered".

The search ranges scale with the frame interval (`frame_interval_s`, seconds), not with the
frame index: a limb grid's half-range is `range_gain` times the change over the two preceding
frames (which scales with the interval by itself), clipped to angular speeds
(`min_range_deg_s`, `max_range_deg_s`) times the interval; so are the root simplex's first
steps and the temporal prior's scales. At 30 fps they are the former per-frame constants.

A cast shadow that background subtraction keeps lies on the floor and every view sees it, so
the visual hull holds it as a slab at its bottom. Counted, its pixels pull the feet down to
it, and in the shape pass stretch the legs: the suite's bend_pickup, whose feet float up to
8 cm above its shadow (`mocap synth` retargets CMU clips without foot contact), was given
1.66 m for the 1.55-1.57 m of the same subject in the other clips, and tracked 49.7 mm off.
The pixels that only the hull's lowest `floor_band_m` covers, no voxel above it (the shadow's,
and the bottom few centimetres of a foot on the floor: `_frame_hull`,
`tracking.silhouettes.hull.lowest_band_pixels`), count as missed whatever the pose
(`SilhouetteEnergy`'s ``missed``): the fit does not chase them, and the XOR keeps the scale
the divergence watch's factors were set on. (Out of the XOR altogether, the suite's median
XOR fell from ~10% to ~5.6%, and the cartwheel's frame 18, 24 mm off, crossed 1.6 times it,
a divergence with no recovery in 11 frames.) The start's fit, its height and the starts'
floor leave out the voxels under a gap at the hull's bottom (`floor_only`): a shadow's slab
under feet off the floor.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager, suppress
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from recon.cameras import Camera
from recon.parallel import Beside, fork_map, workers_for
from tracking.body.bvh import rotations_to_channels
from tracking.body.model import (
    ADDED_PARAMS,
    LOWER_LIMITS,
    N_POSE_PARAMS,
    NODE_INDEX,
    NODE_NAMES,
    PARAM_INDEX,
    PARAM_MOVES_NODE,
    SEARCH_LOWER_LIMITS,
    SEARCH_UPPER_LIMITS,
    UPPER_LIMITS,
    WHOLE_TURN,
    BodyModel,
    BodyShape,
    Pose,
    TrackedModel,
    forward_kinematics,
    in_limits,
    root_rotation,
    turn_difference,
)
from tracking.body.motion import zxy_twin
from tracking.rig.cameras import rig_up
from tracking.silhouettes.hull import (
    HullPart,
    check_voxel_grid,
    cut_by_border,
    floor_only,
    hull_diameter,
    hull_min_views,
    hull_parts,
    hull_surface_points,
    lowest_band_pixels,
    rays_meeting_point,
    subject_sized,
)
from tracking.track.contour import ContourConfig, ContourRefiner, refine_shape
from tracking.track.divergence import WatchConfig, XorWatch
from tracking.track.energy import SilhouetteEnergy, XorCount, counted
from tracking.track.extremities import (
    extremity_assignments,
    hull_extremities,
    pose_from_extremities,
)
from tracking.track.render import render_views

_ROOT = [PARAM_INDEX[n] for n in ("root_tx", "root_ty", "root_tz", "root_rz", "root_rx",
                                  "root_ry")]  # fmt: skip
# The trunk's parameters and the simplex's first steps for them, radians.
_TRUNK = [PARAM_INDEX[n] for n in ("spine_flex", "neck_flex", "spine_bend", "spine_twist")]
_TRUNK_STEPS = np.deg2rad([8.0, 8.0, 5.0, 8.0])
_START_HELD = ADDED_PARAMS
"""Held at 0 while the start is searched (the visual-hull fit, the competing starts, the shape
pass) and freed for tracking: free there, they cost the Pose2Sim demo 0.734 -> 0.686 median
IoU (another start won, a worse basin for the whole clip), session 17."""

_EXTREMITY_ASSIGNMENTS = 12
"""Assignments of head, hands and feet to the hull's extremities solved and scored at a start
(`SilhouetteTracker._extremity_starts`), 0.2 s each. On the motion suite's cartwheel at frame 23
(upside down) the right one was 4th by its geodesic lengths (tied with its three left/right
swaps), and its pose 3rd of the 12 by XOR: `init_extremity_starts` 3 refines it."""

_EXTREMITY_LEAD = 0.8
"""An extremity start wins a start that also sets the shape (the first frame's, the shape unknown)
only with an XOR under this fraction of the best of the fit and the upright starts'. A start
with the shape known (a recovery, in the shape pass or after it) takes the lowest XOR: the lead
there cost the suite's cartwheel 40.3 -> 62.7 mm (a recovery in the shape pass), and the tie it
guards against is the shape's (below). Measured at frame 0 (session 26): the extremity starts'
best against the others' was 0.97 on the Pose2Sim demo, where it won without the lead, ended
1.94 m tall against 1.85, and cost the clip's median IoU 0.827 -> 0.794; 0.99 and 0.94 on the
suite's jump and climb_steps (34.4 -> 33.2 and 8.1 -> 8.8 mm: a wash); under 0.8 nowhere else
at frame 0. Where the others fail it leads by far: 0.52 and 0.49 on the suite's cartwheel
upside down (frames 23 and 27, XOR 0.487 -> 0.255 and 0.564 -> 0.279). An extremity start
lower than the others' best without the lead contends with it: both are given their
proportions, and the lead is asked of them after that (`_shaped_winner`; session 47)."""

_SECOND_HEIGHT_STARTS = 4
"""A start searched at two heights (`start_heights`) refines at the second only the starts that
scored lowest at the first, this many of the 12: about 4 s of the second height's 6 (session
38). Each start's refinement is its own, so where the second height's winner is among them the
start is the full search's, bit for bit. Measured with every start refined at both heights
(session 38): of the suite's 45 first frames (15 clips, seeds 0-2), 23 were searched at two
heights, and the second height's winner was the first height's best start in 12, its 2nd in 8,
3rd in 1, 4th in 2 (the run at seed 0, which the second height won, 3656 against 4507 XOR px,
and at seed 1); then on data it was not chosen on, the 15 clips' frame 150 (seed 0), 9 at two
heights: 1st in 6, 2nd, 3rd and 4th in 1 each (squat, won by the first height)."""

_AGAIN_STARTS = 2
"""A recovery's refined starts given `TrackConfig.recovery_passes` (`_pass_again`): the lowest
two, one per core of the machines this runs on, so that side by side they take the time of one
(about 0.8 s a pass). Not tuned: chosen for that, then measured on the suite's 30- and 60-frame
sets (session 32)."""

MEND_BACKOFF_FRAMES = 5
"""Frames after a mend that found nothing without another (`SilhouetteTracker._mend_unexplained`):
the CMU kick's 6 and boxing's 8 flagged frames each searched two limbs in vain, at about 2 s
a frame."""

MEND_STARTS = 3
"""`TrackConfig.init_starts` and `init_twists` of the limb searches that mend a frame whose hull
has a part the body leaves out (`SilhouetteTracker._mend_unexplained`): the CMU squat's left
forearm, held out and turned 62 degrees, is found from the folded start with both at 3, not
with either alone (session 21)."""

# Limb: (ball-joint parameters rz, rx, ry, hinge), its two end nodes and the torso clearance
# as a fraction of the shape's chest half width (arms) or hip half width (legs).
_LIMBS: dict[str, tuple[list[int], tuple[str, str], str]] = {
    f"{side}_{limb}": (
        [PARAM_INDEX[f"{side}_{ball}_{a}"] for a in ("rz", "rx", "ry")]
        + [PARAM_INDEX[f"{side}_{hinge}_flex"]],
        (f"{side}_{hinge}", f"{side}_{end}"),
        limb,
    )
    for side in ("l", "r")
    for limb, ball, hinge, end in (("arm", "shoulder", "elbow", "wrist"),
                                   ("leg", "hip", "knee", "ankle"))
}  # fmt: skip
_MOVES = PARAM_MOVES_NODE
_TWISTS = [PARAM_INDEX[f"{side}_{joint}_ry"] for side in ("l", "r")
           for joint in ("shoulder", "hip")] + [PARAM_INDEX["spine_twist"]]  # fmt: skip


DEFAULT_FRAME_INTERVAL_S = 1.0 / 30.0
"""The frame interval of a tracker not told its frame rate, and the one the per-frame
constants that now scale with it were tuned at: `benchmarks/tracking_synthetic.py` tracks
`mocap synth`'s default 30 fps, where the grids' 240 and 1200 deg/s make the former 8 and 40
degrees, and the root simplex's steps the former 1-8 cm and 0.02-0.15 rad."""
_ROOT_STEP_PER_S = (np.array([0.3] * 3 + [0.6] * 3), np.array([2.4] * 3 + [4.5] * 3))
"""Smallest and largest first step of the root simplex while tracking, per second of frame
interval: metres for the translation, radians for the rotation."""
_WIDE_RANGE_DEG = 40.0
"""Half-range (simplex steps) of a limb's grid with no time in the loop (starts, `refine`)."""
# The relative divergence tests (`tracking.track.divergence`), measured with
# benchmarks/tracking_recovery.py on `mocap synth`'s default subject (MakeHuman's body with
# another shape and loose clothing: not the tracker's model), 4 views 640x480, session 20.
SPIKE_XOR_FACTOR = 1.6
"""A frame over 1.6 times the recent median XOR is a divergence. Tracking stays within 1.4
times it: 9-12% XOR (median 10%) on the CMU walk (cmu_02_01_walk, 30 fps, 24 and 86 frames;
60 fps, 48 frames from the true start: 8-11%) and 9-14% on the CMU wave (cmu_wave, 30 fps, 24
and 74 frames). A track jumped by silhouettes of another frame (frames 12-15 shown
as frame 4) reaches 1.9-3.0 times it: the walk's frame 12 30.5% over 10.2% (the former code
tracked 12-15 at 19-28% without a word), the wave's frame 16 20.2% over 10.5%."""
HIGH_XOR_FACTOR = 1.3
"""... and so is one over 1.3 times it for `HIGH_XOR_FRAMES` frames in a row: the wave's
corrupted frames 12-14 stayed at 1.46-1.55 times its median (16%, 15%, 15.1% over 10.3%),
under the spike factor. The walk's frames never exceeded 1.23 times it (86 frames); the
wave's did once in 74, at frames 31-33 (13-14% over 10%, MPJPE 7 to 21 mm: a drift of the
waving arm that the former code shows too, 21-28 mm at frames 31-35), flagged at 33 and taken
back to 8 mm by the search."""
HIGH_XOR_FRAMES = 3
"""Frames in a row over `HIGH_XOR_FACTOR`: the wave's slide above was flagged at its third
frame (issue 20 asks for recovery within 5 frames; the search itself takes one)."""
XOR_WINDOW = 15
"""Tracked frames in the median: half a second at 30 fps; the median ignores up to 7 odd ones.
Replayed on the runs' XOR sequences (`XorWatch` alone), windows of 3, 8, 15 and 30 frames
flag nothing in the normal runs above (largest ratio to the median 1.29 with 3 frames, 1.21
with 15) and every frame of the former code's jumped stretch. A 60 fps walk whose automatic
start was wrong (22% XOR from frame 0, 200-300 mm MPJPE; a start this issue leaves to another
part) slid to 32% by frame 40: flagged at frame 41 with 30 frames, not with 15."""
XOR_MARGIN = 0.03
"""The relative bars are at least 3 points of XOR above the median: the spread of normal frames
around it on the walk and the wave (9-12% around 10%). Renders of the tracker's own model
reach 1-3% XOR, where 1.6 times the median is under a point of noise."""


@dataclass(frozen=True, kw_only=True)
class TrackConfig:
    levels: int = field(default=3, metadata={"help": "image pyramid levels (1 = full size)"})
    search_level: int = field(
        default=1, metadata={"help": "pyramid level of the grid searches (0 = full size)"}
    )
    prior_weight: float = field(
        default=0.0,
        metadata={"help": "temporal prior: cost of one prior scale of deviation from the "
                  "predicted pose, as a fraction of the silhouette area (0 = pure XOR)"},
    )  # fmt: skip
    prior_scale_deg_s: float = field(
        default=300.0,
        metadata={"help": "prior scale of angles, degrees per second (times the frame "
                  "interval: 10 degrees at 30 fps)"},
    )  # fmt: skip
    prior_scale_m_s: float = field(
        default=1.5,
        metadata={"help": "prior scale of positions, metres per second (times the frame "
                  "interval: 5 cm at 30 fps)"},
    )  # fmt: skip
    twist_weight: float = field(
        default=0.01,
        metadata={"help": "cost of one twist scale of limb twist (shoulders, hips), as a "
                  "fraction of the silhouette area (0 = none)"},
    )  # fmt: skip
    twist_scale_deg: float = field(default=30.0, metadata={"help": "twist prior scale"})
    passes: int = field(
        default=1, metadata={"help": "passes of the whole hierarchy per frame"}
    )
    final_level: int = field(
        default=0, metadata={"help": "pyramid level of the last root refinement of a frame"}
    )
    grid: int = field(
        default=3, metadata={"help": "grid samples per limb parameter (swing, lift, hinge)"}
    )
    init_grid: int = field(
        default=6,
        metadata={"help": "grid samples per limb angle over its whole range at initialisation"},
    )
    init_twists: int = field(
        default=1,
        metadata={"help": "axial twists of the upper limb sampled with that grid, inside its "
                  "range (1: only the start's twist; 3: -45, 0 and +45 for +-90, which with "
                  "--init-starts 3 finds a bent arm turned on its axis but cost the Pose2Sim "
                  "demo 0.811 -> 0.776 median IoU)"},
    )  # fmt: skip
    init_starts: int = field(
        default=1,
        metadata={"help": "best samples of that grid each refined by a simplex, the lowest "
                  "kept (1: the grid's best alone; more can let a limb take pixels another "
                  "limb searched later should explain)"},
    )  # fmt: skip
    min_range_deg_s: float = field(
        default=240.0,
        metadata={"help": "smallest half-range of a limb grid as an angular speed, degrees per "
                  "second (times the frame interval: 8 degrees at 30 fps, 4 at 60)"},
    )  # fmt: skip
    max_range_deg_s: float = field(
        default=1200.0,
        metadata={"help": "largest half-range of a limb grid as an angular speed, degrees per "
                  "second (times the frame interval: 40 degrees at 30 fps, 20 at 60)"},
    )  # fmt: skip
    range_gain: float = field(
        default=2.0,
        metadata={"help": "grid half-range = gain x the parameter's change over the two "
                  "preceding frames (thesis 6.2.5), clipped to the min/max range"},
    )  # fmt: skip
    simplex_evals: int = field(
        default=15, metadata={"help": "evaluations of each downhill-simplex refinement"}
    )
    max_xor_fraction: float = field(
        default=0.35,
        metadata={"help": "a frame whose XOR area exceeds this fraction of the silhouette "
                  "area is a divergence, the start's too: re-initialise"},
    )  # fmt: skip
    spike_xor_factor: float = field(
        default=SPIKE_XOR_FACTOR,
        metadata={"help": "a frame whose XOR fraction exceeds this factor times the median of "
                  "the recent tracked frames (--xor-window) is a divergence even under "
                  "--max-xor-fraction: the start search runs again (0 = off)"},
    )  # fmt: skip
    high_xor_factor: float = field(
        default=HIGH_XOR_FACTOR,
        metadata={"help": "... and so is one above this factor times that median for "
                  "--high-xor-frames frames in a row"},
    )  # fmt: skip
    high_xor_frames: int = field(
        default=HIGH_XOR_FRAMES,
        metadata={"help": "frames in a row above --high-xor-factor that make a divergence "
                  "(0 = off)"},
    )  # fmt: skip
    xor_window: int = field(
        default=XOR_WINDOW, metadata={"help": "recent tracked frames whose median XOR "
                                      "fraction is the reference of the relative tests"}
    )  # fmt: skip
    xor_margin: float = field(
        default=XOR_MARGIN,
        metadata={"help": "the relative bars are at least this fraction of the silhouette area "
                  "above that median"},
    )  # fmt: skip
    max_unexplained_share: float = field(
        default=0.005,
        metadata={"help": "a tracked frame whose visual hull has a part the body leaves out "
                  "(--unexplained-m or more from it, on silhouette pixels the body does not "
                  "cover in 2 views or more) of over this share of the hull's surface voxels: "
                  "a limb likely misplaced; searched again (--mend-unexplained), then, if "
                  "still over, flagged in pose.json, its pose kept (0 = off)"},
    )  # fmt: skip
    unexplained_m: float = field(
        default=0.09,
        metadata={"help": "distance from the body beyond which a part of the visual hull is "
                  "unexplained, metres"},
    )  # fmt: skip
    mend_unexplained: bool = field(
        default=True,
        metadata={"help": "when a frame's visual hull has a part the body leaves out (see "
                  "--max-unexplained-share), search the two limbs nearest it over their whole "
                  "range, as at a start, and keep what lowers the XOR"},
    )  # fmt: skip
    init_shape: bool = field(
        default=True,
        metadata={"help": "estimate the segment lengths at initialisation when the shape is "
                  "unknown (off: the standard proportions of the visual hull's height)"},
    )  # fmt: skip
    shape_frames: int = field(
        default=24,
        metadata={"help": "frames of the shape pass before tracking when the shape is "
                  "unknown: they are tracked, then the segment lengths are refined over every "
                  "--shape-stride-th of them at once (<= 1: the first frame's shape only); a "
                  "start over --max-xor-fraction moves the pass to the first of every 3rd "
                  "frame whose start is under it"},
    )  # fmt: skip
    shape_stride: int = field(
        default=4, metadata={"help": "frame stride of the shape pass's joint refinement"}
    )
    back_xor_factor: float = field(
        default=1.2,
        metadata={"help": "the opening of a track (its first --shape-frames frames) is "
                  "tracked again backwards, from its frame of lowest XOR, when its first "
                  "frame's XOR is over this factor times that (a start gone wrong that the "
                  "track found its way out of), in the shape pass too; so is a divergence "
                  "or loss, from the frame that recovers from it; the frames tracked back "
                  "replace the others where their XOR is clearly lower; and a shape pass runs "
                  "again from its last frame when a start searched there is under 1/factor "
                  "of its XOR there (0 = off)"},
    )  # fmt: skip
    init_headings: int = field(
        default=8,
        metadata={"help": "upright starting poses, at this many headings, that compete with "
                  "the visual-hull fit at initialisation (0 = the fit alone)"},
    )  # fmt: skip
    init_extremity_starts: int = field(
        default=3,
        metadata={"help": "starts from the visual hull's extremities (head, hands and feet "
                  "assigned, inverse kinematics; tracking.track.extremities), the best by XOR, "
                  "that compete with the fit and the upright starts at initialisation "
                  "(at the first frame, where the shape is set too, winning only with an XOR "
                  f"under {_EXTREMITY_LEAD} times theirs) (0 = none): they reach bodies upside "
                  "down or sideways"},
    )  # fmt: skip
    init_simplex_evals: int = field(
        default=120, metadata={"help": "evaluations of each simplex at initialisation"}
    )
    init_crouched: bool = field(
        default=False,
        metadata={"help": "when the visual hull's fit is not upright, crouched bodies at the "
                  "upright starts' headings compete at the start too (a body bent over, "
                  "squatting, picking something up). Not the default: on the motion suite "
                  "from clip frame 150 it took bend_pickup 56.8 -> 13.7 mm but the "
                  "cartwheel 54.9 -> 302 mm (a start won by 3%% of XOR among starts all over "
                  "50%%)"},
    )  # fmt: skip
    recovery_passes: int = field(
        default=3,
        metadata={"help": "passes of the whole hierarchy given to the two best starts of a "
                  "recovery's search from the visual hull (every start has one; 1 = no more); "
                  "those after the second only while the best is still a divergence, and for "
                  "the starts the pass before improved"},
    )  # fmt: skip
    floor_band_m: float = field(
        default=0.1,
        metadata={"help": "height of the visual hull's lowest band, metres, whose pixels no "
                  "voxel above it covers count as missed whatever the pose, so that the fit "
                  "does not stretch to a floor shadow that background subtraction kept; the "
                  "start leaves out the band's voxels under a gap (0 = off)"},
    )  # fmt: skip
    voxel_m: float = field(default=0.03, metadata={"help": "visual-hull voxel size, metres"})
    hull_size_m: float = field(
        default=2.6, metadata={"help": "side of the visual-hull cube around the subject, metres"}
    )
    contour_iterations: int = field(
        default=8,
        metadata={"help": "iterations of the joint refinement of all parameters against the "
                  "silhouette outlines before and after the hierarchy (tracking.track.contour; "
                  "0 = off)"},
    )  # fmt: skip
    contour_level: int = field(
        default=0, metadata={"help": "pyramid level of the outline refinement (0 = full size)"}
    )
    renderer: str = field(
        default="cpu-raster", metadata={"help": "silhouette renderer plugin (mocap plugins)"}
    )
    hold: tuple[str, ...] = field(
        default=(),
        metadata={"help": "a pose parameter held at 0, not tracked (repeatable; e.g. --hold "
                  "spine_bend --hold spine_twist tracks the thesis' 24 parameters): one of "
                  "spine_flex, neck_flex, spine_bend, spine_twist", "metavar": "PARAM"},
    )  # fmt: skip
    body: str = field(
        default="mpfb",
        metadata={"help": "body model plugin the tracker fits (mocap plugins): mpfb "
                  "(MakeHuman's skinned body, its macro shape and loose clothing refined from "
                  "the silhouettes) or superquadric (the thesis' rigid segments)"},
    )  # fmt: skip
    workers: int = field(
        default=0,
        metadata={"help": "processes that fit and refine the candidate starts side by side "
                  "(the automatic start's and a recovery's), and a mend's two limb searches "
                  "(recon.parallel.fork_map); above 1, mocap track also tracks back (after a "
                  "recovery, and the opening) beside the track: 0 = "
                  "$MOCAP_WORKERS if set, else one per core this process may use; 1 = this "
                  "process alone; the poses are the same"},
    )  # fmt: skip

    def __post_init__(self) -> None:
        from recon.errors import UserError

        def flag(name: str) -> str:
            return "--" + name.replace("_", "-")

        if self.levels < 1:
            raise UserError(f"--levels must be >= 1, got {self.levels}")
        for name in ("search_level", "final_level", "contour_level"):
            if not 0 <= getattr(self, name) < self.levels:
                raise UserError(f"{flag(name)} must be in 0..{self.levels - 1} (--levels "
                                f"{self.levels}), got {getattr(self, name)}")
        for name, low in (("grid", 1), ("init_grid", 1), ("init_twists", 1),
                          ("init_starts", 1), ("simplex_evals", 1),
                          ("init_simplex_evals", 1), ("passes", 1), ("shape_stride", 1),
                          ("recovery_passes", 1),
                          ("shape_frames", 0), ("contour_iterations", 0),
                          ("init_headings", 0), ("init_extremity_starts", 0),
                          ("high_xor_frames", 0), ("xor_window", 1), ("workers", 0)):
            if getattr(self, name) < low:
                raise UserError(f"{flag(name)} must be >= {low}, got {getattr(self, name)}")
        for name in ("prior_weight", "twist_weight", "range_gain", "spike_xor_factor",
                     "high_xor_factor", "xor_margin", "max_unexplained_share",
                     "floor_band_m", "back_xor_factor"):
            if getattr(self, name) < 0:
                raise UserError(f"{flag(name)} must be >= 0, got {getattr(self, name)}")
        for name in ("prior_scale_deg_s", "prior_scale_m_s", "twist_scale_deg",
                     "max_xor_fraction", "voxel_m", "unexplained_m"):  # fmt: skip
            if not getattr(self, name) > 0:
                raise UserError(f"{flag(name)} must be > 0, got {getattr(self, name)}")
        if not 0 <= self.min_range_deg_s <= self.max_range_deg_s:
            raise UserError(f"need 0 <= --min-range-deg-s <= --max-range-deg-s, got "
                            f"{self.min_range_deg_s} and {self.max_range_deg_s}")
        check_voxel_grid(self.hull_size_m, self.voxel_m, "--hull-size-m", "--voxel-m")
        trunk = [name for name in PARAM_INDEX if PARAM_INDEX[name] in _TRUNK]
        for name in self.hold:
            if name not in trunk:
                raise UserError(f"--hold {name}: only the trunk's parameters can be held ("
                                f"{', '.join(trunk)})")

    def free_params(self, also_held: tuple[str, ...] = ()) -> np.ndarray:
        """Indices of the tracked pose parameters: all but `hold` (and `also_held`)."""
        held = {PARAM_INDEX[name] for name in (*self.hold, *also_held)}
        return np.array([i for i in range(N_POSE_PARAMS) if i not in held])


STATUSES = ("init", "tracked", "recovered", "diverged", "lost", "absent", "two-subjects")
"""A frame's `FrameResult.status`; new ones go at the end (the recording logs the index)."""


@dataclass(frozen=True)
class FrameResult:
    """One tracked frame: pose or None when lost; energy in full-resolution XOR pixels."""

    frame: int
    pose: Pose | None
    energy: float
    silhouette_area: float
    evaluations: int
    seconds: float
    """The time this frame's forward tracking took (a frame a track back replaced keeps it and
    its evaluations: `mocap track`'s summary counts a track back's apart)."""
    event: str = ""  # "init ...", "recovered ...", "diverged: ...", "lost: ...", "absent: ..."
    status: str = "tracked"
    """One of `STATUSES`: "init" (a start), "tracked", "recovered" (a divergence, or the first
    frame after lost or absent ones, found again by the start search; or, after a "diverged"
    frame, the first tracked frame back under the XOR bar of before it, with the visual hull
    explained: `XorWatch.returned`; or the first diverged or lost frame that a track back from
    a later recovery replaced, `SilhouetteTracker.track_back_gap`), "diverged" (a
    divergence the search found nothing better for, or a frame after it still over the XOR
    bar of before it: the best pose is kept, not trusted),
    "lost" (no pose), "absent" (no pose: no camera has a silhouette, the subject is out of
    view) or "two-subjects" (no pose: the visual hull has two or more separate parts of human
    size, `SilhouetteTracker.subjects_in_view`)."""
    cut_by: tuple[str, ...] = ()
    """Cameras whose silhouette touches the image border: the subject is partly out of their
    view (a flag, whatever the status: the tracker fits what the image shows, and the visual
    hull of a start keeps what is out of one view's image, `hull_min_views`)."""
    unexplained_share: float | None = None
    """The share of the visual hull the frame's pose leaves out
    (`tracking.track.unexplained.unexplained_hull_part`; None: not checked: no pose, or the
    check is off)."""
    unexplained: bool = False
    """The share is over `TrackConfig.max_unexplained_share`: a part of the visual hull the
    body leaves out, a limb likely misplaced (a flag, whatever the status)."""

    @property
    def xor_fraction(self) -> float:
        return self.energy / max(self.silhouette_area, 1.0)


class _StageEnergy:
    """Energy of a pose in which only the parameters `free` change (the rest held at `base`):
    the silhouette of the triangles they do not move is rendered once. `prior`: (centre,
    weight) per parameter, adding sum weight (x - centre)^2 XOR pixels (the temporal prior)."""

    def __init__(self, energy: SilhouetteEnergy, base: np.ndarray, free: Sequence[int],
                 level: int, prior: tuple[np.ndarray, np.ndarray] | None = None,
                 ) -> None:  # fmt: skip
        self.energy, self.level = energy, level
        self.prior = prior
        self.base = base.copy()
        self.free = np.asarray(free)
        model = energy.model
        moved_nodes = _MOVES[self.free].any(axis=0)
        moving = model.faces_moved_by(moved_nodes)
        self.faces = model.faces[moving]
        self.cameras = energy.cameras[level]
        static_faces = model.faces[~moving]
        vertices = model.posed_vertices(Pose(self.base))
        static = (
            render_views(energy.renderer, vertices, static_faces, self.cameras)
            if len(static_faces)
            else None
        )
        self.count = XorCount(energy.renderer, self.cameras, energy.masks[level],
                              energy.known[level], static, energy.missed[level])  # fmt: skip
        # Only the vertices of the moving faces are drawn (and projected).
        self.vertex_ids = np.unique(self.faces)
        self.local_faces = np.searchsorted(self.vertex_ids, self.faces)
        self.local_faces.flags.writeable = False  # counted as is (`ViewGains.edges`)
        self.pixel_area = energy._pixel_area[level]
        self.evaluations = 0

    def params(self, values: np.ndarray) -> np.ndarray:
        x = self.base.copy()
        x[self.free] = values
        return np.clip(x, SEARCH_LOWER_LIMITS, SEARCH_UPPER_LIMITS)

    def __call__(self, values: np.ndarray) -> float:
        self.evaluations += 1
        x = self.params(values)
        vertices = self.energy.model.posed_vertices(Pose(x), self.vertex_ids)
        counts = self.count.counts(vertices, self.local_faces)
        total = 0.0
        if self.prior is not None:
            centre, weight = self.prior
            total += float(np.sum(weight[self.free] * (x[self.free] - centre[self.free]) ** 2))
        for area, count in zip(self.pixel_area, counts, strict=True):
            total += area * count
        return total


def _simplex(fun: Callable[[np.ndarray], float], x0: np.ndarray, steps: np.ndarray,
             lo: np.ndarray, hi: np.ndarray, evals: int) -> np.ndarray:  # fmt: skip
    """Downhill simplex (Nelder-Mead) from x0 with initial edge lengths `steps`, in bounds."""
    x0 = np.clip(x0, lo, hi)
    simplex = np.vstack([x0, x0 + np.diag(steps)])
    # Keep the initial simplex inside the bounds by stepping the other way where needed.
    over = simplex[1:] > hi
    simplex[1:][over] = (x0[None, :] - np.diag(steps))[over]
    simplex = np.clip(simplex, lo, hi)
    from scipy.optimize import minimize  # 0.9 s to import: not for `mocap track --help`

    result = minimize(fun, x0, method="Nelder-Mead", bounds=list(zip(lo, hi, strict=True)),
                      options={"initial_simplex": simplex, "maxfev": evals, "xatol": 1e-4,
                               "fatol": 0.5})  # fmt: skip
    return result.x


class SilhouetteTracker:
    """Tracks one subject through a sequence of multi-view silhouettes (see module docstring).

    cameras: the calibrated views; model: the subject's body (`TrackedModel`, its shape fixed,
    thesis 6.2.4), or None to estimate it at initialisation from the ``config.body`` plugin's
    model (``shape``: a known `BodyShape` of the thesis' model instead); unknown: per view,
    None or the (H, W) bool pixels whose label the silhouettes cannot tell (no background
    known behind them): they count in no energy, and do not carve the visual hull.
    """

    def __init__(self, cameras: Sequence[Camera], config: TrackConfig | None = None,
                 shape: BodyShape | None = None,
                 unknown: Sequence[np.ndarray | None] | None = None,
                 model: TrackedModel | None = None,
                 frame_interval_s: float = DEFAULT_FRAME_INTERVAL_S) -> None:  # fmt: skip
        from plugins.registry import create

        if not (np.isfinite(frame_interval_s) and frame_interval_s > 0):
            raise ValueError(f"frame interval {frame_interval_s} s: not a positive duration")
        self.frame_interval_s = float(frame_interval_s)

        self.cameras = list(cameras)
        self.unknown = list(unknown) if unknown is not None else [None] * len(self.cameras)
        self.known = [None if u is None else ~np.asarray(u, bool) for u in self.unknown]
        self.config = config or TrackConfig()
        self.renderer = create("renderer", self.config.renderer)
        self.body = create("body", self.config.body)
        if shape is not None and model is not None:
            raise ValueError("give the tracker a shape or a model, not both")
        if shape is not None:  # a known skeleton of the superquadric model
            model = BodyModel(shape)
        if model is not None and model.name != self.config.body:
            raise ValueError(f"a {model.name} model for a tracker of body {self.config.body!r}")
        self.model: TrackedModel | None = model
        self.history: list[np.ndarray] = []  # params of the last tracked frames
        self._xor_floor = np.inf  # XOR fraction of the best initialisation (divergence test)
        cfg = self.config
        self.watch = XorWatch(WatchConfig(
            spike_factor=cfg.spike_xor_factor, high_factor=cfg.high_xor_factor,
            high_frames=cfg.high_xor_frames, window=cfg.xor_window, min_margin=cfg.xor_margin))
        self._last_good: tuple[int, np.ndarray] | None = None  # (frame, params) last trusted
        self._lost_since: int | None = None  # first frame of the current run of lost frames
        self._gap_statuses: set[str] = set()  # statuses of that run's frames
        self._tracked_any = False  # a frame has had a pose since the start (or shape pass)
        self.shape_frames_used: list[int] = []  # `calibrate_shape`'s frames (indices)
        # frame -> the pose the shape pass gave it (`calibrate_shape`), trusted: a recovery
        # there starts from it too (`_recover`)
        self._shape_pass_poses: dict[int, np.ndarray] = {}
        # (the frame's energy, level, its outline refiner): built once per frame and level
        self._refiner: tuple[SilhouetteEnergy, int, ContourRefiner] | None = None
        self._part: tuple[object, bytes, tuple[float, np.ndarray]] | None = None  # its last
        # (masks, points, up, band): the frame's hull (`_frame_hull`), for its last masks
        self._hull: tuple[object, np.ndarray, np.ndarray | None, list | None] | None = None
        self._mend_failed_at: int | None = None  # the frame of the last mend that found nothing
        self.evaluations = 0
        # How `calibrate_shape` found the pose it returns: the first tracked frame starts from
        # it as from a given pose, and says this instead.
        self._start_event = ""
        # While the start is searched (the visual-hull start, the shape pass), the spine's side
        # bend and twist stay 0 (`_START_HELD`).
        self._starting = False
        self._backwards = False  # `track_back`: the divergence watch is forwards in time

    @property
    def shape(self) -> BodyShape | None:
        """The subject's skeleton (`TrackedModel.shape`), None until it is estimated."""
        return None if self.model is None else self.model.shape

    # -- initialisation -------------------------------------------------------------------
    def visual_hull_points(self, masks: Sequence[np.ndarray]) -> np.ndarray:
        """(N, 3) centres of the visual hull's surface voxels, world frame."""
        if not all(m.any() for m in masks):
            empty = [c.name for c, m in zip(self.cameras, masks, strict=True) if not m.any()]
            raise TrackingLost(f"empty silhouette in {', '.join(empty)}")
        return hull_surface_points(self.cameras, masks, min_views=hull_min_views(masks),
                                   size_m=self.config.hull_size_m, voxel_m=self.config.voxel_m,
                                   unknown=self.unknown)  # fmt: skip

    def subjects_in_view(self, masks: Sequence[np.ndarray]) -> list[HullPart]:
        """The parts of human size of the visual hull of ``masks`` (`hull_parts`,
        `subject_sized`), largest first: one for one subject in view, two or more for two
        subjects apart (the silhouettes of two subjects that touch make one part). Carved
        on a cube twice `hull_size_m` wide at twice `voxel_m` (0.1 s at 320x240), so that a
        second subject beside the first is in it; only the space every camera sees counts."""
        return subjects_in_view(self.cameras, masks, self.config, self.unknown)

    def _one_subject(self, masks: Sequence[np.ndarray]) -> None:
        """`SubjectsInView` when the silhouettes show two subjects or more."""
        parts = self.subjects_in_view(masks)
        if len(parts) >= 2:
            heights = ", ".join(f"{p.height_m:.2f}" for p in parts)
            apart = float(np.linalg.norm(parts[0].centre - parts[1].centre))
            raise SubjectsInView(
                f"{len(parts)} subjects in view: the visual hull has {len(parts)} separate "
                f"parts of human size ({heights} m tall; the two largest {apart:.2f} m apart), "
                "so the frame is not tracked")

    def initialise(self, masks: Sequence[np.ndarray], init: Pose | None = None,
                   enough: Callable[[float], bool] | None = None) -> tuple[Pose, str]:
        """The first pose: `init` if given, else the best of a body fitted to the visual hull and
        upright bodies at `init_headings` headings, each refined against the silhouettes. Sets
        the shape when it was unknown. enough: for a recovery, whether a pose of this energy
        is no divergence (`_pass_again`)."""
        if init is None:
            with self._searching_start():
                return self._initialise_from_hull(masks, enough)
        if self.shape is None:
            raise ValueError("an initial pose needs the subject's shape")
        message, self._start_event = self._start_event or "init from the given pose", ""
        x = self._refine_all(self._energy(masks), init.params.copy(), init=True)
        self.history = []
        return Pose(in_limits(x)), message

    def _initialise_from_hull(self, masks: Sequence[np.ndarray],
                              enough: Callable[[float], bool] | None = None,
                              ) -> tuple[Pose, str]:  # fmt: skip
        """`initialise` without a given pose."""
        from tracking.fit.body_fit import FitConfig, fit_body

        self._one_subject(masks)  # a fit to two subjects' hull would merge them
        points, up, _ = self._frame_hull(masks)  # carved once with the frame's energy's
        if not len(points):
            self.visual_hull_points(masks)  # an empty silhouette: its one-line reason
        if len(points) < 100:
            raise TrackingLost("the silhouettes do not intersect in a visual hull")
        if up is not None and self.config.floor_band_m > 0:
            # A floor shadow's slab is no body to fit, stand on, or reach with a foot.
            points = points[~floor_only(points, up, band_m=self.config.floor_band_m,
                                        voxel_m=self.config.voxel_m)]  # fmt: skip
        # The superquadrics' fit, whatever `mocap fit` defaults to: it is only a start, the
        # silhouettes refine it (a skinned refinement of a hull is slow and no better). Not
        # judged (the height's test neither): a hull the upright orientations cannot fit (a
        # body upside down) failed the test and ran every fallback stage of the fit, 126 s
        # against 13 for the first stage (test_bad_input's handstand); the hull's extent caps
        # the start's height below, and a recovery keeps the subject's shape.
        fit = fit_body(points, FitConfig(body="superquadric", judge=False, hold=_START_HELD,
                                         workers=self.config.workers),
                       up=up)  # fmt: skip
        bent = up is not None and not is_upright(fit.pose, fit.shape, up)
        estimate_shape = self.shape is None
        if estimate_shape:
            # The fit's height and the hull's along up (`start_heights`): the search runs at
            # each, and the lower XOR keeps its height.
            searches, ranked = [], None
            for height in start_heights(fit.pose, fit.shape, points, up, self.config.voxel_m):
                self.model = self.body.tracking_model(height)
                x, score, start, ranked, contender = self._start_search(
                    masks, fit.pose, points, up, bent, False,
                    only=None if ranked is None else ranked[:_SECOND_HEIGHT_STARTS])
                searches.append((self.model, x, score, start, contender))
            self.model, x, score, start, contender = min(searches, key=lambda s: s[2])
            if len(searches) > 1:
                start += f" at {self.model.shape.height:.2f} m"
                if contender is not None:
                    contender = (contender[0], f"{contender[1]} at "
                                 f"{self.model.shape.height:.2f} m")
        else:
            x, score, start, *_ = self._start_search(masks, fit.pose, points, up, bent, True,
                                                     enough)
        energy = self._energy(masks)
        if estimate_shape and self.config.init_shape:
            x, swapped, start = self._shaped_winner(masks, energy, x, start, contender)
        else:
            x, swapped = self._winner_swapped(energy, x, score)
        message = f"init from visual hull ({len(points)} surface voxels; {start}{swapped})"
        self.history = []
        return Pose(in_limits(x)), message

    def _start_search(self, masks: Sequence[np.ndarray], fit: Pose, points: np.ndarray,
                      up: np.ndarray | None, bent: bool, known_shape: bool,
                      enough: Callable[[float], bool] | None = None,
                      only: Sequence[int] | None = None,
                      ) -> tuple[np.ndarray, float, str, list[int],
                                 tuple[np.ndarray, str] | None]:  # fmt: skip
        """The start of `_initialise_from_hull` with the current model: the hull `fit`, upright
        bodies at `init_headings` headings (crouched ones too where `bent`) and poses on the
        hull's extremities, each refined by the whole hierarchy. Returns the winner, its
        `_objective` at `final_level`, which start it is, the starts' indices (the fit, the
        upright starts, the crouched ones, then the extremities') from the lowest score, and
        the contender: the best extremity start and which it is, when it scored lower than the
        winner but without `_EXTREMITY_LEAD`'s lead (a start that sets the shape; else None).
        The shapes decide between the two (`_shaped_winner`). bent:
        the fit is not upright (`is_upright`), and crouched bodies compete too. known_shape:
        not the start that sets the shape (a recovery); enough: then whether a pose of this
        energy is no divergence: the stances are refined only when none of the hull's own
        starts is (those left score infinity), and it stops `_pass_again`'s passes; only: the
        indices of the starts refined (the others score infinity; `_SECOND_HEIGHT_STARTS`),
        None: all."""
        # The hull fit can put a limb inside the trunk or lean the trunk to explain a
        # limb: upright bodies at several headings compete with it (each refined by the
        # whole hierarchy, limb grids over their whole range); the lowest XOR wins.
        energy = self._energy(masks)
        pelvis = fit.params[:3].copy()
        if up is not None:  # standing on the hull's lowest point
            pelvis += (np.min(points @ up) + self.shape.hip_height - pelvis @ up) * up
        uprights = upright_starts(fit, up, self.config.init_headings, pelvis)
        # A hull the fit finds bent over may be a body crouched: crouched bodies at the same
        # headings compete too (on the fit's pelvis).
        crouched = (crouched_starts(fit, up, self.config.init_headings)
                    if bent and self.config.init_crouched else [])
        # (The fit's left/right swaps and the extremities' poses, made only when refined.)
        wanted = set(range(1 + len(uprights) + len(crouched)
                           + self.config.init_extremity_starts) if only is None else only)
        starts = [self._best_hypothesis(energy, fit.params) if 0 in wanted else fit,
                  *uprights, *crouched]
        # Neither reaches a body upside down or sideways: poses whose head, hands
        # and feet are on the hull's extremities compete too.
        ends = (self._extremity_starts(energy, points)
                if any(i >= len(starts) for i in wanted) else [])
        candidates = [*starts, *ends]
        picked = sorted(i for i in wanted if i < len(candidates))
        refined, scores = [p.params for p in candidates], [np.inf] * len(candidates)
        # A recovery refines the visual hull's own starts (its fit and its extremities') first,
        # and the stances (upright, crouched) only when none of those is `enough`: 3 of the 13
        # searches of recoveries in the suite's three sets ended there (session 44). A group at
        # a time rather than a pair: several jobs to a `fork_map` balance the cores, and 6 pairs
        # took a search that found nothing 4.1 s against 3.1 for its 12 starts at once (the
        # frame-150 turn_pirouette's frame 20). The start that sets the shape refines all at
        # once.
        groups = [picked] if enough is None else [
            [i for i in picked if not 0 < i < len(starts)],
            [i for i in picked if 0 < i < len(starts)]]
        for k, group in enumerate(g for g in groups if g):
            # (A second group exists only with `enough`.)
            if k and enough(energy(Pose(refined[int(np.argmin(scores))]))):
                break
            for i, y in zip(group, self._refine_starts(energy, [candidates[i] for i in group]),
                            strict=True):  # fmt: skip
                refined[i], scores[i] = y, self._objective(energy, y, self.config.final_level)
        if known_shape:
            refined, scores = self._pass_again(energy, refined, scores, enough)
        # When the start also sets the shape, an extremity start wins by a clear lead only;
        # with the shape known (a recovery), the lowest XOR wins.
        best = start_winner(scores[:len(starts)], scores[len(starts):],
                            1.0 if known_shape else _EXTREMITY_LEAD)

        def which(index: int) -> str:
            if index == 0:
                return "its fit"
            if index < len(starts):
                kind = "an upright" if index <= len(uprights) else "a crouched"
                heading = 360 * ((index - 1) % len(uprights)) // len(uprights)
                return f"{kind} start at {heading} deg from its fit"
            return f"start {index - len(starts) + 1} of {len(ends)} from its extremities"

        lowest = int(np.argmin(scores))
        contender = ((refined[lowest], which(lowest)) if lowest >= len(starts) > best
                     and scores[lowest] < scores[best] else None)  # fmt: skip
        return (refined[best], scores[best], which(best),
                [int(i) for i in np.argsort(scores, kind="stable")], contender)

    def _side_by_side(self, job: Callable[[int], Any], count: int) -> list[Any]:
        """``[job(0), ..., job(count - 1)]`` of independent jobs, in `TrackConfig.workers`
        forked processes (`fork_map`): the same results as one by one. The energy evaluations
        the jobs make count in `evaluations` wherever they ran (a child's count is lost
        with it, so each job returns its own)."""
        def counted(index: int) -> tuple[Any, int]:
            before = self.evaluations
            out = job(index)
            made, self.evaluations = self.evaluations - before, before
            return out, made

        results = fork_map(counted, count, workers_for(self.config.workers))
        self.evaluations += sum(made for _, made in results)
        return [out for out, _ in results]

    def _refine_starts(self, energy: SilhouetteEnergy, starts: Sequence[Pose]) -> list[np.ndarray]:
        """Each of `starts` refined by the whole hierarchy, the limbs' grids over their whole
        range (`_refine_all` with init): independent of one another, so side by side in
        `TrackConfig.workers` processes (`fork_map`), with the same results as one by one."""
        refined = self._side_by_side(lambda index: self._refine_all(
            energy, starts[index].params.copy(), init=True), len(starts))
        # What `_refine_all` leaves behind (the start's priors), set here too when the
        # refinements ran in other processes.
        self._prepare(energy, init=True)
        return refined

    def _shaped_winner(self, masks: Sequence[np.ndarray], energy: SilhouetteEnergy,
                       x: np.ndarray, start: str = "",
                       contender: tuple[np.ndarray, str] | None = None,
                       ) -> tuple[np.ndarray, str, str]:  # fmt: skip
        """The winning start `x` of a start that sets the shape (`start` says which it is),
        and its left/right swaps (`left_right_swaps`, each refined by the whole hierarchy),
        each given the subject's proportions (the segment lengths from the silhouettes'
        outlines with the pose, then the whole hierarchy again: thesis 6.2.4), side by side:
        the lowest XOR after that wins and sets the model. Returns it, what the start's message
        says of a swap that won, and which start it is.

        The XOR before the proportions cannot tell: the suite's cartwheel with its noise drawn
        from seed 1 won an upright start's swap of the legs and arms at XOR 0.294 of the
        silhouette area against the start's own 0.316 (173 mm off at frame 0, against 92);
        with their proportions, 0.243 (163 mm) against 0.165 (52 mm) (session 37).

        contender: an extremity start (its pose and which it is) that scored lower than `x`
        before the proportions, without the lead an extremity start needs
        (`_start_search`): it and its swaps are given theirs too, and it wins when the lowest
        of them is under `_EXTREMITY_LEAD` times `x`'s lowest. The suite's cartwheel at 24
        fps: its upright start at 45 degrees won at 13125 px against the extremity start's
        11510 (0.88), and with their proportions ended at 23.6% XOR, 73 mm off at frame 0,
        against 14.5%, 15 mm (the track: 3 frames over 100 mm, flagged unexplained; session 47)."""
        starts = [x] if contender is None else [x, contender[0]]
        swaps = self._refine_starts(energy, [Pose(y) for s in starts
                                             for y in left_right_swaps(s)])
        group = len(SWAPPED) + 1  # a start, then its swaps
        poses = [y for k, s in enumerate(starts)
                 for y in (s, *swaps[k * len(SWAPPED):(k + 1) * len(SWAPPED)])]
        base = self.model

        def shaped(index: int) -> tuple[np.ndarray, TrackedModel, float]:
            self.model = base
            y = self._refine_shape([masks], [Pose(poses[index])])[0].params
            own = self._energy(masks)
            y = self._refine_all(own, y, init=True)
            return y, self.model, self._objective(own, y, self.config.final_level)

        results = self._side_by_side(shaped, len(poses))
        lowest = [k * group + int(np.argmin([r[2] for r in results[k * group:(k + 1) * group]]))
                  for k in range(len(starts))]  # fmt: skip
        best = lowest[0]
        if contender is not None and results[lowest[1]][2] < _EXTREMITY_LEAD * results[best][2]:
            best = lowest[1]
        y, self.model, _ = results[best]
        self._prepare(energy, init=True)  # as `_refine_starts` leaves it
        swapped = "" if best % group == 0 else f", its {SWAPPED[best % group - 1]} swapped"
        if best < group:
            return y, swapped, start
        return y, "", (f"{contender[1]}{swapped}, with its proportions under "
                       f"{_EXTREMITY_LEAD:g} times {start}'s ({results[best][2]:.0f} against "
                       f"{results[lowest[0]][2]:.0f} XOR px)")

    def _refined_swaps(self, energy: SilhouetteEnergy, x: np.ndarray) -> list[np.ndarray]:
        """`left_right_swaps` of `x`, each refined by the whole hierarchy (`_refine_starts`)."""
        return self._refine_starts(energy, [Pose(y) for y in left_right_swaps(x)])

    def _winner_swapped(self, energy: SilhouetteEnergy, x: np.ndarray, score: float
                        ) -> tuple[np.ndarray, str]:  # fmt: skip
        """The winning start `x` (its `_objective` `score` at `final_level`) against its
        left/right swaps of the legs, the arms and both, each refined by the whole hierarchy
        (side by side, `_refine_starts`): the lowest wins. Returns it and, when a swap won,
        what the start's message says of it.

        The hull cannot tell which leg is which, and the starts' grids can put the legs either
        way: the suite's run with its noise drawn from seed 2 (``tracking_suite.py --seeds
        2``) won an upright start with the legs swapped (103 mm at frame 0, XOR 3560 px) and
        was tracked so for the whole clip, 130.8 mm, 31 frames over 100 mm unflagged; its leg
        swap refined scores 2112 px and 16 mm (session 36). The fit's start had its swaps
        (`_best_hypothesis`, on the outlines only), the others none."""
        again = self._refined_swaps(energy, x)
        scores = [self._objective(energy, y, self.config.final_level) for y in again]
        best = int(np.argmin(scores))
        if scores[best] >= score:
            return x, ""
        return again[best], f", its {SWAPPED[best]} swapped"

    def _pass_again(self, energy: SilhouetteEnergy, refined: Sequence[np.ndarray],
                    scores: Sequence[float], enough: Callable[[float], bool] | None = None,
                    ) -> tuple[list[np.ndarray], list[float]]:  # fmt: skip
        """A recovery's refined starts and their scores (`_objective` at `final_level`), the
        `_AGAIN_STARTS` lowest given `recovery_passes` - 1 more passes of the whole hierarchy
        (side by side), each kept where it scores lower. From a far start one pass stops short
        of the basin it is in: on the 30-frame cartwheel's frame 29 (inverted), the best
        extremity start went 0.336 -> 0.242 of the silhouette in a second pass (MPJPE 86 -> 62
        mm; a third: 0.220, 60 mm), past the last good pose's 0.313, and the frame recovered
        (it had diverged, unrecovered). The first frame's start is refined again with the
        shape that follows it (`_initialise_from_hull`).

        The passes after the second run only while the best start is not `enough` (its XOR,
        `_recover`'s test: a pose that is no divergence; None: never enough), and only for
        the starts the pass before lowered (a start it did not is where the same pass leaves
        it again): the same frame 29, after a session-33 change of the outline refinement by
        3e-16, ended its second pass at 0.302, still a divergence, and its third at 0.228."""
        refined, scores = list(refined), list(scores)
        again_for = [int(i) for i in np.argsort(scores, kind="stable")[:_AGAIN_STARTS]]
        for extra in range(self.config.recovery_passes - 1):
            if extra and enough is not None \
                    and enough(energy(Pose(refined[int(np.argmin(scores))]))):
                break
            again = self._refine_starts(energy, [Pose(refined[i]) for i in again_for])
            lowered = []
            for i, y in zip(again_for, again, strict=True):
                score = self._objective(energy, y, self.config.final_level)
                if score < scores[i]:
                    refined[i], scores[i] = y, score
                    lowered.append(i)
            again_for = lowered
            if not again_for:
                break
        return refined, scores

    def _extremity_starts(self, energy: SilhouetteEnergy, points: np.ndarray) -> list[Pose]:
        """The `init_extremity_starts` poses of lowest XOR at `search_level` among those whose
        end sites reach the visual hull's extremities (`tracking.track.extremities`: surface
        voxels `points`), over the `_EXTREMITY_ASSIGNMENTS` best assignments of head, hands
        and feet to them."""
        count = self.config.init_extremity_starts
        if count == 0:
            return []
        assert self.shape is not None
        ends = hull_extremities(points, self.config.voxel_m)
        assignments = extremity_assignments(ends, self.shape, _EXTREMITY_ASSIGNMENTS)
        free, centre = self._free(), points.mean(axis=0)
        poses = self._side_by_side(lambda i: pose_from_extremities(
            ends, assignments[i], self.shape, free, centre)[0], len(assignments))
        scores = [energy(p, self.config.search_level) for p in poses]
        self.evaluations += len(poses)
        return [poses[i] for i in np.argsort(scores, kind="stable")[:count]]

    def _best_hypothesis(self, energy: SilhouetteEnergy, x: np.ndarray) -> Pose:
        """The visual hull cannot tell which leg (or arm) is which: of the pose and its
        left/right swaps of the legs, the arms, and both, the one whose outline refinement
        ends with the lowest XOR energy."""
        level = self.config.search_level
        refiner = ContourRefiner(energy.model, energy.cameras[level], energy.masks[level],
                                 energy.renderer, ContourConfig(iterations=20),
                                 known=energy.known[level])  # fmt: skip
        starts = [x, *left_right_swaps(x)]
        free = self._free()
        # Independent: side by side (`TrackConfig.workers`), the same results.
        refined = self._side_by_side(lambda i: refiner.refine(
            self._held_at_zero(starts[i]), free, lambda p: energy(Pose(p), level)), len(starts))
        best, best_e = x, np.inf
        for y, e, n in refined:
            self.evaluations += n
            if e < best_e:
                best, best_e = y, e
        return Pose(best)

    def _refine_shape(self, sequence: Sequence[Sequence[np.ndarray]], poses: Sequence[Pose],
                      iterations: int = 30) -> list[Pose]:  # fmt: skip
        """The model's shape parameters (`TrackedModel.shape_parameters`: the segment-length
        scales of `SHAPE_GROUPS`, or a skinned body's macro modifiers) and the poses of one or
        more frames together, by Gauss-Newton on the silhouette outlines
        (`tracking.track.contour.refine_shape`); sets the model and returns the poses."""
        assert self.model is not None
        level = self.config.contour_level
        energies = [self._energy(masks) for masks in sequence]

        def energy(model: TrackedModel, xs: Sequence[np.ndarray]) -> float:
            self.evaluations += len(xs)
            return sum(e.with_model(model)(Pose(x), level)
                       for e, x in zip(energies, xs, strict=True))  # fmt: skip

        self.model, xs, _ = refine_shape(
            self.model, [(e.cameras[level], e.masks[level], e.known[level]) for e in energies],
            [p.params for p in poses], self.renderer, energy,
            ContourConfig(iterations=iterations), free=self._free())
        return [Pose(x) for x in xs]

    @contextmanager
    def _searching_start(self) -> Iterator[None]:
        """While the start is searched, `_START_HELD` is held too (`_free`)."""
        starting, self._starting = self._starting, True
        try:
            yield
        finally:
            self._starting = starting

    def _free(self) -> np.ndarray:
        """The parameters refined now: `TrackConfig.free_params`, without the spine's side bend
        and twist while the start is searched (`_starting`)."""
        return self.config.free_params(_START_HELD if self._starting else ())

    def _held_at_zero(self, x: np.ndarray) -> np.ndarray:
        """x with the parameters that are not refined now at 0."""
        x = np.array(x, float)
        x[np.setdiff1d(np.arange(N_POSE_PARAMS), self._free())] = 0.0
        return x

    def calibrate_shape(self, sequence: Sequence[Sequence[np.ndarray]],
                        progress: Callable[[], object] | None = None,
                        frames: Sequence[int] | None = None) -> Pose | None:
        """The subject's shape from the first frames of a sequence (masks per frame), before
        tracking it: a frame is initialised (with its own shape estimate), the frames after it
        up to the last `shape_stride`-th of `shape_frames` are tracked, and every
        `shape_stride`-th one's pose is refined together with the segment lengths, which the
        silhouettes of several poses tell apart better than one.

        That frame is the first, unless its start is over the absolute bar
        (`max_xor_fraction`): a shape from a pose the silhouettes do not allow is wrong, and
        so is every pose after it. The start search then runs again, each time with a shape
        of its own, every `_SEARCH_AGAIN_FRAMES` frames of the first `shape_frames` until one
        is under the bar (else the lowest wins), and the pass runs from there (`sequence` may
        hold the frames it needs past the first `shape_frames`: `mocap track` gives it 3
        times those). A start under the bar can be
        wrong too, and the pass track on from it wrong: a start searched afresh at the pass's
        last frame, clearly lower than the pass there, starts the pass again from there
        (`_second_opinion`). The pose so found is then tracked back to the first frame with
        the pass's shape (`_tracked_to_start`).

        Returns the first frame's pose with that shape (None: the track back did not reach
        it under the bar, and the first frame's start is searched with the shape); the
        tracker then starts afresh from it and its event says how it was found (not "the
        given pose"). frames: the frame numbers of `sequence` (default 0, 1, ...), by which a
        recovery in these frames later finds the pose the pass gave it (`_recover`)."""
        if self.shape is not None:
            raise ValueError("the shape is already known")
        with self._searching_start():
            return self._calibrate_shape(sequence, progress,
                                         range(len(sequence)) if frames is None else frames)

    def _calibrate_shape(self, sequence: Sequence[Sequence[np.ndarray]],
                         progress: Callable[[], object] | None, frames: Sequence[int],
                         ) -> Pose | None:  # fmt: skip
        """`calibrate_shape` (the start's parameters held).

        The second opinion's search does not depend on the pass: it runs beside it, in a
        forked process with a pool of its own (`_opinion_beside`), from the pass's start on,
        and the shape is made from the pass while it runs; where it moves the pass, that is
        made again. The same results as in turn (the pass's frames and the shape use one core,
        the search both)."""
        fresh = self._track_state()
        results = [self._pass_start(sequence, frames, fresh)]
        if progress is not None:
            progress()
        opinion = self._opinion_beside(sequence, results, fresh)
        try:
            results = self._pass_frames(sequence, results, progress)
            event, made = self._start_event, None
            if opinion is not None and opinion[0] == results[-1].frame \
                    and not opinion[1].done():
                made = self._shape_from_pass(sequence, frames, results)  # (as if it stands)
            moved = self._second_opinion(sequence, frames, results, fresh, opinion, event)
        finally:
            if opinion is not None:
                opinion[1].cancel()
        if moved is not None:  # (its frames are not counted again)
            made = self._shape_from_pass(sequence, frames,
                                         self._pass_frames(sequence, [moved], None))
        elif made is None:
            made = self._shape_from_pass(sequence, frames, results)
        return made

    def _shape_from_pass(self, sequence: Sequence[Sequence[np.ndarray]], frames: Sequence[int],
                         results: list[FrameResult]) -> Pose | None:  # fmt: skip
        """`calibrate_shape`'s pose of the first frame from the shape pass's `results`: the
        pass's start tracked back where the frames after it tell it better, the segment
        lengths from every `shape_stride`-th pose, the pass's start with them, tracked back to
        frame 0 where the pass started later; the tracker's state as a fresh track needs."""
        stride = max(self.config.shape_stride, 1)
        first = results[0].frame  # (the pass's start, an index into `sequence`)
        # A start gone wrong is found from the frames after it: the shape comes from those.
        back = self.track_back(results, lambda index: sequence[index])
        if 0 in back:
            self._start_event += f", the first {max(back) + 1} tracked back"
        results = [back.get(i, r) for i, r in enumerate(results)]
        self._shape_pass_poses = {frames[r.frame]: r.pose.params for r in results
                                  if r.pose is not None and not r.unexplained
                                  and r.status in ("init", "tracked", "recovered")}
        picked = [r for i, r in enumerate(results) if i % stride == 0]
        # Which frames of `sequence` (indices) the shape came from: fewer than a full pass's
        # when the sequence is short or the pass lost the subject (`mocap track` warns).
        self.shape_frames_used = [r.frame for r in picked]
        poses = self._refine_shape([sequence[r.frame] for r in picked], [r.pose for r in picked])
        x = self._refine_all(self._energy(sequence[first]), poses[0].params.copy(), init=True)
        if first:
            x = self._tracked_to_start(sequence, frames, first, x)
        # Tracking starts afresh from the first frame: nothing of the pass is a reference.
        self.history, self._last_good, self._lost_since = [], None, None
        self._gap_statuses, self._tracked_any = set(), False
        self.watch.restart()
        return None if x is None else Pose(in_limits(x))

    def _pass_start(self, sequence: Sequence[Sequence[np.ndarray]], frames: Sequence[int],
                    fresh: dict[str, Any]) -> FrameResult:  # fmt: skip
        """The shape pass's start (`calibrate_shape`): the result of the frame it starts from
        (its `frame` an index into `sequence`), the tracker's state as that start left it
        (each search from the state `fresh`); its event in `_start_event`."""
        bar = self.config.max_xor_fraction
        tries: list[tuple[FrameResult, dict[str, Any]]] = []
        for index in range(0, self._pass_length(sequence, 0), _SEARCH_AGAIN_FRAMES):
            self._set_track_state(fresh)
            result = self.track(index, sequence[index])
            if result.pose is None:
                if index == 0:
                    raise TrackingLost(result.event.removeprefix("lost: "))
                continue
            tries.append((result, self._track_state()))
            if result.xor_fraction <= bar:
                break
        result, state = min(tries, key=lambda t: t[0].xor_fraction)
        self._set_track_state(state)
        self._start_event = f"{result.event}; segment lengths from the first frames"
        if result.frame:
            over = [f"{frames[r.frame]} (XOR {r.xor_fraction:.1%})" for r, _ in tries
                    if r.frame < result.frame]  # fmt: skip
            self._start_event = _pass_moved(
                result.event, f"{frames[result.frame]}", f"the start search at frame(s) "
                f"{', '.join(over)} was over the absolute bar ({bar:.0%})")
        return result

    def _pass_length(self, sequence: Sequence[Sequence[np.ndarray]], first: int) -> int:
        """The frames of a shape pass from index `first` of `sequence`: `shape_frames`, or
        those `sequence` has from there."""
        return min(max(self.config.shape_frames, 1), len(sequence) - first)

    def _pass_last(self, sequence: Sequence[Sequence[np.ndarray]], first: int) -> int:
        """The index of the last frame a shape pass from index `first` tracks: its last
        `shape_stride`-th of `_pass_length` (`_pass_frames`)."""
        stride = max(self.config.shape_stride, 1)
        return first + (self._pass_length(sequence, first) - 1) // stride * stride

    def _pass_frames(self, sequence: Sequence[Sequence[np.ndarray]],
                     results: list[FrameResult], progress: Callable[[], object] | None
                     ) -> list[FrameResult]:  # fmt: skip
        """The shape pass's frames after its start (`results`, one), tracked: `shape_frames`
        from the start, those after the last one refined not (they tell the shape nothing: 3
        of the default 24, about 0.8 s of a start), until one is lost. Returns the results."""
        first = results[0].frame
        length = self._pass_length(sequence, first)
        last = self._pass_last(sequence, first)
        for index in range(first + 1, last + 1):
            result = self.track(index, sequence[index])
            if progress is not None:
                progress()
            if result.pose is None:
                break
            results.append(result)
        else:  # the frames not needed are done too
            for _ in range(first + length - 1 - last) if progress is not None else ():
                progress()
        return results

    def _opinion_beside(self, sequence: Sequence[Sequence[np.ndarray]],
                        results: list[FrameResult], fresh: dict[str, Any],
                        ) -> tuple[int, Beside[tuple[FrameResult, dict[str, Any], int]]] | None:
        """The second opinion's start search (`_opinion_search`) at the frame the shape pass
        from `results` (its start) is to end on, beside this process (`Beside`, with a pool of
        its own: the search's starts side by side), or here, at once, with one worker: (that
        frame's index, the job). None: no second opinion there (`_has_opinion`)."""
        first = results[0].frame
        last = self._pass_last(sequence, first)
        if not self._has_opinion(sequence, first, last):
            return None
        return last, Beside(lambda: self._opinion_search(sequence, last, fresh),
                            workers_for(self.config.workers), pools=True)  # fmt: skip

    def _has_opinion(self, sequence: Sequence[Sequence[np.ndarray]], first: int,
                     last: int) -> bool:
        """Whether a shape pass from index `first` to `last` of `sequence` gets a second
        opinion: not with `back_xor_factor` 0, for a pass of one frame, or where `sequence`
        has fewer frames from `last` than the pass had (a shape from fewer poses)."""
        return (self.config.back_xor_factor > 0 and last > first
                and len(sequence) - last >= self._pass_length(sequence, first))

    def _opinion_search(self, sequence: Sequence[Sequence[np.ndarray]], index: int,
                        fresh: dict[str, Any]) -> tuple[FrameResult, dict[str, Any], int]:
        """A start searched afresh (from the state `fresh`) at index `index` of `sequence`:
        its result, the state it left and its energy evaluations, the tracker as it was."""
        before, event = self.evaluations, self._start_event
        with self._state_kept():
            self._set_track_state(fresh)
            result = self.track(index, sequence[index])
            state = self._track_state()
        made, self.evaluations, self._start_event = self.evaluations - before, before, event
        return result, state, made

    def _second_opinion(self, sequence: Sequence[Sequence[np.ndarray]], frames: Sequence[int],
                        results: list[FrameResult], fresh: dict[str, Any],
                        opinion: tuple[int, Beside[tuple[FrameResult, dict[str, Any], int]]]
                        | None, event: str) -> FrameResult | None:  # fmt: skip
        """A start searched afresh (a shape of its own, from the state `fresh`) at the shape
        pass's last frame, against what the pass tracked there from its start (`results`; the
        start's event was `event`): when clearly lower (its XOR times `back_xor_factor` under
        the pass's), the pass started wrong and tracked on wrong (the suite's bend_pickup from
        clip frame 150: a start at 27% XOR, 103 mm off, 1.40 m for a 1.56 m subject, tracked
        at 26-35% XOR, 100-130 mm, and a shape of 1.45 m; a start at its frames 6-23 reaches
        13-19%, 30-34 mm, 1.50-1.55 m; session 46), and it runs again from there: returns that
        start's result, the state set as that start left it. None (the state as it was): the
        pass stands, or it has no opinion (`_has_opinion`). The search is `opinion`'s
        (`_opinion_beside`) where the pass ended on its frame, else (the pass lost the
        subject before it) it runs here."""
        last = results[-1]
        if opinion is not None and opinion[0] == last.frame:
            result, state, made = opinion[1].result()
        elif self._has_opinion(sequence, results[0].frame, last.frame):
            result, state, made = self._opinion_search(sequence, last.frame, fresh)
        else:
            return None
        self.evaluations += made
        if result.pose is None or self.config.back_xor_factor * result.xor_fraction \
                >= last.xor_fraction:
            return None
        self._set_track_state(state)
        start = frames[results[0].frame]
        self._start_event = _pass_moved(
            result.event, f"{frames[last.frame]} (XOR {result.xor_fraction:.1%})",
            f"the shape pass from frame {start} had reached XOR {last.xor_fraction:.1%} there "
            f"(its start: {event})")
        return result

    def _tracked_to_start(self, sequence: Sequence[Sequence[np.ndarray]],
                          frames: Sequence[int], first: int, x: np.ndarray
                          ) -> np.ndarray | None:  # fmt: skip
        """The shape pass's pose `x` of frame `first` (its start, past the first frame: see
        `calibrate_shape`) tracked back to frame 0 of `sequence` with the pass's shape, each
        frame under the absolute bar (backwards, a divergence ends it). Returns the pose of
        frame 0, or None where the track back ended before it; the frames it reached are the
        pass's poses of those frames (`_recover`), and `_start_event` says how it went."""
        self.history, self._lost_since, self._backwards = [x], None, True
        try:
            for index in range(first - 1, -1, -1):
                result = self.track(index, sequence[index])
                if result.pose is None or result.status != "tracked":
                    self._start_event += (f", not tracked back to frame {frames[0]} (frame "
                                          f"{frames[index]}: {result.event})")
                    return None
                if not result.unexplained:
                    self._shape_pass_poses[frames[index]] = result.pose.params
        finally:
            self._backwards = False
        self._start_event += f", tracked back to frame {frames[0]}"
        return result.pose.params

    def refine(self, masks: Sequence[np.ndarray], pose: Pose, *, passes: int = 2,
               shape: bool = False) -> Pose:  # fmt: skip
        """The best pose of one frame this body model reaches from `pose`, with no time in the
        loop: `passes` runs of the whole hierarchy with every limb's grid over its whole range
        (what the initialisation gives each start); with `shape`, the segment scales are fitted
        to this frame alone first (this sets the tracker's shape). A measure of the model
        rather than of the tracking: how far a tracked pose is from what the model can do."""
        if self.shape is None:
            raise ValueError("refine needs the subject's shape")
        x = pose.params.copy()
        if shape:
            x = self._refine_shape([masks], [pose])[0].params
        energy = self._energy(masks)
        for _ in range(passes):
            x = self._refine_all(energy, x, init=True)
        return Pose(in_limits(x))

    # -- tracking -------------------------------------------------------------------------
    def _energy(self, masks: Sequence[np.ndarray]) -> SilhouetteEnergy:
        assert self.model is not None
        return SilhouetteEnergy(self.model, self.cameras, masks, self.renderer,
                                levels=self.config.levels, known=self.known,
                                missed=self._frame_hull(masks)[2])  # fmt: skip

    def _prediction(self) -> tuple[np.ndarray, np.ndarray]:
        """Constant-velocity prediction and the per-parameter change of the last two frames
        (a whole turn's the shorter way round: the stored angles wrap at 180 degrees, and the
        prediction goes on past it)."""
        if len(self.history) >= 2:
            change = np.where(WHOLE_TURN, turn_difference(self.history[-1], self.history[-2]),
                              self.history[-1] - self.history[-2])
            return (np.clip(self.history[-1] + change, SEARCH_LOWER_LIMITS, SEARCH_UPPER_LIMITS),
                    np.abs(change))
        return self.history[-1].copy(), np.zeros(N_POSE_PARAMS)

    def _stage(self, energy: SilhouetteEnergy, x: np.ndarray, free: Sequence[int],
               steps: np.ndarray, level: int, evals: int | None = None) -> np.ndarray:  # fmt: skip
        stage = _StageEnergy(energy, x, free, level, self._prior)
        free = list(free)
        values = _simplex(stage, x[free], steps, SEARCH_LOWER_LIMITS[free],
                          SEARCH_UPPER_LIMITS[free],
                          evals or self.config.simplex_evals)  # fmt: skip
        self.evaluations += stage.evaluations
        return stage.params(values)

    def _limb(self, energy: SilhouetteEnergy, x: np.ndarray, limb: str, change: np.ndarray,
              level: int, wide: bool, cfg: TrackConfig | None = None) -> np.ndarray:  # fmt: skip
        params, ends, kind = _LIMBS[limb]
        cfg = cfg or self.config
        stage = _StageEnergy(energy, x, params, level, self._prior)
        half = limb_half_range(change[params], self.frame_interval_s, cfg, wide)
        # Grid over abduction, flexion and the hinge; the axial twist is left to the simplex,
        # but at initialisation, where nothing bounds the limb, `init_twists` twists too.
        grid_axes = [0, 1, 3]
        if wide:
            # At initialisation nothing bounds the limb yet: the whole range of each angle.
            axes = [np.linspace(LOWER_LIMITS[params[a]], UPPER_LIMITS[params[a]], cfg.init_grid)
                    for a in grid_axes]  # fmt: skip
            if cfg.init_twists > 1:
                # Interior samples of the twist's range (+-45 degrees for +-90). Sampled at the
                # start's twist alone, a bent forearm only turns within the simplex's reach:
                # the CMU squat's left forearm, held out at 28 degrees of flexion and 62 of
                # twist, is started folded on the chest at -3 (409 mm off, unflagged). Not
                # the default: on the Pose2Sim demo (real masks) with `init_starts` 3 the
                # start then grew the subject to 1.94 m in the shape pass (1.84 without),
                # median IoU 0.776 against 0.811 with neither (session 21). The twist prior
                # (`twist_weight`) also holds such an arm back: at 62 degrees it costs 4% of
                # the silhouette area.
                grid_axes = [0, 1, 3, 2]
                axes.append(np.linspace(LOWER_LIMITS[params[2]], UPPER_LIMITS[params[2]],
                                        cfg.init_twists + 2)[1:-1])
            mesh = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, len(grid_axes))
            samples = np.repeat(x[params][None], len(mesh), axis=0)
            samples[:, grid_axes] = mesh
        else:
            offsets = np.linspace(-1, 1, cfg.grid) if cfg.grid > 1 else np.zeros(1)
            mesh = np.stack(np.meshgrid(*[offsets] * 3, indexing="ij"), -1).reshape(-1, 3)
            samples = np.repeat(x[params][None], len(mesh), axis=0)
            samples[:, grid_axes] += mesh * half[grid_axes]
        samples = np.clip(samples, LOWER_LIMITS[params], UPPER_LIMITS[params])
        scored = [(stage(x[params]), 0, x[params])]
        valid = self._valid(np.array([stage.params(v) for v in samples]), ends, kind, energy,
                            level)  # fmt: skip
        for k, values in enumerate(samples, 1):
            if valid[k - 1]:
                scored.append((stage(values), k, values))
        scored.sort(key=lambda item: item[:2])
        steps = np.maximum(half / max(cfg.grid - 1, 1), np.deg2rad(3.0))
        # With `init_starts` > 1, the best few samples each start a simplex (at
        # initialisation): on the XOR's narrow basins the grid's best is often not the one
        # whose simplex ends lowest (the squat's forearm: 4th of the grid, 6012 XOR pixels
        # after its simplex against 7292). Not the default: the limbs are searched one after
        # another, and a lower XOR for one can be another's pixels (a clean synthetic walk's
        # start: the left wrist 233 mm off at 3.3% XOR, against 1.0% and 9 mm with 1 start).
        refined = [_simplex(stage, start, steps, LOWER_LIMITS[params], UPPER_LIMITS[params],
                            cfg.init_simplex_evals if wide else cfg.simplex_evals)
                   for _, _, start in scored[:cfg.init_starts if wide else 1]]  # fmt: skip
        values = refined[0] if len(refined) == 1 else min(refined, key=stage)
        if wide and kind == "arm" and abs(values[0]) > np.pi / 2 and values[1] < -np.pi / 2:
            # At initialisation, an arm raised past horizontal both sideways and forwards:
            # the ZXY box also holds the twin of these angles, a lowered arm (z - 180,
            # -180 - x) twisted by 180 degrees, which the twist limit clips. The two bend the
            # elbow opposite ways, and the track stays in the basin it starts in (the CMU
            # run's left arm, elbow bent backwards for the whole clip: 24.3 mm MPJPE, 14.0
            # with the twin): the twin, its twist clipped into range, is refined as well.
            # Not while tracking: there it cost the superquadric model 0.673 -> 0.635 median
            # IoU on the Pose2Sim demo's first 41 frames (neutral at initialisation).
            twin = np.clip(np.r_[zxy_twin(values[:3]), values[3]], LOWER_LIMITS[params],
                           UPPER_LIMITS[params])  # fmt: skip
            twin = _simplex(stage, twin, np.maximum(steps, np.deg2rad(15.0)),
                            LOWER_LIMITS[params], UPPER_LIMITS[params],
                            cfg.init_simplex_evals)  # fmt: skip
            if stage(twin) < stage(values):
                values = twin
        self.evaluations += stage.evaluations
        return stage.params(values)

    def _valid(self, xs: np.ndarray, ends: tuple[str, str], kind: str,
               energy: SilhouetteEnergy, level: int) -> np.ndarray:  # fmt: skip
        """Thesis 6.2.5's sample test, (N,) bool for the (N, P) poses `xs`: the limb's two end
        nodes lie inside the (dilated) silhouette in every view and away from the torso
        axis."""
        assert self.shape is not None
        nodes = [NODE_INDEX[n] for n in ("pelvis", "neck", *ends)]
        # (N, 4, 3): pelvis, neck and the two ends of each pose.
        world = np.array([forward_kinematics(Pose(x), self.shape)[nodes, :3, 3] for x in xs])
        world = world.reshape(len(xs), len(nodes), 3)
        pelvis, neck, points = world[:, 0], world[:, 1], world[:, 2:]
        axis = neck - pelvis
        axis /= np.maximum(np.linalg.norm(axis, axis=1), 1e-9)[:, None]
        clearance = (0.5 * self.shape.chest_half_width if kind == "arm"
                     else 0.3 * self.shape.hip_half_width)  # fmt: skip
        from_pelvis = points - pelvis[:, None]
        along = np.einsum("nkj,nj->nk", from_pelvis, axis)
        off_axis = from_pelvis - along[..., None] * axis[:, None]
        valid = (np.linalg.norm(off_axis, axis=2) >= clearance).all(axis=1)
        for cam, mask in zip(energy.cameras[level], self._dilated[level], strict=True):
            uv, depth = cam.project(points.reshape(-1, 3))
            col, row = np.floor(uv[:, 0]), np.floor(uv[:, 1])
            seen = np.isfinite(col) & np.isfinite(row) & (depth > 0)
            seen &= (col >= 0) & (col < cam.width) & (row >= 0) & (row < cam.height)
            inside = np.zeros(len(col), bool)
            inside[seen] = mask[row[seen].astype(int), col[seen].astype(int)]
            valid &= inside.reshape(len(xs), -1).all(axis=1)
        return valid

    def _prepare(self, energy: SilhouetteEnergy, x: np.ndarray | None = None,
                 init: bool = False) -> None:  # fmt: skip
        """The state a refinement of the frame of `energy` reads: the dilated silhouettes of
        the samples' test (`_valid`) and the priors (`_prior`: temporal, centred on the
        prediction `x` unless at initialisation, and the twists')."""
        import cv2

        cfg = self.config

        # Where a view cannot tell (unknown pixels), a joint counts as inside its silhouette.
        def inside(mask: np.ndarray, known: np.ndarray | None) -> np.ndarray:
            grown = cv2.dilate(mask.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
            return grown if known is None else grown | ~known

        self._dilated = [[inside(m, k) for m, k in zip(masks, known, strict=True)]
                         for masks, known in zip(energy.masks, energy.known, strict=True)]
        # Temporal prior (thesis: "prediction"): a deviation of one `prior_scale` from the
        # predicted pose costs `prior_weight` of the silhouette area, in XOR pixels.
        area = _known_area(energy.masks[0], energy.known[0])
        # The deviation the prior tolerates grows with the time between frames.
        scale = self.frame_interval_s * np.where(np.arange(N_POSE_PARAMS) < 3,
                                                 cfg.prior_scale_m_s,
                                                 np.deg2rad(cfg.prior_scale_deg_s))
        if init or x is None:
            centre, weight = np.zeros(N_POSE_PARAMS), np.zeros(N_POSE_PARAMS)
        else:
            centre, weight = x.copy(), cfg.prior_weight * area / scale**2
        # A limb's axial twist barely changes its silhouette (limbs are nearly round), so
        # without a pull it drifts and other joints compensate: pull twists weakly to 0.
        twist = cfg.twist_weight * area / np.deg2rad(cfg.twist_scale_deg) ** 2
        total = weight[_TWISTS] + twist
        # Without the temporal prior and with --twist-weight 0 nothing pulls: no 0/0.
        centre[_TWISTS] = np.divide(weight[_TWISTS] * centre[_TWISTS], total,
                                    out=centre[_TWISTS].copy(), where=total > 0)
        weight[_TWISTS] = weight[_TWISTS] + twist
        self._prior = (centre, weight)

    def _refine_all(self, energy: SilhouetteEnergy, x: np.ndarray, init: bool = False,
                    change: np.ndarray | None = None) -> np.ndarray:  # fmt: skip
        """Root, trunk, limbs, root again: the hierarchy of thesis 6.2.5."""
        cfg = self.config
        x = self._held_at_zero(x)
        self._prepare(energy, x, init)
        coarse = min(cfg.levels - 1, cfg.search_level + 1)
        if init or change is None:
            change = np.zeros(N_POSE_PARAMS)
            root_steps = np.array([0.05, 0.05, 0.05, 0.08, 0.08, 0.15])
        else:
            # The simplex starts as large as the last frame-to-frame change, within limits.
            low, high = (self.frame_interval_s * v for v in _ROOT_STEP_PER_S)
            root_steps = np.clip(1.5 * change[_ROOT], low, high)
        evals = cfg.init_simplex_evals if init else cfg.simplex_evals
        start = None
        if cfg.contour_iterations:
            # The outlines first: from a close start they reach the optimum on their own; the
            # hierarchy's grids then look for larger motions, and the better of the two wins
            # (the coarse levels of the hierarchy can leave a fine optimum).
            x = self._contour(energy, x, cfg.contour_level)
            start = x.copy()
        for level in sorted({coarse, cfg.search_level}, reverse=True):
            x = self._stage(energy, x, _ROOT, root_steps, level, evals)
            root_steps = root_steps / 2
        trunk = np.isin(_TRUNK, self._free())
        x = self._stage(energy, x, np.array(_TRUNK)[trunk], _TRUNK_STEPS[trunk],
                        cfg.search_level, evals)
        for limb in _LIMBS:
            x = self._limb(energy, x, limb, change, cfg.search_level, wide=init)
        x = self._stage(energy, x, _ROOT, root_steps / 2, cfg.final_level, evals)
        if start is not None:
            x = self._contour(energy, x, cfg.contour_level)
            if self._objective(energy, start, cfg.final_level) < self._objective(
                    energy, x, cfg.final_level):
                x = start
        return x

    def _objective(self, energy: SilhouetteEnergy, x: np.ndarray, level: int) -> float:
        """The XOR energy at `level` plus the temporal and twist priors."""
        centre, weight = self._prior
        return energy(Pose(x), level) + float(np.sum(weight * (x - centre) ** 2))

    def _contour(self, energy: SilhouetteEnergy, x: np.ndarray, level: int) -> np.ndarray:
        """All parameters at once against the silhouette outlines (`tracking.track.contour`), steps
        accepted only when the XOR energy plus the temporal prior goes down."""
        # One refiner per frame and level: its image outlines and distance fields are the
        # frame's, whichever pose it refines (twice a frame: before and after the hierarchy).
        if self._refiner is None or self._refiner[0] is not energy or self._refiner[1] != level:
            self._refiner = (energy, level, ContourRefiner(
                energy.model, energy.cameras[level], energy.masks[level], energy.renderer,
                ContourConfig(iterations=self.config.contour_iterations),
                known=energy.known[level]))
        refiner = self._refiner[2]
        x, _, evaluations = refiner.refine(x, self._free(),
                                           lambda y: self._objective(energy, y, level))
        self.evaluations += evaluations
        return x

    def track(self, frame: int, masks: Sequence[np.ndarray], init: Pose | None = None
              ) -> FrameResult:  # fmt: skip
        """Track one frame; masks: one (H, W) bool silhouette per camera. The result names
        the cameras whose silhouette touches the image border (`FrameResult.cut_by`)."""
        result = self._track(frame, masks, init)
        cut = tuple(self.cameras[k].name for k in cut_by_border(masks))
        if cut:
            result = dataclasses.replace(result, cut_by=cut)
        limit = self.config.max_unexplained_share
        if result.pose is not None and limit > 0 and not self._starting:
            share = self.unexplained_share(masks, result.pose)
            result = dataclasses.replace(result, unexplained_share=share,
                                         unexplained=share > limit)
            words = self.watch.bar_words() if self.watch.diverged is not None else ""
            back = (self.watch.returned(result.xor_fraction) if result.status == "tracked"
                    and not result.unexplained and not self._backwards else None)
            if back is not None:
                # The track found again after a divergence the start search found nothing
                # better for: back to this subject's usual XOR, and the hull explained.
                event = (f"recovered: XOR {result.xor_fraction:.1%} of the silhouette, back "
                         f"under {back[1]:.1%} ({words}), with the visual hull explained")
                result = dataclasses.replace(
                    result, status="recovered",
                    event=_events(event, result.event))
        return result

    def track_back(self, results: Sequence[FrameResult],
                   masks_of: Callable[[int], Sequence[np.ndarray]]) -> dict[int, FrameResult]:
        """The opening of a track tracked again backwards: `results` (a sequence's, in frame
        order; `masks_of`: a frame's silhouettes), from the frame of lowest XOR among its first
        `shape_frames` (while each has a pose and is "init" or "tracked") back to the first,
        when the first's XOR is over `back_xor_factor` times that. A start that went wrong
        and that the track found its way out of (the limbs' search, the mend) is then found
        from the frames after it. The backward track replaces the forward one where it is
        clearly lower (`_tracked_back`). Returns the replacing results by index into
        `results` (the first keeps its status and says it was tracked back).

        Measured (`tracking_suite.py --start 150`, session 40): boxing's start held both arms
        in a guard in front of the chest, 220-390 mm off at XOR 17.7%, and the track found
        them at frame 6; its shape pass tracked back from frame 20, and its first 6 frames
        went from 92-104 mm to 6-12 (the clip 21.3 -> 5.9 mm)."""
        factor = self.config.back_xor_factor
        first = next((i for i, r in enumerate(results) if r.pose is not None), None)
        if factor <= 0 or first is None:
            return {}
        opening = []
        for i in range(first, min(first + self.back_frames, len(results))):
            if results[i].pose is None or results[i].status not in ("init", "tracked"):
                break
            opening.append(i)
        if not opening:  # a start over the absolute bar: "diverged" (`track_back_gap`)
            return {}
        xor = [results[i].xor_fraction for i in opening]
        anchor = opening[int(np.argmin(xor))]
        if anchor == first or xor[0] <= factor * min(xor):
            return {}
        switch, replaced = self._tracked_back(results, masks_of, first, anchor)
        origin = f"frame {results[anchor].frame}"
        if replaced and switch > first:  # the two tracks meet here: say so
            replaced[switch] = dataclasses.replace(replaced[switch], event=_events(
                f"the track back from {origin} starts here", replaced[switch].event))
        if first in replaced:
            start = results[first]
            replaced[first] = dataclasses.replace(
                replaced[first], status=start.status,
                event=_events(start.event, f"tracked back from {origin}", replaced[first].event))
        return replaced

    def track_back_gap(self, results: Sequence[FrameResult],
                       masks_of: Callable[[int], Sequence[np.ndarray]]
                       ) -> dict[int, FrameResult]:  # fmt: skip
        """The frames before a recovery (the last of `results`) tracked again backwards from
        it (`_gap`): those of the divergence or loss it recovered from (the forward track held
        them wrong, or had no pose for them), then on while lower (the track slid before it
        diverged: the watch's high bar is for several frames in a row, and a divergence the
        search recovers from at once has no diverged frame), within `back_frames`. Replaced as
        in `track_back` (`_tracked_back`: the lowest summed energies, a frame without a pose
        counting infinite; clearly lower by `_BACK_GAIN`). The first frame replaced is then
        "recovered", by the track back, or "tracked" where the forward track was not yet
        diverged or lost; the last of `results` keeps its own status. Returns the replacing
        results by index into `results`, as `track_back`; nothing when off (`back_xor_factor`
        0) or when the recovered pose leaves a part of the visual hull out (a limb likely
        misplaced: the suite's cartwheel recovered from the hull at frame 27 at 50 mm, and
        its frames 23-26 tracked back from there went from 24-46 to 41-43 mm at a lower
        XOR)."""
        anchor = len(results) - 1
        if (self.config.back_xor_factor <= 0 or anchor < 1 or results[anchor].pose is None
                or results[anchor].status != "recovered" or results[anchor].unexplained):
            return {}  # (a recovered pose that leaves a part of the hull out: not trusted)
        reach, first = self._gap(results[:anchor])
        needed = anchor if first is None else max(first, reach)
        switch, replaced = self._tracked_back(results, masks_of, needed, anchor, reach)
        if replaced:
            what = f"the track back from frame {results[anchor].frame}" + (
                "" if first is None else
                f" over the {results[first].status} frames from {results[first].frame}")
            replaced[switch] = dataclasses.replace(
                replaced[switch], status="recovered" if switch >= needed else "tracked",
                event=_events(f"recovered by {what}" if switch >= needed else
                              f"{what} starts here", replaced[switch].event))
        return replaced

    @property
    def back_frames(self) -> int:
        """The frames a track back spans (`track_back`, `track_back_gap`), the one it starts
        from included: `mocap track` holds the last this many frames' silhouettes, and records
        them once no track back can replace them."""
        return max(self.config.shape_frames, 1)

    def _gap(self, results: Sequence[FrameResult]) -> tuple[int, int | None]:
        """What a recovery in the frame after `results` tracks back over: the index of the first
        frame after the last start or recovery (or absent or two-subjects frame, which no track
        reaches), within `back_frames` of the recovery, and that of the first "diverged" or
        "lost" frame since (None: none)."""
        start, first = len(results), None
        for i in range(len(results) - 1, -1, -1):
            status = results[i].status
            if status in ("init", "recovered", "absent", "two-subjects"):
                break
            start = i
            if status in ("diverged", "lost"):
                first = i
        return max(start, len(results) + 1 - self.back_frames), first

    def _tracked_back(self, results: Sequence[FrameResult],
                      masks_of: Callable[[int], Sequence[np.ndarray]], first: int, anchor: int,
                      before: int | None = None) -> tuple[int, dict[int, FrameResult]]:
        """`results`' frames from `anchor` - 1 back to `first` tracked again, backwards, from the
        anchor's pose (the prediction runs from the frame after it, when there is one, then the
        anchor), while each is "tracked" (under the absolute bar: backwards, a divergence ends it,
        no search) and leaves no part of the visual hull out where the forward one did not
        (`FrameResult.unexplained`); then on to `before` (<= `first`) while each is lower than the
        forward one (once it is not, the two tracks have met). The backward track replaces the
        forward one from the frame where the two's summed energies are lowest (one switch: both are
        continuous; a frame without a pose counts infinite) to the anchor, where its XOR there is
        clearly lower (`_BACK_GAIN`). Returns the switch and the replacing results by index (none:
        the forward track stays). What tracking a frame changes of the tracker is as before after it
        (`_state_kept`): the track goes on from its last frame."""

        def forward(i: int) -> float:
            return results[i].energy if results[i].pose is not None else np.inf

        back: dict[int, FrameResult] = {}
        with self._state_kept():
            self.history = [results[i].pose.params.copy() for i in (anchor + 1, anchor)
                            if i < len(results) and results[i].pose is not None]
            self._lost_since, self._backwards = None, True
            for i in range(anchor - 1, (first if before is None else before) - 1, -1):
                result = self.track(results[i].frame, masks_of(results[i].frame))
                if (result.pose is None or result.status != "tracked"
                        or (result.unexplained and not results[i].unexplained)
                        or (i < first and result.energy >= forward(i))):  # fmt: skip
                    break
                back[i] = result
        if not back:
            return anchor, {}
        # Backwards from `switch` to the anchor, forwards before it: the lowest sum.
        energies = {s: sum(forward(i) for i in range(min(back), s))
                    + sum(back[i].energy for i in range(s, anchor))
                    for s in range(min(back), anchor + 1)}  # fmt: skip
        switch = min(energies, key=energies.__getitem__)
        ahead = sum(forward(i) for i in range(switch, anchor))
        behind = sum(back[i].energy for i in range(switch, anchor))
        if switch == anchor or behind > (1 - _BACK_GAIN) * ahead:
            return anchor, {}  # not clearly lower: the forward track stays
        return switch, {i: dataclasses.replace(back[i], seconds=results[i].seconds,
                                               evaluations=results[i].evaluations)
                        for i in range(switch, anchor)}  # fmt: skip

    _TRACK_STATE = ("history", "watch", "_last_good", "_lost_since", "_gap_statuses",
                    "_tracked_any", "_xor_floor", "_mend_failed_at", "_backwards")
    """What tracking a frame changes of the tracker (the prediction's history, the divergence
    watch, the last good pose, the lost frames, the mend's back-off); a start also sets the
    model."""

    def _track_state(self) -> dict[str, Any]:
        """A copy of `_TRACK_STATE` and the model (`_set_track_state` puts it back)."""
        import copy

        return {"model": self.model,  # (replaced by a start or a shape refinement, not changed)
                **{name: copy.deepcopy(getattr(self, name)) for name in self._TRACK_STATE}}

    def _set_track_state(self, state: dict[str, Any]) -> None:
        """The tracker's state as `_track_state` copied it."""
        import copy

        for name, value in state.items():
            setattr(self, name, value if name == "model" else copy.deepcopy(value))

    @contextmanager
    def _state_kept(self) -> Iterator[None]:
        """The tracker's state (`_track_state`) as it was before: `track_back` tracks frames
        again without changing the track that follows."""
        saved = self._track_state()
        try:
            yield
        finally:
            self._set_track_state(saved)

    def unexplained_share(self, masks: Sequence[np.ndarray], pose: Pose) -> float:
        """The share of this frame's visual hull that `pose` leaves out
        (`tracking.track.unexplained.unexplained_hull_part`, at `TrackConfig.unexplained_m`; 0
        when the silhouettes have no hull)."""
        return self.unexplained_part(masks, pose)[0]

    def unexplained_part(self, masks: Sequence[np.ndarray], pose: Pose
                         ) -> tuple[float, np.ndarray]:  # fmt: skip
        """`unexplained_share` and the points of that part of the hull (M, 3). The frame's
        hull is carved once for all the poses checked on the same masks (a mend checks up to
        four), and the last answer is kept for the same masks and pose."""
        from tracking.track.unexplained import unexplained_hull_part

        assert self.model is not None
        key = pose.params.tobytes()
        if self._part is not None and self._part[0] is masks and self._part[1] == key:
            return self._part[2]
        points, up, _ = self._frame_hull(masks)
        if not len(points):
            return 0.0, np.empty((0, 3))
        up = np.array([0.0, 1.0, 0.0]) if up is None else up
        vertices = self.model.posed_vertices(pose)
        model_masks = render_views(self.renderer, vertices, self.model.faces, self.cameras)
        part = unexplained_hull_part(
            self.model, pose, self.cameras, masks, points, model_masks, up, known=self.known,
            vertices=vertices, distance_m=self.config.unexplained_m,
            opening_m=self.config.voxel_m)
        self._part = (masks, key, part)
        return part

    def _frame_hull(self, masks: Sequence[np.ndarray]
                    ) -> tuple[np.ndarray, np.ndarray | None, list[np.ndarray] | None]:  # fmt: skip
        """(points (N, 3), up (3,), band) of the frame of `masks`: its visual hull's surface
        voxels (none when a silhouette is empty), the rig's up there (`rig_up`; None when the
        rig cannot tell, and the band then measured along +Y), and per view the pixels
        of the hull's lowest band alone (`lowest_band_pixels`, `TrackConfig.floor_band_m`;
        None when off), which its XOR counts as missed whatever the pose. Carved once for the
        masks held."""
        if self._hull is None or self._hull[0] is not masks:
            try:
                points = self.visual_hull_points(masks)
            except TrackingLost:  # an empty silhouette: nothing to check against
                points = np.empty((0, 3))
            up = rig_up(self.cameras, points.mean(axis=0)) if len(points) else None
            band = None
            if self.config.floor_band_m > 0 and len(points):
                band = lowest_band_pixels(self.cameras, masks, points,
                                          np.array([0.0, 1.0, 0.0]) if up is None else up,
                                          band_m=self.config.floor_band_m,
                                          voxel_m=self.config.voxel_m)  # fmt: skip
            # The masks held: their id is not reused while they are the key.
            self._hull = (masks, points, up, band)
        return self._hull[1], self._hull[2], self._hull[3]

    def _mend_unexplained(self, energy: SilhouetteEnergy, masks: Sequence[np.ndarray],
                          x: np.ndarray, frame: int = 0) -> tuple[np.ndarray, str]:  # fmt: skip
        """x, or when its hull has a part the body leaves out (`unexplained_part`), the pose
        with one of the two limbs whose root (shoulder, hip) is nearest that part searched
        over its whole range, as at a start (`MEND_STARTS` starts and twists), without the
        twist prior on that limb: the one of lowest XOR, when its XOR is lower than x's and
        it leaves a smaller part out; and what was done, for the frame's event. The hull is
        the evidence the twist prior lacks: the CMU squat's left forearm, held out and turned
        (62 degrees), costs 2.5% of the silhouette area in that prior at the twist found, more
        than the XOR it explains (7254 -> 6309 pixels; the part 3.6% -> 0% of the hull).
        After a search that found nothing, none for `MEND_BACKOFF_FRAMES` frames (`frame`:
        this one's number): a part the model cannot explain stays, and each search costs
        about 2 s."""
        cfg = self.config
        share, part = self.unexplained_part(masks, Pose(x))
        if share <= cfg.max_unexplained_share or not cfg.mend_unexplained or not len(part):
            return x, ""
        if (self._mend_failed_at is not None
                and abs(frame - self._mend_failed_at) < MEND_BACKOFF_FRAMES):  # (`track_back`)
            return x, ""
        joints = self.model.joints(Pose(x))
        centre = part.mean(axis=0)

        def root_of(limb: str) -> np.ndarray:
            side, kind = limb.split("_")
            return joints[NODE_NAMES.index(f"{side}_{'shoulder' if kind == 'arm' else 'hip'}")]

        nearest = sorted(_LIMBS, key=lambda limb: float(np.linalg.norm(root_of(limb) - centre)))
        wide = dataclasses.replace(cfg, init_starts=MEND_STARTS, init_twists=MEND_STARTS)
        prior = self._prior
        best, best_xor, found = x, energy(Pose(x), cfg.final_level), ""
        start_xor = best_xor
        limbs = nearest[:2]

        def search(index: int) -> tuple[np.ndarray, float, float]:
            """The pose with limbs[index] searched, its XOR and its hull's unexplained
            share."""
            weight = prior[1].copy()
            weight[_LIMBS[limbs[index]][0][2]] = 0.0  # the limb's axial twist
            self._prior = (prior[0], weight)
            try:
                y = self._limb(energy, x, limbs[index], np.zeros(N_POSE_PARAMS),
                               cfg.search_level, wide=True, cfg=wide)  # fmt: skip
            finally:
                self._prior = prior
            return (y, energy(Pose(y), cfg.final_level),
                    self.unexplained_part(masks, Pose(y))[0])  # fmt: skip

        # Both limbs from x, independent of each other: side by side, the same results.
        for limb, (y, xor, left_out) in zip(
                limbs, self._side_by_side(search, len(limbs)), strict=True):
            if xor < best_xor and left_out < share:
                best, best_xor, found = y, xor, limb
        if not found:
            self._mend_failed_at = frame
            return x, ""
        self._mend_failed_at = None
        return best, (f"{found.replace('_', ' ')} searched again where the visual hull shows "
                      f"a part the body left out ({share:.1%} of the hull; XOR "
                      f"{start_xor:.0f} -> {best_xor:.0f} px at level {cfg.final_level})")

    def _track(self, frame: int, masks: Sequence[np.ndarray], init: Pose | None
               ) -> FrameResult:  # fmt: skip
        """`track` without the border flags."""
        start = time.perf_counter()
        self.evaluations = 0
        area = _known_area([np.asarray(m, bool) for m in masks], self.known)
        empty = [c.name for c, m in zip(self.cameras, masks, strict=True) if not m.any()]
        if len(empty) == len(masks):
            # Nobody in view: the subject left (issue 20). No search; the first frame with
            # silhouettes again starts afresh from the visual hull (and is "recovered").
            return self._lost(frame, float("nan"), area, start, "no silhouette in any camera "
                              "(the subject is out of view)", status="absent")
        # Foreground in every pixel: the background model failed, and the silhouette has no
        # outline to fit (its distance field is infinite).
        full = [c.name for c, m in zip(self.cameras, masks, strict=True) if m.all()]
        all_unknown = area == 0 and len(empty) < len(masks)
        if empty or full or all_unknown:
            self.history = []
            unknown = ("every silhouette pixel is unknown (its background is: see the "
                       "warnings of mocap silhouettes)")
            why = "; ".join([*([f"empty silhouette in {', '.join(empty)}"] if empty else []),
                             *([f"every pixel foreground in {', '.join(full)}"] if full else []),
                             *([unknown] if all_unknown else [])])
            return self._lost(frame, float("nan"), area, start, why)
        event, still = "", False
        try:
            if not self.history and init is None and self._lost_since is not None \
                    and self._last_good is not None:
                # After lost frames the start search runs from the last good pose as well as
                # from the visual hull, whose upright starts and fit cannot reach every pose.
                energy = self._energy(masks)
                x, _, found = self._recover(frame, masks, energy, None, np.inf)
                if x is None:  # no candidate: neither the last good pose nor the hull
                    raise TrackingLost("the start search found no pose")
                event = f"init from {found}"
            elif not self.history:
                pose, event = self.initialise(masks, init)
                if init is None and self._start_event and not self._starting:
                    # The shape pass's pose did not reach this frame (`calibrate_shape`).
                    event = f"{event}, with the shape of the shape pass: {self._start_event}"
                    self._start_event = ""
                x = pose.params
                energy = self._energy(masks)  # the model exists (and is fixed) from here on
            else:
                energy = self._energy(masks)
                predicted, change = self._prediction()
                x = self._refine_all(energy, predicted, change=change)
                for _ in range(self.config.passes - 1):
                    # Another pass from the result, with the ranges of a small change.
                    x = self._refine_all(energy, x, change=np.abs(x - predicted) / 2)
            mended = ""
            if self.config.max_unexplained_share > 0 and not self._starting:
                x, mended = self._mend_unexplained(energy, masks, x, frame)
            e = energy(Pose(x))
            if event and e > self.config.max_xor_fraction * area:
                self._one_subject(masks)  # a given start, and a second subject beside it
            if event:
                # What the silhouettes allow: real masks have holes and ghosts, so the first
                # frame's XOR sets the bar (at least `max_xor_fraction`) for the divergence test.
                # The lowest such bar so far: a re-initialisation that starts worse must not
                # raise it, or a drifting track would never count as diverged again.
                self._xor_floor = min(self._xor_floor, e / area)
            limit = max(self.config.max_xor_fraction, 1.5 * self._xor_floor) * area
            status, why = ("init" if event else "tracked"), ""
            if event and self._lost_since is not None and e > limit:
                # A new start after frames without a pose, over the bar an earlier start set:
                # not "recovered" (a subject back in only some views, a second one out of
                # the others' view).
                return self._lost(frame, e, area, start, f"the start search after frames "
                                  f"{self._lost_since}-{frame - 1} found nothing under the "
                                  f"absolute bar {limit / area:.0%} (XOR {e / area:.1%})")
            absolute = self.config.max_xor_fraction
            start_over_bar = (bool(event) and self._lost_since is None and not self._starting
                              and not self._backwards and e > absolute * area)  # fmt: skip
            if start_over_bar:
                # A start over the absolute bar: the search found no pose the silhouettes
                # allow, and its XOR must not set this subject's reference (the frame-150
                # cartwheels of the suite started at 35-47% XOR, 200-330 mm off, and with the
                # bar at 1.5 times that were tracked so; session 45). Not trusted: "diverged",
                # and the search runs again every few frames while over the bar (then
                # "recovered", and the frames before it tracked back from there).
                status = "diverged"
                event = (f"diverged: {event}, XOR {e / area:.1%} of the silhouette, over the "
                         f"absolute bar {absolute:.0%}: its pose is kept, not trusted, and the "
                         f"start search runs again every {_SEARCH_AGAIN_FRAMES} frames while "
                         "over it")
            if not event:
                if e > limit:
                    why = (f"XOR {e / area:.1%} of the silhouette, over the absolute bar "
                           f"{limit / area:.0%}")
                elif not self._starting and not self._backwards:
                    # The shape pass's model is not the subject's yet; a track backwards
                    # has no recent frames of its own.
                    why = self.watch.verdict(e / area)
            if why and self._backwards:
                # Backwards (`_tracked_back`), a divergence ends the track back: no search.
                status, event = "diverged", f"diverged: {why}"
            elif why:
                # A second subject makes a divergence (its silhouettes are unexplained): say
                # so, and track no merged blob. Else the start search again, from the last
                # good pose and the hull.
                self._one_subject(masks)

                def settled(e_y: float) -> bool:
                    """A pose of this energy is no divergence (under both bars)."""
                    return e_y <= limit and not self.watch.verdict(e_y / area)

                x, e, found = self._recover(frame, masks, energy, x, e, enough=settled)
                if e > limit:
                    return self._lost(frame, e, area, start, f"{why}; the start search found "
                                      f"nothing under it (XOR {e / area:.1%})")
                # Recovered when the search found a pose that is no divergence (a recovered
                # frame between the high and spike bars counts towards a slide).
                if found is None or not settled(e):
                    status = "diverged"
                    # A pose the search found can be better and still a divergence: say which.
                    searched = ("found nothing better" if found is None else
                                f"found {found}, still a divergence")
                    event = (f"diverged: {why}; the start search {searched} "
                             f"(XOR {e / area:.1%}): its best pose is kept, and its XOR is "
                             "this subject's reference from here")
                else:
                    status = "recovered"
                    event = f"recovered from {found} (XOR {e / area:.1%}): {why}"
            elif (not event and not self._starting and not self._backwards
                  and self.watch.diverged is not None
                  and (frame - self.watch.diverged[0]) % _SEARCH_AGAIN_FRAMES == 0
                  and e > self.watch.diverged[1] * area):
                # Still over the bar of before a divergence the search found nothing better
                # for: the search again, every few frames, until the track is back.
                since, bar = self.watch.diverged
                y, e_y, found = self._recover(frame, masks, energy, x, e,
                                              enough=lambda value: value <= bar * area)
                if found is not None:
                    x, e = y, e_y
                    if e <= bar * area:
                        status = "recovered"
                        event = (f"recovered from {found} (XOR {e / area:.1%}), searched again "
                                 f"{frame - since} frames after the divergence at frame "
                                 f"{since}: back under {bar:.1%}")
                    else:
                        event = (f"searched again {frame - since} frames after the divergence "
                                 f"at frame {since}: {found} lowered the XOR to {e / area:.1%},"
                                 f" still over {bar:.1%}")
            if (status == "tracked" and not self._starting and not self._backwards
                    and self.watch.diverged is not None
                    and e > self.watch.diverged[1] * area):  # fmt: skip
                # Still over the bar of before a divergence the search found nothing better
                # for: the track is not back, whatever the reference the divergence set says.
                # (Tracked, such a frame was trusted: the superquadric walk of
                # test_the_start_search_recovers_a_track_that_jumped diverged at frame 6 with a
                # pose 504 mm off at 11.9% XOR, and frame 7 was "tracked" at 502 mm, 13.3%.)
                bar = self.watch.diverged[1]
                status, still = "diverged", True
                event = _events(f"diverged: XOR {e / area:.1%} of the silhouette, still over "
                                f"{bar:.1%} ({self.watch.bar_words()})", event)
            elif status == "init" and self._lost_since is not None:
                status = "recovered"
                gap = " or ".join(_GAP_WORDS[s] for s in sorted(self._gap_statuses))
                event = (f"recovered after frames {self._lost_since}-{frame - 1} were {gap}: "
                         f"{event}")
        except TrackingLost as exc:
            return self._lost(frame, float("nan"), area, start, str(exc), status=exc.status)
        x = in_limits(x)  # a whole turn's angle back in -180..180 (the same pose)
        if status == "diverged" and not still:
            # The level the model now reaches: the reference from here (`XorWatch.diverge`).
            self.watch.diverge(frame, e / area,
                               self.config.max_xor_fraction if start_over_bar else None)
        elif status == "init" or self._lost_since is not None:
            self.watch.restart(e / area)  # a new start
        else:
            self.watch.accept(e / area)
            if status == "recovered":
                self.watch.diverged = None  # found again: no divergence before it is open
        if status != "diverged" and self.watch.streak == 0:
            self._last_good = (frame, x.copy())
        self._lost_since, self._gap_statuses, self._tracked_any = None, set(), True
        self.history = [*self.history[-1:], x]
        event = _events(event, mended)
        return FrameResult(frame, Pose(x), e, area, self.evaluations,
                           time.perf_counter() - start, event, status)  # fmt: skip

    def _lost(self, frame: int, energy: float, area: float, start: float, why: str,
              status: str = "lost") -> FrameResult:  # fmt: skip
        """A frame without a pose (`status` "lost", "absent" or "two-subjects"); the next frame
        starts afresh (and is "recovered")."""
        self.history = []
        if self._lost_since is None and self._tracked_any:
            # (Frames before the first start are no gap: that start is "init".)
            self._lost_since = frame
        self._gap_statuses.add(status)
        if np.isfinite(energy) and "XOR" not in why:
            why = f"XOR {energy / area:.0%} of the silhouette area; {why}"
        return FrameResult(frame, None, energy, area, self.evaluations,
                           time.perf_counter() - start, f"{status}: {why}", status)  # fmt: skip

    def _recover(self, frame: int, masks: Sequence[np.ndarray], energy: SilhouetteEnergy,
                 x: np.ndarray | None, e: float,
                 enough: Callable[[float], bool] | None = None,
                 ) -> tuple[np.ndarray | None, float, str | None]:  # fmt: skip
        """After a divergence or lost frames at `frame`, the start search again: from the last
        good pose (and its left/right swaps) with the limbs' grids over their whole range, then
        from the pose the shape pass gave this frame (alike), then from the visual hull
        (`initialise`). Returns the candidate of lowest XOR, the tracked pose `x` (energy `e`;
        None and inf after lost frames) included, its energy, and where it came from (None:
        `x`). Cheapest first: once a candidate is `enough` (its energy no divergence), the
        next ones do not run; the hull's search is 8 of a recovery's 9 s on the suite's
        cartwheel.

        The shape pass tracks the first frames before the track proper tracks them again with
        the shape it found, and a divergence there is often one the pass met too: its search
        ran then, and its pose, refined with the subject's shape, spares running it again
        (the turn_pirouette from clip frame 150 met its divergence at frame 5 in both: 8 s
        each, session 42)."""
        history = self.history
        best_x, best_e, found = x, e, None

        def consider(name: str, y: np.ndarray) -> None:
            nonlocal best_x, best_e, found
            e_y = energy(Pose(y))
            if e_y < best_e:
                best_x, best_e, found = y, e_y, name

        def settled() -> bool:
            """A candidate no divergence is found: the dearer ones do not run."""
            return found is not None and enough is not None and enough(best_e)

        poses = [] if self._last_good is None else [
            (f"the last good pose (frame {self._last_good[0]})", self._last_good[1])]
        if frame in self._shape_pass_poses:
            poses.append(("the shape pass's pose", self._shape_pass_poses[frame]))
        for name, pose in poses:  # each with its left/right swaps, limbs over their range
            if not settled():
                seed = self._best_hypothesis(energy, pose).params
                consider(name, self._refine_all(energy, seed, init=True))
        if not settled():
            with suppress(TrackingLost):  # no visual hull: the last good pose's alone
                consider("the visual hull", self.initialise(masks, enough=enough)[0].params)
        # A recovered pose has no velocity; the tracked one keeps its own.
        self.history = history if found is None else []
        return best_x, best_e, found


def _pass_moved(event: str, frame: str, why: str) -> str:
    """The start event of a shape pass that runs from a later frame than the first (`frame`,
    with what it adds), and `why` (`calibrate_shape`)."""
    return f"{event} at frame {frame}; segment lengths from the frames from there: {why}"


def _events(*parts: str) -> str:
    """A frame's event of several parts, the empty ones left out."""
    return "; ".join(part for part in parts if part)


_BACK_GAIN = 0.1
"""A track back (`SilhouetteTracker._tracked_back`) replaces the forward track only where its XOR
summed over the frames it replaces is at least this fraction lower: two tracks of a right start
differ by the silhouettes' noise, and the shape pass would then take its lengths from poses no
better. Set on openings (`track_back`), on the suite's first 24 frames at seed 0 and from clip
frame 150 (27 clips, the shape pass and the track; session 40): where the start had gone wrong,
0.14-0.26 lower (the cartwheel, boxing, bend_pickup and squat from frame 150); elsewhere
0.00-0.06 (the walk's shape pass 0.017, and its shape from those poses cost it 7.8 -> 8.4 mm).
Kept for the frames before a recovery (`track_back_gap`, session 41) without tuning."""

_SEARCH_AGAIN_FRAMES = 3
"""After a divergence the start search found nothing better for, the frames between searches
again while the track stays over the bar of before it (`XorWatch.diverged`; those frames are
"diverged" too since session 43). The diverged frame's XOR is the reference, so the watch alone
never flags a track stuck there again: the suite's 60-frame
cartwheel diverged at frame 45 as it stood up (its search: 167 mm), and its next 14 frames
drifted to 99 mm at 26-31% XOR; the start search finds frames 50 and 59 at 13.6% and 12.4%
XOR, 26 and 14 mm (session 35)."""


UPRIGHT_TRUNK_DEG = 30.0
"""A hull fit whose trunk (pelvis to neck) is within this angle of up is of a subject upright:
its hull's extent along up is its height (`start_height`). Measured: 0-15 degrees at the first
frame of the 15 clips of the motion suite (30 and 60 frames: other cameras) but the
cartwheel, and 12 on the Pose2Sim demo; 48-49 on the cartwheel, which starts bent over."""


def start_height(fit: Pose, shape: BodyShape, points: np.ndarray, up: np.ndarray | None,
                 voxel_m: float) -> float:  # fmt: skip
    """The height of a start from the visual hull `points` (N, 3): the hull fit's (`fit`,
    `shape`), at most 1.05 times the subject's extent in the hull. A hull carved by few views
    is fatter than the body, and the fit grows the model to fill it (1.86-2.02 m for the
    ~1.75 m subject of the Pose2Sim demo, whose hull is 1.74 m tall). (Capping at the extent
    itself cost the synthetic walk 5 mm: the lengths' refinement then settled elsewhere.)

    The extent is along up when the fit is upright (`UPRIGHT_TRUNK_DEG`): a standing subject
    is hardly taller than its hull there. A subject bent over is far taller than that, and is
    capped at the hull's longest extent (`hull_diameter`): the suite's cartwheel starts so,
    its hull 1.23 m along up and 1.52 m long; capped at 1.29 m, the shape pass left a subject
    of 1.45 m (82.7 mm MPJPE over 60 frames). Not the longest extent for all: a running
    stride's is its diagonal, 1.61 m for 1.56 m along up, and the suite's run, started 5 cm
    taller, was tracked at 92 mm instead of 17 (session 29)."""
    height = shape.height
    if up is None:
        return height
    extent = float(np.ptp(points @ up)) if is_upright(fit, shape, up) else hull_diameter(points)
    return min(height, 1.05 * (extent + voxel_m))


def start_heights(fit: Pose, shape: BodyShape, points: np.ndarray, up: np.ndarray | None,
                  voxel_m: float) -> list[float]:  # fmt: skip
    """The heights the start is searched at (`SilhouetteTracker.initialise`; the lower XOR
    keeps its own): `start_height`, and for a subject upright its hull's extent along up
    plus a voxel when that is lower by more than a voxel (`voxel_m`: the hull cannot tell
    heights closer than that apart).

    The fit's height is the fat hull's: over the suite's 15 clips and 3 noise draws (first
    frames, one subject of 1.56 m) the start's height was 1.49-1.76 m, the extent plus a voxel
    1.53-1.68. Neither alone: at the extent the start of bend_pickup's seed 2 is 15 mm off
    instead of 53 (XOR 0.107 against 0.168), kick's 8 instead of 29 and turn_pirouette's 15
    instead of 44; but squat's seed 1 is 199 mm off instead of 82 (XOR 0.310 against 0.188)
    and start_walk_stop's seed 1 50 instead of 28 (session 37)."""
    height = start_height(fit, shape, points, up, voxel_m)
    if up is None or not is_upright(fit, shape, up):
        return [height]
    extent = float(np.ptp(points @ up)) + voxel_m
    return [height, extent] if extent < height - voxel_m else [height]


def is_upright(fit: Pose, shape: BodyShape, up: np.ndarray) -> bool:
    """Whether the trunk (pelvis to neck) of `fit` is within `UPRIGHT_TRUNK_DEG` of `up`."""
    nodes = forward_kinematics(fit, shape)[[NODE_INDEX["pelvis"], NODE_INDEX["neck"]], :3, 3]
    trunk = nodes[1] - nodes[0]
    cos_tilt = float(trunk @ up) / max(float(np.linalg.norm(trunk)), 1e-9)
    return cos_tilt >= np.cos(np.deg2rad(UPRIGHT_TRUNK_DEG))


def start_winner(others: Sequence[float], extremities: Sequence[float], lead: float) -> int:
    """Index (into others, then extremities) of the start that wins: the lowest score of
    `others` (the fit and the upright starts), unless the lowest of `extremities` (the starts
    from the hull's extremities) is under `lead` times it (`_EXTREMITY_LEAD`, or 1)."""
    best = int(np.argmin(others))
    if len(extremities):
        k = int(np.argmin(extremities))
        if extremities[k] < lead * others[best]:
            return len(others) + k
    return best


def subjects_in_view(cameras: Sequence[Camera], masks: Sequence[np.ndarray],
                     config: TrackConfig, unknown: Sequence[np.ndarray | None] | None = None,
                     ) -> list[HullPart]:  # fmt: skip
    """`SilhouetteTracker.subjects_in_view` for these cameras (any world frame)."""
    try:
        centre = rays_meeting_point(cameras, masks)
    except ValueError:  # fewer than two views with a silhouette
        return []
    return subject_sized(hull_parts(cameras, masks, size_m=2 * config.hull_size_m,
                                    voxel_m=2 * config.voxel_m, unknown=unknown,
                                    up=rig_up(cameras, centre),
                                    min_views=hull_min_views(masks)))  # fmt: skip


def limb_half_range(change: np.ndarray, frame_interval_s: float, config: TrackConfig,
                    wide: bool = False) -> np.ndarray:  # fmt: skip
    """Half-ranges (radians) of a limb's grid around the prediction: `range_gain` times the
    parameters' change between the two preceding frames (thesis 6.2.5), clipped to the
    angular speeds `min_range_deg_s`..`max_range_deg_s` times the frame interval (seconds),
    so that 25-60 fps need no tuning; `_WIDE_RANGE_DEG` when `wide` (no time in the loop)."""
    change = np.asarray(change, dtype=float)
    if wide:
        return np.full(change.shape, np.deg2rad(_WIDE_RANGE_DEG))
    return np.clip(config.range_gain * change,
                   np.deg2rad(config.min_range_deg_s * frame_interval_s),
                   np.deg2rad(config.max_range_deg_s * frame_interval_s))


def upright_starts(fit: Pose, up: np.ndarray | None, headings: int,
                   pelvis: np.ndarray | None = None) -> list[Pose]:  # fmt: skip
    """Standing poses with their pelvis at `pelvis` (default: `fit`'s), at `headings` headings
    evenly around `up` (None: `fit`'s own up) from `fit`'s, arms hanging a little away from
    the body."""
    rotation = root_rotation(fit)
    up = rotation[:, 1] if up is None else np.asarray(up, dtype=float)
    forward = rotation[:, 2] - (rotation[:, 2] @ up) * up
    if np.linalg.norm(forward) < 1e-6:  # the fit lies along `up`: any heading will do
        forward = np.linalg.svd(up[None])[2][-1]
    forward /= np.linalg.norm(forward)
    starts = []
    for k in range(headings):
        a = 2.0 * np.pi * k / headings
        heading = np.cos(a) * forward + np.sin(a) * np.cross(up, forward)
        x = np.zeros(N_POSE_PARAMS)
        x[:3] = fit.params[:3] if pelvis is None else pelvis
        x[3:6] = np.deg2rad(rotations_to_channels(
            np.stack([np.cross(up, heading), up, heading], axis=1), "ZXY"))
        for side, sign in (("l", 1.0), ("r", -1.0)):
            x[PARAM_INDEX[f"{side}_shoulder_rz"]] = np.deg2rad(10.0) * sign
            x[PARAM_INDEX[f"{side}_elbow_flex"]] = np.deg2rad(10.0)
        starts.append(Pose(in_limits(x)))
    return starts


_CROUCH_DEG = {"pitch": 30.0, "spine_flex": 60.0, "hip_rx": -100.0, "hip_rz": 20.0,
               "knee_flex": 115.0}
"""The crouched starts' stance (`crouched_starts`), degrees: the whole body pitched forward, the
chest bent forward, hips flexed and apart, knees bent deep. Taken from the suite's bend_pickup
at clip frame 150, a deep squat reaching for the floor (its pitch 33, chest 60, hips 99-117 and
30 apart, knees 113-119; session 39), where every other start ended 107 mm off or more.
Measured on the rest of the suite (``benchmarks/tracking_suite.py --trackers crouched``): the
seed-0 clips unchanged, the frame-150 cartwheel 54.9 -> 302 mm; hence `init_crouched` off."""


def crouched_starts(fit: Pose, up: np.ndarray, headings: int) -> list[Pose]:
    """`upright_starts` on `fit`'s pelvis at `headings` headings, crouched (`_CROUCH_DEG`):
    a body bent over, squatting or picking something up, which neither the fit nor a standing
    body reaches when the fit folds it wrong."""
    c = {name: np.deg2rad(value) for name, value in _CROUCH_DEG.items()}
    pitch = np.array([[1.0, 0.0, 0.0],
                      [0.0, np.cos(c["pitch"]), -np.sin(c["pitch"])],
                      [0.0, np.sin(c["pitch"]), np.cos(c["pitch"])]])  # fmt: skip
    starts = []
    for pose in upright_starts(fit, up, headings):
        x = pose.params.copy()
        x[3:6] = np.deg2rad(rotations_to_channels(root_rotation(pose) @ pitch, "ZXY"))
        x[PARAM_INDEX["spine_flex"]] = c["spine_flex"]
        for side, sign in (("l", 1.0), ("r", -1.0)):
            x[PARAM_INDEX[f"{side}_hip_rx"]] = c["hip_rx"]
            x[PARAM_INDEX[f"{side}_hip_rz"]] = sign * c["hip_rz"]
            x[PARAM_INDEX[f"{side}_knee_flex"]] = c["knee_flex"]
        starts.append(Pose(in_limits(x)))
    return starts


def _known_area(masks: Sequence[np.ndarray], known: Sequence[np.ndarray | None]) -> float:
    """Silhouette pixels over all views, counting only the known ones."""
    return float(sum(np.count_nonzero(counted(m, k)) for m, k in zip(masks, known, strict=True)))


SWAPPED = ("legs", "arms", "legs and arms")
"""What each of `left_right_swaps` swaps."""


def left_right_swaps(x: np.ndarray) -> list[np.ndarray]:
    """The pose `x` with its legs swapped, its arms swapped, and both (`swap_sides`): what
    the silhouettes can hardly tell from it."""
    return [swap_sides(x, "leg"), swap_sides(x, "arm"), swap_sides(swap_sides(x, "leg"), "arm")]


def swap_sides(x: np.ndarray, limb: str) -> np.ndarray:
    """Pose parameters with the left and right legs (limb "leg") or arms ("arm") exchanged:
    flexion and the hinge carry over, abduction and twist change sign (they mirror)."""
    x = np.array(x, dtype=float)
    ball, hinge = ("shoulder", "elbow") if limb == "arm" else ("hip", "knee")
    for name, sign in ((f"{ball}_rz", -1.0), (f"{ball}_rx", 1.0), (f"{ball}_ry", -1.0),
                       (f"{hinge}_flex", 1.0)):  # fmt: skip
        left, right = PARAM_INDEX[f"l_{name}"], PARAM_INDEX[f"r_{name}"]
        x[left], x[right] = sign * x[right], sign * x[left]
    return x


class TrackingLost(Exception):
    """The subject cannot be found in this frame."""

    status = "lost"


class SubjectsInView(TrackingLost):
    """Two subjects or more in view: the frame is refused, not tracked on a merged blob."""

    status = "two-subjects"


_GAP_WORDS = {"lost": "lost", "absent": "absent", "two-subjects": "refused (two subjects)"}
"""How the event of a recovered frame names the frames without a pose before it."""
