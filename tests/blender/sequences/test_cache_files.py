"""Caches travel with the .blend (issue 16 item 2): a saved file carries its scan and point caches beside
it with relative paths (moved out of the cache folder on the first save, copied on Save As to another
folder), so it plays in a fresh process after the cache folder is deleted; a missing cache is shown on
the object and in the panel; re-imports leave no orphan caches after saving."""
import json
import os
import shutil
import subprocess
import sys

import bpy
import numpy as np
import pytest

from ...conftest import REPO
from .test_import_depth import make_recording
from .test_import_scans import evaluated, make_frames, write_folder

pytestmark = pytest.mark.usefixtures("cache_home")   # a fresh ARTICULA_HOME per test


def _import_both(tmp_path):
    """A scan sequence "Scans" (4 frames) and a point-cloud sequence "rec Points" (3 frames)."""
    frames = make_frames(4, seed=5)
    assert bpy.ops.articula.import_scans(directory=write_folder(str(tmp_path / "scans"), frames),
                                         name="Scans") == {'FINISHED'}
    folder, _ = make_recording(tmp_path / "rec", n=3)
    assert bpy.ops.articula.import_depth(directory=folder) == {'FINISHED'}
    return frames


def _cloud_frames(ob, n):
    out = []
    for frame in range(1, n + 1):
        bpy.context.scene.frame_set(frame)
        co = np.empty(3 * len(ob.data.vertices), np.float32)
        ob.data.attributes["position"].data.foreach_get("vector", co)
        out.append(co.reshape(-1, 3))
    return out


PLAY = """
import json, sys
sys.path.insert(0, {repo!r})
import bpy, numpy as np
import batch
batch.enable_addon(bpy)
bpy.ops.wm.open_mainfile(filepath={blend!r})
out = {{}}
for name in ("Scans", "rec Points"):
    ob = bpy.data.objects[name]
    frames = []
    for f in range(1, ob.articula.frame_count + 1):
        bpy.context.scene.frame_set(f)
        co = np.empty(3 * len(ob.data.vertices), np.float32)
        ob.data.attributes["position"].data.foreach_get("vector", co)
        frames.append(co.tolist())
    out[name] = {{"frames": frames, "warning": ob.get("articula_warning", "")}}
print("PLAYED" + json.dumps(out))
"""


def _play_in_fresh_process(blend, tmp_path):
    """Open ``blend`` in a new Blender process (its own cache folder) and read every frame of both objects."""
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "user2"), ARTICULA_HOME=str(tmp_path / "home2"))
    res = subprocess.run([sys.executable, "-c", PLAY.format(repo=REPO, blend=str(blend))], capture_output=True,
                         text=True, env=env, timeout=300, cwd=str(tmp_path))
    line = [ln for ln in res.stdout.splitlines() if ln.startswith("PLAYED")]
    assert line, res.stdout[-2000:] + res.stderr[-2000:]
    return json.loads(line[0][len("PLAYED"):])


def test_first_save_moves_the_caches_beside_the_file(tmp_path, cache_home, pkg):
    frames = _import_both(tmp_path)
    scans, cloud = bpy.data.objects["Scans"], bpy.data.objects["rec Points"]
    for ob in (scans, cloud):                     # unsaved: absolute, in the cache folder
        assert ob.articula.cache_file.startswith(str(cache_home))
    clouds = _cloud_frames(cloud, 3)
    blend = tmp_path / "project" / "take.blend"
    blend.parent.mkdir()
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    for ob in (scans, cloud):
        assert ob.articula.cache_file.startswith("//take_articula/"), ob.articula.cache_file
        assert os.path.exists(bpy.path.abspath(ob.articula.cache_file))
    assert not [f for _d, _s, files in os.walk(cache_home) for f in files]      # moved, not copied
    shutil.rmtree(cache_home)
    played = _play_in_fresh_process(blend, tmp_path)
    assert np.array_equal(np.array(played["Scans"]["frames"], np.float32).reshape(4, -1, 3), frames)
    for k in range(3):
        assert np.array_equal(np.array(played["rec Points"]["frames"][k], np.float32).reshape(-1, 3), clouds[k])
    assert played["Scans"]["warning"] == played["rec Points"]["warning"] == ""


def test_save_as_elsewhere_copies_and_the_original_keeps_its_caches(tmp_path, pkg):
    frames = _import_both(tmp_path)
    first = tmp_path / "a" / "one.blend"
    first.parent.mkdir()
    bpy.ops.wm.save_as_mainfile(filepath=str(first))
    other = tmp_path / "b" / "two.blend"
    other.parent.mkdir()
    bpy.ops.wm.save_as_mainfile(filepath=str(other))
    for ob in bpy.data.objects:
        if ob.articula.cache_file:
            assert ob.articula.cache_file.startswith("//two_articula/")
    one = sorted(os.listdir(tmp_path / "a" / "one_articula"))
    assert one == sorted(os.listdir(tmp_path / "b" / "two_articula")) and len(one) == 2
    assert np.array_equal(np.array(_play_in_fresh_process(first, tmp_path)["Scans"]["frames"],
                                   np.float32).reshape(4, -1, 3), frames)
    shutil.rmtree(tmp_path / "a")                 # the copy does not need the original's folder
    assert np.array_equal(np.array(_play_in_fresh_process(other, tmp_path)["Scans"]["frames"],
                                   np.float32).reshape(4, -1, 3), frames)


def test_save_copy_leaves_the_open_file_on_its_own_caches(tmp_path, pkg):
    _import_both(tmp_path)
    paths = {ob.name: ob.articula.cache_file for ob in bpy.data.objects if ob.articula.cache_file}
    copy = tmp_path / "copy" / "c.blend"
    copy.parent.mkdir()
    bpy.ops.wm.save_as_mainfile(filepath=str(copy), copy=True)
    assert {ob.name: ob.articula.cache_file for ob in bpy.data.objects if ob.articula.cache_file} == paths
    for path in paths.values():
        assert os.path.exists(path)               # still where the unsaved file had them
    assert len(os.listdir(tmp_path / "copy" / "c_articula")) == 2
    assert _play_in_fresh_process(copy, tmp_path)["Scans"]["warning"] == ""


def test_missing_cache_is_shown_on_the_object_and_in_the_panel(tmp_path, pkg):
    _import_both(tmp_path)
    blend = tmp_path / "m.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    playback = pkg("addon.sequences.playback")
    scans = bpy.data.objects["Scans"]
    path = playback.cache_abspath(scans)
    assert playback.cache_problem(scans) == "" and playback.WARNING not in scans
    hidden = path + ".away"
    os.rename(path, hidden)
    bpy.ops.wm.open_mainfile(filepath=str(blend))
    scans = bpy.data.objects["Scans"]
    assert path in scans[playback.WARNING] and "missing" in scans[playback.WARNING]
    assert playback.cache_problem(scans).startswith(f"frame cache missing: {path}; ")
    assert playback.cache_problem(bpy.data.objects["rec Points"]) == ""
    panels = pkg("addon.panels")
    lines = panels._wrap(playback.cache_problem(scans), 48)
    assert "".join(lines).replace(" ", "") == playback.cache_problem(scans).replace(" ", "")
    assert all(len(line) <= 48 for line in lines[:-1])
    os.rename(hidden, path)                       # back: it plays and the warning goes
    bpy.context.scene.frame_set(3)
    assert playback.WARNING not in scans and playback.cache_problem(scans) == ""


@pytest.mark.parametrize("saved_first", [True, False])
def test_reimporting_leaves_no_orphan_caches(tmp_path, pkg, cache_home, saved_first):
    blend = tmp_path / "r.blend"
    if saved_first:
        bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    folder, _ = make_recording(tmp_path / "rec", n=3)
    scans = write_folder(str(tmp_path / "scans"), make_frames(3, seed=2))
    for _ in range(3):                            # import, delete, import again ...
        for ob in [ob for ob in bpy.data.objects]:
            bpy.data.objects.remove(ob)
        assert bpy.ops.articula.import_depth(directory=folder) == {'FINISHED'}
        assert bpy.ops.articula.import_scans(directory=scans) == {'FINISHED'}
    kept = tmp_path / "r_articula" / "keep.txt"   # a user's file in the folder is never touched
    kept.parent.mkdir(exist_ok=True)
    kept.write_text("mine")
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    used = sorted(os.path.basename(bpy.path.abspath(ob.articula.cache_file))
                  for ob in bpy.data.objects if ob.articula.cache_file)
    assert len(used) == 2
    assert sorted(os.listdir(kept.parent)) == sorted(used + ["keep.txt"])
    assert not [f for _d, _s, files in os.walk(cache_home) for f in files]
    bpy.ops.wm.save_mainfile()                    # saving again keeps what the .blend1 uses
    assert sorted(os.listdir(kept.parent)) == sorted(used + ["keep.txt"])


def test_an_undo_step_from_before_the_save_still_finds_the_moved_cache(tmp_path, pkg):
    frames = make_frames(3, seed=9)
    assert bpy.ops.articula.import_scans(directory=write_folder(str(tmp_path / "u"), frames)) == {'FINISHED'}
    bpy.ops.ed.undo_push(message="imported")
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "u.blend"))
    ob = bpy.data.objects["u"]
    ob.articula.cache_file = ob.articula.cache_file.replace("//u_articula", str(tmp_path / "home" / "scan_cache"))
    assert not os.path.exists(ob.articula.cache_file)          # as the undo step names it
    for k in (2, 0):
        bpy.context.scene.frame_set(1 + k)
        assert np.array_equal(evaluated(ob), frames[k])
