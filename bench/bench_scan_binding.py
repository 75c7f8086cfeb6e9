"""Scan binding (``articula.bind_scan``, Blender's Surface Deform) measured on a large synthetic scan.

The scan: the MakeHuman body's rig (13,380 vertices, 26,756 triangles) posed by a range-of-motion pose,
its surface subdivided twice (1 -> 4 midpoint splits, 214k vertices) and displaced along the
interpolated normals by 0.6-3 mm (a wavy pattern), as a detailed scan would be.  Every scan vertex
keeps its rig triangle and barycentric coordinates, so the reference motion of a point glued at
constant normal offset ``d`` (the dissertation's gluing: posed barycentric point + ``d`` x posed
interpolated normal) is known exactly.

Lines printed (``scan_binding_lines``): bind time; time per frame of the depsgraph with and without
the scan; error at the bind pose and under a rigid motion of the rig (relative to the scan's size);
for offset shells d = -1 cm ... 10 cm the Surface Deform result against the glued reference after a
second pose (median / 95th percentile / max in mm), next to the same gluing done in numpy with the
closest triangle and the face normal, and each shell's rigid-motion error; the bytes per scan vertex
that the binding adds to a saved .blend; and the tube body (19 separate tubes, touching at
the joints) bound at rest, where vertices near another piece follow it.

Usage: ``./run bench scan_binding [--picture docs/images/scan_binding.png]``; ``./run bench retarget`` prints
the same lines (:func:`scan_binding_lines`).
"""
import argparse
import importlib
import os
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common  # noqa: E402

import numpy as np  # noqa: E402

from articula.solver.geometry.procrustes import fit_rigid  # noqa: E402
from articula.solver.geometry.normals import vertex_normals  # noqa: E402  (area-weighted)


PKG = []


def _addon():
    os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="articula_bench_"))
    import bpy
    sys.path.insert(0, _common.REPO)
    import batch
    PKG[:] = [importlib.import_module(batch.enable_addon(bpy))]
    return bpy, PKG[0]


def _mod(pkg, name):
    return importlib.import_module(f"{pkg.__name__}.{name}")


def subdivide_tracked(faces, levels):
    """Midpoint subdivision (1 -> 4, ``levels`` times) of triangles ``faces`` (F,3) that keeps, for every
    new vertex, an original triangle and barycentric coordinates in it.
    Returns (faces (16^levels F... ,3), tri (V',), bary (V',3)); vertex order: originals first."""
    f = np.asarray(faces, np.int64)
    nv = int(f.max()) + 1
    ftri = np.arange(len(f))
    fb = np.repeat(np.eye(3)[None], len(f), axis=0)
    for _ in range(levels):
        e = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
        uniq, inv = np.unique(e, axis=0, return_inverse=True)
        m01, m12, m20 = nv + inv.reshape(-1).reshape(3, -1)
        a, b, c = f.T
        b0, b1, b2 = fb[:, 0], fb[:, 1], fb[:, 2]
        h01, h12, h20 = (b0 + b1) / 2, (b1 + b2) / 2, (b2 + b0) / 2
        f = np.concatenate([np.stack(t, 1) for t in ((a, m01, m20), (b, m12, m01), (c, m20, m12),
                                                     (m01, m12, m20))])
        fb = np.concatenate([np.stack(t, 1) for t in ((b0, h01, h20), (b1, h12, h01), (b2, h20, h12),
                                                      (h01, h12, h20))])
        ftri = np.tile(ftri, 4)
        nv += len(uniq)
    tri, bary = np.empty(nv, np.int64), np.empty((nv, 3))
    tri[f.ravel()], bary[f.ravel()] = np.repeat(ftri, 3), fb.reshape(-1, 3)
    return f, tri, bary


def glued(rig_v, rig_f, tri, bary, offset):
    """Points at barycentric ``bary`` of rig triangles ``tri``, moved by ``offset`` (metres, scalar or (V,))
    along the interpolated vertex normal."""
    corners = rig_f[tri]
    n = np.einsum("vk,vkc->vc", bary, vertex_normals(rig_v, rig_f)[corners])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    return np.einsum("vk,vkc->vc", bary, rig_v[corners]) + np.reshape(offset, (-1, 1)) * n


def glue(points, rig_v, rig_f, k=12):
    """The dissertation's gluing (ch. 4, Sec. 4.2.3): for each point the closest triangle among those of
    its ``k`` nearest rig vertices, the barycentric coordinates of the projection and the signed offset
    along the face normal.  Returns (tri, bary (N,3), offset (N,))."""
    from scipy.spatial import cKDTree
    cs = _mod(PKG[0], "solver.geometry.surface_distance").closest_points_on_triangles
    incident = [[] for _ in range(len(rig_v))]
    for t, face in enumerate(rig_f):
        for v in face:
            incident[v].append(t)
    width = max(len(x) for x in incident)
    table = np.array([x + [x[0]] * (width - len(x)) for x in incident])
    _, near = cKDTree(rig_v).query(points, k=k)
    cand = table[near].reshape(len(points), -1)                        # (N, k * width)
    rows = np.repeat(np.arange(len(points)), cand.shape[1])
    a, b, c = (rig_v[rig_f[cand.ravel(), i]] for i in range(3))
    q = cs(points[rows], a, b, c)
    d = np.linalg.norm(q - points[rows], axis=1).reshape(len(points), -1)
    tri = cand[np.arange(len(points)), d.argmin(1)]
    a, b, c = (rig_v[rig_f[tri, i]] for i in range(3))
    n = np.cross(b - a, c - a)
    area2 = np.einsum("ij,ij->i", n, n)
    offset = np.einsum("ij,ij->i", points - a, n) / np.sqrt(area2)
    foot = points - offset[:, None] * n / np.sqrt(area2)[:, None]
    w1 = np.einsum("ij,ij->i", np.cross(foot - a, c - a), n) / area2
    w2 = np.einsum("ij,ij->i", np.cross(b - a, foot - a), n) / area2
    return tri, np.stack([1 - w1 - w2, w1, w2], 1), offset


def unglue(rig_v, rig_f, tri, bary, offset):
    """Points rebuilt from posed rig vertices: barycentric point + offset x unit face normal."""
    a, b, c = (rig_v[rig_f[tri, i]] for i in range(3))
    n = np.cross(b - a, c - a)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    return bary[:, :1] * a + bary[:, 1:2] * b + bary[:, 2:] * c + offset[:, None] * n



class _Scene:
    """The MakeHuman rig with frames 1 (pose A), 2 (pose A moved rigidly), 3 (pose B)."""

    def __init__(self, bpy, pkg):
        self.bpy, self.pkg = bpy, pkg
        bpy.ops.wm.read_homefile(use_empty=True)
        self.model = _mod(pkg, "sample_scenes.subjects").make_subject().hybrid_model()
        sk = self.model.skeleton
        p = _mod(pkg, "sample_scenes.poses").rom_poses(sk, 2, seed=3, amplitude=0.6)
        rot = p.rotations[[0, 0, 1]].copy()
        trans = np.zeros((3, 3))
        half = np.radians(35) / 2
        rot[1, 0] = _mod(pkg, "solver.geometry.rotations").quat_mul(
            np.array([np.cos(half), 0, 0, np.sin(half)]), rot[0, 0])
        trans[1] = [0.25, -0.15, 0.05]
        poses = _mod(pkg, "solver.rig.model").Poses(rot, trans, np.ones(3))
        self.rig = _mod(pkg, "addon.rig.builder").build_rig(bpy.context, self.model, "Body")
        _mod(pkg, "addon.rig.actions").write_action(self.rig.armature, sk.names, poses)
        self.io = _mod(pkg, "addon.scene.mesh_io")

    def evaluated(self, ob, frame):
        self.bpy.context.scene.frame_set(frame)
        return self.io.evaluated_positions(ob)

    def scan(self, name, points, faces):
        me = self.io.new_mesh(name, points, faces)
        ob = self.bpy.data.objects.new(name, me)
        self.bpy.context.scene.collection.objects.link(ob)
        return ob

    def bind(self, scan, frame=1):
        self.bpy.context.scene.frame_set(frame)
        t0 = time.perf_counter()
        self.bpy.ops.articula.bind_scan(scan=scan.name, rig=self.rig.armature.name)
        return time.perf_counter() - t0


def _frame_times(bpy, scan, frames=(1, 3) * 5):
    """Best wall time (s) of a frame change (depsgraph update) with the scan shown and hidden."""
    out = []
    for shown in (True, False):
        scan.hide_viewport = not shown
        best = float("inf")
        for f in frames:
            t0 = time.perf_counter()
            bpy.context.scene.frame_set(f)
            bpy.context.view_layer.depsgraph.update()
            best = min(best, time.perf_counter() - t0)
        out.append(best)
    scan.hide_viewport = False
    return out


def _large_scan_lines(sc, lines):
    bpy = sc.bpy
    rig1 = sc.evaluated(sc.rig.mesh, 1)
    faces, tri, bary = subdivide_tracked(sc.model.faces, 2)
    wave = lambda x: 0.003 * (1.5 + np.sin(x[:, 0] * 300) * np.cos(x[:, 2] * 200)) / 2.5   # noqa: E731
    base = glued(rig1, sc.model.faces, tri, bary, 0.0)
    points = glued(rig1, sc.model.faces, tri, bary, wave(base))
    scan = sc.scan("Scan", points, faces)
    seconds = sc.bind(scan)
    size = float(np.linalg.norm(np.ptp(points, axis=0)))
    lines.append(f"scan {len(points):,} vertices / {len(faces):,} triangles on a {len(rig1):,}-vertex rig: "
                 f"bind {seconds:.2f} s")
    with_scan, without = _frame_times(bpy, scan)
    lines.append(f"frame change (depsgraph): {1000 * with_scan:.0f} ms with the scan, {1000 * without:.0f} ms "
                 f"without -> {1000 * (with_scan - without):.0f} ms per frame for the scan")
    err = np.abs(sc.evaluated(scan, 1) - points).max()
    R, t = fit_rigid(rig1, sc.evaluated(sc.rig.mesh, 2))
    rigid = np.abs(sc.evaluated(scan, 2) - (points @ R.T + t)).max()
    lines.append(f"bind pose error {err / size:.2g}, rigid motion error {rigid / size:.2g} of the size "
                 f"({1e3 * err:.4f} / {1e3 * rigid:.4f} mm)")
    rig3 = sc.evaluated(sc.rig.mesh, 3)
    ref = glued(rig3, sc.model.faces, tri, bary, wave(base))
    e = 1e3 * np.linalg.norm(sc.evaluated(scan, 3) - ref, axis=1)
    lines.append(f"second pose, against the glued reference: median {np.median(e):.2f}, 95% "
                 f"{np.percentile(e, 95):.2f}, max {e.max():.1f} mm")
    return scan, points


def _shell_lines(sc, lines, offsets=(-0.01, 0.003, 0.02, 0.05, 0.10)):
    """Offset shells (one subdivision) bound at frame 1 and compared with the glued reference at frame 3."""
    rig1, rig3 = sc.evaluated(sc.rig.mesh, 1), sc.evaluated(sc.rig.mesh, 3)
    faces, tri, bary = subdivide_tracked(sc.model.faces, 1)
    lines.append("offset shell d, error after a second pose against the glued reference, median / 95% / max mm:")
    lines.append("          Surface Deform       | closest-triangle gluing (numpy)")
    for d in offsets:
        points = glued(rig1, sc.model.faces, tri, bary, d)
        scan = sc.scan(f"Shell {d}", points, faces)
        sc.bind(scan)
        ref = glued(rig3, sc.model.faces, tri, bary, d)
        e = 1e3 * np.linalg.norm(sc.evaluated(scan, 3) - ref, axis=1)
        g = 1e3 * np.linalg.norm(unglue(rig3, sc.model.faces, *glue(points, rig1, sc.model.faces)) - ref, axis=1)
        R, t = fit_rigid(rig1, sc.evaluated(sc.rig.mesh, 2))
        rigid = 1e3 * np.abs(sc.evaluated(scan, 2) - (points @ R.T + t)).max()
        lines.append(f"  d = {100 * d:+5.1f} cm: {_stats(e)} | {_stats(g)}; rigid motion max {rigid:.4f} mm")
        sc.bpy.data.objects.remove(scan)


def _stats(e):
    return f"{np.median(e):5.2f} / {np.percentile(e, 95):5.2f} / {e.max():5.1f}"


def _storage_line(sc) -> str:
    """Bytes per scan vertex that the binding adds to a saved .blend."""
    faces, tri, bary = subdivide_tracked(sc.model.faces, 1)
    scan = sc.scan("Stored", glued(sc.evaluated(sc.rig.mesh, 1), sc.model.faces, tri, bary, 0.003), faces)
    sizes = []
    with tempfile.TemporaryDirectory() as tmp:
        for bound in (False, True):
            if bound:
                sc.bind(scan)
            path = os.path.join(tmp, f"{bound}.blend")
            sc.bpy.ops.wm.save_as_mainfile(filepath=path, copy=True, compress=False)
            sizes.append(os.path.getsize(path))
    sc.bpy.data.objects.remove(scan)
    return f"saved binding: {(sizes[1] - sizes[0]) / len(tri):.0f} bytes per scan vertex (.blend uncompressed)"


def _tube_lines(bpy, pkg, lines):
    """The tube body's separate pieces: a rest-pose binding of a 2 mm displaced copy, posed."""
    bpy.ops.wm.read_homefile(use_empty=True)
    model = _mod(pkg, "sample_scenes.synthetic").tube_body()
    poses = _mod(pkg, "solver.rig.pose_sampling").random_poses(1, model.skeleton.num_bones, seed=5,
                                                               max_twist_deg=30, max_swing_deg=30)
    rig = _mod(pkg, "addon.rig.builder").build_rig(bpy.context, model, "Tubes")
    _mod(pkg, "addon.rig.actions").write_action(rig.armature, model.skeleton.names, poses)
    faces, tri, bary = subdivide_tracked(model.faces, 1)
    io = _mod(pkg, "addon.scene.mesh_io")
    scan = bpy.data.objects.new("Tubes scan", io.new_mesh("Tubes scan", glued(
        model.rest_vertices, model.faces, tri, bary, 0.002), faces))
    bpy.context.scene.collection.objects.link(scan)
    bpy.context.scene.frame_set(1)
    bpy.ops.articula.bind_scan(scan=scan.name, rig=rig.armature.name, bind_pose='REST')
    posed = io.evaluated_positions(rig.mesh)
    e = 1e3 * np.linalg.norm(io.evaluated_positions(scan) - glued(posed, model.faces, tri, bary, 0.002), axis=1)
    lines.append(f"tube body (19 separate tubes), rest binding, posed: median {np.median(e):.2f}, 99% "
                 f"{np.percentile(e, 99):.2f}, max {e.max():.1f} mm (vertices near another tube follow it)")


def _picture(sc, scan, points, path):
    """Captured scan (left), the rig in a new pose (middle), the scan driven by it (right)."""
    bpy, io = sc.bpy, sc.io
    rig3 = sc.evaluated(sc.rig.mesh, 3)
    shifted = sc.evaluated(scan, 3)
    exhibits = {}
    for title, v, f, dx in (("scan as captured (214k vertices)", points, scan.data, -1.1),
                            ("fitted rig, new pose", rig3, sc.rig.mesh.data, 0.0),
                            ("scan driven by the rig", shifted, scan.data, 1.1)):
        ob = sc.scan(title, v + [dx, 0, 0], io.read_triangles(f))
        for p in ob.data.polygons:
            p.use_smooth = True
        exhibits[title] = [ob]
    for ob in bpy.data.objects:
        if not any(ob in g for g in exhibits.values()):
            ob.hide_render = True
    _mod(sc.pkg, "addon.scene.render").render_overview(bpy.context.scene, os.path.abspath(path), exhibits)


def scan_binding_lines(picture: str = "") -> list:
    """The measurement lines (see the module docstring); with ``picture``, also render it there (PNG)."""
    bpy, pkg = _addon()
    sc = _Scene(bpy, pkg)
    lines = [f"Blender {bpy.app.version_string}"]
    scan, points = _large_scan_lines(sc, lines)
    if picture:
        _picture(sc, scan, points, picture)
        return lines
    bpy.data.objects.remove(scan)
    _shell_lines(sc, lines)
    lines.append(_storage_line(sc))
    _tube_lines(bpy, pkg, lines)
    return lines


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--picture", default="", help="render the picture to this PNG instead of the shells")
    args = parser.parse_args(argv)
    for line in scan_binding_lines(args.picture):
        print(line, flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
