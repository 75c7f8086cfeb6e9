"""A batch command given no ``--blend`` saves nothing and says so (issue 16, rough edges item 1): its last
line is ``not saved: give --blend FILE to keep it`` and the caches it wrote are removed again; with
``--open my.blend`` (no ``--blend``) the opened file is not saved over and the same is said."""
import hashlib
import os
import subprocess
import sys

import bpy
import pytest

from ...conftest import REPO
from .test_blend_files import _commands, _scans, _user_file

pytestmark = pytest.mark.usefixtures("cache_home")   # a fresh ARTICULA_HOME per test

NOT_SAVED = "not saved: give --blend FILE to keep it"


def _files(folder) -> list:
    return sorted(os.path.join(d, n) for d, _s, names in os.walk(folder) for n in names)


@pytest.mark.parametrize("command", ["import-scans", "import-depth", "build-rig"])
def test_without_blend_says_not_saved_and_leaves_no_cache(pkg, tmp_path, capsys, cache_home, command):
    args, added = _commands(pkg, tmp_path)[command]
    capsys.readouterr()
    assert pkg("addon.cli.main").main([command, *args]) == 0
    out = capsys.readouterr().out
    assert out.strip().splitlines()[-1] == NOT_SAVED, out
    assert added in bpy.data.objects                      # the command did its work
    assert _files(cache_home) == []                       # ... and took its cache away again
    assert not [n for n in os.listdir(tmp_path) if n.endswith(".blend")]


def test_open_without_blend_keeps_the_opened_file(pkg, tmp_path):
    """``python batch.py --open my.blend import-scans --scans DIR``: a fresh process, as a user runs it."""
    blend = tmp_path / "my.blend"
    before = _user_file(blend)
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "user"), ARTICULA_HOME=str(tmp_path / "home"))
    res = subprocess.run([sys.executable, os.path.join(REPO, "batch.py"), "--open", str(blend), "import-scans",
                          "--scans", _scans(tmp_path / "scans", pkg)], capture_output=True, text=True, env=env,
                         timeout=300)
    assert res.returncode == 0, res.stderr[-2000:]
    last = res.stdout.strip().splitlines()[-1]
    assert last.startswith(NOT_SAVED) and "my.blend is unchanged" in last, res.stdout
    assert hashlib.sha256(blend.read_bytes()).hexdigest() == before
    assert not os.path.exists(str(blend) + "1")
    assert not (tmp_path / "my_articula").exists()        # the cache written beside the opened file is gone
    assert _files(tmp_path / "home") == []


def test_with_blend_says_saved(pkg, tmp_path, capsys):
    args, _ = _commands(pkg, tmp_path)["import-scans"]
    blend = tmp_path / "s.blend"
    capsys.readouterr()
    assert pkg("addon.cli.main").main(["import-scans", *args, "--blend", str(blend)]) == 0
    out = capsys.readouterr().out
    assert f"saved {blend}" in out and NOT_SAVED not in out
    assert blend.is_file() and len(os.listdir(tmp_path / "s_articula")) == 1
