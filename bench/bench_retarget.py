"""Retargeting benchmark: ``./run bench retarget [--quick] [--no-topology] [--no-scan]``.

Skeleton retargeting of the CMU BVH clips in ../shared/data/mocap (both naming styles, T-pose, imported
with Blender's own importer at CMU's scale) onto MakeHuman's A-pose rigs (default 163 bones with twist
segments, game_engine = the Unreal mannequin, cmu_mb, mixamo) and onto Articula rigs (the template body
built as an exact swing/twist rig; a rig learned from registered scans when ``--learned`` is given):

* segment directions: angle between every mapped source and target segment, both read back from
  Blender's evaluated poses at every frame (targets: mean <= 3 deg, 95th percentile <= 10 deg);
* root travel: the target hips' horizontal path length / (source's x leg-length ratio) (target: within 10 %);
* foot sliding: the ankle's horizontal path during the source's foot contacts, in cm, clean-up off and on;
* speed: 1,000 frames onto the 163-bone MakeHuman default rig, operator wall time (target <= 5 s).

Then the shared-topology fit (:mod:`_retarget_topology`) and the scan binding (:mod:`_scan_binding`).
"""
import importlib
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))   # the bench command loads us by path
import _common  # noqa: E402  (makes ``import articula`` work)

import bpy  # noqa: E402
import numpy as np  # noqa: E402

from articula.sample_scenes import mpfb_armature  # noqa: E402
from articula.solver.retarget import directions, foot_plant, metrics  # noqa: E402
from articula.solver.retarget.armature import world_pose  # noqa: E402
from articula.solver.retarget.roles import LEG_ROLES  # noqa: E402

MOCAP = os.path.join(os.path.dirname(os.path.realpath(_common.REPO)), "shared", "data", "mocap")
CLIPS = ("cmu_01_01", "cmu_131_01")
RIGS = ("default", "game_engine", "cmu_mb", "mixamo")
CMU_SCALE = 0.056444


def _addon():
    """``pkg(name)`` importing a submodule of the enabled extension (the one whose operators run)."""
    sys.path.insert(0, _common.REPO)
    import batch
    mod = batch.enable_addon(bpy)
    return lambda name: importlib.import_module(f"{mod}.{name}")


def _bvh(name):
    path = os.path.join(MOCAP, name + ".bvh")
    if not os.path.isfile(path):
        raise SystemExit(f"missing {path} (../shared/data/mocap)")
    bpy.ops.import_anim.bvh(filepath=path, global_scale=CMU_SCALE, frame_start=1)
    return bpy.context.active_object


def _mpfb(pkg, rig):
    d = mpfb_armature.rig_bones(rig)
    return pkg("addon.retarget.armature_builder").new_armature(
        bpy.context, f"MPFB {rig}", d["names"], d["parents"], d["heads"], d["tails"], d["rolls"])


def _articula_template(pkg):
    from articula.solver.track_depth.template import load_template
    rig = pkg("addon.rig.builder").build_rig(bpy.context, load_template().base, "Articula template")
    return rig.armature


def _evaluated(pkg, ob, frames):
    rest = pkg("addon.retarget.armatures").read_rest(ob)
    return rest, world_pose(rest, pkg("addon.retarget.source_clip").pose_from_scene(ob, rest, frames))


def _sliding_cm(pkg, source, target, mapping, frames, fps):
    """Mean ankle slide (cm) over the source's contacts, per side, read from the evaluated target."""
    src, (_, hs) = _evaluated(pkg, source, frames)
    tgt, (_, ht) = _evaluated(pkg, target, frames)
    pairs = mapping.pairs()
    leg = pkg("solver.retarget.root_motion").leg_length(src, {r: s for r, (s, _) in pairs.items()})
    out = []
    for side, (_, _, foot) in LEG_ROLES.items():
        ranges = foot_plant.contacts(hs[:, src.index[pairs[foot][0]]], leg, fps)
        out.append(100 * foot_plant.sliding(ht[:, tgt.index[pairs[foot][1]]], ranges))
    return float(np.mean(out))


def measure(pkg, clip, target, label):
    """One result line for ``clip`` retargeted onto ``target`` (fresh actions each time)."""
    source = bpy.data.objects[clip]
    skeleton = pkg("addon.retarget.skeleton")
    fps = bpy.context.scene.render.fps
    t0 = time.perf_counter()
    bpy.ops.articula.retarget(source=source.name, target=target.name)
    seconds = time.perf_counter() - t0
    first, last = (int(x) for x in target.animation_data.action.frame_range)
    frames = np.arange(first, last + 1)
    mapping, *_ = skeleton.auto_mapping(source, target)
    src, (_, hs) = _evaluated(pkg, source, frames)
    tgt, (_, ht) = _evaluated(pkg, target, frames)
    angles = metrics.segment_angles(directions.plan_segments(src, tgt, mapping.pairs()), hs, ht)
    report = skeleton.retarget(bpy.context, source, target)[1]
    hips_s, hips_t = (a.index[mapping.pairs()["hips"][k]] for k, a in ((0, src), (1, tgt)))
    travel = metrics.travel(ht[:, hips_t]) / (report["leg_ratio"] * metrics.travel(hs[:, hips_s]))
    slide_off = _sliding_cm(pkg, source, target, mapping, frames, fps)
    bpy.ops.articula.retarget(source=source.name, target=target.name, foot_cleanup=True)
    slide_on = _sliding_cm(pkg, source, target, mapping, frames, fps)
    return (f"{clip} -> {label}: {len(frames)} frames, {angles.shape[1]} segments, angle mean "
            f"{angles.mean():.4f} deg p95 {np.percentile(angles, 95):.4f} max {angles.max():.4f}; travel / "
            f"(source x leg ratio {report['leg_ratio']:.3f}) = {travel:.4f}; foot sliding {slide_off:.2f} cm -> "
            f"{slide_on:.2f} cm with clean-up; {seconds:.2f} s")


def speed_line(pkg) -> str:
    """1,000 frames of cmu_01_01 onto the 163-bone MakeHuman default rig (operator wall time)."""
    source = bpy.data.objects["cmu_01_01"]
    action = source.animation_data.action
    action.use_frame_range, action.frame_start, action.frame_end = True, 1, 1000
    target = _mpfb(pkg, "default")
    runs = []
    for _ in range(3):
        t0 = time.perf_counter()
        bpy.ops.articula.retarget(source=source.name, target=target.name)
        runs.append(time.perf_counter() - t0)
    action.use_frame_range = False
    best = min(runs)
    return (f"speed: 1000 frames onto {len(target.data.bones)} bones: best {best:.2f} s of 3 "
            f"({', '.join(f'{r:.2f}' for r in runs)}); ratio to the 5 s target {best / 5.0:.3f}")


def main(argv=None) -> int:
    argv = list(argv or [])
    pkg = _addon()
    bpy.ops.wm.read_homefile(use_empty=True)
    clips = CLIPS[1:] if "--quick" in argv else CLIPS
    for clip in clips:
        _bvh(clip)
    lines = []
    targets = [(_mpfb(pkg, rig), f"MPFB {rig}") for rig in (RIGS[:2] if "--quick" in argv else RIGS)]
    targets.append((_articula_template(pkg), "Articula template rig"))
    for clip in clips:
        for target, label in targets:
            lines.append(measure(pkg, clip, target, label))
            print(lines[-1], flush=True)
    if "--quick" not in argv:
        lines.append(speed_line(pkg))
        print(lines[-1], flush=True)
    if "--no-topology" not in argv:
        from _retarget_topology import topology_lines
        for line in topology_lines():
            print(line, flush=True)
    if "--no-scan" not in argv:
        from _scan_binding import scan_binding_lines
        for line in scan_binding_lines():
            print(line, flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
