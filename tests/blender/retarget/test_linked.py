"""Retargeting onto characters linked from another .blend: through a library override (Object › Library
Override › Make) the operator and ``./run retarget`` give the override the same new action as the local
character gets, and the saved file reloads with it; a plainly linked armature (read-only) is refused
before anything changes, with one line naming the library's file and what to do.  Baking poses
(``articula.bake_poses``, ``./run bake``) onto an overridden or linked Articula rig likewise."""
import os

import bpy
import numpy as np
import pytest

from ...conftest import SHARED_DATA
from ..linked_helpers import (HERO, HERO_CHAR, RIG_CHAR, animation_state, bone_matrices, counts, link_override,
                              link_plain, overridden, write_library)

BVH = os.path.join(SHARED_DATA, "mocap", "cmu_131_01.bvh")
FRAMES = (1, 150, 420, 700, 994)
REFUSED = r"'{}' is linked from lib\.blend and cannot be changed: make a library override \(Object › Library " \
          r"Override › Make\) and try again"


def _bvh():
    assert os.path.isfile(BVH), f"missing fixture {BVH}"
    bpy.ops.import_anim.bvh(filepath=BVH, global_scale=0.056444, frame_start=1)
    return bpy.context.active_object


@pytest.fixture
def library(pkg, tmp_path):
    return write_library(pkg, str(tmp_path))


def _local_retarget(lib):
    """Bone matrices of the library's own (local) Hero after retargeting the BVH onto it."""
    bpy.ops.wm.open_mainfile(filepath=lib)
    source = _bvh()
    assert bpy.ops.articula.retarget(source=source.name, target=HERO) == {'FINISHED'}
    return bone_matrices(bpy.data.objects[HERO], FRAMES)


def test_retarget_onto_a_library_override_matches_the_local_character(pkg, tmp_path, library):
    lib, _, _ = library
    expected = _local_retarget(lib)
    bpy.ops.wm.read_homefile(use_empty=True)
    hero = overridden(link_override(lib, HERO_CHAR), HERO)
    source = _bvh()
    original = next(o for o in bpy.data.objects if o.name == HERO and o.library is not None)
    with pytest.raises(pkg("solver.errors").ArticulaInputError, match="use its library override 'Hero'"):
        pkg("addon.retarget.skeleton").retarget(bpy.context, source, original)        # the linked original
    assert bpy.ops.articula.retarget(source=source.name, target=hero.name) == {'FINISHED'}
    action = hero.animation_data.action.name
    assert hero.animation_data.action.library is None and "cmu_131_01" in action
    assert np.abs(bone_matrices(hero, FRAMES) - expected).max() < 1e-5
    out = str(tmp_path / "out.blend")
    bpy.ops.wm.save_as_mainfile(filepath=out)
    bpy.ops.wm.open_mainfile(filepath=out)
    hero = next(o for o in bpy.data.objects if o.name == HERO and o.override_library is not None)
    assert hero.animation_data.action.name == action
    assert np.abs(bone_matrices(hero, FRAMES) - expected).max() < 1e-5


def test_retarget_command_onto_a_library_override(pkg, tmp_path, library):
    lib, _, _ = library
    expected = _local_retarget(lib)
    bpy.ops.wm.read_homefile(use_empty=True)
    link_override(lib, HERO_CHAR)
    shot, out = str(tmp_path / "shot.blend"), str(tmp_path / "out.blend")
    bpy.ops.wm.save_as_mainfile(filepath=shot)
    assert pkg("addon.cli.main").main(["retarget", "--source", BVH, "--target", shot, "--out", out]) == 0
    bpy.ops.wm.open_mainfile(filepath=out)
    hero = next(o for o in bpy.data.objects if o.name == HERO and o.override_library is not None)
    assert "cmu_131_01" in hero.animation_data.action.name
    assert np.abs(bone_matrices(hero, FRAMES) - expected).max() < 2e-3     # the command scales the BVH itself


def test_plainly_linked_target_is_refused_and_nothing_changes(pkg, tmp_path, capsys, library):
    lib, _, _ = library
    hero, = link_plain(lib, [HERO])
    source = _bvh()
    before, animation = counts(), animation_state(hero)
    with pytest.raises(RuntimeError, match=REFUSED.format(HERO)):
        bpy.ops.articula.retarget(source=source.name, target=hero.name)
    with pytest.raises(RuntimeError, match=REFUSED.format(HERO)):
        bpy.ops.articula.retarget(source=source.name, target=hero.name, mapping='TOPOLOGY')
    assert counts() == before and animation_state(hero) == animation
    bpy.data.objects.remove(source)
    shot, out = str(tmp_path / "shot.blend"), str(tmp_path / "out.blend")
    bpy.ops.wm.save_as_mainfile(filepath=shot)
    capsys.readouterr()
    assert pkg("addon.cli.main").main(["retarget", "--source", BVH, "--target", shot, "--out", out]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "lib.blend" in err[0] and "make a library override" in err[0]
    assert not os.path.exists(out)


def _bake_reference(lib, rig, take):
    bpy.ops.wm.open_mainfile(filepath=lib)
    assert bpy.ops.articula.bake_poses(filepath=take, armature=rig) == {'FINISHED'}
    return bone_matrices(bpy.data.objects[rig], range(1, 6))


def test_bake_onto_a_library_override_matches_the_local_rig(pkg, tmp_path, library):
    lib, rig, take = library
    expected = _bake_reference(lib, rig, take)
    bpy.ops.wm.read_homefile(use_empty=True)
    arm = overridden(link_override(lib, RIG_CHAR), rig)
    assert bpy.ops.articula.bake_poses(filepath=take, armature=arm.name) == {'FINISHED'}
    assert arm.animation_data.action.library is None
    assert np.abs(bone_matrices(arm, range(1, 6)) - expected).max() < 1e-5
    shot, out = str(tmp_path / "shot.blend"), str(tmp_path / "out.blend")
    bpy.ops.wm.read_homefile(use_empty=True)
    link_override(lib, RIG_CHAR)
    bpy.ops.wm.save_as_mainfile(filepath=shot)
    assert pkg("addon.cli.main").main(["bake", "--bundle", take, "--blend", shot, "--armature", rig,
                                       "--out", out]) == 0
    bpy.ops.wm.open_mainfile(filepath=out)
    arm = next(o for o in bpy.data.objects if o.name == rig and o.override_library is not None)
    assert np.abs(bone_matrices(arm, range(1, 6)) - expected).max() < 1e-5


def test_bake_onto_a_plainly_linked_rig_is_refused_and_nothing_changes(pkg, tmp_path, capsys, library):
    lib, rig, take = library
    arm = link_plain(lib, [rig])[0]
    before, animation = counts(), animation_state(arm)
    with pytest.raises(RuntimeError, match=REFUSED.format(rig)):
        bpy.ops.articula.bake_poses(filepath=take, armature=arm.name)
    assert counts() == before and animation_state(arm) == animation
    shot, out = str(tmp_path / "shot.blend"), str(tmp_path / "out.blend")
    bpy.ops.wm.save_as_mainfile(filepath=shot)
    capsys.readouterr()
    assert pkg("addon.cli.main").main(["bake", "--bundle", take, "--blend", shot, "--armature", rig,
                                       "--out", out]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "lib.blend" in err[0] and "make a library override" in err[0]
    assert not os.path.exists(out)
