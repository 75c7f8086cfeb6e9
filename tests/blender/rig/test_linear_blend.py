"""``articula.export_lbs``: the linear-blend rig Blender builds deforms exactly as solver.rig.linear_blend
predicts, and its reported deviation from the exact rig is that prediction (shrinking with more
segments where one joint twists per vertex)."""
import numpy as np

import bpy

from ..rig_helpers import bbox_diagonal, evaluate_frames, poses, subject


def _rig(pkg, model, p):
    rig = pkg("addon.rig.builder").build_rig(bpy.context, model, "Body")
    pkg("addon.rig.actions").write_action(rig.armature, model.skeleton.names, p)
    return rig


def test_lbs_rig_matches_its_prediction(pkg):
    model = subject(pkg, rings=8, segments=10)
    p = poses(pkg, model.skeleton.num_bones, 8, seed=6, max_twist_deg=120)
    rig = _rig(pkg, model, p)
    before = len(bpy.data.objects)
    assert bpy.ops.articula.export_lbs(armature=rig.armature.name, segments=3) == {'FINISHED'}
    assert len(bpy.data.objects) == before + 2
    lbs_arm = bpy.context.view_layer.objects.active
    mesh = next(ob for ob in lbs_arm.children if ob.type == 'MESH')
    assert [m.type for m in mesh.modifiers] == ['ARMATURE'] and not mesh.modifiers[0].use_deform_preserve_volume
    le = pkg("solver.rig.linear_blend")
    _, W = le.lbs_weights(model, 3)
    Rm, tm = le.bone_maps(model, p, 3)
    predicted = pkg("solver.rig.skinning").lbs(model.rest_vertices, W, Rm, tm)
    got = evaluate_frames(pkg, mesh, range(1, 9))
    assert np.linalg.norm(got - predicted, axis=2).max() / bbox_diagonal(model.rest_vertices) < 1e-5
    worst, _ = le.deviation(model, p, 3)
    assert abs(lbs_arm["articula_lbs_max_mm"] - 1000 * worst.max()) < 1e-3      # mm; rig read back as float32
    hybrid = evaluate_frames(pkg, rig.mesh, range(1, 9))
    assert abs(np.linalg.norm(got - hybrid, axis=2).max() - worst.max()) < 1e-4


def test_more_segments_deviate_less_on_a_twisted_limb(pkg):
    tube = pkg("sample_scenes.synthetic")
    model = tube.cylinder()
    Poses = pkg("solver.rig.model").Poses
    q = np.array([[[1, 0, 0, 0], [np.cos(np.pi / 4), 0, np.sin(np.pi / 4), 0]]])     # 90° twist
    p = Poses(q, np.zeros((1, 3)), np.ones(1))
    dev = [pkg("solver.rig.linear_blend").deviation(model, p, n)[0].max() for n in (1, 2, 4, 8)]
    assert all(a > b for a, b in zip(dev, dev[1:]))
    assert dev[0] > 0.05 and dev[-1] < 0.006


def test_export_lbs_without_rig_reports(pkg):
    before = len(bpy.data.objects)
    try:
        result = bpy.ops.articula.export_lbs(armature="nothing")
    except RuntimeError as exc:
        result = {'CANCELLED'}
        assert "nothing" in str(exc)
    assert result == {'CANCELLED'} and len(bpy.data.objects) == before
