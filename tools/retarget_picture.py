"""The picture of docs/retarget.md: one frame of a CMU walk (BVH, T-pose rest) retargeted by
``articula.retarget`` onto MakeHuman's default rig and the Unreal-style game_engine rig (A-pose rests,
other rolls, twist bones) and onto the Articula template body, shown side by side (bones drawn as tubes,
the body as its posed mesh).

    ~/.cache/articula/venv-bpy52/bin/python tools/retarget_picture.py ../shared/data/mocap/cmu_01_01.bvh \\
        docs/images/retarget.png [--frame 140]
"""
import argparse
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "bench"))
import _common  # noqa: E402,F401  (makes ``import articula`` work)
from _armatures import new_armature  # noqa: E402

import bpy  # noqa: E402
import bmesh  # noqa: E402  (after bpy: the bpy module provides it)
import numpy as np  # noqa: E402
from mathutils import Matrix, Vector  # noqa: E402


def _pkg():
    return _common.addon_modules(bpy)


def bone_tubes(ob, name, radius=0.012):
    """A static mesh of one tube per bone of armature ``ob`` in its current (evaluated) pose (a floor
    root bone that stays behind when the hips walk away is left out)."""
    bm = bmesh.new()
    for pb in ob.pose.bones:
        if pb.parent is None and len(pb.children) == 1 and pb.children[0].head.z > 5 * pb.head.z + 0.2:
            continue
        head, tail = ob.matrix_world @ pb.head, ob.matrix_world @ pb.tail
        length = (tail - head).length
        if length < 1e-4:
            continue
        rot = (tail - head).to_track_quat('Z', 'Y').to_matrix().to_4x4()
        m = Matrix.Translation((head + tail) / 2) @ rot
        bmesh.ops.create_cone(bm, cap_ends=True, segments=8, radius1=radius, radius2=radius * 0.6,
                              depth=length, matrix=m)
    me = bpy.data.meshes.new(name)
    bm.to_mesh(me)
    bm.free()
    out = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(out)
    return out


def frozen_mesh(ob, name):
    """A static copy of mesh object ``ob`` as evaluated now (its rig's pose applied)."""
    dg = bpy.context.evaluated_depsgraph_get()
    me = bpy.data.meshes.new_from_object(ob.evaluated_get(dg))
    out = bpy.data.objects.new(name, me)
    out.matrix_world = ob.matrix_world
    bpy.context.scene.collection.objects.link(out)
    return out


def _place(ob, x):
    """Move ``ob`` so its bounding box's centre is at x = ``x``, y = 0."""
    lo = np.min([ob.matrix_world @ Vector(c) for c in ob.bound_box], axis=0)
    hi = np.max([ob.matrix_world @ Vector(c) for c in ob.bound_box], axis=0)
    ob.location += Vector((x - (lo[0] + hi[0]) / 2, -(lo[1] + hi[1]) / 2, -lo[2]))


def main(argv=None):
    p = argparse.ArgumentParser()
    p.add_argument("bvh")
    p.add_argument("out")
    p.add_argument("--frame", type=int, default=140)
    args = p.parse_args(argv)
    pkg = _pkg()
    from articula.sample_scenes import mpfb_armature
    from articula.solver.track_depth.template import load_template
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.import_anim.bvh(filepath=os.path.abspath(args.bvh), global_scale=0.056444, frame_start=1)
    source = bpy.context.active_object
    targets = []
    for rig, title in (("default", "MakeHuman default rig"), ("game_engine", "game_engine / Unreal rig")):
        d = mpfb_armature.rig_bones(rig)
        arm = new_armature(
            bpy.context, title, d["names"], d["parents"], d["heads"], d["tails"], d["rolls"])
        targets.append((arm, title, None))
    body = pkg("addon.rig.builder").build_rig(bpy.context, load_template().base, "Articula body")
    targets.append((body.armature, "Articula template body", body.mesh))
    for arm, _, _ in targets:
        bpy.ops.articula.retarget(source=source.name, target=arm.name, foot_cleanup=True)
    bpy.context.scene.frame_set(args.frame)
    exhibits = {"CMU BVH (T-pose rest)": [bone_tubes(source, "source tubes")]}
    for arm, title, mesh in targets:
        exhibits[title] = [frozen_mesh(mesh, title + " posed") if mesh else bone_tubes(arm, title + " tubes")]
    for ob in bpy.data.objects:
        if not any(ob in group for group in exhibits.values()):
            ob.hide_render = True
    for i, group in enumerate(exhibits.values()):
        _place(group[0], 1.1 * i)
    pkg("addon.scene.render").render_overview(bpy.context.scene, os.path.abspath(args.out), exhibits,
                                              width=1400, height=560)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main(sys.argv[1:])
