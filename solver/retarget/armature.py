"""An armature as plain arrays, and its forward kinematics, in Blender's conventions.

``ArmatureRest`` holds what retargeting needs of a rig: bone names, parents (−1 for roots, parents
before children), rest bone matrices in armature space ``rest (J, 4, 4)`` (Blender's
``bone.matrix_local``: columns = the bone's axes, +Y along the bone, translation = its head), tails
``(J, 3)``, which bones are connected to their parent, and the object's world matrix ``world (4, 4)``
(rotation times a uniform scale, and a translation).  Lengths are in the armature's own units.

Pose (Blender's rule): ``M_b = M_parent · (rest_parentᵀ-relative rest_b) · L_b`` with ``L_b`` = the pose
bone's location/rotation/scale; roots use ``rest_b · L_b``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import ArticulaInputError


@dataclass
class ArmatureRest:
    name: str
    bones: list            # J names
    parents: np.ndarray    # (J,) int, -1 for roots, parents first
    rest: np.ndarray       # (J, 4, 4) armature-space rest matrices
    tails: np.ndarray      # (J, 3) armature-space rest tails
    connected: np.ndarray  # (J,) bool: the head is locked to the parent's tail
    world: np.ndarray      # (4, 4) object matrix

    def __post_init__(self):
        self.parents = np.asarray(self.parents, dtype=np.int64)
        self.rest = np.asarray(self.rest, dtype=np.float64)
        self.tails = np.asarray(self.tails, dtype=np.float64)
        self.connected = np.asarray(self.connected, dtype=bool)
        self.world = np.asarray(self.world, dtype=np.float64)
        J = len(self.bones)
        if not (self.parents.shape == (J,) and self.rest.shape == (J, 4, 4) and self.tails.shape == (J, 3)):
            raise ArticulaInputError(f"armature {self.name!r}: inconsistent bone arrays")
        if np.any(self.parents >= np.arange(J)):
            raise ArticulaInputError(f"armature {self.name!r}: bones must come after their parents")
        self.index = {b: i for i, b in enumerate(self.bones)}

    @property
    def scale(self) -> float:
        """The object's uniform scale (world units per armature unit)."""
        return float(np.cbrt(abs(np.linalg.det(self.world[:3, :3]))))

    @property
    def rotation(self) -> np.ndarray:
        """(3, 3) the object's rotation (its matrix without the scale)."""
        return self.world[:3, :3] / self.scale

    def world_points(self, p: np.ndarray) -> np.ndarray:
        """Armature-space points ``(..., 3)`` in world space."""
        return p @ self.world[:3, :3].T + self.world[:3, 3]

    def armature_points(self, p: np.ndarray) -> np.ndarray:
        """World points ``(..., 3)`` in armature space."""
        return (p - self.world[:3, 3]) @ np.linalg.inv(self.world[:3, :3]).T

    def relative_rest(self) -> np.ndarray:
        """(J, 4, 4) each bone's rest matrix relative to its parent's (the root's own rest for roots)."""
        rel = self.rest.copy()
        has = self.parents >= 0
        rel[has] = np.linalg.inv(self.rest[self.parents[has]]) @ self.rest[has]
        return rel

    def is_ancestor(self, a: int, b: int) -> bool:
        """Bone ``a`` is bone ``b`` or one of its ancestors."""
        while b >= 0:
            if b == a:
                return True
            b = self.parents[b]
        return False

    def children(self) -> list:
        out = [[] for _ in self.bones]
        for b, p in enumerate(self.parents):
            if p >= 0:
                out[p].append(b)
        return out


def local_matrices(rotations: np.ndarray, locations=None) -> np.ndarray:
    """(F, J, 4, 4) pose-bone matrices from rotations ``(F, J, 3, 3)`` and optional locations ``(F, J, 3)``."""
    F, J = rotations.shape[:2]
    L = np.zeros((F, J, 4, 4))
    L[..., :3, :3] = rotations
    L[..., 3, 3] = 1.0
    if locations is not None:
        L[..., :3, 3] = locations
    return L


def forward(arm: ArmatureRest, local: np.ndarray) -> np.ndarray:
    """(F, J, 4, 4) armature-space pose matrices from pose-bone matrices ``local (F, J, 4, 4)``."""
    rel = arm.relative_rest()
    out = np.empty_like(local)
    for b, p in enumerate(arm.parents):
        base = rel[b] if p < 0 else out[:, p] @ rel[b]
        out[:, b] = base @ local[:, b]
    return out


def world_pose(arm: ArmatureRest, pose: np.ndarray):
    """World rotations ``(F, J, 3, 3)`` (scale removed) and heads ``(F, J, 3)`` of armature-space pose
    matrices ``pose (F, J, 4, 4)``."""
    R = arm.rotation @ pose[..., :3, :3]
    R = R / np.linalg.norm(R[..., :, 0], axis=-1)[..., None, None]
    return R, arm.world_points(pose[..., :3, 3])


def rest_world(arm: ArmatureRest):
    """World rest rotations ``(J, 3, 3)`` and heads ``(J, 3)``."""
    R, h = world_pose(arm, arm.rest[None])
    return R[0], h[0]


def subset(arm: ArmatureRest, keep) -> ArmatureRest:
    """The armature of the bones where ``keep (J,)`` is true; a kept bone's parent becomes its nearest kept
    ancestor (roles are then found on, e.g., a rig's control bones without its helper bones)."""
    keep = np.asarray(keep, dtype=bool)
    new_index = np.cumsum(keep) - 1
    parents = []
    for b in np.flatnonzero(keep):
        p = arm.parents[b]
        while p >= 0 and not keep[p]:
            p = arm.parents[p]
        parents.append(int(new_index[p]) if p >= 0 else -1)
    idx = np.flatnonzero(keep)
    return ArmatureRest(arm.name, [arm.bones[i] for i in idx], np.array(parents, dtype=np.int64), arm.rest[idx],
                        arm.tails[idx], arm.connected[idx], arm.world)


def local_from_pose(arm: ArmatureRest, pose: np.ndarray) -> np.ndarray:
    """(F, J, 4, 4) pose-bone matrices that give the armature-space ``pose (F, J, 4, 4)`` under plain
    parenting (the inverse of :func:`forward`)."""
    rel = arm.relative_rest()
    out = np.empty_like(pose)
    for b, p in enumerate(arm.parents):
        base = rel[b][None] if p < 0 else pose[:, p] @ rel[b]
        out[:, b] = np.linalg.solve(base, pose[:, b])
    return out
