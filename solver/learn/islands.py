"""Separate mesh islands (eyes, teeth, buttons of a real scan): the rig is learned from the largest
island and every other island is carried rigidly by the bone nearest to it.

:func:`split_islands` finds the islands of ``faces`` and refuses islands too large to be accessories;
:func:`carry_islands` extends the model learned on the main island to every vertex: an island's anchor
is a bone of the main-island vertices nearest to it in the rest scan, its twist/swing weights
are zero (so it moves exactly with that bone's chain map), and its rest vertices are the least-squares
fit of that rigid motion to the island's positions in all scans.  Vertex order and faces stay those of
the input.  "Nearest" is in space and motion: the bones that the main-island vertices nearest to the
island are anchored to or weighted on compete, and the one whose motion fits the island best carries it.
"""
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from ..errors import ArticulaInputError
from ..geometry.mesh_graph import components
from ..rig.kinematics import forward_kinematics
from ..rig.model import Model

MAX_ISLAND_FRACTION = 0.5   # an island with this fraction of the largest island's vertices is a second body
NEAREST = 16                # the bones of this many main-island vertices nearest each island vertex compete


@dataclass
class Islands:
    """The input mesh split into its largest island ``main (Vm,)`` (sorted vertex indices) with its faces
    renumbered ``main_faces (Fm,3)``, and the other islands ``others`` (list of vertex index arrays,
    largest first) of a mesh of ``num_vertices`` vertices with ``faces (F,3)``."""
    num_vertices: int
    faces: np.ndarray
    main: np.ndarray
    main_faces: np.ndarray
    others: list

    @property
    def carried(self) -> int:
        """Vertices outside the main island."""
        return int(sum(len(o) for o in self.others))


def split_islands(faces, num_vertices) -> Islands:
    """:class:`Islands` of a mesh with triangles ``faces (F,3)`` over ``num_vertices`` vertices (every vertex
    in some triangle).  Raises :class:`ArticulaInputError` if a second island holds at least
    MAX_ISLAND_FRACTION of the largest one's vertices (two bodies: learn each on its own)."""
    n, labels = components(faces, num_vertices)
    sizes = np.bincount(labels, minlength=n)
    order = np.argsort(-sizes, kind="stable")
    if n > 1 and sizes[order[1]] >= MAX_ISLAND_FRACTION * sizes[order[0]]:
        raise ArticulaInputError(
            f"mesh: {n} disconnected islands of {sizes[order[:5]].tolist()}{'...' if n > 5 else ''} vertices; "
            f"the second is {sizes[order[1]] / sizes[order[0]]:.0%} of the largest, too large to be carried "
            f"rigidly (islands under {MAX_ISLAND_FRACTION:.0%} are): learn each body on its own or join them")
    main = np.flatnonzero(labels == order[0])
    index = np.full(num_vertices, -1, dtype=np.int64)
    index[main] = np.arange(len(main))
    main_faces = index[faces[np.all(index[faces] >= 0, axis=1)]].astype(np.int32)
    return Islands(num_vertices, np.asarray(faces, np.int32), main, main_faces,
                   [np.flatnonzero(labels == c) for c in order[1:]])


def carry_islands(model: Model, poses, scans, rest_scan, islands: Islands):
    """The model over all vertices from ``model`` learned on ``islands.main`` posed by ``poses`` (one per
    scan of ``scans (M,V,3)`` metres, all vertices); ``rest_scan (V,3)`` places the islands relative to the
    main island.  Returns ``(full Model, report dict)``: per island its vertex count, the bone carrying it
    and the RMS (mm) of that bone's rigid motion against the island's scanned positions."""
    if not islands.others:
        return model, dict(count=0, vertices=0, islands=[])
    main, V, B = islands.main, islands.num_vertices, model.skeleton.num_bones
    tree = cKDTree(rest_scan[main])
    Rm, tm = forward_kinematics(model.skeleton, poses)                  # (M,B,3,3), (M,B,3)
    rest = np.zeros((V, 3))
    anchor = np.zeros(V, np.int32)
    twist, swing = np.zeros((V, B), np.float32), np.zeros((V, B), np.float32)
    rest[main], anchor[main], twist[main], swing[main] = (model.rest_vertices, model.anchor,
                                                          model.twist_weights, model.swing_weights)
    rows = []
    for members in islands.others:
        dist, nearest = tree.query(rest_scan[members], k=min(NEAREST, len(main)))
        near = np.unique(nearest)
        bones = np.union1d(model.anchor[near], np.flatnonzero((model.twist_weights[near] > 0).any(0)
                                                              | (model.swing_weights[near] > 0).any(0)))
        fits = [_rigid_fit(Rm[:, b], tm[:, b], scans[:, members]) for b in bones]
        best = int(np.argmin([rms for _, rms in fits]))
        b, (x, rms) = int(bones[best]), fits[best]
        rest[members], anchor[members] = x, b
        rows.append(dict(vertices=int(len(members)), bone=model.skeleton.names[b], rms_mm=rms * 1e3,
                         distance_mm=float(dist.min() * 1e3)))
    full = Model(rest, islands.faces, model.skeleton, anchor, twist, swing)
    return full, dict(count=len(rows), vertices=islands.carried, islands=rows)


def _rigid_fit(R, t, points):
    """``(rest positions (P,3), RMS metres)`` of ``points (M,P,3)`` carried by the maps ``R``, ``t``."""
    x = rigid_rest_positions(R, t, points)
    posed = np.einsum("mij,vj->mvi", R, x) + t[:, None]
    return x, float(np.sqrt(np.mean(np.sum((posed - points) ** 2, axis=2))))


def rigid_rest_positions(R, t, points):
    """Rest positions ``(P,3)`` minimising ``Σ_m ‖R_m x + t_m − points_m‖²`` for the maps ``R (M,3,3)``,
    ``t (M,3)`` (rotations, possibly scaled) and ``points (M,P,3)``."""
    A = np.einsum("mji,mjk->ik", R, R)
    rhs = np.einsum("mji,mpj->pi", R, points - t[:, None])
    return np.linalg.solve(A, rhs.T).T
