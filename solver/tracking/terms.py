"""Residual terms of a frame fit, each linearised into normal equations over the frame's parameters.

A term has ``linearise(body, state) -> Linear`` (Gauss–Newton with IRLS weights at the state's pose)
and ``energy(body, state) -> float`` (the same energy at a trial pose, correspondences re-found there:
what Levenberg–Marquardt's acceptance test compares); ``state`` (:class:`.lm.State`) holds the pose, the
posed mesh, its surface and a cache so a trial's correspondences serve its linearisation.  Energies are sums of
robust penalties in square metres; ``Linear.H (P, P)``, ``Linear.g (P,)`` with the step solving
``(H + damping) step = -g``.
"""
from __future__ import annotations

import dataclasses

import numpy as np
from scipy.spatial import cKDTree


@dataclasses.dataclass
class Linear:
    """One term's normal equations at a pose: ``H (P, P)``, gradient ``g (P,)``, ``energy``."""
    H: np.ndarray
    g: np.ndarray
    energy: float

    def __add__(self, other):
        return Linear(self.H + other.H, self.g + other.g, self.energy + other.energy)

    def scaled(self, factor: float) -> "Linear":
        """The same term weighted by ``factor``."""
        return Linear(self.H * factor, self.g * factor, self.energy * factor)


def bone_columns(bones) -> np.ndarray:
    """``(k, 3)`` parameter ids of the rotation increments of ``bones`` (k,) in a frame's parameters
    (``3 + 3 b + axis``, after the root translation)."""
    return 3 + 3 * np.asarray(bones, dtype=np.int64)[:, None] + np.arange(3)


def charbonnier(r, eps):
    """Penalty ``eps^2 (sqrt(1 + (r/eps)^2) - 1)`` (~ r^2/2 near 0, ~ eps |r| far) and its IRLS weight."""
    s = np.sqrt(1.0 + (r / eps) ** 2)
    return eps * eps * (s - 1.0), 1.0 / s


class Sample:
    """A fixed seeded sample of ``count`` capture points ``(N, 3)`` and normals, with their closest points on
    a state's surface found once (cached on the state): terms of several scales share one."""

    def __init__(self, points, normals, count: int, seed: int = 0):
        pick = sample(len(points), count, seed)
        self.points, self.normals = points[pick], normals[pick]

    def closest(self, state):
        """``(face, barycentric, foot)`` of the sample on ``state.surface`` (:meth:`.body.Surface.closest`)."""
        key = ("closest", self)        # the sample itself: a freed sample's id can come back
        if key not in state.cache:
            state.cache[key] = state.surface.closest(self.points)[:3]
        return state.cache[key]


class ScanToModel:
    """Capture points to the posed surface, point-to-plane along the model's face normal.

    A fixed sample of ``count`` capture points (seeded; the same every update, so energies compare),
    each matched to the closest point on the one-ring of its nearest posed vertex
    (:meth:`Body.surface`); the residual is the distance along that triangle's normal, its derivative
    the barycentric combination of the triangle's vertex Jacobians (:func:`normal_jacobian`).  Pairs whose
    capture normal points against the face normal (below ``min_cos``) or farther than ``reach`` metres are
    left out; the rest weigh by Charbonnier with ``eps`` (about the capture noise, metres).  ``weight``
    scales the energy per point (energy = weight * mean penalty * 1, so terms with other point counts
    compare); ``shared``: a :class:`Sample` to use instead of drawing one (its closest points serve every
    term on it)."""

    def __init__(self, points, normals, count: int = 5000, eps: float = 0.002, reach: float = 0.05,
                 min_cos: float = 0.2, weight: float = 1.0, seed: int = 0, shared: "Sample" = None):
        self.sample = Sample(points, normals, count, seed) if shared is None else shared
        self.points, self.normals = self.sample.points, self.sample.normals
        self.eps, self.reach, self.min_cos, self.weight = eps, reach, min_cos, weight

    def pairs(self, state):
        """``(barycentric, face, residual, kept)`` of the sample against the state's surface (cached)."""
        key = ("scan", self)           # the term itself: a freed term's id can come back
        if key not in state.cache:
            face, bary, foot = self.sample.closest(state)
            n = state.surface.face_normals[face]
            r = np.sum((self.points - foot) * n, axis=1)
            dist = np.linalg.norm(self.points - foot, axis=1)
            kept = (np.sum(n * self.normals, axis=1) >= self.min_cos) & (dist <= self.reach)
            state.cache[key] = bary, face, r, kept
        return state.cache[key]

    def energy(self, body, state) -> float:
        _, _, r, kept = self.pairs(state)
        return self._scale() * float(charbonnier(r[kept], self.eps)[0].sum())

    def linearise(self, body, state) -> Linear:
        bary, face, r, kept = self.pairs(state)
        bary, face, r = bary[kept], face[kept], r[kept]
        nJ = normal_jacobian(body, state, body.faces[face], state.surface.face_normals[face], bary)
        # residual = n . (point - foot): its derivative is minus n . d(foot)
        pen, w = charbonnier(r, self.eps)
        s = self._scale()
        A = nJ * np.sqrt(w)[:, None]
        return Linear(s * (A.T @ A), s * (-(nJ.T @ (w * r))), s * float(pen.sum()))

    def _scale(self):
        return self.weight / max(len(self.points), 1)

    def residuals(self, state):
        """``(distance along the normal (K,), kept (K,))`` of the sample: for reports and tests."""
        _, _, r, kept = self.pairs(state)
        return r, kept


def normal_jacobian(body, state, vertices, normals, weights=None):
    """``(K, P)`` derivative of ``normals[k] . sum_c weights[k, c] x(vertices[k, c])`` with the unit
    ``normals (K, 3)`` held fixed: points on the posed surface given by ``vertices (K, C)`` and their
    barycentric ``weights (K, C)`` (C = 1 and weight 1 for vertices themselves), by
    :meth:`.body.Body.combined_jacobian`."""
    if len(normals) == 0:
        return np.zeros((0, body.size))
    vertices = np.asarray(vertices).reshape(len(normals), -1)
    weights = np.ones(vertices.shape) if weights is None else weights
    return body.combined_jacobian(state.pose, vertices, weights[:, :, None] * normals[:, None, :], state.slot)


class ModelToScan:
    """Posed model vertices to the capture, point-to-plane along the capture's normal: the coverage
    term that pulls parts with no capture points on them towards the capture.  ``vertices``: the model
    vertices taking part (a spread subset); a vertex whose nearest capture point is farther than
    ``reach`` or whose normal disagrees is left out (the capture may not see it)."""

    def __init__(self, points, normals, vertices, eps: float = 0.005, reach: float = 0.15,
                 min_cos: float = 0.2, weight: float = 1.0):
        self.points, self.normals = points, normals
        self.tree = cKDTree(points)
        self.vertices = np.asarray(vertices, dtype=np.int64)
        self.eps, self.reach, self.min_cos, self.weight = eps, reach, min_cos, weight

    def pairs(self, state):
        key = ("model", self)
        if key not in state.cache:
            state.cache[key] = self._pairs(state.posed, state.surface)
        return state.cache[key]

    def _pairs(self, posed, surface):
        x = posed[self.vertices]
        dist, nearest = self.tree.query(x)
        vn = vertex_normals_at(surface, self.vertices)
        n = self.normals[nearest]
        r = np.sum((x - self.points[nearest]) * n, axis=1)
        kept = (dist <= self.reach) & (np.sum(vn * n, axis=1) >= self.min_cos)
        return n, r, kept

    def energy(self, body, state) -> float:
        _, r, kept = self.pairs(state)
        return self._scale() * float(charbonnier(r[kept], self.eps)[0].sum())

    def linearise(self, body, state) -> Linear:
        n, r, kept = self.pairs(state)
        nJ = normal_jacobian(body, state, self.vertices[kept], n[kept])
        pen, w = charbonnier(r[kept], self.eps)
        s = self._scale()
        A = nJ * np.sqrt(w)[:, None]
        return Linear(s * (A.T @ A), s * (nJ.T @ (w * r[kept])), s * float(pen.sum()))

    def _scale(self):
        return self.weight / max(len(self.vertices), 1)


def vertex_normals_at(surface, vertices):
    """Unit normals ``(n, 3)`` of the posed ``vertices``: mean of the face normals around each."""
    ring = surface.ring[vertices]
    fn = np.where((ring >= 0)[..., None], surface.face_normals[np.maximum(ring, 0)], 0.0).sum(axis=1)
    return fn / np.maximum(np.linalg.norm(fn, axis=1, keepdims=True), 1e-300)


def sample(n: int, count: int, seed: int = 0) -> np.ndarray:
    """Sorted indices of ``min(count, n)`` of ``n`` items drawn without replacement (seeded)."""
    if count <= 0 or count >= n:
        return np.arange(n)
    return np.sort(np.random.default_rng(seed).choice(n, count, replace=False))
