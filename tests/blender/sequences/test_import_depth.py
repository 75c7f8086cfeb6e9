"""articula.import_depth: scene objects, camera projection vs intrinsics, playback, save/reload,
bad input (scene untouched), real Kinect frames.  Synthetic recordings are exact ray casts
(sample_scenes/depth_scene.py)."""
import os
import re

import bpy
import numpy as np
import pytest
from bpy_extras.object_utils import world_to_camera_view
from mathutils import Vector

from articula.solver.depth import camera
from articula.solver.formats.png16 import write_png16

from ...conftest import SHARED_DATA
from articula.sample_scenes.depth_scene import floor_box_scene

INTR = camera.Intrinsics(160, 120, 140.0, 131.0, 84.3, 55.7)   # fx != fy, off-centre principal point
KINECT = os.path.join(SHARED_DATA, "depth", "skeltrack_kinect")
DATA = ("objects", "meshes", "cameras", "collections", "materials", "images", "node_groups")


def box_x(k, n):
    return -0.5 + 1.0 * k / max(n - 1, 1)


def make_recording(folder, n=5, intr=INTR, intrinsics_file=True):
    os.makedirs(folder, exist_ok=True)
    if intrinsics_file:
        camera.save_intrinsics(os.path.join(folder, "intrinsics.json"), intr)
    c2w = None
    for k in range(n):
        x = box_x(k, n)
        depth, c2w, _ = floor_box_scene(intr, box=((x - .2, 2.2, 0), (x + .2, 2.6, .8)))
        write_png16(os.path.join(folder, f"depth_{k:04d}.png"), (depth * 1000).round().astype(np.uint16))
    return str(folder), c2w


def counts():
    return {name: len(getattr(bpy.data, name)) for name in DATA}


def evaluated_points(ob):
    """World positions of the evaluated point cloud of ``ob`` (Geometry Nodes output)."""
    dg = bpy.context.evaluated_depsgraph_get()
    for inst in dg.object_instances:
        if inst.object.original == ob and inst.object.type == 'POINTCLOUD':
            pc = inst.object.data
            co = np.empty(len(pc.points) * 3, np.float32)
            pc.attributes["position"].data.foreach_get("vector", co)
            m = np.array(inst.matrix_world)
            radius = np.empty(len(pc.points), np.float32)
            pc.attributes["radius"].data.foreach_get("value", radius)
            return co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3], radius
    raise AssertionError(f"no evaluated point cloud for {ob.name}")


def sensor_points(ob, frame):
    seq = pkg_pcs().load_sequence(_PCS["playback"].cache_abspath(ob))
    return seq.points[seq.frame(frame)]


_PCS = {}


def pkg_pcs():
    return _PCS["mod"]


@pytest.fixture(autouse=True)
def _pcs(pkg):
    _PCS["mod"] = pkg("addon.sequences.points")
    _PCS["playback"] = pkg("addon.sequences.playback")


def test_import_builds_camera_and_points_that_follow_the_frame(tmp_path):
    folder, c2w = make_recording(tmp_path / "walk", n=5)
    assert bpy.ops.articula.import_depth(directory=folder, point_radius=0.006) == {'FINISHED'}
    scene = bpy.context.scene
    coll = bpy.data.collections["walk"]
    ob = bpy.data.objects["walk Points"]
    cam = bpy.data.objects["walk Camera"]
    assert {o.name for o in coll.objects} == {ob.name, cam.name}
    assert ob.articula.kind == 'POINT_CLOUD_SEQUENCE' and ob.articula.frame_count == 5
    assert (scene.frame_start, scene.frame_end) == (1, 5)
    assert scene.camera == cam
    # the floor-aligned placement reproduces the scene's own camera pose (mm-quantised depth)
    np.testing.assert_allclose(np.array(cam.matrix_world), c2w @ np.diag([1, -1, -1, 1]), atol=5e-3)
    for frame in (3, 1, 5, 2):
        scene.frame_set(frame)
        world, radius = evaluated_points(ob)
        k = frame - 1
        expect = sensor_points(ob, k) @ c2w[:3, :3].T + c2w[:3, 3]
        assert world.shape == expect.shape
        np.testing.assert_allclose(world, expect, atol=6e-3)
        # independent check: the points are the box of frame k, above the floor
        x = box_x(k, 5)
        assert (np.abs(world[:, 0] - x) <= 0.2 + 6e-3).all() and (world[:, 2] > 0.01).all()
        np.testing.assert_allclose(radius, 0.006)
        # the original mesh holds exactly frame k of the cache
        co = np.empty(len(ob.data.vertices) * 3, np.float32)
        ob.data.attributes["position"].data.foreach_get("vector", co)
        np.testing.assert_array_equal(co.reshape(-1, 3), sensor_points(ob, k))
    # before the first / after the last frame the nearest frame is shown
    scene.frame_set(20)
    assert len(ob.data.vertices) == len(sensor_points(ob, 4))
    assert "sensor_normal" in ob.data.attributes


def test_blender_camera_projects_points_onto_their_pixels(tmp_path):
    folder, _ = make_recording(tmp_path / "rec", n=1)
    assert bpy.ops.articula.import_depth(directory=folder, remove_floor=False) == {'FINISHED'}
    scene = bpy.context.scene
    cam = bpy.data.objects["rec Camera"]
    ob = bpy.data.objects["rec Points"]
    scene.frame_set(1)
    world, _ = evaluated_points(ob)
    pts = sensor_points(ob, 0)
    uv_ref, _ = camera.project(pts, INTR)              # every point came from an integer pixel
    np.testing.assert_allclose(uv_ref, np.round(uv_ref), atol=1e-3)
    sel = np.random.default_rng(0).choice(len(world), 400, replace=False)
    got = []
    for p in world[sel]:
        n = world_to_camera_view(scene, cam, Vector(p.tolist()))
        got.append((n.x * INTR.width - 0.5, (1 - n.y) * INTR.height - 0.5))
    err = np.abs(np.array(got) - uv_ref[sel])
    assert err.max() < 1e-3, err.max()
    r = scene.render
    assert (r.resolution_x, r.resolution_y) == (INTR.width, INTR.height)


def test_save_and_reload_keep_playback(tmp_path):
    blend = str(tmp_path / "scene.blend")
    bpy.ops.wm.save_as_mainfile(filepath=blend)
    folder, _ = make_recording(tmp_path / "rec", n=4)
    assert bpy.ops.articula.import_depth(directory=folder) == {'FINISHED'}
    ob = bpy.data.objects["rec Points"]
    assert ob.articula.cache_file.startswith("//scene_articula/rec-")      # beside the saved .blend, relative
    expect = [sensor_points(ob, k).copy() for k in range(4)]
    bpy.context.scene.frame_set(2)
    bpy.ops.wm.save_mainfile()
    pkg_pcs().forget_cache()
    bpy.ops.wm.open_mainfile(filepath=blend)
    ob = bpy.data.objects["rec Points"]
    for frame in (4, 1, 3):
        bpy.context.scene.frame_set(frame)
        co = np.empty(len(ob.data.vertices) * 3, np.float32)
        ob.data.attributes["position"].data.foreach_get("vector", co)
        np.testing.assert_array_equal(co.reshape(-1, 3), expect[frame - 1])
        world, _ = evaluated_points(ob)
        assert len(world) == len(expect[frame - 1])
    # the project folder moved elsewhere (the .blend with its cache): still plays
    import shutil
    moved = tmp_path / "moved"
    moved.mkdir()
    for name in ("scene.blend", "scene_articula"):      # the .blend and its cache folder
        shutil.move(str(tmp_path / name), str(moved / name))
    pkg_pcs().forget_cache()
    bpy.ops.wm.open_mainfile(filepath=str(moved / "scene.blend"))
    bpy.context.scene.frame_set(3)   # the file was saved showing frame 2
    ob = bpy.data.objects["rec Points"]
    co = np.empty(len(ob.data.vertices) * 3, np.float32)
    ob.data.attributes["position"].data.foreach_get("vector", co)
    np.testing.assert_array_equal(co.reshape(-1, 3), expect[2])


def test_point_cloud_files_with_colours(tmp_path):
    rng = np.random.default_rng(2)
    folder = tmp_path / "clouds"
    folder.mkdir()
    frames = []
    for k in range(3):
        p = rng.uniform([-1, -1, 1.5], [1, 0.5, 3.0], size=(300 + 10 * k, 3))
        c = rng.uniform(0, 1, size=(len(p), 3))
        np.save(folder / f"cloud_{k}.npy", np.c_[p, c])
        frames.append((p, c))
    assert bpy.ops.articula.import_depth(directory=str(folder), remove_floor=False,
                                         estimate_normals=False) == {'FINISHED'}
    ob = bpy.data.objects["clouds Points"]
    assert "clouds Camera" not in bpy.data.objects        # no intrinsics -> no camera
    bpy.context.scene.frame_set(2)
    assert len(ob.data.vertices) == 310
    col = np.empty(310 * 4, np.float32)
    ob.data.attributes["color"].data.foreach_get("color", col)
    lin = np.where(frames[1][1] <= 0.04045, frames[1][1] / 12.92, ((frames[1][1] + 0.055) / 1.055) ** 2.4)
    np.testing.assert_allclose(col.reshape(-1, 4)[:, :3], lin, atol=1e-5)
    world, _ = evaluated_points(ob)
    m = np.array(ob.matrix_world)                         # sensor frame -> world, camera looking along +Y
    np.testing.assert_allclose(world, frames[1][0] @ m[:3, :3].T + m[:3, 3], atol=1e-5)
    np.testing.assert_allclose(m[:3, :3] @ [0, 0, 1], [0, 1, 0], atol=1e-6)    # optical axis -> +Y
    np.testing.assert_allclose(m[:3, :3] @ [0, 1, 0], [0, 0, -1], atol=1e-6)   # sensor down -> -Z


def test_exr_depth_equals_png_depth(tmp_path):
    folder, _ = make_recording(tmp_path / "png", n=1)
    from articula.solver.formats.png16 import read_png16
    depth_m = read_png16(os.path.join(folder, "depth_0000.png")).astype(np.float32) / 1000
    exr_dir = tmp_path / "exr"
    exr_dir.mkdir()
    camera.save_intrinsics(str(exr_dir / "intrinsics.json"), INTR)
    img = bpy.data.images.new("d", INTR.width, INTR.height, float_buffer=True)
    img.colorspace_settings.is_data = True   # else Blender's save writes sRGB-encoded values
    px = np.zeros((INTR.height, INTR.width, 4), np.float32)
    px[..., 0] = depth_m[::-1]                             # Blender rows run bottom to top
    px[..., 3] = 1
    img.pixels.foreach_set(px.ravel())
    img.filepath_raw = str(exr_dir / "depth_0000.exr")
    img.file_format = 'OPEN_EXR'
    img.save()
    bpy.data.images.remove(img)
    assert bpy.ops.articula.import_depth(directory=folder) == {'FINISHED'}
    assert bpy.ops.articula.import_depth(directory=str(exr_dir)) == {'FINISHED'}
    a = sensor_points(bpy.data.objects["png Points"], 0)
    b = sensor_points(bpy.data.objects["exr Points"], 0)
    assert a.shape == b.shape
    np.testing.assert_allclose(a, b, atol=1e-5)
    assert len(bpy.data.images) == 0


def test_colour_frames_become_point_colours(tmp_path):
    folder, _ = make_recording(tmp_path / "rec", n=2)
    cdir = tmp_path / "rgb"
    cdir.mkdir()
    for k in range(2):
        img = bpy.data.images.new(f"c{k}", INTR.width, INTR.height)
        px = np.zeros((INTR.height, INTR.width, 4), np.float32)
        px[..., 0] = (np.arange(INTR.width) / 255.0)[None, :]      # red = column
        px[..., 1] = (np.arange(INTR.height) / 255.0)[::-1, None]  # green = row (flipped storage)
        px[..., 2] = k / 255.0
        px[..., 3] = 1
        img.pixels.foreach_set(px.ravel())
        img.filepath_raw = str(cdir / f"color_{k}.png")
        img.file_format = 'PNG'
        img.save()
        bpy.data.images.remove(img)
    assert bpy.ops.articula.import_depth(directory=folder, color_directory=str(cdir)) == {'FINISHED'}
    ob = bpy.data.objects["rec Points"]
    seq = pkg_pcs().load_sequence(_PCS["playback"].cache_abspath(ob))
    pts = seq.points[seq.frame(1)]
    uv, _ = camera.project(pts, INTR)
    rgb = seq.colors[seq.frame(1)] * 255
    np.testing.assert_allclose(rgb[:, 0], np.round(uv[:, 0]), atol=0.01)
    np.testing.assert_allclose(rgb[:, 1], np.round(uv[:, 1]), atol=0.01)
    np.testing.assert_allclose(rgb[:, 2], 1, atol=0.01)


# ------------------------------------------------------------------------------------ bad input

def _assert_fails(match, **kw):
    before = counts()
    frame = bpy.context.scene.frame_current
    with pytest.raises(RuntimeError, match=match):
        bpy.ops.articula.import_depth(**kw)
    assert counts() == before
    assert bpy.context.scene.frame_current == frame


def test_bad_input_is_reported_and_leaves_the_scene_untouched(tmp_path):
    bpy.ops.mesh.primitive_cube_add()
    empty = tmp_path / "empty"
    empty.mkdir()
    _assert_fails(r"empty: no frames found", directory=str(empty))
    _assert_fails(r"nowhere: not a folder", directory=str(tmp_path / "nowhere"))
    folder, _ = make_recording(tmp_path / "rec", n=3)
    write_png16(os.path.join(folder, "depth_0003.png"), np.zeros((INTR.height, INTR.width), np.uint8))
    _assert_fails(r"depth_0003.png: 8-bit PNG", directory=folder)
    write_png16(os.path.join(folder, "depth_0003.png"), np.zeros((60, 80), np.uint16))
    _assert_fails(r"depth_0003.png: 80x60 pixels, but depth_0000.png is 160x120", directory=folder)
    with open(os.path.join(folder, "depth_0003.png"), "wb") as f:
        f.write(b"not a png at all")
    _assert_fails(r"depth_0003.png", directory=folder)
    os.remove(os.path.join(folder, "depth_0003.png"))
    os.remove(os.path.join(folder, "intrinsics.json"))
    _assert_fails(r"rec: no intrinsics.json; give an intrinsics file or choose a camera preset", directory=folder)
    _assert_fails(r"160x120 pixels, but the intrinsics 'kinect_v2' are for 512x424",
                  directory=folder, preset='kinect_v2')
    _assert_fails(r"depth range \[3.0, 1.0\] m is empty", directory=folder, preset='kinect_v1',
                  depth_min=3.0, depth_max=1.0)
    clouds = tmp_path / "clouds"
    clouds.mkdir()
    good = np.random.default_rng(0).uniform(1, 2, size=(50, 3))
    np.save(clouds / "c_0.npy", good)
    bad = good.copy()
    bad[13, 2] = np.nan
    np.save(clouds / "c_1.npy", bad)
    _assert_fails(r"c_1.npy: 1 point\(s\) with NaN/inf coordinates \(first at row 14\)", directory=str(clouds))
    np.save(clouds / "c_1.npy", good)
    (clouds / "c_2.ply").write_bytes(b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nend_header\n1\n2\n")
    _assert_fails(r"c_2.ply", directory=str(clouds))


def test_no_cache_is_left_behind_after_an_error(tmp_path):
    folder, _ = make_recording(tmp_path / "rec", n=2)
    write_png16(os.path.join(folder, "depth_0002.png"), np.zeros((10, 10), np.uint16))
    cache = tmp_path / "c.npz"
    with pytest.raises(RuntimeError):
        bpy.ops.articula.import_depth(directory=folder, cache_file=str(cache))
    assert not cache.exists()


# --------------------------------------------------------------------------------- real frames

@pytest.mark.skipif(not os.path.isdir(KINECT), reason="shared Kinect frames not present")
def test_real_kinect_frames_with_the_kinect_v1_preset(tmp_path):
    # No intrinsics ship with these frames: the nominal Kinect v1 model (fx = fy = 580 px) is assumed.
    from articula.solver.formats.png16 import read_png16
    assert bpy.ops.articula.import_depth(directory=KINECT, preset='kinect_v1',
                                         cache_file=str(tmp_path / "k.npz")) == {'FINISHED'}
    ob = bpy.data.objects["skeltrack_kinect Points"]
    assert ob.articula.frame_count == 12
    seq = pkg_pcs().load_sequence(str(tmp_path / "k.npz"))
    intr = camera.PRESETS["kinect_v1"]
    names = sorted(os.listdir(KINECT), key=lambda n: [int(t) if t.isdigit() else t for t in
                                                       __import__("re").split(r"(\d+)", n)])
    names = [n for n in names if n.endswith(".png")]
    assert [os.path.basename(n) for n in seq.frame_names] == names
    for k, name in enumerate(names):
        raw = read_png16(os.path.join(KINECT, name))
        pts = seq.points[seq.frame(k)]
        # background already removed and no level floor in view: every measured pixel is a point
        assert len(pts) == ((raw >= 300) & (raw <= 5000)).sum()
        uv, z = camera.project(pts, intr)
        u, v = np.round(uv).astype(int).T
        np.testing.assert_allclose(raw[v, u] / 1000.0, z, atol=1e-6)
        # an upper body 0.7-2 m from the camera
        assert 0.4 < np.ptp(pts[:, 0]) < 1.6 and 0.6 < np.ptp(pts[:, 1]) < 1.3
    bpy.context.scene.frame_set(7)
    world, _ = evaluated_points(ob)
    assert len(world) == len(seq.points[seq.frame(6)])


def test_background_subtraction_through_the_operator(tmp_path):
    """A wall and floor with the box moving across: with a background frame, or the median of the
    frames, only the box remains."""
    folder = tmp_path / "bg"
    folder.mkdir()
    camera.save_intrinsics(str(folder / "intrinsics.json"), INTR)
    empty, c2w, _ = floor_box_scene(INTR, box=None, wall_y=3.5)
    write_png16(str(tmp_path / "background.png"), (empty * 1000).round().astype(np.uint16))
    labels = []
    for k in range(5):
        x = box_x(k, 5) * 1.6
        depth, _, label = floor_box_scene(INTR, box=((x - .2, 2.2, 0), (x + .2, 2.6, .8)), wall_y=3.5)
        write_png16(str(folder / f"depth_{k}.png"), (depth * 1000).round().astype(np.uint16))
        labels.append(label)
    for kw in (dict(background=str(tmp_path / "background.png")), dict(background_frames=5)):
        bpy.ops.wm.read_homefile(use_empty=True)
        assert bpy.ops.articula.import_depth(directory=str(folder), subtract_background=True,
                                             cache_file=str(tmp_path / "c.npz"), **kw) == {'FINISHED'}
        seq = pkg_pcs().load_sequence(str(tmp_path / "c.npz"))
        for k in range(5):
            uv, _ = camera.project(seq.points[seq.frame(k)], INTR)
            u, v = np.round(uv).astype(int).T
            assert len(u) > 300
            assert (labels[k][v, u] == 2).all(), kw            # nothing of the wall or floor is left


def test_points_render_in_cycles_animation(tmp_path):
    """Rendering an animation shows each frame's points (the frame_change_pre handler runs before the
    render's own evaluation of the frame)."""
    folder, _ = make_recording(tmp_path / "rec", n=2)
    assert bpy.ops.articula.import_depth(directory=folder, point_radius=0.01) == {'FINISHED'}
    scene = bpy.context.scene
    scene.render.engine = 'CYCLES'
    scene.cycles.device, scene.cycles.samples, scene.cycles.use_denoising = 'CPU', 1, False
    scene.render.film_transparent = True
    scene.render.filepath = str(tmp_path / "r_")
    scene.render.image_settings.file_format = 'PNG'
    scene.render.image_settings.color_mode = 'RGBA'
    scene.frame_set(1)
    bpy.ops.render.render(animation=True)
    ob = bpy.data.objects["rec Points"]
    for k in range(2):
        img = bpy.data.images.load(str(tmp_path / f"r_{k + 1:04d}.png"))
        alpha = np.array(img.pixels[:], np.float32).reshape(INTR.height, INTR.width, 4)[::-1, :, 3]
        uv, _ = camera.project(sensor_points(ob, k), INTR)
        u, v = np.round(uv).astype(int).T
        covered = np.zeros(alpha.shape, bool)
        covered[v, u] = True
        assert alpha[covered].mean() > 0.9             # the points are drawn where their pixels are
        empty_cols = ~np.isin(np.arange(INTR.width), u)
        assert empty_cols.sum() > 20
        assert alpha[:, empty_cols].max() < 0.05       # and nothing in columns without points


def test_batch_command(tmp_path, pkg):
    folder, _ = make_recording(tmp_path / "rec", n=3)
    cli = pkg("addon.cli.main")
    blend = tmp_path / "out" / "depth.blend"
    assert cli.main(["import-depth", "--depth", folder, "--voxel", "0.02", "--blend", str(blend)]) == 0
    cache = bpy.data.objects["rec Points"].articula.cache_file
    assert blend.exists() and re.fullmatch(r"//depth_articula/rec-[0-9a-f]{8}\.points\.npz", cache), cache
    assert os.path.isfile(tmp_path / "out" / cache[2:])
    assert cli.main(["import-depth", "--depth", str(tmp_path / "missing")]) == 2


def test_failure_while_building_restores_scene_settings(tmp_path, monkeypatch):
    folder, _ = make_recording(tmp_path / "rec", n=2)
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end = 10, 20
    scene.render.resolution_x, scene.render.resolution_y = 1000, 500
    pcs = pkg_pcs()
    errors = __import__(pcs.__name__.rsplit(".", 3)[0] + ".solver.errors", fromlist=["x"])

    def broken(*a, **k):
        raise errors.ArticulaInputError("simulated failure after the camera was made")
    monkeypatch.setattr(pcs, "add_points_modifier", broken)
    before = counts()
    with pytest.raises(RuntimeError, match="simulated failure"):
        bpy.ops.articula.import_depth(directory=folder, cache_file=str(tmp_path / "c.npz"))
    assert counts() == before
    assert (scene.frame_start, scene.frame_end, scene.render.resolution_x, scene.render.resolution_y) == (10, 20, 1000, 500)
    assert scene.camera is None
    assert not (tmp_path / "c.npz").exists()


def _box_mesh(lo, hi):
    c = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])], float)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    return c, np.array([t for a, b, cc, d in quads for t in ((a, b, cc), (a, cc, d))], np.int64)


def test_sample_recording_with_kinect_noise(tmp_path):
    """A recording from sample_scenes.depth_recording (z-buffer rasteriser, Kinect v1 noise model,
    floor and back wall, ground-truth camera): the fitted floor gives the true camera height and tilt,
    and after floor and background removal the points lie on the moving subject."""
    from articula.sample_scenes.depth_recording import generate_depth
    boxes = []
    for k in range(6):
        x = -0.5 + 0.2 * k
        boxes.append(((x - 0.2, -0.15, 0.0), (x + 0.2, 0.15, 1.7)))
    meshes = [_box_mesh(*b) for b in boxes]
    frames = np.stack([m[0] for m in meshes])
    info = generate_depth(str(tmp_path / "sample"), frames, meshes[0][1], resolution=(320, 240),
                          floor=True, background=True, seed=1)
    gt = np.load(info["ground_truth"])
    c2w = gt["cam_to_world"][0]
    assert bpy.ops.articula.import_depth(directory=str(tmp_path / "sample"), subtract_background=True,
                                         background_frames=6, cache_file=str(tmp_path / "c.npz")) == {'FINISHED'}
    seq = pkg_pcs().load_sequence(str(tmp_path / "c.npz"))
    mine = np.asarray(seq.world_from_sensor)
    assert abs(mine[2, 3] - c2w[2, 3]) < 0.01                        # camera height above the floor (z = 0)
    tilt = lambda m: np.degrees(np.arcsin(-m[2, 2]))                  # optical axis below the horizon
    assert abs(tilt(mine) - tilt(c2w)) < 0.3
    for k, (lo, hi) in enumerate(boxes):
        world = seq.points[seq.frame(k)] @ c2w[:3, :3].T + c2w[:3, 3]     # with the TRUE camera pose
        assert len(world) > 500
        inside = np.all((world > np.array(lo) - 0.03) & (world < np.array(hi) + 0.03), axis=1)
        assert inside.mean() > 0.99, (k, inside.mean())
        assert (world[:, 2] > 0.0).all()                                # nothing of the floor is left


def test_file_browser_options_name_real_properties():
    """The draw() beside the file browser only references properties the operator has (a UI layout
    is unavailable in background mode, so a recorder stands in for it)."""
    cls = bpy.types.ARTICULA_OT_import_depth
    rna = bpy.ops.articula.import_depth.get_rna_type()
    names = {p.identifier for p in rna.properties}
    drawn = []

    class Recorder:
        use_property_split = use_property_decorate = active = False

        def column(self, **kw):
            return self

        def prop(self, data, name, **kw):
            drawn.append(name)

    class Op:
        layout = Recorder()

        def __getattr__(self, name):
            return rna.properties[name].default

    cls.draw(Op(), bpy.context)
    assert drawn and set(drawn) <= names
    hidden = {"rna_type", "directory", "filter_folder", "run_modal"}
    assert names - hidden - set(drawn) == set()          # every option is offered


def test_an_empty_frame_shows_no_points(tmp_path):
    folder, _ = make_recording(tmp_path / "rec", n=3)
    write_png16(os.path.join(folder, "depth_0001.png"), np.zeros((INTR.height, INTR.width), np.uint16))
    assert bpy.ops.articula.import_depth(directory=folder) == {'FINISHED'}
    ob = bpy.data.objects["rec Points"]
    counts_per_frame = []
    for frame in (1, 2, 3, 2):
        bpy.context.scene.frame_set(frame)
        counts_per_frame.append(len(ob.data.vertices))
        world, _ = evaluated_points(ob) if len(ob.data.vertices) else (np.zeros((0, 3)), None)
        assert len(world) == len(ob.data.vertices)
    assert counts_per_frame[1] == counts_per_frame[3] == 0
    assert counts_per_frame[0] > 0 and counts_per_frame[2] > 0
