"""Gaze shots on characters linked from another .blend: through a library override (Object › Library
Override › Make) ``articula.gaze`` and ``./run gaze`` put the shot's NLA strip on the override, the pose
is the one the local character gets, and the saved file reloads with it; a plainly linked armature
(read-only) is refused before anything changes, with one line naming the library's file and what to do."""
import os

import bpy
import numpy as np
import pytest

from ..linked_helpers import (HERO, HERO_CHAR, animation_state, bone_matrices, counts, link_override, link_plain,
                              overridden, write_library)

FRAMES = range(1, 41)
SHOT = dict(frame_start=5, frame_end=35, fade_frames=5)


def _look():
    ob = bpy.data.objects.new("Look", None)
    bpy.context.scene.collection.objects.link(ob)
    ob.location = (1.2, -2.0, 1.9)
    ob.keyframe_insert("location", frame=5)
    ob.location = (-1.0, -2.5, 1.1)
    ob.keyframe_insert("location", frame=35)
    return ob


@pytest.fixture
def library(pkg, tmp_path):
    lib, _, _ = write_library(pkg, str(tmp_path))
    bpy.ops.wm.open_mainfile(filepath=lib)               # the reference: the same character, local
    _look()
    hero = bpy.data.objects[HERO]
    before = bone_matrices(hero, FRAMES)
    assert bpy.ops.articula.gaze(armature=HERO, target="Look", **SHOT) == {'FINISHED'}
    after = bone_matrices(hero, FRAMES)
    assert np.abs(after - before).max() > 0.05                     # the shot turns the head
    bpy.ops.wm.read_homefile(use_empty=True)
    return lib, after


def _gaze_strips(ob):
    return [s.name for t in ob.animation_data.nla_tracks if t.name.startswith("Articula Gaze") for s in t.strips]


def test_gaze_on_a_library_override_matches_the_local_character(pkg, tmp_path, library):
    lib, expected = library
    hero = overridden(link_override(lib, HERO_CHAR), HERO)
    _look()
    assert bpy.ops.articula.gaze(armature=hero.name, target="Look", **SHOT) == {'FINISHED'}
    assert _gaze_strips(hero) == ["Gaze Look 5-35"]
    assert np.abs(bone_matrices(hero, FRAMES) - expected).max() < 1e-5
    out = str(tmp_path / "out.blend")
    bpy.ops.wm.save_as_mainfile(filepath=out)
    bpy.ops.wm.open_mainfile(filepath=out)
    hero = next(o for o in bpy.data.objects if o.name == HERO and o.override_library is not None)
    assert _gaze_strips(hero) == ["Gaze Look 5-35"]
    assert np.abs(bone_matrices(hero, FRAMES) - expected).max() < 1e-5


def test_gaze_command_on_a_library_override(pkg, tmp_path, library):
    lib, expected = library
    link_override(lib, HERO_CHAR)
    _look()
    shot, out = str(tmp_path / "shot.blend"), str(tmp_path / "out.blend")
    bpy.ops.wm.save_as_mainfile(filepath=shot)
    assert pkg("addon.cli.main").main(["gaze", "--blend", shot, "--armature", HERO, "--target", "Look",
                                       "--frames", "5:35", "--fade", "5", "--out", out]) == 0
    bpy.ops.wm.open_mainfile(filepath=out)
    hero = next(o for o in bpy.data.objects if o.name == HERO and o.override_library is not None)
    assert _gaze_strips(hero) == ["Gaze Look 5-35"]
    assert np.abs(bone_matrices(hero, FRAMES) - expected).max() < 1e-5


def test_gaze_on_a_plainly_linked_character_is_refused_and_nothing_changes(pkg, tmp_path, capsys, library):
    lib, _ = library
    hero, = link_plain(lib, [HERO])
    _look()
    before, animation = counts(), animation_state(hero)
    with pytest.raises(RuntimeError, match=r"'Hero' is linked from lib\.blend and cannot be changed: make a library "
                                           r"override \(Object › Library Override › Make\) and try again"):
        bpy.ops.articula.gaze(armature=hero.name, target="Look", **SHOT)
    assert counts() == before and animation_state(hero) == animation
    shot, out = str(tmp_path / "shot.blend"), str(tmp_path / "out.blend")
    bpy.ops.wm.save_as_mainfile(filepath=shot)
    capsys.readouterr()
    assert pkg("addon.cli.main").main(["gaze", "--blend", shot, "--armature", HERO, "--target", "Look",
                                       "--frames", "5:35", "--out", out]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "lib.blend" in err[0] and "make a library override" in err[0]
    assert not os.path.exists(out)
