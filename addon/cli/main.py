"""Batch commands: ``./run <command> ...`` and ``blender -b -P batch.py -- <command> ...``.

Each module in ``COMMAND_MODULES`` defines ``add_commands(subparsers)``; every command parser sets
``func`` (``args -> int`` exit code).  Input errors (``ArticulaInputError``) become a one-line
message and exit code 2; anything else is a bug and prints a traceback, exit code 1.  A command that
fails writes nothing (:mod:`.outputs`).
"""
import argparse
import sys
import traceback

import bpy

from ...sample_scenes import cli as samples
from ...solver.errors import ArticulaInputError, Cancelled
from . import bench, bind_scan, demo, depth, farm, gaze, lbs, learn, outputs, retarget, rig, scans, track

COMMAND_MODULES = (bench, samples, rig, lbs, scans, depth, learn, track, retarget, bind_scan, gaze, farm, demo)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="articula", description="Articula batch commands")
    sub = parser.add_subparsers(dest="command", metavar="<command>")
    sub.add_parser("help", help="list the commands").set_defaults(func=lambda a: (parser.print_help(), 0)[1])
    for module in COMMAND_MODULES:
        module.add_commands(sub)
    return parser


def main(argv) -> int:
    parser = build_parser()
    if not argv:
        parser.print_help()
        return 0
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        with outputs.kept_on_failure(outputs.output_paths(args)) as outcome:   # a failure writes nothing
            code = int(args.func(args) or 0)
            outcome["ok"] = code == 0
        return code
    except ArticulaInputError as exc:
        print(f"articula {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except Cancelled as exc:
        print(f"articula {args.command}: cancelled {exc}", file=sys.stderr)
        return 3
    except Exception:  # a bug: show everything
        traceback.print_exc()
        return 1
