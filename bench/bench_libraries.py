"""Articula's mesh readers, surface distance and mesh graph next to trimesh's: time, agreement.

The bundled-library question, measured: Articula's own mesh readers, exact surface distance and mesh
graph next to trimesh's (``trimesh.load``, ``trimesh.proximity.closest_point``, ``trimesh.graph`` /
``Trimesh.edges_unique`` / ``trimesh.smoothing.laplacian_calculation``).  docs/libraries.md holds the
numbers and the decision for each piece.

1. loading: a 13,380-vertex MakeHuman sequence frame (quads) as OBJ and binary PLY, and 400 OBJ frames of
   754 vertices (Dem Bones' Bone_Anim from ``../shared/data/dem_bones``; a 28 x 28 quad grid when absent):
   best wall time, same vertices, polygons kept, same triangles in the same order;
2. malformed files: the message each side gives (or what trimesh loads without complaint);
3. surface distance: 13,380 noisy scan points vs the posed model, another pose vs the model, and 20
   Bone_Anim-sized frames: CPU seconds, largest difference, points that differ, brute force at the worst;
4. graph queries: edges, adjacency, uniform Laplacian, components: CPU seconds and identical arrays;
5. k-d tree shape (scipy's ``cKDTree``): the MakeHuman rest vertices reflected through the three planes
   through their centroid along the principal axes (the symmetry search's queries, mostly off the surface)
   against the tree built by ``solver.geometry.neighbours.far_query_tree`` and scipy's default tree:
   CPU seconds of the queries and identical distances.

``trimesh.proximity.closest_point`` needs the ``rtree`` package, which neither the venvs nor the zip carry:
install it anywhere (``python -m pip install --target /tmp/rtree rtree``) and pass ``--rtree /tmp/rtree``;
without it part 3 reports ours only.

Usage: ./run bench libraries [--rtree DIR] [--repeats 5] [--only loading|errors|distance|graph|trees]
"""
import argparse
import os
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))   # bench_cli loads us by path
import _common  # noqa: E402  (makes ``import articula`` work)

import numpy as np  # noqa: E402

DEM = os.path.join(os.path.dirname(os.path.realpath(_common.REPO)), "shared", "data", "dem_bones")


def _makehuman():
    """(posed vertices (3, 13380, 3), triangles (26756, 3), quads (13378, 4)) of a 3-pose sample sequence."""
    from articula.sample_scenes.registered import posed_sequence
    posed, _, gt = posed_sequence("cmu_mb", None, 3, "rom", "lbs", 0, None)
    return np.asarray(posed, np.float64), gt["faces"], gt["quads"]


def _small_frames():
    """(frames (400, V, 3), quads (F, 4), name): Dem Bones' Bone_Anim, or a wavy 28 x 28 grid."""
    from articula.solver.formats.obj import read_obj
    anim = os.path.join(DEM, "Bone_Anim_positions_400x754x3.npy")
    if os.path.isfile(anim):
        rest = read_obj(os.path.join(DEM, "Bone_Geom_rest.obj"))
        return np.load(anim).astype(np.float64), rest.corner_verts.reshape(-1, 4), "Bone_Anim"
    from bench_import import _grid
    verts, quads = _grid(28)
    wave = np.sin(np.linspace(0, 6.0, 400))[:, None, None] * np.array([0, 0, 0.05])
    return verts[None] + wave * verts[None, :, :1], quads, "28x28 grid"


def _load_pair(path):
    import trimesh
    from articula.solver.formats.mesh_files import read_mesh
    return read_mesh(path), trimesh.load(path, process=False)


def _exactness(label, ours, theirs):
    same_v = np.array_equal(ours.vertices, np.asarray(theirs.vertices))
    tri = ours.triangles()
    same_order = np.array_equal(tri, np.asarray(theirs.faces))
    same_set = same_order or {tuple(sorted(t)) for t in tri.tolist()} == \
        {tuple(sorted(t)) for t in np.asarray(theirs.faces).tolist()}
    sizes = np.unique(ours.face_sizes).tolist()
    _common.report(f"{label} exactness", f"vertices identical {same_v}; ours keeps faces of {sizes} corners "
                   f"({len(ours.face_sizes)} faces), trimesh {len(theirs.faces)} triangles; same triangles "
                   f"{same_set}, same order as our fan {same_order}")


def _loading(repeats):
    import trimesh
    from articula.sample_scenes.mesh_files import SequenceWriter
    from articula.solver.formats.mesh_files import read_mesh
    posed, _, quads = _makehuman()
    frames, small_quads, name = _small_frames()
    with tempfile.TemporaryDirectory(prefix="bench-libraries-") as tmp:
        for fmt in ("obj", "ply"):
            path = os.path.join(tmp, f"mh.{fmt}")
            SequenceWriter(quads, fmt).write(path, posed[0])
            t_ours, _ = _common.best_time(lambda: read_mesh(path), repeats)
            t_tm, _ = _common.best_time(lambda: trimesh.load(path, process=False), repeats)
            _common.report(f"load 13380-vertex {fmt.upper()}", f"ours {1e3 * t_ours:.1f} ms, trimesh "
                           f"{1e3 * t_tm:.1f} ms", note="best wall time")
            _exactness(f"  {fmt.upper()}", *_load_pair(path))
        writer = SequenceWriter(small_quads, "obj")
        paths = [os.path.join(tmp, f"f{i:04d}.obj") for i in range(len(frames))]
        for p, v in zip(paths, frames):
            writer.write(p, v)
        t_ours, _ = _common.best_time(lambda: [read_mesh(p) for p in paths], max(1, repeats // 2))
        t_tm, _ = _common.best_time(lambda: [trimesh.load(p, process=False) for p in paths], max(1, repeats // 2))
        _common.report(f"load {len(paths)} OBJs of {frames.shape[1]} vertices ({name})",
                       f"ours {t_ours:.3f} s, trimesh {t_tm:.3f} s", note="best wall time")
        _exactness("  small OBJ", *_load_pair(paths[0]))


MALFORMED = [   # (file name, content): what a scan folder can hold by mistake
    ("truncated.ply", b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\n"
                      b"property float y\nproperty float z\nelement face 1\nproperty list uchar int "
                      b"vertex_indices\nend_header\n" + b"\0" * 20),
    ("truncated.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2"),
    ("nan.obj", b"v 0 0 0\nv 1 nan 0\nv 0 1 0\nf 1 2 3\n"),
    ("out_of_range.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n"),
    ("out_of_range.off", b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n"),
    ("bad_number.obj", b"v 0 0 0\nv 1 0 0\nv zero 1 0\nf 1 2 3\n"),
    ("garbage.obj", b"\0\1\2garbage" * 10),
    ("garbage.ply", b"garbage" * 10),
    ("garbage.stl", b"\x01" * 300),
    ("empty.obj", b"# nothing\n"),
]


def _message(fn):
    try:
        out = fn()
    except Exception as exc:   # noqa: BLE001 - we report whatever each side raises
        return f"{type(exc).__name__}: {str(exc)[:110]}"
    faces = getattr(out, "faces", getattr(out, "face_sizes", ()))
    return f"LOADED {len(getattr(out, 'vertices', ()))} vertices, {len(faces)} faces"


def _errors():
    import trimesh
    from articula.solver.formats.mesh_files import read_mesh
    with tempfile.TemporaryDirectory(prefix="bench-libraries-") as tmp:
        for name, content in MALFORMED:
            path = os.path.join(tmp, name)
            with open(path, "wb") as fh:
                fh.write(content)
            _common.report(f"malformed {name}", "")
            print(f"    ours:    {_message(lambda: read_mesh(path)).replace(tmp + os.sep, '')}")
            print(f"    trimesh: {_message(lambda: trimesh.load(path, process=False)).replace(tmp + os.sep, '')}")


def _brute_force(point, vertices, faces):
    """Distance of one point to every triangle (the Voronoi-region kernel), minimum."""
    from articula.solver.geometry.surface_distance import closest_points_on_triangles
    tri = vertices[faces]
    q = closest_points_on_triangles(np.repeat(point[None], len(faces), 0), tri[:, 0], tri[:, 1], tri[:, 2])
    return float(np.linalg.norm(q - point, axis=1).min())


def _distance_case(label, points, vertices, faces, repeats, with_trimesh):
    import trimesh
    from articula.solver.geometry.surface_distance import distance_to_surface
    t_ours, ours = _common.best_time(lambda: distance_to_surface(points, vertices, faces), repeats, time.process_time)
    if not with_trimesh:
        _common.report(label, f"ours {t_ours:.3f} s", note="CPU time; trimesh needs rtree (--rtree DIR)")
        return

    def theirs_fn():
        return trimesh.proximity.closest_point(trimesh.Trimesh(vertices, faces, process=False), points)[1]
    t_tm, theirs = _common.best_time(theirs_fn, repeats, time.process_time)
    diff = np.abs(ours - theirs)
    worst = int(np.argmax(diff))
    brute = _brute_force(points[worst], vertices, faces)
    _common.report(label, f"ours {t_ours:.3f} s, trimesh {t_tm:.3f} s; max |difference| {diff.max():.3g} m, "
                   f"{int((diff > 1e-9).sum())} of {len(points)} points differ by > 1e-9 m; worst point: ours "
                   f"{ours[worst]:.9g}, trimesh {theirs[worst]:.9g}, brute force {brute:.9g}", note="CPU time")


def _distances(repeats, rtree_dir):
    if rtree_dir:
        sys.path.insert(0, rtree_dir)
    try:
        import rtree  # noqa: F401
        with_trimesh = True
    except ImportError:
        with_trimesh = False
    posed, faces, _ = _makehuman()
    rng = np.random.default_rng(0)
    noisy = posed[1] + rng.normal(scale=0.005, size=posed[1].shape)
    _distance_case("distance 13380 scan points (5 mm noise) to the posed model", noisy, posed[1], faces,
                   repeats, with_trimesh)
    _distance_case("distance 13380 vertices of another pose to the model", posed[1], posed[0], faces,
                   repeats, with_trimesh)
    frames, quads, name = _small_frames()
    tris = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    noise = 0.01 * np.ptp(frames[0], axis=0).max()
    pairs = [(frames[m] + rng.normal(scale=noise, size=frames[m].shape), frames[m]) for m in range(20)]
    _distance_case(f"distance {name} frame 0 (noise 1% of its size)", *pairs[0], tris, repeats, with_trimesh)
    _frames_case(f"distance 20 {name} frames, one call per frame", pairs, tris, with_trimesh)


def _frames_case(label, pairs, faces, with_trimesh):
    import trimesh
    from articula.solver.geometry.surface_distance import distance_to_surface
    sides = {"ours": lambda p, v: distance_to_surface(p, v, faces)}
    if with_trimesh:
        sides["trimesh"] = lambda p, v: trimesh.proximity.closest_point(
            trimesh.Trimesh(v, faces, process=False), p)
    seconds = {}
    for side, fn in sides.items():
        t0 = time.process_time()
        for p, v in pairs:
            fn(p, v)
        seconds[side] = time.process_time() - t0
    _common.report(label, ", ".join(f"{k} {v:.3f} s" for k, v in seconds.items()), note="CPU time")


def _same(a, b):
    """Identical arrays (sparse matrices: identical CSR arrays)."""
    if hasattr(a, "indptr"):
        return all(np.array_equal(getattr(a, k), getattr(b, k)) for k in ("indptr", "indices", "data"))
    return np.array_equal(a, b)


def _graph(repeats):
    import scipy.sparse as sp
    import trimesh
    import trimesh.smoothing
    from articula.solver.geometry import mesh_graph
    posed, faces, _ = _makehuman()
    nv = posed.shape[1]

    def mesh():
        return trimesh.Trimesh(posed[0], faces, process=False)

    def tm_adjacency():
        e = mesh().edges_unique
        return sp.coo_matrix((np.ones(2 * len(e)), (np.r_[e[:, 0], e[:, 1]], np.r_[e[:, 1], e[:, 0]])),
                             shape=(nv, nv)).tocsr()

    cases = [
        ("edges (lexicographic)", lambda: mesh_graph.edges_of(faces), lambda: mesh().edges_unique),
        ("adjacency", lambda: mesh_graph.adjacency(faces, nv), tm_adjacency),
        ("uniform Laplacian", lambda: mesh_graph.uniform_laplacian(faces, nv),
         lambda: (sp.identity(nv, format="csr")
                  - trimesh.smoothing.laplacian_calculation(mesh(), equal_weight=True)).tocsr()),
        ("component labels", lambda: mesh_graph.components(faces, nv)[1],
         lambda: trimesh.graph.connected_component_labels(mesh().edges_unique, node_count=nv)),
    ]
    for label, ours_fn, tm_fn in cases:
        t_ours, ours = _common.best_time(ours_fn, repeats, time.process_time)
        t_tm, theirs = _common.best_time(tm_fn, repeats, time.process_time)
        _common.report(f"graph {label}", f"ours {1e3 * t_ours:.1f} ms, trimesh {1e3 * t_tm:.1f} ms "
                       f"(Trimesh construction included); identical arrays {_same(ours, theirs)}",
                       note="13380 vertices, CPU time")


def _trees(repeats):
    """Part 5: reflected-point queries against the two k-d tree shapes (module docstring)."""
    from scipy.spatial import cKDTree
    from articula.solver.geometry.neighbours import far_query_tree
    pts = _makehuman()[0][0]
    c = pts.mean(axis=0)
    _, axes = np.linalg.eigh(np.cov((pts - c).T))
    queries = np.concatenate([pts - 2.0 * np.outer((pts - c) @ n, n) for n in axes.T])
    t_default, (d_default, _) = _common.best_time(lambda: cKDTree(pts).query(queries), repeats, time.process_time)
    t_far, (d_far, _) = _common.best_time(lambda: far_query_tree(pts).query(queries), repeats, time.process_time)
    _common.report("k-d tree, reflected points: far_query_tree", t_far, "s",
                   f"scipy's default tree {t_default:.3f} s ({t_default / t_far:.2f}x); distances identical "
                   f"{bool(np.array_equal(d_far, d_default))}; {len(pts)} points, {len(queries)} queries, CPU time, "
                   f"tree build included")


def main(argv) -> int:
    parser = argparse.ArgumentParser(prog="./run bench libraries", description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=5, help="best of this many runs (default 5)")
    parser.add_argument("--rtree", default="", help="folder holding the rtree package (for trimesh's "
                                                    "closest_point)")
    parser.add_argument("--only", choices=("loading", "errors", "distance", "graph", "trees"), help="one part only")
    args = parser.parse_args(argv)
    parts = {"loading": lambda: _loading(args.repeats), "errors": _errors,
             "distance": lambda: _distances(max(1, args.repeats // 2), args.rtree),
             "graph": lambda: _graph(args.repeats), "trees": lambda: _trees(args.repeats)}
    for name, run in parts.items():
        if args.only in (None, name):
            run()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
