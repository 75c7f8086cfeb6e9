"""``articula.gaze`` in Blender (spec test A1 on real rigs): a MakeHuman rig moved by a retargeted CMU clip
looks at a moving target within 1 deg in Blender's evaluated pose at full strength; chest, neck and head
share the turn 10/40/50 %; frames outside the shot and the animation's keys are bit-identical; Euler rigs,
Articula rigs (annotated gaze line), stacked shots; refusals; the batch command."""
import os

import bpy
import numpy as np
import pytest

from articula.bench._armatures import new_armature
from articula.sample_scenes import mpfb_armature
from articula.solver.gaze.aim import gaze_line
from articula.solver.geometry.rotations import matrix_to_quat, quat_to_rotvec
from ...conftest import SHARED_DATA

BVH = os.path.join(SHARED_DATA, "mocap", "cmu_131_01.bvh")


def bvh(last=120):
    assert os.path.isfile(BVH), f"missing fixture {BVH}"
    bpy.ops.import_anim.bvh(filepath=BVH, global_scale=0.056444, frame_start=1)
    ob = bpy.context.active_object
    a = ob.animation_data.action
    a.use_frame_range, a.frame_start, a.frame_end = True, 1, last
    return ob


def hero(pkg, rig="default"):
    """A MakeHuman rig moved by the first 120 frames of a CMU clip (quaternion channels)."""
    source = bvh()
    d = mpfb_armature.rig_bones(rig)
    ob = new_armature(
        bpy.context, "Hero", d["names"], d["parents"], d["heads"], d["tails"], d["rolls"])
    assert bpy.ops.articula.retarget(source=source.name, target=ob.name) == {'FINISHED'}
    return ob


def moving_target(first=1, last=120):
    ob = bpy.data.objects.new("Look", None)
    bpy.context.scene.collection.objects.link(ob)
    ob.location = (1.5, -2.5, 1.7)
    ob.keyframe_insert("location", frame=first)
    ob.location = (-1.5, -2.0, 1.2)
    ob.keyframe_insert("location", frame=last)
    return ob


def evaluated(pkg, ob, frames):
    rest = pkg("addon.retarget.armatures").read_rest(ob)
    return rest, pkg("addon.retarget.source_clip").pose_from_scene(ob, rest, frames)


def keys(pkg, ob, action):
    out = []
    for fc in pkg("addon.compat").object_action_fcurves(ob, action):
        co = np.empty(2 * len(fc.keyframe_points), np.float32)
        fc.keyframe_points.foreach_get("co", co)
        out.append(co)
    return out


def test_gaze_meets_a_moving_target_with_the_split_and_leaves_the_rest(pkg):
    ob = hero(pkg)
    ob.location.x += 2.0                    # moved by a script just before: the gaze must see it moved
    target = moving_target()
    action = ob.animation_data.action
    before_keys = keys(pkg, ob, action)
    frames = np.arange(1, 121)
    rest, before = evaluated(pkg, ob, frames)
    assert bpy.ops.articula.gaze(armature=ob.name, target=target.name, frame_start=20, frame_end=100,
                                 fade_frames=10) == {'FINISHED'}
    _, after = evaluated(pkg, ob, frames)
    outside = (frames < 20) | (frames > 100)
    assert np.array_equal(after[outside], before[outside])
    assert all(np.array_equal(a, b) for a, b in zip(keys(pkg, ob, action), before_keys))
    chain, eyes, how = pkg("addon.gaze.chain").gaze_chain(ob, rest)
    full = (frames >= 30) & (frames <= 90)
    p, d = gaze_line(rest, after[full], chain)
    goal = rest.armature_points(pkg("addon.gaze.shot").target_path(bpy.context, target, frames[full])) - p
    cos = np.einsum("fi,fi->f", d, goal) / np.linalg.norm(goal, axis=1)
    assert np.degrees(np.arccos(np.clip(cos, -1, 1))).max() < 1.0
    turns = []
    for j in chain.joints:
        P = before[full][:, rest.parents[j], :3, :3] @ rest.relative_rest()[j][:3, :3]
        Lb = np.linalg.solve(P, before[full][:, j, :3, :3])          # pose-bone rotations, read back
        La = np.linalg.solve(after[full][:, rest.parents[j], :3, :3] @ rest.relative_rest()[j][:3, :3],
                             after[full][:, j, :3, :3])
        turns.append(np.linalg.norm(quat_to_rotvec(matrix_to_quat(P @ La @ np.linalg.inv(Lb) @
                                                                  np.swapaxes(P, 1, 2))), axis=1))
    turns = np.stack(turns, axis=1)
    big = turns.sum(axis=1) > np.radians(5)
    assert big.any()
    assert np.abs(turns[big] / turns[big].sum(axis=1, keepdims=True) - [0.1, 0.4, 0.5]).max() < 1e-3


def test_euler_rig_and_stacked_shots(pkg):
    ob = bvh()
    target = moving_target()
    for first, last in ((10, 50), (60, 110)):
        assert bpy.ops.articula.gaze(armature=ob.name, target=target.name, frame_start=first, frame_end=last,
                                     fade_frames=5) == {'FINISHED'}
    tracks = [t for t in ob.animation_data.nla_tracks if t.name.startswith("Articula Gaze")]
    assert len(tracks) == 1 and len(tracks[0].strips) == 2
    assert bpy.ops.articula.gaze(armature=ob.name, target=target.name, frame_start=40, frame_end=70,
                                 fade_frames=5) == {'FINISHED'}
    tracks = [t for t in ob.animation_data.nla_tracks if t.name.startswith("Articula Gaze")]
    assert len(tracks) == 2


def test_articula_rig_uses_the_annotated_gaze_line(pkg):
    from articula.solver.track_depth.template import load_template
    rig = pkg("addon.rig.builder").build_rig(bpy.context, load_template().base, "Body")
    target = moving_target()
    rest = pkg("addon.retarget.armatures").read_rest(rig.armature)
    chain, eyes, how = pkg("addon.gaze.chain").gaze_chain(rig.armature, rest)
    assert how.startswith("annotated")
    _, _, how = pkg("addon.gaze.chain").gaze_chain(rig.armature, rest, facing="+X")
    assert how.startswith("facing +X")
    bpy.context.scene.frame_start, bpy.context.scene.frame_end = 1, 40
    assert bpy.ops.articula.gaze(armature=rig.armature.name, target=target.name, fade_frames=5) == {'FINISHED'}


def _refused(match, **kw):
    with pytest.raises(RuntimeError, match=match):
        bpy.ops.articula.gaze(**kw)


def test_bad_input(pkg):
    ob = hero(pkg, "game_engine")
    target = moving_target()
    strips = lambda: sum(len(t.strips) for t in ob.animation_data.nla_tracks)  # noqa: E731
    child = bpy.data.objects.new("Hat", None)
    bpy.context.scene.collection.objects.link(child)
    child.parent = ob
    _refused("part of the character", armature=ob.name, target=child.name, frame_start=10, frame_end=50)
    _refused("outside", armature=ob.name, target=target.name, frame_start=100, frame_end=300)
    _refused("must come after", armature=ob.name, target=target.name, frame_start=50, frame_end=50)
    _refused("does not fit", armature=ob.name, target=target.name, frame_start=10, frame_end=20, fade_frames=8)
    assert strips() == 0
    arm = bpy.data.armatures.new("Stick")
    stick = bpy.data.objects.new("Stick", arm)
    bpy.context.scene.collection.objects.link(stick)
    bpy.context.view_layer.objects.active = stick
    bpy.ops.object.mode_set(mode='EDIT')
    for i in range(3):
        eb = arm.edit_bones.new(f"b{i}")
        eb.head, eb.tail = (0, 0, i), (0, 0, i + 1)
    bpy.ops.object.mode_set(mode='OBJECT')
    _refused("no head bone", armature=stick.name, target=target.name, frame_start=1, frame_end=30, fade_frames=5)
    behind = bpy.data.objects.new("Behind", None)
    bpy.context.scene.collection.objects.link(behind)
    behind.location = (0.0, 3.0, 1.5)
    _, report = None, pkg("addon.gaze.shot").apply_shot(bpy.context, ob, behind, 10, 60, 5)
    assert report["limited"] and "out of reach" in pkg("addon.gaze.shot").summary(report)


def test_batch_command(pkg, tmp_path):
    ob = hero(pkg, "mixamo")
    moving_target()
    src = str(tmp_path / "in.blend")
    bpy.ops.wm.save_as_mainfile(filepath=src)
    out = str(tmp_path / "out.blend")
    cli = pkg("addon.cli.main")
    assert cli.main(["gaze", "--blend", src, "--armature", ob.name, "--target", "Look", "--frames", "10:90",
                     "--fade", "8", "--out", out]) == 0
    bpy.ops.wm.open_mainfile(filepath=out)
    tracks = bpy.data.objects["Hero"].animation_data.nla_tracks
    assert any(t.name.startswith("Articula Gaze") for t in tracks)
    assert cli.main(["gaze", "--blend", src, "--armature", "Hero", "--target", "Look", "--frames", "10-90",
                     "--out", out]) == 2
    assert cli.main(["gaze", "--blend", src, "--armature", "Hero", "--target", "Look", "--out", src]) == 2
