"""Round trips: bundle -> rig -> Model, poses -> action -> poses (4.2 legacy and slotted actions), and a
rig surviving save/reload, renaming and linking into another file."""

import numpy as np
import pytest

import bpy

from ..rig_helpers import bbox_diagonal, evaluate_frames, poses, subject


def _canonical(q):
    return np.where(q[..., :1] < 0, -q, q)


def test_bundle_rig_model_round_trip(pkg, tmp_path):
    model = subject(pkg)
    path = str(tmp_path / "body.npz")
    pkg("solver.formats.bundle").save_bundle(path, model)
    rig, _ = pkg("addon.rig.bundle_io").build_from_bundle(bpy.context, path)
    back = pkg("addon.rig.reader").read_model(rig.armature)
    sk, bk = model.skeleton, back.skeleton
    assert bk.names == sk.names
    np.testing.assert_array_equal(bk.parents, sk.parents)
    for key in ("heads", "tails", "frames"):
        np.testing.assert_allclose(getattr(bk, key), getattr(sk, key), atol=2e-6, err_msg=key)
    np.testing.assert_allclose(back.rest_vertices, model.rest_vertices, atol=1e-6)
    np.testing.assert_array_equal(back.faces, model.faces)
    np.testing.assert_array_equal(back.anchor, model.anchor)
    np.testing.assert_array_equal(back.twist_weights, model.twist_weights)
    np.testing.assert_array_equal(back.swing_weights, model.swing_weights)
    assert rig.frame_error < 2e-6


def test_vertex_groups_hold_remainders(pkg):
    model = subject(pkg)
    rig = pkg("addon.rig.builder").build_rig(bpy.context, model, "Body")
    sk = model.skeleton
    names = ["NEUTRAL"] + list(sk.names)
    w = pkg("addon.scene.mesh_io").read_vertex_groups(rig.mesh, names)
    np.testing.assert_allclose(w[:, 0], 1 - model.twist_weights.sum(1), atol=1e-6)
    anchor_w = w[np.arange(model.num_vertices), 1 + model.anchor]
    np.testing.assert_allclose(anchor_w, 1 - model.swing_weights.sum(1), atol=1e-6)
    mods = [(m.type, m.object, m.use_deform_preserve_volume, m.use_multi_modifier) for m in rig.mesh.modifiers]
    assert mods == [('ARMATURE', rig.twist, True, False), ('ARMATURE', rig.armature, False, False)]
    arm = rig.armature.data
    assert {c.name for c in arm.collections} == {"Controls", "Helpers"}
    assert not arm.collections["Helpers"].is_visible
    assert all(pb.rotation_mode == 'QUATERNION' for pb in rig.armature.pose.bones if pb.name in sk.names)
    assert rig.armature.articula.kind == 'RIG_ARMATURE' and rig.twist.articula.kind == 'TWIST_ARMATURE'
    assert rig.mesh.articula.kind == 'RIG_MESH'
    for ob in (rig.armature, rig.twist, rig.mesh):
        np.testing.assert_array_equal(np.array(ob.matrix_world), np.eye(4))


@pytest.mark.parametrize("nla", [False, True])
def test_action_round_trip(pkg, nla):
    model = subject(pkg)
    p = poses(pkg, model.skeleton.num_bones, 30, seed=5)
    rig = pkg("addon.rig.builder").build_rig(bpy.context, model, "Body")
    actions = pkg("addon.rig.actions")
    first = actions.write_action(rig.armature, model.skeleton.names, p, name="Take", frame_start=1)
    second = actions.write_action(rig.armature, model.skeleton.names, p, name="Take", frame_start=1, nla=nla)
    assert first.name == "Take" and second.name != "Take"          # nothing overwritten
    assert first.use_fake_user or first.users > 0                    # the replaced action is kept
    sc = bpy.context.scene
    assert (sc.frame_start, sc.frame_end) == (1, 30)
    if nla:
        ad = rig.armature.animation_data
        assert ad.action == first and ad.nla_tracks[-1].strips[0].action == second
    back = pkg("addon.rig.reader").read_poses(rig.armature, second)
    assert len(back) == 30
    np.testing.assert_allclose(_canonical(back.rotations), _canonical(p.rotations), atol=1e-6)
    np.testing.assert_allclose(back.translations, p.translations, atol=1e-6)
    np.testing.assert_allclose(back.scales, p.scales, atol=1e-6)


def test_export_bundle_round_trip_with_poses(pkg, tmp_path):
    model = subject(pkg, rings=6, segments=8)
    p = poses(pkg, model.skeleton.num_bones, 12, seed=7)
    src, out = str(tmp_path / "in.npz"), str(tmp_path / "out.npz")
    pkg("solver.formats.bundle").save_bundle(src, model, p)
    assert bpy.ops.articula.build_rig(filepath=src) == {'FINISHED'}
    arm = bpy.context.view_layer.objects.active
    assert arm.articula.kind == 'RIG_ARMATURE' and arm.animation_data.action is not None
    assert bpy.ops.articula.export_bundle(filepath=out, armature=arm.name) == {'FINISHED'}
    b = pkg("solver.formats.bundle").load_bundle(out)
    np.testing.assert_allclose(b.model.rest_vertices, model.rest_vertices, atol=1e-6)
    np.testing.assert_array_equal(b.model.twist_weights, model.twist_weights)
    np.testing.assert_allclose(_canonical(b.poses.rotations), _canonical(p.rotations), atol=1e-6)
    np.testing.assert_allclose(b.poses.translations, p.translations, atol=1e-6)
    np.testing.assert_allclose(b.poses.scales, p.scales, atol=1e-6)


def _rig_with_action(pkg, n=5):
    model = subject(pkg, rings=6, segments=8)
    p = poses(pkg, model.skeleton.num_bones, n, seed=9)
    rig = pkg("addon.rig.builder").build_rig(bpy.context, model, "Body")
    pkg("addon.rig.actions").write_action(rig.armature, model.skeleton.names, p)
    ref = pkg("solver.rig.skinning").hybrid_skin(model, p)
    return model, rig, ref, bbox_diagonal(model.rest_vertices)


def test_save_reload_and_rename(pkg, tmp_path):
    model, rig, ref, diag = _rig_with_action(pkg)
    path = str(tmp_path / "rig.blend")
    rig.armature.name, rig.twist.name, rig.mesh.name = "Renamed", "Hidden Twist", "Skin"
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.wm.open_mainfile(filepath=path)
    mesh = bpy.data.objects["Skin"]
    got = evaluate_frames(pkg, mesh, range(1, 6))
    assert np.linalg.norm(got - ref, axis=2).max() / diag < 1e-5
    back = pkg("addon.rig.reader").read_model(pkg("addon.rig.reader").find_armature("Skin"))
    np.testing.assert_array_equal(back.swing_weights, model.swing_weights)


def test_linked_into_another_file(pkg, tmp_path):
    model, rig, ref, diag = _rig_with_action(pkg)
    path = str(tmp_path / "lib.blend")
    names = [rig.armature.name, rig.twist.name, rig.mesh.name]
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.read_homefile(use_empty=True)
    with bpy.data.libraries.load(path, link=True) as (src, dst):
        dst.objects = names
    for ob in dst.objects:
        bpy.context.scene.collection.objects.link(ob)
    mesh = next(ob for ob in dst.objects if ob.type == 'MESH')
    assert mesh.library is not None
    got = evaluate_frames(pkg, mesh, range(1, 6))
    assert np.linalg.norm(got - ref, axis=2).max() / diag < 1e-5


def test_frames_read_back_are_turned_onto_the_float32_bone_directions(pkg):
    """Bone matrices and heads/tails in float32 disagree by ~1e-6: the reader turns every frame by the
    smallest rotation putting its Y axis on tail - head exactly, keeping it a rotation."""
    import numpy as np
    reader = pkg("addon.rig.reader")
    rng = np.random.default_rng(0)
    heads = rng.normal(size=(6, 3))
    tails = heads + rng.normal(size=(6, 3))
    y = (tails - heads) / np.linalg.norm(tails - heads, axis=1, keepdims=True)
    x = np.cross(y, rng.normal(size=(6, 3)))
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    F = np.stack([x, y, np.cross(x, y)], axis=2)
    noisy = reader._nearest_rotations(F + rng.normal(0, 3e-6, F.shape))
    out = reader._along_bones(noisy, heads, tails)
    assert np.abs(out[:, :, 1] - y).max() < 1e-12
    assert np.abs(np.einsum("bji,bjk->bik", out, out) - np.eye(3)).max() < 1e-12
    assert np.abs(out - F).max() < 1e-4
