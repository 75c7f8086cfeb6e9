"""A batch command that fails writes nothing: :func:`kept_on_failure` wraps every command (``main``).

The outputs a command names (``--out``, ``--blend``, ``--report``, ``--out-dir``, ``--to``) are looked at
before it runs; when it fails (an input error, a bug, Ctrl-C), every file or folder that appeared at an
output path, at the temporary names writers use beside it (``.tmp.npz`` of
:func:`solver.formats.bundle.temporary_path`, ``.tmp``, ``.part``, Blender's ``@``) or, for a .blend, in
its ``<name>_articula`` cache folder is removed; inside an output path that is a folder, what is new in
it; the folders the command made on the way; and an output file that existed and was replaced gets its
previous bytes back (a hard link kept while the command runs).  Paths that existed stay.  A command whose
outputs are many independent results (``farm learn``/``farm import``: one file per subject) names them in
``partial_outputs`` (``set_defaults``): what it finished stays when others fail.
"""
import contextlib
import os
import shutil

from ...solver.formats.bundle import temporary_path

OPTIONS = ("out", "blend", "report", "out_dir", "to")
KEEP = ".articula-previous"          # suffix of the hard link that keeps a replaced output's bytes


def output_paths(args) -> list:
    """The absolute paths of the output options ``args`` (an ``argparse.Namespace``) sets, except those its
    command keeps in part (``args.partial_outputs``)."""
    partial = set(getattr(args, "partial_outputs", ()))
    return sorted({os.path.abspath(v) for k in OPTIONS if k not in partial for v in [getattr(args, k, None)]
                   if isinstance(v, str) and v.strip()})


def companions(path: str) -> list:
    """``path`` and the names written beside it on the way to it (module docstring)."""
    out = [path, temporary_path(path), path + ".tmp", path + ".part", path + ".part.npz", path + "@"]
    if path.lower().endswith(".blend"):
        out.append(os.path.splitext(path)[0] + "_articula")
    return out


def _missing_folders(path: str) -> list:
    """The folders above ``path`` that do not exist yet, deepest first."""
    out, folder = [], os.path.dirname(path)
    while folder and not os.path.exists(folder) and os.path.dirname(folder) != folder:
        out.append(folder)
        folder = os.path.dirname(folder)
    return out


def _remove(path: str) -> None:
    if os.path.isdir(path) and not os.path.islink(path):
        shutil.rmtree(path, ignore_errors=True)
    elif os.path.lexists(path):
        os.remove(path)


class _Snapshot:
    """What existed at the outputs before the command ran (module docstring)."""

    def __init__(self, paths):
        self.absent = [p for path in paths for p in companions(path) if not os.path.lexists(p)]
        self.folders = {p: set(os.listdir(p)) for p in paths if os.path.isdir(p)}
        self.made = sorted({f for p in paths for f in _missing_folders(p)}, key=len, reverse=True)
        self.kept = {}
        for p in paths:
            if os.path.isfile(p) and not os.path.lexists(p + KEEP):
                with contextlib.suppress(OSError):      # no hard links here: the file is not protected
                    os.link(p, p + KEEP)
                    self.kept[p] = p + KEEP

    def restore(self) -> None:
        """Remove what the failed command wrote and put replaced files back."""
        for p in self.absent:
            _remove(p)
        for folder, names in self.folders.items():
            for name in set(os.listdir(folder)) - names if os.path.isdir(folder) else ():
                _remove(os.path.join(folder, name))
        for p, keep in self.kept.items():
            if os.path.isfile(p) and os.path.samefile(p, keep):
                os.remove(keep)                       # never replaced (rename onto a hard link is a no-op)
            else:
                os.replace(keep, p)
        for folder in self.made:
            with contextlib.suppress(OSError):
                os.rmdir(folder)                      # only when empty: another writer's files stay

    def release(self) -> None:
        for keep in self.kept.values():
            with contextlib.suppress(OSError):
                os.remove(keep)


@contextlib.contextmanager
def kept_on_failure(paths):
    """Run a command over output ``paths``; when it raises, or sets ``outcome["ok"]`` False on the dict
    it is given (a non-zero exit code), leave them as they were (module docstring)."""
    snap, outcome = _Snapshot(paths), {"ok": True}
    try:
        yield outcome
    except BaseException:
        snap.restore()
        raise
    if outcome["ok"]:
        snap.release()
    else:
        snap.restore()
