"""A check of a tracked pose against the visual hull: a part of the hull the body leaves out
(issue 20, "know when you are lost").

The XOR watch (`tracking.track.divergence`) is relative to the track's own XOR, so a track
wrong from its start has no good reference: the CMU squat's left forearm, held out, was
started folded on the chest and tracked there for the whole clip (wrist 300-440 mm off) at
an XOR no higher than the right frames of other clips. Its silhouettes still show the arm:
the visual hull has a forearm-sized part far from the tracked body, and the model leaves that
part's pixels uncovered in the views that see it.

`unexplained_hull_part` gives the share of the hull's surface voxels in the largest connected
group of those that are

* farther than ``distance_m`` from the posed body's surface,
* more than ``floor_m`` above the hull's lowest point (a shadow on the floor is part of the
  silhouettes and of their hull, and no limb), and
* on silhouette pixels the model leaves uncovered in at least ``min_views`` views, opened by
  ``opening_m`` at the subject's distance (the tracker's voxel, 3 cm), so that slivers along
  the outline, where a real body is wider than the model, do not count. A hull carved by few
  views also has ghost volume the body does not fill, but the body covers its pixels in
  every view.

A frame over ``TrackConfig.max_unexplained_share`` is mended when it can be
(`SilhouetteTracker._mend_unexplained`: the two limbs whose roots are nearest the part are
searched again over their whole range, without the twist prior on them, and a pose of lower
XOR that leaves less out is kept), and flagged when it still is: a flag whatever the status,
like a silhouette cut by the image border.

The flag, measured (session 22) on the tracked poses of two 15-clip suite runs of session 21
(`benchmarks/tracking_suite.py --frames 30`, synth's mismatched subject: the defaults, and
``--init-starts 3``), against each frame's worst joint, and on the Pose2Sim demo's 100 real
frames (defaults, median IoU 0.811), with 9 cm and a 3 cm opening:

============================  ==========================  ===========================
                              frames > 100 mm flagged     frames < 50 mm flagged
============================  ==========================  ===========================
defaults (tuned on)           74% of 110 (squat 30/30)    0 of 265 (largest 0.19%)
``--init-starts 3``           57% of 81                   0 of 291
Pose2Sim demo (real)          (no truth)                  1 of 100 frames flagged
============================  ==========================  ===========================

Without the views' test, the largest such part of the hull was over 1% in 14% of the right
frames (hull ghosts); in 2-D alone (the largest uncovered blob per view) the synthetic
silhouettes' shadow made 5% in every frame; without the opening, 7 of the demo's frames were
flagged at 1% (the back of a real body stooping, wider than the model's). A whole body off
by a bend (bend_pickup, 118 mm at its worst joint with every limb near its place) leaves no
such part: it is not flagged.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from recon.cameras import Camera
from tracking.body.model import Pose


def unexplained_hull_part(model: Any, pose: Pose, cameras: Sequence[Camera],
                           masks: Sequence[np.ndarray], hull_points: np.ndarray,
                           model_masks: Sequence[np.ndarray], up: np.ndarray, *,
                           vertices: np.ndarray | None = None,
                           known: Sequence[np.ndarray | None] | None = None,
                           distance_m: float, min_views: int = 2, floor_m: float = 0.10,
                           opening_m: float = 0.0) -> tuple[float, np.ndarray]:  # fmt: skip
    """The share of `hull_points` (N, 3; the hull's surface voxels) in the largest group left
    out by the body posed at `pose` (module docstring), and that group's points (M, 3);
    `model_masks`: the body's silhouette in each camera at `pose`, full size; `up`: the
    world's up direction; `vertices`: the posed body's vertices when they are at hand."""
    import cv2

    from tracking.fit.body_fit import largest_far_group, mesh_distances
    from tracking.silhouettes.hull import project_voxels

    none = np.empty((0, 3))
    if len(hull_points) == 0:
        return 0.0, none
    known = list(known) if known is not None else [None] * len(cameras)
    missed_in = np.zeros(len(hull_points), int)
    centre = hull_points.mean(axis=0)
    for camera, mask, body, seen in zip(cameras, masks, model_masks, known, strict=True):
        missed = np.asarray(mask, bool) & ~body
        if seen is not None:
            missed &= seen
        # Opened by `opening_m` at the subject's distance (at least 3 px): slivers along the
        # outline, where a real body is wider than the model, do not count.
        _, depth = camera.project(centre[None])
        pixels = opening_m * float(camera.K[0, 0]) / max(float(depth[0]), 1e-6)
        size = max(3, int(round(pixels)))
        kernel = np.ones((size, size), np.uint8)
        missed = cv2.morphologyEx(missed.astype(np.uint8), cv2.MORPH_OPEN, kernel) > 0
        seen = project_voxels(camera, hull_points)
        missed_in += seen.seen & missed[seen.row, seen.col]
    height = hull_points @ up
    above = height > height.min() + floor_m
    if not above.any():
        return 0.0, none
    points = hull_points[above]
    # Only the voxels missed in enough views can be in the part: the others' distance is 0.
    candidates = missed_in[above] >= min_views
    distances = np.zeros(len(points))
    if candidates.any():
        distances[candidates] = mesh_distances(model, pose, points[candidates], vertices)
    group = points[largest_far_group(points, distances, distance_m)]
    return len(group) / len(points), group
