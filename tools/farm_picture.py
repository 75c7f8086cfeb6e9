"""The picture of docs/farm.md: one frame of several tracked bundles side by side (posed meshes from the
solver's hybrid skin), optionally with the capture of that frame, e.g. a chunk that started on another
solution, the same chunk repaired by the farm, and the one-process run.

    ~/.cache/articula/venv-bpy52/bin/python tools/farm_picture.py docs/images/farm_repair.png --frame 12 \\
        --scan /tmp/uscans/scan_0012.ply "chunk 1 alone=WORK/chunk_0001_0006-0024.npz" "farm=farm.npz" "one=one.npz"

Each bundle's pose is the one of input frame ``--frame`` (its provenance's ``first_frame`` is taken off).
"""
import argparse
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "bench"))
import _common  # noqa: E402,F401  (makes ``import articula`` work)

import bpy  # noqa: E402
import numpy as np  # noqa: E402


def _pkg():
    return _common.addon_modules(bpy)


def posed_mesh(path, frame, name):
    """A mesh object of the bundle at ``path`` posed at input frame ``frame``."""
    from articula.solver.formats.bundle import load_bundle
    from articula.solver.rig.skinning import hybrid_skin
    b = load_bundle(path)
    k = frame - int((b.provenance or {}).get("first_frame", 0))
    if not 0 <= k < len(b.poses):
        raise SystemExit(f"{path}: input frame {frame} is not among its poses")
    verts = hybrid_skin(b.model, b.poses.take(k))[0]
    me = bpy.data.meshes.new(name)
    me.from_pydata(verts.tolist(), [], np.asarray(b.model.faces).tolist())
    ob = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(ob)
    return ob


def scan_mesh(path, name):
    """The capture file at ``path`` as written (PLY/OBJ/STL/OFF through the solver's readers)."""
    from articula.solver.formats.mesh_files import read_mesh
    mesh = read_mesh(path)
    faces = np.split(mesh.corner_verts, np.cumsum(mesh.face_sizes)[:-1])
    me = bpy.data.meshes.new(name)
    me.from_pydata(mesh.vertices.tolist(), [], [f.tolist() for f in faces])
    ob = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(ob)
    return ob


def main(argv=None):
    p = argparse.ArgumentParser()
    p.add_argument("out")
    p.add_argument("bundles", nargs="+", metavar="LABEL=BUNDLE.npz")
    p.add_argument("--frame", type=int, required=True, help="input frame (0-based)")
    p.add_argument("--scan", help="the capture of that frame, shown first")
    p.add_argument("--spacing", type=float, default=1.2)
    args = p.parse_args(argv)
    pkg = _pkg()
    bpy.ops.wm.read_homefile(use_empty=True)
    exhibits = {}
    if args.scan:
        exhibits[f"capture, frame {args.frame}"] = [scan_mesh(args.scan, "capture")]
    for item in args.bundles:
        label, path = item.split("=", 1)
        exhibits[label] = [posed_mesh(path, args.frame, label)]
    for i, (ob,) in enumerate(exhibits.values()):
        ob.location.x += args.spacing * i
    pkg("addon.scene.render").render_overview(bpy.context.scene, os.path.abspath(args.out), exhibits,
                                              width=1400, height=560)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main(sys.argv[1:])
