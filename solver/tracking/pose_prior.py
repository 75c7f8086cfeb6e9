"""The pose prior of tracking: pairwise Gaussian mixtures on successive joints and per-DoF box limits.

Dissertation (model-adaptive mocap) §4.1.1 (Eq. 4.1) and §4.1.3 (Eq. 4.7-4.8), box constraints §4.1.1
and §4.1.4.  Rotations are bone-local exp-map vectors ``r = log(q)`` (angle = norm, radians) of the pose
quaternions of :class:`solver.rig.model.Poses`.  Joints are bones 1..B-1; bone 0 (root) is free.

* Pairs: ``(parents[c], c)`` for every bone c whose parent is not the root; each pair has a mixture over
  the 6-vector ``x = [r_parent; r_child]`` whose component count (1..k_max) is chosen by leave-one-out,
  then a greedy leave-one-out search zeroes entries of the cross-joint 3x3 precision block.
* Value: the unnormalised mixture ``P~_p(x) = sum_k w_k exp(-1/2 (x - m_k)^T L_k (x - m_k))`` in (0, 1];
  ``Q^pose = 1 - mean_p P~_p``; the Levenberg-Marquardt residual is ``e_p = sqrt(1 - P~_p + 1e-12)``.
* Covariances get at least ``min_variance`` (rad²) on their diagonal (:mod:`.gmm`): the default keeps them
  regular; a prior meant for other bodies than its training poses' uses a larger floor.
* Box limits: per joint and DoF, [min, max] of r over the training poses widened by ``margin`` times
  the interval width on each side (default 0, as in the dissertation).

Stored as a small ``.npz`` (format "articula-pose-prior/1", no pickles).  A generic human prior ships in
``data/generic_human_prior.npz`` (built by ``tools/make_generic_prior.py``; docs/track.md) and is mapped to
another skeleton through the bone-role vocabulary (:func:`generic_prior`, :func:`solver.roles.bone_keys`).
"""
import os
from dataclasses import dataclass, field, replace

import numpy as np

from ..errors import ArticulaInputError
from ..geometry.rotations import quat_to_rotvec
from ..rig.jacobians import pose_layout
from ..rig.model import Poses
from ..roles import bone_keys
from . import gmm

FORMAT = "articula-pose-prior/1"
K_MAX = 8                # largest component count tried (the dissertation found 2-10 on 71 poses)
RESIDUAL_EPS = 1e-12     # keeps e_p differentiable where P~ = 1
MIN_POSES = 3            # fewer poses cannot be cross-validated: use the generic prior
GENERIC_PATH = os.path.join(os.path.dirname(os.path.abspath(__file__)), "data", "generic_human_prior.npz")
_ARRAYS = ("frames", "pairs", "weights", "means", "precisions", "lower", "upper", "components", "loo_scores")


@dataclass
class PosePrior:
    """names (B,); frames (B, 3, 3) rest axes of the rig it was learned on (columns, world); pairs (P, 2)
    bone indices (parent joint, child joint); weights (P, K); means (P, K, 6); precisions (P, K, 6, 6)
    (padding components have weight 0); lower, upper (B, 3) radians (+-inf: no bound); components (P,)
    chosen counts; loo_scores (P,) mean held-out log-likelihoods; info: strings (provenance); enabled:
    False makes every term and bound vanish."""
    names: list
    frames: np.ndarray
    pairs: np.ndarray
    weights: np.ndarray
    means: np.ndarray
    precisions: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    components: np.ndarray
    loo_scores: np.ndarray
    info: dict = field(default_factory=dict)
    enabled: bool = True

    @property
    def num_pairs(self) -> int:
        return len(self.pairs) if self.enabled else 0

    @classmethod
    def none(cls, skeleton) -> "PosePrior":
        """The switched-off prior: no pair terms, no bounds."""
        B = skeleton.num_bones
        return cls(list(skeleton.names), skeleton.frames, np.zeros((0, 2), np.int64), np.zeros((0, 1)),
                   np.zeros((0, 1, 6)), np.zeros((0, 1, 6, 6)), np.full((B, 3), -np.inf), np.full((B, 3), np.inf),
                   np.zeros(0, np.int64), np.zeros(0), {"source": "none"}, enabled=False)

    @classmethod
    def from_poses(cls, skeleton, poses: Poses, k_max: int = K_MAX, margin: float = 0.0, seed: int = 0,
                   sparsify: bool = True, min_variance: float = gmm.REG_ABS) -> "PosePrior":
        """Learn the prior from training ``poses`` (N >= 3) of ``skeleton`` (see the module docstring)."""
        poses.validate(skeleton.num_bones)
        if len(poses) < MIN_POSES:
            raise ArticulaInputError(f"pose prior: {len(poses)} training pose(s); at least {MIN_POSES} are "
                                     f"needed to learn one (use the generic human prior instead)")
        if margin < 0:
            raise ArticulaInputError(f"pose prior: margin must be >= 0, got {margin}")
        r = quat_to_rotvec(poses.rotations)
        pairs = joint_pairs(skeleton.parents)
        fitted = [fit_pair(np.concatenate([r[:, a], r[:, c]], axis=1), k_max, seed, sparsify, min_variance)
                  for a, c in pairs]
        lower, upper = box_limits(r, margin)
        info = {"source": "training poses", "poses": str(len(poses)), "k_max": str(k_max), "margin": str(margin),
                "min_variance": str(min_variance)}
        return cls.from_mixtures(skeleton, pairs, [f[0] for f in fitted], lower, upper,
                                 np.array([f[1] for f in fitted]), info)

    @classmethod
    def from_mixtures(cls, skeleton, pairs, mixtures, lower, upper, loo_scores, info) -> "PosePrior":
        """Pack one :class:`gmm.Mixture` per pair of ``skeleton``'s bones into padded arrays."""
        K = max([m.num_components for m in mixtures], default=1)
        P = len(mixtures)
        w, mu, L = np.zeros((P, K)), np.zeros((P, K, 6)), np.tile(np.eye(6), (P, K, 1, 1))
        for p, m in enumerate(mixtures):
            k = m.num_components
            w[p, :k], mu[p, :k], L[p, :k] = m.weights, m.means, m.precisions
        comps = np.array([m.num_components for m in mixtures], dtype=np.int64)
        return cls(list(skeleton.names), skeleton.frames, np.asarray(pairs, np.int64).reshape(-1, 2), w, mu, L,
                   lower, upper, comps, np.asarray(loo_scores, np.float64), dict(info))

    # --- evaluation ------------------------------------------------------------------------------
    def pair_vectors(self, rotations) -> np.ndarray:
        """``(N, P, 6)`` pair vectors of quaternions ``(N, B, 4)``."""
        r = quat_to_rotvec(_as_poses(rotations, len(self.names)))
        return np.concatenate([r[:, self.pairs[:, 0]], r[:, self.pairs[:, 1]]], axis=2)

    def likelihoods(self, rotations) -> np.ndarray:
        """``(N, P)`` unnormalised mixtures P~ in (0, 1] at poses ``(N, B, 4)`` or ``(B, 4)``."""
        return _unnormalised(self.pair_vectors(rotations), self.weights, self.means, self.precisions)[0]

    def value(self, rotations) -> np.ndarray:
        """``(N,)`` Q^pose = 1 - mean over pairs of P~ (Eq. 4.8); 0 when there are no pairs."""
        lik = self.likelihoods(rotations)
        return 1.0 - lik.mean(axis=1) if lik.shape[1] else np.zeros(len(lik))

    def residuals(self, rotations) -> np.ndarray:
        """``(N, P)`` residuals e_p = sqrt(1 - P~_p + 1e-12) (unscaled; the solver multiplies by
        sqrt(w_pose / (N P)))."""
        return np.sqrt(1.0 - self.likelihoods(rotations) + RESIDUAL_EPS)

    def pair_jacobian(self, rotations) -> np.ndarray:
        """``(N, P, 6)`` derivative of e_p with respect to its pair vector [r_parent; r_child]."""
        lik, grad = _unnormalised(self.pair_vectors(rotations), self.weights, self.means, self.precisions)
        e = np.sqrt(1.0 - lik + RESIDUAL_EPS)
        return -grad / (2.0 * e[..., None])

    def jacobian(self, rotations) -> np.ndarray:
        """``(N, P, 4 + 3B)`` derivative of e_p with respect to the pose increments of
        :func:`solver.rig.jacobians.pose_layout` (``q_b <- q_b exp(delta_b)``): the pair Jacobian chained
        through d r_b / d delta_b (:func:`rotvec_increment_jacobian`)."""
        q = _as_poses(rotations, len(self.names))
        B = len(self.names)
        layout = pose_layout(B)
        Jx = self.pair_jacobian(q)
        Jr = rotvec_increment_jacobian(quat_to_rotvec(q))           # (N, B, 3, 3)
        out = np.zeros((len(q), self.num_pairs, layout["size"]))
        for p, (a, c) in enumerate(self.pairs[:self.num_pairs]):
            out[:, p, layout["rotation"](a)] += np.einsum("ni,nij->nj", Jx[:, p, :3], Jr[:, a])
            out[:, p, layout["rotation"](c)] += np.einsum("ni,nij->nj", Jx[:, p, 3:], Jr[:, c])
        return out

    def box_violations(self, rotvecs):
        """For proposed rotation vectors ``(B, 3)`` (or ``(N, B, 3)``): ``(violated bool, clamped)`` of the
        same shape; clamped values lie on the violated bound (the active set of §4.1.4)."""
        r = np.asarray(rotvecs, dtype=np.float64)
        if not self.enabled:
            return np.zeros(r.shape, dtype=bool), r.copy()
        clamped = np.clip(r, self.lower, self.upper)
        return clamped != r, clamped

    # --- files -----------------------------------------------------------------------------------
    def save(self, path) -> None:
        """Write the prior as an ``.npz`` (format "articula-pose-prior/1"); info values are strings."""
        arrays = {k: getattr(self, k) for k in _ARRAYS}
        np.savez_compressed(path, format=np.array(FORMAT), names=np.array(self.names, dtype=str),
                            enabled=np.array(self.enabled), info_keys=np.array(list(self.info), dtype=str),
                            info_values=np.array([str(v) for v in self.info.values()], dtype=str), **arrays)

    @classmethod
    def load(cls, path) -> "PosePrior":
        """Read a file written by :meth:`save`; :class:`ArticulaInputError` naming the file and problem."""
        try:
            with np.load(path, allow_pickle=False) as z:
                data = {k: z[k] for k in z.files}
        except (OSError, ValueError, EOFError) as exc:
            raise ArticulaInputError(f"{path}: not a readable pose-prior .npz file ({exc})") from None
        if str(data.get("format", "")) != FORMAT:
            raise ArticulaInputError(f"{path}: format key is {str(data.get('format', 'missing'))!r}, "
                                     f"expected {FORMAT!r}")
        missing = [k for k in _ARRAYS + ("names", "enabled", "info_keys", "info_values") if k not in data]
        if missing:
            raise ArticulaInputError(f"{path}: missing key(s) {', '.join(missing)}")
        info = dict(zip([str(k) for k in data["info_keys"]], [str(v) for v in data["info_values"]]))
        prior = cls([str(n) for n in data["names"]], *(data[k] for k in _ARRAYS), info, bool(data["enabled"]))
        _check(prior, path)
        return prior


def _check(prior: PosePrior, path) -> None:
    """Shapes and values consistent (raises ArticulaInputError naming ``path`` and the key)."""
    B, P, K = len(prior.names), len(prior.pairs), prior.weights.shape[-1]
    shapes = {"frames": (B, 3, 3), "pairs": (P, 2), "weights": (P, K), "means": (P, K, 6),
              "precisions": (P, K, 6, 6), "lower": (B, 3), "upper": (B, 3), "components": (P,), "loo_scores": (P,)}
    for key, shape in shapes.items():
        if getattr(prior, key).shape != shape:
            raise ArticulaInputError(f"{path}: {key}: expected shape {shape}, got {getattr(prior, key).shape}")
    if P and ((prior.pairs < 0) | (prior.pairs >= B)).any():
        raise ArticulaInputError(f"{path}: pairs: bone index outside 0..{B - 1}")
    if not all(np.isfinite(getattr(prior, k)).all() for k in ("weights", "means", "precisions")):
        raise ArticulaInputError(f"{path}: non-finite mixture values")
    if (prior.lower > prior.upper).any():
        raise ArticulaInputError(f"{path}: lower bound above upper bound")


def _as_poses(rotations, num_bones) -> np.ndarray:
    q = np.asarray(rotations, dtype=np.float64)
    q = q[None] if q.ndim == 2 else q
    if q.ndim != 3 or q.shape[1:] != (num_bones, 4):
        raise ArticulaInputError(f"pose prior: rotations of shape {q.shape}, expected (N, {num_bones}, 4)")
    return q


def _unnormalised(x, weights, means, precisions):
    """P~ ``(N, P)`` and its gradient ``(N, P, 6)`` at pair vectors ``x (N, P, 6)``."""
    diff = x[:, :, None, :] - means[None]                            # (N, P, K, 6)
    Ld = np.einsum("pkij,npkj->npki", precisions, diff)
    g = weights[None] * np.exp(-0.5 * np.einsum("npki,npki->npk", diff, Ld))
    return g.sum(axis=2), -np.einsum("npk,npki->npi", g, Ld)


def joint_pairs(parents) -> np.ndarray:
    """``(P, 2)`` (parent, child) for every bone c >= 1 whose parent is not bone 0 (the root)."""
    parents = np.asarray(parents)
    child = np.flatnonzero(parents > 0)
    return np.stack([parents[child], child], axis=1).astype(np.int64)


def box_limits(r, margin: float = 0.0):
    """``(lower, upper)`` (B, 3) from rotation vectors ``r (N, B, 3)``: per-DoF min/max widened by
    ``margin`` times the width on each side; the root (bone 0) is unbounded."""
    lo, hi = r.min(axis=0), r.max(axis=0)
    width = hi - lo
    lo, hi = lo - margin * width, hi + margin * width
    lo[0], hi[0] = -np.inf, np.inf
    return lo, hi


def fit_pair(X, k_max: int = K_MAX, seed: int = 0, sparsify: bool = True, min_variance: float = gmm.REG_ABS):
    """``(mixture, loo score)`` for the pair vectors ``X (N, 6)``: component count by leave-one-out, then
    the greedy leave-one-out zero pattern of the cross-joint precision block (rows 0-2, columns 3-5)."""
    _, mix, fits, scores = gmm.select_components(X, k_max, seed, min_variance)
    score = scores.max()
    if sparsify:
        cross = [(i, j) for i in range(3) for j in range(3, 6)]
        entries, _, score = gmm.greedy_zero_pattern(X, fits, cross)
        mix = gmm.sparsified(mix, entries)
    return mix, score


def rotvec_increment_jacobian(r) -> np.ndarray:
    """``(..., 3, 3)`` d log(exp(r) exp(delta)) / d delta at delta = 0 for rotation vectors ``r (..., 3)``:
    the inverse right Jacobian of SO(3), ``I + [r]x/2 + c(t) [r]x^2`` with t = |r| and
    ``c = (1 - (t/2) cot(t/2)) / t^2`` (-> 1/12 at t = 0, 1/pi^2 at t = pi: finite for every angle)."""
    r = np.asarray(r, dtype=np.float64)
    t = np.linalg.norm(r, axis=-1)
    small = t < 1e-4
    ts = np.where(small, 1.0, t)
    c = np.where(small, 1.0 / 12.0 + t * t / 720.0, (1.0 - 0.5 * ts / np.tan(0.5 * ts)) / (ts * ts))
    z = np.zeros(t.shape)
    K = np.stack([z, -r[..., 2], r[..., 1], r[..., 2], z, -r[..., 0], -r[..., 1], r[..., 0], z],
                 axis=-1).reshape(r.shape + (3,))
    return np.eye(3) + 0.5 * K + c[..., None, None] * (K @ K)


def generic_prior(skeleton, path: str = GENERIC_PATH) -> PosePrior:
    """The shipped generic human prior (cmu_mb bones) mapped onto ``skeleton`` bone by bone through the
    role vocabulary (:func:`solver.roles.bone_keys`: the bones' roles, so any naming the recogniser knows,
    a learned rig's role names included; bones without a role by their name).

    A pair (parent, child) of ``skeleton`` gets the generic mixture of the matching pair, rotated from the
    generic rig's rest frames into ``skeleton``'s (``r_local' = F'^T F r_local``; both rigs must share the
    world convention, Z up, facing -Y, and a similar rest pose).  Bones or pairs it cannot map get no
    prior term and no bound (their box is the axis-aligned hull of the rotated box when they map)."""
    src = PosePrior.load(path)
    src_parents = np.full(len(src.names), -1)
    src_parents[src.pairs[:, 1]] = src.pairs[:, 0]          # from the pairs; the root's children stay -1
    index = {k: i for i, k in enumerate(bone_keys(src.names, src_parents))}
    src_pair = {(int(a), int(c)): p for p, (a, c) in enumerate(src.pairs)}
    to_src = [index.get(k) for k in bone_keys(skeleton.names, skeleton.parents)]
    to_src[0] = None
    R = [None if s is None else skeleton.frames[b].T @ src.frames[s] for b, s in enumerate(to_src)]
    pairs, mixtures, scores = [], [], []
    for a, c in joint_pairs(skeleton.parents):
        p = src_pair.get((to_src[a], to_src[c])) if None not in (to_src[a], to_src[c]) else None
        if p is None:
            continue
        T = np.zeros((6, 6))
        T[:3, :3], T[3:, 3:] = R[a], R[c]
        k = int(src.components[p])
        L = np.einsum("ij,kjl,ml->kim", T, src.precisions[p, :k], T)
        mixtures.append(gmm.Mixture(src.weights[p, :k], src.means[p, :k] @ T.T, L))
        pairs.append((a, c))
        scores.append(src.loo_scores[p])
    lower, upper = _mapped_box(src, to_src, R, skeleton.num_bones)
    info = dict(src.info)
    info["mapped_pairs"] = f"{len(pairs)} of {len(joint_pairs(skeleton.parents))}"
    return PosePrior.from_mixtures(skeleton, pairs, mixtures, lower, upper, scores, info)


def widened(prior: PosePrior, other: PosePrior = None, pad: float = 0.0) -> PosePrior:
    """``prior`` with its box limits replaced by the hull of its box and ``other``'s finite bounds (e.g.
    the generic human prior's on the same skeleton), widened by ``pad`` radians on each side.  Why: the
    dissertation's box is the min/max over many training poses; over a model's few (30 range-of-motion
    poses) it excludes ordinary motion (docs/track.md "Box limits")."""
    if pad < 0 or not np.isfinite(pad):
        raise ArticulaInputError(f"pose prior: pad must be finite and >= 0, got {pad}")
    lower, upper = prior.lower.copy(), prior.upper.copy()
    if other is not None:
        if other.lower.shape != lower.shape:
            raise ArticulaInputError(f"pose prior: box of shape {other.lower.shape}, expected {lower.shape}")
        lower = np.where(np.isfinite(other.lower), np.minimum(lower, other.lower), lower)
        upper = np.where(np.isfinite(other.upper), np.maximum(upper, other.upper), upper)
    info = dict(prior.info, box=f"hull with {other.info.get('source', 'another prior') if other else 'nothing'}, "
                                f"pad {pad:g} rad")
    return replace(prior, lower=lower - pad, upper=upper + pad, info=info)


def _mapped_box(src, to_src, R, B):
    """Bounds (B, 3) of the rotated source boxes (axis-aligned hull); unmapped bones unbounded, and so
    are bones mapped to a source bone with an unbounded DoF (the generic root, ``Hips``, as a child
    bone): the rotation mixes its axes, and ``inf - inf`` would give NaN bounds."""
    lower, upper = np.full((B, 3), -np.inf), np.full((B, 3), np.inf)
    for b, s in enumerate(to_src):
        if s is not None and np.isfinite(src.lower[s]).all() and np.isfinite(src.upper[s]).all():
            centre, half = 0.5 * (src.upper[s] + src.lower[s]), 0.5 * (src.upper[s] - src.lower[s])
            lower[b], upper[b] = R[b] @ centre - np.abs(R[b]) @ half, R[b] @ centre + np.abs(R[b]) @ half
    return lower, upper
