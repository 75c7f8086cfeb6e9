"""Initial skeleton from a segmentation (dissertation (model-adaptive mocap) §3.2, steps 3-5;
docs/learn_rig_solver.md).

* Part adjacency: the number of mesh edges between two parts.
* Tree: the maximum spanning tree of that graph (a long shared boundary = a real joint; a hand resting on
  a hip shares only a few edges), rooted at the most central part (least summed hop distance to all
  other parts, ties to the larger part).  Bones are numbered breadth-first so ``parents[b] < b``.
* Joint centres: the centroid of the boundary ring between parent and child, refined as the least-squares
  rotation centre: the point h that both parts' per-scan rigid transforms move alike,
  ``min_h Σ_m ‖(R_p,m − R_c,m) h − (t_c,m − t_p,m)‖² + μ² M ‖h − h_ring‖²`` (μ keeps a hinge's axis
  direction, which the motion cannot fix, at the ring; μ² M is far below the eigenvalues of Σ_m DᵀD
  along any well-determined direction, so it moves no determined joint noticeably).  The two transforms
  are *joint-local robust* fits (:func:`joint_fits`, when the scans are given): each part's Kabsch fit
  weights its vertices by ``exp(−d / (2ρ))`` (d: rest distance to the joint's boundary ring, ρ: the
  ring's radius), then is reweighted 5 times by ``1 / (1 + (r / s)²)`` (r: the vertex's RMS residual
  over the scans, s: half the RMS residual).  Whole-part fits are biased by the blended skin on both
  sides of every joint and, for a part spanning two bones (a hand with the thumb and finger bases, a
  pelvis with the lower back), by the far bone's motion; without the locality a part's fit follows its
  larger bone, not the one at the joint.  A joint that stands for two generating joints (shoulder + arm)
  lands at the rotation centre of the composite motion.
* Frames: Y from the joint towards the main child's joint (the child continuing the incoming direction;
  for the root the largest unpaired child), or for end parts towards the part's mean vertex, with the
  tail at the part's far extent along it; X/Z completed by :func:`solver.rig.model.frames_from_bones`.
* Mirror pairs (:mod:`solver.learn.symmetry`): voted from the vertex mirror map or the symmetry planes,
  kept if structurally plausible and if their bones, where both continue into a child, have initial
  lengths within MIRROR_LENGTH_TOLERANCE (learning ties paired lengths with λ = 1e10, so a pair whose
  two sides were cut at different places would drag joints).  Pairs are named ``part_NN.L`` /
  ``part_NN.R``, .L on the side the mirror normal points to.
Units: metres.
"""
from collections import deque

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import minimum_spanning_tree, shortest_path

from ..errors import ArticulaInputError
from ..geometry.inside import winding_numbers
from ..geometry.mesh_graph import edges_of
from ..geometry.neighbours import nearest
from ..geometry.procrustes import fit_rigid
from ..rig.model import Skeleton, frames_from_bones
from .chain_pairs import chain_votes
from .shape_pairs import shape_votes
from .symmetry import MAX_SYMMETRY_SCANS, consistent_pairs, map_covers, part_pair_votes, unequal_pairs


def part_adjacency(labels, faces, k):
    """Symmetric ``(k,k)`` count of mesh edges joining two different parts."""
    e = edges_of(faces)
    a, b = labels[e[:, 0]], labels[e[:, 1]]
    cross = a != b
    C = np.zeros((k, k))
    np.add.at(C, (a[cross], b[cross]), 1.0)
    return C + C.T


def part_tree(adj, sizes):
    """Maximum spanning tree of the part adjacency ``adj (k,k)`` rooted at the most central part.
    Returns ``(order (k,) parts in breadth-first order, parent_part (k,) with -1 at the root)``.
    Raises when the parts are not all connected."""
    k = len(adj)
    if k == 1:
        return np.array([0]), np.array([-1])
    W = np.where(adj > 0, adj.max() + 1.0 - adj, 0.0)          # max spanning tree = min of (max+1-w)
    T = minimum_spanning_tree(sp.csr_matrix(W)).toarray()
    T = (T + T.T) > 0
    hops = shortest_path(sp.csr_matrix(T.astype(float)), unweighted=True, directed=False)
    if not np.isfinite(hops).all():
        raise ArticulaInputError("mesh: the parts are not connected to each other (disconnected mesh?)")
    score = hops.sum(axis=1) - 1e-9 * np.asarray(sizes, dtype=float) / max(1, np.max(sizes))
    root = int(np.argmin(score))
    parent = np.full(k, -1)
    order, queue, seen = [], deque([root]), {root}
    while queue:
        p = queue.popleft()
        order.append(p)
        for c in np.flatnonzero(T[p]):
            if int(c) not in seen:
                seen.add(int(c))
                parent[c] = p
                queue.append(int(c))
    return np.array(order), parent


def boundary_centroid(rest, labels, faces, p, c):
    """Centroid of the vertices on edges between parts p and c ``(3,)``."""
    return rest[boundary_vertices(labels, edges_of(faces), p, c)].mean(axis=0)


JOINT_REACH = 2.0               # joint-local fits: weight exp(−d / (JOINT_REACH ρ)), ρ = boundary-ring radius
ROBUST_SCALE = 0.5              # Cauchy scale of the residual weights, times the weighted RMS residual
ROBUST_ITERATIONS = 5           # reweighted fits
JOINT_INSIDE_FRACTION = 1.0      # initial joints within this fraction of their cross-section's radius
MIN_RING_FRACTION = 0.1         # ρ at least this fraction of the parts' RMS distance to the ring centre (a
                                # ring of a few close vertices would leave too few weighted vertices;
                                # MakeHuman rings are 0.13 of it or more)


def boundary_vertices(labels, edges, p, c):
    """Indices of the vertices on mesh ``edges (E,2)`` between parts p and c."""
    la, lb = labels[edges[:, 0]], labels[edges[:, 1]]
    sel = ((la == p) & (lb == c)) | ((la == c) & (lb == p))
    return np.unique(edges[sel])


def joint_local_fit(rest, scans, idx, dist, rho, reach=JOINT_REACH, scale=ROBUST_SCALE,
                    iterations=ROBUST_ITERATIONS):
    """Per-scan rigid map ``(R (M,3,3), t (M,3))`` of the vertices ``idx`` of one part as seen from one of
    its joints: weighted Kabsch with weights ``w0 = exp(−dist / (reach·rho))`` (dist: rest distance of each
    vertex to the joint's boundary ring, rho: the ring radius), reweighted ``iterations`` times by
    ``w = w0 / (1 + (r / s)²)`` with r the vertex's RMS residual over the scans and s = scale × the
    w0-weighted RMS residual (see the module doc)."""
    src, dst = rest[idx], scans[:, idx]
    w0 = np.exp(-dist / (reach * max(rho, 1e-12)))
    w = w0
    for it in range(iterations + 1):
        R, t = fit_rigid(src, dst, w)
        if it == iterations:
            break
        r = np.sqrt(np.mean(np.sum((np.einsum("mij,pj->mpi", R, src) + t[:, None] - dst) ** 2, axis=2), axis=0))
        s = scale * np.sqrt(np.sum(w0 * r * r) / np.sum(w0))
        if not s > 0:
            break
        w = w0 / (1.0 + (r / s) ** 2)
    return R, t


def joint_fits(rest, scans, labels, edges, p, c):
    """Joint-local robust rigid maps of parent part p and child part c at their joint:
    ``(Rp, tp, Rc, tc)`` (:func:`joint_local_fit` of each part with distances to their boundary ring; ρ =
    the ring's mean radius, at least MIN_RING_FRACTION of the larger part's RMS distance to its centre)."""
    ring = rest[boundary_vertices(labels, edges, p, c)]
    centre = ring.mean(axis=0)
    rho = float(np.mean(np.linalg.norm(ring - centre, axis=1)))
    parts = [np.flatnonzero(labels == q) for q in (p, c)]
    extent = max(float(np.sqrt(np.mean(np.sum((rest[idx] - centre) ** 2, axis=1)))) for idx in parts)
    rho = max(rho, MIN_RING_FRACTION * extent)
    out = []
    for idx in parts:
        out += joint_local_fit(rest, scans, idx, nearest(ring, rest[idx])[0], rho)
    return out


def rotation_centre(Rp, tp, Rc, tc, h0, mu=0.02, radius=None):
    """Least-squares common rotation centre of two parts (see module doc), within ``radius`` of h0.

    Rp, Rc ``(M,3,3)``, tp, tc ``(M,3)`` per-scan rigid maps of parent and child; h0 ``(3,)`` prior
    (boundary centroid).  ``mu²·M`` weighs the prior (dimensionless, relative to rotation angles² in
    radians²).  radius (metres, None: unbounded): the centre is kept inside the ball of that radius about
    h0 (the joint's cross-section, :func:`ring_radius`) by raising the prior's weight just enough
    (:func:`_bounded_solve`): directions the motion determines stay where the data put them, those it
    leaves free (a hinge's axis) come to h0, the middle of the cross-section."""
    D = Rp - Rc
    r = tc - tp
    A = np.einsum("mji,mjk->ik", D, D)
    b = np.einsum("mji,mj->i", D, r)
    h = np.linalg.solve(A + mu ** 2 * len(D) * np.eye(3), b + mu ** 2 * len(D) * h0)
    if radius is None or np.linalg.norm(h - h0) <= radius:
        return h
    return _bounded_solve(A, b, h0, radius, mu ** 2 * len(D))


def _bounded_solve(A, b, h0, radius, lam_min):
    """``h = (A + λI)⁻¹ (b + λ h0)`` with the smallest λ ≥ lam_min for which ``‖h − h0‖ ≤ radius``
    (``‖h − h0‖`` falls as λ grows; bisection on log λ in A's eigenbasis).  A ``(3,3)`` PSD, b, h0 ``(3,)``.
    Directions with eigenvalues far above λ keep the data's solution, those far below it come to h0."""
    lam_A, Q = np.linalg.eigh(A)
    g = Q.T @ (b - A @ h0)

    def offset(lam):
        return Q @ (g / (lam_A + lam))

    lo, hi = lam_min, max(lam_min, 1e-12) * 2.0
    while np.linalg.norm(offset(hi)) > radius and hi < 1e300:
        lo, hi = hi, hi * 4.0
    for _ in range(60):
        mid = np.sqrt(lo * hi)
        lo, hi = (mid, hi) if np.linalg.norm(offset(mid)) > radius else (lo, mid)
    return h0 + offset(hi)


def ring_radius(ring):
    """The radius (metres) of a joint's cross-section from its boundary-ring vertices ``(n,3)``: the
    median distance of the ring to its centroid, times JOINT_INSIDE_FRACTION (a joint within it lies
    inside the limb for a roughly round cross-section)."""
    centre = ring.mean(axis=0)
    return JOINT_INSIDE_FRACTION * float(np.median(np.linalg.norm(ring - centre, axis=1)))


def _main_child(b, kids, heads, parents, paired, subtree_size):
    """The child of bone b that continues the chain (see module doc)."""
    if parents[b] >= 0:
        incoming = heads[b] - heads[parents[b]]
        n = np.linalg.norm(incoming)
        if n > 1e-12:
            dirs = heads[kids] - heads[b]
            cos = dirs @ incoming / (np.linalg.norm(dirs, axis=1) * n + 1e-300)
            return kids[int(np.argmax(cos))]
    unpaired = [c for c in kids if c not in paired]
    cands = unpaired or kids
    return max(cands, key=lambda c: subtree_size[c])


def build_skeleton(rest, labels, faces, k, part_R=None, part_t=None, symmetry=True, symmetry_scans=None,
                   max_symmetry_scans=MAX_SYMMETRY_SCANS, scans=None, mirror=None):
    """Skeleton from a segmentation.

    rest (V,3), labels (V,) parts in [0,k), faces (F,3); part_R (M,k,3,3), part_t (M,k,3) the per-scan
    rigid maps of the parts (for the rotation-centre refinement; None keeps the boundary centroids).
    scans: optional (M,V,3) scans of those maps: the rotation centres then use the joint-local robust
    fits of the two parts (:func:`joint_fits`) instead of part_R/part_t; by default the symmetry_scans
    when they are the M scans of part_R (as :func:`solver.learn.pipeline.initialise` passes them).
    symmetry: look for mirror pairs (:func:`solver.learn.symmetry.part_pair_votes`: from the vertex
    ``mirror (V,)`` map (-1: none) when it covers the mesh, else from the symmetry planes of the rest
    and up to max_symmetry_scans of the (M,V,3) symmetry_scans).
    Returns ``(skeleton, part_of_bone (B,), bone_of_part (k,), bone_pairs [(l, r)])``."""
    rest = np.asarray(rest, dtype=np.float64)
    sizes = np.bincount(labels, minlength=k)
    order, parent_part = part_tree(part_adjacency(labels, faces, k), sizes)
    bone_of_part = np.empty(k, dtype=np.int64)
    bone_of_part[order] = np.arange(k)
    parents = np.array([-1 if parent_part[p] < 0 else bone_of_part[parent_part[p]] for p in order], dtype=np.int32)
    if scans is None and part_R is not None and symmetry_scans is not None and len(symmetry_scans) == len(part_R):
        scans = symmetry_scans
    heads = joint_heads(rest, labels, faces, order, parent_part, part_R, part_t, scans)
    tree = (order, bone_of_part, parent_part, parents, sizes)
    pairs, trusted = [], set()
    if symmetry and k > 1:
        votes = part_pair_votes(rest, labels, k, mirror, symmetry_scans, max_symmetry_scans)
        if not map_covers(mirror):                     # no topological map: add the structural pairs
            shapes = 1 + (0 if symmetry_scans is None else min(len(symmetry_scans), max_symmetry_scans))
            head_of_part = heads[bone_of_part]
            shaped = shape_votes(rest, labels, order, head_of_part, weight=shapes)
            trusted = {(min(key), max(key)) for key in shaped}
            for more in (chain_votes(rest, labels, order, parent_part, head_of_part, sizes, weight=shapes), shaped):
                for key, n in more.items():
                    votes[key] = votes.get(key, 0) + n
        pairs = _equal_pairs(votes, rest, labels, tree, heads, trusted)
    tails = _tails(rest, labels, order, parents, heads, {x for pr in pairs for x in pr})
    names = _names(k, pairs)
    frames = frames_from_bones(heads, tails)
    return Skeleton(names, parents, heads, tails, frames), order, bone_of_part, pairs


def joint_heads(rest, labels, faces, order, parent_part, part_R=None, part_t=None, scans=None):
    """Bone heads ``(k,3)`` in the bone order ``order (k,)`` (parts, breadth first; ``parent_part (k,)``):
    the root's at its part's mean vertex, every other at the centroid of its boundary ring with the
    parent part, refined to the parts' common rotation centre (:func:`rotation_centre`) when their
    rigid maps are given: joint-local fits (:func:`joint_fits`) with ``scans (M,V,3)``, else the
    whole-part maps ``part_R (M,k,3,3)``, ``part_t (M,k,3)``.  A rotation centre outside the rest mesh
    (winding number, :mod:`solver.geometry.inside`) is recomputed within its cross-section
    (:func:`ring_radius`); centres inside keep the data's place."""
    if scans is not None:
        scans = np.asarray(scans, dtype=np.float64)
    edges = edges_of(faces)
    k = len(order)
    heads = np.empty((k, 3))
    heads[0] = rest[labels == order[0]].mean(axis=0)
    fits, rings = {}, {}
    for b in range(1, k):
        p, c = parent_part[order[b]], order[b]
        rings[b] = rest[boundary_vertices(labels, edges, p, c)]
        heads[b] = rings[b].mean(axis=0)
        if part_R is not None:
            fits[b] = (joint_fits(rest, scans, labels, edges, p, c) if scans is not None else
                       (part_R[:, p], part_t[:, p], part_R[:, c], part_t[:, c]))
            heads[b] = rotation_centre(*fits[b], heads[b])
    if fits:
        outside = np.abs(winding_numbers(heads[1:], rest, faces)) <= 0.5
        for b in np.flatnonzero(outside) + 1:
            heads[b] = rotation_centre(*fits[b], rings[b].mean(axis=0), radius=ring_radius(rings[b]))
    return heads


def _equal_pairs(votes, rest, labels, tree, heads, trusted=()):
    """Mirror bone pairs ``[(l, r), ...]`` from part-pair ``votes``: the structurally consistent ones
    (:func:`solver.learn.symmetry.consistent_pairs`) less those whose bones differ in length
    (:func:`solver.learn.symmetry.unequal_pairs`; a dropped pair takes its children's pairs with it, as
    they lose their paired parents).  ``tree`` = (order, bone_of_part, parent_part, parents, sizes) of
    :func:`build_skeleton`."""
    order, bone_of_part, parent_part, parents, sizes = tree
    while True:
        part_pairs = consistent_pairs(votes, parent_part, sizes, trusted=trusted)
        pairs = [(int(bone_of_part[a]), int(bone_of_part[b])) for a, b in part_pairs]
        tails = _tails(rest, labels, order, parents, heads, {x for pr in pairs for x in pr})
        bad = unequal_pairs(heads, tails, parents, pairs)
        if not bad:
            return pairs
        for l, r in bad:
            votes.pop((int(order[l]), int(order[r])), None)
            votes.pop((int(order[r]), int(order[l])), None)


def _tails(rest, labels, order, parents, heads, paired):
    """Bone tails: the main child's joint, or the far end of an end part along its mean direction."""
    k = len(order)
    subtree = np.bincount(labels, minlength=k)[order].astype(float)
    for b in range(k - 1, 0, -1):
        subtree[parents[b]] += subtree[b]
    tails = np.empty((k, 3))
    for b in range(k):
        kids = [int(c) for c in np.flatnonzero(parents == b)]
        if kids:
            tails[b] = heads[_main_child(b, kids, heads, parents, paired, subtree)]
            if np.linalg.norm(tails[b] - heads[b]) > 1e-9:
                continue
        pts = rest[labels == order[b]]
        d = pts.mean(axis=0) - heads[b]
        if np.linalg.norm(d) < 1e-9:
            d = pts[np.argmax(np.linalg.norm(pts - heads[b], axis=1))] - heads[b]
        d /= np.linalg.norm(d)
        tails[b] = heads[b] + d * max(((pts - heads[b]) @ d).max(), 1e-6)
    return tails


def _names(k, pairs):
    """``root``, ``part_NN`` and mirror pairs ``part_NN.L`` / ``part_NN.R`` (NN = the smaller bone index)."""
    names = ["root"] + [f"part_{b:02d}" for b in range(1, k)]
    for l, r in pairs:
        base = f"part_{min(l, r):02d}"
        names[l], names[r] = base + ".L", base + ".R"
    return names
