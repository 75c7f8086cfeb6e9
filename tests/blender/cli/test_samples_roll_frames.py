"""Rest frames computed from MPFB2 head/tail/roll (sample_scenes.mpfb_rig.roll_frames) equal Blender's own
edit-bone matrices: the independent reference for the roll convention."""
import bpy
import numpy as np
import pytest


@pytest.mark.parametrize("rig", ["cmu_mb", "default"])
def test_roll_frames_match_blender_edit_bones(pkg, rig):
    mh = pkg("sample_scenes.makehuman")
    mr = pkg("sample_scenes.mpfb_rig")
    spec = mr.load_rig(rig)
    heads, tails = mr.place_joints(spec, mh.shaped_vertices(), mh.load_base_mesh())
    frames = mr.roll_frames(heads, tails, spec.rolls)

    arm = bpy.data.armatures.new("rig")
    obj = bpy.data.objects.new("rig", arm)
    bpy.context.scene.collection.objects.link(obj)
    bpy.context.view_layer.objects.active = obj
    bpy.ops.object.mode_set(mode='EDIT')
    for name, h, t, r in zip(spec.names, heads, tails, spec.rolls):
        eb = arm.edit_bones.new(name)
        eb.head, eb.tail, eb.roll = h.tolist(), t.tolist(), float(r)
    bpy.ops.object.mode_set(mode='OBJECT')
    blender = np.array([[list(row) for row in arm.bones[n].matrix_local.to_3x3()] for n in spec.names])
    # Blender stores float32 positions: recompute from what it stored so only the convention is compared
    h32 = np.array([list(arm.bones[n].head_local) for n in spec.names])
    t32 = np.array([list(arm.bones[n].tail_local) for n in spec.names])
    assert np.abs(blender - mr.roll_frames(h32, t32, spec.rolls)).max() < 5e-5  # float32 arithmetic, tiny face bones
    assert np.abs(blender - frames).max() < 1e-4
    # the comparison can fail: a wrong roll sign is visible
    wrong = mr.roll_frames(heads, tails, -spec.rolls)
    assert np.abs(blender - wrong).max() > 0.1


def test_euler_xyz_matches_mathutils(pkg):
    """The walk-cycle Euler convention (sample_scenes.fcurves) is Blender's XYZ Euler."""
    from mathutils import Euler
    fc = pkg("sample_scenes.fcurves")
    rng = np.random.default_rng(0)
    for e in rng.uniform(-3, 3, (20, 3)):
        blender = np.array(Euler(e.tolist(), 'XYZ').to_matrix())
        assert np.abs(fc.euler_xyz_to_matrix(e) - blender).max() < 1e-6
        assert np.abs(fc.euler_xyz_to_matrix(e[::-1]) - blender).max() > 1e-3 or np.allclose(e, e[::-1])
