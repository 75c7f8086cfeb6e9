"""Batch command ``samples``: generate sample data with exact ground truth.

    ./run samples registered --rig cmu_mb --poses 30 --skin hybrid --shape female,heavy --seed 0 --out DIR
    ./run samples subject --rig default --shape male,tall --out model.npz

``samples depth`` and ``samples unregistered`` come from :mod:`samples_cameras`; a new kind of sample data adds
its module's ``add_sample_commands(subparsers)`` to ``KIND_MODULES`` (each parser sets ``func(args) -> int``)
and takes the shared subject and motion options from :mod:`arguments`.
"""
from __future__ import annotations

import time
from pathlib import Path

from . import samples_cameras
from .arguments import add_motion_arguments, add_subject_arguments, motion_options

KIND_MODULES = (samples_cameras,)


def _run_registered(args) -> int:
    from .registered import generate_registered
    t0 = time.perf_counter()
    gt = generate_registered(args.out, args.rig, args.shape, args.poses, args.motion, args.skin, args.format,
                             args.seed, args.subject_seed, args.faces, **motion_options(args))
    n, v = gt["posed_vertices"].shape[:2]
    print(f"samples registered: {n} {args.format.upper()} meshes of {v} vertices, {len(gt['bone_names'])} bones, "
          f"skin {args.skin}, motion {args.motion} -> {args.out} ({time.perf_counter() - t0:.2f} s)")
    return 0


def _run_subject(args) -> int:
    from ..solver.formats.bundle import save_bundle
    from .subjects import make_subject
    subject = make_subject(args.rig, args.shape, args.subject_seed)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    save_bundle(args.out, subject.hybrid_model(), provenance={
        "generator": "articula.sample_scenes.subjects", "rig": args.rig, "macros": subject.macros})
    print(f"samples subject: {args.rig} model, {len(subject.vertices)} vertices, "
          f"{subject.skeleton.num_bones} bones -> {args.out}")
    return 0


def _add_builtin(sub) -> None:
    p = sub.add_parser("registered", help="registered mesh sequence (OBJ/PLY per pose) + ground_truth.npz")
    add_subject_arguments(p)
    add_motion_arguments(p)
    p.add_argument("--format", default="obj", choices=("obj", "ply"), help="mesh file format")
    p.add_argument("--faces", default="quads", choices=("quads", "triangles"), help="faces in the files")
    p.add_argument("--out", required=True, help="output folder")
    p.set_defaults(func=_run_registered)
    p = sub.add_parser("subject", help="a subject's hybrid-skin model bundle (articula-model/1)")
    add_subject_arguments(p)
    p.add_argument("--out", required=True, help="output .npz")
    p.set_defaults(func=_run_subject)


def add_commands(subparsers) -> None:
    """Register ``samples`` and its subcommands (built-in ones, then the extension modules)."""
    p = subparsers.add_parser("samples", help="generate sample data with ground truth (samples -h)")
    sub = p.add_subparsers(dest="samples_kind", metavar="<kind>")
    p.set_defaults(func=lambda args: (p.print_help(), 2)[1])
    _add_builtin(sub)
    for module in KIND_MODULES:
        module.add_sample_commands(sub)
