"""The learner's input: registered scans from a scan-sequence object (main thread, its frame cache) or
from mesh files (no bpy), checked before the solver runs, and an initial skeleton from an armature.

The scans stay in their own coordinates (the object's local space, the files' axes); ``LearnInput.matrix``
is the object matrix that places them in the scene, given to the learned rig too."""
from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from ...solver.errors import ArticulaInputError
from ...solver.formats.axes import AUTO, conversion
from ...solver.formats.mesh_files import read_mesh
from ...solver.formats.scan_files import list_scan_files, natural_sorted, read_scan_files
from ...solver.learn.memory import check_sizes
from ...solver.learn.options import MIN_SCANS
from ...solver.rig.model import Skeleton
from ..sequences import scans as scan_sequence


@dataclass
class LearnInput:
    """Registered scans ``(M, V, 3)`` metres and their triangles ``(F, 3)``, where they came from
    (``source``: the object name or folder), the scene frame of scan 0, and a default rig name;
    ``matrix`` (4, 4): scans -> world (the scan-sequence object's matrix, or the files' axis conversion)."""
    scans: np.ndarray
    faces: np.ndarray
    source: str
    name: str
    frame_start: int = 1
    object_name: str = ""
    matrix: np.ndarray = None

    def __post_init__(self):
        self.matrix = np.eye(4) if self.matrix is None else np.array(self.matrix, np.float64).reshape(4, 4)


def check_scans(scans, faces, source: str) -> None:
    """Raise :class:`ArticulaInputError` naming ``source`` unless the scans can be learned from."""
    scans = np.asarray(scans)
    if scans.ndim != 3 or scans.shape[2] != 3:
        raise ArticulaInputError(f"{source}: expected scans of shape (M, V, 3), got {scans.shape}")
    if len(scans) < MIN_SCANS:
        raise ArticulaInputError(f"{source}: {len(scans)} scan{'s' if len(scans) != 1 else ''}; learning a rig "
                                 f"needs at least {MIN_SCANS} registered scans in different poses")
    bad = np.argwhere(~np.isfinite(scans))
    if len(bad):
        m, v, _ = bad[0]
        raise ArticulaInputError(f"{source}: scan {m} (frame index {m}) has a non-finite coordinate (NaN or inf) "
                                 f"at vertex {v}")
    if len(faces) == 0:
        raise ArticulaInputError(f"{source}: the scans have no faces; learning needs a connected surface mesh")


def input_from_object(ob) -> LearnInput:
    """The frames of a registered scan-sequence object (main thread)."""
    if ob is None:
        raise ArticulaInputError("no scan-sequence object: select one (Import › Scans…) or name it")
    if not scan_sequence.is_scan_sequence(ob):
        raise ArticulaInputError(f"{ob.name!r} is not a scan-sequence object; import the scans first "
                                 f"(Import › Scans…) and select the result")
    if not ob.articula.registered:
        raise ArticulaInputError(f"{ob.name!r}: the scans are not registered (vertex count or faces change between "
                                 f"frames); learning a rig needs registered scans of one topology")
    scans, faces = scan_sequence.scan_frames(ob)        # names the object if its frame cache is missing
    check_scans(scans, faces, repr(ob.name))
    return LearnInput(scans.astype(np.float64), faces, ob.name, ob.name, int(ob.articula.frame_start), ob.name,
                      np.array(ob.matrix_world, np.float64))


def scan_paths(directory: str = "", names=()) -> list:
    """Mesh files to learn from: ``names`` in ``directory`` (natural order), or every scan file of the
    folder ``directory``."""
    names = [n for n in names if n]
    if names:
        paths = [os.path.join(directory, n) for n in natural_sorted(names)]
        missing = [p for p in paths if not os.path.isfile(p)]
        if missing:
            raise ArticulaInputError(f"{missing[0]}: file not found")
        return paths
    if not directory:
        raise ArticulaInputError("no scans given: a scan-sequence object, a folder or files")
    return list_scan_files(directory)


def files_matrix(paths, axes=(AUTO, AUTO)) -> np.ndarray:
    """(4, 4) axis conversion of the scan files ``paths`` read with ``axes`` (forward, up; ``AUTO``: the
    format's convention); raises on invalid axes (call before reading)."""
    return conversion(os.path.splitext(paths[0])[1] if paths else "", *axes)


def _source(paths) -> str:
    """How messages name the files ``paths``: their folder, or the one file."""
    return (os.path.dirname(os.path.abspath(paths[0])) if len(paths) > 1 else paths[0]) if paths else ""


def check_before_reading(paths, options) -> None:
    """Refuse settings the input cannot serve and runs over the memory bound
    (:func:`solver.learn.memory.check_sizes`) from the file count and the first file's vertex count,
    before the other files are read; the message names the folder (or file)."""
    source = _source(paths)
    try:
        if paths:
            check_sizes(options, len(paths), len(read_mesh(paths[0]).vertices), source)
    except ArticulaInputError as exc:
        msg = str(exc)
        raise ArticulaInputError(msg if msg.startswith(source) else f"{source}: {msg}") from None


def check_input_sizes(inp: LearnInput, options) -> None:
    """:func:`solver.learn.memory.check_sizes` for scans already in memory (a scan-sequence object's)."""
    try:
        check_sizes(options, len(inp.scans), inp.scans.shape[1], repr(inp.source))
    except ArticulaInputError as exc:
        msg = str(exc)
        raise ArticulaInputError(msg if msg.startswith(repr(inp.source)) else f"{inp.source!r}: {msg}") from None


def input_from_files(paths, progress=None, matrix=None, options=None) -> LearnInput:
    """Read registered scans from mesh files (no bpy).  Coordinates and vertex order are kept as written;
    ``matrix``: where they stand in the scene (:func:`files_matrix`; None: that of the format's axes).
    ``options`` (:class:`LearnOptions`): checked against the sizes first (:func:`check_before_reading`)."""
    paths = list(paths)
    folder = os.path.dirname(os.path.abspath(paths[0])) if paths else ""
    source = _source(paths)
    if options is not None:
        if progress is not None:
            progress(0.0, f"checking {os.path.basename(paths[0])}")
        check_before_reading(paths, options)
    try:
        seq = read_scan_files(paths, progress, require_registered=True)
    except ArticulaInputError as exc:
        raise ArticulaInputError(f"{source}: {exc}") from None
    faces = seq.topology.triangles()
    check_scans(seq.frames, faces, source)
    name = os.path.basename(folder) if len(paths) > 1 else os.path.splitext(os.path.basename(source))[0]
    matrix = files_matrix(paths) if matrix is None else matrix
    return LearnInput(seq.frames.astype(np.float64), faces, source, name or "scans", matrix=matrix)


def skeleton_from_armature(ob, world_to_scans=None) -> Skeleton:
    """The bones of armature object ``ob`` in world coordinates as an initial skeleton (bones in
    breadth-first order from the single root; the control bones only for an Articula rig);
    ``world_to_scans`` (4, 4): map them into the scans' coordinates (the inverse of ``LearnInput.matrix``)."""
    if ob is None or ob.type != 'ARMATURE':
        raise ArticulaInputError(f"{getattr(ob, 'name', ob)!r} is not an armature")
    order, parent_of = _bones_breadth_first(ob)
    index = {b.name: i for i, b in enumerate(order)}
    mw = np.array(ob.matrix_world, dtype=np.float64)
    if world_to_scans is not None:
        mw = np.asarray(world_to_scans, np.float64) @ mw
    heads = np.array([b.head_local for b in order]) @ mw[:3, :3].T + mw[:3, 3]
    tails = np.array([b.tail_local for b in order]) @ mw[:3, :3].T + mw[:3, 3]
    frames = []
    for b in order:
        u, _, vt = np.linalg.svd(mw[:3, :3] @ np.array(b.matrix_local, dtype=np.float64)[:3, :3])
        frames.append(u @ vt)                            # nearest rotation (object scale removed)
    parents = [-1] + [index[parent_of(b).name] for b in order[1:]]
    sk = Skeleton([b.name for b in order], parents, heads, tails, np.array(frames))
    try:
        sk.validate()
    except ArticulaInputError as exc:
        raise ArticulaInputError(f"armature {ob.name!r}: {exc}") from None
    return sk


def _bones_breadth_first(ob):
    """``(bones in breadth-first order from the single root, parent_of)`` of armature ``ob``, the control
    bones only for an Articula rig; ``parent_of(bone)`` skips parents that are left out."""
    bones = list(ob.data.bones)
    if ob.articula.kind == 'RIG_ARMATURE':
        from ..rig.reader import control_names
        keep = set(control_names(ob))
        bones = [b for b in bones if b.name in keep]
    names = {b.name for b in bones}

    def parent_of(b):
        p = b.parent
        while p is not None and p.name not in names:
            p = p.parent
        return p

    roots = [b for b in bones if parent_of(b) is None]
    if len(roots) != 1:
        raise ArticulaInputError(f"armature {ob.name!r}: the initial skeleton needs exactly one root bone, found "
                                 f"{len(roots)} ({', '.join(b.name for b in roots[:4])})")
    order, queue = [], [roots[0]]
    while queue:
        b = queue.pop(0)
        order.append(b)
        queue += [c for c in bones if parent_of(c) is not None and parent_of(c).name == b.name]
    return order, parent_of
