"""Body-model fitting to point clouds, and BVH retargeting residuals (issue 5), one run.

    .venv/bin/python benchmarks/body_fit.py [--poses 24] [--spread 0.5]

Fitting: for each of N random poses (joint angles uniform over the middle `spread` of every
joint's range, random heading, subject height 1.55-1.95 m) a cloud of 5,000 surface samples is
drawn, the 30% of the surface facing away from a random horizontal viewpoint is removed and
5 mm Gaussian noise added; `fit_body` then runs with its defaults. Reported: the mean joint
position error per pose and per joint (16 nodes: 11 joints and 5 end sites), the success flag,
and the time per fit. The peer in the same run is the same ICP without the initialisation
search (rest pose on the principal axes, one orientation), to show what the search buys.

Targets: mean joint position error <= 15 mm over >= 20 random poses; <= 10 s per fit on 2 cores.

Real poses on a mismatched subject: frames spread over CMU clips (`REAL_CLIPS`, retargeted
by `tracking.body.retarget`) at a random heading pose MakeHuman's body shaped as `MISMATCHED`
(full mesh), and the same kind of cloud is sampled from it; the truth is that subject's own
joints (`MpfbModel.joints`). Both ``--body superquadric`` and ``--body mpfb`` fit each cloud
(`fit_body` defaults otherwise). Reported per pose and in summary: the mean joint error (16
nodes, and the 11 joints without the end sites), the maximum, the success flag, the
confident-wrong fits (success claimed with a mean or a maximum joint error above 50 mm), and
the time per fit. Targets: mpfb mean <= 15 mm, no confident-wrong fit.

Retargeting: every frame of the two CMU clips is retargeted (`tracking.body.retarget`) and the
residual per joint (distance between our node and its CMU joint) reported in mm.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from _cli import SHARED_DATA  # benchmarks/ is on sys.path when a script here runs

from tracking.body.model import (
    NODE_NAMES,
    BodyModel,
    BodyShape,
    Pose,
    node_positions_in_world,
    pose_in_frame,
)
from tracking.body.synthetic import body_cloud, random_pose
from tracking.fit.body_fit import (
    _H,
    N_POSE_PARAMS,
    FitConfig,
    _bounds,
    _initial_x,
    _orientation_candidates,
    _Problem,
    _surface,
    fit_body,
    shape_from_scales,
)

BVH = SHARED_DATA / "mocap_bvh"


def _errors_mm(joints: dict, truth: dict) -> np.ndarray:
    return np.array([1000 * np.linalg.norm(np.asarray(joints[n]) - truth[n]) for n in NODE_NAMES])


def _no_search(points: np.ndarray) -> dict:
    """The peer: ICP of the rest-pose model from the principal axes, without any search."""
    rng = np.random.default_rng(0)
    points = points[rng.choice(len(points), min(1500, len(points)), replace=False)]
    rotations, extent = _orientation_candidates(points, 8)
    problem = _Problem(_surface(), _bounds(extent), FitConfig().robust_scale * extent)
    x = problem.icp(_initial_x(rotations[0], points, extent), points,
                    np.arange(N_POSE_PARAMS + 2), rounds=15, steps=3)  # fmt: skip
    pose = Pose(x[:N_POSE_PARAMS]).clamped()
    return node_positions_in_world(pose, shape_from_scales(x[_H], 1.0))


def fitting(poses: int, spread: float, body: str | None = None) -> None:
    config = FitConfig() if body is None else FitConfig(body=body)
    print(f"fitting: {poses} random poses (spread {spread}) of the superquadric model, 5 mm "
          f"noise, 30% hidden; fitted with --body {config.body}")  # fmt: skip
    print(f"{'pose':>4} {'height':>6} {'ours mm':>8} {'max mm':>7} {'no-search mm':>12} "
          f"{'s/fit':>6} result")  # fmt: skip
    ours, peer, seconds, ok, per_joint = [], [], [], [], []
    for k in range(poses):
        rng = np.random.default_rng(k)
        height = rng.uniform(1.55, 1.95)
        shape = BodyShape.default(height)
        pose = random_pose(rng, spread)
        points, _ = body_cloud(BodyModel(shape), pose, rng)
        truth = node_positions_in_world(pose, shape)
        start = time.perf_counter()
        result = fit_body(points, config)
        seconds.append(time.perf_counter() - start)
        errors = _errors_mm(result.joints, truth)
        per_joint.append(errors)
        ours.append(errors.mean())
        peer.append(_errors_mm(_no_search(points), truth).mean())
        ok.append(result.success)
        print(f"{k:>4} {height:>6.2f} {ours[-1]:>8.1f} {errors.max():>7.0f} {peer[-1]:>12.1f} "
              f"{seconds[-1]:>6.1f} {result.message}")  # fmt: skip
    per_joint_mm = np.mean(per_joint, axis=0)
    print("\nper joint, mean over poses (mm): " + ", ".join(
        f"{n} {e:.1f}" for n, e in zip(NODE_NAMES, per_joint_mm, strict=True)))  # fmt: skip
    mean, median = float(np.mean(ours)), float(np.median(ours))
    print(f"\nmean joint error: ours {mean:.1f} mm (median {median:.1f}, worst pose "
          f"{max(ours):.1f}); no-search ICP {np.mean(peer):.1f} mm; ratio ours/no-search "
          f"{mean / np.mean(peer):.3f}")  # fmt: skip
    print(f"accepted fits: {sum(ok)}/{poses}; time per fit: median {np.median(seconds):.1f} s, "
          f"max {max(seconds):.1f} s")  # fmt: skip
    verdict = "PASS" if mean <= 15 else "FAIL"
    print(f"target mean <= 15 mm over >= 20 poses: {verdict}; target <= 10 s per fit: "
          f"{'PASS' if np.median(seconds) <= 10 else 'FAIL'} (median)")  # fmt: skip


REAL_CLIPS: tuple[str, ...] = ("cmu_02_01_walk.bvh", "cmu_run.bvh", "cmu_wave.bvh",
                               "cmu_bend_pickup.bvh")  # fmt: skip
MISMATCHED = {"gender": 0.2, "weight": 0.7, "height": 0.4, "age_years": 40.0}
"""`benchmarks/tracking_synthetic.py`'s mismatched subject (with 2 cm of clothing): a heavier,
shorter, mostly female 40-year-old, not the fit's start (MakeHuman's average subject)."""
CONFIDENT_WRONG_MM = 50.0


HELD_OUT_CLIPS: tuple[str, ...] = ("cmu_dance.bvh", "cmu_squat.bvh", "cmu_boxing.bvh",
                                    "cmu_jump.bvh", "cmu_cartwheel.bvh")  # fmt: skip
"""Clips the fit's constants were not chosen on (`--clips held-out`) until session 16, whose
limb repair was developed on one of their frames (dance 449)."""
UNSEEN_CLIPS: tuple[str, ...] = ("cmu_arms_overhead.bvh", "cmu_turn_pirouette.bvh",
                                 "cmu_131_01_start_walk_stop.bvh")  # fmt: skip
"""Clips no fit development has looked at (`--clips unseen`), first measured in session 16 (the
shared data's Daz-style clips, kick, sit-stand and climb, are not CMU skeletons the
retargeting reads)."""
FRESH_CLIPS: tuple[str, ...] = ("cmu_kick.bvh", "cmu_sit_stand.bvh", "cmu_climb_steps.bvh")
"""The shared data's Daz-style clips (`--clips fresh`), first read by the retargeting and
measured in session 19, after that session's changes to the fit were made on the other sets:
kicking a ball, sitting on a stool and standing up, climbing steps."""
CLIP_SETS: dict[str, tuple[str, ...]] = {"tuned": REAL_CLIPS, "held-out": HELD_OUT_CLIPS,
                                         "unseen": UNSEEN_CLIPS,
                                         "fresh": FRESH_CLIPS}  # fmt: skip


def real_poses(frames_per_clip: int,
               clips: tuple[str, ...] = REAL_CLIPS) -> list[tuple[str, int, Pose]]:  # fmt: skip
    """(clip, frame, pose) of `frames_per_clip` frames evenly over each of `clips`, turned to
    a random heading about the vertical (seeded by the frame)."""
    from tracking.body.bvh import read_bvh
    from tracking.body.retarget import retarget

    out = []
    for clip in clips:
        motion = read_bvh(BVH / clip)
        frames = np.linspace(0, motion.num_frames - 1, frames_per_clip + 2)[1:-1].astype(int)
        result = retarget(motion, None, frames)  # in the clip naming's unit
        for frame, pose in zip(result.frames, result.poses, strict=True):
            angle = np.random.default_rng(int(frame)).uniform(-np.pi, np.pi)
            c, s = np.cos(angle), np.sin(angle)
            turn = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
            out.append((clip, int(frame), pose_in_frame(pose, turn)))
    return out


FITTERS: dict[str, dict] = {
    "superquadric": {"body": "superquadric"},
    "mpfb": {"body": "mpfb"},
    "mpfb-24": {"body": "mpfb", "hold": ("spine_bend", "spine_twist")},
}
"""`FitConfig` settings of each fitter of the real poses: the two body models with their
defaults, and mpfb without the spine's side bend and twist (the thesis' 24 parameters)."""


def real_fitting(frames_per_clip: int, clips: tuple[str, ...] = REAL_CLIPS,
                 bodies: tuple[str, ...] = ("superquadric", "mpfb")) -> None:  # fmt: skip
    from tracking.body.mpfb.model import MacroShape
    from tracking.body.mpfb.subject import MpfbModel
    from tracking.fit.body_fit import FitConfig

    if not BVH.is_dir():
        print(f"\nreal poses: skipped, {BVH} is absent")
        return
    subject = MpfbModel(MacroShape(**MISMATCHED), clothes_cm=2.0, mesh="full")
    poses = real_poses(frames_per_clip, clips)
    print(f"\nreal poses on a mismatched mpfb subject ({subject.shape.height:.3f} m, "
          f"{MISMATCHED}, 2 cm clothes, full mesh): {len(poses)} frames of "
          f"{len(clips)} clips, 5 mm noise, 30% hidden")  # fmt: skip
    print(f"{'clip':>20} {'frame':>5} " + " ".join(
        f"{b[:5] + ' mean':>10} {'j11':>5} {'max':>5} {'inl':>4} {'s':>5} {'ok':>3}"
        for b in bodies))
    rows = {b: [] for b in bodies}  # (mean, joints11 mean, max, seconds, success)
    for k, (clip, frame, pose) in enumerate(poses):
        rng = np.random.default_rng(1000 + k)
        points, _ = body_cloud(subject, pose, rng)
        truth = subject.joints(pose)
        line = f"{clip.removesuffix('.bvh'):>20} {frame:>5} "
        messages = {}
        for body in bodies:
            start = time.perf_counter()
            result = fit_body(points, FitConfig(**FITTERS[body]))
            seconds = time.perf_counter() - start
            joints = np.array([result.joints[n] for n in NODE_NAMES])
            errors = 1000 * np.linalg.norm(joints - truth, axis=1)
            rows[body].append((errors.mean(), errors[:11].mean(), errors.max(), seconds,
                               result.success))  # fmt: skip
            messages[body] = result.message
            line += (f"{errors.mean():>10.1f} {errors[:11].mean():>5.1f} {errors.max():>5.0f} "
                     f"{result.inlier_fraction:>4.0%} "
                     f"{seconds:>5.1f} {'yes' if result.success else 'no':>3} ")  # fmt: skip
        print(line, flush=True)
        notes = {b: m for b, m in messages.items() if m != "ok"}
        if notes:
            print(" " * 27 + "; ".join(f"{b}: {m}" for b, m in notes.items()), flush=True)
    print()
    for body in bodies:
        a = np.array(rows[body])
        wrong_mean = int(np.sum(a[:, 4].astype(bool) & (a[:, 0] > CONFIDENT_WRONG_MM)))
        wrong_max = int(np.sum(a[:, 4].astype(bool) & (a[:, 2] > CONFIDENT_WRONG_MM)))
        print(f"{body:>12}: mean joint error {a[:, 0].mean():.1f} mm (median "
              f"{np.median(a[:, 0]):.1f}, worst pose {a[:, 0].max():.1f}; 11 joints "
              f"{a[:, 1].mean():.1f}; mean of max {a[:, 2].mean():.0f}; over the accepted fits "
              f"{a[a[:, 4] > 0, 0].mean() if a[:, 4].any() else np.nan:.1f}); success "
              f"{int(a[:, 4].sum())}/{len(a)}; confident-wrong (success, error > "
              f"{CONFIDENT_WRONG_MM:.0f} mm): {wrong_mean} by mean, {wrong_max} by max; time "
              f"per fit median {np.median(a[:, 3]):.1f} s, max {a[:, 3].max():.1f} s")  # fmt: skip
    seconds = {b: np.median(np.array(rows[b])[:, 3]) for b in bodies}
    if "superquadric" in bodies and "mpfb" in bodies:
        print(f"time ratio mpfb/superquadric (medians): "
              f"{seconds['mpfb'] / seconds['superquadric']:.2f}")
    if "mpfb" not in bodies:
        return
    mean = np.array(rows["mpfb"])[:, 0].mean()
    wrong = sum(1 for r in rows["mpfb"] if r[4] and r[2] > CONFIDENT_WRONG_MM)
    print(f"target mpfb mean <= 15 mm: {'PASS' if mean <= 15 else 'FAIL'}; target no "
          f"confident-wrong mpfb fit (by max): {'PASS' if wrong == 0 else 'FAIL'}")


def retargeting() -> None:
    from tracking.body.bvh import CMU_METRES_PER_UNIT, read_bvh
    from tracking.body.retarget import cmu_node_positions, retarget

    if not BVH.is_dir():
        print(f"\nretargeting: skipped, {BVH} is absent")
        return
    for clip in ("cmu_02_01_walk.bvh", "cmu_131_01_start_walk_stop.bvh"):
        motion = read_bvh(BVH / clip)
        start = time.perf_counter()
        result = retarget(motion, CMU_METRES_PER_UNIT)
        seconds = time.perf_counter() - start
        targets = cmu_node_positions(motion, CMU_METRES_PER_UNIT)
        per_joint = {n: [] for n in targets}
        for frame, pose in zip(result.frames, result.poses, strict=True):
            nodes = node_positions_in_world(pose, result.shape)
            for n, positions in targets.items():
                per_joint[n].append(1000 * np.linalg.norm(nodes[n] - positions[frame]))
        print(f"\nretargeting {clip}: {motion.num_frames} frames in {seconds:.1f} s, RMS "
              f"{1000 * np.sqrt(np.mean(result.residual_rms_m ** 2)):.1f} mm; per joint mean "
              f"(max) mm:")  # fmt: skip
        print("  " + ", ".join(f"{n} {np.mean(v):.1f} ({np.max(v):.0f})"
                               for n, v in per_joint.items()))  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--poses", type=int, default=24)
    parser.add_argument("--spread", type=float, default=0.5)
    parser.add_argument("--random-body", choices=("superquadric", "mpfb"),
                        help="the body model fitted to the random poses' clouds (default: "
                        "mocap fit's)")  # fmt: skip
    parser.add_argument("--real-frames", type=int, default=6,
                        help="frames per clip of the real-pose section (0: skip it)")
    parser.add_argument("--clips", choices=tuple(CLIP_SETS), default="tuned",
                        help="the real-pose section's clips: those the fit was developed on "
                        "(walk, run, wave, bend and pick up), held out until session 16 "
                        "(dance, squat, boxing, jump, cartwheel), never looked at until "
                        "session 18 (arms overhead, pirouette, start-walk-stop), or the "
                        "Daz-style clips first read in session 19 (kick, sit-stand, "
                        "climb)")  # fmt: skip
    parser.add_argument("--bodies", nargs="+", choices=tuple(FITTERS),
                        default=["superquadric", "mpfb"],
                        help="the fitters of the real-pose section (mpfb-24: mpfb without "
                        "the spine's side bend and twist)")  # fmt: skip
    parser.add_argument("--no-retarget", action="store_true")
    args = parser.parse_args()
    if args.poses:
        fitting(args.poses, args.spread, args.random_body)
    if args.real_frames:
        real_fitting(args.real_frames, CLIP_SETS[args.clips], tuple(args.bodies))
    if not args.no_retarget:
        retargeting()


if __name__ == "__main__":
    main()
