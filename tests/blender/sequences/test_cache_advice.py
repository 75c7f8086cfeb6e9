"""A missing cache says what to do (issue 16, rough edges item 4): put the named ``<blend name>_articula``
folder back beside the .blend, or import again; for scan and point-cloud objects alike, on the object
(its warning, the console line) and in the panel's text (:func:`playback.cache_problem`)."""
import os

import bpy
import pytest

from .test_import_depth import make_recording
from .test_import_scans import make_frames, write_folder

pytestmark = pytest.mark.usefixtures("cache_home")   # a fresh ARTICULA_HOME per test


def _saved_with_both(tmp_path):
    assert bpy.ops.articula.import_scans(directory=write_folder(str(tmp_path / "scans"), make_frames(4, seed=3)),
                                         name="Scans") == {'FINISHED'}
    assert bpy.ops.articula.import_depth(directory=make_recording(tmp_path / "rec", n=3)[0]) == {'FINISHED'}
    blend = tmp_path / "proj" / "m.blend"
    blend.parent.mkdir()
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    return blend


def test_missing_cache_folder_is_named_with_where_to_put_it(tmp_path, pkg):
    playback = pkg("addon.sequences.playback")
    blend = _saved_with_both(tmp_path)
    os.rename(tmp_path / "proj" / "m_articula", tmp_path / "elsewhere")
    bpy.ops.wm.open_mainfile(filepath=str(blend))
    advice = f"put the folder m_articula back beside m.blend (in {tmp_path / 'proj'}), or import the"
    scans, points = bpy.data.objects["Scans"], bpy.data.objects["rec Points"]
    assert scans[playback.WARNING].startswith("Scans: its frame cache ")
    assert f"is missing; {advice} scans again" in scans[playback.WARNING]
    assert points[playback.WARNING].startswith("rec Points: its point cache ")
    assert f"is missing; {advice} depth recording again" in points[playback.WARNING]
    for ob, source in ((scans, "scans"), (points, "depth recording")):
        problem = playback.cache_problem(ob)              # what the panel shows
        assert problem.startswith(f"frame cache missing: {playback.cache_abspath(ob)}; ")
        assert problem.endswith(f"{advice} {source} again")
    os.rename(tmp_path / "elsewhere", tmp_path / "proj" / "m_articula")     # the advice works
    bpy.context.scene.frame_set(2)
    assert playback.WARNING not in scans and playback.WARNING not in points
    assert playback.cache_problem(scans) == playback.cache_problem(points) == ""


def test_unreadable_cache_says_import_again(tmp_path, pkg):
    playback = pkg("addon.sequences.playback")
    blend = _saved_with_both(tmp_path)
    for ob in bpy.data.objects:
        if ob.articula.cache_file:
            with open(playback.cache_abspath(ob), "wb") as fh:
                fh.write(b"garbage")
    bpy.ops.wm.open_mainfile(filepath=str(blend))
    scans, points = bpy.data.objects["Scans"], bpy.data.objects["rec Points"]
    assert "is unreadable; import the scans again" in scans[playback.WARNING]
    assert points[playback.WARNING].startswith("rec Points: ")
    assert points[playback.WARNING].endswith("; import the depth recording again")
    assert "put the folder" not in scans[playback.WARNING] + points[playback.WARNING]
