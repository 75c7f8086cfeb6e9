"""The character model as plain arrays: skeleton, rest mesh, anchors and swing/twist skin, and poses.

Bones are body parts.  Bone 0 is the root part (parent -1); every other bone b is a part whose joint
(rotation centre) is its head, and ``parents[b] < b``.  ``frames[b]`` holds the rest local axes X, Y, Z
as columns in world coordinates; Y = (tail - head)/|tail - head| is the twist axis.  Lengths in metres.
Each vertex has an anchor part ``anchor[v]``; its twist and swing weights may be non-zero only on the
children of that part (its blend set), each row in [0, 1] with sum <= 1 (remainder = neutral).
The bundle file: :mod:`solver.formats.bundle`; conventions: docs/skinning.md.

``validate()`` raises :class:`ArticulaInputError` naming the key and the offending index.
"""
from dataclasses import dataclass

import numpy as np

from ..errors import ArticulaInputError

FRAME_TOL = 1e-6        # orthonormality / det / Y-axis tolerance of rest frames
QUAT_TOL = 1e-6         # |q| - 1 tolerance of pose quaternions
QUAT_RENORM_TOL = 1e-4  # |q| - 1 up to which a loaded quaternion is normalised (float32 round-off) with a note
WEIGHT_TOL = 1e-6       # tolerance of the weight bounds (weights are float32)


def _check_shape(key, arr, shape):
    """Raise unless ``arr`` has ``shape`` (None = any length)."""
    if arr.ndim != len(shape) or any(s is not None and s != a for s, a in zip(shape, arr.shape)):
        want = "(" + ", ".join("*" if s is None else str(s) for s in shape) + ")"
        raise ArticulaInputError(f"{key}: expected shape {want}, got {arr.shape}")


def _check_finite(key, arr):
    bad = np.argwhere(~np.isfinite(arr))
    if len(bad):
        raise ArticulaInputError(f"{key}: non-finite value at index {tuple(int(i) for i in bad[0])}")


@dataclass
class Skeleton:
    """names (B,), parents (B,) int32, heads (B,3), tails (B,3), frames (B,3,3) float64."""
    names: list
    parents: np.ndarray
    heads: np.ndarray
    tails: np.ndarray
    frames: np.ndarray

    def __post_init__(self):
        self.names = [str(n) for n in self.names]
        self.parents = np.asarray(self.parents, dtype=np.int32)
        self.heads = np.asarray(self.heads, dtype=np.float64)
        self.tails = np.asarray(self.tails, dtype=np.float64)
        self.frames = np.asarray(self.frames, dtype=np.float64)

    @property
    def num_bones(self) -> int:
        return len(self.parents)

    def children(self, b: int) -> list:
        """Indices of the bones whose parent is ``b`` (ascending)."""
        return [int(c) for c in np.flatnonzero(self.parents == b)]

    def child_matrix(self) -> np.ndarray:
        """(B, B) bool: ``[a, c]`` is True when ``parents[c] == a``."""
        B = self.num_bones
        m = np.zeros((B, B), dtype=bool)
        c = np.arange(1, B)
        m[self.parents[1:], c] = True
        return m

    def validate(self) -> None:
        B = self.num_bones
        _check_shape("parents", self.parents, (B,))
        if B < 1:
            raise ArticulaInputError("parents: the skeleton needs at least one bone")
        if len(self.names) != B:
            raise ArticulaInputError(f"bone_names: {len(self.names)} names for {B} bones")
        if len(set(self.names)) != B:
            dup = next(n for n in self.names if self.names.count(n) > 1)
            raise ArticulaInputError(f"bone_names: duplicate name {dup!r}")
        if self.parents[0] != -1:
            raise ArticulaInputError(f"parents: bone 0 must be the root (parent -1), got {self.parents[0]}")
        for b in range(1, B):
            if not 0 <= self.parents[b] < b:
                raise ArticulaInputError(
                    f"parents: bone {b} ({self.names[b]!r}) has parent {self.parents[b]}; parents must satisfy "
                    f"0 <= parents[b] < b (no cycles, topological order)")
        for key in ("heads", "tails"):
            _check_shape(key, getattr(self, key), (B, 3))
            _check_finite(key, getattr(self, key))
        _check_shape("frames", self.frames, (B, 3, 3))
        _check_finite("frames", self.frames)
        length = np.linalg.norm(self.tails - self.heads, axis=1)
        bad = np.flatnonzero(length < 1e-9)
        if len(bad):
            raise ArticulaInputError(f"tails: bone {bad[0]} ({self.names[bad[0]]!r}) has head == tail")
        orth = np.abs(np.einsum("bji,bjk->bik", self.frames, self.frames) - np.eye(3)).max(axis=(1, 2))
        bad = np.flatnonzero(orth > FRAME_TOL)
        if len(bad):
            raise ArticulaInputError(f"frames: frame of bone {bad[0]} is not orthonormal (error {orth[bad[0]]:.3g})")
        bad = np.flatnonzero(np.linalg.det(self.frames) < 0)
        if len(bad):
            raise ArticulaInputError(f"frames: frame of bone {bad[0]} has det -1 (left-handed)")
        y = (self.tails - self.heads) / length[:, None]
        err = np.linalg.norm(self.frames[:, :, 1] - y, axis=1)
        bad = np.flatnonzero(err > FRAME_TOL)
        if len(bad):
            raise ArticulaInputError(
                f"frames: Y axis of bone {bad[0]} is not (tail - head)/|tail - head| (error {err[bad[0]]:.3g})")


@dataclass
class Model:
    """rest_vertices (V,3), faces (F,3) int32, skeleton, anchor (V,) int32,
    twist_weights and swing_weights (V,B) float32."""
    rest_vertices: np.ndarray
    faces: np.ndarray
    skeleton: Skeleton
    anchor: np.ndarray
    twist_weights: np.ndarray
    swing_weights: np.ndarray

    def __post_init__(self):
        self.rest_vertices = np.asarray(self.rest_vertices, dtype=np.float64)
        self.faces = np.asarray(self.faces, dtype=np.int32)
        self.anchor = np.asarray(self.anchor, dtype=np.int32)
        self.twist_weights = np.asarray(self.twist_weights, dtype=np.float32)
        self.swing_weights = np.asarray(self.swing_weights, dtype=np.float32)

    @property
    def num_vertices(self) -> int:
        return len(self.rest_vertices)

    def validate(self) -> None:
        sk = self.skeleton
        sk.validate()
        B = sk.num_bones
        _check_shape("rest_vertices", self.rest_vertices, (None, 3))
        _check_finite("rest_vertices", self.rest_vertices)
        V = len(self.rest_vertices)
        _check_shape("faces", self.faces, (None, 3))
        bad = np.argwhere((self.faces < 0) | (self.faces >= V))
        if len(bad):
            raise ArticulaInputError(f"faces: face {bad[0][0]} refers to vertex {self.faces[tuple(bad[0])]}, "
                                     f"outside 0..{V - 1}")
        _check_shape("anchor", self.anchor, (V,))
        bad = np.flatnonzero((self.anchor < 0) | (self.anchor >= B))
        if len(bad):
            raise ArticulaInputError(f"anchor: vertex {bad[0]} has anchor {self.anchor[bad[0]]}, outside 0..{B - 1}")
        child = sk.child_matrix()
        for key in ("twist_weights", "swing_weights"):
            self._validate_weights(key, getattr(self, key), child)

    def _validate_weights(self, key, w, child):
        V, B = len(self.rest_vertices), self.skeleton.num_bones
        _check_shape(key, w, (V, B))
        _check_finite(key, w)
        bad = np.argwhere((w < -WEIGHT_TOL) | (w > 1 + WEIGHT_TOL))
        if len(bad):
            v, b = bad[0]
            raise ArticulaInputError(f"{key}: vertex {v}, bone {b}: weight {w[v, b]:.6g} outside [0, 1]")
        s = w.astype(np.float64).sum(axis=1)
        bad = np.flatnonzero(s > 1 + WEIGHT_TOL)
        if len(bad):
            raise ArticulaInputError(f"{key}: vertex {bad[0]}: weights sum to {s[bad[0]]:.6g} > 1")
        bad = np.argwhere((w != 0) & ~child[self.anchor])
        if len(bad):
            v, b = bad[0]
            raise ArticulaInputError(
                f"{key}: vertex {v} has weight on bone {b} ({self.skeleton.names[b]!r}), which is not a child of "
                f"its anchor bone {self.anchor[v]} ({self.skeleton.names[self.anchor[v]]!r})")


@dataclass
class Poses:
    """rotations (N,B,4) unit quaternions (w,x,y,z) relative to rest in bone-local axes,
    translations (N,3) root translation in world metres, scales (N,) uniform subject scale."""
    rotations: np.ndarray
    translations: np.ndarray
    scales: np.ndarray

    def __post_init__(self):
        self.rotations = np.asarray(self.rotations, dtype=np.float64)
        self.translations = np.asarray(self.translations, dtype=np.float64)
        self.scales = np.asarray(self.scales, dtype=np.float64)

    @classmethod
    def identity(cls, n: int, num_bones: int) -> "Poses":
        rot = np.zeros((n, num_bones, 4))
        rot[..., 0] = 1.0
        return cls(rot, np.zeros((n, 3)), np.ones(n))

    def __len__(self) -> int:
        return len(self.rotations)

    def take(self, index) -> "Poses":
        """The frames ``index`` (an int, a slice or a sequence of ints) as new Poses with copied arrays;
        an int keeps the frame axis (one frame)."""
        if isinstance(index, (int, np.integer)):
            index = slice(int(index), int(index) + 1)
        elif not isinstance(index, slice):
            index = np.asarray(list(index), dtype=np.intp)
        return Poses(self.rotations[index].copy(), self.translations[index].copy(), self.scales[index].copy())

    def normalise_near_unit(self) -> str:
        """Normalise, in place, the rotations whose norm is off 1 by more than ``QUAT_TOL`` but at most
        ``QUAT_RENORM_TOL`` (rounding of float32 or text round trips); others are left for :meth:`validate`
        to refuse.  Returns a note for the user naming how many were normalised and the worst one, or ""."""
        r = self.rotations
        if r.ndim != 3 or r.shape[-1] != 4 or not np.isfinite(r).all():
            return ""
        norm = np.linalg.norm(r, axis=2)
        err = np.abs(norm - 1.0)
        fix = (err > QUAT_TOL) & (err <= QUAT_RENORM_TOL)
        if not fix.any():
            return ""
        n, b = np.unravel_index(np.argmax(np.where(fix, err, -1.0)), err.shape)
        self.rotations = np.where(fix[..., None], r / np.where(fix, norm, 1.0)[..., None], r)
        return (f"pose_rotations: normalised {int(fix.sum())} quaternion(s) whose norm was within "
                f"{QUAT_RENORM_TOL:g} of 1 (worst: frame {n}, bone {b}, norm {float(norm[n, b])!r})")

    def validate(self, num_bones: int = None) -> None:
        r = self.rotations
        if r.ndim != 3 or r.shape[2] != 4 or (num_bones is not None and r.shape[1] != num_bones):
            want = f"(N, {num_bones if num_bones is not None else 'B'}, 4)"
            raise ArticulaInputError(f"pose_rotations: expected shape {want}, got {r.shape}")
        N = len(r)
        _check_finite("pose_rotations", r)
        norm = np.linalg.norm(r, axis=2)
        bad = np.argwhere(np.abs(norm - 1.0) > QUAT_TOL)
        if len(bad):
            n, b = bad[0]
            raise ArticulaInputError(f"pose_rotations: frame {n}, bone {b}: quaternion norm "
                                     f"{float(norm[n, b])!r} is not 1 (off by {abs(norm[n, b] - 1.0):.3g}; the tolerance is {QUAT_TOL:g}, and "
                                     f"norms within {QUAT_RENORM_TOL:g} of 1 are normalised when a bundle is loaded)")
        _check_shape("pose_translations", self.translations, (N, 3))
        _check_finite("pose_translations", self.translations)
        _check_shape("pose_scales", self.scales, (N,))
        _check_finite("pose_scales", self.scales)
        bad = np.flatnonzero(self.scales <= 0)
        if len(bad):
            raise ArticulaInputError(f"pose_scales: frame {bad[0]}: scale {self.scales[bad[0]]:.6g} must be > 0")


def frames_from_bones(heads, tails, up=(0.0, 0.0, 1.0)):
    """Rest frames ``(B, 3, 3)`` (columns X, Y, Z; det +1) with Y = (tail − head)/|tail − head| and Z the
    component of ``up`` (3,) orthogonal to Y (world X is used instead where ``up`` is nearly parallel
    to Y).  heads, tails ``(B, 3)``.  Bones with head == tail get an arbitrary frame (invalid anyway)."""
    d = np.asarray(tails, dtype=np.float64) - np.asarray(heads, dtype=np.float64)
    y = d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-300)
    up = np.broadcast_to(np.asarray(up, dtype=np.float64), y.shape)
    alt = np.broadcast_to(np.array([1.0, 0.0, 0.0]), y.shape)
    ref = np.where(np.abs(np.sum(y * up, axis=1, keepdims=True)) > 0.99 * np.linalg.norm(up, axis=1, keepdims=True),
                   alt, up)
    z = ref - np.sum(ref * y, axis=1, keepdims=True) * y
    z /= np.linalg.norm(z, axis=1, keepdims=True)
    x = np.cross(y, z)
    return np.stack([x, y, z], axis=2)
