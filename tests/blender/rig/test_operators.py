"""Operators and batch commands of the rig feature: bad input is reported clearly and creates nothing;
build/bake/export work headless through bpy.ops and the batch CLI."""
import os

import numpy as np
import pytest

import bpy

from ..rig_helpers import bundle_arrays, poses, subject, write_raw_bundle


def _counts():
    return {k: len(getattr(bpy.data, k)) for k in ("objects", "meshes", "armatures", "actions", "collections")}


def _run(op, **kw):
    """Call ``op``; returns (result set, error text)."""
    try:
        return op(**kw), ""
    except RuntimeError as exc:           # background mode turns ERROR reports into RuntimeError
        return {'CANCELLED'}, str(exc)


def _small(pkg):
    model = subject(pkg, rings=6, segments=8)
    return model, poses(pkg, model.skeleton.num_bones, 4, seed=4)


def _break_anchor(a, model):
    tw = a["twist_weights"].copy()
    v = int(np.flatnonzero(model.anchor == 0)[0])
    tw[v, model.skeleton.names.index("forearm.L")] = 0.2                  # not a child of the pelvis
    a["twist_weights"] = tw


def _break_quat(a, model):
    r = a["pose_rotations"].copy()
    r[2, 5] *= 1.5
    a["pose_rotations"] = r


def _break_length(a, model):
    t = a["tails"].copy()
    t[7] = a["heads"][7]
    a["tails"] = t


def _break_cycle(a, model):
    p = a["parents"].copy()
    p[3], p[4] = 4, 3                                                      # neck <-> head
    a["parents"] = p


def _break_name(a, model):
    n = a["bone_names"].copy()
    n[5] = "SW-shoulder"
    a["bone_names"] = n


@pytest.mark.parametrize("breaker, message", [
    (_break_anchor, "not a child of its anchor"),
    (_break_quat, "norm"),
    (_break_length, "head == tail"),
    (_break_cycle, "parents"),
    (_break_name, "reserved"),
])
def test_bad_bundle_is_reported_and_creates_nothing(pkg, tmp_path, breaker, message):
    model, p = _small(pkg)
    arrays = bundle_arrays(pkg, model, p)
    breaker(arrays, model)
    path = str(tmp_path / "bad.npz")
    write_raw_bundle(path, arrays)
    before = _counts()
    result, error = _run(bpy.ops.articula.build_rig, filepath=path)
    assert result == {'CANCELLED'}
    assert message in error and "bad.npz" in error
    assert _counts() == before


def test_missing_file_is_reported(pkg, tmp_path):
    before = _counts()
    result, error = _run(bpy.ops.articula.build_rig, filepath=str(tmp_path / "none.npz"))
    assert result == {'CANCELLED'} and "no such bundle file" in error
    assert _counts() == before


def test_bake_onto_existing_rig(pkg, tmp_path):
    model, p = _small(pkg)
    rig_path, pose_path = str(tmp_path / "rig.npz"), str(tmp_path / "take.npz")
    save = pkg("solver.formats.bundle").save_bundle
    save(rig_path, model)
    save(pose_path, model, p)
    assert bpy.ops.articula.build_rig(filepath=rig_path) == {'FINISHED'}
    arm = bpy.context.view_layer.objects.active
    assert arm.animation_data is None or arm.animation_data.action is None        # no poses, no action
    assert bpy.ops.articula.bake_poses(filepath=pose_path, armature=arm.name, nla=True) == {'FINISHED'}
    assert arm.animation_data.nla_tracks and arm.animation_data.action is None   # still no active action
    assert bpy.ops.articula.bake_poses(filepath=pose_path, armature=arm.name) == {'FINISHED'}
    assert arm.animation_data.action.name == "take poses.001"
    before = _counts()
    result, error = _run(bpy.ops.articula.bake_poses, filepath=rig_path, armature=arm.name)
    assert result == {'CANCELLED'} and "no poses" in error and _counts() == before
    result, error = _run(bpy.ops.articula.bake_poses, filepath=pose_path, armature="Nope")
    assert result == {'CANCELLED'} and "Nope" in error and _counts() == before


def test_read_action_requires_an_action(pkg, tmp_path):
    model, _ = _small(pkg)
    path = str(tmp_path / "rig.npz")
    pkg("solver.formats.bundle").save_bundle(path, model)
    bpy.ops.articula.build_rig(filepath=path)
    arm = bpy.context.view_layer.objects.active
    result, error = _run(bpy.ops.articula.read_action, filepath=str(tmp_path / "x.npz"), armature=arm.name)
    assert result == {'CANCELLED'} and "no active action" in error
    assert not os.path.exists(tmp_path / "x.npz")


def test_batch_commands(pkg, tmp_path):
    model, p = _small(pkg)
    src = str(tmp_path / "subject.npz")
    pkg("solver.formats.bundle").save_bundle(src, model, p)
    cli = pkg("addon.cli.main")
    blend, out = str(tmp_path / "rig.blend"), str(tmp_path / "back.npz")
    assert cli.main(["build-rig", "--bundle", src, "--blend", blend]) == 0
    assert cli.main(["bake", "--bundle", src, "--blend", blend, "--armature", "subject"]) == 0
    assert cli.main(["export-bundle", "--blend", blend, "--out", out, "--armature", "subject"]) == 0
    b = pkg("solver.formats.bundle").load_bundle(out)
    assert len(b.poses) == len(p)
    assert cli.main(["build-rig", "--bundle", str(tmp_path / "missing.npz")]) == 2


def test_build_with_large_fork_twists_needs_no_warning(pkg, tmp_path):
    """The solver blends twists with Blender's own hemisphere rule, so even fork twists adding up to
    more than 180° (where that rule flips a twist) build without caveats; exactness is checked in
    test_rig_exactness.py."""
    model = subject(pkg, rings=6, segments=8, fork_twist="all")
    p = poses(pkg, model.skeleton.num_bones, 20, seed=1)
    assert pkg("solver.rig.skinning").twist_flips(model, p).any()
    path = str(tmp_path / "forks.npz")
    pkg("solver.formats.bundle").save_bundle(path, model, p)
    rig, action = pkg("addon.rig.bundle_io").build_from_bundle(bpy.context, path)
    assert action is not None and rig.warnings == ()


def _break_format(a, model):
    a["format"] = np.array("articula-model/9")


def _random_bytes(path):
    with open(path, "wb") as fh:
        fh.write(np.random.default_rng(1).bytes(5000))


@pytest.mark.parametrize("make, expected", [
    (lambda path, arrays: _random_bytes(path), "bad.npz: not a model bundle (not a valid .npz archive of arrays)"),
    (lambda path, arrays: (_break_format(arrays, None), write_raw_bundle(path, arrays)),
     "bad.npz: key 'format' is 'articula-model/9', expected 'articula-model/1'"),
])
def test_unreadable_bundles_are_named_plainly_on_both_paths(pkg, tmp_path, capfd, make, expected):
    model, p = _small(pkg)
    path = str(tmp_path / "bad.npz")
    make(path, bundle_arrays(pkg, model, p))
    before = _counts()
    for op in (bpy.ops.articula.build_rig, bpy.ops.articula.bake_poses):
        result, error = _run(op, filepath=path)
        assert result == {'CANCELLED'} and expected in error, error
        assert "allow_pickle" not in error and "array(" not in error
    assert _counts() == before
    cli = pkg("addon.cli.main")
    capfd.readouterr()
    assert cli.main(["build-rig", "--bundle", path]) == 2
    err = capfd.readouterr().err
    assert expected in err and "allow_pickle" not in err and "array(" not in err
    assert _counts() == before


def test_empty_bundle_path_says_no_file_given(pkg, tmp_path, capfd):
    before = _counts()
    for op in (bpy.ops.articula.build_rig, bpy.ops.articula.bake_poses):
        result, error = _run(op, filepath="")
        assert result == {'CANCELLED'} and "no bundle file given" in error and ": :" not in error, error
    capfd.readouterr()
    assert pkg("addon.cli.main").main(["build-rig", "--bundle", ""]) == 2
    err = capfd.readouterr().err
    assert "no bundle file given" in err and ": :" not in err, err
    assert _counts() == before


def test_near_unit_quaternions_are_normalised_with_a_warning(pkg, tmp_path, capfd):
    """Float32 round-off (norms within 1e-4 of 1) is normalised on load and said so, on the operator and
    the batch path; the baked action holds the unit quaternions."""
    model, p = _small(pkg)
    arrays = bundle_arrays(pkg, model, p)
    arrays["pose_rotations"] = arrays["pose_rotations"] * 1.00005
    path = str(tmp_path / "f32.npz")
    write_raw_bundle(path, arrays)
    capfd.readouterr()
    assert bpy.ops.articula.build_rig(filepath=path) == {'FINISHED'}
    out = "".join(capfd.readouterr())
    assert "normalised" in out and "f32.npz" in out, out
    arm = bpy.context.view_layer.objects.active
    read = pkg("addon.rig.reader").read_poses(arm, arm.animation_data.action)
    np.testing.assert_allclose(np.linalg.norm(read.rotations, axis=2), 1.0, atol=1e-6)
    assert bpy.ops.articula.bake_poses(filepath=path, armature=arm.name) == {'FINISHED'}
    assert "normalised" in "".join(capfd.readouterr())
    cli = pkg("addon.cli.main")
    blend = str(tmp_path / "rig.blend")
    assert cli.main(["build-rig", "--bundle", path, "--blend", blend]) == 0
    assert "warning: " in capfd.readouterr().out
    assert cli.main(["bake", "--bundle", path, "--blend", blend, "--armature", "f32"]) == 0
    out = capfd.readouterr().out
    assert "warning: " in out and "normalised" in out, out
