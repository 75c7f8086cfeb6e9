"""Build the start pose set shipped as ``solver/tracking/data/start_poses.npz``: body poses from which the
first frame of a tracked capture is searched (:mod:`solver.tracking.start_search`, docs/track.md).

    python tools/make_start_poses.py [--mocap DIR] [--count N] [--out PATH]

Sources: every frame of the CMU clips ``cmu_01_01.bvh`` and ``cmu_131_01.bvh`` in ``--mocap`` (the
project's shared data), and MPFB2's walk cycle on MakeHuman bodies with the ``cmu_mb`` rig (the frames of
the generic body poses, ``tools/make_generic_poses.py``); each also mirrored left/right.  Every pose is
stored rig-independently as the world positions of the role joints (:mod:`solver.roles`) and of the ends
of the head, hands and toes, relative to the hips joint, in the body's own frame (columns left, back, up:
up = the capture's world up, left = from the right to the left thigh joint, level), in units of the
body's height: the segment directions every rig is aimed along (:mod:`solver.tracking.start_poses`).
``--count`` poses are kept by farthest-point sampling on the segment directions (the walk frames first).
"""
import argparse
import json
import os
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / ".pkgroot"))
from articula.solver.roles import role_bones  # noqa: E402
from articula.solver.tracking.start_poses import (POSE_ROLES, START_POSES_PATH, mirror_role,  # noqa: E402
                                                  pose_features)

MOCAP = ROOT.parent / "shared" / "data" / "mocap"
CLIPS = ("cmu_01_01.bvh", "cmu_131_01.bvh")


def read_bvh(path):
    """``(names, parents, world positions (F, J, 3))`` of a BVH file's joints and end sites (an end site
    is named ``<joint>.end``); the file's own axes and units."""
    words = Path(path).read_text(encoding="latin-1").split()
    names, parents, offsets, channels, stack, i = [], [], [], [], [], 0
    while words[i] != "MOTION":
        w = words[i]
        if w in ("ROOT", "JOINT") or (w == "End" and words[i + 1] == "Site"):
            names.append(words[i + 1] if w != "End" else names[stack[-1]] + ".end")
            parents.append(stack[-1] if stack else -1)
            channels.append([])
            i += 2
        elif w == "{":
            stack.append(len(names) - 1)
            i += 1
        elif w == "}":
            stack.pop()
            i += 1
        elif w == "OFFSET":
            offsets.append([float(v) for v in words[i + 1:i + 4]])
            i += 4
        elif w == "CHANNELS":
            n = int(words[i + 1])
            channels[-1] = words[i + 2:i + 2 + n]
            i += 2 + n
        else:
            i += 1
    frames = int(words[i + 2])
    values = np.array(words[i + 6:], dtype=np.float64).reshape(frames, -1)
    return names, parents, _positions(parents, np.array(offsets), channels, values)


def _axis_rotation(axis, degrees):
    a = np.radians(degrees)
    c, s = np.cos(a), np.sin(a)
    R = np.zeros(a.shape + (3, 3))
    i, j = {"X": (1, 2), "Y": (2, 0), "Z": (0, 1)}[axis]
    k = 3 - i - j
    R[..., k, k] = 1.0
    R[..., i, i], R[..., i, j], R[..., j, i], R[..., j, j] = c, -s, s, c
    return R


def _positions(parents, offsets, channels, values):
    F, col = len(values), 0
    rot = np.empty((F, len(parents), 3, 3))
    pos = np.empty((F, len(parents), 3))
    for j, p in enumerate(parents):
        R, t = np.broadcast_to(np.eye(3), (F, 3, 3)).copy(), offsets[j] + np.zeros((F, 3))
        for name in channels[j]:
            if name.endswith("position"):
                t[:, "XYZ".index(name[0])] += values[:, col]
            else:
                R = R @ _axis_rotation(name[0], values[:, col])
            col += 1
        if p < 0:
            rot[:, j], pos[:, j] = R, t
        else:
            rot[:, j] = rot[:, p] @ R
            pos[:, j] = pos[:, p] + np.einsum("fij,fj->fi", rot[:, p], t)
    return pos


def body_joints(names, positions, up, ends):
    """``(F, R, 3)`` positions of :data:`POSE_ROLES` in the body frame (module docstring), or NaN rows
    for roles the skeleton lacks; ``ends {end role: joint name}`` names the end points."""
    roles = role_bones(names)
    index = {n: i for i, n in enumerate(names)}
    cols = [roles.get(r, index.get(ends.get(r, ""), -1)) for r in POSE_ROLES]
    P = np.where(np.array(cols)[None, :, None] >= 0, positions[:, cols], np.nan)
    hips = P[:, POSE_ROLES.index("hips")]
    left = P[:, POSE_ROLES.index("thigh.L")] - P[:, POSE_ROLES.index("thigh.R")]
    left -= (left @ up)[:, None] * up
    left /= np.linalg.norm(left, axis=1, keepdims=True)
    E = np.stack([left, np.cross(up, left), np.broadcast_to(up, left.shape)], axis=2)
    local = np.einsum("fji,frj->fri", E, P - hips[:, None])
    height = np.nanmax(local[..., 2], axis=1) - np.nanmin(local[..., 2], axis=1)
    return local / np.median(height)


def mirrored(joints):
    """The left/right mirror images of ``joints (F, R, 3)`` (body frame: negate left, swap sides)."""
    out = joints[:, [POSE_ROLES.index(mirror_role(r)) for r in POSE_ROLES]].copy()
    out[..., 0] *= -1.0
    return out


def farthest_points(features, count, first):
    """Indices of ``count`` rows of ``features`` picked by farthest-point sampling, starting with ``first``."""
    chosen = list(first)
    d = np.min(np.linalg.norm(features[:, None] - features[chosen][None], axis=2), axis=1)
    while len(chosen) < min(count, len(features)):
        k = int(np.argmax(d))
        chosen.append(k)
        d = np.minimum(d, np.linalg.norm(features - features[k], axis=1))
    return np.array(chosen)


def walk_joints():
    """Joint positions of MPFB2's walk cycle (cmu_mb rig, average and female bodies, 6 frames each)."""
    from articula.sample_scenes.subjects import make_subject
    from articula.sample_scenes.walk import CYCLE_FRAMES, walk_poses
    from articula.solver.rig.kinematics import forward_kinematics
    out = []
    for i, shape in enumerate(("average", "female")):
        subject = make_subject("cmu_mb", shape)
        sk = subject.skeleton
        poses = walk_poses(subject, 6, seed=i, step=CYCLE_FRAMES / 6)
        Rm, tm = forward_kinematics(sk, poses)
        heads = np.einsum("nbij,bj->nbi", Rm, sk.heads) + tm
        tails = np.einsum("nbij,bj->nbi", Rm, sk.tails) + tm
        names = list(sk.names) + [n + ".end" for n in sk.names]
        ends = {"head.end": "Head.end", "hand.L.end": "HandFinger1.L.end", "hand.R.end": "HandFinger1.R.end",
                "toe.L.end": "ToeBase.L.end", "toe.R.end": "ToeBase.R.end"}
        out.append(body_joints(names, np.concatenate([heads, tails], axis=1), np.array([0.0, 0.0, 1.0]), ends))
    return np.concatenate(out)


def clip_joints(path):
    names, _, positions = read_bvh(path)
    have = set(names)
    ends = {"head.end": "Head.end"}
    for side, word in (("L", "Left"), ("R", "Right")):
        ends[f"hand.{side}.end"] = f"{side}Fingers.end"
        ends[f"toe.{side}.end"] = next(n for n in (f"{word}ToeBase.end", f"{word}Toe.end") if n in have)
    return body_joints(names, positions, np.array([0.0, 1.0, 0.0]), ends)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mocap", default=str(MOCAP))
    ap.add_argument("--count", type=int, default=240)
    ap.add_argument("--out", default=START_POSES_PATH)
    args = ap.parse_args(argv)
    walk = walk_joints()
    clips = [clip_joints(os.path.join(args.mocap, c)) for c in CLIPS]
    sets = [walk] + clips
    joints = np.concatenate([np.concatenate([s, mirrored(s)]) for s in sets])
    source = np.concatenate([np.full(2 * len(s), k) for k, s in enumerate(sets)])
    frame = np.concatenate([np.concatenate([np.arange(len(s)), np.arange(len(s))]) for s in sets])
    if np.isnan(joints).any():
        raise SystemExit("a source lacks a role joint: " + ", ".join(
            r for k, r in enumerate(POSE_ROLES) if np.isnan(joints[:, k]).any()))
    pick = farthest_points(pose_features(joints), args.count, range(len(walk)))
    info = {"sources": ["MPFB2 walk cycle (CC0) on MakeHuman average/female, cmu_mb rig"] + list(CLIPS),
            "mirrored": "second half of each source", "selection": f"farthest points on segment directions, "
            f"{len(pick)} of {len(joints)}", "tool": "tools/make_start_poses.py"}
    os.makedirs(os.path.dirname(args.out), exist_ok=True)
    np.savez_compressed(args.out, format=np.array("articula-start-poses/1"), roles=np.array(POSE_ROLES),
                        joints=joints[pick].astype(np.float32), source=source[pick].astype(np.int16),
                        frame=frame[pick].astype(np.int32), info=np.array(json.dumps(info)))
    print(f"{len(pick)} poses -> {args.out} ({Path(args.out).stat().st_size / 1024:.1f} kB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
