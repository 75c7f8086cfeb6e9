"""addon/sequences/playback.py: one set of handlers plays scan sequences and point-cloud sequences alike,
on frame change, after loading a file, after undo/redo, and after saving the .blend elsewhere."""
import os

import bpy
import numpy as np
import pytest

from .test_import_depth import make_recording
from .test_import_scans import evaluated, make_frames, write_folder


@pytest.fixture
def both(tmp_path, pkg):
    """A saved .blend holding a scan sequence ("Scans", 4 frames) and a point-cloud sequence ("rec Points",
    4 frames), both starting at frame 1; returns a function checking what every object shows."""
    blend = tmp_path / "proj" / "scene.blend"
    blend.parent.mkdir()
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    frames = make_frames(4, seed=3)
    assert bpy.ops.articula.import_scans(directory=write_folder(str(tmp_path / "scans"), frames),
                                         name="Scans") == {'FINISHED'}
    folder, _ = make_recording(tmp_path / "rec", n=4)
    assert bpy.ops.articula.import_depth(directory=folder) == {'FINISHED'}
    points, playback = pkg("addon.sequences.points"), pkg("addon.sequences.playback")
    clouds = points.load_sequence(playback.cache_abspath(bpy.data.objects["rec Points"]))
    clouds = [np.array(clouds.points[clouds.frame(k)]) for k in range(4)]

    def check(frame=None):
        """Both objects show the recording's frame for ``frame`` (default: the scene's current one),
        in their meshes and in the evaluated scene."""
        k = min(max((bpy.context.scene.frame_current if frame is None else frame) - 1, 0), 3)
        scans, cloud = bpy.data.objects["Scans"], bpy.data.objects["rec Points"]
        assert np.array_equal(evaluated(scans), frames[k])
        co = np.empty(3 * len(cloud.data.vertices), np.float32)
        cloud.data.attributes["position"].data.foreach_get("vector", co)
        assert np.array_equal(co.reshape(-1, 3), clouds[k])
        assert scans.data[playback.SHOWN] == k and cloud.data[playback.SHOWN] == k
    return blend, check


def test_handlers_are_installed_once_and_before_the_frame_is_evaluated(pkg):
    playback = pkg("addon.sequences.playback")

    def ours(name):
        return [h for h in getattr(bpy.app.handlers, name) if getattr(h, "__module__", "") == playback.__name__]
    for kind in ("scans", "points"):            # as an add-on reload does: register again
        pkg(f"addon.sequences.{kind}").register_extra()
    for name in ("frame_change_pre", "load_post", "undo_post", "redo_post", "save_pre", "save_post",
                 "save_post_fail"):
        assert len(ours(name)) == 1, name
    assert not ours("frame_change_post")
    assert not [h for h in bpy.app.handlers.frame_change_post if "articula" in getattr(h, "__module__", "")]


def test_both_kinds_follow_the_frame(both):
    _, check = both
    for frame in (3, 1, 4, 2, 9, -5):           # outside the recording the end frames are held
        bpy.context.scene.frame_set(frame)
        check(frame)


def test_both_kinds_play_after_loading_the_file(both):
    blend, check = both
    bpy.context.scene.frame_set(2)
    bpy.ops.wm.save_mainfile()
    bpy.context.scene.frame_set(4)              # the file holds frame 2
    bpy.ops.wm.open_mainfile(filepath=str(blend))
    check(2)
    for frame in (4, 1, 3):
        bpy.context.scene.frame_set(frame)
        check(frame)


def test_both_kinds_play_after_undo_and_redo(both):
    _, check = both
    bpy.context.scene.frame_set(1)
    bpy.ops.ed.undo_push(message="imported")
    bpy.context.scene.frame_set(3)
    bpy.ops.object.empty_add()
    bpy.ops.ed.undo_push(message="empty")
    bpy.ops.ed.undo()
    assert "Empty" not in bpy.data.objects
    check()
    bpy.ops.ed.redo()
    assert "Empty" in bpy.data.objects
    check()
    bpy.context.scene.frame_set(2)
    check(2)


def test_saving_elsewhere_keeps_both_caches_found(both, tmp_path):
    blend, check = both
    scans, cloud = bpy.data.objects["Scans"], bpy.data.objects["rec Points"]
    assert scans.articula.cache_file.startswith("//") and cloud.articula.cache_file.startswith("//")
    other = tmp_path / "elsewhere" / "copy.blend"
    other.parent.mkdir()
    bpy.ops.wm.save_as_mainfile(filepath=str(other))
    for ob in (scans, cloud):                   # copied beside the new .blend (test_cache_files.py)
        assert ob.articula.cache_file.startswith("//copy_articula/")
    bpy.ops.wm.open_mainfile(filepath=str(other))
    for frame in (3, 1):
        bpy.context.scene.frame_set(frame)
        check(frame)


def test_an_object_without_its_cache_is_reported_once_and_the_other_plays(both, capsys, pkg):
    _, check = both
    cloud = bpy.data.objects["rec Points"]
    os.remove(pkg("addon.sequences.playback").cache_abspath(cloud))
    pkg("addon.sequences.points").forget_cache()
    for frame in (2, 3, 4):
        bpy.context.scene.frame_set(frame)
        assert np.array_equal(evaluated(bpy.data.objects["Scans"]), make_frames(4, seed=3)[frame - 1])
    assert capsys.readouterr().out.count("rec Points: cannot show point-cloud frame 2") == 1


def test_cache_paths_and_frame_index(pkg, tmp_path):
    playback = pkg("addon.sequences.playback")
    blend = str(tmp_path / "p" / "a.blend")
    assert playback.stored_path(str(tmp_path / "p" / "c" / "x.npy"), blend) == "//c/x.npy"
    assert playback.stored_path(str(tmp_path / "q" / "x.npy"), blend) == str(tmp_path / "q" / "x.npy")
    assert playback.stored_path(str(tmp_path / "x.npy"), "") == str(tmp_path / "x.npy")
    assert playback.safe_name("a b/c:d.e-f_g", "x") == "a_b_c_d.e-f_g" and playback.safe_name("", "x") == "x"
    ob = bpy.data.objects.new("o", bpy.data.meshes.new("o"))
    ob.articula.frame_start, ob.articula.frame_count = 5, 3
    assert [playback.frame_index(ob, f) for f in (1, 5, 6, 7, 8, 100)] == [0, 0, 1, 2, 2, 2]
