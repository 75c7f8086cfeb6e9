"""Segmentation of a registered mesh sequence into k rigid parts by their motion (dissertation
(model-adaptive mocap) §3.2, step 2; docs/learn_rig_solver.md).

Method (rigid-transform clustering in the spirit of Le & Deng's rigid-bone initialisation):

1. seeding: k-means++ on vertex trajectories (the concatenated 3M positions of a vertex over the M
   scans), applied hierarchically: the k-part solution is built from the (k−1)-part one by splitting
   its worst-fitting part (largest squared error) in two, seeded by k-means++ (k = 2) on that part's
   trajectories and refined as a 2-part rigid clustering of that part alone (best of SPLIT_TRIES);
2. per part and scan, the best rigid transform rest → scan (Kabsch);
3. every vertex moves to the part whose M rigid transforms reproduce its M positions best
   (least squared error); empty parts are re-seeded at the worst-fitting vertex;
4. 2-3 repeat until no label changes (after every split, over all parts);
5. connectivity: every part must be one connected piece of the mesh.  Islands (all components of a
   part but its largest) are removed smallest first, each by the cheaper of merging it into the
   adjacent part whose refitted motion fits the union best, or (islands of at least
   MIN_PART_VERTICES) making it a part of its own and merging instead the two adjacent parts whose
   union fits best (two distant pieces with alike motion in one part); 2-3 and 5 alternate (at most
   CONNECT_ROUNDS times);
6. mirror symmetry (when the mesh has a vertex mirror map, :mod:`solver.learn.mirror_map`): 2-3 and 5
   alternate once more with step 3 replaced by :func:`solver.learn.symmetry.mirrored_labels`: a vertex
   and its mirror vertex go together to the compatible pair of parts that fits both best, so that
   mirror-image parts are cut alike, where the motion of both sides together puts each boundary rather
   than wherever each side's noise and skin blending put it.  Meshes without a map skip this step.

Speed:

* steps 1-4 run on about SAMPLES vertices: the rest mesh is binned in cubic cells and every occupied
  cell contributes one vertex, weighted by the number of vertices in its cell, so that the weighted
  sample error estimates the full one.  All vertices are then assigned to their best part and 2-3
  are repeated at full resolution until the labels settle (at most POLISH_ROUNDS rounds);
* 2 and 3 work on one *moment* vector per vertex, ``φ_v = [s_mv x_vᵀ (9M), s_mv (3M), x_v (3), c_v]``
  (x rest, s scans, both centred; ``c_v = M|x_v|² + Σ_m|s_mv|²``): the per-part sums ``Σ_v w_v φ_v``
  hold all covariances and centroids Kabsch needs, the squared error of vertex v under part c is
  ``Σ_m|t_mc|² − 2 φ_v·ψ_c`` with ``ψ_c = [R_mc, t_mc, −Σ_m R_mcᵀ t_mc, −½]``, and the least error
  of any vertex set follows from its sums alone (the costs of step 5);
* only the parts that gained or lost vertices are refitted and only their error columns recomputed;
  their sums are updated by the moments of the vertices that moved;
* the hierarchy makes every k cost one refinement started close to its optimum: the curve
  k = 1..k_max is one run, and ``segment(k)`` with the same seed finishes the curve's k-th solution.

``choose_num_parts`` reads k from the curve E(k) (RMS rigid-fit error on the samples, metres): the
smallest k whose error is at most RESIDUAL_FRACTION (3 %) of the one-part error E(1), i.e. the parts
reproduce all but 3 % (RMS) of the motion that a single rigid transform cannot; or, if that is never
reached, the smallest k within PLATEAU (10 %) of the best error on the curve (noise or skin
deformation that no number of rigid parts removes).  A human body's curve falls smoothly after the
torso and limbs (k = 5), every further split still taking off 5-15 %, so neither the knee of log E(k)
nor a threshold relative to the body size serves (curves: docs/learn_rig_solver.md).

Units: positions in metres, errors in metres (squared errors in m²).
"""
import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from ..errors import ArticulaInputError, Cancelled  # noqa: F401  (Cancelled raised by callbacks)
from ..geometry.mesh_graph import adjacency
from ..geometry.procrustes import rotation_from_covariance
from .mirror_map import mirror_map
from .symmetry import mirror_compatible, mirrored_labels


MIN_PART_VERTICES = 4       # a rigid part needs a few non-collinear points to have a defined motion
SAMPLES = 2000              # about this many vertices carry the clustering (cell subsample of the rest mesh)
SPLIT_TRIES = 3             # k-means++ seeded 2-clusterings tried when a part is split (best kept)
CHUNK = 4096                # vertices per block of full-resolution moments
POLISH_ROUNDS = 10          # at most this many full-resolution rounds of steps 2-3 after the sample clustering
CONNECT_ROUNDS = 3          # at most this many alternations of full-resolution refinement and step 5
RESIDUAL_FRACTION = 0.03    # choose_num_parts: smallest k with E(k) <= this fraction of E(1) ...
PLATEAU = 0.10              # ... or within this fraction of the curve's best error


# ----------------------------------------------------------------------------- moments and fits

def centred(rest, scans):
    """Rest ``(V,3)`` and scans ``(M,V,3)`` (float64) moved to their centroids: rigid fits and errors
    are unchanged, the expanded squared errors lose fewer digits."""
    rest = np.asarray(rest, dtype=np.float64)
    scans = np.asarray(scans, dtype=np.float64)
    return rest - rest.mean(axis=0), scans - scans.mean(axis=1, keepdims=True)


def moments(rest, scans):
    """Per-vertex moments ``φ (V, 12M+4)`` = [s_mv x_vᵀ row-major per scan (9M), s_mv (3M), x_v (3), c_v]
    with ``c_v = M|x_v|² + Σ_m |s_mv|²`` (m²), the constant of the expanded squared error."""
    M, V = scans.shape[:2]
    s = scans.transpose(1, 0, 2)                                        # (V,M,3)
    outer = (s[:, :, :, None] * rest[:, None, None, :]).reshape(V, 9 * M)
    c = M * np.einsum("vi,vi->v", rest, rest) + np.einsum("vmi,vmi->v", s, s)
    return np.concatenate([outer, s.reshape(V, 3 * M), rest, c[:, None]], axis=1)


def part_sums(phi, labels, weights, k):
    """Weighted per-part sums ``(S (k, D), n (k,))`` of moments ``phi (P,D)`` under ``labels (P,)``."""
    P = len(labels)
    W = sp.csr_matrix((weights, (labels, np.arange(P))), shape=(k, P))
    return np.asarray(W @ phi), np.bincount(labels, weights=weights, minlength=k)


def fit_from_sums(S, n, M):
    """Kabsch per part and scan from part sums ``S (p, 12M+4)`` and weights ``n (p,)``.
    Returns ``R (M,p,3,3)``, ``t (M,p,3)``; parts without weight get the identity."""
    p = len(n)
    safe = np.where(n > 0, n, 1.0)
    cross = S[:, :9 * M].reshape(p, M, 3, 3)                          # Σ w s xᵀ
    mu_d = S[:, 9 * M:12 * M].reshape(p, M, 3) / safe[:, None, None]
    mu_s = S[:, 12 * M:12 * M + 3] / safe[:, None]                     # (p,3)
    cov = cross - n[:, None, None, None] * mu_d[..., :, None] * mu_s[:, None, None, :]
    R = rotation_from_covariance(cov)
    R = np.where((n > 0)[:, None, None, None], R, np.eye(3))
    t = mu_d - np.einsum("pmij,pj->pmi", R, mu_s)
    return R.transpose(1, 0, 2, 3), t.transpose(1, 0, 2)


def part_vectors(R, t):
    """``ψ (p, 12M+4)`` = [R_mc, t_mc, −Σ_m R_mcᵀ t_mc, −½] and ``T (p,)`` = Σ_m |t_mc|², such that the
    squared error (m²) of a vertex with moments φ under part c is ``T_c − 2 φ·ψ_c``."""
    M, p = t.shape[:2]
    psi = np.concatenate([R.transpose(1, 0, 2, 3).reshape(p, 9 * M), t.transpose(1, 0, 2).reshape(p, 3 * M),
                          -np.einsum("mkij,mki->kj", R, t), np.full((p, 1), -0.5)], axis=1)
    return psi, np.einsum("mki,mki->k", t, t)


def errors_from_moments(phi, R, t):
    """Squared errors ``(P,p)`` (m², summed over scans) of moments ``phi (P,D)`` under the part
    transforms ``R (M,p,3,3)``, ``t (M,p,3)``."""
    psi, T = part_vectors(R, t)
    # einsum, not BLAS: few columns at a time, where threaded BLAS costs more CPU than it saves
    return np.maximum(T[None, :] - 2.0 * np.einsum("pd,kd->pk", phi, psi), 0.0)


def sums_cost(S, n, M):
    """Least total squared error (m²) of point sets with sums ``S (p,D)``, weights ``n (p,)`` under their
    own best rigid fits."""
    psi, T = part_vectors(*fit_from_sums(S, n, M))
    return np.maximum(n * T - 2.0 * np.einsum("pd,pd->p", S, psi), 0.0)


def rigid_fit_errors(rest, scans, R, t):
    """Squared error ``(V,k)`` (m²): ``Σ_m ‖R[m,c] rest[v] + t[m,c] − scans[m,v]‖²`` for every vertex and
    part (rest ``(V,3)``, scans ``(M,V,3)``, R ``(M,k,3,3)``, t ``(M,k,3)``), by expanding the square
    (no (M,k,V,3) temporary)."""
    x2 = np.einsum("vi,vi->v", rest, rest)
    s2 = np.einsum("mvi,mvi->v", scans, scans)
    t2 = np.einsum("mki,mki->k", t, t)
    Rt = np.einsum("mkij,mki->kj", R, t)                              # Σ_m R_mcᵀ t_mc
    sR = np.einsum("mvi,mkij->vkj", scans, R, optimize=True)          # Σ_m s_mvᵀ R_mc
    st = np.einsum("mvi,mki->vk", scans, t, optimize=True)
    M = scans.shape[0]
    err = (M * x2 + s2)[:, None] + t2[None, :] + 2 * rest @ Rt.T
    err -= 2 * np.einsum("vkj,vj->vk", sR, rest) + 2 * st
    return np.maximum(err, 0.0)


# ----------------------------------------------------------------------------- point sets

def cells(ijk):
    """Index ``(V,)`` in 0..C−1 of the distinct rows of integer cell coordinates ``ijk (V,3)``."""
    order = np.lexsort(ijk.T[::-1])
    s = ijk[order]
    cell = np.empty(len(ijk), dtype=np.int64)
    cell[order] = np.cumsum(np.r_[True, np.any(s[1:] != s[:-1], axis=1)]) - 1
    return cell


def grid_sample(points, n):
    """About ``n`` points of ``points (V,3)`` spread evenly: the points are binned in cubic cells whose
    size makes about n cells occupied (bisection on the size) and every occupied cell contributes its
    point nearest to the cell's mean.  Returns ``(indices (P,), cell (V,))`` with ``cell[v]`` the
    position in ``indices`` of v's cell (``bincount(cell)`` = vertices per sample)."""
    V = len(points)
    if n >= V:
        return np.arange(V), np.arange(V)
    q = points - points.min(axis=0)
    lo, hi = 0.0, float(q.max()) + 1e-12
    for _ in range(40):
        h = 0.5 * (lo + hi)
        cell = cells(np.floor(q / h).astype(np.int64))
        P = int(cell.max()) + 1
        if abs(P - n) <= n // 20:
            break
        lo, hi = (h, hi) if P > n else (lo, h)
    count = np.bincount(cell, minlength=P)
    mean = np.stack([np.bincount(cell, weights=points[:, i], minlength=P) for i in range(3)], 1) / count[:, None]
    d2 = np.sum((points - mean[cell]) ** 2, axis=1)
    order = np.lexsort((d2, cell))                             # by cell, nearest to the mean first
    first = np.r_[True, cell[order][1:] != cell[order][:-1]]
    return order[first], cell


class Sample:
    """Weighted points with stored moments: ``phi (P,D)``, weights ``w (P,)`` (vertices represented),
    trajectories ``traj (P,3M)``, number of scans ``M``."""

    def __init__(self, phi, w, traj, M):
        self.phi, self.w, self.traj, self.M = phi, w, traj, M

    @classmethod
    def of_mesh(cls, rest, scans, n=SAMPLES):
        """The cell subsample (:func:`grid_sample`) of centred ``rest (V,3)``, ``scans (M,V,3)``."""
        index, cell = grid_sample(rest, n)
        traj = scans[:, index].transpose(1, 0, 2).reshape(len(index), -1)
        return cls(moments(rest[index], scans[:, index]), np.bincount(cell).astype(np.float64), traj,
                   scans.shape[0])

    def subset(self, mask):
        return Sample(self.phi[mask], self.w[mask], self.traj[mask], self.M)

    def rest_points(self):
        """The points' centred rest positions ``(P,3)`` (held in their moments)."""
        return self.phi[:, 12 * self.M:12 * self.M + 3]

    def __len__(self):
        return len(self.w)

    def sums(self, idx, labels, k):
        """Part sums ``(S (k,D), n (k,))`` of the points ``idx`` with ``labels``."""
        return part_sums(self.phi[idx], labels, self.w[idx], k)

    def errors(self, R, t):
        """Squared errors ``(P,p)`` under ``R (M,p,3,3)``, ``t (M,p,3)``."""
        return errors_from_moments(self.phi, R, t)


class Mesh:
    """All vertices (weight 1) of centred ``rest (V,3)``, ``scans (M,V,3)``; moments formed on demand."""

    def __init__(self, rest, scans):
        self.rest, self.scans, self.M = rest, scans, scans.shape[0]
        self.w = np.ones(len(rest))

    def __len__(self):
        return len(self.rest)

    def sums(self, idx, labels, k):
        """Part sums of the vertices ``idx`` with ``labels``, in blocks of CHUNK vertices."""
        S, n = np.zeros((k, 12 * self.M + 4)), np.zeros(k)
        for a in range(0, len(idx), CHUNK):
            phi = moments(self.rest[idx[a:a + CHUNK]], self.scans[:, idx[a:a + CHUNK]])
            S_, n_ = part_sums(phi, labels[a:a + CHUNK], self.w[idx[a:a + CHUNK]], k)
            S += S_
            n += n_
        return S, n

    def errors(self, R, t):
        return rigid_fit_errors(self.rest, self.scans, R, t)


# ----------------------------------------------------------------------------- clustering

class Clustering:
    """Labels ``(P,)`` of a point set (:class:`Sample` or :class:`Mesh`) with their part sums, rigid fits
    ``R (M,k,3,3)``, ``t (M,k,3)`` and squared errors ``err (P,k)``, kept consistent by :meth:`relabel`."""

    def __init__(self, points, labels, k):
        self.points, self.labels, self.k = points, np.asarray(labels, dtype=np.int64), k
        self.S, self.n = points.sums(np.arange(len(points)), self.labels, k)
        self.R, self.t = fit_from_sums(self.S, self.n, points.M)
        self.err = points.errors(self.R, self.t)

    def add_part(self):
        """One more (empty, identity) part."""
        P, M = len(self.points), self.points.M
        self.k += 1
        self.S = np.vstack([self.S, np.zeros((1, self.S.shape[1]))])
        self.n = np.r_[self.n, 0.0]
        self.R = np.concatenate([self.R, np.broadcast_to(np.eye(3), (M, 1, 3, 3))], axis=1)
        self.t = np.concatenate([self.t, np.zeros((M, 1, 3))], axis=1)
        self.err = np.hstack([self.err, np.full((P, 1), np.inf)])

    def relabel(self, new):
        """Move the points to ``new`` labels; refit the parts that changed.  Returns False if none did."""
        moved = np.flatnonzero(new != self.labels)
        if len(moved) == 0:
            return False
        S_out, n_out = self.points.sums(moved, self.labels[moved], self.k)
        S_in, n_in = self.points.sums(moved, new[moved], self.k)
        self.S += S_in - S_out
        self.n += n_in - n_out                              # vertex counts: exact in float64
        parts = np.unique(np.r_[self.labels[moved], new[moved]])
        R, t = fit_from_sums(self.S[parts], self.n[parts], self.points.M)
        self.R[:, parts], self.t[:, parts] = R, t
        self.err[:, parts] = self.points.errors(R, t)
        self.labels = new
        return True

    def best_labels(self, mirror=None, compatible=None):
        """Step 3: every point to its best part, or with a vertex ``mirror (V,)`` map and the ``compatible
        (k,k)`` parts, every vertex and its mirror vertex together to their best compatible pair of parts
        (step 6, :func:`solver.learn.symmetry.mirrored_labels`); empty parts get the worst-fitting points."""
        new = np.argmin(self.err, axis=1) if mirror is None else mirrored_labels(self.err, mirror, compatible)
        counts = np.bincount(new, minlength=self.k)
        if counts.min() == 0:
            new = _reseed_empty(new, self.err[np.arange(len(new)), new], self.k)
        return new

    def total(self):
        """Weighted total squared error (m²)."""
        return float(self.points.w @ self.err[np.arange(len(self.labels)), self.labels])

    def refine(self, iterations, mirror=None, compatible=None):
        """Steps 2-3 until no label changes (at most ``iterations`` rounds; mirror: see
        :meth:`best_labels`)."""
        for _ in range(iterations):
            if not self.relabel(self.best_labels(mirror, compatible)):
                break
        return self


def _reseed_empty(labels, err_current, k):
    """Give every empty part the worst-fitting vertex (largest error under its current part)."""
    counts = np.bincount(labels, minlength=k)
    order = np.argsort(-err_current)
    taken = 0
    for c in np.flatnonzero(counts == 0):
        while counts[labels[order[taken]]] <= 1:
            taken += 1
        counts[labels[order[taken]]] -= 1
        labels[order[taken]] = c
        counts[c] = 1
        taken += 1
    return labels


def kmeanspp_labels(features, k, rng, weights):
    """k-means++ seeds on ``features (P,D)`` (drawn with probability ∝ weight × squared distance to the
    nearest seed); returns the nearest-seed labels ``(P,)``."""
    P = len(features)
    seeds = [int(rng.choice(P, p=weights / weights.sum()))]
    d2 = np.sum((features - features[seeds[0]]) ** 2, axis=1)
    for _ in range(1, k):
        p = weights * d2
        p = p / p.sum() if p.sum() > 0 else weights / weights.sum()
        seeds.append(int(rng.choice(P, p=p)))
        d2 = np.minimum(d2, np.sum((features - features[seeds[-1]]) ** 2, axis=1))
    D = np.stack([np.sum((features - features[s]) ** 2, axis=1) for s in seeds], axis=1)
    return np.argmin(D, axis=1)


def two_motions(cl, mask, rng, iterations):
    """The best of SPLIT_TRIES rigid 2-clusterings (k-means++ seeded) of the points ``mask`` of ``cl``
    (:class:`Clustering`), as a :class:`Clustering` of those points alone."""
    sub = cl.points.subset(mask)
    tries = [Clustering(sub, kmeanspp_labels(sub.traj, 2, rng, sub.w), 2).refine(iterations)
             for _ in range(SPLIT_TRIES)]
    return min(tries, key=Clustering.total)


def split_part(cl, mask, two, iterations):
    """k → k+1 parts in place: the points ``mask`` that ``two`` (their 2-clustering) labels 1 become the
    new part; then all parts are refined."""
    new = cl.labels.copy()
    new[np.flatnonzero(mask)[two.labels == 1]] = cl.k
    cl.add_part()
    cl.relabel(new)
    return cl.refine(iterations)


def part_errors(cl):
    """Weighted squared error of every part of ``cl`` ``(k,)`` (m², summed over its points and scans)."""
    own = cl.err[np.arange(len(cl.labels)), cl.labels] * cl.points.w
    return np.bincount(cl.labels, weights=own, minlength=cl.k)


def split_worst(cl, rng, iterations):
    """k → k+1 parts in place: the part of ``cl`` (:class:`Clustering`) with the largest weighted error
    is split by a rigid 2-clustering of its own points, then all parts are refined."""
    sizes = np.bincount(cl.labels, minlength=cl.k)
    worst = int(np.argmax(np.where(sizes >= 2, part_errors(cl), -1.0)))
    mask = cl.labels == worst
    return split_part(cl, mask, two_motions(cl, mask, rng, iterations), iterations)


def hierarchy(rest, scans, k_max, seed=0, iterations=50, samples=SAMPLES, progress=None,
              stage="choosing the number of parts"):
    """Steps 1-4 on the cell subsample for k = 1..k_max.  Yields ``(k, Clustering)`` (the same object,
    updated in place) for every k; centred ``rest (V,3)``, ``scans (M,V,3)``.  ``progress(fraction,
    text, None)`` after each k, the text ``stage`` and k."""
    rng = np.random.default_rng(seed)
    sample = Sample.of_mesh(rest, scans, samples)
    cl = Clustering(sample, np.zeros(len(sample), dtype=np.int64), 1)
    yield 1, cl
    for k in range(2, min(k_max, len(sample)) + 1):
        split_worst(cl, rng, iterations)
        if progress is not None:
            progress(k / k_max, f"{stage} (k={k} of {k_max})", None)
        yield k, cl


# ----------------------------------------------------------------------------- full resolution

def islands_of(labels, A):
    """Components of the parts on the mesh: ``(comp (V,), size (C,), islands)`` where ``islands`` are the
    components that are not their part's largest.  ``A``: vertex adjacency as COO."""
    same = labels[A.row] == labels[A.col]
    G = sp.coo_matrix((np.ones(same.sum()), (A.row[same], A.col[same])), shape=A.shape)
    n, comp = connected_components(G, directed=False)
    size = np.bincount(comp, minlength=n)
    comp_label = np.zeros(n, dtype=np.int64)
    comp_label[comp] = labels
    largest = np.full(int(labels.max()) + 1, -1)
    order = np.argsort(size, kind="stable")                    # ascending: the last write wins
    largest[comp_label[order]] = order
    return comp, size, np.setdiff1d(np.arange(n), largest[largest >= 0])


def adjacent_pairs(labels, A, k):
    """Pairs ``(a, b)``, a < b < k, of parts that share a mesh edge ``(E,2)``."""
    a, b = labels[A.row], labels[A.col]
    keep = (a < b) & (b < k)
    return np.unique(np.stack([a[keep], b[keep]], axis=1), axis=0)


def make_parts_connected(mesh, labels, A):
    """Step 5: remove every island of a part (a connected component that is not the part's largest),
    smallest first, by the cheaper of (a) merging it into the adjacent part whose refitted rigid motion
    fits the union best and (b) making it a part of its own and merging the two adjacent parts whose
    union fits best (keeps k; only for islands of at least MIN_PART_VERTICES vertices).  Costs are
    exact least-squares errors from part sums (:func:`sums_cost`).  ``mesh``: :class:`Mesh`;
    ``A``: vertex adjacency (V,V) of a connected mesh.  Returns new labels; every part is connected."""
    labels, k, M = labels.copy(), int(labels.max()) + 1, mesh.M
    A = sp.coo_matrix(A)
    S, n = mesh.sums(np.arange(len(labels)), labels, k)
    while True:
        comp, size, islands = islands_of(labels, A)
        if len(islands) == 0:
            return labels
        members = np.flatnonzero(comp == islands[np.argmin(size[islands])])
        p = labels[members[0]]
        S_i, n_i = mesh.sums(members, np.zeros(len(members), dtype=np.int64), 1)
        S[p] -= S_i[0]
        n[p] -= n_i[0]
        inside = np.zeros(len(labels), dtype=bool)
        inside[members] = True
        nb = np.unique(labels[A.col[inside[A.row] & ~inside[A.col]]])
        gain = sums_cost(S[nb] + S_i, n[nb] + n_i, M) - sums_cost(S[nb], n[nb], M)
        j = nb[np.argmin(gain)]
        own = np.inf
        if n_i[0] >= MIN_PART_VERTICES:
            labels[members] = k                                # the island as a (temporary) part k
            pairs = adjacent_pairs(labels, A, k)
            merge = (sums_cost(S[pairs[:, 0]] + S[pairs[:, 1]], n[pairs[:, 0]] + n[pairs[:, 1]], M)
                     - sums_cost(S[pairs[:, 0]], n[pairs[:, 0]], M) - sums_cost(S[pairs[:, 1]], n[pairs[:, 1]], M))
            own = sums_cost(S_i, n_i, M)[0] + merge.min() if len(pairs) else np.inf
        if own < gain.min():
            a, b = pairs[np.argmin(merge)]
            labels[labels == b] = a
            labels[members] = b
            S[a] += S[b]
            n[a] += n[b]
            S[b], n[b] = S_i[0], n_i[0]
        else:
            labels[members] = j
            S[j] += S_i[0]
            n[j] += n_i[0]


def connected_refinement(mesh, cl, A, mirror=None, compatible=None, progress=None):
    """Steps 2-3 (step 6's mirror-aware step 3 with a ``mirror`` map, see :meth:`Clustering.best_labels`)
    alternating with step 5 (at most CONNECT_ROUNDS times) on ``cl`` (a :class:`Clustering` of ``mesh``,
    updated in place); ``A``: vertex adjacency.  Returns the final labels ``(V,)``, every part connected.
    ``progress(text)`` is called before each round."""
    for r in range(CONNECT_ROUNDS):
        if progress is not None:
            progress(f"round {r + 1}")
        labels = make_parts_connected(mesh, cl.refine(POLISH_ROUNDS, mirror, compatible).labels, A)
        if not cl.relabel(labels):
            break
    return labels


def finish(rest, scans, faces, R, t, mirror=None, progress=None, drop_small=False):
    """Steps 2-5 at full resolution from the sample's part transforms ``R (M,k,3,3)``, ``t (M,k,3)``
    (centred ``rest``, ``scans``).  With a vertex ``mirror (V,)`` map, the parts that are mirror images
    of each other are then re-cut alike (step 6; :func:`solver.learn.symmetry.mirror_compatible` says
    which parts may hold a vertex and its image).  Returns ``(labels (V,), rms metres)``.
    drop_small: parts left with fewer than MIN_PART_VERTICES vertices are dropped (their vertices go to
    the parts that fit them best; the count was chosen, not asked for) instead of refused.
    ``progress(text)`` names each full-resolution step as it starts."""
    say = progress or (lambda text: None)
    mesh, A = Mesh(rest, scans), adjacency(faces, len(rest))
    while True:
        say("assigning every vertex to its best part")
        k = t.shape[1]
        err = rigid_fit_errors(rest, scans, R, t)
        labels = np.argmin(err, axis=1)
        labels = _reseed_empty(labels, err[np.arange(len(labels)), labels], k)
        cl = Clustering(mesh, labels, k)
        labels = connected_refinement(mesh, cl, A, progress=lambda r: say(f"connected parts, {r}"))
        small = np.bincount(labels, minlength=k) < MIN_PART_VERTICES
        if not (drop_small and small.any() and k > 1):
            break
        R, t = cl.R[:, ~small], cl.t[:, ~small]
    compatible = mirror_compatible(labels, mirror, k) if mirror is not None else np.ones((k, k), dtype=bool)
    if not compatible.all():
        labels = connected_refinement(mesh, cl, A, mirror, compatible,
                                      progress=lambda r: say(f"mirror-image parts cut alike, {r}"))
    counts = np.bincount(labels, minlength=k)
    if counts.min() < MIN_PART_VERTICES:
        raise ArticulaInputError(
            f"parts: the motion cannot be split into {k} connected rigid parts (one part would have only "
            f"{counts.min()} vertices); use fewer parts")
    final = Clustering(mesh, labels, k)                        # sums from scratch, no accumulated updates
    return labels, float(np.sqrt(final.total() / (len(rest) * len(scans))))


def segment(rest, scans, faces, k, seed=0, iterations=50, samples=SAMPLES, mirror=True, progress=None,
            start=None):
    """Segment into exactly ``k`` connected rigid parts (each with at least MIN_PART_VERTICES vertices).

    rest (V,3), scans (M,V,3) metres, faces (F,3); seed: k-means++ draws of the splits; iterations: at
    most this many rounds of steps 2-3 per split; samples: size of the cell subsample.  Returns
    ``(labels (V,) int64 in [0,k), rms)`` where rms is the RMS distance (metres) of the scans from the
    per-part rigid fits.  Raises :class:`ArticulaInputError` when a part ends up with too few vertices.
    mirror: True finds the mesh's vertex mirror map (:func:`solver.learn.mirror_map.mirror_map`) and
    cuts mirror-image parts alike (:func:`finish`); False does not; or a map ``(V,)`` (-1: no mirror
    vertex) to use.  ``progress(fraction, stage, None)``: after each split (fraction to 0.7 at k), then
    at each full-resolution step (may raise Cancelled).  start: the sample's part transforms ``(R (M,k,3,3),
    t (M,k,3))`` of the centred data (:func:`solver.learn.part_count.articulated_parts`) to finish from
    instead of the hierarchy's k-part solution; parts too small at full resolution are then dropped
    (fewer than k parts may come back: the count was chosen, not asked for)."""
    if mirror is True:
        mirror = mirror_map(rest, scans, faces) if k > 1 else None
    elif mirror is False:
        mirror = None
    else:
        mirror = np.asarray(mirror, dtype=np.int64)
    rest, scans = centred(rest, scans)
    V = len(rest)
    if k < 1 or k > V:
        raise ArticulaInputError(f"parts: {k} parts requested for a mesh of {V} vertices")
    given = start is not None
    if start is None:
        split = None if progress is None else (lambda f, text, _: progress(0.7 * f, text, None))
        for kk, cl in hierarchy(rest, scans, k, seed, iterations, samples, split, f"segmenting into {k} parts"):
            pass
        if kk < k:
            raise ArticulaInputError(f"parts: {k} parts requested for a mesh of {V} vertices; use fewer parts")
        start = (cl.R, cl.t)
    steps = iter(np.linspace(0.7, 1.0, 2 * CONNECT_ROUNDS + 2))
    full = None if progress is None else (lambda text: progress(float(next(steps, 1.0)), f"segmentation: {text}",
                                                                None))
    return finish(rest, scans, faces, *start, mirror, full, drop_small=given)


def parts_from_curve(errors, floor=0.0):
    """Index (k − 1) chosen on a curve ``errors (K,)`` = E(1..K): the first point with
    E ≤ RESIDUAL_FRACTION·E(1), else the first within PLATEAU of the smallest E.  Errors are first
    raised to ``floor`` (exact fits give rounding-level errors)."""
    e = np.maximum(np.asarray(errors, dtype=np.float64), floor)
    ok = (e <= RESIDUAL_FRACTION * e[0]) | (e <= (1.0 + PLATEAU) * e.min())
    return int(np.argmax(ok))


def choose_num_parts(rest, scans, faces, k_max=20, seed=0, progress=None):
    """Number of parts from the motion (module docstring): the curve E(k), k = 1..k_max, of the
    hierarchical clustering and :func:`parts_from_curve` (errors floored at 1e-6 of the mesh size).

    Returns ``(k, errors (k_max,))`` with ``errors[i]`` = E(i+1) in metres (RMS on the cell subsample;
    repeated at the end if the subsample cannot carry k_max parts).  ``progress(fraction, stage,
    objective)`` is called after each k (may raise Cancelled)."""
    rest, scans = centred(rest, scans)
    k_max = int(min(k_max, len(rest)))
    errors = []
    for _, cl in hierarchy(rest, scans, k_max, seed, progress=progress):
        errors.append(np.sqrt(cl.total() / (cl.points.w.sum() * len(scans))))
    errors = np.array(errors + errors[-1:] * (k_max - len(errors)))
    size = np.linalg.norm(np.ptp(rest, axis=0))
    return parts_from_curve(errors, 1e-6 * size) + 1, errors
