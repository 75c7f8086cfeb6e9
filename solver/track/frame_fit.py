"""One frame's pose of a fixed model fitted to an unregistered capture: ICP with a robust data term, the
pose prior and box limits.

Model-adaptive mocap dissertation §4.1.3-4.1.4 (a): correspondences are refreshed before every update
(:func:`.correspondences.correspondences` on the posed model), then one Levenberg–Marquardt update
(:func:`solver.fit.least_squares.levenberg_marquardt` with the Armijo line search) minimises, with the
pairs and their IRLS weights ω_c held fixed, the least-squares majoriser of ``Q^data + w_pose Q^pose``:

    E(p) = (1 / 2C) Σ_c ω_c ‖m_c(p) − y_c‖² + (w_pose / P) Σ_p e_p(p)²      (m; C pairs, P prior pairs)

where the model point ``m_c = Σ_i β_ci x'_{v_ci}`` is a barycentric combination of skinned vertices, so
its Jacobian is the same combination of the vertex Jacobians (:func:`solver.rig.jacobians.dense_jacobian`),
and ``e_p = sqrt(1 − P~_p)`` are the pose prior's residuals (:mod:`solver.tracking.pose_prior`).  Parameters: root
translation, optional uniform scale, the root rotation and every joint rotation in the layout of
:func:`solver.rig.jacobians.pose_layout`.

Box limits (§4.1.4, active set): a bone with a finite bound is parametrised additively in its exp-map
vector r (``δ = J_r⁻¹ Δr`` to first order, exact on update), so a DoF that a step would push outside its
interval is clamped onto the bound, its row and column leave the damped system (its fixed value moves to
the right-hand side) and the system is solved again until no further DoF is violated.

Model pairs (model vertex -> capture point) are point-to-plane by default: their residual is
``n (n · (x'_v − y))`` along the capture normal n, since the nearest noisy capture point of a vertex is
biased sideways and inwards (docs/track.md "Per-frame fit").  Coarse to fine: ICP stages with only the
bones up to a tree depth free (``depth_stages``, root first), each from the previous stage's result, then
all bones, so that extremities are not caught by neighbouring parts while the trunk is still far off.

Stopping, per stage: the relative change of Q between two refreshes below ``rel_tol`` (1e-4), or
``max_iterations`` (50) updates over all stages; non-monotone: Q may rise for ``patience`` (5) refreshes,
the best pose seen is returned.
Units: metres and radians.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import scipy.sparse as sp

from ..errors import ArticulaInputError
from ..fit.least_squares import ArmijoLineSearch, FixedRatioDamping, Limits, levenberg_marquardt, solve_damped
from ..parallel import single_blas_thread
from ..geometry.rotations import quat_canonical, quat_normalize, quat_to_rotvec, rotvec_to_quat
from ..rig.jacobians import apply_pose_increment, dense_jacobian
from ..rig.model import Poses
from ..rig.skinning import AnchorGroups, check_pose_shapes, hybrid_skin
from . import robust
from .correspondences import CorrespondenceOptions, correspondences
from ..tracking.pose_prior import PosePrior, rotvec_increment_jacobian
from ..geometry.normals import vertex_normals
from ..tracking.limbs import bone_depths

DAMP_FLOOR = 1e-9      # ε of the damping matrix diag(H) + ε mean diag(H)
MU0, MU_MIN = 1e-3, 1e-8   # damping relative to diag H (Marquardt's scaling): start and floor
REJECTIONS = 14        # rejected damped steps (×10 each) before an update gives up (μ from the floor to 1e6)


@dataclasses.dataclass
class Capture:
    """One unregistered capture: ``points (N, 3)`` metres, unit ``normals (N, 3)``, ``triangles (G, 3)``
    or None (point cloud), ``cameras``: list of ``(cam_to_world (4, 4), Intrinsics)`` or None."""
    points: np.ndarray
    normals: np.ndarray
    triangles: np.ndarray = None
    cameras: list = None

    @classmethod
    def from_mesh(cls, points, triangles, cameras=None) -> "Capture":
        """A triangulated capture with area-weighted vertex normals."""
        return cls(np.asarray(points, np.float64), vertex_normals(points, triangles), np.asarray(triangles),
                   cameras)


@dataclasses.dataclass(frozen=True)
class FrameFitOptions:
    """Settings of :func:`fit_frame`.  w_pose: weight of Q^pose (the dissertation's value for metre-scale
    data, §4.1.5); fit_scale: also fit the uniform scale; lm_steps: accepted damped steps per
    correspondence refresh (1: the dissertation's ICP); to_plane: which pairs' residual is the distance
    along the capture point's normal (point-to-plane) instead of the 3-D difference: "none", "model"
    (model pairs: the nearest noisy capture point to a vertex is biased sideways and inwards,
    docs/track.md "Per-frame fit") or "all"; depth_stages: coarse-to-fine, one ICP stage per entry
    with only the bones at most that deep in the tree free (0: root only), then all bones; each coarse
    stage stops at ``coarse_rel_tol``, takes ``coarse_lm_steps`` steps per refresh and at most
    ``coarse_iterations`` updates (all stages share ``max_iterations``)."""
    w_pose: float = 1e-3
    fit_scale: bool = False
    max_iterations: int = 50
    rel_tol: float = 1e-4
    patience: int = 5
    lm_steps: int = 1
    line_search: bool = True
    to_plane: str = "model"
    depth_stages: tuple = (0, 3, 6)
    coarse_rel_tol: float = 1e-3
    coarse_lm_steps: int = 2
    coarse_iterations: int = 10
    correspondence: CorrespondenceOptions = CorrespondenceOptions()


@dataclasses.dataclass
class FrameFit:
    """Result of :func:`fit_frame`.  pose: :class:`Poses` of one frame (the best Q seen); stats: of its
    correspondences: ``median_mm``, ``mean_mm`` (capture point to model, capture pairs), ``removed_capture``,
    ``removed_model`` (fractions trimmed), ``capture_pairs``, ``model_pairs`` (kept); iterations: updates
    made; converged: the relative change fell below rel_tol (False: iteration or patience limit);
    log: per refresh ``Q``, ``data`` (Q^data, m), ``pose`` (Q^pose), ``pairs``, ``trials`` (damped systems
    solved by the update after it)."""
    pose: Poses
    stats: dict
    iterations: int
    converged: bool
    log: dict


def pair_residuals(pairs, posed, plane=None):
    """``(C, 3)`` residuals ``m_c − y_c`` of ``pairs`` on the posed vertices ``posed (V, 3)``; the rows of
    the ``plane (C,)`` mask are projected onto the target's normal (point-to-plane: ``n (n · e)``)."""
    e = pairs.model_points(posed) - pairs.targets
    if plane is not None:
        n = pairs.target_normals[plane]
        e[plane] = n * np.einsum("cj,cj->c", n, e[plane])[:, None]
    return e


def data_system(J, posed, pairs, scale, plane=None):
    """Normal equations of ``Σ_c scale_c ‖e_c‖²`` (:func:`pair_residuals`; ``plane (C,)`` bool or None):
    ``H (P, P)``, ``g (P,)`` (half the gradient) and the value, from the vertex Jacobian ``J (V, 3, P)``,
    posed vertices ``posed (V, 3)``, ``pairs`` (:class:`.correspondences.Correspondences`: vertex_ids,
    weights β, targets y, target normals n) and ``scale (C,)``.  Point pairs: ``H = Jᵀ (A ⊗ I₃) J`` with the
    sparse vertex coupling ``A = Σ_c scale_c β_c β_cᵀ`` over the vertices they use, so no per-pair Jacobian
    is formed; plane pairs add ``Σ_c scale_c j_c j_cᵀ`` with the row ``j_c = Σ_i β_ci n_cᵀ J_{v_ci}``."""
    plane = np.zeros(len(scale), dtype=bool) if plane is None else plane
    H, g, E = _point_system(J, posed, _subset(pairs, ~plane), scale[~plane])
    if plane.any():
        sub, s = _subset(pairs, plane), scale[plane]
        rows = np.einsum("ci,ck,cikp->cp", sub.weights, sub.target_normals, J[sub.vertex_ids])
        r = np.einsum("cj,cj->c", sub.target_normals, sub.model_points(posed) - sub.targets)
        H, g, E = H + rows.T @ (s[:, None] * rows), g + rows.T @ (s * r), E + float(s @ (r * r))
    return H, g, E


def _subset(pairs, mask):
    """The rows ``mask`` of the pairs' arrays that :func:`data_system` reads."""
    return dataclasses.replace(pairs, vertex_ids=pairs.vertex_ids[mask], weights=pairs.weights[mask],
                               targets=pairs.targets[mask], target_normals=pairs.target_normals[mask])


def _point_system(J, posed, pairs, scale):
    """:func:`data_system` of point-to-point pairs only."""
    P = J.shape[-1]
    if not len(scale):
        return np.zeros((P, P)), np.zeros(P), 0.0
    used, local = np.unique(pairs.vertex_ids, return_inverse=True)
    local = local.reshape(pairs.vertex_ids.shape)
    e = np.einsum("ci,cij->cj", pairs.weights, posed[pairs.vertex_ids]) - pairs.targets
    U = len(used)
    Ju = J[used]
    sb = scale[:, None] * pairs.weights                                          # (C, 3)
    A = sp.csr_matrix(((sb[:, :, None] * pairs.weights[:, None, :]).ravel(),
                       (np.repeat(local, 3, axis=1).ravel(), np.tile(local, (1, 3)).ravel())), shape=(U, U))
    K = A @ Ju.reshape(U, 3 * P)
    H = Ju.reshape(3 * U, P).T @ K.reshape(3 * U, P)
    b = np.stack([np.bincount(local.ravel(), (sb[:, :, None] * e[:, None, :])[..., k].ravel(), U)
                  for k in range(3)], axis=1)
    return H, np.einsum("ukp,uk->p", Ju, b), float(np.einsum("c,cj,cj->", scale, e, e))


def pose_columns(num_bones, fit_scale):
    """Jacobian pieces of :func:`solver.rig.jacobians.dense_jacobian` in the ``pose_layout`` columns."""
    return {"t": 0, **({"s": 3} if fit_scale else {}), **{("rot", b): 4 + 3 * b for b in range(num_bones)}}


def active_set_solve(H, g, mu, z, violations):
    """Box limits as an active set (model-adaptive mocap dissertation §4.1.4): from the damped step ``z``
    of ``H z = −g``, entries that ``violations(z) -> (bad (n,) bool, value (n,))`` flags are clamped to
    ``value`` and leave the system (their value moves to the right-hand side), which is solved again until
    nothing else is violated.  Returns the step ``(n,)``."""
    active = np.zeros(len(z), dtype=bool)
    for _ in range(len(z)):
        bad, value = violations(z)
        bad &= ~active
        if not bad.any():
            break
        active |= bad
        z[active] = value[active]
        f = ~active
        rhs = g[f] + H[f][:, active] @ z[active]
        z[f] = solve_damped(H[f][:, f][None], rhs[None], mu, DAMP_FLOOR)[0]
    return z


class QuadraticSteps:
    """The LM core's step model for a problem of size 1 holding its damped system as ``H (P, P)`` and
    ``g (P,)`` (half the gradient): slope, predicted decrease and step norm of steps ``(k, P)``."""

    def slope(self, idx, steps):
        return 2.0 * steps @ self.g

    def predicted_decrease(self, idx, steps):
        return -2.0 * steps @ self.g - np.einsum("ki,ij,kj->k", steps, self.H, steps)

    def step_norm(self, steps):
        return np.linalg.norm(steps, axis=1)


class _Update(QuadraticSteps):
    """One update of one frame as a problem of the LM core (size 1): the pairs, IRLS weights and the
    bounded bones' reparametrisation fixed at the starting pose.  Steps ``z (1, P_free)``: translation,
    [scale], δ_b for free bones and Δr_b for bounded ones."""
    size = 1

    def __init__(self, model, groups, pose, pairs, prior, options, max_depth=None, motion=None):
        self.model, self.groups, self.pose, self.pairs, self.prior = model, groups, pose, pairs, prior
        self.motion = motion
        B = model.skeleton.num_bones
        self.w_pose = options.w_pose if prior.num_pairs else 0.0
        self.scale = pairs.irls_weights / (2.0 * max(len(pairs.irls_weights), 1))
        self.plane = plane_mask(pairs, options.to_plane)
        self.cols = pose_columns(B, options.fit_scale)
        self.free = np.ones(4 + 3 * B, dtype=bool)
        self.free[3] = options.fit_scale
        if max_depth is not None:
            self.free[4:] = np.repeat(bone_depths(model.skeleton.parents) <= max_depth, 3)
        self.bounded = np.isfinite(prior.lower).any(axis=1) | np.isfinite(prior.upper).any(axis=1) \
            if prior.enabled else np.zeros(B, dtype=bool)
        self.r0 = quat_to_rotvec(pose.rotations[0])                              # (B, 3)

    def energy_at(self, pose):
        posed = hybrid_skin(self.model, pose, self.groups)[0]
        e = pair_residuals(self.pairs, posed, self.plane)
        E = float(np.einsum("c,cj,cj->", self.scale, e, e))
        if self.w_pose:
            E += self.w_pose / self.prior.num_pairs * float(np.sum(self.prior.residuals(pose.rotations) ** 2))
        if self.motion is not None:
            E += self.motion.value(pose.rotations[0])
        return E

    def energy(self, idx):
        return np.array([self.energy_at(self.pose)])

    def build(self, idx):
        posed, J = dense_jacobian(self.model, self.pose, self.cols, len(self.free), self.groups)
        H, g, E = data_system(J[0], posed[0], self.pairs, self.scale, self.plane)
        if self.w_pose:
            w = self.w_pose / self.prior.num_pairs
            Jp, ep = self.prior.jacobian(self.pose.rotations)[0], self.prior.residuals(self.pose.rotations)[0]
            H, g, E = H + w * Jp.T @ Jp, g + w * Jp.T @ ep, E + w * float(ep @ ep)
        if self.motion is not None:
            Hm, gm, Em = self.motion.system(self.pose.rotations[0], len(self.free))
            H, g, E = H + Hm, g + gm, E + Em
        M = self._reparametrisation()
        H, g = M.T @ H @ M, M.T @ g
        self.H, self.g = H[self.free][:, self.free], g[self.free]
        return np.array([E])

    def _reparametrisation(self):
        """``dδ/dz (P, P)``: identity, with ``J_r(r_b)⁻¹`` (:func:`solver.tracking.pose_prior.rotvec_increment_jacobian`)
        on the blocks of bounded bones."""
        M = np.eye(len(self.free))
        for b in np.flatnonzero(self.bounded):
            s = slice(4 + 3 * b, 7 + 3 * b)
            M[s, s] = np.linalg.inv(rotvec_increment_jacobian(self.r0[b]))
        return M

    def solve(self, idx, mu):
        """The damped step with the box limits as an active set (module docstring)."""
        z = solve_damped(self.H[None], self.g[None], mu, DAMP_FLOOR)[0]
        if not self.bounded.any():
            return z[None]
        rows = np.flatnonzero(self.free)                                          # z index -> layout column
        return active_set_solve(self.H, self.g, mu, z, lambda x: self._violations(x, rows))[None]

    def _violations(self, z, rows):
        """Per entry of ``z``: whether it takes a bounded DoF outside its interval, and the step onto it."""
        full = np.zeros(len(self.free))
        full[rows] = z
        dr = full[4:].reshape(-1, 3)
        r = np.where(self.bounded[:, None], self.r0 + dr, self.r0)
        bad, clamped = self.prior.box_violations(r)
        bad &= self.bounded[:, None]
        step = np.concatenate([np.zeros(4), (clamped - self.r0).ravel()])
        return np.concatenate([np.zeros(4, bool), bad.ravel()])[rows], step[rows]

    def try_steps(self, idx, steps):
        self.trial = self.moved(steps[0])
        return np.array([self.energy_at(self.trial)])

    def moved(self, z):
        """The pose moved by the step ``z (P_free,)``."""
        full = np.zeros(len(self.free))
        full[self.free] = z
        delta = full.copy()
        delta[4:].reshape(-1, 3)[self.bounded] = 0.0
        out = apply_pose_increment(self.pose, delta[None])
        b = np.flatnonzero(self.bounded)
        out.rotations[0, b] = rotvec_to_quat(self.r0[b] + full[4:].reshape(-1, 3)[b])
        return out

    def accept(self, which):
        if which[0]:
            self.pose = self.trial
            self.r0 = quat_to_rotvec(self.pose.rotations[0])     # bounded bones step from the new pose


def _refresh(model, groups, pose, capture, options):
    """Correspondences of the model posed at ``pose`` and ``capture``."""
    posed = hybrid_skin(model, pose, groups)[0]
    tris = model.faces
    pairs = correspondences(posed, tris, vertex_normals(posed, tris), capture.points, capture.normals,
                            capture.triangles, capture.cameras, options.correspondence)
    plane = plane_mask(pairs, options.to_plane)
    return pairs if plane is None else to_plane(pairs, posed, plane, options.correspondence.eps)


def plane_mask(pairs, which):
    """``(C,)`` bool: the pairs taken point-to-plane (``which``: "none" -> None, "model", "all")."""
    if which not in ("none", "model", "all"):
        raise ArticulaInputError(f"to_plane: expected 'none', 'model' or 'all', got {which!r}")
    return None if which == "none" else ~pairs.from_capture | (which == "all")


def to_plane(pairs, posed, plane, eps):
    """``pairs`` with the distances, IRLS weights and Q^data of the ``plane (C,)`` rows taken along the
    capture normal (:func:`pair_residuals`), the others unchanged."""
    d = np.linalg.norm(pair_residuals(pairs, posed, plane), axis=1)
    return dataclasses.replace(pairs, distances=d, irls_weights=robust.irls_weights(d, eps),
                               energy=robust.data_energy(d, eps))


def pair_stats(pairs) -> dict:
    """Scan-to-model distances (mm) and trimming of one frame's correspondences."""
    d = pairs.distances[pairs.from_capture] * 1e3
    return {"median_mm": float(np.median(d)) if len(d) else float("nan"),
            "mean_mm": float(d.mean()) if len(d) else float("nan"),
            "removed_capture": pairs.stats["removed_capture"], "removed_model": pairs.stats["removed_model"],
            "capture_pairs": int(pairs.from_capture.sum()), "model_pairs": int((~pairs.from_capture).sum())}


def _start_pose(model, init):
    check_pose_shapes(model, init)
    if len(init) != 1:
        raise ArticulaInputError(f"init: expected the pose of one frame, got {len(init)}")
    init.validate(model.skeleton.num_bones)
    return Poses(quat_normalize(init.rotations), init.translations.copy(), init.scales.copy())


def into_box(pose: Poses, prior: PosePrior) -> Poses:
    """``pose`` with every bounded joint's rotation vector clamped into the prior's box, so that updates
    start feasible (a DoF outside its box would be pulled onto it by every step, whatever its length,
    and the line search could never accept one)."""
    r = quat_to_rotvec(pose.rotations)
    bad, clamped = prior.box_violations(r)
    if not bad.any():
        return pose
    return Poses(rotvec_to_quat(clamped), pose.translations, pose.scales)


def fit_frame(model, capture: Capture, init: Poses, prior: PosePrior = None,
              options: FrameFitOptions = FrameFitOptions(), groups: AnchorGroups = None,
              motion=None) -> FrameFit:
    """Fit the pose of ``model`` (fixed; metres) to one unregistered ``capture`` starting from ``init``
    (one frame, e.g. the previous frame's pose).  prior: a :class:`PosePrior` (None or
    ``PosePrior.none(skeleton)``: no prior term and no bounds); groups: the model's :class:`AnchorGroups`
    to reuse across frames; motion: a :class:`.temporal.MotionPrior` added to Q (pass 1 of tracking) or
    None.  The start is clamped into the prior's box (:func:`into_box`).  Returns :class:`FrameFit`
    (module docstring).  Runs numpy's BLAS on one
    thread (:func:`solver.parallel.single_blas_thread`: its small products lose to thread start-up)."""
    with single_blas_thread():
        return _fit_frame(model, capture, init, prior, options, groups, motion)


def _fit_frame(model, capture, init, prior, options, groups, motion=None):
    """The body of :func:`fit_frame`: the ICP stages of ``options.depth_stages``, each from the previous
    stage's best pose, then all bones (coarse-to-fine: extremities are not caught by neighbouring parts
    while the trunk is still far off)."""
    groups = AnchorGroups(model) if groups is None else groups
    prior = PosePrior.none(model.skeleton) if prior is None else prior
    pose = into_box(_start_pose(model, init), prior)
    log = {key: [] for key in ("Q", "data", "pose", "pairs", "trials")}
    coarse = dataclasses.replace(options, rel_tol=options.coarse_rel_tol, lm_steps=options.coarse_lm_steps,
                                 max_iterations=options.coarse_iterations)
    stages = [(coarse, d) for d in options.depth_stages] + [(options, None)]
    updates = 0
    for stage, depth in stages:
        pose, pairs, done, converged = _icp(model, groups, capture, pose, prior, stage, log,
                                            min(stage.max_iterations, options.max_iterations - updates), depth,
                                            motion)
        updates += done
    pose = Poses(quat_canonical(quat_normalize(pose.rotations)), pose.translations, pose.scales)
    return FrameFit(pose, pair_stats(pairs), updates, converged, {k: np.array(v) for k, v in log.items()})


def _icp(model, groups, capture, pose, prior, options, log, budget, max_depth=None, motion=None):
    """Refresh-and-update rounds from ``pose`` until the stopping rule (module docstring) or ``budget``
    updates; appends to ``log``.  Returns ``(best pose, its pairs, updates made, converged)``."""
    damping = FixedRatioDamping([MU0], decrease=10.0, increase=10.0, mu_min=MU_MIN)
    search = ArmijoLineSearch() if options.line_search else None
    best, stale, converged, updates = None, 0, False, 0
    while True:
        pairs = _refresh(model, groups, pose, capture, options)
        if not len(pairs.distances):
            raise ArticulaInputError("capture: no correspondences between the model and the capture "
                                     "(empty, or too far from the starting pose)")
        q_pose = float(prior.value(pose.rotations)[0]) if prior.num_pairs else 0.0
        Q = pairs.energy + options.w_pose * q_pose + (motion.value(pose.rotations[0]) if motion else 0.0)
        for key, value in (("Q", Q), ("data", pairs.energy), ("pose", q_pose), ("pairs", len(pairs.distances))):
            log[key].append(value)
        if best is not None and abs(log["Q"][-2] - Q) <= options.rel_tol * log["Q"][-2]:
            converged = True
        if best is None or Q < best[0]:
            best, stale = (Q, pose, pairs), 0
        else:
            stale += 1
        if converged or stale >= options.patience or updates >= budget:
            break
        update = _Update(model, groups, pose, pairs, prior, options, max_depth, motion)
        out = levenberg_marquardt(update, damping, Limits(steps=options.lm_steps, rejections=REJECTIONS),
                                  line_search=search)
        log["trials"].append(int(out.trials[0]))
        updates += 1
        if out.steps[0] == 0:                      # no decrease even for short steps: a minimum
            converged = True
            break
        pose = update.pose
    return best[1], best[2], updates, converged
