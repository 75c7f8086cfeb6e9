"""Step (a) of the alternation (joints + poses) on a well-spread vertex subset, weighted so that its
objective estimates the full one.

The joints and poses are ``5(B−1) + M(3B+3)`` numbers, which a few thousand well-spread vertices pin as
well as all of them, while the cost of an LM iteration grows with the vertices.  So step (a) works on

* seeds S: a cell subsample of the rest mesh (:func:`solver.learn.segmentation.grid_sample`), and
  U = S ∪ the one-ring of S (the vertices the seeds' Laplacian rows need);
* ``Q_U = Σ_{u∈U} w_u ‖p_u − s_u‖² + α Σ_{s∈S} ω_s ‖(L p)_s − (L s)_s‖²`` with ``w_u`` the number of mesh
  vertices whose nearest U vertex (rest positions) is u and ``ω_s`` the vertices of s's cell: both sum
  to V, so Q_U estimates Q (m²) and the symmetry weight λ and joint prior κ keep their meaning.

The weights and the rest shape are still solved on all vertices, and :func:`solver.learn.pipeline.
alternation_round` keeps the step only if the full E does not increase.  docs/learn_rig_solver.md
("Doing less work") has the measurements.
"""
import copy

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from .joints_poses import JointPoseProblem, gradient_blocks
from .objective import RigObjective
from .segmentation import grid_sample

MIN_RATIO = 4.0     # a subset only for meshes of more than this many times its size: MakeHuman 13,380 v
                    # with 3,625 learned in 35.6 s (step (a) 1.8 s a round) and on all vertices in 30.6 s


class WeightedObjective(RigObjective):
    """:class:`RigObjective` of a vertex subset: data rows weighted by ``data_weights (U,)`` (vertices
    represented), Laplacian rows ``L (U,U)`` already carrying √ω (rows of non-seeds empty)."""

    def __init__(self, scans, L, alpha, data_weights):
        super().__init__(scans, L, alpha)
        self.data_weights = np.asarray(data_weights, dtype=np.float64)

    def value(self, posed):
        """Q_U for posed subset vertices ``(M,U,3)`` (m²)."""
        d, l = self.residuals(posed)
        return float(np.einsum("mvi,mvi,v->", d, d, self.data_weights) + self.alpha * np.sum(l * l))


class VertexSubset:
    """The subset of step (a): ``vertices (U,)`` sorted mesh indices, ``data_weights (U,)``, ``lap (U,U)``
    csr Laplacian rows of the seeds times √ω, ``seeds`` (count); problems per α are cached."""

    def __init__(self, vertices, data_weights, lap, seeds):
        self.vertices, self.data_weights, self.lap, self.seeds = vertices, data_weights, lap, seeds
        self._problems = {}

    def model(self, model):
        """``model`` restricted to the subset (a shallow copy sharing the skeleton)."""
        sub = copy.copy(model)
        U = self.vertices
        sub.rest_vertices, sub.anchor = model.rest_vertices[U], model.anchor[U]
        sub.twist_weights, sub.swing_weights = model.twist_weights[U], model.swing_weights[U]
        sub.faces = np.zeros((0, 3), np.int32)
        return sub

    def problem(self, problem):
        """The :class:`JointPoseProblem` of the subset for the full ``problem`` (same α, pairs, λ, prior)."""
        key = id(problem)
        if key not in self._problems:
            self._problems[key] = (problem, JointPoseProblem(self.objective(problem.objective), problem.sym_pairs,
                                                             problem.lam, prior_heads=problem.prior_heads,
                                                             kappa=problem.kappa))
        return self._problems[key][1]

    def correction(self, model, poses, problem, fix_joints):
        """``(c_s, c_o)``: the gradient of the full ``problem``'s Q at ``(model, poses)`` minus that of the
        subset's (:func:`solver.learn.joints_poses.gradient_blocks`): with it the subset's LM takes the full
        gradient and the subset's curvature (:func:`solver.learn.joints_poses.optimise_joints_and_poses`),
        and stops where the full problem does instead of at the subset's own minimum."""
        full = gradient_blocks(model, poses, problem.objective, own_only=fix_joints)
        sub = gradient_blocks(self.model(model), poses, self.problem(problem).objective, own_only=fix_joints)
        return full[0] - sub[0], full[1] - sub[1]

    def objective(self, objective):
        """The :class:`WeightedObjective` of the subset for the full :class:`RigObjective` ``objective``."""
        return WeightedObjective(objective.scans[:, self.vertices], self.lap, objective.alpha, self.data_weights)


def vertex_subset(rest, L, target):
    """:class:`VertexSubset` of about ``target`` vertices (U) of the mesh with rest vertices ``rest (V,3)``
    and uniform Laplacian ``L (V,V)``; None when ``target`` is 0 or the mesh has at most MIN_RATIO × target
    vertices (then the subset saves little)."""
    V = len(rest)
    if target <= 0 or V <= MIN_RATIO * target:
        return None
    L = sp.csr_matrix(L)
    degree = max(L.nnz / V, 2.0)                  # a row: the vertex and its one-ring
    n = max(int(target / degree), 1)
    for _ in range(2):                            # one correction for the rings' overlap
        seeds, cell = grid_sample(rest, n)
        U = np.unique(L[seeds].indices)
        n = max(int(n * target / len(U)), 1)
    omega = np.bincount(cell, minlength=len(seeds)).astype(np.float64)
    _, nearest = cKDTree(rest[U]).query(rest)
    w = np.bincount(nearest, minlength=len(U)).astype(np.float64)
    rows = np.searchsorted(U, seeds)              # seed i's row of the subset Laplacian, times √ω_i
    put = sp.csr_matrix((np.sqrt(omega), (rows, np.arange(len(seeds)))), shape=(len(U), len(seeds)))
    lap = (put @ L[seeds][:, U]).tocsr()          # every column of a seed's row is in U
    lap.eliminate_zeros()
    lap.sort_indices()
    return VertexSubset(U, w, lap, len(seeds))
