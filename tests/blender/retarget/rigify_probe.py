"""Retarget a CMU BVH onto Rigify's generated human in a Blender of its own and report, as JSON, what the
test checks.

    python rigify_probe.py <bvh> <out.json>

Run in a subprocess by ``test_skeleton_retarget.py``: the bpy 4.2 module crashes at interpreter exit once
Rigify was enabled, so this process leaves with ``os._exit`` after writing its report (the crash is
Blender's, at teardown; every number is written before it).
"""
import importlib
import json
import os
import sys

BVH, OUT = sys.argv[1:3]
REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
sys.path.insert(0, REPO)

import bpy  # noqa: E402
import addon_utils  # noqa: E402
import numpy as np  # noqa: E402

import batch  # noqa: E402

addon_utils.enable("rigify", default_set=True)
pkg_name = batch.enable_addon(bpy)


def pkg(name):
    return importlib.import_module(f"{pkg_name}.{name}")


def main():
    sys.path.insert(0, batch.dev_package_root())                  # the checkout as ``articula``
    from articula.bench import _retarget_metrics as metrics
    world_pose = pkg("solver.retarget.armature").world_pose
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.object.armature_human_metarig_add()
    bpy.ops.pose.rigify_generate()
    bpy.ops.object.mode_set(mode='OBJECT')
    rig = bpy.data.objects["rig"]
    for name in ("upper_arm_parent.L", "upper_arm_parent.R", "thigh_parent.L", "thigh_parent.R"):
        rig.pose.bones[name]["IK_FK"] = 1.0                         # the limbs follow their FK controls
    bpy.ops.import_anim.bvh(filepath=BVH, global_scale=0.056444, frame_start=1)
    source = bpy.context.active_object
    action = source.animation_data.action
    action.use_frame_range, action.frame_start, action.frame_end = True, 1, 12
    skeleton = pkg("addon.retarget.skeleton")
    mapping, _, found = skeleton.auto_mapping(source, rig)
    _, report = skeleton.retarget(bpy.context, source, rig)
    frames = np.arange(1, 13)
    read = pkg("addon.retarget.armatures").read_rest
    pose_from_scene = pkg("addon.retarget.source_clip").pose_from_scene
    src, tgt = read(source), read(rig)
    _, hs = world_pose(src, pose_from_scene(source, src, frames))
    _, ht = world_pose(tgt, pose_from_scene(rig, tgt, frames))
    angles = metrics.role_segment_angles(mapping.pairs(), src.index, tgt.index, hs, ht, trunk=False)
    return {"preset": found.preset, "upper_arm.L": mapping.pairs()["upper_arm.L"][1],
            "solved": report["target_solved"], "segments": len(angles),
            "max_angle": max(float(a.max()) for a in angles.values()),
            "shoulder": "shoulder.L-upper_arm.L" in angles}


try:
    result = main()
except Exception as exc:  # reported to the test, which fails with it
    import traceback
    result = {"error": f"{exc!r}", "traceback": traceback.format_exc()}
with open(OUT, "w") as fh:
    json.dump(result, fh)
sys.stdout.flush()
sys.stderr.flush()
os._exit(0)
