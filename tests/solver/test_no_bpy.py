"""solver/ must import and run with plain Python: no bpy, no mathutils."""
import os
import subprocess
import sys

from ..conftest import PKGROOT

SCRIPT = r"""
import importlib, pkgutil, sys
sys.modules['bpy'] = None          # any 'import bpy' now raises ImportError
sys.modules['mathutils'] = None
import articula.solver as solver
names = [m.name for m in pkgutil.walk_packages(solver.__path__, 'articula.solver.')]
for n in names:
    importlib.import_module(n)
assert 'bpy' not in [k for k, v in sys.modules.items() if v is not None]
print(len(names))
"""


def test_solver_imports_without_bpy():
    env = dict(os.environ, PYTHONPATH=PKGROOT)
    res = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True, env=env)
    assert res.returncode == 0, res.stderr
    assert int(res.stdout.strip()) >= 1


def test_no_solver_source_mentions_bpy():
    solver_dir = os.path.join(os.path.dirname(PKGROOT), "solver")
    for root, _, files in os.walk(solver_dir):
        for f in files:
            if f.endswith(".py"):
                text = open(os.path.join(root, f)).read()
                for line in text.splitlines():
                    words = line.split()
                    if words[:1] in (["import"], ["from"]):
                        assert not {"bpy", "mathutils", "bmesh"} & set(w.split(".")[0] for w in words[1:2]), (f, line)
