"""Learning a rig from registered scans, on the Blender side (issue 4): where the scans come from, the
solver run with progress, and the rig it becomes in the scene.

Pipeline (what ``articula.learn_rig``, the ``learn-rig`` batch command and the demo call):

1. input: :func:`input_from_object` (a registered scan-sequence object; main thread, reads its frame
   cache) or :func:`input_from_files` (OBJ/PLY/STL/OFF files or a folder; no bpy), checked by
   :func:`check_scans` (at least 3 scans, finite coordinates, triangles);
2. :func:`learn` (no bpy: runs in the worker thread) calls :func:`solver.learn.pipeline.learn_rig`, turning its
   ``progress(fraction, stage, objective)`` into the job's ``progress(fraction, text)``; the per-vertex
   error is the solver's distance of every scan vertex to the posed model's surface
   (``LearnResult.scan_distances``), averaged over the scans (:func:`vertex_error_mm` recomputes it);
3. :func:`build` (main thread, inside ``scene_guard``) builds the exact swing/twist rig with the rig
   builder from an in-memory bundle, bakes the poses on the scan-sequence object's frames (scan k on
   frame ``frame_start + k``, so scrubbing replays the scans with the learned rig), adds the heat map
   (FLOAT point attribute ``articula_error_mm`` and FLOAT_COLOR point attribute
   ``articula_error_color``, made the active and render colour) and stores the solver's report as JSON
   in the armature's ID property ``articula_learn_report``;
4. :func:`save` writes the bundle (input coordinates and vertex order unchanged, one pose per scan in
   scan order, the report in its provenance).

:func:`learn_from_object` runs 1-3 synchronously (for the demo and scripts).
"""
from __future__ import annotations

import json
import os
from dataclasses import dataclass, field

import bpy
import numpy as np

from ...solver.formats.bundle import Bundle, save_bundle
from ...solver.errors import ArticulaInputError
from ...solver.learn.key_scans import KEY_SCANS
from ...solver.learn.pipeline import JOINT_PRIOR, learn_rig
from ...solver.rig.model import Skeleton
from ...solver.formats.scan_files import list_scan_files, natural_sorted, read_scan_files
from ...solver.rig.skinning import hybrid_skin
from ...solver.geometry.surface_distance import per_vertex_scan_distances
from ..rig import builder as rig_builder
from ..rig import bundle_io as rig_io
from ..sequences import scans as scan_sequence

MIN_SCANS = 3
ERROR_ATTRIBUTE = "articula_error_mm"
COLOR_ATTRIBUTE = "articula_error_color"
SCALE_PROPERTY = "articula_error_scale_mm"      # mesh ID property: the error the ramp's top colour means
REPORT_PROPERTY = "articula_learn_report"       # armature ID property: the solver's report (JSON)

# Heat-map colour ramp (linear RGB): 0 mm blue -> cyan -> green -> yellow -> red at the scale's top.
RAMP_POSITIONS = (0.0, 0.25, 0.5, 0.75, 1.0)
RAMP_COLORS = ((0.0, 0.05, 1.0), (0.0, 0.8, 1.0), (0.0, 1.0, 0.1), (1.0, 0.9, 0.0), (1.0, 0.0, 0.0))


@dataclass
class LearnInput:
    """Registered scans ``(M, V, 3)`` metres and their triangles ``(F, 3)``, where they came from
    (``source``: the object name or folder), the scene frame of scan 0, and a default rig name."""
    scans: np.ndarray
    faces: np.ndarray
    source: str
    name: str
    frame_start: int = 1
    object_name: str = ""


@dataclass
class LearnOptions:
    parts: int = 0                  # 0: chosen from the motion
    alpha: float = 100.0
    symmetry: bool = True
    max_iterations: int = 4         # outer rounds after the warm start (solver default); 0: initialisation only
    seed: int = 0
    initial_skeleton: Skeleton | None = None
    key_scans: int = KEY_SCANS      # learn from at most this many scans, fit the others' poses; 0: all
    workers: int = 0                # solver threads; 0: one per CPU core (the preferences' Threads)
    joint_prior: float = JOINT_PRIOR  # ρ of the joint-centre prior (solver.learn.pipeline.learn_rig); 0: none

    def solver_kwargs(self) -> dict:
        return dict(parts=self.parts or None, alpha=float(self.alpha), symmetry=bool(self.symmetry),
                    max_iterations=int(self.max_iterations), seed=int(self.seed),
                    initial_skeleton=self.initial_skeleton, key_scans=int(self.key_scans) or None,
                    workers=int(self.workers), joint_prior=float(self.joint_prior))


@dataclass
class LearnOutcome:
    """What :func:`learn` returns: the input, the solver's result (``model``, ``poses``, ``report``) and
    the per-vertex mean distance to the scans in mm ``(V,)``."""
    input: LearnInput
    result: object
    vertex_error_mm: np.ndarray
    options: LearnOptions = field(default_factory=LearnOptions)

    @property
    def model(self):
        return self.result.model

    @property
    def poses(self):
        return self.result.poses

    @property
    def report(self) -> dict:
        return self.result.report


# ------------------------------------------------------------------------------------------- input

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
    return LearnInput(scans.astype(np.float64), faces, ob.name, ob.name, int(ob.articula.frame_start), ob.name)


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


def input_from_files(paths, progress=None) -> LearnInput:
    """Read registered scans from mesh files (no bpy).  Coordinates and vertex order are kept as written."""
    paths = list(paths)
    folder = os.path.dirname(os.path.abspath(paths[0])) if paths else ""
    source = folder if len(paths) > 1 else (paths[0] if paths else "")
    try:
        seq = read_scan_files(paths, progress, require_registered=True)
    except ArticulaInputError as exc:
        raise ArticulaInputError(f"{source}: {exc}") from None
    faces = seq.topology.triangles()
    check_scans(seq.frames, faces, source)
    name = os.path.basename(folder) if len(paths) > 1 else os.path.splitext(os.path.basename(source))[0]
    return LearnInput(seq.frames.astype(np.float64), faces, source, name or "scans")


def skeleton_from_armature(ob) -> Skeleton:
    """The bones of armature object ``ob`` in world coordinates as an initial skeleton (bones in
    breadth-first order from the single root; the control bones only for an Articula rig)."""
    if ob is None or ob.type != 'ARMATURE':
        raise ArticulaInputError(f"{getattr(ob, 'name', ob)!r} is not an armature")
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
    index = {b.name: i for i, b in enumerate(order)}
    mw = np.array(ob.matrix_world, dtype=np.float64)
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


# ------------------------------------------------------------------------------------------- learning

def learn(inp: LearnInput, options: LearnOptions, progress=None) -> LearnOutcome:
    """Run the solver (no bpy).  ``progress(fraction, text)`` may raise ``Cancelled``."""
    def report(fraction, stage, objective=None):
        if progress is not None:
            q = "" if objective is None else f"  Q = {float(objective):.6g}"
            progress(0.95 * float(fraction), f"{stage}{q}")

    result = learn_rig(inp.scans, inp.faces, progress=report, **options.solver_kwargs())
    heat = 1000.0 * result.scan_distances.mean(axis=0)      # the distances the solver's report summarises
    if progress is not None:
        progress(1.0, "done")
    return LearnOutcome(inp, result, heat, options)


def vertex_error_mm(model, poses, scans, faces=None) -> np.ndarray:
    """Heat map ``(V,)``: for every vertex v, the mean over the scans of the distance (mm) of scan vertex v
    to the posed model's surface (the rig mesh keeps the scans' vertex order).  This is the distance the
    solver's ``surface_error_mm`` statistics summarise, so the heat map's mean is their mean."""
    posed = hybrid_skin(model, poses)
    return 1000.0 * per_vertex_scan_distances(scans, posed, model.faces).mean(axis=0)


def error_summary(report: dict) -> dict:
    """The error statistics in mm from the solver's report (keys mean, median, max, ...)."""
    for key in ("surface_error_mm", "error_mm"):
        if isinstance(report.get(key), dict):
            return report[key]
    return {k: report[k] for k in ("mean", "std", "median", "mad", "iqr", "max") if k in report}


def summary_text(outcome: LearnOutcome) -> str:
    s = error_summary(outcome.report)
    parts = [f"{k} {s[k]:.2f}" for k in ("mean", "median", "max") if k in s]
    return "error (mm) " + ", ".join(parts) if parts else "no error statistics"


# ------------------------------------------------------------------------------------------- scene

def error_colors(values_mm, scale_mm: float) -> np.ndarray:
    """RGBA ``(V, 4)`` float32 of errors through the heat-map ramp (0 -> blue, ``scale_mm`` and above -> red)."""
    t = np.clip(np.asarray(values_mm, np.float64) / max(float(scale_mm), 1e-12), 0.0, 1.0)
    rgb = np.stack([np.interp(t, RAMP_POSITIONS, [c[i] for c in RAMP_COLORS]) for i in range(3)], axis=1)
    return np.column_stack([rgb, np.ones(len(t))]).astype(np.float32)


def add_heat_map(me, values_mm, scale_mm: float = None) -> float:
    """Write the per-vertex error (mm) as ``articula_error_mm`` and its ramp colours as
    ``articula_error_color`` (active and render colour attribute).  Returns the ramp's scale in mm
    (default: the largest value)."""
    values = np.ascontiguousarray(values_mm, np.float32)
    if len(values) != len(me.vertices):
        raise ArticulaInputError(f"{me.name}: {len(values)} error values for {len(me.vertices)} vertices")
    scale = float(values.max()) if scale_mm is None and len(values) else float(scale_mm or 0.0)
    scale = max(scale, 1e-3)
    for name in (ERROR_ATTRIBUTE, COLOR_ATTRIBUTE):
        old = me.attributes.get(name)
        if old is not None:
            me.attributes.remove(old)
    me.attributes.new(ERROR_ATTRIBUTE, 'FLOAT', 'POINT').data.foreach_set("value", values)
    color = me.color_attributes.new(COLOR_ATTRIBUTE, 'FLOAT_COLOR', 'POINT')
    color.data.foreach_set("color", error_colors(values, scale).ravel())
    me.color_attributes.active_color = color
    me.color_attributes.render_color_index = me.color_attributes.active_color_index
    me[SCALE_PROPERTY] = scale
    return scale


def _jsonable(x):
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return _jsonable(x.tolist())
    if isinstance(x, np.generic):
        return x.item()
    return x


def report_json(outcome: LearnOutcome) -> dict:
    """The solver's report with the run's input and options (JSON-serialisable)."""
    opts = outcome.options
    return _jsonable({**outcome.report,
                      "input": {"source": outcome.input.source, "scans": int(len(outcome.input.scans)),
                                "vertices": int(outcome.input.scans.shape[1]),
                                "faces": int(len(outcome.input.faces))},
                      "options": {"parts": opts.parts, "alpha": opts.alpha, "symmetry": opts.symmetry,
                                  "max_iterations": opts.max_iterations, "seed": opts.seed,
                                  "key_scans": opts.key_scans, "workers": opts.workers,
                                  "joint_prior": opts.joint_prior,
                                  "initial_skeleton": opts.initial_skeleton is not None}})


def build(context, outcome: LearnOutcome, name: str = ""):
    """Build the learned rig, bake one key per scan on the scans' frames and add the heat map.
    Returns ``(rig, action)``.  Call inside ``scene_guard``."""
    inp = outcome.input
    bundle = Bundle(outcome.model, outcome.poses, {"source": "learn_rig", "scans": inp.source})
    rig_builder.check_model(bundle.model, bundle.poses)
    rig, action = rig_io.build_bundle(context, bundle, name or f"{inp.name} Rig", True, inp.frame_start)
    add_heat_map(rig.mesh.data, outcome.vertex_error_mm)
    rig.armature[REPORT_PROPERTY] = json.dumps(report_json(outcome))
    return rig, action


def check_output_path(path: str) -> None:
    if path:
        folder = os.path.dirname(os.path.abspath(path))
        if not os.path.isdir(folder):
            raise ArticulaInputError(f"{path}: folder {folder!r} does not exist")


def save(path: str, outcome: LearnOutcome) -> None:
    """Write the learned model and its per-scan poses (scan order) to a bundle; the report goes into
    the provenance."""
    check_output_path(path)
    try:
        save_bundle(path, outcome.model, outcome.poses,
                    {"source": "learn_rig", "scans": outcome.input.source, "report": report_json(outcome)})
    except OSError as exc:
        raise ArticulaInputError(f"{path}: cannot write the bundle ({exc.strerror or exc})") from None


def learn_from_object(context, ob, options: LearnOptions = None, name: str = "", progress=None):
    """Learn a rig from scan-sequence object ``ob`` and build it, synchronously (for the demo and
    scripts).  Returns ``(rig, action, outcome)``; on failure the scene is left as it was."""
    from ..jobs import scene_guard
    inp = input_from_object(ob)
    outcome = learn(inp, options or LearnOptions(), progress)
    with scene_guard():
        rig, action = build(context, outcome, name)
    return rig, action, outcome
