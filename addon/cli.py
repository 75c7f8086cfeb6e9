"""Batch commands: ``./run <command> ...`` and ``blender -b -P batch.py -- <command> ...``.

Each module in ``COMMAND_MODULES`` defines ``add_commands(subparsers)``; every command parser sets
``func`` (``args -> int`` exit code).  Input errors (``ArticulaInputError``) become a one-line
message and exit code 2; anything else is a bug and prints a traceback, exit code 1.
"""
import argparse
import importlib
import os
import sys
import traceback

import bpy

from ..solver.errors import ArticulaInputError, Cancelled

_PKG = __package__.rpartition(".")[0]

# Relative to the extension package.
COMMAND_MODULES = (
    ".addon.bench_cli",
    ".sample_scenes.cli",
    ".addon.rig_cli",
    ".addon.scan_cli",
    ".addon.depth_cli",
    ".addon.learn_cli",
    ".addon.demo",
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="articula", description="Articula batch commands")
    sub = parser.add_subparsers(dest="command", metavar="<command>")
    sub.add_parser("help", help="list the commands").set_defaults(func=lambda a: (parser.print_help(), 0)[1])
    for name in COMMAND_MODULES:
        importlib.import_module(name, _PKG).add_commands(sub)
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
        return int(args.func(args) or 0)
    except ArticulaInputError as exc:
        print(f"articula {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except Cancelled as exc:
        print(f"articula {args.command}: cancelled {exc}", file=sys.stderr)
        return 3
    except Exception:  # a bug: show everything
        traceback.print_exc()
        return 1


# -- shared by the command modules ------------------------------------------------------------------

def call_operator(op, **props) -> None:
    """Run ``bpy.ops.articula.<x>(**props)``; an operator's ERROR report (bad input) becomes
    ``ArticulaInputError`` with the operator's message."""
    try:
        op(**props)
    except RuntimeError as exc:
        raise ArticulaInputError(str(exc).replace("Error: ", "").strip()) from None


def save_blend_first(path: str) -> str:
    """Save the current (empty or opened) file at ``path`` before importing, so caches written by the
    import go next to it and are referenced relative to it.  Returns the absolute path."""
    blend = os.path.abspath(path)
    os.makedirs(os.path.dirname(blend), exist_ok=True)
    bpy.ops.wm.save_as_mainfile(filepath=blend)
    return blend


def save_blend_again() -> None:
    """Save the current file once more, without leaving a ``.blend1`` of the copy saved just before."""
    prefs = bpy.context.preferences.filepaths
    versions, prefs.save_version = prefs.save_version, 0
    try:
        bpy.ops.wm.save_mainfile()
    finally:
        prefs.save_version = versions
    print(f"saved {bpy.data.filepath}")
