"""``articula.retarget`` in Blender: a real CMU BVH (imported with Blender's importer, T-pose, Euler
channels) onto MakeHuman A-pose rigs; the target's pose read back from Blender's evaluated scene points
every mapped segment where the source's does; new action, nothing overwritten; rotation modes; sources
with constraints; the panel's list and JSON mappings; refusals that leave the scene as it was."""
import json
import os
import subprocess
import sys
from pathlib import Path

import bpy
import numpy as np
import pytest
from mathutils import Euler, Matrix

from articula.bench._armatures import new_armature
from articula.sample_scenes import mpfb_armature
from articula.bench import _retarget_metrics as metrics
from articula.solver.retarget import directions
from articula.solver.retarget.armature import world_pose
from ...conftest import SHARED_DATA

BVH = os.path.join(SHARED_DATA, "mocap", "cmu_131_01.bvh")
PROBE = Path(__file__).with_name("rigify_probe.py")
CMU_SCALE = 0.056444


def import_bvh(path=BVH, scale=CMU_SCALE):
    assert os.path.isfile(path), f"missing fixture {path}"
    bpy.ops.import_anim.bvh(filepath=path, global_scale=scale, frame_start=1)
    return bpy.context.active_object


def target_rig(pkg, rig="game_engine", name="Hero"):
    d = mpfb_armature.rig_bones(rig)
    return new_armature(
        bpy.context, name, d["names"], d["parents"], d["heads"], d["tails"], d["rolls"])


def evaluated(pkg, ob, frames):
    rest = pkg("addon.retarget.armatures").read_rest(ob)
    return rest, world_pose(rest, pkg("addon.retarget.source_clip").pose_from_scene(ob, rest, frames))


def segment_angles(pkg, source, target, frames):
    """(F, S) degrees between source and target segments, both read from Blender's evaluated poses."""
    mapping, *_ = pkg("addon.retarget.skeleton").auto_mapping(source, target)
    src, (_, hs) = evaluated(pkg, source, frames)
    tgt, (_, ht) = evaluated(pkg, target, frames)
    return metrics.segment_angles(directions.plan_segments(src, tgt, mapping.pairs()), hs, ht)


def test_bvh_onto_makehuman_rig_follows_every_segment(pkg):
    source = import_bvh()
    src_action = source.animation_data.action
    keys_before = sum(len(fc.keyframe_points) for fc in pkg("addon.compat").object_action_fcurves(source, src_action))
    target = target_rig(pkg)
    old = bpy.data.actions.new("Hero idle")
    target.animation_data_create().action = old
    assert bpy.ops.articula.retarget(source=source.name, target=target.name) == {'FINISHED'}
    action = target.animation_data.action
    assert action != old and old.use_fake_user and "cmu_131_01" in action.name
    frames = np.arange(1, 995, 13)
    angles = segment_angles(pkg, source, target, frames)
    assert angles.shape[1] >= 14 and angles.max() < 0.01
    assert source.animation_data.action == src_action
    assert sum(len(fc.keyframe_points) for fc in pkg("addon.compat").object_action_fcurves(source, src_action)) \
        == keys_before


@pytest.mark.parametrize("mode", ["YZX", "AXIS_ANGLE", "XZY"])
def test_target_bones_keep_their_rotation_mode(pkg, mode):
    source = import_bvh()
    target = target_rig(pkg, "cmu_mb")
    for pb in target.pose.bones:
        pb.rotation_mode = mode
    assert bpy.ops.articula.retarget(source=source.name, target=target.name) == {'FINISHED'}
    assert all(pb.rotation_mode == mode for pb in target.pose.bones)
    assert segment_angles(pkg, source, target, np.arange(1, 995, 97)).max() < 0.05


def test_euler_conversions_match_blender():
    from articula.addon.retarget.clip_writer import matrix_to_euler
    from articula.addon.retarget.source_clip import euler_to_matrix
    rng = np.random.default_rng(0)
    angles = rng.uniform(-3, 3, (40, 3))
    for order in ("XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX"):
        mine = euler_to_matrix(angles, order)
        ref = np.array([np.array(Euler(a, order).to_matrix()) for a in angles])
        assert np.abs(mine - ref).max() < 1e-6, order
        back = matrix_to_euler(mine, order)
        assert np.abs(euler_to_matrix(back, order) - mine).max() < 1e-9, order
        blender = np.array([Matrix(m.tolist()).to_euler(order) for m in mine])
        assert np.abs(euler_to_matrix(blender, order) - mine).max() < 1e-5, order


def test_source_with_constraints_is_read_from_the_evaluated_scene(pkg):
    source = import_bvh()
    con = source.pose.bones["LeftElbow"].constraints.new('LIMIT_ROTATION')
    con.use_limit_x, con.max_x, con.owner_space = True, 0.2, 'LOCAL'
    target = target_rig(pkg, "mixamo")
    assert bpy.ops.articula.retarget(source=source.name, target=target.name) == {'FINISHED'}
    assert segment_angles(pkg, source, target, np.arange(1, 995, 91)).max() < 0.05


def test_panel_list_and_json_mapping(pkg, tmp_path):
    source = import_bvh()
    target = target_rig(pkg, "default")
    state = bpy.context.scene.articula_retarget
    state.source, state.target = source, target
    assert bpy.ops.articula.retarget_find_mapping() == {'FINISHED'}
    rows = {r.role: (r.source_bone, r.target_bone) for r in state.rows}
    assert rows["upper_arm.L"] == ("LeftShoulder", "upperarm01.L") and rows["hips"] == ("Hips", "root")
    path = str(tmp_path / "map.json")
    assert bpy.ops.articula.retarget_save_mapping(filepath=path) == {'FINISHED'}
    next(r for r in state.rows if r.role == "head").target_bone = "neck03"
    assert bpy.ops.articula.retarget_load_mapping(filepath=path) == {'FINISHED'}
    assert next(r for r in state.rows if r.role == "head").target_bone == "head"
    assert bpy.ops.articula.retarget(mapping='LIST') == {'FINISHED'}
    assert bpy.ops.articula.retarget(mapping='FILE', mapping_file=path) == {'FINISHED'}
    assert segment_angles(pkg, source, target, np.arange(1, 995, 101)).max() < 0.05


def _refused(pkg, match, **kw):
    actions = set(bpy.data.actions)
    with pytest.raises(RuntimeError, match=match):
        bpy.ops.articula.retarget(**kw)
    assert set(bpy.data.actions) == actions


def test_bad_input_is_refused_with_a_clear_message_and_nothing_made(pkg, tmp_path):
    source = import_bvh()
    target = target_rig(pkg, "game_engine")
    still = target_rig(pkg, "cmu_mb", "Still")
    _refused(pkg, "no active action", source=still.name, target=target.name)
    ik = target.pose.bones["calf_l"].constraints.new('IK')
    _refused(pkg, "calf_l.*constraints", source=source.name, target=target.name)
    ik.mute = True
    target.scale = (1.0, 2.0, 1.0)
    _refused(pkg, "non-uniformly", source=source.name, target=target.name)
    target.scale = (1.0, 1.0, 1.0)
    path = str(tmp_path / "map.json")
    with open(path, "w") as fh:
        fh.write('{"format": "articula-retarget-mapping", "rows": [{"role": "hips", "source": "Hips", '
                 '"target": "pelvis"}]}')
    _refused(pkg, "thigh.L.*target", source=source.name, target=target.name, mapping='FILE', mapping_file=path)
    _refused(pkg, "no source object", source="Nope", target=target.name)


def test_linked_target_is_refused(pkg, tmp_path):
    target_rig(pkg, "cmu_mb", "Linked")
    lib = str(tmp_path / "lib.blend")
    bpy.ops.wm.save_as_mainfile(filepath=lib)
    bpy.ops.wm.read_homefile(use_empty=True)
    with bpy.data.libraries.load(lib, link=True) as (src, dst):
        dst.objects = ["Linked"]
    bpy.context.scene.collection.objects.link(dst.objects[0])
    source = import_bvh()
    _refused(pkg, "linked from lib.blend .*make a library override", source=source.name, target="Linked")


def test_batch_command_retargets_a_bvh_into_a_new_blend(pkg, tmp_path):
    target_rig(pkg, "mixamo", "Dancer")
    character = str(tmp_path / "character.blend")
    bpy.ops.wm.save_as_mainfile(filepath=character)
    out = str(tmp_path / "out.blend")
    cli = pkg("addon.cli.main")
    assert cli.main(["retarget", "--source", BVH, "--target", character, "--out", out, "--plant-feet"]) == 0
    bpy.ops.wm.open_mainfile(filepath=out)
    dancer = bpy.data.objects["Dancer"]
    assert dancer.animation_data.action is not None and dancer.animation_data.action.frame_range[1] == 994
    assert cli.main(["retarget", "--source", BVH, "--target", character, "--out", character]) == 2
    assert cli.main(["retarget", "--source", str(tmp_path / "none.bvh"), "--target", character, "--out", out]) == 2


def _random_action(pkg, arm_ob, frames=6, amplitude=0.5, seed=0):
    """Random bone rotations (and a root walk) keyed on every bone of ``arm_ob``."""
    from articula.solver.rig.model import Poses
    from articula.solver.geometry.rotations import rotvec_to_quat
    rng = np.random.default_rng(seed)
    names = [b.name for b in arm_ob.data.bones]
    for pb in arm_ob.pose.bones:
        pb.rotation_mode = 'QUATERNION'
    q = rotvec_to_quat(rng.normal(0, amplitude / 2, (frames, len(names), 3)))
    trans = np.outer(np.linspace(0, 1, frames), [0.0, -0.5, 0.0])
    pkg("addon.rig.actions").write_action(arm_ob, names, Poses(q, trans, np.ones(frames)), name="random")


def test_fingers_and_twist_segments_mixamo_onto_makehuman_default(pkg):
    """Mixamo (3 bones per finger) onto MakeHuman's default rig (metacarpals, split arms and legs): every
    mapped segment, fingers included, follows."""
    source = target_rig(pkg, "mixamo", "Mixamo")
    _random_action(pkg, source)
    target = target_rig(pkg, "default", "Default")
    assert bpy.ops.articula.retarget(source=source.name, target=target.name) == {'FINISHED'}
    mapping, *_ = pkg("addon.retarget.skeleton").auto_mapping(source, target)
    assert {"index.02.L", "thumb.03.R", "pinky.01.L"} <= set(mapping.pairs())
    angles = segment_angles(pkg, source, target, np.arange(1, 7))
    assert angles.shape[1] >= 38 and angles.max() < 0.01


def test_articula_rig_as_source(pkg):
    """A tracked/learned Articula rig (swing helpers with constraints, names found by shape) drives a
    MakeHuman rig."""
    from articula.solver.track_depth.template import load_template
    rig = pkg("addon.rig.builder").build_rig(bpy.context, load_template().base, "Tracked")
    _random_action(pkg, rig.armature, amplitude=0.4)
    target = target_rig(pkg, "game_engine")
    assert bpy.ops.articula.retarget(source=rig.armature.name, target=target.name) == {'FINISHED'}
    assert segment_angles(pkg, rig.armature, target, np.arange(1, 7)).max() < 0.01


def test_rigify_fk_controls_under_constrained_parents(tmp_path):
    """A Rigify rig generated by Blender's own Rigify (FK controls hang from MCH bones moved by
    constraints): the FK-control preset is chosen over the constrained deform bones, and the channels
    found through the evaluated scene put every mapped control where the source's segments point.  Run in
    a Blender of its own (rigify_probe.py): Rigify makes the bpy 4.2 module crash at exit."""
    out = tmp_path / "rigify.json"
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "user"))
    done = subprocess.run([sys.executable, str(PROBE), BVH, str(out)], env=env, capture_output=True, text=True,
                          timeout=600)
    assert out.exists(), done.stdout[-2000:] + done.stderr[-2000:]
    result = json.loads(out.read_text())
    assert "error" not in result, result.get("traceback")
    assert result["preset"] == "Rigify (FK controls)" and result["upper_arm.L"] == "upper_arm_fk.L"
    assert result["solved"].startswith("evaluated") and result["segments"] >= 14 and result["shoulder"]
    assert result["max_angle"] < 0.01


def test_unit_mismatch_is_detected_and_handled(pkg):
    """A BVH imported at scale 1 (CMU's units: ~17x a person): reported as a unit mismatch, the root motion
    scaled by the leg ratio, the segments still exact."""
    source = import_bvh(scale=1.0)
    source.animation_data.action.use_frame_range = True
    source.animation_data.action.frame_start, source.animation_data.action.frame_end = 1, 40
    target = target_rig(pkg, "game_engine")
    action, report = pkg("addon.retarget.skeleton").retarget(bpy.context, source, target)
    assert report["unit_mismatch"] and 0.04 < report["leg_ratio"] < 0.08
    assert "units differ" in pkg("addon.retarget.skeleton").summary(report)
    assert segment_angles(pkg, source, target, np.arange(1, 41, 3)).max() < 0.01
