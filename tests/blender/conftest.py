"""Blender fixtures: the add-on is enabled the way Blender enables extensions (a local extension
repository whose folder contains ``articula`` -> the checkout, module ``bl_ext.articula_test.articula``),
and every test starts from an empty scene (``read_homefile(use_empty=True)`` keeps add-ons enabled)."""
import importlib

import bpy
import pytest

from ..conftest import PKGROOT

REPO_MODULE = "articula_test"
MODULE = f"bl_ext.{REPO_MODULE}.articula"


@pytest.fixture(scope="session", autouse=True)
def addon():
    repos = bpy.context.preferences.extensions.repos
    if REPO_MODULE not in [r.module for r in repos]:
        repos.new(name=REPO_MODULE, module=REPO_MODULE, custom_directory=PKGROOT, source='USER')
    assert bpy.ops.preferences.addon_enable(module=MODULE) == {'FINISHED'}
    assert MODULE in bpy.context.preferences.addons
    yield importlib.import_module(MODULE)
    bpy.ops.preferences.addon_disable(module=MODULE)


@pytest.fixture(autouse=True)
def empty_scene(addon):
    bpy.ops.wm.read_homefile(use_empty=True)
    yield bpy.context.scene


@pytest.fixture
def pkg(addon):
    """Import a submodule of the enabled extension: ``pkg('addon.rig.builder')``."""
    return lambda name: importlib.import_module(f"{MODULE}.{name}")


@pytest.fixture
def cache_home(tmp_path, monkeypatch):
    """A fresh ``ARTICULA_HOME`` (the cache folder of unsaved files) under the test's tmp_path; modules
    that write caches use it for every test with ``pytestmark = pytest.mark.usefixtures("cache_home")``."""
    monkeypatch.setenv("ARTICULA_HOME", str(tmp_path / "home"))
    return tmp_path / "home"
