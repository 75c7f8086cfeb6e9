"""A tracked bundle against the ground truth of the captures it tracked: vertex and joint errors.

Usage: ``./run bench track_truth --tracked T.npz --truth DIR/ground_truth.npz``, e.g. after
``./run track --model out/demo_data/learned.npz --scans out/demo_data/unregistered --out T.npz`` (the demo's
learned rig) or the README's ``./run track --model out/learned.npz --scans out/data/unreg ...``.

The truth's posed body is its linear-blend skin (``rest_vertices``, ``lbs_weights``, ``bone_matrices``, as
``./run samples unregistered`` writes it); the tracked model must share its vertices (a rig learned from the
same body, or that body's own model).  Prints the mean vertex error per frame and over the frames, the five
parts of the truth's rig farthest off on the worst frame, and, when the tracked rig has the truth's bone
names, the mean error of the 14 major joints per frame.  Errors are against the truth, never the tracker's
residual.
"""
import argparse
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))   # the bench command loads us by path
import _common  # noqa: E402,F401  (makes ``import articula`` work)

import numpy as np  # noqa: E402


def errors(tracked, truth_path):
    """``(vertex errors (N, V) mm, joint errors (N,) mm or None, truth arrays)`` of the bundle at ``tracked``."""
    from articula.solver.formats.bundle import load_bundle
    from articula.solver.rig.kinematics import forward_kinematics
    from articula.solver.rig.skinning import hybrid_skin, lbs
    gt = np.load(truth_path)
    M = gt["bone_matrices"]
    truth = lbs(gt["rest_vertices"], gt["lbs_weights"], M[:, :, :3, :3], M[:, :, :3, 3])
    b = load_bundle(tracked)
    posed = hybrid_skin(b.model, b.poses)
    if posed.shape[1] != truth.shape[1] or len(posed) > len(truth):
        raise SystemExit(f"track_truth: {tracked} has {len(posed)} frames of {posed.shape[1]} vertices, the truth "
                         f"{len(truth)} of {truth.shape[1]}: not the same body")
    vertex = np.linalg.norm(posed - truth[:len(posed)], axis=2) * 1e3
    names = [str(n) for n in gt["bone_names"]]
    major = [names[int(k)] for k in gt["major_joint_bones"]]
    if not all(n in b.model.skeleton.names for n in major):
        return vertex, None, gt, names
    Rm, tm = forward_kinematics(b.model.skeleton, b.poses)
    ours = [b.model.skeleton.names.index(n) for n in major]
    heads = np.einsum("nbij,bj->nbi", Rm[:, ours], b.model.skeleton.heads[ours]) + tm[:, ours]
    want = gt["posed_heads"][:len(posed)][:, [int(k) for k in gt["major_joint_bones"]]]
    return vertex, np.linalg.norm(heads - want, axis=2).mean(axis=1) * 1e3, gt, names


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="bench track_truth")
    p.add_argument("--tracked", required=True, help="tracked bundle (.npz) from ./run track")
    p.add_argument("--truth", required=True, help="ground_truth.npz of the tracked sample captures")
    args = p.parse_args(argv)
    vertex, joints, gt, names = errors(args.tracked, args.truth)
    per = vertex.mean(axis=1)
    print(f"mean vertex error per frame (mm): {' '.join(f'{x:.1f}' for x in per)}; mean {vertex.mean():.2f} mm")
    worst = int(np.argmax(per))
    part = np.asarray(gt["lbs_weights"]).argmax(axis=1)
    by_part = np.bincount(part, vertex[worst]) / np.maximum(np.bincount(part), 1)
    top = np.argsort(-by_part)[:5]
    print(f"frame {worst}, parts farthest off: " + ", ".join(f"{names[k]} {by_part[k]:.0f} mm" for k in top))
    if joints is not None:
        print(f"major joints per frame (mm): {' '.join(f'{x:.1f}' for x in joints)}; mean {joints.mean():.2f} mm")
    return 0


if __name__ == "__main__":
    sys.exit(main())
