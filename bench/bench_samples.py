"""Time to generate registered sample sequences (OBJ/PLY files and ground truth), per skin.

Usage: ``./run bench samples [--poses N] [--rig R]``.

Reports, per skin, the in-memory posing time (``posed_sequence``) and the full ``generate_registered``
time (OBJ and PLY files + ground_truth.npz, + model bundle for hybrid) for N poses (default 30), and
the walk cycle (hybrid skin) in memory."""
import argparse
import os
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))   # bench_cli loads us by path
import _common  # noqa: E402  (makes ``import articula`` work)

from articula.sample_scenes import registered
from articula.sample_scenes.subjects import make_subject


def _timed(fn, *args, **kwargs):
    t0 = time.perf_counter()
    fn(*args, **kwargs)
    return time.perf_counter() - t0


def main(argv) -> int:
    parser = argparse.ArgumentParser(prog="bench samples")
    parser.add_argument("--poses", type=int, default=30)
    parser.add_argument("--rig", default="cmu_mb")
    args = parser.parse_args(argv)
    make_subject(args.rig, "female,heavy")                  # warm the asset caches
    _common.report("make_subject", _timed(make_subject, args.rig, "male,thin"), "s", args.rig)
    for skin in registered.SKINS:
        t = _timed(registered.posed_sequence, args.rig, "female,heavy", args.poses, skin=skin, seed=0)
        _common.report(f"posed_sequence {skin}", t, "s", f"{args.poses} poses in memory")
        for fmt in ("obj", "ply"):
            with tempfile.TemporaryDirectory() as out:
                t = _timed(registered.generate_registered, out, args.rig, "female,heavy", args.poses,
                           skin=skin, fmt=fmt, seed=0)
            _common.report(f"generate_registered {skin} {fmt}", t, "s", f"{args.poses} files + ground truth")
    t = _timed(registered.posed_sequence, args.rig, "female,heavy", args.poses, motion="walk", skin="hybrid")
    _common.report("posed_sequence hybrid walk", t, "s", f"{args.poses} poses in memory (IK retargeting)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
