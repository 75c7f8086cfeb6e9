"""The body evaluated fast: a fixed subset of a model's vertices under linear blend skinning, posed by the
model's own kinematic chain, with the lever arms of the depth-camera tracking dissertation (ch. 3,
Eq. 3.24; ch. 5, Eq. 5.2): a joint's rotation increment turns its whole subtree about the joint's current
position, so a point's derivative is a cross product with its lever arm and the normal equations reduce
to one Gram matrix of lever arms (:mod:`.normal_equations`).

Parameters are those of :class:`.body.Body` (``P = 3 + 3B``: the root translation in metres, then one
rotation increment per bone in the bone's local axes, applied on the right, ``q_b <- q_b exp(delta_b)``),
so the priors of :mod:`.priors` and the solver of :mod:`.lm` serve both bodies.  Internally the
increment of bone b is the world-axes rotation vector ``omega_b = A_b delta_b`` (:meth:`BlendBody.axes`).

Skinning weights: the hybrid skin's swing weights on the anchor's children and the remainder on the
anchor (the linear-blend reading of the swing/twist skin; twist ramps are not modelled), at most
``MAX_INFLUENCES`` per vertex.  Joint positions come from the exact forward kinematics, so fitted poses
are poses of the model itself.
"""
from __future__ import annotations

import numpy as np

from ..errors import ArticulaInputError
from ..geometry.normals import vertex_normals
from ..rig.jacobians import apply_pose_increment
from ..rig.kinematics import forward_kinematics
from ..rig.model import Model, Poses
from .normal_equations import cross

MAX_INFLUENCES = 4
SUBSET_SIZE = 1500      # model points used for correspondences (the dissertation's ch. 6 samples ~1000)


def linear_blend_weights(model: Model) -> np.ndarray:
    """(V, B) linear-blend weights of the swing/twist model: swing weights on the anchor's children, the
    remainder (1 - sum) on the anchor; rows sum to 1."""
    w = np.asarray(model.swing_weights, dtype=np.float64).copy()
    rows = np.arange(model.num_vertices)
    w[rows, model.anchor] += 1.0 - w.sum(axis=1)
    return w


def ancestor_table(parents) -> np.ndarray:
    """(B, B) bool: ``[k, j]`` is True when bone j is bone k or one of its ancestors."""
    B = len(parents)
    table = np.eye(B, dtype=bool)
    for k in range(1, B):
        table[k] |= table[parents[k]]
    return table


def spread_subset(vertices: np.ndarray, count: int, seed: int = 0) -> np.ndarray:
    """About ``count`` vertex ids spread evenly over the surface: one random vertex per occupied cell of
    a grid whose cell size gives roughly ``count`` cells (sorted ids; deterministic for a seed)."""
    n = len(vertices)
    if count >= n:
        return np.arange(n)
    rng = np.random.default_rng(seed)
    order = rng.permutation(n)
    lo = vertices.min(0)
    ids = order
    for cell in np.geomspace(np.ptp(vertices, axis=0).max() / 4, 1e-4, 60):
        keys = np.floor((vertices[order] - lo) / cell).astype(np.int64)
        _, first = np.unique(keys, axis=0, return_index=True)
        if len(first) >= count:
            ids = order[first]
            break
    return np.sort(rng.choice(ids, size=min(count, len(ids)), replace=False))


class PosedBody:
    """One pose of the body: ``pose`` (one frame), ``points`` (M, 3) and ``normals`` (M, 3) of the
    subset, ``per_bone`` (M, I, 3) each vertex moved by each of its influences, ``joints`` (B, 3) posed
    heads, ``world`` (B, 3, 3) world rotations of the parts (scale removed).  The normals are computed
    when first asked for (most posings need only the points)."""

    def __init__(self, pose, points, per_bone, joints, world, normals_of):
        self.pose, self.points, self.per_bone, self.joints, self.world = pose, points, per_bone, joints, world
        self._normals_of, self._normals = normals_of, None

    @property
    def normals(self) -> np.ndarray:
        if self._normals is None:
            self._normals = self._normals_of()
        return self._normals


class BlendBody:
    """A subset of ``model``'s vertices with compact linear-blend weights (see the module docstring).

    ``ids`` (M,) vertex ids; ``rest`` / ``rest_normals`` (M, 3); ``bones`` / ``weights`` (M, I) the
    influences; ``main_bone`` (M,) the bone of largest weight; ``chain`` (M, B) the weight of each
    vertex's influences in each bone's subtree (beta of Eq. 3.26)."""

    def __init__(self, model: Model, ids=None, count: int = SUBSET_SIZE, seed: int = 0):
        verts = np.asarray(model.rest_vertices, dtype=np.float64)
        if ids is None:
            ids = spread_subset(verts, count, seed)
        ids = np.asarray(ids, dtype=np.int64)
        if len(ids) < 10:
            raise ArticulaInputError(f"the model has {len(ids)} usable vertices; tracking needs at least 10")
        self.model = model
        self.ids = ids
        self.rest = verts[ids]
        self.rest_normals = vertex_normals(verts, model.faces)[ids] if len(model.faces) else np.zeros_like(self.rest)
        w = linear_blend_weights(model)[ids]
        order = np.argsort(-w, axis=1, kind="stable")[:, :MAX_INFLUENCES]
        top = np.take_along_axis(w, order, axis=1)
        self.bones = order.astype(np.int64)
        self.weights = top / top.sum(axis=1, keepdims=True)
        self.main_bone = order[:, 0]
        self.ancestors = ancestor_table(model.skeleton.parents)
        self.ancestors_f = self.ancestors.astype(np.float64)
        self.chain = np.einsum("mi,mib->mb", self.weights, self.ancestors_f[self.bones])
        self.num_bones = model.skeleton.num_bones
        self.size = 3 + 3 * self.num_bones
        self.columns = np.r_[0:3, 4:4 + 3 * self.num_bones]     # of the rig's full layout (no scale)

    def pose(self, poses: Poses) -> PosedBody:
        """The subset posed by one frame of ``poses``."""
        Rm, tm = forward_kinematics(self.model.skeleton, poses)
        Rm, tm = Rm[0], tm[0]
        B = len(Rm)
        flat = Rm.transpose(2, 0, 1).reshape(3, 3 * B)                  # [c, (b, r)] = Rm[b, r, c]
        moved = (self.rest @ flat).reshape(-1, B, 3) + tm[None]         # (M, B, 3) every bone's map
        rows = np.arange(len(self.rest))[:, None]
        per_bone = moved[rows, self.bones]                              # (M, I, 3)
        points = np.einsum("mi,mir->mr", self.weights, per_bone)
        heads = self.model.skeleton.heads
        joints = np.einsum("brc,bc->br", Rm, heads) + tm
        world = Rm / poses.scales[0]

        def normals():
            turned = (self.rest_normals @ flat).reshape(-1, B, 3)
            return np.einsum("mi,mir->mr", self.weights, turned[rows, self.bones])
        return PosedBody(poses, points, per_bone, joints, world, normals)

    def axes(self, posed: PosedBody) -> np.ndarray:
        """(B, 3, 3) ``A_b``: bone b's local increment ``delta_b`` turns its subtree by the world rotation
        vector ``A_b delta_b`` (its world rotation times its rest frame)."""
        return posed.world @ self.model.skeleton.frames

    def world_step(self, posed: PosedBody, step) -> np.ndarray:
        """(3 + 3B,) the parameter ``step`` with each bone's increment turned into world axes."""
        step = np.asarray(step, dtype=np.float64)
        omega = np.einsum("bij,bj->bi", self.axes(posed), step[3:].reshape(-1, 3))
        return np.concatenate([step[:3], omega.ravel()])

    def lever_arms(self, posed: PosedBody, rows=None) -> np.ndarray:
        """(m, 3, B) lever arms of the chosen subset points (``rows``, default all): the point's motion
        under joint j's world rotation increment omega_j is ``omega_j x a[:, :, j]`` with
        ``a_mj = S_mj - beta_mj g_j``, S_mj the weighted influences of vertex m in j's subtree (exact for
        the linear blend: influences outside the subtree do not move)."""
        sel = slice(None) if rows is None else rows
        wy = self.weights[sel][:, :, None] * posed.per_bone[sel]
        bones = self.bones[sel]
        m, B = len(bones), self.num_bones
        C = np.zeros((m, 3, B))
        C[np.arange(m)[:, None], :, bones] = wy                         # influences are distinct bones
        S = (C.reshape(3 * m, B) @ self.ancestors_f).reshape(m, 3, B)
        return S - self.chain[sel][:, None, :] * posed.joints.T[None]

    def motion(self, posed: PosedBody, step, arms: np.ndarray) -> np.ndarray:
        """(m, 3) first-order motion of points with lever arms ``arms`` (m, 3, B) under ``step``."""
        w = self.world_step(posed, step)
        omega = w[3:].reshape(-1, 3)
        return w[:3] + cross(omega[None], arms.transpose(0, 2, 1)).sum(axis=1)

    def jacobian(self, posed: PosedBody, rows=None) -> np.ndarray:
        """(m, 3, P) derivative of the chosen points by the parameters (for tests and single rows)."""
        a = self.lever_arms(posed, rows)
        m, B = a.shape[0], self.num_bones
        J = np.zeros((m, 3, 3 + 3 * B))
        J[:, 0, 0] = J[:, 1, 1] = J[:, 2, 2] = 1.0
        rot = J[:, :, 3:].reshape(m, 3, B, 3)
        # omega x a = -[a]x omega
        rot[:, 0, :, 1], rot[:, 0, :, 2] = a[:, 2], -a[:, 1]
        rot[:, 1, :, 0], rot[:, 1, :, 2] = -a[:, 2], a[:, 0]
        rot[:, 2, :, 0], rot[:, 2, :, 1] = a[:, 1], -a[:, 0]
        rot[:] = np.einsum("mrbi,bij->mrbj", rot, self.axes(posed))
        return J

    def moved(self, pose: Poses, step) -> Poses:
        """The pose after the increment ``step`` (P,) (as :meth:`.body.Body.moved`)."""
        full = np.zeros((1, 4 + 3 * self.num_bones))
        full[0, self.columns] = step
        return apply_pose_increment(pose, full)
