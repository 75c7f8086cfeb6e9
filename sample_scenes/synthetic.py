"""Synthetic models with known structure, for tests, benchmarks and demos: a 19-part human-like
skeleton, random skins that respect the anchor rule, random poses, and a two-part tube (the
candy-wrapper test object).  Lengths in metres; Y of every bone points from head to tail."""
import numpy as np

from ..solver.rig.model import Model, Poses, Skeleton, frames_from_bones
from ..solver.geometry.rotations import rotvec_to_quat

_HUMAN = [  # name, parent, head, tail   (metres, Z up, character faces -Y)
    ("pelvis", None, (0, 0, 1.00), (0, 0, 1.10)),
    ("spine", "pelvis", (0, 0, 1.10), (0, 0, 1.30)),
    ("chest", "spine", (0, 0, 1.30), (0, 0, 1.50)),
    ("neck", "chest", (0, 0, 1.50), (0, 0, 1.62)),
    ("head", "neck", (0, 0, 1.62), (0, 0, 1.85)),
    ("clavicle.L", "chest", (0.03, 0, 1.45), (0.18, 0, 1.47)),
    ("clavicle.R", "chest", (-0.03, 0, 1.45), (-0.18, 0, 1.47)),
    ("upper_arm.L", "clavicle.L", (0.18, 0, 1.47), (0.46, 0, 1.47)),
    ("upper_arm.R", "clavicle.R", (-0.18, 0, 1.47), (-0.46, 0, 1.47)),
    ("forearm.L", "upper_arm.L", (0.46, 0, 1.47), (0.72, 0.01, 1.47)),
    ("forearm.R", "upper_arm.R", (-0.46, 0, 1.47), (-0.72, 0.01, 1.47)),
    ("hand.L", "forearm.L", (0.72, 0.01, 1.47), (0.90, 0.01, 1.47)),
    ("hand.R", "forearm.R", (-0.72, 0.01, 1.47), (-0.90, 0.01, 1.47)),
    ("thigh.L", "pelvis", (0.10, 0, 1.00), (0.11, 0, 0.55)),
    ("thigh.R", "pelvis", (-0.10, 0, 1.00), (-0.11, 0, 0.55)),
    ("shin.L", "thigh.L", (0.11, 0, 0.55), (0.11, 0.02, 0.10)),
    ("shin.R", "thigh.R", (-0.11, 0, 0.55), (-0.11, 0.02, 0.10)),
    ("foot.L", "shin.L", (0.11, 0.02, 0.10), (0.11, -0.15, 0.02)),
    ("foot.R", "shin.R", (-0.11, 0.02, 0.10), (-0.11, -0.15, 0.02)),
]


def human_skeleton() -> Skeleton:
    """A 19-part (18-joint) human-like skeleton in the spec's topology (§2)."""
    names = [r[0] for r in _HUMAN]
    parents = [-1 if r[1] is None else names.index(r[1]) for r in _HUMAN]
    heads = np.array([r[2] for r in _HUMAN], dtype=np.float64)
    tails = np.array([r[3] for r in _HUMAN], dtype=np.float64)
    return Skeleton(names, parents, heads, tails, frames_from_bones(heads, tails, up=(0, -1, 0)))


def random_skin(skeleton: Skeleton, num_vertices: int, rng, radius: float = 0.05):
    """Random vertices scattered around the bones, with anchors and swing/twist weights that respect
    the anchor rule.  A vertex around bone a at fraction s along it is anchored at a; if a has
    children, it gets random weights on them that grow with s (sum <= 1).
    Returns ``(vertices (V,3), anchor (V,), twist (V,B) float32, swing (V,B) float32)``."""
    B = skeleton.num_bones
    anchor = rng.integers(0, B, num_vertices).astype(np.int32)
    s = rng.uniform(0, 1, num_vertices)
    h, t = skeleton.heads[anchor], skeleton.tails[anchor]
    offset = rng.normal(size=(num_vertices, 3))
    offset *= radius / np.linalg.norm(offset, axis=1, keepdims=True)
    vertices = h + s[:, None] * (t - h) + offset
    twist = np.zeros((num_vertices, B), dtype=np.float32)
    swing = np.zeros((num_vertices, B), dtype=np.float32)
    for a in range(B):
        kids = skeleton.children(a)
        rows = np.flatnonzero(anchor == a)
        if not kids or not len(rows):
            continue
        for w in (twist, swing):
            raw = rng.uniform(0, 1, (len(rows), len(kids)))
            raw /= raw.sum(axis=1, keepdims=True)
            w[np.ix_(rows, kids)] = (raw * s[rows, None] ** 2).astype(np.float32)
    return vertices, anchor, twist, swing


def random_model(num_vertices: int = 2000, seed: int = 0) -> Model:
    """Human-like skeleton with a random anchor-respecting skin (no faces)."""
    rng = np.random.default_rng(seed)
    sk = human_skeleton()
    v, anchor, twist, swing = random_skin(sk, num_vertices, rng)
    return Model(v, np.zeros((0, 3), dtype=np.int32), sk, anchor, twist, swing)


def random_poses(n: int, num_bones: int, seed: int = 0, max_angle: float = 1.5,
                 translation: float = 0.5, scale_range=(0.8, 1.2)) -> Poses:
    """Random poses: rotation vectors uniform in a ball of radius ``max_angle`` (radians) per bone,
    root translation uniform in [-translation, translation]³, scale uniform in ``scale_range``."""
    rng = np.random.default_rng(seed)
    r = rng.normal(size=(n, num_bones, 3))
    r *= (max_angle * rng.uniform(0, 1, (n, num_bones, 1)) ** (1 / 3)) / np.linalg.norm(r, axis=2, keepdims=True)
    return Poses(rotvec_to_quat(r), rng.uniform(-translation, translation, (n, 3)),
                 rng.uniform(*scale_range, n))


def tube_model(length: float = 2.0, radius: float = 1.0, rings: int = 41, sectors: int = 32,
               blend_width: float = 1.0, swing_ramp: bool = False) -> Model:
    """A closed-side cylinder of ``radius`` along world +X from -length to +length, with two parts:
    ``upper`` (root, head at x=-length, tail at 0) and ``lower`` (joint at the origin, tail at +length).
    All vertices are anchored at ``upper``; the twist weight of ``lower`` ramps linearly 0 -> 1 over
    x in [-blend_width/2, blend_width/2]; the swing weight is the same ramp if ``swing_ramp`` else a
    step (1 for x > 0).  Faces are triangles between consecutive rings."""
    x = np.linspace(-length, length, rings)
    ang = np.linspace(0, 2 * np.pi, sectors, endpoint=False)
    X, A = np.meshgrid(x, ang, indexing="ij")
    verts = np.stack([X, radius * np.cos(A), radius * np.sin(A)], axis=-1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(rings - 1), np.arange(sectors), indexing="ij")
    a, b = i * sectors + j, i * sectors + (j + 1) % sectors
    c, d = a + sectors, b + sectors
    faces = np.concatenate([np.stack([a, b, d], -1).reshape(-1, 3), np.stack([a, d, c], -1).reshape(-1, 3)])
    heads = np.array([[-length, 0, 0], [0, 0, 0]], dtype=np.float64)
    tails = np.array([[0, 0, 0], [length, 0, 0]], dtype=np.float64)
    sk = Skeleton(["upper", "lower"], [-1, 0], heads, tails, frames_from_bones(heads, tails))
    ramp = np.clip(verts[:, 0] / blend_width + 0.5, 0, 1)
    twist = np.zeros((len(verts), 2), dtype=np.float32)
    swing = np.zeros((len(verts), 2), dtype=np.float32)
    twist[:, 1] = ramp
    swing[:, 1] = ramp if swing_ramp else (verts[:, 0] > 0)
    return Model(verts, faces.astype(np.int32), sk, np.zeros(len(verts), dtype=np.int32), twist, swing)
