"""One tracking frame fit with the exact model on noisy 4-view scans: error (mm), time, updates.

Per-frame tracking fit (``solver.track.frame_fit.fit_frame``) with the subject's exact model on its own
noisy, unregistered 4-view scans (``sample_scenes.unregistered.scan_frame``, 4 x 320x240), each frame started
from the previous frame's true pose, no pose prior: mean vertex error against the ground truth (mm), median
scan-to-model distance, wall time and updates, for frames 1 and 2 of a walk and of a random motion (MakeHuman
cmu_mb, 13,380 vertices, hybrid skin).  Issue 17's targets: <= 3 mm, <= 1 s per frame.

Usage: ./run bench track_frame [--truth]   (--truth: start at the frame's own true pose)
"""
import argparse
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))   # bench_cli loads us by path
import _common  # noqa: E402  (makes ``import articula`` work)

import numpy as np  # noqa: E402


def _frame(poses, n):
    from articula.solver.rig.model import Poses
    return Poses(poses.rotations[n:n + 1].copy(), poses.translations[n:n + 1].copy(), poses.scales[n:n + 1].copy())


def _setup(motion, **options):
    from articula.sample_scenes import registered
    from articula.solver.rig.model import Model, Poses, Skeleton
    frames, _, gt = registered.posed_sequence(n_poses=4, motion=motion, skin="hybrid", seed=0, **options)
    sk = Skeleton(list(gt["bone_names"]), gt["parents"], gt["heads"], gt["tails"], gt["frames"])
    model = Model(gt["rest_vertices"], gt["faces"], sk, gt["anchor"], gt["twist_weights"], gt["swing_weights"])
    return model, Poses(gt["pose_rotations"], gt["pose_translations"], gt["pose_scales"]), frames


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="bench track_frame")
    p.add_argument("--truth", action="store_true", help="start each frame at its own true pose")
    args = p.parse_args(argv)
    from articula.sample_scenes import unregistered
    from articula.solver.rig.skinning import AnchorGroups, hybrid_skin
    from articula.solver.track import frame_fit
    for motion, options in (("walk", {}), ("rom", {"key_every": 8})):
        model, poses, frames = _setup(motion, **options)
        groups = AnchorGroups(model)
        for f in (1, 2):
            pts, tris, _, _, cams = unregistered.scan_frame(frames[f], model.faces, np.random.default_rng([0, f]))
            start = _frame(poses, f if args.truth else f - 1)
            t0 = time.perf_counter()
            out = frame_fit.fit_frame(model, frame_fit.Capture.from_mesh(pts, tris, cams), start, None,
                                      frame_fit.FrameFitOptions(), groups)
            seconds = time.perf_counter() - t0
            before = np.linalg.norm(hybrid_skin(model, start)[0] - frames[f], axis=1).mean()
            after = np.linalg.norm(hybrid_skin(model, out.pose)[0] - frames[f], axis=1).mean()
            _common.report(f"{motion} frame {f}: mean vertex error", after * 1e3, "mm",
                           f"start {before * 1e3:.1f} mm, {len(pts)} points, median scan-to-model "
                           f"{out.stats['median_mm']:.2f} mm, {seconds:.1f} s, {out.iterations} updates")
    return 0


if __name__ == "__main__":
    sys.exit(main())
