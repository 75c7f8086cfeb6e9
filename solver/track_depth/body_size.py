"""Limb lengths of the template adapted to the person (depth-camera tracking dissertation ch. 5 §4.6,
Eq. 5.12-5.19, and ch. 6 Algorithm 4).

One scale ``s_b`` per part stretches the part along its bone (head -> tail): child joints move to
``h'_c = h'_b + s_b (h_c - h_b)``, a vertex's share on part b keeps its offset across the bone and
scales its position along it (``x'_b = h'_b + s_b gamma u_b + r_perp``, the dissertation's differential
bone coordinates: lengths change, girths do not).  With the pose's rotations fixed the posed vertices
are linear in the scales, so the scales solve a linear least-squares problem on the tracker's point
pairs, with the regulariser of Eq. 5.19 / 6.17 (left/right pairs weight 1, connected parts 0.5) and a
weak pull to the template's length for parts the camera does not see.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from ..rig.kinematics import forward_kinematics
from ..rig.model import Model, Skeleton
from ..tracking.blend_body import linear_blend_weights

SYMMETRY_WEIGHT = 1.0      # nu of left/right pairs (Eq. 5.19)
CONNECTED_WEIGHT = 0.5     # nu of a part and its parent
REGULARISER = 2.0          # lambda_s relative to the mean diagonal of the data term (ours)
KEEP_WEIGHT = 0.02         # pull to the start scales, relative to the same diagonal
CONTACT_WEIGHT = 50.0      # the standing foot's floor contact, in point pairs
SCALE_RANGE = (0.6, 1.6)   # scales are clipped to this (a body part is not half or twice the template's)


@dataclasses.dataclass
class PartFrames:
    """The template geometry the scales act on: ``heads``/``tails`` (B, 3), ``axes`` u_b (B, 3),
    ``path`` (B, B) bool ``[b, a]`` a is a strict ancestor of b, ``via`` (B, B) int: the child of a on the
    way to b (-1 elsewhere)."""
    heads: np.ndarray
    tails: np.ndarray
    axes: np.ndarray
    path: np.ndarray
    via: np.ndarray

    @classmethod
    def of(cls, skeleton: Skeleton) -> "PartFrames":
        B, par = skeleton.num_bones, skeleton.parents
        d = skeleton.tails - skeleton.heads
        axes = d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)
        path = np.zeros((B, B), bool)
        via = np.full((B, B), -1)
        for b in range(1, B):
            path[b] = path[par[b]]
            via[b] = via[par[b]]
            path[b, par[b]] = True
            via[b, par[b]] = b
        return cls(skeleton.heads.copy(), skeleton.tails.copy(), axes, path, via)


def scaled_model(template: Model, scales: np.ndarray) -> Model:
    """``template`` with every part stretched by ``scales`` (B,) (see the module docstring); rest frames,
    faces and weights unchanged."""
    sk = template.skeleton
    pf = PartFrames.of(sk)
    heads = _scaled_heads(pf, sk.parents, scales)
    tails = heads + scales[:, None] * (sk.tails - sk.heads)
    w = linear_blend_weights(template)
    x = template.rest_vertices
    rel = x[:, None, :] - sk.heads[None]                       # (V, B, 3)
    gamma = np.einsum("vbc,bc->vb", rel, pf.axes)
    moved = heads[None] + rel + ((scales - 1.0) * gamma)[:, :, None] * pf.axes[None]
    verts = np.einsum("vb,vbc->vc", w, moved)
    skel = Skeleton(sk.names, sk.parents, heads, tails, sk.frames)
    return Model(verts, template.faces, skel, template.anchor, template.twist_weights, template.swing_weights)


def _scaled_heads(pf: PartFrames, parents, scales) -> np.ndarray:
    heads = pf.heads.copy()
    for b in range(1, len(parents)):
        p = parents[b]
        heads[b] = heads[p] + scales[p] * (pf.heads[b] - pf.heads[p])
    return heads


def linear_terms(template: Model, body_ids, pose) -> tuple:
    """Posed subset points of the scaled template as ``c (m, 3) + sum_a s_a E[:, a] (m, B, 3)`` for the
    pose's rotations and root joint (exact: the rest vertex, the joints and the linear blend are all
    linear in the scales)."""
    sk = template.skeleton
    pf = PartFrames.of(sk)
    Rm, _ = forward_kinematics(sk, pose)
    Rm = Rm[0]                                                    # includes the uniform scale
    g0 = sk.heads[0] + pose.translations[0]
    w = linear_blend_weights(template)[body_ids]                 # (m, B)
    rel = template.rest_vertices[body_ids][:, None, :] - sk.heads[None]
    gamma = np.einsum("mbc,bc->mb", rel, pf.axes)
    perp = rel - gamma[:, :, None] * pf.axes[None]
    B = sk.num_bones
    delta = np.zeros((B, B, 3))                                  # [b, a]: h_via - h_a on b's path (rest)
    rows, cols = np.nonzero(pf.path)
    delta[rows, cols] = pf.heads[pf.via[rows, cols]] - pf.heads[cols]
    # rest vertex x' = x0 + sum_a s_a X_a;  joints h'_b = h0 + sum_a s_a delta[b, a]
    x0 = sk.heads[0] + np.einsum("mb,mbc->mc", w, perp)
    X = np.einsum("mb,bac->mac", w, delta) + (w * gamma)[:, :, None] * pf.axes[None]
    # v = sum_b w_b [g'_b + Rm_b (x' - h'_b)],  g'_b = g0 + sum_a s_a Rm_a delta[b, a]
    c = g0 + np.einsum("mb,brc,mc->mr", w, Rm, x0 - sk.heads[0])
    chain = np.einsum("arc,bac->bar", Rm, delta) - np.einsum("brc,bac->bar", Rm, delta)
    E = np.einsum("mb,bar->mar", w, chain) + np.einsum("mb,brc,mac->mar", w, Rm, X)
    return c, E


def pair_weights(skeleton: Skeleton) -> list:
    """``(i, j, nu)`` regulariser pairs: mirror parts (names ending .L/.R) and every part with its parent."""
    index = {n: i for i, n in enumerate(skeleton.names)}
    pairs = []
    for i, n in enumerate(skeleton.names):
        if n.endswith(".L") and n[:-2] + ".R" in index:
            pairs.append((i, index[n[:-2] + ".R"], SYMMETRY_WEIGHT))
    for b in range(1, skeleton.num_bones):
        if skeleton.parents[b] > 0:
            pairs.append((b, int(skeleton.parents[b]), CONNECTED_WEIGHT))
    return pairs


@dataclasses.dataclass
class FramePairs:
    """What one adaptation frame contributes: subset vertex ids ``ids`` (n,) with observed ``targets``
    (n, 3) at ``pose``; ``contact`` (vertex id, n (3,), d) a vertex standing on the floor plane or None."""
    ids: np.ndarray
    targets: np.ndarray
    pose: object
    contact: tuple | None = None


def frame_system(frame: FramePairs, terms) -> tuple:
    """``(AtA, Atb)`` of one frame's pairs for unknowns ``[p (P), translation (3)]``, where
    ``terms(ids, pose) -> (c (n, 3), E (n, P, 3))`` gives the posed points as ``c + sum_i p_i E_i``."""
    c, E = terms(frame.ids, frame.pose)
    n, P = E.shape[:2]
    A = np.concatenate([E.transpose(0, 2, 1), np.broadcast_to(np.eye(3), (n, 3, 3))], axis=2).reshape(-1, P + 3)
    AtA, Atb = A.T @ A, A.T @ (frame.targets - c).reshape(-1)
    if frame.contact is not None:
        vid, normal, d = frame.contact
        cc, EE = terms(np.array([vid]), frame.pose)
        a = np.concatenate([EE[0] @ normal, normal]) * np.sqrt(CONTACT_WEIGHT)
        AtA += np.outer(a, a)
        Atb -= a * (cc[0] @ normal + d) * np.sqrt(CONTACT_WEIGHT)
    return AtA, Atb


def pooled(frames, terms, P: int) -> tuple:
    """Sum over frames of the systems with each frame's translation eliminated (Schur complement)."""
    H, g = np.zeros((P, P)), np.zeros(P)
    for f in frames:
        AtA, Atb = frame_system(f, terms)
        Hst, Htt = AtA[:P, P:], AtA[P:, P:] + 1e-9 * np.eye(3)
        K = Hst @ np.linalg.inv(Htt)
        H += AtA[:P, :P] - K @ Hst.T
        g += Atb[:P] - K @ Atb[P:]
    return H, g


def solve_scales(template: Model, frames, prior) -> np.ndarray:
    """Per-part scales over ``template`` from the frames' pairs (Eq. 5.19 / 6.16-6.17): data term,
    mirror/connected regulariser and a weak pull to ``prior`` (B,), clipped to :data:`SCALE_RANGE`."""
    B = template.skeleton.num_bones
    H, g = pooled(frames, lambda ids, pose: linear_terms(template, ids, pose), B)
    scale = max(float(np.mean(np.diag(H))), 1e-9)
    R = np.zeros((B, B))
    for i, j, nu in pair_weights(template.skeleton):
        R[[i, j], [i, j]] += nu
        R[i, j] -= nu
        R[j, i] -= nu
    H = H + REGULARISER * scale * R + KEEP_WEIGHT * scale * np.eye(B)
    g = g + KEEP_WEIGHT * scale * np.asarray(prior, float)
    return np.clip(np.linalg.solve(H, g), *SCALE_RANGE)
