"""Batch command ``gaze``: make a character in a .blend look at a target over a shot (as ``articula.gaze``
does) and save the result as another .blend.

    ./run gaze --blend in.blend --armature Hero --target Camera --frames 20:180 --fade 12 --out out/hero_gaze.blend

``--blend`` is never written; a command that fails saves nothing.
"""
import os

import bpy

from ...solver.errors import ArticulaInputError
from ..gaze.chain import FACINGS
from .common import allow_axis_values, call_operator, check_blend_output, finish, open_blend


def _frames(text: str):
    try:
        a, b = (int(x) for x in text.split(":"))
    except ValueError:
        raise ArticulaInputError(f"--frames {text}: give FIRST:LAST, e.g. 20:180") from None
    return a, b


def _split(text: str):
    try:
        values = tuple(float(x) for x in text.split(","))
    except ValueError:
        values = ()
    if len(values) != 3 or min(values) < 0 or sum(values) <= 0:
        raise ArticulaInputError(f"--split {text}: give three shares for chest, neck, head, e.g. 0.1,0.4,0.5")
    return values


def gaze(args) -> int:
    if os.path.normpath(os.path.abspath(args.out)) == os.path.normpath(os.path.abspath(args.blend)):
        raise ArticulaInputError(f"--out {args.out}: give another file than --blend (it is never replaced)")
    if os.path.splitext(args.out)[1].lower() != ".blend":
        raise ArticulaInputError(f"--out {args.out}: must be a .blend file")
    first, last = _frames(args.frames) if args.frames else (-1, -1)
    shares = _split(args.split)
    check_blend_output(args.out)
    open_blend(args.blend)
    if bpy.data.objects.get(args.armature) is None:
        raise ArticulaInputError(f"{args.blend} has no object {args.armature!r}")
    call_operator(bpy.ops.articula.gaze, armature=args.armature, target=args.target, frame_start=first,
                  frame_end=last, fade_frames=args.fade, shares=shares, chest=args.chest, neck=args.neck,
                  head=args.head, facing=args.facing)
    return finish(f"{args.armature!r} looks at {args.target!r} on frames {args.frames or 'of the scene'}", args.out)


def add_commands(sub):
    p = sub.add_parser("gaze", help="make a character look at a target over a shot (an NLA layer)")
    p.add_argument("--blend", required=True, help=".blend with the character (never written)")
    p.add_argument("--armature", required=True, help="the character's armature object")
    p.add_argument("--target", required=True, help="object to look at (may move)")
    p.add_argument("--frames", default="", help="FIRST:LAST frames of the shot (default: the scene's range)")
    p.add_argument("--fade", type=int, default=10, help="frames of fade in and of fade out (default 10)")
    p.add_argument("--split", default="0.1,0.4,0.5", help="shares of the turn for chest,neck,head")
    for role in ("chest", "neck", "head"):
        p.add_argument(f"--{role}", default="", help=f"the {role} bone (default: found by role)")
    allow_axis_values(p)
    p.add_argument("--facing", choices=("AUTO", *FACINGS), default="AUTO",
                   help="where the face points in the rest pose (default: annotated eyes, else the body's facing)")
    p.add_argument("--out", required=True, help=".blend to save the result to")
    p.set_defaults(func=gaze)
