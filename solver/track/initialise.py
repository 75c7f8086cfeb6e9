"""The first frame's pose without manual placement: global alignment plus several starting hypotheses.

The dissertation starts from a manual alignment or a known start pose (model-adaptive mocap dissertation
§4.1.2, §4.2); the issue asks for any upright pose and facing.  Hypotheses are body poses (the model's
training poses, spread, and the rest pose) times facings about the up axis (``FACINGS`` steps of 45 deg)
times the capture's possible up directions (the world up when the capture's longest principal axis is
within 45 deg of it, else both signs of that axis, for files written with another up axis).  Each is
placed by matching the centres of the model's and the capture's boxes (:func:`box_centre`) and scored
by the mean Charbonnier distance of capture points to the nearest normal-compatible model vertex (the
capture pairs of the tracker without trimming); the best ``keep`` are refined by a root-only ICP, the best
two of those by the full per-frame fit, and the lowest final Q wins.

Also here: :func:`check_units`, the early refusal of a model and captures in different units.
"""
from __future__ import annotations

import dataclasses
import os

import numpy as np

from ..errors import ArticulaInputError
from ..geometry.rotations import matrix_to_quat, quat_mul, quat_normalize, quat_to_matrix, rotation_between
from ..rig.model import Poses
from ..rig.skinning import hybrid_skin
from ..roles import bone_keys
from . import robust
from .correspondences import nearest_compatible
from .frame_fit import FrameFitOptions, fit_frame
from .limb_search import place_limbs
from ..geometry.normals import vertex_normals

GENERIC_POSES_PATH = os.path.join(os.path.dirname(os.path.abspath(__file__)), "data", "generic_body_poses.npz")
UP = np.array([0.0, 0.0, 1.0])     # the model's up axis (Blender world Z)
FACINGS = 8                        # facings tried about the up axis (45 deg apart)
SCORE_POINTS = 3000                # capture points scoring a hypothesis
SIZE_RATIO = (0.4, 2.5)            # capture extent / model height outside this: different units
ALIGN_ROUNDS = 4                   # translation-only ICP rounds per hypothesis
FAR_M = 1.0                        # score distance of a capture point with no compatible vertex


@dataclasses.dataclass
class Initialisation:
    """The chosen start: ``pose`` (one frame), its per-frame ``fit`` (:class:`.frame_fit.FrameFit`),
    ``tried`` hypotheses scored, ``refined`` of them fitted, and the ``scores`` of the best ones."""
    pose: Poses
    fit: object
    tried: int
    refined: int
    scores: list


def body_poses(skeleton, training_poses: Poses = None, count: int = 24, generic: bool = True) -> Poses:
    """Up to ``count`` body poses: the rest pose, the generic body poses (:func:`generic_body_poses`, walk
    frames: arms down, legs apart, which range-of-motion training poses rarely are) and the training
    poses, each set spread evenly (every k-th) over at most half of the rest; root rotation, translation
    and scale reset (the facing and position are searched)."""
    sets = [Poses.identity(1, skeleton.num_bones).rotations]
    extra = generic_body_poses(skeleton) if generic else None
    for source in (extra, training_poses):
        if source is not None and len(source) and count > 1:
            pick = np.unique(np.linspace(0, len(source) - 1, min(len(source), max(1, (count - 1) // 2)))
                             .round().astype(int))
            sets.append(source.rotations[pick])
    rot = np.concatenate(sets)
    rot[:, 0] = (1.0, 0.0, 0.0, 0.0)
    return Poses(rot, np.zeros((len(rot), 3)), np.ones(len(rot)))


def generic_body_poses(skeleton, path: str = GENERIC_POSES_PATH) -> Poses:
    """The shipped generic body poses (walk frames of the cmu_mb rig, ``tools/make_generic_poses.py``)
    mapped onto ``skeleton`` by bone role (:func:`solver.roles.bone_keys`), each local rotation re-expressed
    in the model's rest frame (``F'ᵀ F R Fᵀ F'``); bones that do not map stay at rest.  None when no bone
    other than the root maps."""
    with np.load(path, allow_pickle=False) as data:
        names, frames, rotations = list(data["names"]), data["frames"], data["rotations"]
    index = {k: i for i, k in enumerate(bone_keys([str(n) for n in names]))}
    out = Poses.identity(len(rotations), skeleton.num_bones)
    mapped = 0
    for b, key in enumerate(bone_keys(skeleton.names)[1:], start=1):
        s = index.get(key)
        if s is None or s == 0:
            continue
        C = skeleton.frames[b].T @ frames[s]
        R = C @ quat_to_matrix(rotations[:, s]) @ C.T
        out.rotations[:, b] = matrix_to_quat(R)
        mapped += 1
    return out if mapped else None


def check_units(model, points) -> None:
    """Refuse captures whose extent is not that of the model's body (``SIZE_RATIO``), naming both sizes:
    a capture in millimetres or centimetres against a model in metres is the usual cause."""
    if len(points) < 3:
        return
    lo, hi = np.percentile(points, [1, 99], axis=0)
    capture = float(np.max(hi - lo))
    body = float(np.ptp(model.rest_vertices, axis=0).max())
    ratio = capture / max(body, 1e-12)
    if not SIZE_RATIO[0] <= ratio <= SIZE_RATIO[1]:
        hint = ""
        for factor, unit in ((1000.0, "millimetres"), (100.0, "centimetres"), (1 / 0.0254, "inches")):
            if abs(np.log(ratio / factor)) < 0.7:
                hint = f" (about {factor:.4g}x: are the captures in {unit} and the model in metres?)"
        raise ArticulaInputError(f"captures and model differ in size: the capture spans {capture:.4g} units, "
                                 f"the model is {body:.4g} m tall{hint}; bring both to metres before tracking")


def up_candidates(points) -> list:
    """Up directions of the capture: world up when its longest principal axis is within 45 deg of it,
    else that axis in both signs."""
    centred = points - points.mean(axis=0)
    axis = np.linalg.eigh(centred.T @ centred)[1][:, -1]
    if abs(axis @ UP) >= np.cos(np.radians(45.0)):
        return [UP]
    return [axis, -axis]


def facing_rotations(up) -> list:
    """World rotations taking the model's up onto ``up`` followed by ``FACINGS`` turns about it."""
    base = rotation_between(UP, up)
    out = []
    for k in range(FACINGS):
        a = 2.0 * np.pi * k / FACINGS
        K = np.array([[0, -up[2], up[1]], [up[2], 0, -up[0]], [-up[1], up[0], 0]])
        out.append((np.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * K @ K) @ base)
    return out


def placed(model, pose: Poses, G, offset) -> Poses:
    """``pose`` moved rigidly: posed points x -> ``G x + offset`` (world rotation G (3, 3), metres).
    The root's local rotation becomes ``F₀ᵀ G F₀ R(q₀)`` and its translation follows (kinematics:
    ``M₀(x) = s R₀ (x − h₀) + h₀ + t``)."""
    F, h = model.skeleton.frames[0], model.skeleton.heads[0]
    g = matrix_to_quat(F.T @ G @ F)
    rot = pose.rotations.copy()
    rot[:, 0] = quat_normalize(quat_mul(np.broadcast_to(g, rot[:, 0].shape), rot[:, 0]))
    t = (pose.translations + h) @ G.T + offset - h
    return Poses(rot, t, pose.scales.copy())


def box_centre(points):
    """Centre of the box between the 2nd and 98th percentiles of ``points (N, 3)`` per axis: the model's
    vertex density (dense hands and face) differs from a capture's, so medians of the two disagree."""
    lo, hi = np.percentile(points, [2, 98], axis=0)
    return 0.5 * (lo + hi)


def _score(points, normals, vertices, vertex_normals_):
    """Median distance (m) of capture points to the nearest normal-compatible vertex: the trunk decides,
    limbs in another pose than the hypothesis' do not."""
    idx = nearest_compatible(vertices, vertex_normals_, points, normals)
    d = np.where(idx >= 0, np.linalg.norm(vertices[np.maximum(idx, 0)] - points, axis=1), FAR_M)
    return float(np.median(d))


def align_translation(points, normals, vertices, vertex_normals_, offset, rounds: int = ALIGN_ROUNDS):
    """Translation-only robust ICP: ``offset`` (3,) moved ``rounds`` times by the median of (capture
    point − nearest normal-compatible vertex) over the capture points; returns ``(offset, score)``
    (:func:`_score` at the final offset)."""
    tree_vertices = vertices + offset
    for _ in range(rounds):
        idx = nearest_compatible(tree_vertices, vertex_normals_, points, normals)
        ok = idx >= 0
        if not ok.any():
            break
        step = np.median(points[ok] - tree_vertices[idx[ok]], axis=0)
        offset, tree_vertices = offset + step, tree_vertices + step
    return offset, _score(points, normals, tree_vertices, vertex_normals_)


def hypotheses(model, capture, bodies: Poses, groups=None):
    """Every (body pose, up, facing) placed on the capture (box centres, then
    :func:`align_translation`) and scored (:func:`_score`); returns ``(score, pose)`` pairs, best first."""
    rng = np.random.default_rng(0)
    pick = rng.choice(len(capture.points), min(SCORE_POINTS, len(capture.points)), replace=False)
    pts, nrm = capture.points[pick], capture.normals[pick]
    centre = box_centre(capture.points)
    posed = hybrid_skin(model, bodies, groups)
    out = []
    for k in range(len(bodies)):
        body = bodies.take(k)
        for up in up_candidates(capture.points):
            for G in facing_rotations(up):
                v = posed[k] @ G.T
                offset, score = align_translation(pts, nrm, v, vertex_normals(v, model.faces), centre - box_centre(v))
                out.append((score, placed(model, body, G, offset)))
    out.sort(key=lambda item: item[0])
    return out


def initialise(model, capture, prior=None, training_poses: Poses = None, options: FrameFitOptions = FrameFitOptions(),
               groups=None, count: int = 24, keep: int = 6, extra: list = (), check: bool = True, limbs: bool = True) -> Initialisation:
    """The first frame's pose of ``model`` on ``capture`` (module docstring).  ``count`` body poses,
    ``keep`` hypotheses refined by a root-only ICP, two by the full fit; ``extra`` poses (e.g. the
    previous frame's when a frame is lost) join the full fits; check: refuse a capture of another size
    (:func:`check_units`; off for re-initialising a frame of a recording already accepted)."""
    if check:
        check_units(model, capture.points)
    scored = hypotheses(model, capture, body_poses(model.skeleton, training_poses, count), groups)
    root = _root_only(options)
    coarse = []
    for score, pose in scored[:keep]:
        fit = fit_frame(model, capture, pose, None, root, groups)
        coarse.append((float(fit.log["Q"].min()), fit.pose))
        if limbs:
            placed_ = place_limbs(model, fit.pose, capture.points, groups)
            fit = fit_frame(model, capture, placed_, None, root, groups)
            coarse.append((float(fit.log["Q"].min()), fit.pose))
    coarse.sort(key=lambda item: item[0])
    best = None
    for _, pose in coarse[:2] + [(None, p) for p in extra]:
        fit = fit_frame(model, capture, pose, prior, options, groups)
        q = float(fit.log["Q"].min())
        if best is None or q < best[0]:
            best = (q, fit)
    return Initialisation(best[1].pose, best[1], len(scored), len(coarse) + 2 + len(extra),
                          [s for s, _ in scored[:keep]])


def _root_only(options: FrameFitOptions, updates: int = 6) -> FrameFitOptions:
    """Options of a short ICP moving only the root: one stage at depth 0 that uses the whole budget of
    ``updates``, so the final all-bones stage only measures."""
    return dataclasses.replace(options, depth_stages=(0,), coarse_iterations=updates, max_iterations=updates,
                               coarse_rel_tol=1e-3, coarse_lm_steps=2)
