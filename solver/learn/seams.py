"""Vertices split at seams, welded while the rig is learned.

Meshes exported from animation packages (FBX, glTF, game assets) split a vertex into copies wherever
its UV or normal changes, so the surface falls apart into islands that are one body in every scan.
Learning such a mesh as islands would learn from the largest piece and carry the rest rigidly
(:mod:`solver.learn.islands`).  Copies that coincide in every scan (within WELD_TOL of the mesh's
size) are one vertex for the learner: it learns on the welded mesh and every copy gets its vertex's
model (rest position, anchor, weights) back, with the input's faces and vertex order.  The surface is
the same either way; only the error statistics count each welded vertex once.
"""
from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from ..rig.model import Model

WELD_TOL = 1e-6     # copies closer than this × the bounding-box diagonal, in every scan, are one vertex


@dataclass
class Seams:
    """``index (V,)``: welded vertex of each input vertex; ``first (W,)``: one input vertex of each."""
    index: np.ndarray
    first: np.ndarray

    @classmethod
    def of(cls, scans, tol=WELD_TOL):
        """The seams of finite ``scans (M,V,3)`` (any float type; only the candidate pairs are converted),
        or None when no two vertices coincide in every scan."""
        rest = np.asarray(scans[0], dtype=np.float64)
        eps = tol * max(float(np.linalg.norm(np.ptp(rest, axis=0))), 1e-300)
        pairs = cKDTree(rest).query_pairs(eps, output_type="ndarray")
        if len(pairs):
            a, b = (np.asarray(scans[:, pairs[:, i]], dtype=np.float64) for i in (0, 1))
            pairs = pairs[np.abs(a - b).max(axis=(0, 2)) <= eps]
        if not len(pairs):
            return None
        V = rest.shape[0]
        graph = sp.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(V, V))
        _, label = connected_components(graph, directed=False)
        _, first, index = np.unique(label, return_index=True, return_inverse=True)
        return cls(index.ravel().astype(np.int64), first.astype(np.int64))

    @property
    def welded(self) -> int:
        """Input vertices merged into another."""
        return len(self.index) - len(self.first)

    def weld(self, scans, faces):
        """``(scans (M,W,3), faces (F',3))`` of the welded mesh; triangles that collapse are dropped."""
        f = self.index[np.asarray(faces)]
        keep = (f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2])
        return scans[:, self.first], f[keep].astype(np.int32)

    def expand_model(self, model, faces):
        """The learned ``model`` of the welded mesh for every input vertex, with the input ``faces``."""
        i = self.index
        return Model(model.rest_vertices[i], faces, model.skeleton, model.anchor[i],
                     model.twist_weights[i], model.swing_weights[i])

    def expand(self, result, faces):
        """A :class:`solver.learn.pipeline.LearnResult` of the welded mesh for the input mesh."""
        distances = None if result.scan_distances is None else result.scan_distances[:, self.index]
        report = dict(result.report, welded_vertices=self.welded)
        return replace(result, model=self.expand_model(result.model, faces), report=report,
                       scan_distances=distances)
