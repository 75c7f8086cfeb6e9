"""The template's surface adapted to the person's (depth-camera tracking dissertation ch. 6 §5.5,
Eq. 6.18-6.20; ch. 5 §4.5): every vertex moves along its rest normal only.  After a frame's pose has
converged, each paired model point's observed target is mapped back to the rest pose through the
inverse of its blended skinning transform and its offset along the normal is averaged over the frames,
weighted by 1/z^2 (depth noise grows with z^2); every ``surface_every`` frames the displacements of all
template vertices solve the sparse system of Eq. 6.20: data where a point has been seen, edge smoothness
``EDGE_WEIGHT`` (d_i - d_j)^2 and ``RIDGE`` d^2.

The tracker follows a subset of the vertices, so the smoothness term carries the offsets to the vertices
in between; its weight is set for that spacing (the dissertation's lambda_e = 0.1 goes with every vertex
having data).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import spsolve

from ..geometry.mesh_graph import adjacency
from ..geometry.normals import vertex_normals
from ..rig.kinematics import forward_kinematics
from ..rig.model import Model
from ..tracking.blend_body import linear_blend_weights

EDGE_WEIGHT = 2.0        # lambda_e of Eq. 6.20 for the tracker's subset spacing (ours)
RIDGE = 0.01             # lambda_d: pull of unseen vertices to no displacement
MAX_OFFSET_M = 0.05      # offsets farther than this along the normal are not averaged in


class SurfaceFit:
    """Running per-vertex offsets along the rest normals of ``model`` (the undisplaced adapted body)."""

    def __init__(self, model: Model):
        self.model = model
        self.normals = vertex_normals(model.rest_vertices, model.faces)
        self.weights = linear_blend_weights(model)
        V = model.num_vertices
        self.sum_w, self.sum_wd = np.zeros(V), np.zeros(V)
        A = adjacency(model.faces, V)
        self.graph = EDGE_WEIGHT * (sp.diags(np.asarray(A.sum(axis=1)).ravel()) - A) + RIDGE * sp.identity(V)

    def add_frame(self, ids, targets, pose, camera_centre) -> None:
        """Observed ``targets`` (n, 3) of the vertices ``ids`` (n,) at ``pose`` (one frame)."""
        if len(ids) == 0:
            return
        Rm, tm = forward_kinematics(self.model.skeleton, pose)
        w = self.weights[ids]
        A = np.einsum("nb,brc->nrc", w, Rm[0])
        t = w @ tm[0]
        rest = np.linalg.solve(A, (targets - t)[..., None])[..., 0]
        off = ((rest - self.model.rest_vertices[ids]) * self.normals[ids]).sum(axis=1)
        z2 = ((targets - camera_centre) ** 2).sum(axis=1)
        keep = np.abs(off) <= MAX_OFFSET_M
        np.add.at(self.sum_w, ids[keep], 1.0 / z2[keep])
        np.add.at(self.sum_wd, ids[keep], off[keep] / z2[keep])

    def displacements(self) -> np.ndarray:
        """(V,) offsets along the rest normals (metres) solving Eq. 6.20 for the frames seen so far."""
        seen = (self.sum_w > 0).astype(float)
        mean = np.divide(self.sum_wd, self.sum_w, out=np.zeros_like(self.sum_wd), where=self.sum_w > 0)
        M = (self.graph + sp.diags(seen)).tocsc()
        return spsolve(M, seen * mean)

    def displaced(self) -> Model:
        """The model with its rest vertices moved by :meth:`displacements`."""
        m = self.model
        verts = m.rest_vertices + self.displacements()[:, None] * self.normals
        return Model(verts, m.faces, m.skeleton, m.anchor, m.twist_weights, m.swing_weights)
