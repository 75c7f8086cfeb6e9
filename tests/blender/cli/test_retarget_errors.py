"""``./run retarget`` on bad files, as a user calls it (a fresh process): a truncated or malformed BVH and
a target or source .blend without an armature each give exit code 2, exactly one line on stderr naming
the file and the problem (no importer traceback), and no output file."""
import os
import subprocess
import sys

import bpy
import pytest

from articula.bench._armatures import new_armature
from articula.sample_scenes import mpfb_armature
from ...conftest import REPO, SHARED_DATA

BVH = os.path.join(SHARED_DATA, "mocap", "cmu_131_01.bvh")


def _run(args, tmp_path):
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "user"))
    return subprocess.run([sys.executable, os.path.join(REPO, "batch.py"), "retarget", *args], capture_output=True,
                          text=True, env=env, timeout=300)


def _save(path, armature, pkg):
    """Save a .blend holding an MPFB armature (``armature``) or only a cube."""
    if armature:
        d = mpfb_armature.rig_bones("game_engine")
        new_armature(bpy.context, "Hero", d["names"], d["parents"], d["heads"], d["tails"], d["rolls"])
    else:
        bpy.ops.mesh.primitive_cube_add()
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    return str(path)


def _cut(tmp_path, size):
    assert os.path.isfile(BVH), f"missing fixture {BVH}"
    with open(BVH, "rb") as fh:
        data = fh.read(size)
    path = tmp_path / "t.bvh"
    path.write_bytes(data)
    return str(path)


def _refused(res, out, *words):
    err = res.stderr.strip().splitlines()
    assert res.returncode == 2 and len(err) == 1, res.stderr[-3000:]
    assert err[0].startswith("articula retarget: error: ") and all(w in err[0] for w in words), err[0]
    assert not os.path.exists(out)


@pytest.mark.parametrize("size, words", [
    (300_000, ("t.bvh", "truncated", "cut short")),          # within a frame's line (the example)
    (2_000, ("t.bvh", "truncated", "HIERARCHY")),             # within the hierarchy
    (3_991, ("t.bvh", "truncated", "'Frames: ...'")),        # right after MOTION
])
def test_truncated_bvh_is_one_line_naming_the_file(pkg, tmp_path, size, words):
    target = _save(tmp_path / "character.blend", True, pkg)
    out = str(tmp_path / "x.blend")
    _refused(_run(["--source", _cut(tmp_path, size), "--target", target, "--out", out], tmp_path), out, *words)


def test_target_blend_without_an_armature_says_so(pkg, tmp_path):
    target = _save(tmp_path / "props.blend", False, pkg)
    out = str(tmp_path / "x.blend")
    _refused(_run(["--source", BVH, "--target", target, "--out", out], tmp_path), out, "props.blend", "has no armature")


def test_source_blend_without_an_armature_says_so(pkg, tmp_path):
    source = _save(tmp_path / "props.blend", False, pkg)
    bpy.ops.wm.read_homefile(use_empty=True)
    target = _save(tmp_path / "character.blend", True, pkg)
    out = str(tmp_path / "x.blend")
    _refused(_run(["--source", source, "--target", target, "--out", out], tmp_path), out, "props.blend",
             "has no armature")
