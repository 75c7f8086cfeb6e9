"""Mirror symmetry of a body: symmetry planes, mirror-image parts, and left/right bone pairs
(dissertation (model-adaptive mocap) §3.2, steps 2-5; docs/learn_rig_solver.md).

A body's left and right halves are mirror images; learning uses that twice:

* segmentation (:func:`solver.learn.segmentation.finish`): parts that are mirror images of each other
  are cut alike.  :func:`mirror_partners` and :func:`mirror_compatible` say which parts may hold a vertex
  and its mirror vertex, :func:`mirrored_labels` assigns both together;
* skeleton (:func:`solver.learn.skeleton.build_skeleton`): parts that are mirror images become bone
  pairs ``.L`` / ``.R`` whose lengths the joints-and-poses step keeps equal.  The pairs come from the
  vertex mirror map when it covers the mesh (:func:`map_pair_votes`), else from votes of the symmetry
  planes of several scans (:func:`symmetry_planes`, :func:`pair_votes`); they are kept when
  structurally plausible (:func:`consistent_pairs`) and of equal initial length (:func:`unequal_pairs`).

Both ask which share of a part's vertices has its mirror image in the other part, with their own
thresholds (each was set with its rule; they are not one setting):

* ``SEGMENT_MIRROR_MATCH`` = 0.5, a majority: it only couples where two parts are cut, and the cut
  itself is what the mirror step makes alike, so the parts need not match better beforehand;
* ``SKELETON_MIRROR_MATCH`` = 0.6, stricter: a pair is named and its bone lengths are tied with
  λ = 1e10, so a false pair drags joints; and a plane's nearest-vertex matches in a posed scan stray
  across part boundaries.

The vertex mirror map itself comes from :mod:`solver.learn.mirror_map`.  Planes: ``x·n = d`` with unit
normal n, offsets and positions in metres; .L is the side the normal points to, the normal's largest
component made positive (+X for a character facing −Y: Blender's left).
"""
import numpy as np

from .. import parallel
from ..geometry.neighbours import far_query_tree, nearest

SEGMENT_MIRROR_MATCH = 0.5      # segmentation partners: this share of a part's vertices mapped, and of those
                                # mapped into the partner (see the module doc)
SEGMENT_MIRROR_CONTAIN = 0.7    # segmentation: compatible when this share of one part maps into the other
SKELETON_MIRROR_MATCH = 0.6     # skeleton pairs: this share of a part's vertices has its image in the other
MIRROR_SIZE_RATIO = 0.8         # skeleton pairs: vertex counts within this ratio (cut alike on both sides)
MIRROR_LENGTH_TOLERANCE = 0.1   # skeleton pairs: initial bone lengths within this fraction of the longer
MAP_COVERAGE = 0.9              # a vertex mirror map pairs the parts itself when it maps this share of vertices
SYMMETRY_SAMPLE = 1000          # points that take part in the reflect-and-match iterations
MAX_SYMMETRY_SCANS = 12         # planes: at most this many scans besides the rest vote for pairs


# ----------------------------------------------------------------------------- symmetry planes

def reflect(pts, n, d):
    """Mirror images ``(N,3)`` of ``pts (N,3)`` in the plane ``x·n = d`` (n unit)."""
    return pts - 2.0 * ((pts @ n) - d)[:, None] * n


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
        idx = tree.query(reflect(sub, n, d))[1]
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
    refl = reflect(pts, n, d)
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
    tree = far_query_tree(pts)
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


# ----------------------------------------------------------------------------- mirror-image parts

def mirror_counts(labels, mirror, k):
    """``(k,k)`` count of the vertices of part a whose mirror vertex (``mirror (V,)``, -1: none) is in
    part b."""
    ok = mirror >= 0
    C = np.zeros((k, k))
    np.add.at(C, (labels[ok], labels[mirror[ok]]), 1.0)
    return C


def mirror_partners(labels, mirror, k, match=SEGMENT_MIRROR_MATCH):
    """Mirror image of every part under the vertex map ``mirror (V,)`` (-1: unknown): ``partner (k,)``
    with partner[a] = b when most (``match``) of a's mapped vertices map into b and most of b's into a
    (b = a: a part symmetric in itself, such as the trunk), else -1.  Also needs most of the part's
    vertices mapped."""
    C = mirror_counts(labels, mirror, k)
    size = np.bincount(labels, minlength=k)
    rows = C.sum(axis=1)
    best = np.argmax(C, axis=1)
    good = (rows >= match * size) & (C[np.arange(k), best] >= match * np.maximum(rows, 1))
    partner = np.where(good, best, -1)
    mutual = good & (partner[np.where(good, best, 0)] == np.arange(k))
    return np.where(mutual, partner, -1)


def mirror_compatible(labels, mirror, k, contain=SEGMENT_MIRROR_CONTAIN, match=SEGMENT_MIRROR_MATCH):
    """Which parts may hold a vertex and its mirror image: ``(k,k)`` bool, symmetric.  Parts a and b are
    compatible when they are mirror partners (:func:`mirror_partners`, a = b for a part symmetric in
    itself) or when one of them lies mostly (``contain`` of its mapped vertices) in the other's mirror
    image — a limb end split in two on one side only (hand and fingers) is then compatible with the one
    part on the other side.  Parts with no compatible part, or with fewer than ``match`` of their vertices
    mapped, are compatible with every part (no constraint)."""
    C = mirror_counts(labels, mirror, k)
    rows = C.sum(axis=1)
    inside = C >= contain * np.maximum(rows, 1)[:, None]
    P = inside | inside.T
    partner = mirror_partners(labels, mirror, k, match)
    a = np.flatnonzero(partner >= 0)
    P[a, partner[a]] = P[partner[a], a] = True
    free = ~P.any(axis=1) | (rows < match * np.bincount(labels, minlength=k))
    P[free, :] = True
    P[:, free] = True
    return P


def mirrored_labels(err, mirror, compatible):
    """Segmentation step 3 with mirror symmetry: labels ``(V,)`` from the squared errors ``err (V,k)``
    of every vertex under every part's rigid motion.  A vertex v with a mirror vertex m(v) goes to the
    part c of the compatible pair (c, d) (:func:`mirror_compatible`) that minimises
    ``err[v, c] + err[m(v), d]``; the pair minimises the same sum seen from m(v), so m(v) goes to d:
    mirror-image parts are cut at mirrored places, where the motion of both sides together puts the
    boundary.  Vertices without a mirror vertex go to their best part.  Parts may end up empty."""
    new = np.argmin(err, axis=1)
    v = np.flatnonzero(mirror >= 0)
    if len(v):
        own, other = err[v], err[mirror[v]]
        cost = np.empty_like(own)
        for c in range(err.shape[1]):
            cost[:, c] = own[:, c] + other[:, compatible[c]].min(axis=1)
        new[v] = np.argmin(cost, axis=1)
    return new


# ----------------------------------------------------------------------------- skeleton pairs

def mirror_pairs(rest, labels, k, plane, min_match=SKELETON_MIRROR_MATCH):
    """Pairs of parts that are mirror images ``[(left, right), ...]`` (part indices; left on the
    positive side of the plane ``(n, d, score)``).  A part pairs with the part where most of its
    reflected vertices (``rest (V,3)``) land, when that relation is mutual and the two are different
    parts."""
    n, d, _ = plane
    target = labels[nearest(rest, reflect(rest, n, d))[1]]
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


def map_pair_votes(rest, labels, k, mirror, min_match=SKELETON_MIRROR_MATCH):
    """Mirror-pair votes ``{(left, right): 1}`` (part indices) from a vertex mirror map ``mirror (V,)``
    (:func:`solver.learn.mirror_map.mirror_map`; -1: no image): parts p and q pair when at least
    ``min_match`` of each one's mapped vertices have their image in the other.  Left is the side the
    mirror normal points to: the dominant direction of the differences ``x_v − x_mirror(v)`` of
    ``rest (V,3)`` with its largest component made positive, as for :func:`symmetry_planes`.  Exact for
    a topological map, so the mirror-image parts the segmentation cut alike pair regardless of how far
    the rest scan is posed from symmetry; no plane search."""
    mapped = np.flatnonzero(mirror >= 0)
    d = rest[mapped] - rest[mirror[mapped]]
    _, vecs = np.linalg.eigh(d.T @ d)
    n = vecs[:, -1]
    n = n if n[np.argmax(np.abs(n))] > 0 else -n
    counts = mirror_counts(labels, mirror, k)
    share = counts / np.maximum(counts.sum(axis=1, keepdims=True), 1.0)
    side = np.zeros(k)
    np.add.at(side, labels[mapped], d @ n)
    votes = {}
    for p in range(k):
        for q in range(p + 1, k):
            if share[p, q] >= min_match and share[q, p] >= min_match:
                votes[(p, q) if side[p] > side[q] else (q, p)] = 1
    return votes


def map_covers(mirror):
    """True when the vertex ``mirror (V,)`` map (or None) maps at least MAP_COVERAGE of the vertices."""
    return mirror is not None and np.mean(np.asarray(mirror) >= 0) >= MAP_COVERAGE


def part_pair_votes(rest, labels, k, mirror=None, scans=None, max_scans=MAX_SYMMETRY_SCANS):
    """Mirror-pair votes ``{(left, right): votes}`` for the parts ``labels (V,)`` of ``rest (V,3)``: from
    the vertex mirror map ``mirror (V,)`` when it maps at least MAP_COVERAGE of the vertices (a
    topological map, :func:`map_pair_votes`), else from the symmetry planes of the rest and up to
    ``max_scans`` evenly spaced ``scans (M,V,3)`` (:func:`pair_votes`; a posed rest scan is rarely
    symmetric, the pairing of parts holds in every scan)."""
    if map_covers(mirror):
        return map_pair_votes(rest, labels, k, np.asarray(mirror, dtype=np.int64))
    shapes = [rest]
    if scans is not None:
        step = max(1, int(np.ceil(len(scans) / max_scans)))
        shapes += list(np.asarray(scans)[::step])
    return pair_votes(shapes, labels, k)


def consistent_pairs(votes, parent_part, sizes, min_size_ratio=MIRROR_SIZE_RATIO, trusted=()):
    """The mirror pairs to keep, ``[(left, right), ...]`` (part indices), from ``votes`` of
    :func:`pair_votes`.  A pair is kept only if it is structurally a mirror pair: neither part is the
    root, the two are of similar size (vertex counts within ``min_size_ratio``), and their parents are
    the same part or themselves a kept pair (with the left child under the left parent).  Candidates
    are taken by votes (both orders of a pair summed; the order with more votes names left/right) and
    revisited until nothing changes, so children are accepted after their parents.  A plane through a
    posed scan can pair a neck with an arm; these rules reject that.  Two parents that no vote pairs with
    another part (central parts, on the mirror plane) count as the same parent; the ``trusted`` keys
    ``(min, max)`` (pairs of mirror-image shapes, :mod:`solver.learn.shape_pairs`) need no parent rule:
    an asymmetric cut can hang a limb and its mirror image from different torso parts."""
    total, order = {}, {}
    for (l, r), n in votes.items():
        key = (min(l, r), max(l, r))
        total[key] = total.get(key, 0) + n
        if n > order.get(key, (None, 0))[1]:
            order[key] = ((l, r), n)
    ranked = sorted(total, key=lambda key: (-total[key], key))
    candidates = {p for key in total for p in key if key[0] != key[1]}
    central = set(range(len(parent_part))) - candidates            # parts no vote pairs with another
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
            if pl != pr and not (pl in central and pr in central) and key not in trusted:
                if partner.get(pl) != pr:
                    continue
                if not left_of[pl]:
                    l, r = r, l
            partner[l], partner[r] = r, l
            left_of[l], left_of[r] = True, False
            changed = True
    return sorted((p, q) for p, q in partner.items() if left_of[p])


def continuing_child(heads, tails, parents, b):
    """The first child of bone b whose head is at b's tail (the bone continues into it), or None.
    ``heads``, ``tails (B,3)``, ``parents (B,)``."""
    kids = [int(c) for c in np.flatnonzero(parents == b) if np.linalg.norm(heads[c] - tails[b]) < 1e-9]
    return kids[0] if kids else None


def unequal_pairs(heads, tails, parents, pairs, tol=MIRROR_LENGTH_TOLERANCE):
    """The mirror pairs ``[(l, r), ...]`` (bones) whose bones both continue into a child
    (:func:`continuing_child`: the bone lengths that the symmetry term of
    :mod:`solver.learn.joints_poses` equalises) and whose initial lengths differ by more than ``tol``
    relative to the longer."""
    def length(b):
        continues = continuing_child(heads, tails, parents, b) is not None
        return np.linalg.norm(tails[b] - heads[b]) if continues else None
    bad = []
    for l, r in pairs:
        a, b = length(l), length(r)
        if a is not None and b is not None and abs(a - b) > tol * max(a, b):
            bad.append((l, r))
    return bad


def continuing_pairs(skeleton, pairs):
    """``[(l, child_l, r, child_r), ...]`` for the mirror bone pairs ``[(l, r), ...]`` of ``skeleton``
    whose bones both continue into a child (:func:`continuing_child`): the bone lengths
    ``|head(child) − head(bone)|`` that the symmetry term of :mod:`solver.learn.joints_poses` equalises."""
    out = []
    for l, r in pairs:
        sl, sr = (continuing_child(skeleton.heads, skeleton.tails, skeleton.parents, b) for b in (l, r))
        if sl is not None and sr is not None:
            out.append((l, sl, r, sr))
    return out
