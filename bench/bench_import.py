"""Importing scan sequences (articula.import_scans), and the per-frame playback cost.

* the Dem Bones Alembic fixture (400 frames x 754 vertices; ../shared/data, skipped when absent);
* a folder of 400 OBJ files of the same size (written by sample_scenes.mesh_files.SequenceWriter):
  parsing alone (solver) and the whole operator;
* playback: one frame change (``scene.frame_set`` + depsgraph evaluation) of a registered sequence (positions written from the
  memory-mapped cache) and of an unregistered one (geometry rebuilt from the cache), at 754 and 50,000
  vertices, next to the alternative "one mesh datablock per frame, swapped into the object".

Usage: ./run bench import   or   ~/.cache/articula/venv-bpy52/bin/python bench/bench_import.py [--frames 400]
"""
import argparse
import os
import shutil
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))   # bench_cli loads us by path
import _common  # noqa: E402  (makes ``import articula`` work)

import numpy as np  # noqa: E402

DEM = os.path.join(os.path.dirname(os.path.realpath(_common.REPO)), "shared", "data", "dem_bones")


def _addon():
    import bpy
    if not hasattr(bpy.types, "ARTICULA_OT_import_scans"):   # run directly, not through ./run
        sys.path.insert(0, _common.REPO)
        import batch
        batch.enable_addon(bpy)
    return bpy


def _grid(n_side):
    """A wavy (n_side x n_side) quad grid: vertices (V, 3), faces (F, 4)."""
    u, v = np.meshgrid(np.linspace(0, 1, n_side), np.linspace(0, 1, n_side), indexing="ij")
    verts = np.stack([u, v, 0.1 * np.sin(6 * u) * np.cos(4 * v)], -1).reshape(-1, 3)
    i = np.arange(n_side - 1)[:, None] * n_side + np.arange(n_side - 1)[None, :]
    faces = np.stack([i, i + n_side, i + n_side + 1, i + 1], -1).reshape(-1, 4)
    return verts, faces


def _timed(fn):
    t0 = time.perf_counter()
    out = fn()
    return time.perf_counter() - t0, out


def _frame_cost(bpy, ob, frames, repeats=3):
    scene = bpy.context.scene
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        for f in frames:
            scene.frame_set(f)
            bpy.context.evaluated_depsgraph_get()   # include the evaluation of the new data
        best = min(best, (time.perf_counter() - t0) / len(frames))
    return best


def main(argv=()) -> int:
    ap = argparse.ArgumentParser(prog="bench import")
    ap.add_argument("--frames", type=int, default=400)
    args = ap.parse_args(list(argv))
    bpy = _addon()
    from articula.sample_scenes.mesh_files import SequenceWriter
    from articula.solver.formats.scan_files import list_scan_files, read_scan_files
    tmp = tempfile.mkdtemp(prefix="articula_bench_import_")
    os.environ.setdefault("ARTICULA_HOME", tmp)
    try:
        bpy.ops.wm.read_homefile(use_empty=True)
        abc = os.path.join(DEM, "Bone_Anim.abc")
        if os.path.isfile(abc):
            t, _ = _timed(lambda: bpy.ops.articula.import_scans(filepath=abc))
            ob = bpy.context.active_object
            _common.report("alembic import (400 x 754, Dem Bones)", t, "s",
                           f"{ob.articula.frame_count} frames, target < 10 s")
        else:
            _common.report("alembic import", "skipped", note=f"{DEM} absent")

        # 400 OBJ files of 754 vertices: the Dem Bones frames on their own faces, else a wavy grid
        rest = os.path.join(DEM, "Bone_Geom_rest.obj")
        npy = os.path.join(DEM, "Bone_Anim_positions_400x754x3.npy")
        if os.path.isfile(rest) and os.path.isfile(npy):
            from articula.solver.formats.obj import read_obj
            base = read_obj(rest)
            faces = base.corner_verts.reshape(-1, 3) if (base.face_sizes == 3).all() else base.triangles()
            frames = np.load(npy)[:args.frames]
        else:
            verts, faces = _grid(28)   # 784 vertices
            rng = np.random.default_rng(0)
            frames = verts[None] + 0.01 * rng.normal(size=(args.frames, len(verts), 3))
        folder = os.path.join(tmp, "objs")
        os.makedirs(folder)
        writer = SequenceWriter(faces, "obj")
        t_write, _ = _timed(lambda: [writer.write(os.path.join(folder, f"scan{k + 1}.obj"), f)
                                     for k, f in enumerate(frames)])
        files = list_scan_files(folder)
        t_parse, seq = _timed(lambda: read_scan_files(files))
        _common.report(f"OBJ parse ({len(files)} files x {frames.shape[1]} v)", t_parse, "s",
                       f"{1000 * t_parse / len(files):.2f} ms/file; writing them took {t_write:.2f} s")
        bpy.ops.wm.read_homefile(use_empty=True)
        t, _ = _timed(lambda: bpy.ops.articula.import_scans(directory=folder))
        ob = bpy.context.active_object
        _common.report(f"OBJ folder import ({len(files)} files)", t, "s",
                       f"registered={ob.articula.registered}, target < 10 s")
        n = ob.articula.frame_count
        _common.report("frame change, registered, 754 v", 1000 * _frame_cost(bpy, ob, range(1, n + 1, 7)), "ms")

        # playback at scan size: registered vs unregistered (rebuild) vs one mesh per frame (swap)
        verts, faces = _grid(224)   # 50,176 vertices
        rng = np.random.default_rng(1)
        big = os.path.join(tmp, "big")
        os.makedirs(big)
        w = SequenceWriter(faces, "ply")
        for k in range(8):
            w.write(os.path.join(big, f"f{k}.ply"), verts + 0.01 * rng.normal(size=verts.shape))
        bpy.ops.wm.read_homefile(use_empty=True)
        bpy.ops.articula.import_scans(directory=big, name="big")
        ob = bpy.context.active_object
        _common.report(f"frame change, registered, {len(verts)} v", 1000 * _frame_cost(bpy, ob, range(1, 9)), "ms")
        # same frames, but marked unregistered -> every frame change rebuilds the geometry
        os.replace(os.path.join(big, "f7.ply"), os.path.join(tmp, "f7.ply"))
        SequenceWriter(faces[:-1], "ply").write(os.path.join(big, "f7.ply"), verts)
        bpy.ops.wm.read_homefile(use_empty=True)
        bpy.ops.articula.import_scans(directory=big, name="bigraw")
        ob = bpy.context.active_object
        assert not ob.articula.registered
        _common.report(f"frame change, unregistered (rebuild), {len(verts)} v",
                       1000 * _frame_cost(bpy, ob, range(1, 9)), "ms")
        # the alternative: meshes prepared per frame, swapped into the object by a handler
        from articula.addon.sequences import scans as scan_sequence
        meshes = []
        for k, m in enumerate(scan_sequence.scan_frame_meshes(ob)):
            me = bpy.data.meshes.new(f"swap{k}")
            scan_sequence.set_geometry(me, m.vertices, m.face_sizes, m.corner_verts)
            meshes.append(me)
        swap_ob = bpy.data.objects.new("swap", meshes[0])
        bpy.context.scene.collection.objects.link(swap_ob)
        ob.articula.kind = 'NONE'   # only the swap handler runs now

        def swap(scene, depsgraph=None):
            swap_ob.data = meshes[min(max(scene.frame_current - 1, 0), len(meshes) - 1)]
        bpy.app.handlers.frame_change_post.append(swap)
        try:
            _common.report(f"frame change, one mesh per frame (swap), {len(verts)} v",
                           1000 * _frame_cost(bpy, swap_ob, range(1, 9)), "ms",
                           "needs every frame as a datablock in the .blend")
        finally:
            bpy.app.handlers.frame_change_post.remove(swap)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
