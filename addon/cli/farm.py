"""Batch command ``farm``: Articula's long batch work on a Flamenco Manager (docs/farm.md).

    ./run farm job-types --to /opt/flamenco/scripts          (then restart the Manager)
    ./run farm track --manager http://farm:8080 --model person.npz --depth rec/ --out tracked.npz \\
                     [--blend tracked.blend] [--chunk 300] [--overlap 60] [--retries 2]
    ./run farm track --manager URL --depth rec/ --out tracked.npz      (template body, adapted by a first task)
    ./run farm learn --manager URL --subjects captures/ --out-dir rigs/ [--names a,b] [--blend]
    ./run farm import --manager URL --subjects captures/ --out-dir blends/
    ./run farm status --manager URL JOB_ID      ./run farm cancel --manager URL JOB_ID

``farm track`` checks the inputs, submits one task per chunk and a merge task, follows the job, submits
the chunks that failed again (``--retries`` times), and leaves at ``--out`` the same tracked bundle as
``./run track`` with the same flags would write.  Paths must lie on storage every Worker sees; the
Manager's two-way variables map them between platforms.  Ctrl-C cancels the job.
"""
import math
import os

from ...solver.errors import ArticulaInputError, Cancelled
from ...solver.farm import chunks
from ...solver.farm.flamenco import Manager
from ...solver.farm.follow import FarmRun
from ...solver.depth.camera import preset_key
from ...solver.farm.subjects_job import SubjectsJob
from ...solver.farm.track_job import AGREE_MM, SCANS_AGREE_MM
from ...solver.track.options import TrackOptions
from ...solver.track_depth.options import PERSON_CHOICES, TRACKERS
from ..farm import inputs, job_types
from .track_depth import CAMERAS


def _follow(run: FarmRun, args) -> None:
    run.start()
    print(f"submitted job {run.job_id} to {run.manager.url} ({run.work.count} {run.work.unit}s)", flush=True)
    if args.no_wait:
        print(f"not waiting: follow it with ./run farm status --manager {run.manager.url} {run.job_id}")
        return
    try:
        run.wait(args.poll, report=lambda text: print(text, flush=True))
    except KeyboardInterrupt:
        raise Cancelled(f"(job {run.job_id}: {run.cancel()})") from None


def run_job_types(args) -> int:
    written = job_types.install(args.to)
    for path in written:
        print(f"wrote {path}")
    print("restart the Flamenco Manager: it reads job types at start-up")
    return 0


def run_track(args) -> int:
    if (args.depth is None) == (args.scans is None):
        raise ArticulaInputError("give the recording as --depth DIR (depth frames) or --scans DIR (captures)")
    kind = "depth" if args.depth is not None else "scans"
    options = []
    for flag, value in (("--tracker", args.tracker), ("--person", args.person)):
        if value:
            if kind != "depth":
                raise ArticulaInputError(f"{flag}: for --depth only")
            options += [flag, value]
    size, overlap, note = chunks.settings(args.chunk, args.overlap, *inputs.DEFAULT_CHUNK[kind])
    job = inputs.track_job(args.model, args.depth or args.scans, kind, args.out, args.blend or "", size,
                           overlap, options, args.camera or "", args.work_dir or "")
    if note:
        print(note)
    window = TrackOptions().window
    if kind == "scans" and len(job.ranges) > 1 and overlap < window - 1:
        print(f"overlap {overlap} frames: under {window - 1}, the frames by a cut come from a chunk's edge window "
              f"and may differ from one process's track by a few mm (give --overlap {window - 1} or more)")
    if args.agree is not None:
        if not args.agree >= 0 or not math.isfinite(args.agree):
            raise ArticulaInputError(f"--agree: expected millimetres >= 0 (0: no check), got {args.agree}")
        job.agree_mm = args.agree
    if not 1 <= args.adapt_frames <= 100_000:
        raise ArticulaInputError(f"--adapt-frames: expected 1..100000, got {args.adapt_frames}")
    job.adapt_frames = args.adapt_frames
    print(f"{len(job.ranges)} chunks: {', '.join(f'{a}:{b}' for a, b in job.ranges)}; chunk bundles in {job.work_dir}")
    run = FarmRun(Manager(args.manager, args.timeout), job, args.retries)
    _follow(run, args)
    if not args.no_wait:
        print(f"wrote {job.out}" + (f" and {job.blend}" if job.blend else "") + f" (jobs {', '.join(run.jobs)})")
    return 0


def _subjects(args) -> list:
    root = os.path.abspath(args.subjects)
    if not os.path.isdir(root):
        raise ArticulaInputError(f"{args.subjects}: not a folder")
    names = [n.strip() for n in args.names.split(",")] if args.names else \
        sorted(n for n in os.listdir(root) if os.path.isdir(os.path.join(root, n)) and not n.startswith("."))
    missing = [n for n in names if not os.path.isdir(os.path.join(root, n))]
    if missing or not names:
        raise ArticulaInputError(f"{root}: no subject folder {', '.join(missing) or '(none found)'}")
    return names


def run_subjects(args) -> int:
    command = {"learn": "learn-rig", "import": "import-scans"}[args.farm_command]
    out_dir = os.path.abspath(args.out_dir)          # made by the job's prepare(), once submitting is possible
    work = SubjectsJob(command, os.path.abspath(args.subjects), _subjects(args), out_dir,
                       bool(getattr(args, "blend", False)), args.options.split() if args.options else [])
    run = FarmRun(Manager(args.manager, args.timeout), work, args.retries)
    _follow(run, args)
    if not args.no_wait:
        print(f"wrote the results of {work.count} subjects in {out_dir} (jobs {', '.join(run.jobs)})")
    return 0


def run_status(args) -> int:
    manager = Manager(args.manager, args.timeout)
    job = manager.job(args.job)
    print(f"job {job['id']} {job['name']!r}: {job['status']}")
    for t in manager.tasks(args.job):
        print(f"  {t['name']}: {t['status']}")
    return 0


def run_cancel(args) -> int:
    Manager(args.manager, args.timeout).cancel(args.job)
    print(f"asked the Manager to cancel job {args.job}")
    return 0


def _common(p, follow=True) -> None:
    p.add_argument("--manager", required=True, metavar="URL", help="Flamenco Manager, e.g. http://farm:8080")
    p.add_argument("--timeout", type=float, default=10.0, help="seconds per request to the Manager (default 10)")
    if follow:
        p.add_argument("--retries", type=int, default=2,
                       help="how many times failed tasks are submitted again (default 2)")
        p.add_argument("--poll", type=float, default=2.0, help="seconds between status reads (default 2)")
        p.add_argument("--no-wait", action="store_true", help="submit and return (no re-submission of failures)")


def add_commands(sub):
    p = sub.add_parser("farm", help="run tracking, rig learning and imports on a Flamenco render farm")
    fs = p.add_subparsers(dest="farm_command", metavar="<farm command>", required=True)
    q = fs.add_parser("job-types", help="write Articula's Flamenco job types into the Manager's scripts folder")
    q.add_argument("--to", required=True, metavar="DIR", help="the 'scripts' folder beside flamenco-manager")
    q.set_defaults(func=run_job_types)
    q = fs.add_parser("track", help="track a long recording in chunks on the farm (like ./run track)")
    _common(q)
    q.add_argument("--model", default="", help="the person's model bundle (.npz); without it (--depth only) a first "
                                               "task adapts the built-in template body on --adapt-frames frames")
    q.add_argument("--adapt-frames", type=int, default=300, metavar="N",
                   help="without --model: frames the template adapts on before the chunks (default 300)")
    q.add_argument("--depth", metavar="DIR", help="a depth recording (16-bit PNG frames, intrinsics.json)")
    q.add_argument("--scans", metavar="DIR", help="a folder of unregistered captures")
    q.add_argument("--camera", type=preset_key, choices=CAMERAS, metavar="PRESET",
                   help="with --depth: the camera of a folder without intrinsics.json")
    q.add_argument("--tracker", type=str.lower, choices=TRACKERS, help="with --depth: the per-frame fit")
    q.add_argument("--person", type=str.lower, choices=PERSON_CHOICES,
                   help="with --depth and several people in view: whom to track (as ./run track --person)")
    q.add_argument("--out", required=True, help="tracked bundle to write (.npz)")
    q.add_argument("--blend", help="also bake the tracked rig and action into this .blend")
    q.add_argument("--chunk", type=int, default=0,
                   help="frames per chunk (default: 300 for --depth, 60 for --scans)")
    q.add_argument("--overlap", type=int, default=0,
                   help="frames a chunk tracks before its own to settle (default: 60 for --depth, 10 for --scans; "
                        "with --chunk alone, at most half the chunk)")
    q.add_argument("--work-dir", help="shared folder for the chunk bundles (default: OUT.farm beside --out)")
    q.add_argument("--agree", type=float, default=None, metavar="MM",
                   help="chunks differing more than this (mm) where the merge switches started on another solution: "
                        f"with --scans (default {SCANS_AGREE_MM:g}, pass-1 poses) the later one goes on from the "
                        f"earlier one's pass 1, which makes it the one process's track; with --depth (default "
                        f"{AGREE_MM:g}) the merge refuses; 0: off")
    q.set_defaults(func=run_track)
    for name, what in (("learn", "learn a rig per subject folder (learn-rig)"),
                       ("import", "import each subject's scan sequence into a .blend (import-scans)")):
        q = fs.add_parser(name, help=what)
        _common(q)
        q.add_argument("--subjects", required=True, metavar="ROOT", help="folder of subject folders")
        q.add_argument("--names", help="comma-separated subject folders (default: every folder in ROOT)")
        q.add_argument("--out-dir", required=True, help="folder for <subject>.npz / .blend")
        q.add_argument("--options", default="", help="further flags of the command, quoted (no paths)")
        if name == "learn":
            q.add_argument("--blend", action="store_true", help="also save <subject>.blend")
        q.set_defaults(func=run_subjects, partial_outputs=("out_dir",))   # subjects done stay when others fail
    for name, func, what in (("status", run_status, "show a job's tasks"), ("cancel", run_cancel, "cancel a job")):
        q = fs.add_parser(name, help=what)
        _common(q, follow=False)
        q.add_argument("job", help="job id")
        q.set_defaults(func=func)
