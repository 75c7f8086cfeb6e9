"""Mesh connectivity and the uniform (umbrella) Laplacian of the model-adaptive mocap dissertation §3.3 (Eq. 3.20).

``L(v) = v − (1/|N(v)|) Σ_{n∈N(v)} v_n`` with N(v) the one-ring of the triangle mesh.  As a sparse
matrix ``L = I − D⁻¹ A`` (A = vertex adjacency, D = degrees) acting on ``(V,3)`` positions.  L has
no units of its own: applied to positions in metres it gives metres.
"""
import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components


def edges_of(faces):
    """Unique undirected edges ``(E,2)`` int64 (``i < j``) of triangles ``faces (F,3)``, in lexicographic
    order (unique codes ``i·n + j``: 1-D, several times faster than ``np.unique(axis=0)``)."""
    f = np.asarray(faces, dtype=np.int64)
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]], axis=0)
    e = np.sort(e, axis=1)
    e = e[e[:, 0] != e[:, 1]]
    if len(e) == 0:
        return e.reshape(0, 2)
    n = int(e.max()) + 1
    code = np.unique(e[:, 0] * n + e[:, 1])
    return np.stack([code // n, code % n], axis=1)


def adjacency(faces, n_vertices):
    """Symmetric 0/1 vertex adjacency ``(V,V)`` CSR matrix."""
    e = edges_of(faces)
    data = np.ones(2 * len(e))
    A = sp.coo_matrix((data, (np.r_[e[:, 0], e[:, 1]], np.r_[e[:, 1], e[:, 0]])),
                      shape=(n_vertices, n_vertices)).tocsr()
    A.data[:] = 1.0
    return A


def uniform_laplacian(faces, n_vertices):
    """Uniform Laplacian ``L = I − D⁻¹A`` as ``(V,V)`` CSR.  Isolated vertices get the row ``L(v) = v``
    (no neighbours; learning refuses such meshes anyway)."""
    A = adjacency(faces, n_vertices)
    deg = np.asarray(A.sum(axis=1)).ravel()
    inv = np.where(deg > 0, 1.0 / np.maximum(deg, 1), 0.0)
    return (sp.identity(n_vertices, format="csr") - sp.diags(inv) @ A).tocsr()


def components(faces, n_vertices):
    """``(count, labels (V,))`` of the connected components of the mesh's vertex graph."""
    n, lab = connected_components(adjacency(faces, n_vertices), directed=False)
    return n, lab


def kron3(M):
    """``M ⊗ I₃``: acts on positions flattened as ``x.reshape(-1)`` (x, y, z of a vertex adjacent)."""
    return sp.kron(sp.csr_matrix(M), sp.identity(3), format="csr")
