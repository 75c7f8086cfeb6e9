"""What the weight step keeps between evaluations: posed vertices, Laplacian residuals and each vertex's
completed square (:class:`State`), and which evaluations a change invalidates (:class:`Tracker`).

With everything but vertex v fixed, Q depends on v's posed positions only through its data term and the
Laplacian rows that contain it; completing the square, ``Q(p') = κ_v Σ_m ‖p'_m − g_v,m‖² + const`` with
``κ_v = 1 + α Σ_n L[n,v]²`` and ``g_v = (s_v − α[(Lᵀ r)_v − (Σ_n L[n,v]²) p_v]) / κ_v`` (r = L p − L s),
so the exact gain of moving v alone from p to p' is ``κ_v Σ_m (‖p_m − g_m‖² − ‖p'_m − g_m‖²)``."""
import numpy as np

from ...rig.skinning import hybrid_skin


class State:
    """Posed vertices, Laplacian residuals and the per-vertex completion-of-square quantities.
    Stored vertex-major ``(V,M,3)`` (``Pv``, ``Rv``, ``Sv``) so one vertex set is one row block and the
    Laplacian products are single sparse × dense products; ``P`` and ``R`` are ``(M,V,3)`` views."""

    def __init__(self, model, poses, objective):
        self.obj = objective
        L = objective.L.tocsr()
        self.LT = L.T.tocsr()
        self.Lc = L.tocsc()
        self.colsq = np.asarray(L.multiply(L).sum(axis=0)).ravel()     # Σ_n L[n,v]²
        self.kappa = 1.0 + objective.alpha * self.colsq
        P = hybrid_skin(model, poses)
        self.Pv = np.ascontiguousarray(P.transpose(1, 0, 2))
        self.Rv = np.ascontiguousarray((objective.laplacian(P) - objective.scan_lap).transpose(1, 0, 2))
        self.Sv = np.ascontiguousarray(objective.scans.transpose(1, 0, 2))

    P = property(lambda self: self.Pv.transpose(1, 0, 2), doc="posed vertices (M,V,3) (view)")
    R = property(lambda self: self.Rv.transpose(1, 0, 2), doc="Laplacian residuals L p − L s (M,V,3) (view)")

    def targets(self, idx):
        """g ``(n,M,3)`` for vertices idx."""
        n, V = len(idx), len(self.Pv)
        LtR = (self.LT[idx] @ self.Rv.reshape(V, -1)).reshape(n, -1, 3)
        a = self.obj.alpha
        return (self.Sv[idx] - a * (LtR - self.colsq[idx, None, None] * self.Pv[idx])) \
            / self.kappa[idx, None, None]

    def update(self, idx, P_new):
        """Set the posed positions ``(n,M,3)`` of vertices idx; residual rows of their one-ring follow."""
        d = (P_new - self.Pv[idx]).reshape(len(idx), -1)
        self.Pv[idx] = P_new
        cols = self.Lc[:, idx].tocsr()
        rows = np.flatnonzero(np.diff(cols.indptr))
        R = self.Rv.reshape(len(self.Pv), -1)
        R[rows] += cols[rows] @ d


class DataTargets:
    """A stand-in for :class:`State` whose targets ignore the Laplacian term (κ = 1, g = the scan vertex):
    candidate evaluation then proposes each vertex's best data fit, independently of its neighbours."""

    def __init__(self, state):
        self.Pv = state.Pv
        self.kappa = np.ones_like(state.kappa)
        self.Sv = state.Sv

    def targets(self, idx):
        """g ``(n,M,3)`` for vertices idx: their scan vertices."""
        return self.Sv[idx]


class Tracker:
    """Which evaluations a state change invalidates.

    ``stale (V,)``: the vertex's data-only proposal (:func:`joint_move`) must be recomputed — it depends on
    the vertex's own anchor and weights only.  ``dirty (V,)``: the vertex's BCD evaluation may differ from
    its last one — its targets g depend on the posed positions of its two-ring (``ring2``, CSR pattern),
    its candidates on its own state; a vertex that is not dirty had no improving candidate last time and
    would have none now.  ``proposal``: the cached joint-move proposals."""

    def __init__(self, model, M, ring2=None):
        V = model.num_vertices
        self.ring2 = ring2
        self.dirty = np.ones(V, dtype=bool)
        self.stale = np.ones(V, dtype=bool)
        self.proposal = (np.zeros(V), np.empty(V, np.int32), np.empty_like(model.twist_weights),
                         np.empty_like(model.swing_weights), np.empty((V, M, 3)))

    def changed(self, idx):
        """Vertices idx changed state."""
        self.stale[idx] = True
        self.dirty[idx] = True                       # also when a vertex has no Laplacian row
        if self.ring2 is not None and len(idx):
            self.dirty[self.ring2[idx].indices] = True

