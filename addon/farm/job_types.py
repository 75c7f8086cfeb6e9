"""Articula's Flamenco job types: JavaScript files the Manager loads from the ``scripts`` folder beside
its executable (at start-up only).  ``articula-track``: a recording in frame chunks, then merge and bake;
``articula-subjects``: one learn-rig or import-scans task per subject."""
from __future__ import annotations

import os
import shutil

from ...solver.errors import ArticulaInputError

FOLDER = os.path.join(os.path.dirname(os.path.abspath(__file__)), "job_types")


def files() -> list:
    """Paths of the shipped job-type scripts."""
    return sorted(os.path.join(FOLDER, n) for n in os.listdir(FOLDER) if n.endswith(".js"))


def install(dest: str) -> list:
    """Copy the job types into ``dest`` (created when missing; the Manager's ``scripts`` folder); returns
    the written paths.  Existing files of the same names are replaced, others left alone."""
    dest = os.path.abspath(dest)
    if os.path.exists(dest) and not os.path.isdir(dest):
        raise ArticulaInputError(f"{dest}: is a file, not the Manager's scripts folder")
    try:
        os.makedirs(dest, exist_ok=True)
        return [shutil.copyfile(src, os.path.join(dest, os.path.basename(src))) for src in files()]
    except OSError as exc:
        raise ArticulaInputError(f"{dest}: cannot write the job types ({exc.strerror or exc})") from None
