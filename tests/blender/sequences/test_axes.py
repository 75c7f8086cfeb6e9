"""Axis conventions of scan files (issue 16 item 8): ``articula.import_scans`` and ``import-scans`` place
files as Blender's own importers do (OBJ forward -Z, up Y; PLY/STL as written), the Forward/Up options,
the frames kept in file coordinates with the conversion in the object matrix, the learned rig with the
scans' object matrix, and the sample files standing up in Blender's importers.

References computed independently: ``bpy_extras.io_utils.axis_conversion`` and Blender's importers
(``wm.obj_import`` / ``wm.ply_import`` / ``wm.stl_import``) on the same files."""
import os
from types import SimpleNamespace

import bpy
import numpy as np
import pytest
from bpy_extras.io_utils import axis_conversion

from articula.sample_scenes.tube_scans import hybrid_truth

pytestmark = pytest.mark.usefixtures("cache_home")   # a fresh ARTICULA_HOME per test

SHORT = {"X": "X", "Y": "Y", "Z": "Z", "NEGATIVE_X": "-X", "NEGATIVE_Y": "-Y", "NEGATIVE_Z": "-Z"}
BOX = (0.2, 0.3, 1.0)          # half sizes: a tall box, 2 m high in Blender's Z


def world_vertices(ob):
    """(V, 3) vertices of ``ob``'s mesh in world coordinates (its object matrix applied)."""
    me = ob.data
    co = np.empty(3 * len(me.vertices), np.float64)
    me.vertices.foreach_get("co", co)
    m = np.array(ob.matrix_world, np.float64)
    return co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3]


def extent(points):
    return points.max(axis=0) - points.min(axis=0)


def export_tall_box(path, exporter, **options):
    """A tall box (moved, so a wrong axis also moves it) exported by Blender's exporter with its defaults;
    the box's world vertices; the scene emptied again."""
    bpy.ops.mesh.primitive_cube_add(location=(0.5, -0.4, 1.2))
    ob = bpy.context.active_object
    ob.scale = BOX
    bpy.context.view_layer.update()
    truth = world_vertices(ob)
    exporter(filepath=path, **options)
    bpy.data.objects.remove(ob)
    return truth


def imported_by_blender(importer, path, **axes):
    before = set(bpy.data.objects)
    importer(filepath=path, **axes)
    (ob,) = set(bpy.data.objects) - before
    pts = world_vertices(ob)
    bpy.data.objects.remove(ob)
    return pts


def test_axis_matrix_is_blenders_axis_conversion(pkg):
    axes = pkg("solver.formats.axes")
    pairs = 0
    for f in axes.AXES:
        for u in axes.AXES:
            if f[-1] == u[-1]:
                with pytest.raises(ValueError, match="same axis"):
                    axes.axis_matrix(f, u)
                continue
            ref = np.array(axis_conversion(from_forward=SHORT[f], from_up=SHORT[u]).to_4x4())
            np.testing.assert_array_equal(axes.axis_matrix(f, u), ref)
            pairs += 1
    assert pairs == 24
    np.testing.assert_array_equal(axes.conversion(".obj"), axis_conversion(from_forward="-Z", from_up="Y").to_4x4())
    for ext in (".ply", ".stl", ".off", ".mdd", ".pc2"):
        np.testing.assert_array_equal(axes.conversion(ext), np.eye(4))
    assert [axes.parse_axis(a) for a in ("-z", "Y", "NEGATIVE_X", "auto")] == ["NEGATIVE_Z", "Y", "NEGATIVE_X", "AUTO"]


@pytest.mark.parametrize("forward, up", [("AUTO", "AUTO"), ("Y", "Z"), ("X", "NEGATIVE_Y")])
def test_blender_exported_obj_stands_up_like_blenders_importer(tmp_path, pkg, forward, up):
    """A tall box exported with the OBJ exporter's defaults: imported with the default axes it stands
    upright (Z is the tall extent) where it was; with any axes, the world vertices are those of
    ``wm.obj_import`` with the same axes.  The frames stay in file coordinates (the matrix converts)."""
    path = str(tmp_path / "box.obj")
    truth = export_tall_box(path, bpy.ops.wm.obj_export)
    blender_axes = {} if forward == "AUTO" else {"forward_axis": forward, "up_axis": up}
    theirs = imported_by_blender(bpy.ops.wm.obj_import, path, **blender_axes)
    ours_axes = {} if forward == "AUTO" else {"axis_forward": forward, "axis_up": up}     # AUTO: the default
    assert bpy.ops.articula.import_scans(filepath=path, **ours_axes) == {'FINISHED'}
    ob = bpy.context.active_object
    ours = world_vertices(ob)
    np.testing.assert_allclose(ours, theirs, atol=1e-6)
    file_coords = pkg("solver.formats.mesh_files").read_mesh(path).vertices
    np.testing.assert_allclose(pkg("addon.sequences.scans").scan_frames(ob)[0][0], file_coords, atol=1e-6)
    if forward == "AUTO":
        np.testing.assert_allclose(ours, truth, atol=1e-5)
        assert np.argmax(extent(ours)) == 2 and extent(ours)[2] == pytest.approx(2 * BOX[2], abs=1e-5)
        assert ob.location[:] == pytest.approx((0, 0, 0)) and ob.rotation_euler[0] == pytest.approx(np.pi / 2)


@pytest.mark.parametrize("ext", ["ply", "stl"])
def test_ply_and_stl_follow_blenders_importers(tmp_path, ext):
    """Blender's PLY and STL importers and exporters use forward Y, up Z (no conversion): so do we."""
    path = str(tmp_path / f"box.{ext}")
    exporter = bpy.ops.wm.ply_export if ext == "ply" else bpy.ops.wm.stl_export
    truth = export_tall_box(path, exporter, **({"ascii_format": True} if ext == "ply" else {}))
    theirs = imported_by_blender(bpy.ops.wm.ply_import if ext == "ply" else bpy.ops.wm.stl_import, path)
    assert bpy.ops.articula.import_scans(filepath=path) == {'FINISHED'}
    ob = bpy.context.active_object
    ours = world_vertices(ob)
    # compared as sets of positions: the exporters split corners (PLY) and Blender welds STL its own way
    key = lambda p: set(map(tuple, np.round(p, 5).tolist()))
    assert key(ours) == key(theirs) == key(truth) and len(key(truth)) == 8
    assert np.array(ob.matrix_world) == pytest.approx(np.eye(4))


def test_alembic_default_is_blenders_conversion_and_explicit_axes_apply_on_top(tmp_path, pkg):
    """Alembic is Y up and converted by Blender's importer: the default adds nothing; ``Y``/``Z`` (the
    file declared Z up) leaves the file's Y-up coordinates, as the same declaration does for an OBJ."""
    path = str(tmp_path / "box.abc")
    truth = export_tall_box(path, bpy.ops.wm.alembic_export)
    assert bpy.ops.articula.import_scans(filepath=path, name="auto") == {'FINISHED'}
    assert np.array(bpy.data.objects["auto"].matrix_world) == pytest.approx(np.eye(4))
    key = lambda p: set(map(tuple, np.round(p, 5).tolist()))
    assert key(world_vertices(bpy.data.objects["auto"])) == key(truth)
    assert bpy.ops.articula.import_scans(filepath=path, name="zup", axis_forward='Y', axis_up='Z') == {'FINISHED'}
    as_written = pkg("solver.formats.axes").world_to_file(truth, ".abc")        # (x, z, -y)
    assert key(world_vertices(bpy.data.objects["zup"])) == key(as_written)


def test_bad_axes_are_refused_before_anything_changes(tmp_path):
    path = str(tmp_path / "box.obj")
    export_tall_box(path, bpy.ops.wm.obj_export)
    before = len(bpy.data.objects), len(bpy.data.meshes)
    with pytest.raises(RuntimeError, match="forward Z and up NEGATIVE_Z lie on the same axis"):
        bpy.ops.articula.import_scans(filepath=path, axis_forward='Z', axis_up='NEGATIVE_Z')
    me = bpy.data.meshes.new("keys")
    me.from_pydata([(0, 0, 0), (1, 0, 0), (0, 1, 0)], [], [(0, 1, 2)])
    src = bpy.data.objects.new("Src", me)
    bpy.context.scene.collection.objects.link(src)
    src.shape_key_add(name="Basis")
    before = len(bpy.data.objects), len(bpy.data.meshes)
    with pytest.raises(RuntimeError, match="Forward/Up axes apply to files"):
        bpy.ops.articula.import_scans(source_object="Src", axis_up='Y')
    assert (len(bpy.data.objects), len(bpy.data.meshes)) == before


def test_batch_import_with_forward_and_up(tmp_path, pkg):
    """``import-scans --forward/--up``: the default stands a Blender OBJ up; ``--forward Y --up Z``
    reads it as written (lying on its back, as ``wm.obj_import(forward_axis='Y', up_axis='Z')``)."""
    path = str(tmp_path / "box.obj")
    truth = export_tall_box(path, bpy.ops.wm.obj_export)
    lying = imported_by_blender(bpy.ops.wm.obj_import, path, forward_axis='Y', up_axis='Z')
    cli = pkg("addon.cli.main")
    for args, expected in (([], truth), (["--forward", "-Z", "--up", "Y"], truth), (["--forward", "Y", "--up", "z"], lying)):
        blend = str(tmp_path / f"out{len(args)}{args[1] if args else ''}.blend")
        bpy.ops.wm.read_homefile(use_empty=True)
        assert cli.main(["import-scans", "--scans", path, *args, "--blend", blend]) == 0
        bpy.ops.wm.open_mainfile(filepath=blend)
        np.testing.assert_allclose(world_vertices(bpy.data.objects["box"]), expected, atol=1e-5)
    assert np.argmax(extent(lying)) == 1                         # the tall side along Y: on its back
    assert cli.main(["import-scans", "--scans", path, "--forward", "Z", "--up", "-Z"]) == 2
    with pytest.raises(SystemExit):
        cli.main(["import-scans", "--scans", path, "--forward", "W"])


# --------------------------------------------------------------------------- the learned rig


@pytest.fixture(scope="module")
def truth():
    return hybrid_truth(M=5, seed=4, max_angle=0.6)


def write_blender_objs(pkg, folder, scans, faces):
    """The scans (world, Z up) written as Blender's OBJ exporter would (Y up)."""
    os.makedirs(folder, exist_ok=True)
    writer = pkg("sample_scenes.mesh_files").SequenceWriter(faces, "obj", from_world=True)
    for k, s in enumerate(scans):
        writer.write(os.path.join(folder, f"pose{k + 1}.obj"), s)
    return folder


def rig_world_mesh(pkg, arm):
    mesh = pkg("addon.rig.reader").find_mesh(arm)
    m = np.array(mesh.matrix_world)
    return pkg("addon.scene.mesh_io").evaluated_positions(mesh) @ m[:3, :3].T + m[:3, 3]


def test_rig_built_from_a_y_up_sequence_stands_where_the_scans_stand(pkg, tmp_path, truth):
    """result.build with the generating model (solved in the files' Y-up coordinates): the rig has the scan
    object's matrix and its world mesh equals the scans' world vertices on every frame."""
    inputs, result, heat_map = pkg("addon.learn.inputs"), pkg("addon.learn.result"), pkg("addon.learn.heat_map")
    axes, solve = pkg("solver.formats.axes"), pkg("addon.learn.solve")
    model, poses, scans = truth
    folder = write_blender_objs(pkg, str(tmp_path / "body"), scans, model.faces)
    assert bpy.ops.articula.import_scans(directory=folder) == {'FINISHED'}
    ob = bpy.context.active_object
    inp = inputs.input_from_object(ob)
    file_scans = axes.world_to_file(scans, ".obj")
    np.testing.assert_allclose(inp.scans, file_scans, atol=1e-6)
    np.testing.assert_allclose(inp.matrix, axes.conversion(".obj"), atol=1e-6)     # Blender keeps float32
    # the truth model in the files' coordinates: every point rotated, poses conjugated by the rotation
    r = axes.conversion(".obj")[:3, :3].T                                  # world -> file
    sk = model.skeleton
    file_sk = type(sk)(sk.names, sk.parents, sk.heads @ r.T, sk.tails @ r.T, r @ sk.frames)
    file_model = type(model)(model.rest_vertices @ r.T, model.faces, file_sk, model.anchor, model.twist_weights,
                             model.swing_weights)
    file_poses = type(poses)(poses.rotations, poses.translations @ r.T, poses.scales)
    posed = pkg("solver.rig.skinning").hybrid_skin(file_model, file_poses)
    np.testing.assert_allclose(posed, file_scans, atol=1e-6)
    heat = heat_map.vertex_error_mm(file_model, file_poses, inp.scans)
    fit = SimpleNamespace(model=file_model, poses=file_poses,
                          report={"error_mm": {"mean": 0.0, "median": 0.0, "max": 0.0}})
    with pkg("addon.jobs").scene_guard():
        rig, _ = result.build(bpy.context, solve.LearnOutcome(inp, fit, heat), "Truth")
    np.testing.assert_allclose(np.array(rig.armature.matrix_world), np.array(ob.matrix_world), atol=1e-7)
    for k in range(len(scans)):
        bpy.context.scene.frame_set(ob.articula.frame_start + k)
        np.testing.assert_allclose(rig_world_mesh(pkg, rig.armature), scans[k], atol=3e-5)
        np.testing.assert_allclose(world_vertices(ob), scans[k], atol=1e-5)


def test_learned_rig_has_the_sources_matrix_and_initial_armature_is_taken_as_shown(pkg, tmp_path, truth):
    """articula.learn_rig on a Y-up sequence: the rig's object matrix is the scans' (here also moved by
    the user); an initial armature placed over the scans as they are shown keeps its world joints."""
    model, poses, scans = truth
    folder = write_blender_objs(pkg, str(tmp_path / "body"), scans, model.faces)
    assert bpy.ops.articula.import_scans(directory=folder) == {'FINISHED'}
    ob = bpy.context.active_object
    ob.location = (1.0, 0.0, 0.0)
    bpy.context.view_layer.update()
    sk = model.skeleton
    arm = bpy.data.objects.new("Init", bpy.data.armatures.new("Init"))
    bpy.context.scene.collection.objects.link(arm)
    bpy.context.view_layer.objects.active = arm
    bpy.ops.object.mode_set(mode='EDIT')
    made = [arm.data.edit_bones.new(n) for n in sk.names]
    for b, eb in enumerate(made):
        eb.head, eb.tail = sk.heads[b] + [1.0, 0, 0], sk.tails[b] + [1.0, 0, 0]     # over the moved scans
        if b:
            eb.parent = made[sk.parents[b]]
    bpy.ops.object.mode_set(mode='OBJECT')
    out = str(tmp_path / "learned.npz")
    assert bpy.ops.articula.learn_rig(source_object=ob.name, initial_armature="Init", max_iterations=0,
                                      name="Learned", output_bundle=out) == {'FINISHED'}
    learned = bpy.data.objects["Learned"]
    np.testing.assert_allclose(np.array(learned.matrix_world), np.array(ob.matrix_world), atol=1e-7)
    got = pkg("addon.rig.reader").read_skeleton(learned)
    m = np.array(learned.matrix_world)
    world_heads = got.heads @ m[:3, :3].T + m[:3, 3]
    order = [got.names.index(n) for n in sk.names]
    np.testing.assert_allclose(world_heads[order], sk.heads + [1.0, 0, 0], atol=1e-5)
    # the bundle is in the scans' (files') coordinates; the rig shows it where the scans stand
    bundle = pkg("solver.formats.bundle").load_bundle(out)
    posed = pkg("solver.rig.skinning").hybrid_skin(bundle.model, bundle.poses)
    for k in (0, len(scans) - 1):
        bpy.context.scene.frame_set(ob.articula.frame_start + k)
        np.testing.assert_allclose(rig_world_mesh(pkg, learned), posed[k] @ m[:3, :3].T + m[:3, 3], atol=5e-5)
        assert np.linalg.norm(rig_world_mesh(pkg, learned) - (scans[k] + [1.0, 0, 0]), axis=1).mean() < 0.1


def test_batch_learn_rig_with_axes(tmp_path, pkg, truth):
    """``learn-rig --scans DIR --blend``: the bundle in the files' coordinates, the scans and the rig in
    the .blend with the same object matrix: the files' conversion (default) or as given by --forward/--up."""
    model, poses, scans = truth
    folder = write_blender_objs(pkg, str(tmp_path / "body"), scans, model.faces)
    axes, cli = pkg("solver.formats.axes"), pkg("addon.cli.main")
    for args, expected in (([], axes.conversion(".obj")), (["--forward", "Y", "--up", "Z"], np.eye(4))):
        tag = "zup" if args else "auto"
        out, blend = str(tmp_path / f"{tag}.npz"), str(tmp_path / f"{tag}.blend")
        bpy.ops.wm.read_homefile(use_empty=True)
        assert cli.main(["learn-rig", "--scans", folder, "--parts", "8", "--iterations", "0", *args,
                         "--out", out, "--blend", blend]) == 0
        bundle = pkg("solver.formats.bundle").load_bundle(out)
        file_scans = axes.world_to_file(scans, ".obj")
        posed = pkg("solver.rig.skinning").hybrid_skin(bundle.model, bundle.poses)
        assert np.linalg.norm(posed - file_scans, axis=2).mean() < 0.03      # the files' coordinates
        bpy.ops.wm.open_mainfile(filepath=blend)
        seq = next(o for o in bpy.data.objects if o.articula.kind == 'SCAN_SEQUENCE')
        rig = next(o for o in bpy.data.objects if o.articula.kind == 'RIG_ARMATURE')
        np.testing.assert_allclose(np.array(seq.matrix_world), expected, atol=1e-6)   # float32 matrices
        np.testing.assert_allclose(np.array(rig.matrix_world), np.array(seq.matrix_world), atol=1e-7)


# --------------------------------------------------------------------------- the sample files


@pytest.mark.parametrize("fmt", ["obj", "ply"])
def test_sample_files_stand_up_in_blenders_importer_and_ours(tmp_path, pkg, fmt):
    """``samples registered``: Blender's own importer (default axes) and articula.import_scans both put
    the files' vertices at the ground truth's world coordinates (Z up, standing on z = 0)."""
    registered = pkg("sample_scenes.registered")
    gt = registered.generate_registered(str(tmp_path), "mixamo", "female", 2, skin="lbs", fmt=fmt, seed=1,
                                        faces="triangles")
    path = str(tmp_path / f"pose_0001.{fmt}")
    importer = bpy.ops.wm.obj_import if fmt == "obj" else bpy.ops.wm.ply_import
    theirs = imported_by_blender(importer, path)
    tol = 2e-6 if fmt == "obj" else 1e-5                  # 6 decimals / float32
    np.testing.assert_allclose(theirs, gt["posed_vertices"][1], atol=tol)
    assert extent(theirs)[2] > 1.4 and np.argmax(extent(theirs)) == 2
    assert bpy.ops.articula.import_scans(directory=str(tmp_path)) == {'FINISHED'}
    ob = bpy.context.active_object
    bpy.context.scene.frame_set(ob.articula.frame_start + 1)
    np.testing.assert_allclose(world_vertices(ob), gt["posed_vertices"][1], atol=tol)
