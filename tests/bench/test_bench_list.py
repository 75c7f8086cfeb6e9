"""``./run bench list`` names every benchmark with its one-line description (the first line of its
docstring), in a fresh process as a user runs it."""
import ast
import os
import subprocess
import sys

from ..conftest import REPO

BENCH = os.path.join(REPO, "bench")


def test_bench_list_shows_each_benchmark_with_its_description(tmp_path):
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "user"), ARTICULA_HOME=str(tmp_path / "home"))
    res = subprocess.run([sys.executable, os.path.join(REPO, "batch.py"), "bench", "list"], capture_output=True,
                         text=True, env=env, timeout=600)
    assert res.returncode == 0, res.stderr[-2000:]
    listed = dict(line.split(None, 1) for line in res.stdout.splitlines() if line.strip())
    expected = {}
    for name in sorted(os.listdir(BENCH)):
        if name.startswith("bench_") and name.endswith(".py"):
            with open(os.path.join(BENCH, name), encoding="utf-8") as f:
                expected[name[6:-3]] = ast.get_docstring(ast.parse(f.read())).splitlines()[0].strip()
    assert {k: v.strip() for k, v in listed.items()} == expected
    assert {"retarget_topology", "scan_binding", "learn", "track_depth"} <= set(listed)
