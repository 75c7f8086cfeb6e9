"""Binding a detailed scan to an Articula rig (``articula.bind_scan``, Surface Deform): the scan is
reproduced at the bind pose, moves rigidly with a rigid motion of the rig and with a posed limb near
that limb; bad input is refused clearly and leaves the scene as it was; the batch command."""
import numpy as np
import pytest
from scipy.spatial import cKDTree

import bpy
from articula.solver.geometry.procrustes import fit_rigid
from articula.solver.geometry.normals import vertex_normals

from ..rig_helpers import bbox_diagonal, subject

BIND_TOL = 1e-6      # relative to the scan's bounding-box diagonal
RIGID_TOL = 1e-5


# ----------------------------------------------------------------------------- scene helpers

def _subdivide(v, f):
    """One 1->4 midpoint subdivision of triangles ``f`` over vertices ``v`` (old vertices come first)."""
    e = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    uniq, inv = np.unique(e, axis=0, return_inverse=True)
    m01, m12, m20 = (len(v) + inv.reshape(-1).reshape(3, -1))
    a, b, c = f.T
    faces = np.concatenate([np.stack(t, 1) for t in ((a, m01, m20), (b, m12, m01), (c, m20, m12),
                                                     (m01, m12, m20))])
    return np.vstack([v, v[uniq].mean(1)]), faces


def _scan_points(v, f, levels=2, depth=0.002):
    """A scan-like copy of a surface: subdivided ``levels`` times and displaced along its normals by a
    wavy pattern up to ``depth`` metres."""
    for _ in range(levels):
        v, f = _subdivide(v, f)
    n = vertex_normals(v, f)
    return v + depth * (np.sin(v[:, 0] * 300) * np.cos(v[:, 2] * 200))[:, None] * n, f


def _mesh_object(pkg, name, v, f):
    me = pkg("addon.scene.mesh_io").new_mesh(name, v, f)
    ob = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(ob)
    return ob


def _evaluated(pkg, ob, frame):
    bpy.context.scene.frame_set(frame)
    return pkg("addon.scene.mesh_io").evaluated_positions(ob)



def _rig(pkg, limb_deg=70.0):
    """The tube-body rig with an action: frame 1 a pose, frame 2 the same pose moved rigidly (root
    rotation and translation), frame 3 frame 1 with ``forearm.L`` bent further."""
    model = subject(pkg)
    names = model.skeleton.names
    Poses = pkg("solver.rig.model").Poses
    base = pkg("solver.rig.pose_sampling").random_poses(1, len(names), seed=5, max_twist_deg=30,
                                                       max_swing_deg=30)
    rot = np.repeat(base.rotations, 3, axis=0)
    trans = np.repeat(base.translations, 3, axis=0)
    half = np.radians(40) / 2
    turn = np.array([np.cos(half), 0, 0, np.sin(half)])
    rot[1, 0] = _qmul(turn, rot[0, 0])
    trans[1] += [0.3, -0.2, 0.1]
    half = np.radians(limb_deg) / 2
    fa = names.index("forearm.L")
    rot[2, fa] = _qmul(rot[0, fa], np.array([np.cos(half), np.sin(half), 0, 0]))
    poses = Poses(rot, trans, np.ones(3))
    rig = pkg("addon.rig.builder").build_rig(bpy.context, model, "Body")
    pkg("addon.rig.actions").write_action(rig.armature, names, poses)
    return model, rig


def _qmul(a, b):
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2])


def _posed_scan(pkg, model, rig, frame=1, name="Scan"):
    """A scan of the rig mesh as posed at ``frame`` (~44k vertices), as a new object."""
    posed = _evaluated(pkg, rig.mesh, frame)
    v, f = _scan_points(posed, model.faces)
    return _mesh_object(pkg, name, v, f), v


def _bind(scan, rig, **kw):
    return bpy.ops.articula.bind_scan(scan=scan.name, rig=rig.armature.name, **kw)


# ----------------------------------------------------------------------------- behaviour

def test_scan_follows_the_rig_exactly_at_the_bind_pose_and_rigidly_under_rigid_motion(pkg):
    model, rig = _rig(pkg)
    scan, original = _posed_scan(pkg, model, rig)
    assert 10_000 < len(original) < 60_000
    assert _bind(scan, rig) == {'FINISHED'}
    mod = scan.modifiers[pkg("addon.retarget.scan_binding").MODIFIER]
    assert mod.type == 'SURFACE_DEFORM' and mod.is_bound and mod.target == rig.mesh
    size = bbox_diagonal(original)
    err = np.abs(_evaluated(pkg, scan, 1) - original).max() / size
    assert err < BIND_TOL, f"bind pose reproduced to {err:.3g}"
    R, t = fit_rigid(_evaluated(pkg, rig.mesh, 1), _evaluated(pkg, rig.mesh, 2))
    assert np.abs(_evaluated(pkg, rig.mesh, 1) @ R.T + t - _evaluated(pkg, rig.mesh, 2)).max() < 1e-5
    moved = _evaluated(pkg, scan, 2)
    assert np.abs(moved - original).max() > 0.1
    err = np.abs(moved - (original @ R.T + t)).max() / size
    assert err < RIGID_TOL, f"rigid motion reproduced to {err:.3g}"


def test_posed_limb_moves_the_scan_near_that_limb_only(pkg):
    model, rig = _rig(pkg)
    scan, original = _posed_scan(pkg, model, rig)
    assert _bind(scan, rig) == {'FINISHED'}
    names = model.skeleton.names
    limb = np.isin(model.anchor, [names.index("forearm.L"), names.index("hand.L")])
    rig1, rig3 = _evaluated(pkg, rig.mesh, 1), _evaluated(pkg, rig.mesh, 3)
    still = np.linalg.norm(rig3 - rig1, axis=1) < 1e-9
    R, t = fit_rigid(rig1[limb], rig3[limb])
    near = cKDTree(rig1).query_ball_point(original, r=0.06)
    on_limb = np.array([bool(ix) and limb[ix].all() for ix in near])
    off_limb = np.array([bool(ix) and still[ix].all() for ix in near])
    assert on_limb.sum() > 1000 and off_limb.sum() > 10_000
    got = _evaluated(pkg, scan, 3)
    size = bbox_diagonal(original)
    assert np.linalg.norm(got[on_limb] - original[on_limb], axis=1).min() > 0.02     # the limb moved
    err = np.abs(got[on_limb] - (original[on_limb] @ R.T + t)).max() / size
    assert err < RIGID_TOL, f"scan on the posed limb off its rigid motion by {err:.3g}"
    assert np.abs(got[off_limb] - original[off_limb]).max() / size < BIND_TOL


def test_rest_pose_binding_and_the_rig_is_restored(pkg):
    model, rig = _rig(pkg)
    v, f = _scan_points(model.rest_vertices, model.faces, levels=1)
    scan = _mesh_object(pkg, "Scan", v, f)
    bpy.context.scene.frame_set(2)
    assert _bind(scan, rig, bind_pose='REST') == {'FINISHED'}
    assert rig.armature.data.pose_position == 'POSE' and rig.twist.data.pose_position == 'POSE'
    size = bbox_diagonal(v)
    rig.armature.data.pose_position = rig.twist.data.pose_position = 'REST'
    assert np.abs(_evaluated(pkg, scan, 2) - v).max() / size < BIND_TOL
    rig.armature.data.pose_position = rig.twist.data.pose_position = 'POSE'
    rig2 = _evaluated(pkg, rig.mesh, 2)
    gap = np.linalg.norm(_evaluated(pkg, scan, 2)[:len(rig2)] - rig2, axis=1)
    assert np.percentile(gap, 99) < 0.0021          # the scan lies on the posed rig (displaced by <= 2 mm)


def test_binding_again_replaces_the_modifier_and_binds_the_undeformed_scan(pkg):
    model, rig = _rig(pkg)
    scan, original = _posed_scan(pkg, model, rig)
    scan.modifiers.new("User Smooth", 'SMOOTH').factor = 0.0
    assert _bind(scan, rig) == {'FINISHED'}
    scan.modifiers.move(1, 0)                                       # ours first, the user's after
    bpy.context.scene.frame_set(3)                                  # the old binding bends the scan's arm
    assert _bind(scan, rig) == {'FINISHED'}
    kinds = [(m.name, m.type) for m in scan.modifiers]
    name = pkg("addon.retarget.scan_binding").MODIFIER
    assert kinds == [(name, 'SURFACE_DEFORM'), ("User Smooth", 'SMOOTH')]
    assert np.abs(_evaluated(pkg, scan, 3) - original).max() / bbox_diagonal(original) < BIND_TOL


def test_selection_gives_scan_and_rig(pkg):
    model, rig = _rig(pkg)
    scan, _ = _posed_scan(pkg, model, rig)
    for ob in bpy.context.view_layer.objects:
        ob.select_set(ob in (scan, rig.mesh))
    bpy.context.view_layer.objects.active = scan
    assert bpy.ops.articula.bind_scan() == {'FINISHED'}
    assert scan.modifiers[0].target == rig.mesh
    assert {'REGISTER', 'UNDO'} <= set(bpy.types.ARTICULA_OT_bind_scan.bl_options)


# ----------------------------------------------------------------------------- bad input

def _refused(match, **kw):
    before = {ob.name: [m.name for m in ob.modifiers] for ob in bpy.data.objects}
    with pytest.raises(RuntimeError, match=match):
        bpy.ops.articula.bind_scan(**kw)
    assert {ob.name: [m.name for m in ob.modifiers] for ob in bpy.data.objects} == before


def test_bad_scans_and_rigs_are_refused_clearly(pkg, tmp_path):
    model, rig = _rig(pkg)
    cam = bpy.data.objects.new("Cam", bpy.data.cameras.new("Cam"))
    bpy.context.scene.collection.objects.link(cam)
    empty = bpy.data.objects.new("Empty Scan", bpy.data.meshes.new("Empty Scan"))
    bpy.context.scene.collection.objects.link(empty)
    scan, _ = _posed_scan(pkg, model, rig)
    arm = bpy.data.objects.new("Plain", bpy.data.armatures.new("Plain"))
    bpy.context.scene.collection.objects.link(arm)
    _refused("'Cam' is a camera object, not a mesh", scan="Cam", rig="Body")
    _refused("'Empty Scan' has no vertices", scan=empty.name, rig="Body")
    _refused("no object named 'Nope'", scan="Nope", rig="Body")
    _refused(r"Plain is not \(part of\) an Articula rig", scan=scan.name, rig="Plain")
    _refused("is part of an Articula rig", scan=rig.mesh.name, rig="Body")
    rig.mesh.modifiers.remove(rig.mesh.modifiers[pkg("solver.rig.names").SWING_MODIFIER])
    _refused("has no rig mesh", scan=scan.name, rig="Body")


def test_linked_scan_is_refused(pkg, tmp_path):
    lib = _mesh_object(pkg, "LibScan", np.eye(3), np.array([[0, 1, 2]]))
    path = str(tmp_path / "lib.blend")
    bpy.data.libraries.write(path, {lib})
    bpy.ops.wm.read_homefile(use_empty=True)
    model, rig = _rig(pkg)
    with bpy.data.libraries.load(path, link=True) as (src, dst):
        dst.objects = ["LibScan"]
    bpy.context.scene.collection.objects.link(dst.objects[0])
    _refused("linked from .*Make Local", scan=dst.objects[0].name, rig="Body")


def test_failed_binding_keeps_the_previous_one(pkg):
    model, rig = _rig(pkg)
    scan, original = _posed_scan(pkg, model, rig)
    assert _bind(scan, rig) == {'FINISHED'}
    me = rig.mesh.data
    a, b, c = model.faces[100]
    pos = pkg("addon.scene.mesh_io").read_positions(me)
    pos[c] = (pos[a] + pos[b]) / 2                                   # a degenerate (collinear) triangle
    me.attributes["position"].data.foreach_set("vector", pos.astype(np.float32).ravel())
    me.update()
    _refused("concave or degenerate .*polygon 100", scan=scan.name, rig="Body", bind_pose='REST')
    mod = scan.modifiers[0]
    assert len(scan.modifiers) == 1 and mod.is_bound and mod.show_viewport
    assert rig.armature.data.pose_position == 'POSE' and rig.twist.data.pose_position == 'POSE'


def test_scan_on_the_rig_edges_is_explained(pkg):
    model, rig = _rig(pkg)
    v, f = _scan_points(model.rest_vertices, model.faces, levels=1, depth=0.0)
    copy = _mesh_object(pkg, "Copy", v, f)
    _refused("bound no vertex; .*exactly on the rig mesh's edges", scan=copy.name, rig="Body", bind_pose='REST')


# ----------------------------------------------------------------------------- batch

def test_batch_command_binds_a_scan_file_and_never_writes_the_input(pkg, tmp_path):
    model, rig = _rig(pkg)
    posed = _evaluated(pkg, rig.mesh, 1)
    v, f = _scan_points(posed, model.faces, levels=1)
    ply = str(tmp_path / "scan.ply")
    pkg("sample_scenes.mesh_files").SequenceWriter(f, "ply").write(ply, v)
    blend, out = str(tmp_path / "rig.blend"), str(tmp_path / "out" / "bound.blend")
    bpy.ops.wm.save_as_mainfile(filepath=blend)
    stamp = open(blend, "rb").read()
    main = pkg("addon.cli.main").main
    assert main(["bind-scan", "--blend", blend, "--rig", "Body", "--scan", ply, "--frame", "1",
                 "--out", out]) == 0
    assert open(blend, "rb").read() == stamp
    assert main(["bind-scan", "--blend", blend, "--rig", "Nope", "--scan", ply, "--out", out + "2"]) == 2
    assert main(["bind-scan", "--blend", blend, "--scan", ply, "--out", blend]) == 2
    bpy.ops.wm.open_mainfile(filepath=out)
    scan = bpy.data.objects["scan"]
    assert scan.modifiers[0].is_bound
    size = bbox_diagonal(v)
    assert np.abs(_evaluated(pkg, scan, 1) - v).max() / size < BIND_TOL
    assert np.abs(_evaluated(pkg, scan, 2) - v).max() > 0.1
