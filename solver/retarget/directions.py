"""Bone rotations of a target rig that make every mapped segment point where the source's points.

For a role r mapped on both rigs, its *segment* runs from r's joint to the joint of its first primary
child mapped on both (:data:`.roles.NEXT`); end roles (no such child, or a segment of zero length on
either rig, like a BVH hips joint that coincides with the spine's) use the bone itself, except on
reversed chains (below), where a zero-length child is passed over for the next one.  With world
rest rotations ``S0`` (source bone r) and ``T0`` (target bone r), the target bone's world rotation in a
frame where the source bone has ``S`` is

    T = C · S · S0ᵀ · Q_rᵀ · T0

where ``Q_r`` carries the source's rest segment onto the target's (the smallest rotation after the
body-frame alignment ``G`` of the two rests: facing and up), so rest-pose differences (T-pose source,
A-pose target), bone rolls and axis conventions cancel, and ``C`` is the smallest rotation that makes the
target segment exactly parallel to the source's (it is the identity when the source segment is rigid
with bone r).  The twist about the segment follows the source bone.  End roles take ``Q`` of their
parent role.  Target bones that are not mapped (twist segments, helpers, extra spine bones, fingers the
source lacks) keep their rest pose relative to their parent, so several target bones per source bone
and several source bones per target bone are both handled.

*Reversed* segments: on a rig rooted elsewhere than the hips (a learned rig whose root part is the
chest) the child role's bone can be an ancestor of r's bone (the spine above the hips), so turning r's
bone cannot aim the segment.  Bone r then turns as an end role, and the bone r hangs from (its parent,
mapped or not) is turned about its own head, after its parents are posed, by the smallest rotation that
puts r's joint on the source's direction from the child's joint (exact when that parent's head is the
child's joint; otherwise the nearest point on that line its reach allows).  A bone aims one segment: its
own, unless it is the child role's bone and the reversed segment it spans is the longer (a learned chest
that carries the neck and, below it, the spine); the other segment then turns as an end role.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import ArticulaInputError
from ..geometry.rotations import rotation_between
from .armature import ArmatureRest, rest_world
from ..roles import NEXT, PARENT, ROLES

DEGENERATE = 1e-3        # segments shorter than this fraction of the body height are skipped


@dataclass
class Segment:
    role: str
    source: int            # source bone index of the role
    target: int            # target bone index of the role
    child: str | None      # the role its segment ends at (None: the bone's own direction)
    source_child: int = -1
    target_child: int = -1
    aim: int = -1          # target bone that aims the segment (the role's bone, or its parent if reversed)

    @property
    def aimed_by_own_bone(self) -> bool:
        return self.child is not None and self.aim == self.target


def _height(heads: np.ndarray) -> float:
    return float(max(np.ptp(heads[:, 2]), np.ptp(heads, axis=0).max(), 1e-9))


def plan_segments(source: ArmatureRest, target: ArmatureRest, pairs: dict) -> list:
    """:class:`Segment` of every role in ``pairs`` ``{role: (source bone, target bone)}``, parents first."""
    _, hs = rest_world(source)
    _, ht = rest_world(target)
    Hs, Ht = _height(hs), _height(ht)
    out = []
    for role in ROLES:
        if role not in pairs:
            continue
        s, t = source.index[pairs[role][0]], target.index[pairs[role][1]]
        seg = Segment(role, s, t, None)
        for child in (c for c in NEXT.get(role, []) if c in pairs):
            cs, ct = source.index[pairs[child][0]], target.index[pairs[child][1]]
            if (np.linalg.norm(hs[cs] - hs[s]) <= DEGENERATE * Hs
                    or np.linalg.norm(ht[ct] - ht[t]) <= DEGENERATE * Ht):
                if target.is_ancestor(t, ct):          # t carries the child, whose own aim would undo t's
                    break
                continue                               # zero length on a rig: the next child up the line
            seg.child, seg.source_child, seg.target_child = child, cs, ct
            if not target.is_ancestor(ct, t):          # turning t aims it (through constraints on Rigify)
                seg.aim = t
            break                                      # else reversed: the bone t hangs from aims it
        out.append(seg)
    _assign_reversed_aims(target, out, ht)
    return out


def _assign_reversed_aims(target: ArmatureRest, segs, heads: np.ndarray) -> None:
    """Give each reversed segment the parent of its role's bone as aiming bone.  A bone aims one segment:
    when that bone already aims its own, the reversed one takes it only if the bone is the child role's
    (it spans the reversed segment, as a learned chest above the spine) and the segment is the longer on
    the target (world rest ``heads``); the other then turns with its bone as an end role."""
    length = lambda seg: np.linalg.norm(heads[seg.target_child] - heads[seg.target])  # noqa: E731
    aims = {seg.aim: seg for seg in segs if seg.aim >= 0}
    for seg in segs:
        if seg.child is None or seg.aim >= 0 or target.parents[seg.target] < 0:
            continue
        p = int(target.parents[seg.target])
        if p in aims and (p != seg.target_child or length(aims[p]) >= length(seg)):
            continue
        if p in aims:
            aims[p].aim = -1
        seg.aim, aims[p] = p, seg


def body_frame(heads: np.ndarray, segs, which: str) -> np.ndarray:
    """(3, 3) columns (left, forward, up) of a rig's rest body, from the hips→head line and the thighs (or
    upper arms); ``which`` is 'source' or 'target'."""
    idx = {seg.role: getattr(seg, which) for seg in segs}
    up = None
    top = next((r for r in ("head", "neck", "chest", "spine") if r in idx), None)
    if "hips" in idx and top:
        up = heads[idx[top]] - heads[idx["hips"]]
    if up is None or np.linalg.norm(up) < 1e-12:
        up = np.array([0.0, 0.0, 1.0])
    up = up / np.linalg.norm(up)
    left = None
    for a, b in (("thigh.L", "thigh.R"), ("upper_arm.L", "upper_arm.R"), ("shoulder.L", "shoulder.R")):
        if a in idx and b in idx:
            left = heads[idx[a]] - heads[idx[b]]
            break
    if left is None or np.linalg.norm(left - (left @ up) * up) < 1e-9:
        raise ArticulaInputError("cannot tell the rig's left from its right: map both thighs or both upper arms")
    left = left - (left @ up) * up
    left /= np.linalg.norm(left)
    return np.stack([left, np.cross(up, left), up], axis=1)


def rest_alignments(source: ArmatureRest, target: ArmatureRest, segs) -> np.ndarray:
    """(S, 3, 3) ``Q_r`` per segment (module docstring)."""
    _, hs = rest_world(source)
    _, ht = rest_world(target)
    G = body_frame(ht, segs, "target") @ body_frame(hs, segs, "source").T
    Q = {}
    for seg in segs:
        if not seg.aimed_by_own_bone:
            parent = PARENT.get(seg.role)
            while parent is not None and parent not in Q:
                parent = PARENT.get(parent)
            Q[seg.role] = Q[parent] if parent is not None else G
            continue
        ds = unit(hs[seg.source_child] - hs[seg.source])
        dt = unit(ht[seg.target_child] - ht[seg.target])
        Q[seg.role] = rotation_between(G @ ds, dt) @ G
    return np.stack([Q[seg.role] for seg in segs])


def unit(v):
    """``v (..., 3)`` scaled to unit length (zero vectors stay zero)."""
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)


def target_world_rotations(source: ArmatureRest, target: ArmatureRest, segs, src_rot, src_heads) -> np.ndarray:
    """(F, S, 3, 3) world rotations of the segments' target bones, from the source's world bone
    rotations ``src_rot (F, Js, 3, 3)`` and heads ``src_heads (F, Js, 3)``."""
    S0, _ = rest_world(source)
    T0, ht = rest_world(target)
    Q = rest_alignments(source, target, segs)
    out = np.empty((src_rot.shape[0], len(segs), 3, 3))
    for k, seg in enumerate(segs):
        W = src_rot[:, seg.source] @ (S0[seg.source].T @ Q[k].T @ T0[seg.target])
        if seg.aimed_by_own_bone:
            rest_dir = unit(ht[seg.target_child] - ht[seg.target])
            now = W @ (T0[seg.target].T @ rest_dir)
            want = unit(src_heads[:, seg.source_child] - src_heads[:, seg.source])
            W = rotation_between(now, want) @ W
        out[:, k] = W
    return out


def local_rotations(target: ArmatureRest, segs, world_rot, src_heads) -> np.ndarray:
    """(F, Jt, 3, 3) pose-bone rotations of every target bone: the segments' bones get
    ``world_rot (F, S, 3, 3)``, all other bones keep their rest pose relative to their parent; bones that
    aim a reversed segment are then turned to aim it (module docstring; ``src_heads (F, Js, 3)`` world)."""
    T0, ht = rest_world(target)
    F = world_rot.shape[0]
    driven = {seg.target: k for k, seg in enumerate(segs)}
    reversed_aims = {seg.aim: seg for seg in segs if seg.child is not None and seg.aim >= 0 and seg.aim != seg.target}
    W = np.empty((F, len(target.bones), 3, 3))
    P = np.empty((F, len(target.bones), 3))
    local = np.empty_like(W)
    for b, p in enumerate(target.parents):
        rest_rel = T0[b] if p < 0 else W[:, p] @ (T0[p].T @ T0[b])
        P[:, b] = ht[b] if p < 0 else P[:, p] + np.einsum("fij,j->fi", W[:, p] @ T0[p].T, ht[b] - ht[p])
        W[:, b] = world_rot[:, driven[b]] if b in driven else rest_rel
        if b in reversed_aims:
            W[:, b] = _aim_reversed(reversed_aims[b], W[:, b], P, T0, ht, src_heads)
        local[:, b] = np.swapaxes(rest_rel, -1, -2) @ W[:, b]
    return local


def _aim_reversed(seg, Wb, P, T0, ht, src_heads) -> np.ndarray:
    """World rotation ``(F, 3, 3)`` of the aiming bone of reversed segment ``seg``: ``Wb`` turned about the
    bone's head so that the role's joint lies on the line through the child's joint ``P[:, child]``
    along the source's direction (the point at the bone's reach from its head)."""
    b, r, c = seg.aim, seg.target, seg.target_child
    offset = np.einsum("fij,j->fi", Wb @ T0[b].T, ht[r] - ht[b])         # bone head -> role joint, now
    reach = np.linalg.norm(ht[r] - ht[b])
    d = unit(src_heads[:, seg.source] - src_heads[:, seg.source_child])  # child joint -> role joint
    e = P[:, c] - P[:, b]
    ed = np.einsum("fi,fi->f", e, d)
    t = -ed + np.sqrt(np.maximum(ed ** 2 - np.einsum("fi,fi->f", e, e) + reach ** 2, 0.0))
    want = e + t[:, None] * d
    return rotation_between(unit(offset), unit(want)) @ Wb
