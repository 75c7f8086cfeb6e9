"""Batch commands ``track`` (unregistered captures + a model bundle -> a tracked bundle, + report, + .blend;
with ``--depth`` a depth recording, see :mod:`.track_depth`) and ``merge-tracks`` (chunks tracked
separately -> one tracked bundle).

    ./run track --model person.npz --scans scans/ --out tracked.npz --report tracked.json
    ./run track --model person.npz --scans scans/ --frames 0:60 --out part1.npz
    ./run track --model person.npz --scans scans/ --frames 55:120 --out part2.npz
    ./run merge-tracks part1.npz part2.npz --out tracked.npz --report merge.json
    ./run track --model person.npz --scans scans/ --start-pose posed_over_frame0.npz --out tracked.npz
    blender -b -P batch.py -- track --model person.npz --scans scans/ --out tracked.npz --blend tracked.blend

The captures are read as written (no axis conversion) and the tracked bundle holds the (adapted) model with
its bone names and vertex order and one pose per tracked frame in input order, in the captures' own
coordinates; ``--frames A:B`` tracks input frames A..B-1 (0-based).  ``--forward``/``--up`` only place the
scans and the rig in the .blend.  ``--blend`` saves the scans (a scan-sequence object, frames 1..N) and the
tracked rig playing over them, added to the file when it exists, else in an empty scene.
"""
import os
from dataclasses import replace

import bpy
import numpy as np

from ...solver.errors import ArticulaInputError
from ...solver.formats.axes import conversion
from ...solver.formats.bundle import save_bundle
from ...solver.learn.options import name_setting
from ...solver.track import merge
from ...solver.track.captures import POINT_EXTENSIONS
from ...solver.track.options import ADAPT_CHOICES, ADAPT_MIN_FRAMES, PRIOR_CHOICES, TrackOptions
from .. import jobs
from ..track import inputs, result, solve
from ..track.report import report_document, summary_text
from ..tracking.inputs import parse_frames
from ..tracking.result import check_output_path
from . import track_depth
from .common import call_operator, check_blend_output, editing, finish, write_json
from .scans import add_axis_arguments, axis_props

# TrackOptions field -> the flag that sets it (error messages name the flag the user typed)
FLAGS = {"adapt": "--adapt", "prior": "--prior", "max_points": "--max-points", "frames": "--frames",
         "workers": "--threads"}


def _options(args, count: int) -> TrackOptions:
    options = TrackOptions(adapt="off" if args.no_adapt else args.adapt, prior=args.prior,
                           temporal=not args.no_temporal, fit_scale=args.fit_scale, max_points=args.max_points,
                           workers=args.threads)
    if args.frames is not None:
        options = replace(options, frames=parse_frames(args.frames, count))
    try:
        return options.validate()
    except ArticulaInputError as exc:
        raise ArticulaInputError(name_setting(str(exc), FLAGS)) from None


def _save_blend(blend: str, paths, outcome, axes: dict) -> None:
    """Import the scans as a scan-sequence object on frames 1..N and put the tracked rig over them (its
    matrix: the scans'), with the error colours; saved to ``blend`` (added to it when it exists)."""
    with editing(blend):
        call_operator(bpy.ops.articula.import_scans, directory=os.path.dirname(paths[0]),
                      files=[{"name": os.path.basename(p)} for p in paths], frame_start=1, **axes)
        ob = bpy.context.view_layer.objects.active
        outcome.model_input.matrix = np.array(ob.matrix_world, np.float64)
        outcome.captures.object_name, outcome.captures.frame_start = ob.name, 1
        with jobs.scene_guard():
            arm, action, _warnings = result.build(bpy.context, outcome, blend_path=blend)
        finish(f"{arm.name}: action {action.name!r} on frames {1 + outcome.first_frame}.."
               f"{outcome.first_frame + len(outcome.poses)} over {ob.name!r}", blend)


def run(args) -> int:
    if args.depth is not None and args.scans is not None:
        raise ArticulaInputError("--depth and --scans exclude each other: track a depth recording (--depth DIR) "
                                 "or captures (--scans PATH...), not both")
    if args.depth is not None:
        return track_depth.run(args)
    if args.scans is None:
        raise ArticulaInputError("nothing to track: give --scans PATH... (captures) or --depth DIR (a depth "
                                 "recording)")
    given = [flag for flag, value in (("--camera", args.camera), ("--tracker", args.tracker),
                                      ("--person", args.person)) if value]
    if given:
        raise ArticulaInputError(f"{', '.join(given)}: for --depth only")
    if not args.model:
        raise ArticulaInputError("--scans needs --model MODEL.npz (the person's model bundle); only --depth can "
                                 "track with the built-in template body")
    for path in (args.out, args.report):
        check_output_path(path or "")
    check_blend_output(args.blend)
    paths = inputs.capture_paths(args.scans)
    if args.blend and os.path.splitext(paths[0])[1].lower() in POINT_EXTENSIONS:
        raise ArticulaInputError("--blend shows mesh scans (OBJ, PLY, STL, OFF); import point files with "
                                 "import-depth and track them in Blender")
    conversion(os.path.splitext(paths[0])[1], args.forward, args.up)       # refuse bad axes before the work
    options = _options(args, len(paths))
    model_input = inputs.model_from_bundle(os.path.abspath(args.model))
    model_input.matrix = np.eye(4)
    if args.start_pose:
        model_input.start_pose, model_input.start_label, model_input.resume = inputs.bundle_start_pose(
            args.start_pose, model_input.model)
    captures = inputs.captures_from_files(paths)
    outcome = solve.track(model_input, captures, options, jobs.Progress("track", echo=True),
                          with_point_errors=bool(args.blend))
    result.save(args.out, outcome)
    for note in getattr(outcome.result, "notes", ()):
        print(f"{args.model}: {note}")
    print(f"wrote {args.out}: {outcome.model.num_vertices} vertices, {outcome.model.skeleton.num_bones} bones, "
          f"{len(outcome.poses)} poses; {summary_text(outcome)}")
    if args.report:
        write_json(args.report, report_document(outcome))
        print(f"wrote {args.report}")
    if args.blend:
        _save_blend(os.path.abspath(args.blend), paths, outcome, axis_props(args))
    return 0


def run_merge(args) -> int:
    for path in (args.out, args.report):
        check_output_path(path or "")
    if args.agree < 0 or not np.isfinite(args.agree):
        raise ArticulaInputError(f"--agree: expected millimetres >= 0 (0: no check), got {args.agree}")
    merged = merge.merge_chunks(merge.load_chunks([os.path.abspath(p) for p in args.chunks]), args.agree)
    try:
        save_bundle(args.out, merged.model, merged.poses, merged.provenance)
    except OSError as exc:
        raise ArticulaInputError(f"{args.out}: cannot write the bundle ({exc.strerror or exc})") from None
    rep = merged.report
    if args.report:
        write_json(args.report, rep)
    worst = max(o["max_rotation_deg"] for o in rep["overlaps"])
    cut = max(c["max_vertex_mm"] for c in rep["cuts"]) if rep["cuts"] else 0.0
    used = ", ".join(f"{c['name']} {c['used']}" for c in rep["chunks"])
    return finish(f"wrote {args.out}: frames {rep['first_frame']}..{rep['first_frame'] + rep['frames'] - 1} "
                  f"from {len(rep['chunks'])} chunks (frames used: {used}); largest bone-rotation difference on "
                  f"the overlaps {worst:.3f} deg, largest vertex difference at a cut {cut:.2f} mm"
                  + (f"; wrote {args.report}" if args.report else ""), scene=False)


def add_commands(sub):
    default = TrackOptions()
    p = sub.add_parser("track", help="track unregistered captures (--scans) with a model bundle, or a depth "
                                     "recording (--depth) with a model bundle or the built-in template body "
                                     "(one pose per frame)")
    p.add_argument("--model", help="model bundle (.npz) of the person, e.g. from learn-rig (needed with --scans; "
                                   "with --depth, without it the built-in template body adapts to the person)")
    p.add_argument("--scans", nargs="+", metavar="PATH",
                   help="a folder of captures (OBJ/PLY/STL/OFF meshes or NPY/XYZ/TXT point files) or such files "
                        "(natural order)")
    track_depth.add_arguments(p)
    p.add_argument("--out", required=True, help="tracked bundle to write (.npz)")
    p.add_argument("--report", help="write the per-frame residuals, lost frames and timings as JSON")
    p.add_argument("--blend", help="also save a .blend with the scans (or the depth recording) and the tracked rig")
    p.add_argument("--frames", metavar="A:B", help="track input frames A..B-1 only (0-based; A: or :B allowed)")
    p.add_argument("--start-pose", metavar="BUNDLE.npz[:K]",
                   help="start the first tracked frame from pose K (default 0) of this bundle (the model's bones, "
                        "the captures' coordinates), e.g. exported from the rig posed over it, instead of "
                        "searching for it")
    p.add_argument("--no-adapt", action="store_true", help="do not adapt the model (same as --adapt off)")
    p.add_argument("--adapt", choices=ADAPT_CHOICES, default=default.adapt,
                   help=f"adapt the rest mesh and joints to the recording (default {default.adapt}: when the model "
                        f"is not the person's and the range has at least {ADAPT_MIN_FRAMES} frames)")
    p.add_argument("--prior", choices=PRIOR_CHOICES, default=default.prior,
                   help=f"pose prior (default {default.prior}: the model's poses, else the generic human prior)")
    p.add_argument("--no-temporal", action="store_true", help="no sliding-window pass with the temporal prior")
    p.add_argument("--fit-scale", action="store_true", help="also fit one uniform scale")
    p.add_argument("--max-points", type=int, default=default.max_points,
                   help=f"thin captures to about this many points (default {default.max_points}; 0: keep all)")
    p.add_argument("--threads", type=int, default=default.workers,
                   help=f"solver threads for the capture tracker (default {default.workers}: one per CPU core; the "
                        f"result does not depend on it)")
    add_axis_arguments(p)
    p.set_defaults(func=run)
    m = sub.add_parser("merge-tracks", help="join tracked chunks (track --frames A:B, overlapping) into one")
    m.add_argument("chunks", nargs="+", metavar="CHUNK.npz", help="tracked bundles of one input, overlapping")
    m.add_argument("--out", required=True, help="merged tracked bundle to write (.npz)")
    m.add_argument("--agree", type=float, default=merge.AGREE_MM, metavar="MM",
                   help="refuse (exit 2, nothing written) when two chunks' posed vertices differ by more than MM "
                        "millimetres on the frame where the merge switches between them (default %(default)g; "
                        "0 accepts any difference)")
    m.add_argument("--report", help="write which chunk each frame came from and the overlaps' differences")
    m.set_defaults(func=run_merge)
