"""Left/right pairs from the skeleton's structure, for creatures whose mesh has no mirror map.

A vertex mirror map (:mod:`solver.learn.mirror_map`) needs a mirror-symmetric polygon topology or an
exactly symmetric shape; a scanned or sculpted animal has neither, and in a gallop no scan has both
legs of a pair in mirror poses, so symmetry planes through whole scans find no pairs either.  What every
such body still shows is structure: the legs of a pair hang from the same part (or from a pair),
have as many parts below them, about as many vertices, and their joints with the parent lie mirror-
wise about a plane that maps the parent part onto itself.

:func:`chain_votes` pairs siblings that way: two children of one part whose subtrees have equal part
counts and vertex counts within STRUCTURE_SIZE_RATIO, and whose bisecting plane (normal along the line
between their joints, through its midpoint) reflects the parent part's rest vertices onto itself
(median distance within PLANE_TOL of the part's size).  The pairs are taken best plane first, each part
once; below a pair, children are matched by their subtrees alone (a posed scan has the two legs in
different poses, so no plane applies there).  The votes join those of the symmetry planes in
:func:`solver.learn.skeleton.build_skeleton`, where :func:`solver.learn.symmetry.consistent_pairs` and
the equal-length test decide as for any pair.  Naming: left is the side the plane normal points to,
its largest component made positive (as :mod:`solver.learn.symmetry`).  Positions in metres.
"""
from itertools import combinations

import numpy as np

from ..geometry.neighbours import far_query_tree
from .symmetry import _plane_score

STRUCTURE_SIZE_RATIO = 0.6   # paired subtrees: vertex counts within this ratio
PLANE_TOL = 0.05             # the parent part reflected in the pair's plane: median distance / part size


def subtree_sizes(order, parent_part, sizes):
    """``(parts (k,), vertices (k,))`` in every part's subtree; ``order (k,)`` parts breadth first,
    ``parent_part (k,)`` (-1 at the root), ``sizes (k,)`` vertex counts."""
    parts, verts = np.ones(len(order), dtype=np.int64), np.asarray(sizes, dtype=np.int64).copy()
    for p in order[::-1]:
        q = parent_part[p]
        if q >= 0:
            parts[q] += parts[p]
            verts[q] += verts[p]
    return parts, verts


def _alike(a, b, parts, verts):
    return parts[a] == parts[b] and min(verts[a], verts[b]) >= STRUCTURE_SIZE_RATIO * max(verts[a], verts[b])


def _mirror_plane(head_a, head_b):
    """``(n, d, a_is_left)``: the plane bisecting two joints, n with its largest component positive."""
    n = head_a - head_b
    n = n / np.linalg.norm(n)
    if n[int(np.argmax(np.abs(n)))] < 0:
        n = -n
    return n, float(0.5 * (head_a + head_b) @ n), bool((head_a - head_b) @ n > 0)


def sibling_candidates(rest, labels, children, head_of_part, parts, verts):
    """``[(score, left, right)]``: sibling parts alike in structure whose bisecting plane maps their
    parent part onto itself (score = the median reflected distance over the part's size)."""
    out = []
    for p, kids in children.items():
        if len(kids) < 2:
            continue
        pts = rest[labels == p]
        size = float(np.linalg.norm(np.ptp(pts, axis=0)))
        if len(pts) < 4 or size <= 0:
            continue
        tree = far_query_tree(pts)
        for a, b in combinations(kids, 2):
            gap = np.linalg.norm(head_of_part[a] - head_of_part[b])
            if not _alike(a, b, parts, verts) or gap <= 1e-9 * size:
                continue
            n, d, a_left = _mirror_plane(head_of_part[a], head_of_part[b])
            score = _plane_score(pts, tree, n, d, size, PLANE_TOL)
            if score < PLANE_TOL:
                out.append((score, a, b) if a_left else (score, b, a))
    return sorted(out)


def _match_below(left, right, children, parts, verts, pairs, used):
    """Pair the children of a left/right pair by structure (largest subtrees first), recursively."""
    rights = sorted(children.get(right, []), key=lambda c: -verts[c])
    for a in sorted(children.get(left, []), key=lambda c: -verts[c]):
        match = next((b for b in rights if b not in used and _alike(a, b, parts, verts)), None)
        if match is not None:
            pairs.append((a, match))
            used.update((a, match))
            _match_below(a, match, children, parts, verts, pairs, used)


def chain_votes(rest, labels, order, parent_part, head_of_part, sizes, weight=1):
    """Votes ``{(left part, right part): weight}`` of the structural pairs (module docstring).
    rest (V,3), labels (V,) parts, order (k,) parts breadth first, parent_part (k,), head_of_part (k,3)
    each part's joint with its parent, sizes (k,) vertex counts."""
    parts, verts = subtree_sizes(order, parent_part, sizes)
    children = {}
    for p in order[1:]:
        children.setdefault(int(parent_part[p]), []).append(int(p))
    pairs, used = [], set()
    for _, a, b in sibling_candidates(rest, labels, children, head_of_part, parts, verts):
        if a in used or b in used:
            continue
        pairs.append((a, b))
        used.update((a, b))
        _match_below(a, b, children, parts, verts, pairs, used)
    return {(int(a), int(b)): weight for a, b in pairs}
