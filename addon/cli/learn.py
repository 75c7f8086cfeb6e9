"""Batch command ``learn-rig``: registered scans -> learned model bundle (+ report JSON, + .blend).

    ./run learn-rig --scans scans/ --out model.npz --report report.json
    ./run learn-rig --scans s1.obj s2.obj s3.obj --parts 8 --alpha 100 --no-symmetry --iterations 20 \\
        --seed 0 --out model.npz --blend learned.blend
    blender -b -P batch.py -- learn-rig --scans scans/ --out model.npz

The scans are read with the solver's readers, coordinates as written (no axis conversion) and vertex
order kept; the bundle holds one pose per scan in scan order (natural file order), in the files'
coordinates.  ``--forward``/``--up`` (as for ``import-scans``) only place the scans and the rig in the
.blend (their object matrix).  ``--report`` writes the solver's report as JSON (see
:func:`report_document`).  ``--blend`` saves a scene with the scans as a scan-sequence object (frames
1..N) and the learned rig with its poses on the same frames, added to the file when it exists (a
``.blend1`` keeps its previous version), else in an empty scene.
"""
import os

import bpy
import numpy as np

from ...solver.errors import ArticulaInputError
from ...solver.learn.options import LearnOptions, name_setting
from .. import jobs
from ..learn import inputs, result, solve
from ..learn.report import error_summary, jsonable, report_json, summary_text
from .common import call_operator, check_blend_output, editing, save_blend, write_json
from .scans import add_axis_arguments, axis_props

# LearnOptions field -> the flag that sets it (error messages name the flag the user typed)
FLAGS = {"parts": "--parts", "alpha": "--alpha", "joint_prior": "--joint-prior", "max_iterations": "--iterations",
         "seed": "--seed", "key_scans": "--key-scans", "workers": "--threads", "memory_limit_gb": "--memory-limit",
         "key_scan_budget": "--key-scan-budget"}


def report_document(outcome) -> dict:
    """The report JSON: the solver's report (error statistics in mm, time of each stage, objective log
    as the solver names them), plus ``error_mm`` {mean, std, median, mad, iqr, max} of the
    vertex-to-surface distance over all scans, ``vertex_error_mm`` {mean, median, max} of the heat map
    (per-vertex mean over the scans), ``input`` and ``options``."""
    doc = report_json(outcome)
    doc["error_mm"] = jsonable(error_summary(outcome.report))
    v = outcome.vertex_error_mm
    doc["vertex_error_mm"] = {"mean": float(np.mean(v)), "median": float(np.median(v)), "max": float(np.max(v))}
    return doc


def _scan_paths(items) -> list:
    items = [os.path.abspath(p) for p in items]
    if len(items) == 1 and os.path.isdir(items[0]):
        return inputs.scan_paths(items[0])
    folders = {os.path.dirname(p) for p in items}
    if len(folders) > 1:
        raise ArticulaInputError("give scan files from one folder (or the folder itself)")
    for p in items:
        if not os.path.isfile(p):
            raise ArticulaInputError(f"{p}: file or folder not found")
    return inputs.scan_paths(folders.pop(), [os.path.basename(p) for p in items])


def _save_blend(blend: str, paths, outcome, axes: dict) -> None:
    """Save a .blend with the scans (scan-sequence object, frames 1..N, cache beside the file) and the
    learned rig: added to ``blend`` when it exists (a ``.blend1`` keeps its previous version), else in an
    empty scene; nothing is saved if a step fails."""
    with editing(blend):
        call_operator(bpy.ops.articula.import_scans, directory=os.path.dirname(paths[0]),
                      files=[{"name": os.path.basename(p)} for p in paths],
                      require_registered=True, frame_start=1, **axes)
        outcome.input.frame_start = 1
        with jobs.scene_guard():
            result.build(bpy.context, outcome, f"{outcome.input.name} Rig")
        save_blend(blend)


def _learn(args):
    """Read the scans and learn: ``(scan paths, solve.learn's outcome)``."""
    options = LearnOptions(parts=args.parts, alpha=args.alpha, symmetry=not args.no_symmetry,
                           max_iterations=args.iterations, seed=args.seed, key_scans=args.key_scans,
                           workers=args.threads, joint_prior=args.joint_prior, memory_limit_gb=args.memory_limit,
                           key_scan_budget=args.key_scan_budget, name_roles=not args.no_role_names)
    options.validate()
    paths = _scan_paths(args.scans)
    matrix = inputs.files_matrix(paths, (args.forward, args.up))
    progress = jobs.Progress("learn-rig", echo=True)
    inp = inputs.input_from_files(paths, progress, matrix, options)
    return paths, solve.learn(inp, options, progress)


def run(args) -> int:
    for path in (args.out, args.report, args.blend):
        result.check_output_path(path or "")
    check_blend_output(args.blend)
    try:
        paths, outcome = _learn(args)
    except ArticulaInputError as exc:
        raise ArticulaInputError(name_setting(str(exc), FLAGS)) from None
    result.save(args.out, outcome)
    print(f"wrote {args.out}: {outcome.model.num_vertices} vertices, {outcome.model.skeleton.num_bones} bones, "
          f"{len(outcome.poses)} poses; {summary_text(outcome)}")
    if args.report:
        write_json(args.report, report_document(outcome))
        print(f"wrote {args.report}")
    if args.blend:
        _save_blend(os.path.abspath(args.blend), paths, outcome, axis_props(args))
        print(f"saved {args.blend}: the scans and the learned rig on frames 1..{len(paths)}")
    return 0


def add_commands(sub):
    default = LearnOptions()
    p = sub.add_parser("learn-rig", help="learn a rig (armature, swing/twist skin, rest mesh) from registered scans")
    p.add_argument("--scans", nargs="+", required=True, metavar="PATH",
                   help="a folder of registered OBJ/PLY/STL/OFF scans, or such files (natural order)")
    p.add_argument("--parts", type=int, default=default.parts,
                   help=f"number of body parts (default {default.parts}: chosen from the motion)")
    p.add_argument("--alpha", type=float, default=default.alpha,
                   help=f"weight of the local-shape (Laplacian) term, dimensionless (default {default.alpha:g})")
    p.add_argument("--joint-prior", type=float, default=default.joint_prior,
                   help=f"weight of the prior that keeps joints near their first estimates where the motion "
                        f"hardly determines them, relative to the data's pull on each joint (default "
                        f"{default.joint_prior}; 0: none, which with a small --alpha fits the scans most closely)")
    p.add_argument("--no-symmetry", action="store_true", help="do not pair and symmetrise left/right parts")
    p.add_argument("--no-role-names", action="store_true",
                   help="keep part names (root, part_NN) even when the skeleton is recognised as a humanoid")
    p.add_argument("--iterations", type=int, default=default.max_iterations,
                   help=f"outer rounds of the alternating optimisation after {len(default.warm_start)} warm-start "
                        f"rounds (default {default.max_iterations}; 0: initialisation only)")
    p.add_argument("--seed", type=int, default=default.seed, help=f"random seed (default {default.seed})")
    p.add_argument("--key-scans", type=int, default=default.key_scans,
                   help=f"learn the rig from at most this many scans (the most different poses) and fit the "
                        f"other scans' poses with it (default {default.key_scans}; 0: learn from every scan)")
    p.add_argument("--key-scan-budget", type=int, default=default.key_scan_budget, metavar="N",
                   help=f"on large meshes learn from at most N / vertices key scans, but at least 20 (default "
                        f"{default.key_scan_budget}: 22 key scans for 13,380 vertices; 0: no such limit)")
    p.add_argument("--memory-limit", type=float, default=default.memory_limit_gb, metavar="GB",
                   help=f"memory budget of the run in GB (default {default.memory_limit_gb:g}: 80%% of the memory "
                        f"available when it starts); key scans that do not fit are left out (the run says so), "
                        f"and it is refused only if 3 key scans do not fit")
    p.add_argument("--threads", type=int, default=default.workers,
                   help=f"solver threads (default {default.workers}: one per CPU core)")
    p.add_argument("--out", required=True, help="model bundle to write (.npz)")
    p.add_argument("--report", help="write the error statistics, stage times and objective log as JSON")
    add_axis_arguments(p)
    p.add_argument("--blend", help="also save a .blend with the scans and the learned rig")
    p.set_defaults(func=run)
