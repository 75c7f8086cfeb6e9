"""Batch commands never lose a user's work (issue 16 items 1, 3 and 11): ``--blend`` on an existing file
opens it and adds to it (objects, actions and settings kept, a ``.blend1`` of the previous version), a
failed command leaves the file byte-identical and makes no file at a new path, outputs start from an
empty scene (no default cube, camera, light), and an error is printed once."""
import hashlib
import os
import subprocess
import sys

import bpy
import numpy as np
import pytest

from ...conftest import REPO
from articula.sample_scenes.tube_scans import hybrid_truth
from ..rig_helpers import poses, subject
from ..sequences.test_import_depth import make_recording

pytestmark = pytest.mark.usefixtures("cache_home")   # a fresh ARTICULA_HOME per test


def _digest(path) -> str:
    return hashlib.sha256(open(path, "rb").read()).hexdigest()


def _scans(folder, pkg, n=4, faces=None, frames=None):
    os.makedirs(folder, exist_ok=True)
    if frames is None:
        square = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
        frames, faces = [square + [0, 0, 0.1 * k] for k in range(n)], np.array([[0, 1, 2], [0, 2, 3]])
    writer = pkg("sample_scenes.mesh_files").SequenceWriter(faces, "obj")
    for k, f in enumerate(frames):
        writer.write(os.path.join(folder, f"s{k}.obj"), f)
    return str(folder)


def _user_file(path):
    """A user's .blend: an object with an action, a material and a scene setting of theirs."""
    bpy.ops.wm.read_homefile(use_empty=True)
    ob = bpy.data.objects.new("Mine", bpy.data.meshes.new("Mine"))
    bpy.context.scene.collection.objects.link(ob)
    ob.location = (1, 2, 3)
    ob.keyframe_insert("location", frame=7)
    bpy.data.materials.new("MyMaterial").use_fake_user = True
    bpy.context.scene.render.fps = 17
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    bpy.ops.wm.read_homefile(use_empty=True)
    return _digest(path)


def _assert_user_data_kept(path):
    bpy.ops.wm.open_mainfile(filepath=str(path))
    ob = bpy.data.objects["Mine"]
    assert tuple(ob.location) == (1, 2, 3) and ob.animation_data.action is not None
    assert "MyMaterial" in bpy.data.materials and bpy.context.scene.render.fps == 17


def _commands(pkg, tmp_path):
    """Each command that writes a .blend: (name, arguments without --blend, what it adds)."""
    bundle = str(tmp_path / "subject.npz")
    model = subject(pkg, rings=6, segments=8)
    pkg("solver.formats.bundle").save_bundle(bundle, model, poses(pkg, model.skeleton.num_bones, 3, seed=4))
    folder, _ = make_recording(tmp_path / "rec", n=3)
    return {"import-scans": (["--scans", _scans(tmp_path / "scans", pkg)], "scans"),
            "import-depth": (["--depth", folder], "rec Points"),
            "build-rig": (["--bundle", bundle], "subject")}


@pytest.mark.parametrize("command", ["import-scans", "import-depth", "build-rig"])
def test_existing_file_is_added_to_with_a_backup(pkg, tmp_path, command):
    args, added = _commands(pkg, tmp_path)[command]
    blend = tmp_path / "mine.blend"
    before = _user_file(blend)
    assert pkg("addon.cli.main").main([command, *args, "--blend", str(blend)]) == 0
    assert _digest(str(blend) + "1") == before            # Blender's backup of the previous version
    _assert_user_data_kept(blend)
    assert added in bpy.data.objects
    for ob in bpy.data.objects:                           # every cache beside the file, relative
        if ob.articula.cache_file:
            assert ob.articula.cache_file.startswith("//mine_articula/")
            assert os.path.exists(bpy.path.abspath(ob.articula.cache_file))


@pytest.mark.parametrize("command", ["import-scans", "import-depth", "build-rig"])
def test_new_file_starts_from_an_empty_scene(pkg, tmp_path, command):
    args, added = _commands(pkg, tmp_path)[command]
    blend = tmp_path / "new" / "out.blend"
    bpy.ops.wm.read_homefile()                    # Blender's startup scene, as a batch process starts
    assert {"Cube", "Camera", "Light"} <= {ob.name for ob in bpy.data.objects}
    assert pkg("addon.cli.main").main([command, *args, "--blend", str(blend)]) == 0
    assert not os.path.exists(str(blend) + "1")
    bpy.ops.wm.open_mainfile(filepath=str(blend))
    names = {ob.name for ob in bpy.data.objects}
    assert added in names and not names & {"Cube", "Camera", "Light"}
    assert not {"Cube", "Camera", "Light"} & {d.name for d in (*bpy.data.meshes, *bpy.data.cameras, *bpy.data.lights)}


FAILURES = {
    "import-scans": ["--scans", "MISSING"],
    "import-depth": ["--depth", "MISSING"],
    "build-rig": ["--bundle", "MISSING.npz"],
    "learn-rig": ["--scans", "MISSING", "--out", "OUT/m.npz"],
    "track": ["--model", "MISSING.npz", "--scans", "MISSING", "--out", "OUT/t.npz"],
}


@pytest.mark.parametrize("command", sorted(FAILURES))
def test_failed_command_leaves_the_file_byte_identical(pkg, tmp_path, command, cache_home):
    blend = tmp_path / "mine.blend"
    before = _user_file(blend)
    args = [a.replace("MISSING", str(tmp_path / "missing")).replace("OUT", str(tmp_path)) for a in FAILURES[command]]
    assert pkg("addon.cli.main").main([command, *args, "--blend", str(blend)]) == 2
    assert _digest(blend) == before and not os.path.exists(str(blend) + "1")
    new = tmp_path / "fresh" / "new.blend"
    assert pkg("addon.cli.main").main([command, *args, "--blend", str(new)]) == 2
    assert not new.exists() and not new.parent.exists()
    assert sorted(os.listdir(tmp_path)) == sorted(["mine.blend", *(["home"] if cache_home.exists() else [])])


def test_failure_after_the_import_saves_nothing_and_removes_its_cache(pkg, tmp_path, monkeypatch, cache_home):
    """learn-rig imports the scans into the file, then builds the rig: when building fails the file keeps
    its bytes and the scans' new frame cache is deleted again."""
    model, pose_set, scans = hybrid_truth(M=4, seed=4, max_angle=0.6)
    folder = _scans(tmp_path / "scans", pkg, faces=model.faces, frames=scans)
    blend = tmp_path / "mine.blend"
    before = _user_file(blend)
    learn = pkg("addon.cli.learn")

    def broken_build(*_args, **_kw):
        raise pkg("solver.errors").ArticulaInputError("planted failure while building the rig")
    monkeypatch.setattr(learn.result, "build", broken_build)
    code = pkg("addon.cli.main").main(["learn-rig", "--scans", folder, "--parts", "4", "--iterations", "0",
                                       "--threads", "1", "--out", str(tmp_path / "m.npz"), "--blend", str(blend)])
    assert code == 2
    assert _digest(blend) == before and not os.path.exists(str(blend) + "1")
    assert not (tmp_path / "mine_articula").exists()
    assert not [n for _d, _s, files in os.walk(cache_home) for n in files if n.endswith(".npy")]


def test_bake_over_the_file_or_as_another(pkg, tmp_path):
    args, _ = _commands(pkg, tmp_path)["build-rig"]
    blend = tmp_path / "rig.blend"
    cli = pkg("addon.cli.main")
    assert cli.main(["build-rig", *args, "--blend", str(blend)]) == 0
    built = _digest(blend)
    assert cli.main(["bake", *args, "--blend", str(blend), "--armature", "subject", "--out",
                     str(tmp_path / "baked.blend")]) == 0
    assert _digest(blend) == built and (tmp_path / "baked.blend").is_file()
    assert cli.main(["bake", "--bundle", str(tmp_path / "nope.npz"), "--blend", str(blend)]) == 2
    assert _digest(blend) == built and not os.path.exists(str(blend) + "1")
    assert cli.main(["bake", *args, "--blend", str(blend), "--armature", "subject"]) == 0
    assert _digest(str(blend) + "1") == built


def _run(args, tmp_path):
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "user"), ARTICULA_HOME=str(tmp_path / "home"))
    return subprocess.run([sys.executable, os.path.join(REPO, "batch.py"), *args], capture_output=True,
                          text=True, env=env, timeout=300)


def test_batch_process_keeps_the_file_and_prints_an_error_once(pkg, tmp_path):
    """As a user runs it (``cp rig.blend e.blend; ./run import-scans --scans /nonexistent --blend e.blend``):
    a fresh process, the file untouched, the message printed once; then a real import adds to it."""
    blend = tmp_path / "e.blend"
    before = _user_file(blend)
    res = _run(["import-scans", "--scans", str(tmp_path / "nonexistent"), "--blend", str(blend)], tmp_path)
    assert res.returncode == 2 and _digest(blend) == before
    printed = res.stdout + res.stderr
    assert printed.count("nonexistent: file or folder not found") == 1, printed
    assert res.stderr.strip().splitlines()[-1].startswith("articula import-scans: error:")
    res = _run(["import-scans", "--scans", _scans(tmp_path / "scans", pkg), "--blend", str(blend)], tmp_path)
    assert res.returncode == 0, res.stderr[-2000:]
    assert _digest(str(blend) + "1") == before
    _assert_user_data_kept(blend)
    assert bpy.data.objects["scans"].articula.frame_count == 4


def test_batch_process_output_has_no_default_objects(pkg, tmp_path):
    blend = tmp_path / "out" / "new.blend"
    res = _run(["import-scans", "--scans", _scans(tmp_path / "scans", pkg), "--blend", str(blend)], tmp_path)
    assert res.returncode == 0, res.stderr[-2000:]
    bpy.ops.wm.open_mainfile(filepath=str(blend))
    assert [ob.name for ob in bpy.data.objects] == ["scans"]
    assert bpy.data.objects["scans"].articula.cache_file.startswith("//new_articula/")
