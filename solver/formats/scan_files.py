"""Scan sequences from files: listing a folder in natural order, reading every frame, and checking
whether the frames are *registered* (one vertex count and identical faces in every frame).

Pure numpy, no bpy.  :func:`read_scan_files` returns a :class:`ScanSequence`; a registered sequence
holds its frames as one ``(N, V, 3)`` float32 array, an unregistered one (differing topology, e.g.
raw scans for tracking) keeps one mesh per frame.
"""
from __future__ import annotations

import os
import re
from dataclasses import dataclass, field

import numpy as np

from ..errors import ArticulaInputError
from .mesh_files import MESH_EXTENSIONS, check_mesh, read_mesh
from .polymesh import PolyMesh

_DIGITS = re.compile(r"(\d+)")


def natural_key(name: str):
    """Sort key ordering embedded numbers by value: ``scan2`` before ``scan10``."""
    parts = _DIGITS.split(os.path.basename(name).lower())
    return [(0, int(p)) if i % 2 else (1, p) for i, p in enumerate(parts)] + [(2, name)]


def natural_sorted(names):
    """``names`` in natural order (:func:`natural_key`); the one natural sort of Articula's file lists."""
    return sorted(names, key=natural_key)


def list_scan_files(folder: str, extensions=MESH_EXTENSIONS) -> list[str]:
    """Mesh files in ``folder`` (not recursive), naturally sorted.  All must share one extension."""
    if not os.path.isdir(folder):
        raise ArticulaInputError(f"{folder}: folder not found")
    try:
        names = os.listdir(folder)
    except OSError as exc:
        raise ArticulaInputError(f"{folder}: cannot list folder ({exc.strerror or exc})") from None
    files = [n for n in names if os.path.splitext(n)[1].lower() in extensions
             and os.path.isfile(os.path.join(folder, n))]
    if not files:
        raise ArticulaInputError(f"{folder}: no scan files ({', '.join(extensions)}) in this folder")
    exts = sorted({os.path.splitext(n)[1].lower() for n in files})
    if len(exts) > 1:
        raise ArticulaInputError(f"{folder}: mixed file types ({', '.join(exts)}); put one sequence of one "
                                 f"format in a folder or pick the files")
    return [os.path.join(folder, n) for n in natural_sorted(files)]


@dataclass(eq=False)
class ScanSequence:
    """Frames of one subject.

    ``topology``: the first frame's mesh (its ``vertices`` are frame 0).  Registered: ``frames`` is
    (N, V, 3) float32 and ``meshes`` is empty.  Unregistered: ``frames`` is None and ``meshes`` holds one
    :class:`PolyMesh` per frame; ``why_unregistered`` names the first frame that differs and how.
    """
    names: list
    topology: PolyMesh
    frames: np.ndarray | None = None
    meshes: list = field(default_factory=list)
    why_unregistered: str = ""

    @property
    def registered(self) -> bool:
        return self.frames is not None

    def __len__(self) -> int:
        return len(self.names)


class SequenceAssembler:
    """Builds a :class:`ScanSequence` frame by frame, keeping little memory: while the frames are
    registered only their float32 positions are kept (the faces are checked against the first frame,
    then dropped).  With ``require_registered`` a topology difference is an error naming the first
    differing frame; otherwise it turns the sequence unregistered (one mesh per frame from then on)."""

    def __init__(self, require_registered: bool = False):
        self.require_registered = require_registered
        self.names, self.first = [], None
        self.positions, self.meshes, self.why = [], None, ""

    def add(self, mesh: PolyMesh, name: str) -> None:
        if self.first is None:
            self.first = mesh
        elif self.meshes is None:
            how = self.first.topology_difference(mesh)
            if how:
                self.why = f"{name} differs from {self.names[0]}: {how}"
                if self.require_registered:
                    raise ArticulaInputError(f"not registered: {self.why}")
                f = self.first
                self.meshes = [PolyMesh(p.astype(np.float64), f.face_sizes, f.corner_verts) for p in self.positions]
                self.positions = []
        self.names.append(name)
        if self.meshes is None:
            self.positions.append(np.asarray(mesh.vertices, np.float32))
        else:
            self.meshes.append(mesh)

    def result(self) -> ScanSequence:
        if self.first is None:
            raise ArticulaInputError("no frames to import")
        if self.meshes is None:
            return ScanSequence(list(self.names), self.first, np.stack(self.positions))
        return ScanSequence(list(self.names), self.first, None, self.meshes, self.why)


def assemble(meshes: list, names: list, require_registered: bool = False) -> ScanSequence:
    """:class:`SequenceAssembler` over lists of meshes and names."""
    asm = SequenceAssembler(require_registered)
    for mesh, name in zip(meshes, names):
        asm.add(mesh, name)
    return asm.result()


def read_scan_files(paths, progress=None, require_registered: bool = False) -> ScanSequence:
    """Read mesh files (one frame each, in the given order) -> :class:`ScanSequence`.  Every file is
    checked from its first bytes (``mesh_files.check_mesh``) before the first is read.
    ``progress(fraction, text)`` is called per file and may raise ``Cancelled``."""
    paths = list(paths)
    if not paths:
        raise ArticulaInputError("no scan files given")
    for path in paths:      # every file's header and size first: a bad last file fails in milliseconds
        check_mesh(path)
    asm = SequenceAssembler(require_registered)
    for k, path in enumerate(paths):
        if progress and k % 8 == 0:
            progress(0.9 * k / len(paths), f"reading {os.path.basename(path)}")
        asm.add(read_mesh(path), os.path.basename(path))
    return asm.result()


def sequence_from_cache(frames: np.ndarray, base: PolyMesh, cache_name: str, base_name: str) -> ScanSequence:
    """A registered sequence from point-cache frames (N, V, 3) and the base mesh giving the faces."""
    if frames.shape[1] != len(base.vertices):
        raise ArticulaInputError(f"{cache_name} has {frames.shape[1]} vertices per frame but the base mesh "
                                 f"{base_name} has {len(base.vertices)}")
    names = [f"{cache_name}[{k}]" for k in range(len(frames))]
    topo = PolyMesh(frames[0].astype(np.float64), base.face_sizes, base.corner_verts)
    return ScanSequence(names, topo, np.ascontiguousarray(frames, np.float32))
