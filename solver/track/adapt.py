"""Model adaptation: the rest vertices, the joint centres and the poses of a few key frames of a recording
fitted together to their unregistered captures.

Model-adaptive mocap dissertation §4.1.3-4.1.4 (d) (Eq. 4.3, 4.11-4.14).  Variables: the rest vertices
x (V, 3), the rest heads of the non-root bones (their frames and bone lengths kept, tails following,
as :func:`solver.rig.jacobians.dense_jacobian` with ``heads=True`` differentiates them), and every key
frame's pose (translation and rotations in the layout of :func:`solver.rig.jacobians.pose_layout`; the
scale is held).  Skinning weights, faces and joint orientations are not adapted.  Objective:

    Q = Q^data + w_shape Q^shape + w_sym Q^sym + w_pose Q^pose  [+ w_tangent Q^tan + κ Q^joint]

with Q^data the mean over frames of each frame's mean Charbonnier distance of its correspondences
(:mod:`.frame_fit`, :mod:`.correspondences`; point-to-plane for both directions by default), Q^shape the
Laplacian prior of :mod:`.shape_prior`, Q^sym the squared left/right bone-length differences (mirror
bones by name; w_sym = 1e10) and Q^pose the pose prior (:mod:`solver.tracking.pose_prior`).  Two terms are not in the
dissertation: Q^tan = (1/V) Σ_v ‖(I − n_v n_vᵀ)(x_v − x⁰_v)‖², the rest displacement within the input
model's tangent planes (surface data see only the normal component; without it vertices slide along
the surface and take up joint offsets, docs/track.md), and Q^joint = Σ_b ‖h_b − h⁰_b‖² with a small κ,
for joints that no key frame rotates.

ICP: before every update the correspondences of every key frame are refreshed on the model posed in
that frame; one Levenberg-Marquardt update with the Armijo line search (:mod:`solver.fit.least_squares`,
on the true objective with the pairs held) then moves all variables together.  The pairs' IRLS weights
make Q^data a least-squares majoriser, whose Gauss-Newton system in the posed vertices is lifted to x
and the other parameters (:func:`.shape_prior.lift`: posed vertices are ``A x + c`` per vertex,
Eq. 4.14).  The system is solved by eliminating x (sparse LU of the 3V x 3V block, SuperLU with a
symmetric ordering) and solving the dense Schur complement of the joints and poses.  x enters the
objective linearly, so only the joints and poses are damped (Marquardt's scaling, without the symmetry
rows); x gets a tiny Tikhonov floor for unobserved, disconnected parts.  Every trial point is moved back
onto equal mirror lengths (:func:`restore_symmetry`).  Non-monotone: Q may rise for ``patience``
refreshes, the best state is returned.

Gauge: moving every rest vertex and non-root joint by d while each frame's root translation moves by
−s R_0 d leaves every posed vertex, Laplacian and bone length unchanged.  The solve holds frame 0's root
translation (removing that freedom); the result is then put in the gauge where the median rest-vertex
displacement from the input model is zero (:func:`fix_gauge`), so the adapted model stays where the
input model was.  Units: metres, radians.
"""
from __future__ import annotations

import copy
import dataclasses
import time

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..errors import ArticulaInputError
from ..fit.least_squares import ArmijoLineSearch, FixedRatioDamping, Limits, levenberg_marquardt
from ..geometry.normals import vertex_normals
from ..geometry.rotations import quat_canonical, quat_normalize
from ..learn.joints_poses import symmetry_residuals
from ..learn.symmetry import continuing_pairs
from ..parallel import single_blas_thread
from ..rig.jacobians import apply_pose_increment, dense_jacobian
from ..rig.model import Poses, Skeleton
from ..rig.names import side
from ..rig.skinning import AnchorGroups, affine_form, bone_terms, check_pose_shapes, hybrid_skin
from . import robust
from .frame_fit import DAMP_FLOOR, MU0, MU_MIN, REJECTIONS, FrameFitOptions, _refresh, pair_residuals, \
    pair_stats, plane_mask
from ..tracking.pose_prior import PosePrior
from .shape_prior import MAX_POSES, ShapePrior, block_diagonal, lift

X_FLOOR = 1e-9        # Tikhonov floor of the rest-vertex block, relative to its mean diagonal
SCHUR_CHUNK = 64      # right-hand sides per sparse solve when forming the Schur complement
SYM_CORRECTIONS = 5   # Gauss-Newton corrections that restore equal mirror-bone lengths after a step
SYM_TOL = 1e-12       # metres: length difference below which no correction is made


@dataclasses.dataclass(frozen=True)
class AdaptOptions:
    """Settings of :func:`adapt_model`.  w_shape: weight of Q^shape (1/m; Q^data is in metres, Q^shape
    in m²); w_sym: of Q^sym (1/m); joint_prior: ρ of Q^joint (κ = ρ × the mean Gauss-Newton curvature of
    the other terms in a joint centre at the start); w_tangent: of Q^tan (1/m); the pose prior's weight
    is ``frame.w_pose``; to_plane: which pairs are point-to-plane (as :class:`.frame_fit.FrameFitOptions`;
    "all" here: a point-to-point pair's tangential pull would be taken up by sliding vertices);
    shape_poses: training poses the shape prior keeps; vertices / joints: which of the model's parts are
    adapted (poses always); symmetry: tie the lengths of mirror bones (names ``.L``/``.R``, ``_L``/``_R``,
    ``-L``/``-R``); max_iterations, rel_tol, patience: the ICP's stopping rule (as
    :class:`.frame_fit.FrameFitOptions`); frame: correspondence settings and w_pose.  The defaults were
    chosen on planted subjects (docs/track.md "Model adaptation")."""
    w_shape: float = 100.0
    w_sym: float = 1e10
    joint_prior: float = 1e-3
    w_tangent: float = 100.0
    to_plane: str = "all"
    shape_poses: int = MAX_POSES
    vertices: bool = True
    joints: bool = True
    symmetry: bool = True
    max_iterations: int = 20
    rel_tol: float = 1e-4
    patience: int = 5
    frame: FrameFitOptions = FrameFitOptions()

    def validate(self) -> "AdaptOptions":
        for key in ("w_shape", "w_sym", "joint_prior", "w_tangent"):
            value = getattr(self, key)
            if not (np.isfinite(value) and value >= 0):
                raise ArticulaInputError(f"adapt options: {key} must be a finite number >= 0, got {value!r}")
        for key in ("shape_poses", "max_iterations", "patience"):
            if int(getattr(self, key)) < 1:
                raise ArticulaInputError(f"adapt options: {key} must be >= 1, got {getattr(self, key)!r}")
        if self.to_plane not in ("none", "model", "all"):
            raise ArticulaInputError(f"adapt options: to_plane must be 'none', 'model' or 'all', got {self.to_plane!r}")
        if not self.rel_tol >= 0:
            raise ArticulaInputError(f"adapt options: rel_tol must be >= 0, got {self.rel_tol!r}")
        if self.vertices and self.w_shape <= 0:
            raise ArticulaInputError("adapt options: adapting the rest vertices needs w_shape > 0 (the shape "
                                     "prior keeps unobserved parts of the surface determined)")
        return self


@dataclasses.dataclass
class AdaptResult:
    """model: the adapted :class:`Model` (new rest vertices and joint centres; names, faces, weights and
    joint orientations of the input); poses: the key frames' refined :class:`Poses` (in the adapted
    model's gauge); log: per refresh ``Q``, ``data`` (Q^data, m), ``shape`` (Q^shape, m²), ``sym``
    (Q^sym, m²), ``pose`` (Q^pose), ``joint`` (m²), ``tangent`` (m²), ``pairs`` (all frames), ``trials``
    (damped solves of the update after it); stats: ``iterations``, ``converged``, ``seconds``, ``seconds_per_iteration``,
    ``frames`` (per key frame :func:`.frame_fit.pair_stats`), ``vertex_shift_mm`` (median, max) and
    ``joint_shift_mm`` (max) from the input model, ``gauge_mm`` (the shift :func:`fix_gauge` removed)."""
    model: object
    poses: Poses
    log: dict
    stats: dict


@dataclasses.dataclass
class _State:
    rest: np.ndarray        # (V, 3)
    heads: np.ndarray       # (B, 3)
    poses: Poses            # N key frames


def mirror_pairs(skeleton) -> list:
    """``[(l, child_l, r, child_r), ...]``: bones named as mirror images (``X.L``/``X.R``, also ``_``,
    ``-`` and lower case) whose bones both continue into a child, the lengths ``|head(child) − head(bone)|``
    Q^sym equalises (:func:`solver.learn.symmetry.continuing_pairs`)."""
    index = {name: b for b, name in enumerate(skeleton.names)}
    pairs = []
    for b, name in enumerate(skeleton.names):
        if side(name) == "L":
            other = index.get(name[:-1] + ("R" if name[-1] == "L" else "r"))
            if other is not None:
                pairs.append((b, other))
    return continuing_pairs(skeleton, pairs)


def symmetry_terms(heads, skeleton, sym_pairs):
    """Bone-length differences ``(S,)`` (m) of ``sym_pairs`` at ``heads (B, 3)`` and their Jacobian
    ``(S, 3 (B − 1))`` w.r.t. the heads of bones 1..B−1 (:func:`solver.learn.joints_poses.symmetry_residuals`)."""
    sk = dataclasses.replace(skeleton, heads=heads)
    r, J5 = symmetry_residuals(sk, sym_pairs)
    B = skeleton.num_bones
    return r, J5.reshape(len(r), B - 1, 5)[:, :, :3].reshape(len(r), 3 * (B - 1))


def restore_symmetry(heads, skeleton, sym_pairs, iterations=SYM_CORRECTIONS):
    """``heads (B, 3)`` moved back onto equal mirror-bone lengths by minimum-norm Gauss-Newton corrections
    ``Δ = −Jᵀ (J Jᵀ)⁻¹ r`` of the non-root heads (:func:`symmetry_terms`): a linearised step keeps the
    lengths equal only to first order, and with w_sym = 1e10 its second-order violation would outweigh
    the whole data term (a second-order correction, as in sequential quadratic programming)."""
    heads = heads.copy()
    for _ in range(iterations):
        r, J = symmetry_terms(heads, skeleton, sym_pairs)
        if not len(r) or np.abs(r).max() <= SYM_TOL:
            break
        heads[1:] -= (J.T @ np.linalg.lstsq(J @ J.T, r, rcond=None)[0]).reshape(-1, 3)
    return heads


def adapted_model(model, rest, heads):
    """A copy of ``model`` with rest vertices ``rest (V, 3)`` and joint centres ``heads (B, 3)``; frames and
    bone lengths kept, tails ``heads + length · Y``."""
    sk = model.skeleton
    length = np.linalg.norm(sk.tails - sk.heads, axis=1)
    out = copy.copy(model)
    out.rest_vertices = np.array(rest, dtype=np.float64)
    out.skeleton = Skeleton(list(sk.names), sk.parents.copy(), np.array(heads, dtype=np.float64),
                            heads + length[:, None] * sk.frames[:, :, 1], sk.frames.copy())
    return out


def _regrouped(groups, rest):
    """``groups`` (:class:`AnchorGroups`) holding the rest vertices ``rest (V, 3)`` (anchors and weights
    are shared)."""
    out = copy.copy(groups)
    out.rest = np.ascontiguousarray(rest[groups.order].T)
    return out


def fix_gauge(model, rest, heads, poses, reference):
    """Move ``rest (V, 3)`` and the non-root ``heads (B, 3)`` by −d, d the per-coordinate median of
    ``rest − reference`` (metres), and every frame's root translation by ``Rm_0 d`` (Rm_0 = s R_0, the
    root's world map), which leaves every posed vertex unchanged (module docstring).  ``model``: any
    model with the skeleton's frames and parents.  Returns ``(rest, heads, poses, d)``."""
    d = np.median(rest - reference, axis=0)
    heads = heads.copy()
    heads[1:] -= d
    sk = adapted_model(model, rest, heads).skeleton
    Rm0 = bone_terms(sk, poses)["Rm"][:, 0]
    moved = Poses(poses.rotations.copy(), poses.translations + Rm0 @ d, poses.scales.copy())
    return rest - d, heads, moved, d


def data_terms(pairs, posed, plane, scale):
    """Gauss-Newton form in the posed vertices ``posed (V, 3)`` of ``Σ_c scale_c ‖P_c (m_c − y_c)‖²``
    (P_c = I, or n nᵀ for the ``plane (C,)`` pairs: :func:`.frame_fit.pair_residuals`): ``(H_p (3V, 3V)
    csr, b_p (3V,), used vertices (U,), value)``; the pair rows are ``P_c [β_c1 I, β_c2 I, β_c3 I]``."""
    C, V = len(scale), len(posed)
    P = np.broadcast_to(np.eye(3), (C, 3, 3)).copy()
    if plane is not None and plane.any():
        n = pairs.target_normals[plane]
        P[plane] = n[:, :, None] * n[:, None, :]
    e = pair_residuals(pairs, posed, plane)
    blocks = pairs.weights[:, :, None, None] * P[:, None]                    # (C, 3, 3, 3): pair c, corner i
    R = sp.bsr_matrix((blocks.reshape(3 * C, 3, 3), pairs.vertex_ids.ravel(), np.arange(0, 3 * C + 1, 3)),
                      shape=(3 * C, 3 * V)).tocsr()
    R.sum_duplicates()
    s = np.repeat(scale, 3)
    H_p = (R.T @ sp.diags(s) @ R).tocsr()
    return H_p, R.T @ (s * e.ravel()), np.unique(pairs.vertex_ids), float(np.einsum("c,cj,cj->", scale, e, e))


class _Context:
    """What one adaptation holds fixed: the input model and its anchor groups, captures, options, the
    priors, mirror pairs and the parameter layout (shared block ``[heads 1..B−1 | N poses]``)."""

    def __init__(self, model, captures, prior, shape, sym_pairs, options, groups):
        self.model, self.captures, self.prior, self.shape = model, captures, prior, shape
        self.sym_pairs, self.options, self.groups = sym_pairs, options, groups
        self.refresh = dataclasses.replace(options.frame, to_plane=options.to_plane)
        self.kappa = 0.0 if options.joint_prior == 0 else None       # set at the first build
        n = vertex_normals(model.rest_vertices, model.faces)
        self.tangent = np.eye(3) - n[:, :, None] * n[:, None, :]             # (V, 3, 3) rest tangent planes
        self.B, self.N, self.V = model.skeleton.num_bones, len(captures), model.num_vertices
        self.nh = 3 * (self.B - 1) if options.joints else 0
        self.P = 4 + 3 * self.B
        self.w_pose = options.frame.w_pose if prior.num_pairs else 0.0
        self.w_sym = options.w_sym if (options.joints and sym_pairs) else 0.0
        free = np.ones(self.nh + self.N * self.P, dtype=bool)
        free[self.nh + 3::self.P] = False                                     # scales held
        if options.vertices or options.joints:
            free[self.nh:self.nh + 3] = False                                 # the gauge: frame 0's translation
        self.free = np.flatnonzero(free)

    def at(self, state):
        """``(model, groups)`` of a state."""
        return adapted_model(self.model, state.rest, state.heads), _regrouped(self.groups, state.rest)

    def terms(self, state, pairs):
        """The objective's terms at ``state`` with the pairs ``pairs`` (one per frame) held."""
        model, groups = self.at(state)
        posed = hybrid_skin(model, state.poses, groups)
        eps = self.options.frame.correspondence.eps
        data = np.mean([robust.charbonnier(pair_residuals(p, x, plane_mask(p, self.options.to_plane)),
                                           eps).mean() for p, x in zip(pairs, posed)])
        shape = self.shape.value(model, groups) if self.options.w_shape else 0.0
        sym = float(np.sum(symmetry_terms(state.heads, model.skeleton, self.sym_pairs)[0] ** 2)) \
            if self.w_sym else 0.0
        pose = float(self.prior.value(state.poses.rotations).mean()) if self.w_pose else 0.0
        joint = float(np.sum((state.heads - self.model.skeleton.heads) ** 2)) if self.nh else 0.0
        d = np.einsum("vij,vj->vi", self.tangent, state.rest - self.model.rest_vertices)
        tangent = float(np.sum(d * d)) / self.V
        Q = data + self.options.w_shape * shape + self.w_sym * sym + self.w_pose * pose + (self.kappa or 0.0) * joint \
            + self.options.w_tangent * tangent
        return {"Q": float(Q), "data": float(data), "shape": shape, "sym": sym, "pose": pose, "joint": joint,
                "tangent": tangent}

    def moved(self, state, step, restore=True):
        """The state moved by ``step`` (``[δx (3V) if vertices | free shared parameters]``), the mirror
        lengths then made equal again (:func:`restore_symmetry`) unless ``restore`` is False."""
        rest, k = state.rest, 0
        if self.options.vertices:
            rest, k = state.rest + step[:3 * self.V].reshape(-1, 3), 3 * self.V
        shared = np.zeros(self.nh + self.N * self.P)
        shared[self.free] = step[k:]
        heads = state.heads.copy()
        if self.nh:
            heads[1:] += shared[:self.nh].reshape(-1, 3)
            heads = restore_symmetry(heads, self.model.skeleton, self.sym_pairs) if self.w_sym and restore else heads
        poses = apply_pose_increment(state.poses, shared[self.nh:].reshape(self.N, self.P))
        return _State(rest, heads, poses)


def _system(ctx, state, pairs):
    """Normal equations at ``state`` with ``pairs`` held: ``(H_xx, H_xs, H_ss, g_x, g_s, D_s)`` over the
    rest vertices and the free shared parameters; D_s the diagonal used for damping (no symmetry rows)."""
    model, groups = ctx.at(state)
    opts, nh, P, N = ctx.options, ctx.nh, ctx.P, ctx.N
    n_s = nh + N * P
    cols = {"t": nh, **{("rot", b): nh + 4 + 3 * b for b in range(ctx.B)}}
    cols.update({("head", b): 3 * (b - 1) for b in range(1, ctx.B)} if nh else {})
    A = affine_form(model, state.poses, groups)[0]
    H_xx = sp.csr_matrix((3 * ctx.V, 3 * ctx.V))
    H_xs, H_ss = np.zeros((3 * ctx.V, n_s)), np.zeros((n_s, n_s))
    g_x, g_s = np.zeros(3 * ctx.V), np.zeros(n_s)
    for n, p in enumerate(pairs):
        one = state.poses.take(n)
        posed, J = dense_jacobian(model, one, cols, nh + P, groups, heads=bool(nh))
        scale = p.irls_weights / (2.0 * len(p.irls_weights) * N)
        H_p, b_p, used, _ = data_terms(p, posed[0], plane_mask(p, opts.to_plane), scale)
        hxx, hxs, hss, gx, gs = lift(H_p, b_p, A[n], J[0], used)
        idx = np.concatenate([np.arange(nh), nh + n * P + np.arange(P)])
        H_xx, g_x = H_xx + hxx, g_x + gx
        H_xs[:, idx] += hxs
        H_ss[np.ix_(idx, idx)] += hss
        g_s[idx] += gs
    if ctx.w_pose:
        w = ctx.w_pose / (N * ctx.prior.num_pairs)
        Jp, ep = ctx.prior.jacobian(state.poses.rotations), ctx.prior.residuals(state.poses.rotations)
        for n in range(N):
            idx = nh + n * P + np.arange(P)
            H_ss[np.ix_(idx, idx)] += w * Jp[n].T @ Jp[n]
            g_s[idx] += w * Jp[n].T @ ep[n]
    if opts.w_shape and (opts.vertices or nh):
        sxx, sxh, shh, sgx, sgh, _ = ctx.shape.system(model, groups, nh)
        H_xx, g_x = H_xx + opts.w_shape * sxx, g_x + opts.w_shape * sgx
        H_xs[:, :nh] += opts.w_shape * sxh
        H_ss[:nh, :nh] += opts.w_shape * shh
        g_s[:nh] += opts.w_shape * sgh
    if opts.vertices and opts.w_tangent:
        c = opts.w_tangent / ctx.V
        H_xx = H_xx + c * block_diagonal(ctx.tangent)
        g_x = g_x + c * np.einsum("vij,vj->vi", ctx.tangent, state.rest - ctx.model.rest_vertices).ravel()
    if nh and ctx.kappa is None:
        ctx.kappa = opts.joint_prior * float(np.mean(np.diag(H_ss)[:nh]))
    if nh and ctx.kappa:
        H_ss[:nh, :nh] += ctx.kappa * np.eye(nh)
        g_s[:nh] += ctx.kappa * (state.heads[1:] - ctx.model.skeleton.heads[1:]).ravel()
    D_s = np.diag(H_ss)[ctx.free].copy()
    if ctx.w_sym:
        r, Jr = symmetry_terms(state.heads, model.skeleton, ctx.sym_pairs)
        H_ss[:nh, :nh] += ctx.w_sym * Jr.T @ Jr
        g_s[:nh] += ctx.w_sym * Jr.T @ r
    f = ctx.free
    return H_xx, H_xs[:, f], H_ss[np.ix_(f, f)], g_x, g_s[f], D_s


class SchurSolver:
    """Damped steps of the system ``[[H_xx, H_xs], [H_xsᵀ, H_ss]]`` for the gradient ``(g_x, g_s)``: the
    rest-vertex block H_xx (sparse, with the floor ``X_FLOOR · mean diag``) is factored once and
    eliminated; each damping μ then solves the dense Schur complement with ``μ (D_s + ε mean D_s)``
    on its diagonal.  H_xx None: no vertex block (the dense system alone)."""

    def __init__(self, H_xx, H_xs, H_ss, g_x, g_s, D_s):
        self.H_xs, self.g_x, self.D_s = H_xs, g_x, D_s
        self.D_s = D_s + DAMP_FLOOR * max(float(D_s.mean()) if len(D_s) else 0.0, 1e-300)
        if H_xx is None:
            self.lu, self.S, self.rhs = None, H_ss, -g_s
            return
        d = H_xx.diagonal()
        K = (H_xx + sp.identity(H_xx.shape[0]) * (X_FLOOR * max(float(d.mean()), 1e-300))).tocsc()
        self.lu = spla.splu(K, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options=dict(SymmetricMode=True))
        S = H_ss.copy()
        for c in range(0, H_xs.shape[1], SCHUR_CHUNK):
            S[:, c:c + SCHUR_CHUNK] -= H_xs.T @ self.lu.solve(np.asfortranarray(H_xs[:, c:c + SCHUR_CHUNK]))
        self.S = 0.5 * (S + S.T)
        self.rhs = -g_s + H_xs.T @ self.lu.solve(g_x)

    def step(self, mu):
        """``[δx | δs]`` of the damping ``mu``."""
        ds = np.linalg.solve(self.S + np.diag(mu * self.D_s), self.rhs) if len(self.rhs) else self.rhs
        if self.lu is None:
            return ds
        return np.concatenate([-self.lu.solve(self.g_x + self.H_xs @ ds), ds])


class _Update:
    """One ICP update as a problem of the LM core (size 1): pairs and IRLS weights held at ``state``."""
    size = 1

    def __init__(self, ctx, state, pairs, energy):
        self.ctx, self.state, self.pairs, self.E = ctx, state, pairs, energy

    def energy(self, idx):
        return np.array([self.E])

    def build(self, idx):
        H_xx, H_xs, H_ss, g_x, g_s, D_s = _system(self.ctx, self.state, self.pairs)
        if not self.ctx.options.vertices:
            H_xx, g_x, H_xs = None, np.zeros(0), H_xs[:0]
        self.g = np.concatenate([g_x, g_s])
        self.solver = SchurSolver(H_xx, H_xs, H_ss, g_x, g_s, D_s)
        return np.array([self.E])

    def solve(self, idx, mu):
        return self.solver.step(float(mu[0]))[None]

    def try_steps(self, idx, steps):
        self.trial = self.ctx.moved(self.state, steps[0])
        self.trial_terms = self.ctx.terms(self.trial, self.pairs)
        return np.array([self.trial_terms["Q"]])

    def accept(self, which):
        if which[0]:
            self.state, self.E = self.trial, self.trial_terms["Q"]

    def slope(self, idx, steps):
        return 2.0 * steps @ self.g

    def step_norm(self, steps):
        return np.linalg.norm(steps, axis=1)


def _check_inputs(model, captures, poses, training_poses):
    """ArticulaInputError for mismatched counts, shapes or non-finite values."""
    model.validate()
    check_pose_shapes(model, poses)
    poses.validate(model.skeleton.num_bones)
    if len(captures) == 0:
        raise ArticulaInputError("adapt: no key frames (captures is empty)")
    if len(captures) != len(poses):
        raise ArticulaInputError(f"adapt: {len(captures)} captures but {len(poses)} poses; one pose per capture")
    if len(model.faces) == 0:
        raise ArticulaInputError("adapt: the model has no faces (the shape prior needs its triangles)")
    for n, c in enumerate(captures):
        pts, nrm = np.asarray(c.points), np.asarray(c.normals)
        if pts.ndim != 2 or pts.shape[1] != 3 or nrm.shape != pts.shape:
            raise ArticulaInputError(f"adapt: capture {n}: points and normals must both have shape (K, 3), "
                                     f"got {pts.shape} and {nrm.shape}")
        if len(pts) == 0:
            raise ArticulaInputError(f"adapt: capture {n} has no points")
        if not (np.isfinite(pts).all() and np.isfinite(nrm).all()):
            raise ArticulaInputError(f"adapt: capture {n} has non-finite (NaN or inf) points or normals")
    if training_poses is not None:
        check_pose_shapes(model, training_poses)
        training_poses.validate(model.skeleton.num_bones)


def adapt_model(model, captures, poses: Poses, prior: PosePrior = None, options: AdaptOptions = AdaptOptions(),
                groups: AnchorGroups = None, progress=None, training_poses: Poses = None,
                sym_pairs: list = None) -> AdaptResult:
    """Adapt ``model`` (metres) to the key frames ``captures`` (list of :class:`.frame_fit.Capture`) whose
    ``poses`` (one per capture, e.g. from :func:`.frame_fit.fit_frame` with the input model) are refined
    together with it (module docstring).  prior: :class:`PosePrior` or None (no pose term);
    training_poses: the model's training poses for the shape prior (None: the rest pose); groups: the
    model's :class:`AnchorGroups` to reuse; sym_pairs: the mirror pairs (:func:`mirror_pairs`) to tie, by
    default the model's own (an adapted model's tails no longer meet its children's heads, so a second
    adaptation passes the first model's).  progress(fraction, text) after each update; it may raise
    :class:`solver.errors.Cancelled` (the inputs are never modified).  Returns :class:`AdaptResult`."""
    t0 = time.perf_counter()
    options = options.validate()
    captures = list(captures)
    _check_inputs(model, captures, poses, training_poses)
    groups = AnchorGroups(model) if groups is None else groups
    prior = PosePrior.none(model.skeleton) if prior is None else prior
    with single_blas_thread():
        shape = ShapePrior.from_model(model, training_poses, options.shape_poses, groups)
        sym = [] if not options.symmetry else mirror_pairs(model.skeleton) if sym_pairs is None else list(sym_pairs)
        ctx = _Context(model, captures, prior, shape, sym, options, groups)
        start = _State(model.rest_vertices.copy(), model.skeleton.heads.copy(),
                       Poses(quat_normalize(poses.rotations), poses.translations.copy(), poses.scales.copy()))
        best, log, iterations, converged = _icp(ctx, start, progress)
    state, pairs = best
    rest, heads, out_poses, d = fix_gauge(model, state.rest, state.heads, state.poses, model.rest_vertices)
    out_poses = Poses(quat_canonical(quat_normalize(out_poses.rotations)), out_poses.translations, out_poses.scales)
    adapted = adapted_model(model, rest, heads)
    seconds = time.perf_counter() - t0
    shift = np.linalg.norm(rest - model.rest_vertices, axis=1) * 1e3
    stats = {"iterations": iterations, "converged": converged, "seconds": seconds,
             "seconds_per_iteration": seconds / max(iterations, 1), "frames": [pair_stats(p) for p in pairs],
             "vertex_shift_mm": (float(np.median(shift)), float(shift.max())),
             "joint_shift_mm": float(np.linalg.norm(heads - model.skeleton.heads, axis=1).max() * 1e3),
             "gauge_mm": float(np.linalg.norm(d) * 1e3), "sym_pairs": len(sym)}
    return AdaptResult(adapted, out_poses, {k: np.array(v) for k, v in log.items()}, stats)


def _icp(ctx, state, progress):
    """Refresh-and-update rounds from ``state`` (module docstring).  Returns ``((best state, its pairs),
    log, updates made, converged)``."""
    opts = ctx.options
    damping = FixedRatioDamping([MU0], decrease=10.0, increase=10.0, mu_min=MU_MIN)
    log = {key: [] for key in ("Q", "data", "shape", "sym", "pose", "joint", "tangent", "pairs", "trials")}
    best, stale, converged, updates = None, 0, False, 0
    while True:
        model, groups = ctx.at(state)
        pairs = [_refresh(model, groups, state.poses.take(n), c, ctx.refresh) for n, c in enumerate(ctx.captures)]
        empty = [n for n, p in enumerate(pairs) if not len(p.distances)]
        if empty:
            raise ArticulaInputError(f"adapt: key frame {empty[0]} has no correspondences with the model "
                                     f"(empty capture, or too far from its pose)")
        terms = ctx.terms(state, pairs)
        for key in ("Q", "data", "shape", "sym", "pose", "joint", "tangent"):
            log[key].append(terms[key])
        log["pairs"].append(sum(len(p.distances) for p in pairs))
        if best is not None and abs(log["Q"][-2] - terms["Q"]) <= opts.rel_tol * log["Q"][-2]:
            converged = True
        if best is None or terms["Q"] < best[0]:
            best, stale = (terms["Q"], state, pairs), 0
        else:
            stale += 1
        if converged or stale >= opts.patience or updates >= opts.max_iterations:
            break
        update = _Update(ctx, state, pairs, terms["Q"])
        out = levenberg_marquardt(update, damping, Limits(steps=1, rejections=REJECTIONS),
                                  line_search=ArmijoLineSearch())
        log["trials"].append(int(out.trials[0]))
        updates += 1
        if progress is not None:
            progress(updates / opts.max_iterations, f"adapting the model: update {updates} of at most "
                                                    f"{opts.max_iterations}, Q^data {terms['data'] * 1e3:.3f} mm")
        if out.steps[0] == 0:
            converged = True
            break
        state = update.state
    return (best[1], best[2]), log, updates, converged
