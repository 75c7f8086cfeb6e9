"""Build the generic body poses shipped as ``solver/tracking/data/generic_body_poses.npz``: starting hypotheses
for the first frame of a tracked recording when the model has few poses of its own (docs/track.md
"Pipeline").

    python tools/make_generic_poses.py [--out PATH] [--shapes S,S] [--walk N] [--seed S]

``--walk`` frames spread over MPFB2's walk cycle (``walkcycles/crappy_experimental_female.json``, CC0) on
each MakeHuman body of ``--shapes`` with MPFB2's ``cmu_mb`` rig (sample_scenes), root rotation and
translation reset (the initialisation searches the facing and position).  Stored: the rig's bone names,
rest frames, and the bone-local rotations (quaternions w, x, y, z), format "articula-body-poses/1".
"""
import argparse
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / ".pkgroot"))
from articula.sample_scenes.subjects import make_subject  # noqa: E402
from articula.sample_scenes.walk import CYCLE_FRAMES, walk_poses  # noqa: E402
from articula.solver.tracking.body_poses import GENERIC_POSES_PATH  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=GENERIC_POSES_PATH)
    ap.add_argument("--shapes", default="average,female", help="MakeHuman shape presets, comma-separated")
    ap.add_argument("--walk", type=int, default=6, help="walk-cycle frames per body")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    shapes = args.shapes.split(",")
    rotations = []
    for i, shape in enumerate(shapes):
        poses = walk_poses(make_subject("cmu_mb", shape), args.walk, seed=args.seed + i,
                           step=CYCLE_FRAMES / args.walk)
        rotations.append(poses.rotations)
    rotations = np.concatenate(rotations)
    rotations[:, 0] = (1.0, 0.0, 0.0, 0.0)
    skeleton = make_subject("cmu_mb").skeleton
    info = {"source": "MPFB2 (MakeHuman) walk cycle crappy_experimental_female.json on MakeHuman bodies "
                      f"{'/'.join(shapes)}", "licence": "CC0 1.0 (MPFB2 assets)", "rig": "cmu_mb",
            "poses": f"{args.walk} x {len(shapes)}", "seed": args.seed, "tool": "tools/make_generic_poses.py"}
    np.savez_compressed(args.out, format=np.array("articula-body-poses/1"), names=np.array(skeleton.names),
                        frames=skeleton.frames, rotations=rotations, info=np.array(json.dumps(info)))
    print(f"{len(rotations)} poses -> {args.out} ({Path(args.out).stat().st_size / 1024:.1f} kB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
