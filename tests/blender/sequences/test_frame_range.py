"""Imports never shorten the scene's frame range (issue 16, rough edges item 2): a scan or depth import
widens the range to include the new sequence and sets it outright only in an otherwise empty scene, in
the operator and in the batch command on an existing ``--blend``."""
import os

import bpy
import pytest

from .test_import_depth import make_recording
from .test_import_scans import make_frames, write_folder

pytestmark = pytest.mark.usefixtures("cache_home")   # a fresh ARTICULA_HOME per test


def _user_scene(start=1, end=77):
    """The user's scene: an object of theirs and their frame range."""
    scene = bpy.context.scene
    scene.collection.objects.link(bpy.data.objects.new("Mine", bpy.data.meshes.new("Mine")))
    scene.frame_start, scene.frame_end = start, end
    return scene


def _import(kind, tmp_path, **props):
    if kind == "scans":
        folder = write_folder(str(tmp_path / f"scans{len(os.listdir(tmp_path))}"), make_frames(4, seed=1))
        assert bpy.ops.articula.import_scans(directory=folder, **props) == {'FINISHED'}
        return 4
    folder, _ = make_recording(tmp_path / f"rec{len(os.listdir(tmp_path))}", n=3)
    assert bpy.ops.articula.import_depth(directory=folder, **props) == {'FINISHED'}
    return 3


@pytest.mark.parametrize("kind", ["scans", "depth"])
def test_import_keeps_a_longer_range(tmp_path, kind):
    scene = _user_scene(1, 77)
    _import(kind, tmp_path)
    assert (scene.frame_start, scene.frame_end) == (1, 77)


@pytest.mark.parametrize("kind", ["scans", "depth"])
def test_import_widens_the_range_to_the_new_sequence(tmp_path, kind):
    scene = _user_scene(10, 20)
    n = _import(kind, tmp_path, frame_start=18)
    assert (scene.frame_start, scene.frame_end) == (10, 18 + n - 1)
    _import(kind, tmp_path, frame_start=3)
    assert (scene.frame_start, scene.frame_end) == (3, 18 + n - 1)


@pytest.mark.parametrize("kind", ["scans", "depth"])
def test_import_into_an_empty_scene_sets_the_range(tmp_path, kind):
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end = 1, 250                # Blender's default
    n = _import(kind, tmp_path, frame_start=5)
    assert (scene.frame_start, scene.frame_end) == (5, 5 + n - 1)


@pytest.mark.parametrize("kind", ["scans", "depth"])
def test_batch_import_into_an_existing_file_keeps_its_range(pkg, tmp_path, kind):
    blend = tmp_path / "my.blend"
    _user_scene(1, 77)
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    bpy.ops.wm.read_homefile(use_empty=True)
    if kind == "scans":
        args = ["import-scans", "--scans", write_folder(str(tmp_path / "scans"), make_frames(30, seed=2))]
    else:
        args = ["import-depth", "--depth", make_recording(tmp_path / "rec", n=3)[0], "--frame-start", "90"]
    assert pkg("addon.cli.main").main([*args, "--blend", str(blend)]) == 0
    bpy.ops.wm.open_mainfile(filepath=str(blend))
    scene = bpy.context.scene
    assert (scene.frame_start, scene.frame_end) == ((1, 77) if kind == "scans" else (1, 92))
