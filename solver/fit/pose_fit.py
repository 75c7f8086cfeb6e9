"""Per-frame poses of a FIXED model fitted to registered target vertices (held-out evaluation of a
learned rig; the per-frame core of tracking).

For every frame n it minimises ``E_n(p) = Σ_v w_v ‖hybrid_skin(model, p)_v − y_n,v‖²`` (m²) over the pose
parameters of :func:`solver.rig.jacobians.pose_layout` — root translation t, optionally the subject scale s,
and a bone-local rotation increment δ_b for every bone (``q_b ← q_b · exp(δ_b)``) — by Levenberg–Marquardt
(dissertation (model-adaptive mocap) §5.7 (a); :func:`solver.fit.least_squares.levenberg_marquardt`) with
the analytic Jacobian of :mod:`solver.rig.jacobians` (in factored per-anchor-group form,
:func:`solver.rig.jacobians.group_jacobian`; BLAS on one thread):

    (JᵀWJ + μ (diag(JᵀWJ) + ε·mean diag)) δ = −JᵀW r,   accept if E decreases (μ ← μ/3), else μ ← 4μ.

Frames are independent problems; they are solved together, a block of frames per Jacobian call (batched
normal equations, one ``np.linalg.solve`` for the block).  Rotations are updated multiplicatively on the
quaternion, so there is no singularity at 180° (no Euler angles, no rotation-vector wrap-around), and the
result is the same for q and −q (the skin canonicalises the sign).

Initialisation (``init``):

* ``"procrustes"`` (default): per-part rigid fits (:func:`solver.geometry.procrustes.fit_rigid_soft`) of the vertices
  that move rigidly with their anchor part (weight 1 − their blended weight), converted to joint-local
  rotations by :func:`solver.fit.pose_init.poses_from_part_fits`.  Each frame is initialised on its own, so a
  wrong frame never propagates.  A part with fewer than ``MIN_SUPPORT`` rigid vertices keeps its parent's
  rotation (local identity); such a root (e.g. a floor-level root bone) takes the map of the best-supported
  part.
* ``"previous"``: frames are solved in order; each starts from the better (lower E) of the previous frame's
  solution and its own Procrustes initialisation, so a sudden jump or a 180° flip between frames costs one
  restart rather than a wrong fit.
* a :class:`Poses` with N frames: start from those poses (e.g. a tracker's prediction).

This is the pose-only fit; the rig learner's :mod:`solver.learn.joints_poses` optimises joints *and* poses
together (with the Laplacian term), which is a different problem on the same Levenberg–Marquardt core.
"""
from dataclasses import dataclass

import numpy as np

from .. import parallel
from ..errors import ArticulaInputError
from ..parallel import single_blas_thread
from ..rig.jacobians import apply_pose_increment, factored_gram, group_jacobian, jacobian_terms
from ..rig.model import Poses
from .pose_init import poses_from_part_fits
from ..geometry.procrustes import fit_rigid_soft
from ..geometry.rotations import quat_canonical, quat_normalize
from ..rig.skinning import AnchorGroups, check_pose_shapes, hybrid_skin
from .least_squares import FixedRatioDamping, Limits, levenberg_marquardt, solve_damped

MIN_SUPPORT = 4.0              # rigid-vertex weight a part needs for its own Procrustes fit
BLOCK_BYTES = 40e6             # memory budget of one block of frames (~8 arrays (V, 3) per frame)
MU0, MU_MIN, MU_MAX = 1e-3, 1e-12, 1e12
DAMP_FLOOR = 1e-9              # ε: damping floor relative to the mean of diag(JᵀWJ)


@dataclass
class PoseFit:
    """Result of :func:`fit_poses` (N frames, V vertices).

    poses: fitted :class:`Poses` (quaternions with w >= 0); rms (N,): weighted RMS vertex distance after
    the fit, metres; vertex_errors (N, V) float32: ‖posed − target‖ per vertex, metres; energy (N,): E_n
    (m²); iterations (N,): LM iterations used; converged (N,) bool: the relative decrease or the step fell
    below the tolerance (False: the iteration limit was hit)."""
    poses: Poses
    rms: np.ndarray
    vertex_errors: np.ndarray
    energy: np.ndarray
    iterations: np.ndarray
    converged: np.ndarray


def _check_targets(model, targets, vertex_weights):
    y = np.asarray(targets, dtype=np.float64)
    V = model.num_vertices
    if y.ndim != 3 or y.shape[1:] != (V, 3):
        raise ArticulaInputError(f"targets: expected shape (N, {V}, 3) for this model, got {y.shape}")
    if len(y) == 0:
        raise ArticulaInputError("targets: no frames to fit")
    bad = np.argwhere(~np.isfinite(y))
    if len(bad):
        raise ArticulaInputError(f"targets: frame {bad[0][0]}, vertex {bad[0][1]} is not finite")
    if vertex_weights is None:
        return y, None
    w = np.asarray(vertex_weights, dtype=np.float64)
    if w.shape != (V,):
        raise ArticulaInputError(f"vertex_weights: expected shape ({V},), got {w.shape}")
    if not np.all(np.isfinite(w)) or np.any(w < 0):
        raise ArticulaInputError("vertex_weights: must be finite and >= 0")
    if not np.any(w > 0):
        raise ArticulaInputError("vertex_weights: all weights are zero")
    return y, w


def _take(poses, idx):
    return Poses(poses.rotations[idx], poses.translations[idx], poses.scales[idx])


def _put(dst, idx, src):
    dst.rotations[idx], dst.translations[idx], dst.scales[idx] = src.rotations, src.translations, src.scales


def procrustes_init(model, targets):
    """Initial poses ``(N frames)`` from per-part rigid fits (module docstring).  targets ``(N, V, 3)``."""
    sk = model.skeleton
    B, V = sk.num_bones, model.num_vertices
    load = np.maximum(model.twist_weights.sum(axis=1), model.swing_weights.sum(axis=1)).astype(np.float64)
    W = np.zeros((V, B))
    W[np.arange(V), model.anchor] = np.clip(1.0 - load, 0.0, 1.0)
    R, t = fit_rigid_soft(model.rest_vertices, np.asarray(targets, dtype=np.float64), W)
    support = W.sum(axis=0)
    weak = support < MIN_SUPPORT
    if weak.all():
        raise ArticulaInputError("model: no part has rigidly attached vertices; give an initial pose "
                                 "(init=Poses) instead of 'procrustes'")
    if weak[0]:                      # e.g. a floor-level root bone without vertices: take the best part
        best = int(np.argmax(support))
        R[:, 0], t[:, 0] = R[:, best], t[:, best]
    for b in range(1, B):                                # parents first: inherit the (final) parent map
        if weak[b]:
            p = sk.parents[b]
            R[:, b], t[:, b] = R[:, p], t[:, p]          # local identity: M_b = M_parent
    return poses_from_part_fits(sk, R, t)


class _Problem:
    """The weighted least-squares problem of one block of frames.  The normal equations are summed over
    the anchor groups from the factored group Jacobians (:func:`solver.rig.jacobians.group_jacobian`), with
    the residual as an extra column, so the dense (n, V, 3, P) Jacobian is never formed."""

    def __init__(self, model, groups, targets, weights, free):
        self.model, self.groups, self.y, self.free = model, groups, targets, free
        self.sw = None if weights is None else np.sqrt(weights)[None, :, None]
        self.y_sorted = targets[:, groups.order]
        self.sw_sorted = None if weights is None else np.sqrt(weights)[groups.order, None, None]
        B = model.skeleton.num_bones
        self.cols = {"t": 0, "s": 3, **{("rot", b): 4 + 3 * b for b in range(B)}}

    def residual(self, posed, idx):
        r = posed - self.y[idx]
        return r if self.sw is None else r * self.sw

    def energy(self, poses, idx):
        r = self.residual(hybrid_skin(self.model, poses, self.groups), idx)
        return np.einsum("nvi,nvi->n", r, r)

    def system(self, poses, idx):
        """``H (n, P_free, P_free)``, ``g (n, P_free)``, ``E (n,)`` at ``poses`` (frames ``idx``)."""
        bt = jacobian_terms(self.model, poses)
        n, P = len(poses), len(self.free)
        H = np.zeros((n, P + 1, P + 1))
        E = np.zeros(n)
        for group in self.groups.groups:
            start, stop = group[2], group[3]
            xp, R, T = group_jacobian(bt, self.groups, group, self.cols, P, extra=1)
            R[..., -1] = xp - self.y_sorted[idx, start:stop]
            if self.sw_sorted is not None:
                R *= self.sw_sorted[start:stop]
            E += np.einsum("nvi,nvi->n", R[..., -1], R[..., -1])
            H += factored_gram(R, T)
        free = self.free
        return H[:, :P, :P][:, free][:, :, free], H[:, :P, P][:, free], E


def normal_equations(model, poses, targets, vertex_weights=None, fit_scale=False):
    """Normal equations of the pose fit at ``poses``: ``H = JᵀWJ (N, P, P)``, gradient ``g = JᵀW r (N, P)``
    (half the gradient of E) and ``E (N,)``, in the parameter order of :func:`jacobians.pose_layout`
    without the scale column unless ``fit_scale``.  For tests and diagnostics."""
    y, w = _check_targets(model, targets, vertex_weights)
    check_pose_shapes(model, poses)
    prob = _Problem(model, AnchorGroups(model), y, w, _free_columns(model.skeleton.num_bones, fit_scale))
    with single_blas_thread():
        return prob.system(poses, np.arange(len(y)))


def _free_columns(B, fit_scale):
    free = np.ones(4 + 3 * B, dtype=bool)
    free[3] = bool(fit_scale)
    return free


class _FrameBlock:
    """The frames ``frames`` of a :class:`_Problem`, starting at ``poses``, as independent problems of
    :func:`solver.fit.least_squares.levenberg_marquardt` (their normal equations held as ``H``, ``g``)."""

    def __init__(self, prob, poses, frames):
        self.prob, self.poses, self.frames = prob, poses, frames
        self.size = len(frames)
        P = int(prob.free.sum())
        self.H, self.g = np.empty((self.size, P, P)), np.empty((self.size, P))

    def energy(self, idx):
        return self.prob.energy(_take(self.poses, idx), self.frames[idx])

    def build(self, idx):
        self.H[idx], self.g[idx], E = self.prob.system(_take(self.poses, idx), self.frames[idx])
        return E

    def solve(self, idx, mu):
        return solve_damped(self.H[idx], self.g[idx], mu, DAMP_FLOOR)

    def try_steps(self, idx, steps):
        delta = np.zeros((len(idx), len(self.prob.free)))
        delta[:, self.prob.free] = steps
        self.trial_idx, self.trial = idx, apply_pose_increment(_take(self.poses, idx), delta)
        return self.prob.energy(self.trial, self.frames[idx])

    def accept(self, which):
        _put(self.poses, self.trial_idx[which], _take(self.trial, np.flatnonzero(which)))

    def step_norm(self, steps):
        return np.linalg.norm(steps, axis=1)


def _lm_block(prob, poses, frames, max_iterations, tol):
    """Levenberg–Marquardt on ``frames`` (all together) from ``poses``, ÷3 / ×4 damping from μ = MU0 per
    frame.  Returns (poses, E, iterations, converged)."""
    block = _FrameBlock(prob, poses, frames)
    damping = FixedRatioDamping(np.full(len(frames), MU0), mu_min=MU_MIN, mu_max=MU_MAX)
    out = levenberg_marquardt(block, damping, Limits(trials=max_iterations, decrease_tol=tol, step_tol=tol))
    return block.poses, out.energy, out.trials, out.converged


def _block_size(V):
    """Frames solved together: the posed block, residuals and the compact Jacobian of one anchor group
    (:class:`_Problem`) take about 8 float64 arrays (V, 3) per frame."""
    return max(1, int(BLOCK_BYTES // (8 * V * 3 * 8)))


def fit_poses(model, targets, init="procrustes", fit_scale=False, vertex_weights=None,
              max_iterations=50, tol=1e-12, groups=None, progress=None):
    """Fit one pose per frame of ``targets (N, V, 3)`` (metres; registered to the model's vertices) with
    the model fixed.

    init: ``"procrustes"``, ``"previous"`` or a :class:`Poses` of N frames (module docstring);
    fit_scale: also fit the uniform subject scale (else it stays at the initial value, 1 for Procrustes);
    vertex_weights: optional ``(V,)`` non-negative per-vertex weights (0 ignores a vertex);
    max_iterations: LM iterations per frame; tol: stop when the relative decrease of E or the step norm
    falls below it; groups: an :class:`AnchorGroups` of the model to reuse;
    progress: optional ``progress(fraction, text)`` (may raise ``Cancelled``).
    Returns :class:`PoseFit`.  Runs with numpy's BLAS on one thread (:func:`solver.parallel.single_blas_thread`)."""
    with single_blas_thread():
        return _fit_poses(model, targets, init, fit_scale, vertex_weights, max_iterations, tol, groups, progress)


def _fit_poses(model, targets, init, fit_scale, vertex_weights, max_iterations, tol, groups, progress):
    """The body of :func:`fit_poses`."""
    y, w = _check_targets(model, targets, vertex_weights)
    N, V = y.shape[:2]
    B = model.skeleton.num_bones
    if groups is None:
        groups = AnchorGroups(model)
    prob = _Problem(model, groups, y, w, _free_columns(B, fit_scale))
    if isinstance(init, Poses):
        check_pose_shapes(model, init)
        if len(init) != N:
            raise ArticulaInputError(f"init: {len(init)} poses for {N} target frames")
        start = Poses(init.rotations.copy(), init.translations.copy(), init.scales.copy())
        start.validate(B)
    elif init in ("procrustes", "previous"):
        start = procrustes_init(model, y)
    else:
        raise ArticulaInputError(f"init: expected 'procrustes', 'previous' or Poses, got {init!r}")
    poses = Poses(start.rotations.copy(), start.translations.copy(), start.scales.copy())
    E = np.zeros(N)
    iters = np.zeros(N, dtype=np.int64)
    conv = np.zeros(N, dtype=bool)
    if init == "previous":
        blocks = [np.array([n]) for n in range(N)]
        threads = 1
    else:
        threads = parallel.workers()
        size = parallel.piece_size(N, _block_size(V))
        blocks = [np.arange(s, min(N, s + size)) for s in range(0, N, size)]

    def fit(idx):
        block = _take(poses, idx)
        if init == "previous" and idx[0] > 0:
            prev = _take(poses, idx - 1)
            if prob.energy(prev, idx)[0] < prob.energy(block, idx)[0]:
                block = prev
        block, E[idx], iters[idx], conv[idx] = _lm_block(prob, block, idx, max_iterations, tol)
        _put(poses, idx, block)

    for k in range(0, len(blocks), threads):              # independent blocks, one per solver thread
        batch = blocks[k:k + threads]
        parallel.map_pieces(fit, batch)
        if progress is not None:
            progress((k + len(batch)) / len(blocks), f"fitting poses: frame {batch[-1][-1] + 1} of {N}")
    poses.rotations = quat_canonical(quat_normalize(poses.rotations))
    posed = hybrid_skin(model, poses, groups)
    err = np.linalg.norm(posed - y, axis=2)
    wsum = float(V) if w is None else w.sum()
    e2 = err ** 2 if w is None else err ** 2 * w
    return PoseFit(poses, np.sqrt(e2.sum(axis=1) / wsum), err.astype(np.float32), E, iters, conv)
