"""The picture of docs/gaze.md: before/after ``articula.gaze`` on the Articula template body moved by a
CMU clip (the retargeted motion of ``./run bench gaze``) and on MakeHuman's default rig with an idle
(bones drawn as tubes), each looking at a ball beside its head; the same frame without and with the gaze
layer.

    ~/.cache/articula/venv-bpy52/bin/python tools/gaze_picture.py docs/images/gaze.png [--frame 400]
        [--tracked out/tracked_depth.blend]
"""
import argparse
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "bench"))
sys.path.insert(0, HERE)
import bench_gaze  # noqa: E402  (sets up ``import articula`` and the add-on)

import bpy  # noqa: E402
import numpy as np  # noqa: E402
from mathutils import Vector  # noqa: E402
from retarget_picture import bone_tubes, frozen_mesh  # noqa: E402


def _sphere(location, name):
    me = bpy.data.meshes.new(name)
    import bmesh
    bm = bmesh.new()
    bmesh.ops.create_uvsphere(bm, u_segments=16, v_segments=8, radius=0.08)
    bm.to_mesh(me)
    bm.free()
    ob = bpy.data.objects.new(name, me)
    ob.location = location
    bpy.context.scene.collection.objects.link(ob)
    return ob


def _target_beside_head(arm, frame, name):
    """An empty 0.8 m to the character's left, 0.6 m ahead and 0.3 m above its head at ``frame``."""
    bpy.context.scene.frame_set(frame)
    head = next(pb for pb in arm.pose.bones if pb.name.lower() == "head")
    ob = bpy.data.objects.new(name + " target", None)
    ob.location = arm.matrix_world @ head.head + Vector((0.8, -0.6, 0.3))
    bpy.context.scene.collection.objects.link(ob)
    return ob


def _snapshot(pkg, arm, mesh, target, frame, label, shift):
    """Static copies (body or tubes, and the target) at ``frame``, moved by ``shift`` along x."""
    bpy.context.scene.frame_set(frame)
    body = frozen_mesh(mesh, label) if mesh is not None else bone_tubes(arm, label)
    ball = _sphere(target.matrix_world.translation.copy(), label + " target")
    for ob in (body, ball):
        ob.location += Vector((shift, 0.0, 0.0))
    return [body, ball]


def main(argv=None):
    p = argparse.ArgumentParser()
    p.add_argument("out")
    p.add_argument("--frame", type=int, default=400)
    p.add_argument("--tracked", default="", help="a tracked .blend (./run track --depth ... --blend FILE) whose "
                                                 "rig is shown instead of the template body with a CMU clip")
    args = p.parse_args(argv)
    pkg = bench_gaze._addon()
    if args.tracked:
        bpy.ops.wm.open_mainfile(filepath=os.path.abspath(args.tracked))
        body = next(o for o in bpy.data.objects if o.type == 'ARMATURE' and o.articula.kind == 'RIG_ARMATURE')
        first, last = pkg("addon.gaze.shot").animation_range(body)
        args.frame = min(max(args.frame, first), last)
        title = "tracked person"
    else:
        bpy.ops.wm.read_homefile(use_empty=True)
        body = bench_gaze.tracked_body(pkg)
        title = "template body"
    mesh = pkg("addon.rig.reader").find_mesh(body)
    idle = bench_gaze.idle_rig(pkg)
    shots = []
    for arm, m, frame, title in ((body, mesh, args.frame, title), (idle, None, 100, "MakeHuman default, idle")):
        target = _target_beside_head(arm, frame, title)
        first, last = pkg("addon.gaze.shot").animation_range(arm)
        before = _snapshot(pkg, arm, m, target, frame, f"{title}: before", 0.0)
        pkg("addon.gaze.shot").apply_shot(bpy.context, arm, target, first, last, 10)
        after = _snapshot(pkg, arm, m, target, frame, f"{title}: looking at the ball", 0.0)
        shots += [(f"{title}: before", before), (f"{title}: looking at the ball", after)]
    exhibits = {}
    bpy.context.view_layer.update()
    for i, (title, objects) in enumerate(shots):
        box = [objects[0].matrix_world @ Vector(c) for c in objects[0].bound_box]
        lo, hi = np.min(box, axis=0), np.max(box, axis=0)
        move = Vector((2.2 * i - (lo[0] + hi[0]) / 2, -(lo[1] + hi[1]) / 2, -lo[2]))
        for ob in objects:
            ob.location += move
        exhibits[title] = objects
    for ob in bpy.data.objects:
        if not any(ob in group for group in exhibits.values()):
            ob.hide_render = True
    pkg("addon.scene.render").render_overview(bpy.context.scene, os.path.abspath(args.out), exhibits,
                                              width=1500, height=560)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main(sys.argv[1:])
