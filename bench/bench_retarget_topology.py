"""Retargeting through shared mesh topology: fit RMS (mm) vs copying joint angles, time per frame.

Retargeting through shared topology (solver.retarget.topology; dissertation (model-adaptive mocap)
Sec. 4.2.3, test A2) on MakeHuman subjects of one rig: posed-vertex RMS of the correspondence fit against
parameter copying, and wall time per frame.

The source is the female,thin subject walking (sample_scenes walk, ``frames`` frames); targets: the same
body (both must be 0), male,heavy (the same height macro, another shape), and male,heavy,tall (27 %
taller) without and with the height ratio.  RMS is the per-frame RMS distance (mm) of the target's posed
vertices from the vertices it is fitted to, averaged over frames (max in brackets).

Usage: ``./run bench retarget_topology [frames]``; ``./run bench retarget`` prints the same lines
(:func:`topology_lines`).
"""
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))   # the bench command loads us by path
import _common  # noqa: F401,E402  (makes ``import articula`` work)

from articula.sample_scenes.registered import make_poses
from articula.sample_scenes.subjects import make_subject
from articula.solver.retarget.topology import retarget_topology

RIG = "cmu_mb"
SOURCE = "female,thin"
CASES = (("identical", SOURCE, None), ("other shape", "male,heavy", None),
         ("taller", "male,heavy,tall", None), ("taller, height ratio", "male,heavy,tall", "height"))


def _line(name, value, unit="", note=""):
    """One result line in the format of ``_common.report``."""
    text = f"{value:.4g}" if isinstance(value, float) else str(value)
    return f"{name}: {text} {unit}".rstrip() + (f"  ({note})" if note else "")


def _mm(values):
    return f"{1e3 * values.mean():.3g} mm (max {1e3 * values.max():.3g})"


def topology_lines(frames: int = 60) -> list:
    """Result lines of the benchmark (module docstring)."""
    t0 = time.perf_counter()
    source = make_subject(RIG, SOURCE)
    src_model = source.hybrid_model()
    poses = make_poses(source, "walk", frames, 0)
    lines = [_line("topology setup", time.perf_counter() - t0, "s",
                   f"{RIG} rig, {src_model.num_vertices} vertices, {src_model.skeleton.num_bones} bones, "
                   f"source {SOURCE} walking, {frames} frames")]
    for label, shape, scale in CASES:
        tgt_model = make_subject(RIG, shape).hybrid_model()
        _, rep = retarget_topology(src_model, poses, tgt_model, scale=scale)
        per_frame = 1e3 * rep["seconds"] / frames
        lines.append(_line(f"topology {label} ({shape}) fit RMS", _mm(rep["rms_fit"]), "",
                           f"parameter copying {_mm(rep['rms_copy'])}; rest meshes {1e3 * rep['rms_rest']:.3g} mm "
                           f"apart; scale {rep['scale']:.3f}; {int(rep['from_copy'].sum())}/{frames} frames "
                           f"started from the copy; root {_mm(rep['root_offset'])} from the copied one"))
        lines.append(_line(f"topology {label} wall time", per_frame, "ms/frame",
                           f"{rep['iterations'].mean():.1f} LM iterations per frame, "
                           f"{int(rep['converged'].sum())}/{frames} converged"))
    return lines


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    frames = int(argv[0]) if argv else 60
    for line in topology_lines(frames):
        print(line, flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
