"""Start hypotheses read from the capture's own shape: geodesic extremities and level-set rings.

Distances measured along a body's surface barely change with its pose, so the head, hands and feet are
the points farthest along the surface from everything else (accumulative geodesic extrema, as in
Plagemann et al., ICRA 2010, "Real-time identification and localization of body parts from depth
images"), in any pose and any world orientation:

1. **Graphs**: the capture's points joined to their nearest neighbours only along the surface (close,
   similarly facing, the edge across neither normal), so limbs that touch are not joined through the
   gap; the model's mesh by its edges.
2. **Extremities**: from the point nearest the centroid, ``EXTREMITIES`` times the point farthest from all
   found so far.  The model's five are named by the nearest end of the head, hand and toe chains.
3. **Labels**: five of the capture's extremities matched to the model's five by their pairwise geodesic
   distances (up to a common scale, as the capture's graph runs longer than the mesh's); the body's
   left-right symmetry leaves four labellings that agree about as well, all kept.
4. **Joints**: on the model, each chain joint is the centre of the band of its chain end's geodesic field
   at the level whose centre lies nearest the joint; the capture's band at the scaled level gives the
   joint.  The joints where a limb meets the trunk (hip, shoulder, neck) are put one segment length from
   the next joint along the axis through the segment's middle band; the trunk's joints (and any not
   found) follow them rigidly.
5. **Pose**: the joints onto the rig through the start poses' transfer (:class:`.start_poses.RigPoser`),
   then each limb's start-pose and segment-direction search of :mod:`.start_search`.

Where limbs touch the trunk or each other the extremities and bands are wrong; such hypotheses are
simply beaten by others in the caller's fits.
"""
from __future__ import annotations

import itertools
import weakref

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components, dijkstra
from scipy.spatial import cKDTree

from ..errors import ArticulaInputError
from ..geometry.mesh_graph import edges_of
from ..geometry.normals import vertex_areas
from ..geometry.procrustes import fit_rigid
from .start_poses import POSE_ROLES, REQUIRED, RigPoser
from .start_search import recombined_start

GRAPH_POINTS = 10000   # capture points of the surface graph
NEIGHBOURS = 10        # nearest neighbours tried as edges
SPACING = 1.25         # an edge is at most this many times the median distance to the
SPACING_NEIGHBOUR = 5  # ... 6th nearest neighbour (uniform over a scan's grid and a random sample)
FACING = 0.5           # the two normals of an edge agree at least this much (cosine)
ACROSS = 0.6           # an edge runs along the surface: |cos| to either normal below this
EXTREMITIES = 7        # capture extremities found (five of them are matched)
LABELLINGS = 4         # labellings kept (the body's left-right symmetry gives four)
BAND = 0.015           # half-width of a level band (m)
THIN_BAND = 5          # points of a band widened where it holds fewer than three
RADIUS = 0.12          # a band's points farther than this from its median are left out (m)
LEVEL_STEP = 0.005     # levels tried on the model (m)
MIN_BODY = 0.5         # the graph's largest part must hold this share of the points
ENDS = ("head.end", "hand.L.end", "hand.R.end", "toe.L.end", "toe.R.end")
CHAINS = (("head.end", "head"), ("hand.L.end", "hand.L", "forearm.L"), ("hand.R.end", "hand.R", "forearm.R"),
          ("toe.L.end", "toe.L", "foot.L", "shin.L"), ("toe.R.end", "toe.R", "foot.R", "shin.R"))
ROOTS = (("neck", "head"), ("upper_arm.L", "forearm.L"), ("upper_arm.R", "forearm.R"), ("thigh.L", "shin.L"),
         ("thigh.R", "shin.R"))

_END_BONES = {"head.end": ("head", "neck")} | {f"{a}.{s}.end": (f"{a}.{s}", f"{b}.{s}")
                                                for s in "LR" for a, b in (("hand", "forearm"), ("toe", "foot"))}
_LANDMARKS = {}


def geodesic_starts(model, points, normals, pose_set=None, seed: int = 0) -> list:
    """Up to ``LABELLINGS`` one-frame :class:`Poses` of the humanoid ``model`` on the capture ``points
    (N, 3)`` with outward unit ``normals (N, 3)`` (metres, any world), best labelling first; ``[]`` when
    the capture's surface graph or the model's ends do not give five extremities."""
    marks = landmarks(model)
    if marks is None or len(points) < 50:
        return []
    rng = np.random.default_rng(seed)
    P, graph, body = capture_graph(points, normals, rng)
    if body.sum() < max(50, MIN_BODY * len(P)):
        return []
    ends, fields = extremities(graph, body, P, EXTREMITIES)
    out = []
    for perm, scale in labellings(fields[:, ends], marks.distances)[:LABELLINGS]:
        joints = marks.joints(P, body, fields[list(perm)], scale)
        if joints is not None:
            out.append(recombined_start(model, marks.poser, joints, points, pose_set, seed))
    return out


def labellings(D, model_D) -> list:
    """``[(perm (5,), scale)]`` best first: five of the capture extremities (pairwise geodesic distances
    ``D (E, E)``) in the order of the model's ends (``model_D (5, 5)``), by the mean relative difference of
    their distances after the least-squares scale."""
    perms = np.array([q for c in itertools.combinations(range(len(D)), 5) for q in itertools.permutations(c)])
    Dp = D[perms[:, :, None], perms[:, None, :]]
    scale = (Dp * model_D).sum(axis=(1, 2)) / (model_D * model_D).sum()
    iu = np.triu_indices(5, 1)
    want = scale[:, None] * model_D[iu]
    cost = (np.abs(Dp[:, iu[0], iu[1]] - want) / want).mean(axis=1)
    return [(tuple(int(i) for i in perms[q]), float(scale[q])) for q in np.argsort(cost, kind="stable")]


def capture_graph(points, normals, rng):
    """``(P (G, 3), graph (G, G) sparse, body (G,) bool)``: ``GRAPH_POINTS`` capture points joined along the
    surface (module docstring) and the largest connected part."""
    idx = rng.choice(len(points), min(GRAPH_POINTS, len(points)), replace=False)
    P, N = points[idx], normals[idx]
    k = min(NEIGHBOURS, len(P) - 1)
    d, j = cKDTree(P).query(P, k + 1)
    d, j = d[:, 1:].ravel(), j[:, 1:].ravel()
    i = np.repeat(np.arange(len(P)), k)
    e = (P[j] - P[i]) / np.maximum(d, 1e-12)[:, None]
    ok = ((d < SPACING * np.median(d[SPACING_NEIGHBOUR::k])) & (np.einsum("ij,ij->i", N[i], N[j]) > FACING)
          & (np.abs(np.einsum("ij,ij->i", N[i], e)) < ACROSS) & (np.abs(np.einsum("ij,ij->i", N[j], e)) < ACROSS))
    graph, body = _largest(len(P), i[ok], j[ok], d[ok])
    return P, graph, body


def _largest(n, i, j, w):
    graph = coo_matrix((w, (i, j)), shape=(n, n)).tocsr()
    _, label = connected_components(graph, directed=False)
    return graph, label == np.bincount(label).argmax()


def extremities(graph, body, X, count: int):
    """``(indices [count], fields (count, G))``: geodesic extrema of the part ``body (G,)`` of points ``X (G,
    3)`` and each one's geodesic distance field (inf off the part)."""
    inside = np.flatnonzero(body)
    seed = inside[np.argmin(np.linalg.norm(X[inside] - X[inside].mean(axis=0), axis=1))]
    far = np.where(body, dijkstra(graph, directed=False, indices=seed), -1.0)
    ends, fields = [], []
    for _ in range(count):
        e = int(np.argmax(far))
        field = dijkstra(graph, directed=False, indices=e)
        ends.append(e)
        fields.append(field)
        far = np.minimum(far, np.where(body, field, -1.0))
    return ends, np.array(fields)


def band_centre(X, field, inside, level, weights=None):
    """``(3,)`` weighted centre of the points of ``X`` within ``BAND`` of ``level`` on ``field`` (and
    ``RADIUS`` of the band's median), or None when there are fewer than three.  A band of fewer points is
    widened to the ``THIN_BAND`` nearest the level within ``2 BAND`` (a sparse capture's band near an end)."""
    gap = np.where(inside, np.abs(field - level), np.inf)
    band = gap < BAND
    if band.sum() < 3:
        nearest = np.argsort(gap, kind="stable")[:THIN_BAND]
        band = np.zeros(len(gap), bool)
        band[nearest[gap[nearest] < 2 * BAND]] = True
    if band.sum() < 3:
        return None
    Q = X[band]
    w = np.ones(len(Q)) if weights is None else weights[band]
    near = np.linalg.norm(Q - np.median(Q, axis=0), axis=1) < RADIUS
    if near.sum() < 3:
        return None
    return (Q[near] * w[near, None]).sum(axis=0) / w[near].sum()


def landmarks(model):
    """The model's :class:`Landmarks` (cached per model), or None for a rig without the roles."""
    key = id(model)
    if key not in _LANDMARKS:
        _LANDMARKS[key] = Landmarks.build(model)
        weakref.finalize(model, _LANDMARKS.pop, key, None)     # the id is free again once the model is gone
    return _LANDMARKS[key]


class Landmarks:
    """The model's five ends, their pairwise geodesic ``distances (5, 5)`` and each joint's level:
    ``levels {role: (end index, level m)}``, ``roots {role: (child role, level m, segment length m)}``."""

    def __init__(self, poser, rest, distances, levels, roots):
        self.poser, self.rest, self.distances, self.levels, self.roots = poser, rest, distances, levels, roots

    @classmethod
    def build(cls, model):
        poser = _poser(model)
        if poser is None:
            return None
        rest = rest_joints(model.skeleton, poser.roles)
        if not np.isfinite(rest[[POSE_ROLES.index(r) for r in ENDS + ROOTS[0][:1]]]).all():
            return None
        V, f = model.rest_vertices, model.faces
        edges = edges_of(f)
        graph, body = _largest(len(V), edges[:, 0], edges[:, 1], np.linalg.norm(V[edges[:, 0]] - V[edges[:, 1]],
                                                                                 axis=1))
        found, fields = extremities(graph, body, V, 5)
        near = np.linalg.norm(V[found][:, None] - rest[[POSE_ROLES.index(r) for r in ENDS]][None], axis=2)
        order = min(itertools.permutations(range(5)), key=lambda p: near[list(p), range(5)].sum())
        fields = fields[list(order)]
        distances = fields[:, np.array(found)[list(order)]]
        weights = vertex_areas(V, f)
        levels, roots = {}, {}
        for k, chain in enumerate(CHAINS):
            for role in chain:
                J = rest[POSE_ROLES.index(role)]
                if np.isfinite(J).all():
                    levels[role] = (k, _nearest_level(V, fields[k], body, weights, J, 0.0))
        for root, child in ROOTS:
            Jr, Jc = rest[POSE_ROLES.index(root)], rest[POSE_ROLES.index(child)]
            if child in levels and np.isfinite(Jr).all():
                k, lo = levels[child]
                roots[root] = (child, _nearest_level(V, fields[k], body, weights, 0.5 * (Jr + Jc), lo),
                               float(np.linalg.norm(Jr - Jc)))
        if len(roots) < len(ROOTS):
            return None
        return cls(poser, rest, distances, levels, roots)

    def joints(self, P, body, fields, scale):
        """``(R, 3)`` the :data:`POSE_ROLES` joints on the capture (points ``P``, its part ``body``, the
        labelled ends' ``fields (5, G)``, levels times ``scale``), or None when a root joint is not found."""
        found = {}
        for role, (k, level) in self.levels.items():
            c = band_centre(P, fields[k], body, scale * level)
            if c is not None:
                found[role] = c
        for root, (child, level, length) in self.roots.items():
            k = self.levels[child][0]
            c = band_centre(P, fields[k], body, scale * level)
            if c is None or child not in found:
                return None
            u = c - found[child]
            found[root] = found[child] + scale * length * u / max(np.linalg.norm(u), 1e-12)
        ix = POSE_ROLES.index
        R, t = fit_rigid(self.rest[[ix(r) for r, _ in ROOTS]], np.array([found[r] for r, _ in ROOTS]))
        J = self.rest @ R.T + t                                 # the trunk's, and any joint not found
        if not self.poser.carries_chest:
            # a rig rooted at the chest: its hips bone starts there; the start poses' hips joint is the pelvis
            J[ix("hips")] = 0.5 * (J[ix("thigh.L")] + J[ix("thigh.R")])
        for role, c in found.items():
            J[ix(role)] = c
        missing = ~np.isfinite(J).all(axis=1)
        J[missing] = J[ix("hips")]
        return J


def _poser(model):
    try:
        poser = RigPoser(model.skeleton)
    except ArticulaInputError:       # a rig without the roles the start poses need
        return None
    return poser if all(r in poser.roles for r in REQUIRED) else None


def rest_joints(skeleton, roles) -> np.ndarray:
    """``(R, 3)`` rest positions of the :data:`POSE_ROLES` joints (an end: its role bone's tail, or the
    tail of the chain's last bone the rig has: a foot's without toes; NaN for roles the rig lacks)."""
    J = np.full((len(POSE_ROLES), 3), np.nan)
    for i, role in enumerate(POSE_ROLES):
        if role.endswith(".end"):
            bone = next((roles[r] for r in _END_BONES[role] if r in roles), None)
            if bone is not None:
                J[i] = skeleton.tails[bone]
        elif role in roles:
            J[i] = skeleton.heads[roles[role]]
    return J


def _nearest_level(V, field, body, weights, target, lowest) -> float:
    """The level (from ``lowest``, and at least ``BAND``: a band nearer the end is a cap a sparse capture
    may hold no three points of) of ``field`` whose band centre (:func:`band_centre`) lies nearest
    ``target (3,)``."""
    order = np.flatnonzero(body)[np.argsort(field[body])]
    g, X, w = field[order], V[order], weights[order]
    lowest = max(lowest, BAND)
    best = (np.inf, lowest)
    for level in np.arange(lowest, g[-1], LEVEL_STEP):
        a, b = np.searchsorted(g, [level - BAND, level + BAND])
        if b - a < 3:
            continue
        Q, q = X[a:b], w[a:b]
        near = np.linalg.norm(Q - np.median(Q, axis=0), axis=1) < RADIUS
        if near.sum() >= 3:
            c = (Q[near] * q[near, None]).sum(axis=0) / q[near].sum()
            if np.linalg.norm(c - target) < best[0]:
                best = (float(np.linalg.norm(c - target)), float(level))
    return best[1]
