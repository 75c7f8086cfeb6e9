"""Headless renders print no EGL noise: ``render_overview`` in a fresh process (the EGL lines appear only
when a process creates its first GPU context) writes the picture and nothing about EGL on stderr, while a
plain ``bpy.ops.render.render`` in the same kind of process does print them (so the check can fail)."""
import os
import subprocess
import sys
import tempfile

from ...conftest import PKGROOT

SCRIPT = r"""
import os, sys, tempfile
os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp())
import bpy
bpy.ops.wm.read_homefile(use_empty=True)
scene = bpy.context.scene
me = bpy.data.meshes.new("Quad")
me.from_pydata([(0, 0, 0), (1, 0, 0), (1, 0, 1), (0, 0, 1)], [], [(0, 1, 2, 3)])
ob = bpy.data.objects.new("Quad", me)
scene.collection.objects.link(ob)
out = sys.argv[2]
if sys.argv[1] == "plain":
    scene.render.engine = 'BLENDER_WORKBENCH'
    scene.render.resolution_x, scene.render.resolution_y = 64, 48
    scene.render.filepath = out
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.location = (0.5, -3.0, 0.5)
    cam.rotation_euler = (1.5708, 0.0, 0.0)
    scene.collection.objects.link(cam)
    scene.camera = cam
    bpy.ops.render.render(write_still=True)
else:
    sys.path.insert(0, sys.argv[3])
    from articula.addon.scene import render
    render.render_overview(scene, out, {"Quad": [ob]}, width=64, height=48)
    print("stderr after the render still works", file=sys.stderr)
"""


def _render(kind, tmp):
    out = os.path.join(tmp, f"{kind}.png")
    res = subprocess.run([sys.executable, "-c", SCRIPT, kind, out, PKGROOT],
                         capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stdout + res.stderr
    assert os.path.getsize(out) > 0
    return res.stderr


def test_headless_render_prints_no_egl_lines():
    with tempfile.TemporaryDirectory() as tmp:
        plain = _render("plain", tmp)
        overview = _render("overview", tmp)
    assert "EGL Error" in plain, "this machine's headless render prints no EGL line: the check below proves nothing"
    assert "EGL" not in overview, overview
    assert "stderr after the render still works" in overview
