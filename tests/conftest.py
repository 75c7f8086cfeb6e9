"""Test set-up shared by the whole suite.

* ``import articula`` works (the checkout is exposed as a package through ``.pkgroot/articula``).
* ``BLENDER_USER_RESOURCES`` points at a temporary folder *before* anything imports bpy, so tests
  never touch the user's Blender configuration.
* A warning raised from the solver's own code (module ``articula.solver...``, or the enabled add-on's
  ``bl_ext.articula_test.articula.solver...``) fails the test: a NaN or overflow there is a bug.
Blender fixtures live in ``tests/blender/conftest.py``; ``tests/solver`` never imports bpy.
"""
import importlib.util
import os
import sys
import tempfile

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
_spec = importlib.util.spec_from_file_location("articula_batch", os.path.join(REPO, "batch.py"))
_batch = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_batch)            # batch.py imports bpy only when run as a script
PKGROOT = _batch.dev_package_root()
if PKGROOT not in sys.path:
    sys.path.insert(0, PKGROOT)

os.environ["BLENDER_USER_RESOURCES"] = tempfile.mkdtemp(prefix="articula_bl_user_")

SHARED_DATA = os.path.join(os.path.dirname(REPO), "shared", "data")

#: pytest ``filterwarnings`` line (module regex, matched at the start of the warning's module name).
SOLVER_WARNINGS = r"error::Warning:(bl_ext\.articula_test\.)?articula\.solver\."


def pytest_configure(config):
    config.addinivalue_line("filterwarnings", SOLVER_WARNINGS)
