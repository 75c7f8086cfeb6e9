"""The depth-camera convention (solver.depth.camera) reproduced by a real Blender camera: a world point
projects to the same pixel through ``bpy_extras.object_utils.world_to_camera_view``."""
import bpy
import numpy as np
import pytest
from bpy_extras.object_utils import world_to_camera_view
from mathutils import Matrix, Vector


@pytest.mark.parametrize("intr_args", [
    (640, 480, 580.0, 580.0, 319.5, 239.5),
    (320, 240, 290.0, 290.0, 150.2, 131.7),
    (512, 424, 361.6, 367.2, 250.0, 200.0),
])
def test_blender_camera_projects_like_the_pinhole_model(pkg, intr_args):
    camera = pkg("solver.depth.camera")
    intr = camera.Intrinsics(*intr_args)
    c2w = camera.look_at(eye=(0.4, -3.0, 1.2), target=(0.1, 0.2, 0.9))
    data = bpy.data.cameras.new("depthcam")
    obj = bpy.data.objects.new("depthcam", data)
    bpy.context.scene.collection.objects.link(obj)
    settings = camera.blender_camera_settings(intr)
    for key in ("lens", "sensor_width", "sensor_fit", "shift_x", "shift_y"):
        setattr(data, key, settings[key])
    render = bpy.context.scene.render
    for key in ("resolution_x", "resolution_y", "pixel_aspect_x", "pixel_aspect_y"):
        setattr(render, key, settings[key])
    render.resolution_percentage = 100
    obj.matrix_world = Matrix(camera.blender_from_cv(c2w).tolist())
    bpy.context.view_layer.update()
    pts = np.random.default_rng(0).uniform([-0.8, -0.5, 0.2], [0.8, 0.8, 1.8], (20, 3))
    uv, z = camera.project(camera.world_to_camera(pts, c2w), intr)
    for p, (u, v), depth in zip(pts, uv, z):
        ndc = world_to_camera_view(bpy.context.scene, obj, Vector(p.tolist()))
        u_bl = ndc.x * intr.width - 0.5           # pixel centres at integer coordinates
        v_bl = (1.0 - ndc.y) * intr.height - 0.5  # Blender's y is up, image rows go down
        assert u_bl == pytest.approx(u, abs=1e-3) and v_bl == pytest.approx(v, abs=1e-3)
        assert ndc.z == pytest.approx(depth, abs=1e-5)
