"""Test set-up shared by the whole suite.

* ``import articula`` works (the checkout is exposed as a package through ``.pkgroot/articula``).
* ``BLENDER_USER_RESOURCES`` points at a temporary folder *before* anything imports bpy, so tests
  never touch the user's Blender configuration.
Blender fixtures live in ``tests/blender/conftest.py``; ``tests/solver`` never imports bpy.
"""
import os
import sys
import tempfile

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PKGROOT = os.path.join(REPO, ".pkgroot")
if not os.path.exists(os.path.join(PKGROOT, "articula")):
    os.makedirs(PKGROOT, exist_ok=True)
    try:
        os.symlink("..", os.path.join(PKGROOT, "articula"))
    except FileExistsError:
        pass
if PKGROOT not in sys.path:
    sys.path.insert(0, PKGROOT)

os.environ["BLENDER_USER_RESOURCES"] = tempfile.mkdtemp(prefix="articula_bl_user_")

SHARED_DATA = os.path.join(os.path.dirname(REPO), "shared", "data")
