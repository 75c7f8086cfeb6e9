"""articula.import_scans: every source, playback, save/reload, scan_frames, and bad input that must
leave the scene untouched."""
import os

import bpy
import numpy as np
import pytest

from ...conftest import SHARED_DATA
from ...solver.mesh_writers import (CUBE_FACES, CUBE_VERTS, triangles, write_mdd, write_obj, write_off, write_pc2,
                                   write_ply, write_stl)

pytestmark = pytest.mark.usefixtures("cache_home")   # a fresh ARTICULA_HOME per test


def make_frames(n, seed=0):
    rng = np.random.default_rng(seed)
    return (CUBE_VERTS[None] + rng.normal(scale=0.1, size=(n, len(CUBE_VERTS), 3))).astype(np.float32)


def write_folder(folder, frames, fmt="obj"):
    os.makedirs(folder, exist_ok=True)
    for k, f in enumerate(frames):
        path = os.path.join(folder, f"scan{k + 1}.{fmt}")
        if fmt == "obj":
            write_obj(path, f, CUBE_FACES)
        elif fmt == "ply":
            write_ply(path, f, CUBE_FACES, "binary_little_endian")
        else:
            write_off(path, f, CUBE_FACES)
    return folder


def evaluated(ob):
    dg = bpy.context.evaluated_depsgraph_get()
    ev = ob.evaluated_get(dg)
    me = ev.to_mesh()
    try:
        pos = np.empty(3 * len(me.vertices), np.float32)
        me.attributes["position"].data.foreach_get("vector", pos)
        return pos.reshape(-1, 3)
    finally:
        ev.to_mesh_clear()


def counts():
    return (len(bpy.data.objects), len(bpy.data.meshes), len(bpy.data.collections), len(bpy.data.cache_files),
            len(bpy.data.materials), bpy.context.scene.frame_start, bpy.context.scene.frame_end)


@pytest.mark.parametrize("fmt", ["obj", "ply", "off"])
def test_folder_import_plays_back_every_frame(tmp_path, pkg, fmt):
    frames = make_frames(12)
    folder = write_folder(str(tmp_path / "subject_a"), frames, fmt)
    assert bpy.ops.articula.import_scans(directory=folder, frame_start=5) == {'FINISHED'}
    ob = bpy.context.active_object
    assert ob.name == "subject_a" and ob.articula.kind == 'SCAN_SEQUENCE' and ob.articula.registered
    assert (ob.articula.frame_start, ob.articula.frame_count) == (5, 12)
    assert (bpy.context.scene.frame_start, bpy.context.scene.frame_end) == (5, 16)
    assert [list(p.vertices) for p in ob.data.polygons] == CUBE_FACES
    for k in (3, 0, 11, 7):           # scan{k+1} is shown at scene frame 5 + k
        bpy.context.scene.frame_set(5 + k)
        assert np.array_equal(evaluated(ob), frames[k])
    bpy.context.scene.frame_set(100)  # past the end: the last frame is held
    assert np.array_equal(evaluated(ob), frames[-1])
    got, faces = pkg("addon.sequences.scans").scan_frames(ob)
    assert got.dtype == np.float32 and np.array_equal(got, frames)
    # triangles of the polygons (Blender picks the quads' diagonals): each lies in one face, and the
    # triangles of each face cover exactly its corners
    assert len(faces) == len(triangles(CUBE_FACES))
    owner = [next(i for i, f in enumerate(CUBE_FACES) if set(t) <= set(f)) for t in faces.tolist()]
    for i, f in enumerate(CUBE_FACES):
        tris = [t for t, o in zip(faces.tolist(), owner) if o == i]
        assert len(tris) == len(f) - 2 and set(sum(tris, [])) == set(f)


def test_file_list_in_natural_order_and_save_reload(tmp_path, pkg):
    frames = make_frames(11, seed=1)
    folder = write_folder(str(tmp_path / "s"), frames)
    files = [{"name": f"scan{k}.obj"} for k in (10, 2, 1, 11, 3, 4, 5, 6, 7, 8, 9)]  # shuffled
    blend = str(tmp_path / "proj" / "scene.blend")
    os.makedirs(os.path.dirname(blend))
    bpy.ops.wm.save_as_mainfile(filepath=blend)
    assert bpy.ops.articula.import_scans(directory=folder, files=files, name="Seq") == {'FINISHED'}
    ob = bpy.data.objects["Seq"]
    assert ob.articula.cache_file.startswith("//scene_articula/")   # next to the .blend, relative
    bpy.ops.wm.save_mainfile()
    # save under another folder: the relative cache path must follow
    other = str(tmp_path / "elsewhere" / "copy.blend")
    os.makedirs(os.path.dirname(other))
    bpy.ops.wm.save_as_mainfile(filepath=other)
    for path in (blend, other):
        bpy.ops.wm.read_homefile(use_empty=True)
        bpy.ops.wm.open_mainfile(filepath=path)
        ob = bpy.data.objects["Seq"]
        for k in (6, 1, 10):
            bpy.context.scene.frame_set(1 + k)
            assert np.array_equal(evaluated(ob), frames[k])
        assert np.array_equal(pkg("addon.sequences.scans").scan_frames(ob)[0], frames)


def test_unsaved_file_uses_cache_folder(tmp_path, cache_home):
    folder = write_folder(str(tmp_path / "u"), make_frames(3))
    bpy.ops.articula.import_scans(directory=folder)
    path = bpy.context.active_object.articula.cache_file
    assert path.startswith(str(cache_home / "scan_cache")) and os.path.isfile(path)


def test_unregistered_sequence_rebuilds_topology(tmp_path, pkg):
    frames = make_frames(3, seed=2)
    folder = str(tmp_path / "raw")
    os.makedirs(folder)
    write_obj(os.path.join(folder, "f1.obj"), frames[0], CUBE_FACES)
    write_obj(os.path.join(folder, "f2.obj"), frames[1][:6], [[0, 1, 2, 3], [2, 3, 4, 5]])
    write_obj(os.path.join(folder, "f3.obj"), frames[2], CUBE_FACES[:3])
    before = counts()
    with pytest.raises(RuntimeError, match="not registered: f2.obj differs from f1.obj: vertex count 6 vs 8"):
        bpy.ops.articula.import_scans(directory=folder, require_registered=True)
    assert counts() == before
    assert bpy.ops.articula.import_scans(directory=folder) == {'FINISHED'}
    ob = bpy.context.active_object
    assert not ob.articula.registered and ob.articula.frame_count == 3
    assert ob.articula.cache_file.endswith(".scans") and os.path.isdir(ob.articula.cache_file)
    bpy.context.scene.frame_set(2)
    assert np.array_equal(evaluated(ob), frames[1][:6])
    assert [list(p.vertices) for p in ob.data.polygons] == [[0, 1, 2, 3], [2, 3, 4, 5]]
    bpy.context.scene.frame_set(3)
    assert np.array_equal(evaluated(ob), frames[2]) and len(ob.data.polygons) == 3
    sq = pkg("addon.sequences.scans")
    meshes = sq.scan_frame_meshes(ob)
    assert [len(m.vertices) for m in meshes] == [8, 6, 8]
    with pytest.raises(pkg("solver.errors").ArticulaInputError, match="not registered"):
        sq.scan_frames(ob)


@pytest.mark.parametrize("case, message", [
    ("missing", "gone.obj: file or folder not found"),
    ("empty", "no scan files"),
    ("garbage", "bad.ply: not a PLY file"),
    ("nan", "scan2.obj: vertex 4 has a non-finite"),
    ("nothing", "nothing to import"),
])
def test_bad_input_reports_and_leaves_scene_untouched(tmp_path, case, message, cache_home):
    bpy.ops.mesh.primitive_cube_add()
    folder = str(tmp_path / "in")
    os.makedirs(folder)
    if case == "missing":
        kwargs = dict(filepath=str(tmp_path / "in" / "gone.obj"))
    elif case == "empty":
        kwargs = dict(directory=folder)
    elif case == "garbage":
        write_ply(os.path.join(folder, "good.ply"), CUBE_VERTS, CUBE_FACES)
        with open(os.path.join(folder, "bad.ply"), "wb") as fh:
            fh.write(os.urandom(500))
        kwargs = dict(directory=folder)
    elif case == "nan":
        frames = make_frames(3).astype(float)
        frames[1, 3, 0] = np.nan
        write_folder(folder, frames)
        kwargs = dict(directory=folder)
    else:
        kwargs = {}
    before = counts()
    with pytest.raises(RuntimeError, match=message):
        bpy.ops.articula.import_scans(**kwargs)
    assert counts() == before
    assert not (cache_home / "scan_cache").exists() or not os.listdir(cache_home / "scan_cache")


def _faces_by_position(polys, verts):
    """Faces as tuples of corner positions, rotated to start at the smallest corner: comparable between
    meshes whose vertex numbering differs."""
    out = []
    for p in polys:
        pts = [tuple(np.round(verts[i], 5)) for i in p]
        k = pts.index(min(pts))
        out.append(tuple(pts[k:] + pts[:k]))
    return sorted(out)


@pytest.mark.parametrize("fmt", ["obj", "ply", "stl"])
def test_parsers_agree_with_blenders_importers(tmp_path, pkg, fmt):
    rng = np.random.default_rng(3)
    verts = (CUBE_VERTS + rng.normal(scale=0.05, size=CUBE_VERTS.shape)).astype(np.float32)
    path = str(tmp_path / f"x.{fmt}")
    if fmt == "obj":
        write_obj(path, verts, CUBE_FACES, "slashes")
        bpy.ops.wm.obj_import(filepath=path, forward_axis='Y', up_axis='Z')
    elif fmt == "ply":
        write_ply(path, verts, CUBE_FACES, "binary_big_endian")
        bpy.ops.wm.ply_import(filepath=path, forward_axis='Y', up_axis='Z')
    else:
        write_stl(path, verts, CUBE_FACES, binary=True)
        bpy.ops.wm.stl_import(filepath=path, forward_axis='Y', up_axis='Z')
    theirs = bpy.context.selected_objects[0].data
    their_v = np.array([v.co[:] for v in theirs.vertices])
    ours = pkg("solver.formats.mesh_files").read_mesh(path)
    our_faces = [ours.corner_verts[s:s + n].tolist() for s, n in zip(ours.face_starts, ours.face_sizes)]
    if fmt != "stl":   # STL: Blender numbers welded vertices its own way; compare by position below
        assert np.allclose(ours.vertices, their_v, atol=1e-6)
        assert our_faces == [list(p.vertices) for p in theirs.polygons]
    assert len(ours.vertices) == len(their_v)
    assert _faces_by_position(our_faces, ours.vertices) == \
        _faces_by_position([list(p.vertices) for p in theirs.polygons], their_v)


@pytest.mark.parametrize("ext", ["mdd", "pc2"])
def test_point_cache_with_base_file_or_selected_object(tmp_path, ext, pkg):
    frames = make_frames(6, seed=4)
    cache = str(tmp_path / f"anim.{ext}")
    (write_mdd if ext == "mdd" else write_pc2)(cache, frames)
    base = str(tmp_path / "base.obj")
    write_obj(base, CUBE_VERTS, CUBE_FACES)
    assert bpy.ops.articula.import_scans(filepath=cache, base_mesh=base) == {'FINISHED'}
    ob = bpy.context.active_object
    assert ob.name == "anim" and ob.articula.registered
    assert np.array_equal(pkg("addon.sequences.scans").scan_frames(ob)[0], frames)
    bpy.context.scene.frame_set(4)
    assert np.array_equal(evaluated(ob), frames[3])
    # the faces from a mesh object instead; a wrong vertex count is named
    me = bpy.data.meshes.new("basemesh")
    me.from_pydata(CUBE_VERTS.tolist(), [], CUBE_FACES)
    base_ob = bpy.data.objects.new("Base", me)
    bpy.context.scene.collection.objects.link(base_ob)
    assert bpy.ops.articula.import_scans(filepath=cache, source_object="Base", name="B") == {'FINISHED'}
    assert [list(p.vertices) for p in bpy.data.objects["B"].data.polygons] == CUBE_FACES
    small = bpy.data.meshes.new("small")
    small.from_pydata(CUBE_VERTS[:4].tolist(), [], [[0, 1, 2, 3]])
    bpy.context.scene.collection.objects.link(bpy.data.objects.new("Small", small))
    before = counts()
    with pytest.raises(RuntimeError, match=f"anim.{ext} has 8 vertices per frame but the base mesh Small has 4"):
        bpy.ops.articula.import_scans(filepath=cache, source_object="Small")
    assert counts() == before


def test_shape_keys_and_animation_of_an_object(pkg, tmp_path):
    me = bpy.data.meshes.new("m")
    me.from_pydata(CUBE_VERTS.tolist(), [], CUBE_FACES)
    ob = bpy.data.objects.new("Src", me)
    bpy.context.scene.collection.objects.link(ob)
    ob.location = (1, 2, 3)
    ob.shape_key_add(name="Basis")
    frames = make_frames(3, seed=5)
    for k in (1, 2):
        kb = ob.shape_key_add(name=f"k{k}")
        kb.data.foreach_set("co", frames[k].ravel())
    sq = pkg("addon.sequences.scans")
    # as the file browser sends it when confirmed with no file picked: the object is the source
    assert bpy.ops.articula.import_scans(source_object="Src", directory=str(tmp_path),
                                         filepath=str(tmp_path) + os.sep, files=[{"name": ""}]) == {'FINISHED'}
    got, _ = sq.scan_frames(bpy.context.active_object)
    assert got.shape == (3, 8, 3)
    assert np.allclose(got[0], CUBE_VERTS + [1, 2, 3], atol=1e-6)
    assert np.allclose(got[1:], frames[1:] + np.float32([1, 2, 3]), atol=1e-6)
    # animate the object's location over frames 1..4: the animation is sampled in world space
    for f in (1, 4):
        ob.location = (f, 0, 0)
        ob.keyframe_insert("location", frame=f)
        for kb in me.shape_keys.key_blocks[1:]:
            kb.value = 0.0
    bpy.context.scene.frame_set(2)
    before_frame = bpy.context.scene.frame_current
    assert bpy.ops.articula.import_scans(source_object="Src", object_frames='AUTO', source_frame_start=1,
                                         source_frame_end=4, name="Anim") == {'FINISHED'}
    assert bpy.context.scene.frame_current == before_frame
    got, _ = sq.scan_frames(bpy.data.objects["Anim"])
    assert got.shape == (4, 8, 3)
    xs = got[:, :, 0] - CUBE_VERTS[None, :, 0]
    assert np.allclose(xs[0], 1, atol=1e-5) and np.allclose(xs[3], 4, atol=1e-5)
    assert np.all(np.diff(xs[:, 0]) > 0)


DEM = os.path.join(SHARED_DATA, "dem_bones")


@pytest.mark.skipif(not os.path.isfile(os.path.join(DEM, "Bone_Anim.abc")), reason="shared data absent")
def test_alembic_dem_bones_matches_reference_and_leaves_no_temporaries(pkg):
    bpy.ops.mesh.primitive_cube_add()
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end = 1, 250
    before = counts()
    assert bpy.ops.articula.import_scans(filepath=os.path.join(DEM, "Bone_Anim.abc")) == {'FINISHED'}
    after = counts()
    # exactly one object and one mesh more; no cache files, collections, materials left from the import
    assert after[:5] == (before[0] + 1, before[1] + 1) + before[2:5]
    assert (scene.frame_start, scene.frame_end) == (1, 400)
    ob = bpy.context.active_object
    frames, _ = pkg("addon.sequences.scans").scan_frames(ob)
    ref = np.load(os.path.join(DEM, "Bone_Anim_positions_400x754x3.npy"))
    assert frames.shape == ref.shape == (400, 754, 3)
    # Axis convention: the .npy is the Alembic file's Y-up mesh data; Blender converts to Z-up,
    # (x, y, z) -> (x, -z, y), and the object's Xform adds a constant (0, 0, 0.3851) offset.
    mapped = np.stack([ref[..., 0], -ref[..., 2], ref[..., 1]], axis=-1)
    offset = frames - mapped
    assert np.abs(offset - offset[0, 0]).max() < 1e-5
    assert np.allclose(offset[0, 0], [0, 0, 0.3851], atol=1e-3)
    scene.frame_set(200)
    assert np.allclose(evaluated(ob), mapped[199] + offset[0, 0], atol=1e-5)


def test_batch_command(tmp_path, pkg):
    frames = make_frames(4, seed=6)
    folder = write_folder(str(tmp_path / "walk"), frames, "ply")
    cli = pkg("addon.cli.main")
    out = str(tmp_path / "out" / "walk.blend")
    assert cli.main(["import-scans", "--scans", folder, "--blend", out]) == 0
    assert os.path.isfile(out) and not os.path.exists(out + "1")
    bpy.ops.wm.open_mainfile(filepath=out)
    ob = bpy.data.objects["walk"]
    assert ob.articula.cache_file.startswith("//walk_articula/")
    assert np.array_equal(pkg("addon.sequences.scans").scan_frames(ob)[0], frames)
    os.makedirs(tmp_path / "empty")
    assert cli.main(["import-scans", "--scans", str(tmp_path / "empty")]) == 2


def test_undo_and_redo_of_an_import(tmp_path):
    frames = make_frames(5, seed=8)
    folder = write_folder(str(tmp_path / "u"), frames)
    bpy.ops.ed.undo_push(message="before import")
    before = counts()
    assert bpy.ops.articula.import_scans(directory=folder) == {'FINISHED'}
    bpy.ops.ed.undo_push(message="import")   # what the UI does after an UNDO operator (not bpy.ops here)
    assert "u" in bpy.data.objects
    bpy.ops.ed.undo()
    assert "u" not in bpy.data.objects and counts() == before
    bpy.ops.ed.redo()
    ob = bpy.data.objects["u"]
    for k in (3, 1):
        bpy.context.scene.frame_set(1 + k)
        assert np.array_equal(evaluated(ob), frames[k])


def test_unwritable_cache_is_reported(tmp_path, monkeypatch):
    folder = write_folder(str(tmp_path / "w"), make_frames(2))
    blocker = tmp_path / "not_a_folder"
    blocker.write_text("x")
    monkeypatch.setenv("ARTICULA_HOME", str(blocker))   # the cache folder would have to be inside a file
    before = counts()
    with pytest.raises(RuntimeError, match="cannot write the frame cache"):
        bpy.ops.articula.import_scans(directory=folder)
    assert counts() == before


def _export_alembic(path, ob, first, last):
    assert list(bpy.context.scene.objects) == [ob]   # the whole (one-object) scene is exported
    bpy.ops.wm.alembic_export(filepath=path, start=first, end=last, as_background_job=False)


def test_alembic_round_trip_of_an_animated_mesh(tmp_path, pkg):
    """A self-made .abc (no shared data): an animated, shape-keyed mesh exported by Blender and imported
    back must give the source's world-space evaluated positions per frame, and no leftovers."""
    me = bpy.data.meshes.new("m")
    me.from_pydata(CUBE_VERTS.tolist(), [], CUBE_FACES)
    ob = bpy.data.objects.new("Src", me)
    bpy.context.scene.collection.objects.link(ob)
    ob.shape_key_add(name="Basis")
    kb = ob.shape_key_add(name="bend")
    kb.data.foreach_set("co", make_frames(1, seed=10)[0].ravel())
    for f, value, x in ((1, 0.0, 0.0), (6, 1.0, 2.0)):
        kb.value = value
        kb.keyframe_insert("value", frame=f)
        ob.location = (x, 1.0, 0.5)
        ob.keyframe_insert("location", frame=f)
    path = str(tmp_path / "anim.abc")
    _export_alembic(path, ob, 1, 6)
    expected = []
    for f in range(1, 7):
        bpy.context.scene.frame_set(f)
        m = np.array(ob.matrix_world)
        expected.append(evaluated(ob) @ m[:3, :3].T + m[:3, 3])
    bpy.data.objects.remove(ob)
    bpy.context.scene.frame_set(1)
    before = counts()
    assert bpy.ops.articula.import_scans(filepath=path) == {'FINISHED'}
    after = counts()
    assert after[:5] == (before[0] + 1, before[1] + 1) + before[2:5]
    got, _ = pkg("addon.sequences.scans").scan_frames(bpy.context.active_object)
    assert got.shape == (6, 8, 3)
    assert np.allclose(got, np.array(expected), atol=1e-5)


def test_alembic_with_changing_topology_is_unregistered(tmp_path, pkg):
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=4, y_subdivisions=4)
    ob = bpy.context.active_object
    build = ob.modifiers.new("build", 'BUILD')      # faces appear one by one: topology changes per frame
    build.frame_start, build.frame_duration = 1, 5
    path = str(tmp_path / "grow.abc")
    _export_alembic(path, ob, 1, 5)
    bpy.data.objects.remove(ob)
    with pytest.raises(RuntimeError, match="not registered: grow.abc frame 2 differs from grow.abc frame 1"):
        bpy.ops.articula.import_scans(filepath=path, require_registered=True)
    assert bpy.ops.articula.import_scans(filepath=path) == {'FINISHED'}
    seq_ob = bpy.context.active_object
    assert not seq_ob.articula.registered and seq_ob.articula.frame_count == 5
    sizes = [len(m.face_sizes) for m in pkg("addon.sequences.scans").scan_frame_meshes(seq_ob)]
    assert sizes == sorted(sizes) and sizes[0] < sizes[-1]
    bpy.context.scene.frame_set(5)
    assert len(seq_ob.data.polygons) == sizes[-1]


def test_missing_cache_does_not_break_playback(tmp_path, capsys):
    frames = make_frames(3, seed=11)
    bpy.ops.articula.import_scans(directory=write_folder(str(tmp_path / "a"), frames), name="A")
    bpy.ops.articula.import_scans(directory=write_folder(str(tmp_path / "b"), frames[::-1]), name="B")
    a, b = bpy.data.objects["A"], bpy.data.objects["B"]
    os.remove(bpy.path.abspath(a.articula.cache_file))
    a.articula.cache_file = str(tmp_path / "gone.npy")   # a path never loaded before
    bpy.context.scene.frame_set(2)
    bpy.context.scene.frame_set(3)
    assert np.array_equal(evaluated(b), frames[::-1][2])      # the other object still plays
    assert capsys.readouterr().out.count("A: cannot show scan frame") == 1
