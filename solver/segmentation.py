"""Segmentation of a registered mesh sequence into k rigid parts by their motion (spec §3.2 step 2).

Method (rigid-transform clustering in the spirit of Le & Deng's rigid-bone initialisation, written
from the spec's description):

1. k-means++ seeding on vertex trajectories (the concatenated 3M positions of a vertex over the M
   scans); the first labels are the nearest seed in trajectory space;
2. per part and scan, the best rigid transform rest → scan (Kabsch, :mod:`solver.procrustes`);
3. every vertex moves to the part whose M rigid transforms reproduce its M positions best
   (least squared error); empty parts are re-seeded at the worst-fitting vertex;
4. 2-3 repeat until no label changes; the best of a few seeded restarts is kept;
5. connectivity: every part must be one connected piece of the mesh.  Islands (all components of a
   part but its largest) are merged as a whole into the adjacent part that fits them best.

``choose_num_parts`` picks k from the motion: the knee of the log fit-error curve log E(k) (E = RMS
vertex residual of the rigid segmentation, k = 1..k_max), i.e. the k whose point lies farthest below
the chord from (1, log E(1)) to (k_max, log E(k_max)) in coordinates normalised to [0, 1] ("kneedle"
on a log scale, with E floored at 1e-6 of the mesh size).  On exactly articulated data E drops by
orders of magnitude at the true k and stays flat, so that k is the knee; on soft bodies the log
curve bends where adding parts stops paying off proportionally.
Units: positions in metres, errors in metres.
"""
import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from .errors import ArticulaInputError, Cancelled  # noqa: F401  (Cancelled raised by callbacks)
from .laplacian import adjacency
from .procrustes import fit_parts


MIN_PART_VERTICES = 4       # a rigid part needs a few non-collinear points to have a defined motion


def rigid_fit_errors(rest, scans, R, t):
    """Squared error ``(V,k)``: ``Σ_m ‖R[m,c] rest[v] + t[m,c] − scans[m,v]‖²`` for every vertex and part,
    computed by expanding the square (no (M,k,V,3) temporary)."""
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


def _kmeanspp_labels(features, k, rng):
    """k-means++ seeds on ``features (V,D)``; returns the nearest-seed labels ``(V,)``."""
    V = len(features)
    seeds = [int(rng.integers(V))]
    d2 = np.sum((features - features[seeds[0]]) ** 2, axis=1)
    for _ in range(1, k):
        p = d2 / d2.sum() if d2.sum() > 0 else np.full(V, 1.0 / V)
        seeds.append(int(rng.choice(V, p=p)))
        d2 = np.minimum(d2, np.sum((features - features[seeds[-1]]) ** 2, axis=1))
    D = np.stack([np.sum((features - features[s]) ** 2, axis=1) for s in seeds], axis=1)
    return np.argmin(D, axis=1)


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


def rigid_clustering(rest, scans, k, rng, iterations=50):
    """One seeded run of steps 1-4.  Returns ``(labels (V,), total squared error)``."""
    V, M = rest.shape[0], scans.shape[0]
    features = scans.transpose(1, 0, 2).reshape(V, 3 * M)
    labels = _kmeanspp_labels(features, k, rng)
    for _ in range(iterations):
        R, t = fit_parts(rest, scans, labels, k)
        err = rigid_fit_errors(rest, scans, R, t)
        new = np.argmin(err, axis=1)
        new = _reseed_empty(new, err[np.arange(V), new], k)
        if np.array_equal(new, labels):
            break
        labels = new
    R, t = fit_parts(rest, scans, labels, k)
    err = rigid_fit_errors(rest, scans, R, t)
    return labels, float(err[np.arange(V), labels].sum())


def make_parts_connected(labels, A, err):
    """Merge every island of a part (a connected component that is not the part's largest) into the
    adjacent part with the least total fit error ``err (V,k)`` over the island.  ``A``: vertex
    adjacency (V,V) CSR of a connected mesh.  Returns new labels; every part is then connected."""
    labels = labels.copy()
    A = sp.coo_matrix(A)
    while True:
        same = labels[A.row] == labels[A.col]
        G = sp.coo_matrix((np.ones(same.sum()), (A.row[same], A.col[same])), shape=A.shape)
        n, comp = connected_components(G, directed=False)
        size = np.bincount(comp, minlength=n)
        comp_label = np.zeros(n, dtype=np.int64)
        comp_label[comp] = labels
        k = int(labels.max()) + 1
        largest = np.full(k, -1)
        order = np.argsort(size)                               # ascending: the last write wins
        largest[comp_label[order]] = order
        islands = np.setdiff1d(np.arange(n), largest[largest >= 0])
        if len(islands) == 0:
            return labels
        # handle the smallest island first; re-evaluate after each merge (cheap, islands are few)
        isl = islands[np.argmin(size[islands])]
        members = np.flatnonzero(comp == isl)
        cross = (comp[A.row] == isl) & (comp[A.col] != isl)
        neighbours = np.unique(labels[A.col[cross]])
        cost = err[members][:, neighbours].sum(axis=0)
        labels[members] = neighbours[np.argmin(cost)]


def segment(rest, scans, faces, k, seed=0, restarts=4, iterations=50):
    """Segment into exactly ``k`` connected rigid parts (each with at least MIN_PART_VERTICES vertices).

    rest (V,3), scans (M,V,3) metres, faces (F,3).  Returns ``(labels (V,) int64 in [0,k), rms)`` where
    rms is the RMS distance (metres) of the scans from the per-part rigid fits.  Raises
    :class:`ArticulaInputError` when a part ends up empty (more parts than vertices can support)."""
    rest = np.asarray(rest, dtype=np.float64)
    scans = np.asarray(scans, dtype=np.float64)
    V = len(rest)
    if k < 1 or k > V:
        raise ArticulaInputError(f"parts: {k} parts requested for a mesh of {V} vertices")
    rng = np.random.default_rng(seed)
    best = None
    for _ in range(restarts if k > 1 else 1):
        labels, e = rigid_clustering(rest, scans, k, rng, iterations)
        if best is None or e < best[1]:
            best = (labels, e)
    labels = best[0]
    R, t = fit_parts(rest, scans, labels, k)
    err = rigid_fit_errors(rest, scans, R, t)
    labels = make_parts_connected(labels, adjacency(faces, V), err)
    counts = np.bincount(labels, minlength=k)
    if counts.min() < MIN_PART_VERTICES:
        raise ArticulaInputError(
            f"parts: the motion cannot be split into {k} connected rigid parts (one part would have only "
            f"{counts.min()} vertices); use fewer parts")
    R, t = fit_parts(rest, scans, labels, k)
    rms = np.sqrt(rigid_fit_errors(rest, scans, R, t)[np.arange(V), labels].sum() / (V * len(scans)))
    return labels, float(rms)


def knee(errors):
    """Index of the knee of a decreasing curve ``errors (K,)``: the point farthest below the chord
    between the first and last point, in coordinates normalised to [0,1] (0 for a flat curve)."""
    e = np.asarray(errors, dtype=np.float64)
    if len(e) < 3 or e[0] - e[-1] <= 0:
        return 0
    x = np.linspace(0.0, 1.0, len(e))
    y = (e - e[-1]) / (e[0] - e[-1])
    return int(np.argmax((1.0 - x) - y))


def choose_num_parts(rest, scans, faces, k_max=20, seed=0, progress=None):
    """Number of parts from the motion: the knee of the RMS rigid-fit error E(k), k = 1..k_max.

    Returns ``(k, errors (k_max,))`` with ``errors[i]`` = E(i+1) in metres.  ``progress(fraction,
    stage, objective)`` is called after each k (may raise Cancelled)."""
    k_max = int(min(k_max, len(rest)))
    errors = []
    for k in range(1, k_max + 1):
        try:
            errors.append(segment(rest, scans, faces, k, seed=seed, restarts=2)[1])
        except ArticulaInputError:              # k exceeds what the motion can separate: stop the curve
            break
        if progress is not None:
            progress(k / k_max, f"choosing the number of parts (k={k})", None)
    errors = np.array(errors)
    if len(errors) < k_max:
        errors = np.concatenate([errors, np.full(k_max - len(errors), errors[-1])])
    size = np.linalg.norm(np.ptp(np.asarray(rest, dtype=np.float64), axis=0))
    return knee(np.log(np.maximum(errors, 1e-6 * size))) + 1, errors
