"""Initial skeleton from a segmentation (spec §3.2 steps 3-5).

* Part adjacency: the number of mesh edges between two parts.
* Tree: the maximum spanning tree of that graph (a long shared boundary = a real joint; a hand resting on
  a hip shares only a few edges), rooted at the most central part (least summed hop distance to all
  other parts, ties to the larger part).  Bones are numbered breadth-first so ``parents[b] < b``.
* Joint centres: the centroid of the boundary ring between parent and child, refined as the least-squares
  rotation centre: the point h that both parts' per-scan rigid transforms move alike,
  ``min_h Σ_m ‖(R_p,m − R_c,m) h − (t_c,m − t_p,m)‖² + μ² M ‖h − h_ring‖²`` (μ keeps a hinge's axis
  direction, which the motion cannot fix, at the ring; μ² M = 0.012 for 30 scans is 10-1000x below the
  eigenvalues of Σ_m DᵀD on MakeHuman (0.11 along a knee's hinge axis, 0.4-40 elsewhere): μ = 1e-4
  moves no joint by more than 1 mm there).  The two transforms are *joint-local robust* fits
  (:func:`joint_fits`, when the scans are given): each part's Kabsch fit weights its vertices by
  ``exp(−d / (2ρ))`` (d: rest distance to the joint's boundary ring, ρ: the ring's radius), then is
  reweighted 5 times by ``1 / (1 + (r / s)²)`` (r: the vertex's RMS residual over the scans, s: half the
  RMS residual).  Whole-part fits are biased by the blended skin on both sides of every joint and, for a
  part spanning two bones (a hand with the thumb and finger bases, a pelvis with the lower back), by the
  far bone's motion.  Joint error in the rest scan, matched to the generating joints (MakeHuman hybrid
  skin, 30 scans, 19 parts; mean / median / max mm): cmu_mb 14.9 / 12.4 / 49 → 11.3 / 9.1 / 29,
  game_engine 15.1 / 11.8 / 52 → 11.8 / 7.1 / 50; smoothly skinned tube body: max 7.5 → 1.6 mm (cost:
  0.4 s CPU for the 18 joints of 13,380 vertices × 30 scans).
  Reach 1-3 ρ and scale 0.3-0.7 give the same within 1.3 mm mean (6 segmentations); without the
  locality (reweighting only) some joints end 60-120 mm off (a part's fit follows its larger bone, not
  the one at the joint).
  The remaining errors are mostly joints that stand for two generating joints (shoulder + arm,
  neck + neck1, finger base + fingers, hip joint + upper leg): the rotation centre of a composite motion.
* Frames: Y from the joint towards the main child's joint (the child continuing the incoming direction;
  for the root the largest unpaired child), or for end parts towards the part's mean vertex, with the
  tail at the part's far extent along it; X/Z completed by :func:`solver.rig.model.frames_from_bones`.
* Mirror pairs: from the mesh's vertex mirror map when there is one covering ``MAP_COVERAGE`` of the
  vertices (:func:`map_pair_votes`; the topological map of :func:`solver.learn.segmentation.mirror_map`, which
  the segmentation already used to cut mirror-image parts alike): two parts pair when their vertices'
  images lie in each other.  Measured on the 8 MakeHuman cases of ``./run bench learn`` (19 parts, the
  initialisation alone): 2-5 pairs in every case where the planes found 0-4 (none in three of the four
  game_engine cases: a posed rest scan is rarely symmetric), and initialisation 1.9-2.5 s instead of
  3.0-3.8 s (no plane search).  Otherwise the symmetry planes (best of principal/world axes, refined by
  iterated reflect-and-match of a fixed 1,000-point subsample against all points, then scored once on all
  points; every plane of the rest scan and up to 12 other scans votes for the pairs it matches by
  reflection).  Pairs are kept by votes if structurally plausible (:func:`consistent_pairs`: vertex counts within
  MIRROR_SIZE_RATIO, same or mirrored parents) and if their bones, where both continue into a child,
  have initial lengths within MIRROR_LENGTH_TOLERANCE (:func:`unequal_pairs`; a dropped pair takes its
  descendants' pairs with it).  Learning equalises the paired lengths with λ = 1e10, so a pair whose two
  sides were cut at different places drags joints: MakeHuman cmu_mb at 16-19 parts cuts the left foot
  inside the Foot bone (shin part with the heel, 371 vertices) and the right one at the ankle (240),
  shin bones of 441 vs 372 mm between the initial joints, and the symmetry term left the learned right
  knee 90 mm from the generating one (mean over the scans; 36 mm with the pair dropped).  Pairs are
  named ``part_NN.L`` / ``part_NN.R``, .L on the side the plane normal points to, the normal's largest
  component made positive (+X for a character facing −Y: Blender's left).
Units: metres.
"""
from collections import deque

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import minimum_spanning_tree, shortest_path
from scipy.spatial import cKDTree

from .. import parallel
from ..errors import ArticulaInputError
from ..geometry.mesh_graph import edges_of
from ..rig.model import Skeleton, frames_from_bones
from ..geometry.procrustes import fit_rigid


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
    tree = cKDTree(ring)
    out = []
    for idx in parts:
        out += joint_local_fit(rest, scans, idx, tree.query(rest[idx])[0], rho)
    return out


def rotation_centre(Rp, tp, Rc, tc, h0, mu=0.02):
    """Least-squares common rotation centre of two parts (see module doc).

    Rp, Rc ``(M,3,3)``, tp, tc ``(M,3)`` per-scan rigid maps of parent and child; h0 ``(3,)`` prior
    (boundary centroid).  ``mu²·M`` weighs the prior (dimensionless, relative to rotation angles² in
    radians²)."""
    D = Rp - Rc
    r = tc - tp
    H = np.einsum("mji,mjk->ik", D, D) + mu ** 2 * len(D) * np.eye(3)
    g = np.einsum("mji,mj->i", D, r) + mu ** 2 * len(D) * h0
    return np.linalg.solve(H, g)


MIRROR_SIZE_RATIO = 0.8         # mirror parts: vertex counts within this ratio (cut alike on both sides)
MIRROR_LENGTH_TOLERANCE = 0.1   # mirror bones: initial lengths within this fraction of the longer
MIRROR_MATCH = 0.6              # mirror parts: this share of a part's vertices has its image in the other
SYMMETRY_SAMPLE = 1000          # points that take part in the reflect-and-match iterations


def _reflect(pts, n, d):
    """Mirror images ``(N,3)`` of ``pts (N,3)`` in the plane ``x·n = d`` (n unit)."""
    return pts - 2.0 * ((pts @ n) - d)[:, None] * n


def _nn_tree(pts):
    """k-d tree for nearest neighbours of reflected points.  Sliding-midpoint splits with unshrunk node
    boxes and 64-point leaves answer such queries (many far from the surface) 2-3x faster than scipy's
    default tree (measured on 13,380 MakeHuman vertices); the neighbours are the same (exact search)."""
    return cKDTree(pts, leafsize=64, compact_nodes=False, balanced_tree=False)


def _sample(pts, count, seed=0):
    """Up to ``count`` rows of ``pts (N,3)``, a fixed pseudo-random subset in index order."""
    if len(pts) <= count:
        return pts
    return pts[np.sort(np.random.default_rng(seed).choice(len(pts), count, replace=False))]


def _refine_plane(pts, tree, sub, n, d, iterations, size):
    """Reflect-and-match from the plane ``x·n = d``: reflect the sample ``sub (S,3)``, match each point
    to the nearest of ``pts (N,3)`` (``tree``), take the normal along the summed point-to-match
    differences and the offset as the median midpoint; up to ``iterations`` times, fewer once the
    plane no longer moves.  Returns ``(n (3,), d)`` (metres)."""
    for _ in range(iterations):
        idx = tree.query(_reflect(sub, n, d))[1]
        diff = sub - pts[idx]
        diff *= np.sign(diff @ n)[:, None]
        keep = np.linalg.norm(diff, axis=1) > 1e-9 * size
        if keep.sum() < 3:
            break
        n_new = diff[keep].sum(axis=0)
        n_new /= np.linalg.norm(n_new)
        d_new = float(np.median((0.5 * (sub + pts[idx]))[keep] @ n_new))
        still = n_new @ n > 1.0 - 1e-15 and abs(d_new - d) <= 1e-12 * size
        n, d = n_new, d_new
        if still:
            break
    return n, d


def _plane_score(pts, tree, n, d, size, tol):
    """Median distance of reflected ``pts (N,3)`` to their nearest point, over ``size``; exact when
    below ``tol``, else possibly ``inf``.  The search is bounded at tol·size; only when the lower middle
    value is within it but the upper one (even N) is not is it repeated up to 2·tol·size (beyond that
    the mean of the two is at least tol·size)."""
    refl = _reflect(pts, n, d)
    dist = tree.query(refl, distance_upper_bound=tol * size)[0]
    s = np.median(dist)
    lower = (len(dist) - 1) // 2
    if np.isinf(s) and np.isfinite(np.partition(dist, lower)[lower]):
        s = np.median(tree.query(refl, distance_upper_bound=2.0 * tol * size)[0])
    return float(s) / size


def symmetry_planes(points, iterations=8, tol=0.02, sample=SYMMETRY_SAMPLE):
    """Candidate mirror planes of a point set ``points (N,3)``, best first: ``[(normal (3,), offset,
    score), ...]`` with the plane ``x·n = offset`` (metres) and score = median distance of all reflected
    points to their nearest point, relative to the size (bounding-box diagonal).  Candidates start at
    the principal and world axes through the centroid (near-duplicate starts, |cos| >= 0.99, skipped),
    are refined by reflect-and-match on a fixed subsample of ``sample`` points (:func:`_refine_plane`)
    and scored once on all points; only those with score < tol are returned (distinct normals)."""
    pts = np.asarray(points, dtype=np.float64)
    size = np.linalg.norm(np.ptp(pts, axis=0))
    c = pts.mean(axis=0)
    _, vecs = np.linalg.eigh(np.cov((pts - c).T))
    tree = _nn_tree(pts)
    sub = _sample(pts, sample)
    starts = []
    for n in [vecs[:, i] for i in range(3)] + list(np.eye(3)):
        if all(abs(n @ m) < 0.99 for m in starts):
            starts.append(n)
    found = []
    for n in starts:
        n, d = _refine_plane(pts, tree, sub, n, c @ n, iterations, size)
        axis = int(np.argmax(np.abs(n)))
        if n[axis] < 0:
            n, d = -n, -d
        if any(abs(n @ m) >= 0.99 for m, _, _ in found):
            continue
        s = _plane_score(pts, tree, n, d, size, tol)
        if s < tol:
            found.append((n, float(d), s))
    return sorted(found, key=lambda f: f[2])


def mirror_pairs(rest, labels, k, plane, min_match=MIRROR_MATCH):
    """Pairs of parts that are mirror images ``[(left, right), ...]`` (part indices; left on the
    positive side of the plane).  A part pairs with the part where most of its reflected vertices land,
    when that relation is mutual and the two are different parts."""
    n, d, _ = plane
    tree = cKDTree(rest)
    refl = rest - 2.0 * ((rest @ n) - d)[:, None] * n
    target = labels[tree.query(refl)[1]]
    match = np.full(k, -1)
    for p in range(k):
        t = target[labels == p]
        if len(t):
            best = np.bincount(t, minlength=k).argmax()
            if np.mean(t == best) >= min_match:
                match[p] = best
    pairs = []
    for p in range(k):
        q = match[p]
        if q > p and match[q] == p:
            side = (rest[labels == p] @ n).mean() - d
            pairs.append((p, q) if side > 0 else (q, p))
    return pairs


def pair_votes(shapes, labels, k):
    """Mirror-pair votes over shapes ``[(V,3), ...]`` (the rest scan and other scans): for every symmetry
    plane of every shape, each mutual pair of :func:`mirror_pairs` gets one vote for its (left, right)
    order.  Returns ``{(left, right): votes}`` (part indices).  A posed scan is symmetric only in parts
    (the trunk, a limb pair held alike), so different scans reveal different pairs."""
    def pairs_of(pts):                     # one shape per solver thread (the k-d tree searches overlap)
        return [pair for plane in symmetry_planes(pts) for pair in mirror_pairs(pts, labels, k, plane)]

    votes = {}
    for pairs in parallel.map_pieces(pairs_of, shapes):
        for pair in pairs:
            key = (int(pair[0]), int(pair[1]))
            votes[key] = votes.get(key, 0) + 1
    return votes


MAP_COVERAGE = 0.9             # a vertex mirror map pairs the parts itself when it maps this share of vertices


def map_pair_votes(rest, labels, k, mirror, min_match=MIRROR_MATCH):
    """Mirror-pair votes ``{(left, right): 1}`` (part indices) from a vertex mirror map ``mirror (V,)``
    (:func:`solver.learn.segmentation.mirror_map`; -1: no image): parts p and q pair when at least ``min_match``
    of each one's mapped vertices have their image in the other.  Left is the side the mirror normal
    points to: the dominant direction of the differences ``x_v − x_mirror(v)`` of ``rest (V,3)`` with its
    largest component made positive, as for :func:`symmetry_planes` (+X for a character facing −Y).
    Exact for a topological map, so the mirror-image parts the segmentation cut alike pair regardless of
    how far the rest scan is posed from symmetry; no plane search."""
    mapped = np.flatnonzero(mirror >= 0)
    d = rest[mapped] - rest[mirror[mapped]]
    _, vecs = np.linalg.eigh(d.T @ d)
    n = vecs[:, -1]
    n = n if n[np.argmax(np.abs(n))] > 0 else -n
    src, dst = labels[mapped], labels[mirror[mapped]]
    counts = np.zeros((k, k))
    np.add.at(counts, (src, dst), 1.0)
    share = counts / np.maximum(counts.sum(axis=1, keepdims=True), 1.0)
    side = np.zeros(k)
    np.add.at(side, src, d @ n)
    votes = {}
    for p in range(k):
        for q in range(p + 1, k):
            if share[p, q] >= min_match and share[q, p] >= min_match:
                votes[(p, q) if side[p] > side[q] else (q, p)] = 1
    return votes


def consistent_pairs(votes, parent_part, sizes, min_size_ratio=MIRROR_SIZE_RATIO):
    """The mirror pairs to keep, ``[(left, right), ...]`` (part indices), from ``votes`` of
    :func:`pair_votes`.  A pair is kept only if it is structurally a mirror pair: neither part is the
    root, the two are of similar size (vertex counts within ``min_size_ratio``), and their parents are
    the same part or themselves a kept pair (with the left child under the left parent).  Candidates
    are taken by votes (both orders of a pair summed; the order with more votes names left/right) and
    revisited until nothing changes, so children are accepted after their parents.  A plane through a
    posed scan can pair a neck with an arm; these rules reject that."""
    total, order = {}, {}
    for (l, r), n in votes.items():
        key = (min(l, r), max(l, r))
        total[key] = total.get(key, 0) + n
        if n > order.get(key, (None, 0))[1]:
            order[key] = ((l, r), n)
    ranked = sorted(total, key=lambda key: (-total[key], key))
    partner, left_of = {}, {}
    changed = True
    while changed:
        changed = False
        for key in ranked:
            l, r = order[key][0]
            if l in partner or r in partner or min(parent_part[l], parent_part[r]) < 0:
                continue
            if min(sizes[l], sizes[r]) < min_size_ratio * max(sizes[l], sizes[r]):
                continue
            pl, pr = parent_part[l], parent_part[r]
            if pl != pr:
                if partner.get(pl) != pr:
                    continue
                if not left_of[pl]:
                    l, r = r, l
            partner[l], partner[r] = r, l
            left_of[l], left_of[r] = True, False
            changed = True
    return sorted((p, q) for p, q in partner.items() if left_of[p])


def unequal_pairs(heads, tails, parents, pairs, tol=MIRROR_LENGTH_TOLERANCE):
    """The mirror pairs ``[(l, r), ...]`` (bones) whose bones both continue into a child (a child's head at
    the bone's tail: the bone lengths that :mod:`solver.learn.joints_poses`'s symmetry term equalises) and
    whose initial lengths differ by more than ``tol`` relative to the longer."""
    def length(b):
        kids = [c for c in np.flatnonzero(parents == b) if np.linalg.norm(heads[c] - tails[b]) < 1e-9]
        return np.linalg.norm(tails[b] - heads[b]) if kids else None
    bad = []
    for l, r in pairs:
        a, b = length(l), length(r)
        if a is not None and b is not None and abs(a - b) > tol * max(a, b):
            bad.append((l, r))
    return bad


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
                   max_symmetry_scans=12, scans=None, mirror=None):
    """Skeleton from a segmentation.

    rest (V,3), labels (V,) parts in [0,k), faces (F,3); part_R (M,k,3,3), part_t (M,k,3) the per-scan
    rigid maps of the parts (for the rotation-centre refinement; None keeps the boundary centroids).
    scans: optional (M,V,3) scans of those maps: the rotation centres then use the joint-local robust
    fits of the two parts (:func:`joint_fits`) instead of part_R/part_t; by default the symmetry_scans
    when they are the M scans of part_R (as :func:`solver.learn.pipeline.initialise` passes them).
    symmetry_scans: optional (M,V,3) scans in which to look for the mirror plane as well (a posed rest
    scan is rarely symmetric; the pairing of parts holds in every scan); up to max_symmetry_scans of them,
    evenly spaced, are tried and the one pairing most parts wins.
    mirror: optional vertex mirror map ``(V,)`` (-1: none); when it maps at least ``MAP_COVERAGE`` of the
    vertices (a topological map), the pairs come from it (:func:`map_pair_votes`) instead of planes.
    Returns ``(skeleton, part_of_bone (B,), bone_of_part (k,), bone_pairs [(l, r)])``."""
    rest = np.asarray(rest, dtype=np.float64)
    sizes = np.bincount(labels, minlength=k)
    order, parent_part = part_tree(part_adjacency(labels, faces, k), sizes)
    bone_of_part = np.empty(k, dtype=np.int64)
    bone_of_part[order] = np.arange(k)
    parents = np.array([-1 if parent_part[p] < 0 else bone_of_part[parent_part[p]] for p in order], dtype=np.int32)
    if scans is None and part_R is not None and symmetry_scans is not None and len(symmetry_scans) == len(part_R):
        scans = symmetry_scans
    if scans is not None:
        scans = np.asarray(scans, dtype=np.float64)
    edges = edges_of(faces)
    heads = np.empty((k, 3))
    heads[0] = rest[labels == order[0]].mean(axis=0)
    for b in range(1, k):
        p, c = parent_part[order[b]], order[b]
        h = rest[boundary_vertices(labels, edges, p, c)].mean(axis=0)
        if part_R is not None:
            if scans is not None:
                fits = joint_fits(rest, scans, labels, edges, p, c)
            else:
                fits = (part_R[:, p], part_t[:, p], part_R[:, c], part_t[:, c])
            h = rotation_centre(*fits, h)
        heads[b] = h
    pairs = []
    if symmetry and k > 1:
        mirror = None if mirror is None else np.asarray(mirror, dtype=np.int64)
        if mirror is not None and np.mean(mirror >= 0) >= MAP_COVERAGE:
            votes = map_pair_votes(rest, labels, k, mirror)
        else:
            shapes = [rest]
            if symmetry_scans is not None:
                step = max(1, int(np.ceil(len(symmetry_scans) / max_symmetry_scans)))
                shapes += list(np.asarray(symmetry_scans)[::step])
            votes = pair_votes(shapes, labels, k)
        while True:
            part_pairs = consistent_pairs(votes, parent_part, sizes)
            pairs = [(int(bone_of_part[a]), int(bone_of_part[b])) for a, b in part_pairs]
            tails = _tails(rest, labels, order, parents, heads, {x for pr in pairs for x in pr})
            bad = unequal_pairs(heads, tails, parents, pairs)
            if not bad:
                break
            for l, r in bad:                   # drop the pair (its children lose their paired parents)
                votes.pop((int(order[l]), int(order[r])), None)
                votes.pop((int(order[r]), int(order[l])), None)
    tails = _tails(rest, labels, order, parents, heads, {x for pr in pairs for x in pr})
    names = _names(k, pairs)
    frames = frames_from_bones(heads, tails)
    return Skeleton(names, parents, heads, tails, frames), order, bone_of_part, pairs


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
