"""The batch entry point as users call it: ``python batch.py <command> ...`` (bpy module) and the
``blender -b -P batch.py -- <command> ...`` argument form, in a fresh process with its own Blender
user folder: exit code 0 and the promised files on success, a one-line message and exit code 2 on
bad input."""
import os
import subprocess
import sys

import numpy as np
import pytest

from ...conftest import REPO


def _scans(folder, pkg, n=4):
    writer = pkg("sample_scenes.mesh_files").SequenceWriter(np.array([[0, 1, 2], [0, 2, 3]]), "obj")
    square = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    for k in range(n):
        writer.write(os.path.join(folder, f"s{k}.obj"), square + [0, 0, 0.1 * k])


def _run(args, tmp_path):
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "user"))
    return subprocess.run([sys.executable, os.path.join(REPO, "batch.py"), *args], capture_output=True,
                          text=True, env=env, timeout=300)


@pytest.mark.parametrize("form", [[], ["--"]])
def test_batch_import_scans_writes_a_blend(tmp_path, pkg, form):
    scans = tmp_path / "scans"
    scans.mkdir()
    _scans(str(scans), pkg)
    blend = tmp_path / "out" / "scans.blend"
    res = _run(form + ["import-scans", "--scans", str(scans), "--blend", str(blend)], tmp_path)
    assert res.returncode == 0, res.stderr[-2000:]
    assert blend.is_file() and "4 frames" in res.stdout


def test_batch_bad_input_exits_2_with_a_message(tmp_path):
    res = _run(["import-scans", "--scans", str(tmp_path / "missing")], tmp_path)
    assert res.returncode == 2
    last = res.stderr.strip().splitlines()[-1]
    assert last.startswith("articula import-scans: error:") and "missing" in last


def test_batch_unknown_command_fails(tmp_path):
    res = _run(["no-such-command"], tmp_path)
    assert res.returncode != 0 and "invalid choice" in res.stderr
