"""Batch command ``samples``: generate sample data with exact ground truth.

    ./run samples registered --rig cmu_mb --poses 30 --skin hybrid --shape female,heavy --seed 0 --out DIR
    ./run samples subject --rig default --shape male,tall --out model.npz

Extension point: every module ``sample_scenes/samples_<kind>.py`` that defines
``add_sample_commands(subparsers)`` is found automatically and may add its own ``samples <kind>``
subcommands (each parser sets ``func(args) -> int``), e.g. ``samples depth`` and ``samples unregistered``;
no edit of this file is needed.  :func:`add_subject_arguments` and :func:`add_motion_arguments` give
those commands the same ``--rig/--shape/--subject-seed`` and ``--poses/--motion/--skin/--seed/...``
options, and :func:`sequence_from_args` turns them into ``registered.posed_sequence(...)``.
"""
from __future__ import annotations

import importlib
import pkgutil
import time
from pathlib import Path

from .mpfb_rig import RIGS
from .registered import MOTIONS, SKINS

EXTENSION_PREFIX = "samples_"


def add_subject_arguments(p) -> None:
    """``--rig``, ``--shape``, ``--subject-seed``."""
    p.add_argument("--rig", default="cmu_mb", choices=RIGS, help="MPFB2 rig (default cmu_mb)")
    p.add_argument("--shape", default="", help="presets and macros, e.g. female,heavy,age=0.7 "
                   "(presets: female male heavy thin tall short young old muscular weak average)")
    p.add_argument("--subject-seed", type=int, default=None,
                   help="draw the macros not given in --shape at random (default: MakeHuman defaults)")


def add_motion_arguments(p) -> None:
    """``--poses``, ``--motion``, ``--skin``, ``--seed`` and the motion options."""
    p.add_argument("--poses", type=int, default=30, help="number of poses/frames (default 30)")
    p.add_argument("--motion", default="rom", choices=MOTIONS, help="rom: random range of motion; walk")
    p.add_argument("--skin", default="lbs", choices=SKINS, help="skinning used to pose the mesh")
    p.add_argument("--seed", type=int, default=0, help="random seed of the motion (default 0)")
    p.add_argument("--amplitude", type=float, default=1.0, help="rom: scale of the joint limits (0, 1]")
    p.add_argument("--key-every", type=int, default=1, help="rom: key poses every K frames, interpolated")
    p.add_argument("--step", type=float, default=1.0, help="walk: cycle frames per pose (40-frame cycle)")
    p.add_argument("--root-yaw", type=float, default=0.0, help="random root yaw up to this many degrees")
    p.add_argument("--root-shift", type=float, default=0.0, help="random root shift up to this many metres")


def motion_options(args) -> dict:
    """Pose-generator options from parsed arguments."""
    opts = dict(root_yaw=args.root_yaw, root_shift=args.root_shift)
    if args.motion == "rom":
        opts.update(amplitude=args.amplitude, key_every=args.key_every)
    else:
        opts.update(step=args.step)
    return opts


def sequence_from_args(args):
    """``registered.posed_sequence`` for the subject and motion arguments: (vertices, faces, gt)."""
    from .registered import posed_sequence
    return posed_sequence(args.rig, args.shape, args.poses, args.motion, args.skin, args.seed,
                          args.subject_seed, **motion_options(args))


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


def extension_modules() -> list:
    """Names of the ``samples_<kind>`` modules of this package (sorted)."""
    here = Path(__file__).parent
    return sorted(m.name for m in pkgutil.iter_modules([str(here)]) if m.name.startswith(EXTENSION_PREFIX))


def add_commands(subparsers) -> None:
    """Register ``samples`` and its subcommands (built-in ones, then the extension modules)."""
    p = subparsers.add_parser("samples", help="generate sample data with ground truth (samples -h)")
    sub = p.add_subparsers(dest="samples_kind", metavar="<kind>")
    p.set_defaults(func=lambda args: (p.print_help(), 2)[1])
    _add_builtin(sub)
    for name in extension_modules():
        module = importlib.import_module(f".{name}", __package__)
        if hasattr(module, "add_sample_commands"):
            module.add_sample_commands(sub)
