"""Retargeting through shared mesh topology (dissertation (model-adaptive mocap) Sec. 4.2.3, Fig. 4.17;
docs/retarget_topology.md).

When a source and a target model share their mesh (same vertex count and faces, vertex v of one is
vertex v of the other), the target's pose in frame n is fitted to the source's posed vertices through
that one-to-one correspondence instead of copying joint angles:

    θ_n = argmin_θ Σ_v ‖hybrid_skin(target, θ)_v − y_n,v‖²,   y_n = hybrid_skin(source, θ_src,n)

over the target's root translation and bone rotations (its rest shape, skin and joints stay fixed), by
the Levenberg–Marquardt pose fit :func:`solver.fit.pose_fit.fit_poses`.  By default ``y_n`` are the
source's posed vertices as they are (the dissertation's plain correspondence fit): the fit places the
target to overlap the source, root translation included, which is the point of the method and why the
root translation is not copied.  When the bodies differ in size, an optional ratio ``r`` (target height
/ source height, or any number) maps them about the floor points ``c`` below each model's root joint
(world Z up), so a bigger target need not crouch into the smaller source's silhouette and its root
travels r times as far: ``y_n = c_t + r (hybrid_skin(source, θ_src,n) − c_s)``.

Copying parameters (:func:`copy_parameters`: bone rotations by name, root translation times r) is the
naive baseline and the fit's first initial guess; each frame starts from the better (lower energy) of
the copy and the per-part Procrustes initialisation of the pose fit.  Lengths in metres.
"""
import time

import numpy as np

from ..errors import ArticulaInputError
from ..fit.pose_fit import fit_poses, procrustes_init
from ..rig.model import Poses
from ..rig.skinning import AnchorGroups, check_pose_shapes, hybrid_skin

UP = 2                      # world Z is up (floor points, heights)
MAX_ITERATIONS = 20         # LM iterations per frame (from the copied pose it converges in about 10)


def check_shared_topology(source_model, target_model) -> None:
    """Raise :class:`ArticulaInputError` unless both models have the same vertex count and the same
    faces ``(F, 3)`` (the same triangles in the same order; a triangle may start at another corner)."""
    Vs, Vt = source_model.num_vertices, target_model.num_vertices
    Fs, Ft = np.asarray(source_model.faces), np.asarray(target_model.faces)
    if Vs != Vt or len(Fs) != len(Ft):
        raise ArticulaInputError(
            f"the source and target meshes do not share their topology: the source has {Vs} vertices and "
            f"{len(Fs)} faces, the target {Vt} vertices and {len(Ft)} faces")
    if np.array_equal(Fs, Ft):
        return
    same = (_rotated(Fs) == _rotated(Ft)).all(axis=1)
    if not same.all():
        f = int(np.flatnonzero(~same)[0])
        raise ArticulaInputError(
            f"the source and target meshes do not share their topology: both have {Vs} vertices and "
            f"{len(Fs)} faces, but face {f} joins vertices {Fs[f].tolist()} in the source and "
            f"{Ft[f].tolist()} in the target")


def _rotated(faces):
    """Each triangle ``(F, 3)`` rotated to start at its smallest vertex (orientation kept)."""
    k = np.argmin(faces, axis=1)
    idx = (k[:, None] + np.arange(3)) % 3
    return np.take_along_axis(faces, idx, axis=1)


def bone_map(source_skeleton, target_skeleton) -> np.ndarray:
    """``(B_target,)`` int: the source bone of each target bone with the same name, −1 where none."""
    index = {n: i for i, n in enumerate(source_skeleton.names)}
    return np.array([index.get(n, -1) for n in target_skeleton.names], dtype=np.int64)


def height(model) -> float:
    """Rest height of a model: the extent of its rest vertices along world Z (metres)."""
    z = model.rest_vertices[:, UP]
    return float(z.max() - z.min())


def size_ratio(source_model, target_model, scale=None) -> float:
    """The ratio r of the module docstring: None -> 1 (no mapping), ``"height"`` -> target height /
    source height, or a positive number as given."""
    if scale is None:
        return 1.0
    if isinstance(scale, str):
        if scale != "height":
            raise ArticulaInputError(f"scale: expected None, 'height' or a positive number, got {scale!r}")
        hs, ht = height(source_model), height(target_model)
        if hs <= 0 or ht <= 0:
            raise ArticulaInputError("scale: a model has zero height along Z; give the ratio as a number")
        return ht / hs
    r = float(scale)
    if not np.isfinite(r) or r <= 0:
        raise ArticulaInputError(f"scale: the size ratio must be a positive number, got {scale!r}")
    return r


def floor_point(model) -> np.ndarray:
    """(3,) the point on the model's floor (lowest rest vertex along Z) below its root joint."""
    c = model.skeleton.heads[0].copy()
    c[UP] = model.rest_vertices[:, UP].min()
    return c


def copy_parameters(source_model, source_poses, target_model, scale=None) -> Poses:
    """The naive retarget: each target bone takes the rotation (bone-local quaternion) of the source bone
    with its name (bones without one stay at rest), the root translation is copied times the size ratio
    (:func:`size_ratio`), the subject scale as it is.  Returns :class:`Poses` (N frames, target bones)."""
    check_pose_shapes(source_model, source_poses)
    r = size_ratio(source_model, target_model, scale)
    idx = bone_map(source_model.skeleton, target_model.skeleton)
    out = Poses.identity(len(source_poses), target_model.skeleton.num_bones)
    have = idx >= 0
    out.rotations[:, have] = source_poses.rotations[:, idx[have]]
    out.translations = r * source_poses.translations
    out.scales = source_poses.scales.copy()
    return out


def target_vertices(source_model, source_poses, target_model, scale=None, groups=None) -> np.ndarray:
    """The vertices ``(N, V, 3)`` the target is fitted to: the source's posed vertices, mapped by the size
    ratio about the floor points when ``scale`` is given (module docstring)."""
    return _mapped(source_model, target_model, scale, hybrid_skin(source_model, source_poses, groups))


def _mapped(source_model, target_model, scale, x):
    """Source-space points ``x (..., 3)`` in the target's space: as they are when ``scale`` is None,
    else ``c_t + r (x − c_s)`` (module docstring)."""
    if scale is None:
        return x
    r = size_ratio(source_model, target_model, scale)
    return floor_point(target_model) + r * (x - floor_point(source_model))


def _rms(model, poses, y, groups):
    """Per-frame RMS distance ``(N,)`` (metres) of the posed ``model`` from ``y (N, V, 3)``."""
    return np.sqrt(((hybrid_skin(model, poses, groups) - y) ** 2).sum(axis=2).mean(axis=1))


def _initial_poses(target_model, copied, y, groups):
    """Per frame the better (lower RMS) of the copied pose and the Procrustes initialisation (with the
    source's subject scale, which the fit keeps); returns ``(poses, from_copy (N,) bool)``."""
    rms_copy = _rms(target_model, copied, y, groups)
    proc = procrustes_init(target_model, y)
    proc.scales = copied.scales.copy()
    from_copy = rms_copy <= _rms(target_model, proc, y, groups)
    for key in ("rotations", "translations", "scales"):
        getattr(proc, key)[from_copy] = getattr(copied, key)[from_copy]
    return proc, from_copy


def retarget_topology(source_model, source_poses, target_model, scale=None,
                      max_iterations=MAX_ITERATIONS, progress=None):
    """Fit the target's poses to the source's posed vertices (module docstring).

    source_poses: :class:`Poses` (N frames) of the source; scale: None, ``"height"`` or a ratio
    (:func:`size_ratio`); progress: optional ``progress(fraction, text)`` (may raise ``Cancelled``).
    Returns ``(poses, report)``: the target's :class:`Poses` (N frames) and a dict with, per frame,
    ``rms_fit`` and ``rms_copy`` (N,) (RMS posed-vertex distance to the fitted-to vertices, metres, of
    the fit and of :func:`copy_parameters`), ``from_copy`` (N,) bool (the fit started from the copy,
    else from Procrustes), ``iterations`` (N,), ``converged`` (N,) bool, ``root_offset`` (N,) (‖fitted − copied root
    translation‖, metres); and ``rms_rest`` (the RMS distance of the two rest meshes after the size
    mapping: how different the bodies are), ``scale`` (r), ``bones_copied``, ``frames``, ``seconds`` (wall time)."""
    start = time.perf_counter()
    check_shared_topology(source_model, target_model)
    check_pose_shapes(source_model, source_poses)
    if len(source_poses) == 0:
        raise ArticulaInputError("source poses: no frames to retarget")
    r = size_ratio(source_model, target_model, scale)
    y = target_vertices(source_model, source_poses, target_model, scale)
    groups = AnchorGroups(target_model)
    copied = copy_parameters(source_model, source_poses, target_model, scale)
    init, from_copy = _initial_poses(target_model, copied, y, groups)
    fit = fit_poses(target_model, y, init=init, max_iterations=max_iterations, groups=groups,
                    progress=progress)
    rest = _mapped(source_model, target_model, scale, source_model.rest_vertices)
    report = dict(
        rms_fit=fit.rms, rms_copy=_rms(target_model, copied, y, groups), from_copy=from_copy,
        iterations=fit.iterations, converged=fit.converged,
        root_offset=np.linalg.norm(fit.poses.translations - copied.translations, axis=1),
        rms_rest=float(np.sqrt(((rest - target_model.rest_vertices) ** 2).sum(axis=1).mean())), scale=r,
        bones_copied=int((bone_map(source_model.skeleton, target_model.skeleton) >= 0).sum()),
        frames=len(source_poses), seconds=time.perf_counter() - start)
    return fit.poses, report
