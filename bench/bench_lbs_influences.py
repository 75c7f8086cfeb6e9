"""Linear-blend export with 4 or 8 influences per vertex: deviation from the exact rig (mm).

Linear-blend export with a limited number of influences per vertex (``solver.rig.linear_blend``): the
deviation from the exact swing/twist rig (max / mean over all vertices and poses, mm) of the unlimited weights,
of truncate-and-renormalise (what glTF/FBX exporters do) and of the optimised limited weights, at 4 and 8
influences, on the MakeHuman subject (cmu_mb female, 4 twist segments): on the seeded poses the weights are
fitted to, and on the held-out seeded poses the operator reports.

Usage: ./run bench lbs_influences [--segments 4]
"""
import argparse
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))   # bench_cli loads us by path
import _common  # noqa: E402  (makes ``import articula`` work)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="bench lbs_influences")
    p.add_argument("--segments", type=int, default=4)
    args = p.parse_args(argv)
    from articula.sample_scenes.subjects import make_subject
    from articula.solver.rig import influences, linear_blend as lb
    model = make_subject("cmu_mb", "female").hybrid_model()
    B = model.skeleton.num_bones
    fit, held_out = lb.sample_poses(B, lb.FIT_SEED), lb.sample_poses(B, lb.MEASURE_SEED)
    unlimited = lb.lbs_weights(model, args.segments)[1]
    weights = {"unlimited": unlimited}
    for k in (4, 8):
        weights[f"k={k} truncated"] = influences.truncate(unlimited, k)
        t0 = time.perf_counter()
        weights[f"k={k} optimised"] = lb.limited_weights(model, args.segments, k, fit)[1]
        _common.report(f"k={k} optimised weights: fit time", time.perf_counter() - t0, "s", "wall")
    print(f"MakeHuman cmu_mb female: {model.num_vertices} vertices, {B} bones, {args.segments} segments")
    for label, poses in ((f"fitted poses (seed {lb.FIT_SEED})", fit), (f"held-out poses (seed {lb.MEASURE_SEED})", held_out)):
        for name, W in weights.items():
            worst, mean = lb.deviation(model, poses, args.segments, weights=W)
            _common.report(f"{label}, {name}: max", float(worst.max()) * 1e3, "mm", f"mean {mean * 1e3:.3f} mm")
    return 0


if __name__ == "__main__":
    sys.exit(main())
