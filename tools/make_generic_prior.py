"""Build the generic human pose prior shipped as ``solver/track/data/generic_human_prior.npz``.

    python tools/make_generic_prior.py [--out PATH] [--shapes S,S,..] [--walk N] [--rom N] [--k-max K]
                                       [--margin M] [--min-sd DEG] [--seed S]

Training poses with MPFB2's ``cmu_mb`` rig on MakeHuman bodies (sample_scenes): ``--walk`` frames of
MPFB2's walk cycle (``walkcycles/crappy_experimental_female.json``, CC0, spread evenly over the 40-frame
cycle, a different phase per body) retargeted to each body of ``--shapes`` (the walk's joint angles
depend on the body's proportions, so one body's walk does not cover another's), and ``--rom`` random
range-of-motion poses of the default body within sample_scenes' anatomical joint limits.  The prior keeps
the default body's rest frames.
The box limits are widened by ``--margin`` (10 % of each interval on each side by default: the prior
serves bodies it was not learned on), and every covariance has at least ``--min-sd`` degrees of standard
deviation per DoF (the walk frames lie on a curve: tighter components fit that curve but not another
body's walk; docs/track.md).
MPFB2's own ``poses/`` folder holds only a T-pose per rig, so the walk cycle and the range-of-motion set
are the whole pose material available there (docs/track.md).  The provenance (source, licence, rig,
pose counts) is stored in the file's info.  Takes a few minutes (leave-one-out over every pair).
"""
import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / ".pkgroot"))
from articula.sample_scenes.poses import rom_poses  # noqa: E402
from articula.sample_scenes.subjects import make_subject  # noqa: E402
from articula.sample_scenes.walk import CYCLE_FRAMES, walk_poses  # noqa: E402
from articula.solver.rig.model import Poses  # noqa: E402
from articula.solver.tracking.pose_prior import GENERIC_PATH, PosePrior  # noqa: E402


def training_poses(shapes, n_walk: int, n_rom: int, seed: int) -> Poses:
    """Walk-cycle frames of each body shape, then range-of-motion poses of the default body (root
    rotations kept; the prior does not use bone 0)."""
    sets = [walk_poses(make_subject("cmu_mb", shape), n_walk, seed=seed + i, step=CYCLE_FRAMES / n_walk)
            for i, shape in enumerate(shapes)]
    sets.append(rom_poses(make_subject("cmu_mb").skeleton, n_rom, seed=seed))
    n = sum(len(p) for p in sets)
    return Poses(np.concatenate([p.rotations for p in sets]), np.concatenate([p.translations for p in sets]),
                 np.ones(n))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=GENERIC_PATH)
    ap.add_argument("--shapes", default="average,female,male,heavy,thin",
                    help="MakeHuman shape presets of the walking bodies, comma-separated")
    ap.add_argument("--walk", type=int, default=10, help="walk-cycle frames per body")
    ap.add_argument("--rom", type=int, default=100, help="range-of-motion poses")
    ap.add_argument("--k-max", type=int, default=6)
    ap.add_argument("--margin", type=float, default=0.1, help="box widening, fraction of each interval")
    ap.add_argument("--min-sd", type=float, default=2.0, help="smallest standard deviation, degrees")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    subject = make_subject("cmu_mb")
    shapes = args.shapes.split(",")
    poses = training_poses(shapes, args.walk, args.rom, args.seed)
    start = time.time()
    prior = PosePrior.from_poses(subject.skeleton, poses, k_max=args.k_max, margin=args.margin,
                                  seed=args.seed, min_variance=np.radians(args.min_sd) ** 2)
    prior.info.update(source="MPFB2 (MakeHuman) walk cycle crappy_experimental_female.json on MakeHuman bodies "
                             f"{'/'.join(shapes)} + sample_scenes range-of-motion poses (anatomical limits) "
                             "of the default body",
                      licence="CC0 1.0 (MPFB2 assets)", rig="cmu_mb", walk_poses=f"{args.walk} x {len(shapes)}",
                      rom_poses=str(args.rom), seed=str(args.seed),
                      min_sd_deg=str(args.min_sd), tool="tools/make_generic_prior.py")
    prior.save(args.out)
    names = subject.skeleton.names
    for (a, c), k, s in zip(prior.pairs, prior.components, prior.loo_scores):
        print(f"{names[a]:>14} -> {names[c]:<14} K={k}  mean held-out log-likelihood {s:.2f}")
    print(f"{len(poses)} poses, {len(prior.pairs)} pairs, {time.time() - start:.0f} s -> {args.out} "
          f"({Path(args.out).stat().st_size / 1024:.1f} kB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
