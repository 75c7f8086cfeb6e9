"""The vertex graph of the weight step: two-ring colouring into blocks and the cut into two halves.

Two vertices more than two rings apart have disjoint Laplacian rows and neither's targets depend on the
other's posed positions, so a colour class of :func:`two_ring_colouring` is one BCD block whose gains add
exactly, and the halves of :meth:`TwoRing.halves` (three or more edges apart) can be visited in parallel.
Index arrays are vertex indices; ``ring1`` / ``ring2`` are ``(V,V)`` CSR sparsity patterns."""
import numpy as np
import scipy.sparse as sp
from scipy.sparse import csgraph


def two_ring_colouring(ring2):
    """Greedy colouring of the vertices such that two vertices within two rings of each other never share
    a colour.  ring2: ``(V,V)`` CSR pattern of the two-ring (incl. the vertex).  Returns colours ``(V,)``."""
    V = ring2.shape[0]
    colour = np.full(V, -1, dtype=np.int64)
    indptr, indices = ring2.indptr, ring2.indices
    for v in range(V):
        used = colour[indices[indptr[v]:indptr[v + 1]]]
        used = used[used >= 0]
        if len(used) == 0:
            colour[v] = 0
            continue
        free = np.flatnonzero(np.bincount(used, minlength=used.max() + 2) == 0)
        colour[v] = free[0]
    return colour


def subset_classes(ring2, mask):
    """Colour classes of the vertices where ``mask (V,)`` is True alone (:func:`two_ring_colouring` of
    the two-ring pattern restricted to them): no two within two rings share a class, and the thin band of
    :meth:`TwoRing.halves` needs fewer classes, i.e. fewer evaluation calls, than the mesh's colouring
    cut down to it."""
    idx = np.flatnonzero(mask)
    if len(idx) == 0:
        return []
    colour = two_ring_colouring(ring2[idx][:, idx].tocsr())
    return [idx[colour == c] for c in range(colour.max() + 1)]


def restrict_classes(classes, mask):
    """The colour classes cut down to the vertices where ``mask (V,)`` is True (empty ones dropped)."""
    out = [idx[mask[idx]] for idx in classes]
    return [idx for idx in out if len(idx)]


class TwoRing:
    """The vertex graph of the BCD for a Laplacian ``L (V,V)``: ``ring1`` / ``ring2`` (CSR patterns of the
    one- and two-ring, incl. the vertex), the colour ``classes`` of :func:`two_ring_colouring` (list of
    index arrays) and ``levels (V,)``: breadth-first distance in edges from a pseudo-peripheral vertex
    (-1 where unreachable), from which :meth:`halves` cuts the mesh.  It depends on the mesh only, so one
    learn_rig builds it once for all its :func:`optimise_weights` calls."""

    def __init__(self, L):
        A1 = (sp.csr_matrix(L) != 0).astype(np.float64).tocsr()
        self.ring1 = A1
        self.ring2 = (A1 @ A1).tocsr()
        colour = two_ring_colouring(self.ring2)
        self.classes = [np.flatnonzero(colour == c) for c in range(colour.max() + 1)]
        self.levels = _peripheral_levels(A1)

    def halves(self, work):
        """``(half_a, half_b, band)`` for per-vertex ``work (V,)`` (relative cost to evaluate), or None
        when no cut leaves both halves work.  half_a: the vertices of level < l, half_b: level ≥ l + 2,
        band (boolean mask ``(V,)``): levels l and l + 1 and the unreachable vertices; l balances the
        halves' work.  A vertex of half_a and one of half_b are at
        least three edges apart, i.e. outside each other's two-ring."""
        work = np.asarray(work, dtype=np.float64)
        if self.levels.max() < 3:
            return None
        reach = self.levels >= 0
        per_level = np.bincount(self.levels[reach], weights=work[reach])
        below = np.concatenate([[0.0], np.cumsum(per_level)])         # below[l]: work of levels < l
        l = np.arange(1, len(per_level) - 2)                         # half_a = levels < l, non-empty
        above = below[-1] - below[l + 2]                              # work of levels ≥ l + 2
        l = int(l[np.argmin(np.abs(below[l] - above))])
        if below[l] == 0 or below[-1] - below[l + 2] == 0:
            return None
        half_a = np.flatnonzero(reach & (self.levels < l))
        half_b = np.flatnonzero(self.levels >= l + 2)
        band = ~reach | (self.levels == l) | (self.levels == l + 1)
        return half_a, half_b, band


def _peripheral_levels(A1):
    """Breadth-first levels ``(V,)`` int (-1: unreachable) over the graph ``A1`` from a pseudo-peripheral
    vertex of the component of vertex 0: the farthest vertex from the farthest vertex from 0 (two
    passes), so that the levels run along the mesh's longest extent."""
    V = A1.shape[0]
    if V == 0:
        return np.zeros(0, dtype=np.int64)
    src = 0
    for _ in range(2):
        d = csgraph.shortest_path(A1, unweighted=True, indices=src, directed=False)
        src = int(np.argmax(np.where(np.isfinite(d), d, -1.0)))
    d = csgraph.shortest_path(A1, unweighted=True, indices=src, directed=False)
    return np.where(np.isfinite(d), d, -1).astype(np.int64)

