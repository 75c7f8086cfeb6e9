"""The terminal stays honest (issue 16, rough edges item 5): a successful ``export-lbs`` to glTF prints no
"ERROR" line (the glTF add-on's notes about its optional Draco / MeshOptimizer libraries are left out) and
no "Read blend:" line of our own open call, while a real error inside the same calls still shows; the
one filter (``addon.console``) serves the headless render too (tests/blender/scene/test_render.py)."""
import os
import re
import subprocess
import sys

import pytest

from ...conftest import REPO
from ..rig_helpers import poses, subject


def _run(args, tmp_path):
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "user"), ARTICULA_HOME=str(tmp_path / "home"))
    return subprocess.run([sys.executable, os.path.join(REPO, "batch.py"), *args], capture_output=True,
                          text=True, env=env, timeout=600)


@pytest.fixture
def rig_blend(pkg, tmp_path):
    bundle = str(tmp_path / "subject.npz")
    model = subject(pkg, rings=6, segments=8)
    pkg("solver.formats.bundle").save_bundle(bundle, model, poses(pkg, model.skeleton.num_bones, 3, seed=4))
    blend = tmp_path / "rig.blend"
    res = _run(["build-rig", "--bundle", bundle, "--blend", str(blend)], tmp_path)
    assert res.returncode == 0, res.stderr[-2000:]
    return blend


def test_gltf_export_prints_no_error_line_on_success(rig_blend, tmp_path):
    out = tmp_path / "rig_lbs.glb"
    res = _run(["export-lbs", "--blend", str(rig_blend), "--max-influences", "4", "--out", str(out)], tmp_path)
    assert res.returncode == 0, res.stdout[-2000:] + res.stderr[-2000:]
    assert out.is_file() and out.stat().st_size > 0
    printed = res.stdout + res.stderr
    assert not [line for line in printed.splitlines() if "ERROR" in line], printed
    assert "Read blend" not in printed and "Draco" not in printed and "MeshOptimizer" not in printed
    assert res.stdout.strip().splitlines()[-1].endswith(f"wrote {out}")
    res = _run(["export-bundle", "--blend", str(rig_blend), "--out", str(tmp_path / "b.npz")], tmp_path)
    assert res.returncode == 0 and "Read blend" not in res.stdout + res.stderr, res.stdout + res.stderr


def test_a_real_export_error_still_shows(rig_blend, tmp_path):
    out = tmp_path / "taken.glb"
    out.mkdir()                                  # the glTF writer cannot open a folder as its file
    res = _run(["export-lbs", "--blend", str(rig_blend), "--out", str(out)], tmp_path)
    assert res.returncode != 0
    printed = res.stdout + res.stderr
    # Blender's report of the failed export, printed inside the filtered call (not our traceback's line)
    assert re.search(r"^Error: Python: Traceback", printed, re.M) and "IsADirectoryError" in printed, printed
    assert "Draco" not in printed


def test_filter_keeps_every_other_line_of_c_and_python_output(pkg, capfd):
    console = pkg("addon.console")
    with console.without_lines(console.GLTF_LIBRARIES, console.READ_BLEND):
        print("ERROR Draco is not available because library could not be found at /x/libdraco.so")
        print("ERROR Draco mesh compression is not available because library could not be found at /x.so")
        os.write(1, b'00:01.029  blend            | Read blend: "/tmp/x.blend"\n')
        os.write(1, b"ERROR MeshOptimizer is not available because library could not be found at /y.so\n")
        print("kept on stdout")
        os.write(2, b"ERROR a real problem from C\n")
        print("ERROR a real problem from Python", file=sys.stderr)
    print("after the block")
    out, err = capfd.readouterr()
    assert out.splitlines() == ["kept on stdout", "after the block"], out
    assert err.splitlines() == ["ERROR a real problem from C", "ERROR a real problem from Python"], err


def test_filter_prints_what_it_kept_when_the_block_raises(pkg, capfd):
    console = pkg("addon.console")
    with pytest.raises(RuntimeError):
        with console.without_lines(console.EGL):
            os.write(2, b"EGL Error (0x3009): EGL_BAD_MATCH\nreal trouble\n")
            raise RuntimeError("boom")
    assert capfd.readouterr().err == "real trouble\n"
