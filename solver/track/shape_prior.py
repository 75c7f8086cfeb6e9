"""The shape prior of model adaptation, and the lift of a vertex-space least-squares term to the rest
vertices and joint parameters.

Model-adaptive mocap dissertation §4.1.1 (Eq. 4.2) and §4.1.3 (Eq. 4.11-4.12):

    Q^shape = (1 / M V) Σ_m Σ_v ‖ L(v^train_{v,m}) − L(T_m(x_v)) ‖²

with L the uniform Laplacian of the model's triangle mesh, T_m the model being adapted (rest vertices x,
joint centres) posed in the known training pose m (held fixed), and v^train the M registered training
meshes.  A bundle holds the training poses but not the training meshes, so the targets here are the
Laplacians of the ORIGINAL (unadapted) model posed in those poses: the dissertation's prior whenever
Chapter 3 fitted its training scans exactly (then the posed model is the training mesh), and Q^shape = 0
for the unadapted model.  At most ``MAX_POSES`` training poses are used, spread out by farthest-point
sampling of the joint rotations (:func:`spread_poses`); the rest pose when there are none.

:func:`lift`: a term whose Gauss-Newton form in the posed vertex positions p (3V, metres) is
``(H_p (3V, 3V) sparse, b_p (3V,))`` (half gradient) becomes, through ``p = A x + c`` (A (V, 3, 3) per
vertex, :func:`solver.rig.skinning.affine_form`) and ``dp/dθ = J (V, 3, k)``, the blocks
``H_xx = Aᵀ H_p A``, ``H_xθ = Aᵀ H_p J``, ``H_θθ = Jᵀ H_p J``, ``g_x = Aᵀ b_p``, ``g_θ = Jᵀ b_p``.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import scipy.sparse as sp

from ..errors import ArticulaInputError
from ..geometry.mesh_graph import uniform_laplacian
from ..geometry.rotations import quat_to_rotvec
from ..rig.jacobians import dense_jacobian
from ..rig.model import Poses
from ..rig.skinning import affine_form, hybrid_skin

MAX_POSES = 8     # training poses whose Laplacians the prior keeps (spread; cost grows linearly)


def spread_poses(poses: Poses, count: int) -> np.ndarray:
    """Indices of at most ``count`` of ``poses``, spread out: the pose nearest the rest pose first, then
    repeatedly the one farthest (Euclidean norm over the non-root bones' rotation vectors, radians) from
    those chosen.  The root rotation and translation do not change a Laplacian's norm."""
    r = quat_to_rotvec(poses.rotations)[:, 1:].reshape(len(poses), -1)
    if len(r) <= count:
        return np.arange(len(r))
    chosen = [int(np.argmin(np.linalg.norm(r, axis=1)))]
    dist = np.linalg.norm(r - r[chosen[0]], axis=1)
    while len(chosen) < count:
        chosen.append(int(np.argmax(dist)))
        dist = np.minimum(dist, np.linalg.norm(r - r[chosen[-1]], axis=1))
    return np.sort(np.array(chosen))


def block_diagonal(A) -> sp.csr_matrix:
    """``(3V, 3V)`` sparse block-diagonal matrix of the 3x3 blocks ``A (V, 3, 3)``."""
    V = len(A)
    return sp.bsr_matrix((np.ascontiguousarray(A), np.arange(V), np.arange(V + 1)), shape=(3 * V, 3 * V)).tocsr()


def lift(H_p, b_p, A, J, used=None):
    """Normal-equation blocks in the rest vertices and the parameters θ (module docstring) of a term with
    ``H_p (3V, 3V)`` sparse symmetric and ``b_p (3V,)`` in the posed positions; ``A (V, 3, 3)``,
    ``J (V, 3, k)`` or None (no θ).  ``used``: the vertices the term touches (None: all), so that only
    their rows of J are multiplied.  Returns ``(H_xx (3V, 3V) csr, H_xθ (3V, k), H_θθ (k, k), g_x (3V,),
    g_θ (k,))`` (the θ blocks None without J)."""
    V = len(A)
    Ab = block_diagonal(A)
    H_xx = (Ab.T @ H_p @ Ab).tocsr()
    g_x = Ab.T @ b_p
    if J is None:
        return H_xx, None, None, g_x, None
    k = J.shape[-1]
    if used is None:
        Ju = J.reshape(3 * V, k)
        HJ = H_p @ Ju
        return H_xx, Ab.T @ HJ, Ju.T @ HJ, g_x, Ju.T @ b_p
    rows = (3 * np.asarray(used)[:, None] + np.arange(3)).ravel()
    Ju = J[used].reshape(-1, k)
    HJ = H_p[:, rows] @ Ju                                       # (3V, k): H_p J (zero rows off ``used``)
    return H_xx, Ab.T @ HJ, Ju.T @ HJ[rows], g_x, Ju.T @ b_p[rows]


@dataclasses.dataclass
class ShapePrior:
    """poses: the M training poses kept (:class:`Poses`); L: uniform Laplacian ``(V, V)`` csr of the
    model's faces; targets ``(M, V, 3)`` metres: L of the original model posed in each pose."""
    poses: Poses
    L: sp.csr_matrix
    targets: np.ndarray

    @classmethod
    def from_model(cls, model, training_poses: Poses = None, count: int = MAX_POSES, groups=None) -> "ShapePrior":
        """The prior of ``model`` (unadapted) from its ``training_poses`` (None or empty: the rest pose)."""
        if count < 1:
            raise ArticulaInputError(f"shape prior: count must be >= 1, got {count}")
        B = model.skeleton.num_bones
        if training_poses is None or len(training_poses) == 0:
            poses = Poses.identity(1, B)
        else:
            training_poses.validate(B)
            keep = spread_poses(training_poses, count)
            poses = Poses(training_poses.rotations[keep], training_poses.translations[keep],
                          training_poses.scales[keep])
        L = uniform_laplacian(model.faces, model.num_vertices)
        prior = cls(poses, L, np.zeros((len(poses), model.num_vertices, 3)))
        prior.targets = prior.laplacians(hybrid_skin(model, poses, groups))
        return prior

    @property
    def num_poses(self) -> int:
        return len(self.poses)

    def laplacians(self, posed) -> np.ndarray:
        """L applied to every frame of ``posed (M, V, 3)``."""
        M, V = posed.shape[:2]
        return (self.L @ posed.transpose(1, 0, 2).reshape(V, 3 * M)).reshape(V, M, 3).transpose(1, 0, 2)

    def residuals(self, model, groups=None) -> np.ndarray:
        """``(M, V, 3)`` metres: ``L(T_m(x)) − target_m`` for ``model`` (the adapted rest vertices and
        joints) posed in the prior's poses; ``groups`` must hold the model's rest vertices."""
        return self.laplacians(hybrid_skin(model, self.poses, groups)) - self.targets

    def value(self, model, groups=None) -> float:
        """Q^shape (m², Eq. 4.11-4.12): the mean over poses and vertices of the squared residual norms."""
        r = self.residuals(model, groups)
        return float(np.einsum("mvi,mvi->", r, r)) / r.shape[0] / r.shape[1]

    def system(self, model, groups, num_heads: int):
        """Gauss-Newton blocks of Q^shape (:func:`lift`, summed over the poses) in the rest vertices and
        the joint centres of bones 1..B-1 (``num_heads`` = 3 (B-1) columns; 0: vertices only).  Returns
        ``(H_xx, H_xh, H_hh, g_x, g_h, value)``, all with the factor 1 / (M V) of Q^shape; g is half
        the gradient."""
        M, V = self.num_poses, model.num_vertices
        G = sp.kron((self.L.T @ self.L).tocsr(), sp.identity(3), format="csr")
        A = affine_form(model, self.poses, groups)[0]
        H_xx, g_x, value = sp.csr_matrix((3 * V, 3 * V)), np.zeros(3 * V), 0.0
        H_xh, H_hh, g_h = np.zeros((3 * V, num_heads)), np.zeros((num_heads, num_heads)), np.zeros(num_heads)
        cols = {("head", b): 3 * (b - 1) for b in range(1, model.skeleton.num_bones)}
        for m in range(M):
            one = self.poses.take(m)
            if num_heads:
                posed, J = dense_jacobian(model, one, cols, num_heads, groups, heads=True)
                posed, J = posed[0], J[0]
            else:
                posed, J = hybrid_skin(model, one, groups)[0], None
            r = self.L @ posed - self.targets[m]
            value += float(np.sum(r * r))
            parts = lift(G, (self.L.T @ r).ravel(), A[m], J)
            H_xx, g_x = H_xx + parts[0], g_x + parts[3]
            if num_heads:
                H_xh, H_hh, g_h = H_xh + parts[1], H_hh + parts[2], g_h + parts[4]
        c = 1.0 / (M * V)
        return c * H_xx, c * H_xh, c * H_hh, c * g_x, c * g_h, c * value
