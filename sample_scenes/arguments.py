"""Command-line options shared by the ``samples`` subcommands: the subject (``--rig/--shape/--subject-seed``)
and the motion (``--poses/--motion/--skin/--seed/...``), and the posed sequence they describe."""
from __future__ import annotations

from .mpfb_rig import RIGS
from .registered import MOTIONS, SKINS


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
    p.add_argument("--motion", default="rom", choices=MOTIONS,
                   help="rom: random range of motion; walk; turn: turning left and right on the spot, limbs moving")
    p.add_argument("--skin", default="lbs", choices=SKINS, help="skinning used to pose the mesh")
    p.add_argument("--seed", type=int, default=0, help="random seed of the motion (default 0)")
    p.add_argument("--amplitude", type=float, default=1.0, help="rom, turn: scale of the joint limits (0, 1]")
    p.add_argument("--key-every", type=int, default=None,
                   help="rom, turn: key poses every K frames, interpolated (default: rom 1, turn 12)")
    p.add_argument("--step", type=float, default=1.0, help="walk: cycle frames per pose (40-frame cycle)")
    p.add_argument("--turn-degrees", type=float, default=40.0,
                   help="turn: largest yaw either way (degrees, default 40; one cycle per 60 frames)")
    p.add_argument("--root-yaw", type=float, default=0.0, help="random root yaw up to this many degrees")
    p.add_argument("--root-shift", type=float, default=0.0, help="random root shift up to this many metres")


def motion_options(args) -> dict:
    """Pose-generator options from parsed arguments."""
    opts = dict(root_yaw=args.root_yaw, root_shift=args.root_shift)
    if args.motion in ("rom", "turn"):
        opts.update(amplitude=args.amplitude)
        if args.key_every is not None:
            opts.update(key_every=args.key_every)
    if args.motion == "turn":
        opts.update(turn_degrees=args.turn_degrees)
    if args.motion == "walk":
        opts.update(step=args.step)
    return opts


def sequence_from_args(args):
    """``registered.posed_sequence`` for the subject and motion arguments: (vertices, faces, gt)."""
    from .registered import posed_sequence
    return posed_sequence(args.rig, args.shape, args.poses, args.motion, args.skin, args.seed,
                          args.subject_seed, **motion_options(args))
