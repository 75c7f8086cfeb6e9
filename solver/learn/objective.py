"""The rig-learning objective (dissertation (model-adaptive mocap) §3.3, Eq. 3.19-3.20).

``Q = Σ_m Σ_v ‖s_m,v − p_m,v‖² + α ‖L(s_m)_v − L(p_m)_v‖²`` with s the scans, p the posed model
(``hybrid_skin``), L the uniform Laplacian of the shared topology.  Units: m² (positions in metres).

What α means: both terms are squared lengths, so α is dimensionless; it weighs the mismatch of the
*differential coordinates* (a vertex minus the mean of its one-ring, i.e. local shape detail of the
size of an edge) against the absolute position error.  α = 100 (the thesis' value for metre-scale
human scans) makes a 1 mm error of the local shape cost as much as a 10 mm absolute offset, so the rest
mesh and weights follow the scans' local shape closely while absolute positions may deviate where
the kinematic model cannot explain them.
"""
import numpy as np


class RigObjective:
    """Scans (M,V,3), their Laplacians, α and the symmetry weight λ; evaluates Q for posed vertices."""

    def __init__(self, scans, L, alpha, lam=0.0):
        self.scans = np.asarray(scans, dtype=np.float64)
        self.L = L
        self.alpha = float(alpha)
        self.lam = float(lam)
        self.scan_lap = self.laplacian(self.scans)

    def laplacian(self, P):
        """L applied to every frame of ``P (M,V,3)``."""
        V = P.shape[1]
        return (self.L @ P.transpose(1, 0, 2).reshape(V, -1)).reshape(V, P.shape[0], 3).transpose(1, 0, 2)

    def residuals(self, posed):
        """``(data (M,V,3), laplacian (M,V,3))`` residuals p − s and L(p) − L(s) (unweighted)."""
        return posed - self.scans, self.laplacian(posed) - self.scan_lap

    def value(self, posed):
        """Q for posed vertices ``(M,V,3)`` (m²)."""
        d, l = self.residuals(posed)
        return float(np.sum(d * d) + self.alpha * np.sum(l * l))

    def per_vertex_data(self, posed):
        """Squared data residual per vertex summed over scans ``(V,)``."""
        d = posed - self.scans
        return np.einsum("mvi,mvi->v", d, d)
