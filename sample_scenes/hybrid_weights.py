"""Anchors and swing/twist weights of Articula's hybrid skin, derived from a rig's LBS weights.

Anchor rule.  For vertex v with LBS weights w (rows sum 1) the *coverage* of a candidate anchor a is
``w[a] + sum of w[c] over the children c of a`` (the weight the hybrid skin can express with anchor a).
The anchor is the bone of largest coverage; ties go to the bone with the larger own weight, so a vertex
weighted to one bone only is anchored to that bone with zero weights (rigid).  A vertex blending
across one joint (e.g. upper arm 0.6, forearm 0.4) is anchored to the parent side (upper arm) with
weight 0.4 on the child.  Weight the hybrid skin cannot express is *lifted*, not dropped: weight on a
deeper descendant of a goes to the child of a on its path (it then moves with that child), weight on
an ancestor or another branch joins the anchor's own weight (:func:`lift_table`).  At most
``max_influences`` children are kept (largest first) and the weights are renormalised so that
``w[a] + sum(kept) = 1``; the swing weights are the kept children's weights, the remainder is the
neutral transform.  ``moved`` reports the LBS mass that was not on a or its children.

Twist ramp (so twist weights differ from swing weights where real skin does): for every bone b with
role ``upper_arm`` or ``forearm`` and exactly one child c, the vertices anchored at b get the twist
weight ``max(swing[c], r_max * smoothstep(0.25, 1, t))`` on c, where t = position along b (0 at the
head, 1 at the tail, projected on the bone axis) and r_max = :data:`TWIST_RAMP` of the role: twisting
the hand then twists the forearm skin progressively from the elbow (none) to the wrist, as pronation
does.  All other twist weights equal the swing weights.
"""
from __future__ import annotations

import numpy as np

from ..solver.errors import ArticulaInputError
from .bone_roles import skeleton_roles

TWIST_RAMP = {"upper_arm": 0.5, "forearm": 0.9}


def anchors_from_lbs(weights: np.ndarray, parents: np.ndarray, max_influences: int = 4):
    """(anchor (V,) int32, swing weights (V, B) float64, moved (V,) LBS mass not on a's children).

    weights (V, B) LBS weights with rows summing to 1; parents (B,) with parents[0] = -1.
    """
    W = np.asarray(weights, dtype=np.float64)
    parents = np.asarray(parents)
    if W.ndim != 2 or W.shape[1] != len(parents):
        raise ArticulaInputError(f"weights: expected shape (V, {len(parents)}), got {W.shape}")
    if max_influences < 1:
        raise ArticulaInputError(f"max_influences: must be >= 1, got {max_influences}")
    B = len(parents)
    child = np.zeros((B, B))
    child[parents[1:], np.arange(1, B)] = 1.0                 # child[a, c] = 1 if parents[c] == a
    coverage = W + W @ child.T
    anchor = np.argmax(coverage + 1e-6 * W, axis=1).astype(np.int32)
    moved = 1.0 - coverage[np.arange(len(W)), anchor]
    lifted = np.zeros_like(W)
    lift = lift_table(parents)
    for a in np.unique(anchor):
        rows = np.flatnonzero(anchor == a)
        np.add.at(lifted, (rows[:, None], lift[a][None, :]), W[rows])
    own = lifted[np.arange(len(W)), anchor]
    blend = lifted * child[anchor]
    blend = _keep_largest(blend, max_influences)
    return anchor, blend / (own + blend.sum(axis=1))[:, None], moved


def lift_table(parents: np.ndarray) -> np.ndarray:
    """(B, B) int: ``lift[a, b]`` = the child of a on the path to b if b descends from a child of a,
    else a (b is a itself, an ancestor or on another branch: its weight joins the anchor's own)."""
    B = len(parents)
    lift = np.tile(np.arange(B), (B, 1))
    for b in range(B):
        lift[:, b] = np.arange(B)
        node = b
        while parents[node] >= 0:
            lift[parents[node], b] = node
            node = parents[node]
    return lift


def _keep_largest(blend, k):
    """Keep the k largest entries per row (ties: lower bone index first)."""
    if k >= blend.shape[1]:
        return blend
    order = np.argsort(-blend, axis=1, kind="stable")[:, :k]
    out = np.zeros_like(blend)
    rows = np.arange(len(blend))[:, None]
    out[rows, order] = blend[rows, order]
    return out


def _smoothstep(e0, e1, x):
    t = np.clip((x - e0) / (e1 - e0), 0.0, 1.0)
    return t * t * (3 - 2 * t)


def twist_ramp_weights(vertices, skeleton, anchor, swing):
    """Twist weights (V, B): the swing weights with the forearm/upper-arm ramp (module docstring)."""
    twist = swing.copy()
    roles = skeleton_roles(skeleton.names)
    for b, role in enumerate(roles):
        kids = skeleton.children(b)
        if role not in TWIST_RAMP or len(kids) != 1:
            continue
        c = kids[0]
        rows = np.flatnonzero(anchor == b)
        axis = skeleton.tails[b] - skeleton.heads[b]
        t = (vertices[rows] - skeleton.heads[b]) @ axis / (axis @ axis)
        ramp = TWIST_RAMP[role] * _smoothstep(0.25, 1.0, t)
        twist[rows, c] = np.maximum(swing[rows, c], ramp)
    return twist
