"""Retargeting between two Articula rigs through their shared mesh (addon.retarget.topology): the target's
new action reproduces the solver's fit in Blender's evaluated mesh, the source's action and the target's
old action are untouched, frame ranges, and clear refusals."""
from dataclasses import replace

import numpy as np
import pytest

import bpy

from ..rig_helpers import evaluate_frames, poses, subject


def _other_body(model):
    """The same mesh and skin on another body: 10 % bigger, and every joint but the root moved along its
    bone by 15 % of the bone (so the joints sit elsewhere relative to the vertices)."""
    sk = model.skeleton
    heads, tails = 1.1 * sk.heads, 1.1 * sk.tails
    heads[1:] += 0.15 * (tails[1:] - heads[1:])
    moved = type(sk)(sk.names, sk.parents, heads, tails, sk.frames)
    return replace(model, rest_vertices=1.1 * model.rest_vertices, skeleton=moved)


def _keys(arm, action, pkg):
    """Every F-curve's keyframe coordinates of ``action`` on ``arm``, by (data path, index)."""
    out = {}
    for fc in pkg("addon.compat").object_action_fcurves(arm, action):
        co = np.empty(2 * len(fc.keyframe_points), np.float32)
        fc.keyframe_points.foreach_get("co", co)
        out[(fc.data_path, fc.array_index)] = co
    return out


@pytest.fixture
def rigs(pkg):
    """Source rig with a 4-frame action on frames 1-4, target rig (another body) with an action of its own."""
    src_model = subject(pkg, rings=6, segments=8)
    tgt_model = _other_body(src_model)
    tgt_model.validate()
    builder, actions = pkg("addon.rig.builder"), pkg("addon.rig.actions")
    src = builder.build_rig(bpy.context, src_model, "Source")
    tgt = builder.build_rig(bpy.context, tgt_model, "Target")
    names = src_model.skeleton.names
    p = poses(pkg, len(names), 4, seed=3, max_twist_deg=60.0)
    actions.write_action(src.armature, names, p, name="Walk")
    actions.write_action(tgt.armature, names, poses(pkg, len(names), 2, seed=8), name="Old")
    return src, tgt, src_model, tgt_model, p


def test_target_action_reproduces_the_fit(pkg, rigs):
    src, tgt, src_model, tgt_model, p = rigs
    before = _keys(src.armature, src.armature.animation_data.action, pkg)
    old = tgt.armature.animation_data.action
    action, rep = pkg("addon.retarget.topology").retarget_topology_rigs(bpy.context, src.armature, tgt.mesh)
    assert tgt.armature.animation_data.action == action and action.name.startswith("Walk (topology")
    assert old.name == "Old" and (old.use_fake_user or old.users > 0)
    assert src.armature.animation_data.action.name == "Walk"
    after = _keys(src.armature, src.armature.animation_data.action, pkg)
    assert after.keys() == before.keys() and all(np.array_equal(after[k], before[k]) for k in before)
    assert rep["frames"] == 4 and rep["frame_start"] == 1 and rep["source_action"] == "Walk"
    assert np.all(rep["rms_fit"] < 0.5 * rep["rms_copy"]), (rep["rms_fit"], rep["rms_copy"])
    # the solver on the original models gives the same fit as on the models read back from Blender
    fitted, ref = pkg("solver.retarget.topology").retarget_topology(src_model, p, tgt_model)
    np.testing.assert_allclose(rep["rms_fit"], ref["rms_fit"], atol=1e-5)
    skin = pkg("solver.rig.skinning").hybrid_skin
    got_tgt = evaluate_frames(pkg, tgt.mesh, range(1, 5))
    got_src = evaluate_frames(pkg, src.mesh, range(1, 5))
    assert np.abs(got_tgt - skin(tgt_model, fitted)).max() < 1e-4
    rms = np.sqrt(((got_tgt - got_src) ** 2).sum(-1).mean(-1))
    np.testing.assert_allclose(rms, rep["rms_fit"], atol=1e-5)
    back = pkg("addon.rig.reader").read_poses(tgt.armature, action)
    assert len(back) == 4
    np.testing.assert_allclose(back.translations, fitted.translations, atol=1e-5)


def test_frame_range_and_size_ratio(pkg, rigs):
    src, tgt, *_ = rigs
    action, rep = pkg("addon.retarget.topology").retarget_topology_rigs(
        bpy.context, src.twist, tgt.armature, frame_start=2, frame_end=3, scale=1.1)
    assert rep["frames"] == 2 and rep["frame_start"] == 2 and rep["scale"] == pytest.approx(1.1)
    fcurves = pkg("addon.compat").object_action_fcurves(tgt.armature, action)
    assert {tuple(fc.range()) for fc in fcurves} == {(2.0, 3.0)}


def test_refusals(pkg, rigs):
    src, tgt, src_model, *_ = rigs
    topo = pkg("addon.retarget.topology")
    err = pkg("solver.errors").ArticulaInputError
    n_actions = len(bpy.data.actions)
    plain = bpy.data.objects.new("Plain", bpy.data.meshes.new("Plain"))
    bpy.context.collection.objects.link(plain)
    with pytest.raises(err, match="target 'Plain' is not \\(part of\\) an Articula rig"):
        topo.retarget_topology_rigs(bpy.context, src.armature, plain)
    with pytest.raises(err, match="same rig"):
        topo.retarget_topology_rigs(bpy.context, src.armature, src.mesh)
    with pytest.raises(err, match="source rig 'Target' has no action"):
        tgt.armature.animation_data.action = None
        topo.retarget_topology_rigs(bpy.context, tgt.armature, src.armature)
    other = pkg("addon.rig.builder").build_rig(bpy.context, subject(pkg, rings=5, segments=8), "Other")
    V, F = src_model.num_vertices, len(src_model.faces)
    with pytest.raises(err, match=f"'{src.mesh.name}' has {V} vertices and {F} faces, '{other.mesh.name}' "
                                     f"{19 * 40} vertices"):
        topo.retarget_topology_rigs(bpy.context, src.armature, other.armature)
    faces = src_model.faces.copy()
    faces[[5, 9]] = faces[[9, 5]]
    swapped = pkg("addon.rig.builder").build_rig(bpy.context, replace(src_model, faces=faces), "Swapped")
    with pytest.raises(err, match="both have 912 vertices and 1520 faces, but 2 faces join other vertices "
                                  "\\(the first is face 5\\)"):
        topo.retarget_topology_rigs(bpy.context, src.armature, swapped.armature)
    assert len(bpy.data.actions) == n_actions                      # nothing written


def test_operator_runs_the_topology_fit(pkg, rigs):
    """``articula.retarget(mapping='TOPOLOGY')`` (the panel's Retarget by Shared Mesh) writes the fit as a
    new action on the target; the same rig twice is refused."""
    src, tgt, *_ = rigs
    old = tgt.armature.animation_data.action
    assert bpy.ops.articula.retarget(source=src.armature.name, target=tgt.mesh.name, mapping='TOPOLOGY') \
        == {'FINISHED'}
    assert tgt.armature.animation_data.action not in (None, old)
    with pytest.raises(RuntimeError):
        bpy.ops.articula.retarget(source=src.armature.name, target=src.mesh.name, mapping='TOPOLOGY')
