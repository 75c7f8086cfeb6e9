"""Synthetic subjects with known structure, for tests, benchmarks and demos.  Lengths in metres, Blender
axes (Z up, the character faces -Y, left = +X); Y of every bone points from head to tail.

* a 19-part human-like stick skeleton (:func:`human_skeleton`) with random anchor-respecting skins
  (:func:`random_skin`, :func:`random_model`) and random poses (:func:`random_poses`);
* the tube body (:func:`tube_body`): a 19-bone human-like skeleton with random bone rolls and one open
  tube per bone, with swing and twist weights that respect the anchor rule (see below);
* two-part tubes, the candy-wrapper test objects: :func:`tube_model` along X and :func:`cylinder` along
  Z (with :func:`min_ring_radius_ratio`).

Both human skeletons are built by :func:`build_skeleton` from a bone table.  Random poses within a joint's
swing/twist range are ``solver.rig.pose_sampling.random_poses``, the sampler the rig measures with.

Tube-body skin of a vertex at parameter u in [0, 1] along bone b's tube: for u < 0.5 (and b not the
root) the anchor is parent(b) with twist weight 0.3 + 1.4u and swing weight 0.6 + 0.8u on b (both reach
1 at u = 0.5, where the vertex moves rigidly with b); for u >= 0.5 the anchor is b and, with r = 2u - 1,
each child c of b gets swing 0.6r²/k (k = number of children), so forks blend several joints, and
twist 0.8r on the child nearest b's tail (or 0.8r/k on every child with ``fork_twist="all"``).
"""
import numpy as np

from ..solver.geometry.rotations import rotvec_to_quat
from ..solver.rig.model import Model, Poses, Skeleton, frames_from_bones

HUMAN = [  # the stick skeleton: name, parent, head, tail
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

#            name,           parent,         head,                 tail,                  radius
TUBE_BODY = [
    ("pelvis",       None,          (0, 0, 1.00),        (0, 0, 1.10),        0.14),
    ("spine",        "pelvis",      (0, 0, 1.10),        (0, 0.01, 1.30),     0.13),
    ("chest",        "spine",       (0, 0.01, 1.30),     (0, 0, 1.50),        0.15),
    ("neck",         "chest",       (0, 0, 1.50),        (0, -0.01, 1.60),    0.05),
    ("head",         "neck",        (0, -0.01, 1.60),    (0, -0.02, 1.85),    0.10),
    ("shoulder.L",   "chest",       (0.04, 0, 1.46),     (0.18, 0.01, 1.45),  0.06),
    ("upper_arm.L",  "shoulder.L",  (0.18, 0.01, 1.45),  (0.45, 0.02, 1.38),  0.05),
    ("forearm.L",    "upper_arm.L", (0.45, 0.02, 1.38),  (0.70, -0.02, 1.30), 0.04),
    ("hand.L",       "forearm.L",   (0.70, -0.02, 1.30), (0.80, -0.03, 1.27), 0.03),
    ("shoulder.R",   "chest",       (-0.04, 0, 1.46),    (-0.18, 0.01, 1.45), 0.06),
    ("upper_arm.R",  "shoulder.R",  (-0.18, 0.01, 1.45), (-0.45, 0.02, 1.38), 0.05),
    ("forearm.R",    "upper_arm.R", (-0.45, 0.02, 1.38), (-0.70, -0.02, 1.30), 0.04),
    ("hand.R",       "forearm.R",   (-0.70, -0.02, 1.30), (-0.80, -0.03, 1.27), 0.03),
    ("thigh.L",      "pelvis",      (0.10, 0, 0.95),     (0.11, 0.01, 0.52),  0.08),
    ("shin.L",       "thigh.L",     (0.11, 0.01, 0.52),  (0.11, 0.03, 0.09),  0.06),
    ("foot.L",       "shin.L",      (0.11, 0.03, 0.09),  (0.12, -0.12, 0.02), 0.04),
    ("thigh.R",      "pelvis",      (-0.10, 0, 0.95),    (-0.11, 0.01, 0.52), 0.08),
    ("shin.R",       "thigh.R",     (-0.11, 0.01, 0.52), (-0.11, 0.03, 0.09), 0.06),
    ("foot.R",       "shin.R",      (-0.11, 0.03, 0.09), (-0.12, -0.12, 0.02), 0.04),
]


def build_skeleton(table, roll_seed=None) -> Skeleton:
    """The skeleton of a bone table (rows ``name, parent name or None, head, tail, ...``, parents first).
    Frames: ``frames_from_bones`` with Z towards the front (-Y) when ``roll_seed`` is None, else each bone
    rolled about its Y axis by a random angle from ``default_rng(roll_seed)`` (frames not axis-aligned)."""
    names = [r[0] for r in table]
    parents = [-1 if r[1] is None else names.index(r[1]) for r in table]
    heads = np.array([r[2] for r in table], dtype=np.float64)
    tails = np.array([r[3] for r in table], dtype=np.float64)
    if roll_seed is None:
        frames = frames_from_bones(heads, tails, up=(0, -1, 0))
    else:
        rng = np.random.default_rng(roll_seed)
        frames = np.array([_rolled_frame(h, t, rng.uniform(-np.pi, np.pi)) for h, t in zip(heads, tails)])
    return Skeleton(names, parents, heads, tails, frames)


def _rolled_frame(head, tail, roll: float) -> np.ndarray:
    """(3, 3) right-handed frame: Y along head->tail, X from world X (or Y) projected, turned by roll."""
    y = np.subtract(tail, head, dtype=np.float64)
    y /= np.linalg.norm(y)
    ref = np.array([1.0, 0, 0]) if abs(y[0]) < 0.9 else np.array([0, 1.0, 0])
    x = ref - y * (ref @ y)
    x /= np.linalg.norm(x)
    z = np.cross(x, y)
    c, s = np.cos(roll), np.sin(roll)
    return np.stack([c * x - s * z, y, s * x + c * z], axis=1)


def human_skeleton() -> Skeleton:
    """The 19-part (18-joint) stick skeleton :data:`HUMAN` in the spec's topology (§2)."""
    return build_skeleton(HUMAN)


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


def _tube_faces(rings: int, segments: int) -> np.ndarray:
    """(2 (rings-1) segments, 3) int64 triangles between consecutive rings of ``segments`` vertices
    (vertex ``ring * segments + k``), closed around each ring."""
    r, s = np.meshgrid(np.arange(rings - 1), np.arange(segments), indexing="ij")
    a, b = r * segments + s, r * segments + (s + 1) % segments
    c, d = a + segments, b + segments
    return np.concatenate([np.stack([a, b, d], -1).reshape(-1, 3), np.stack([a, d, c], -1).reshape(-1, 3)])


def _tube(head, tail, axes, radius, rings, segments):
    """Vertices (rings*segments, 3), u (rings*segments,) and triangles of an open tube along a bone."""
    u = np.linspace(0.0, 1.0, rings)
    t = np.linspace(0.0, 2 * np.pi, segments, endpoint=False)
    x, z = axes[:, 0], axes[:, 2]
    ring = radius * (np.cos(t)[:, None] * x + np.sin(t)[:, None] * z)            # (S, 3)
    centre = head + u[:, None] * (np.asarray(tail) - head)                        # (R, 3)
    verts = (centre[:, None, :] + ring[None]).reshape(-1, 3)
    return verts, np.repeat(u, segments), _tube_faces(rings, segments)


def tube_body(rings: int = 12, segments: int = 12, seed: int = 0, fork_twist: str = "nearest") -> Model:
    """The tube body (skeleton :data:`TUBE_BODY`, bone rolls from ``seed``): ``19 * rings * segments``
    vertices (12x12 -> 2,736; 26x26 -> 12,844).
    ``fork_twist``: at a fork the twist weights go to the child nearest the bone's tail ("nearest") or
    are shared by all children ("all"); swing weights are always shared."""
    sk = build_skeleton(TUBE_BODY, roll_seed=seed)
    B = sk.num_bones
    verts, faces, anchor, tw_rows, sw_rows = [], [], [], [], []
    offset = 0
    for b in range(B):
        v, u, f = _tube(sk.heads[b], sk.tails[b], sk.frames[b], TUBE_BODY[b][4], rings, segments)
        tw, sw = np.zeros((len(v), B), np.float32), np.zeros((len(v), B), np.float32)
        anc = np.full(len(v), b, dtype=np.int32)
        near = (u < 0.5) & (b > 0)
        anc[near] = sk.parents[b]
        tw[near, b] = 0.3 + 1.4 * u[near]
        sw[near, b] = 0.6 + 0.8 * u[near]
        kids = sk.children(b)
        far = u >= 0.5
        r = 2 * u[far] - 1
        twisting = kids if fork_twist == "all" else kids[:1] if len(kids) < 2 else [
            min(kids, key=lambda c: np.linalg.norm(sk.heads[c] - sk.tails[b]))]
        for c in kids:
            sw[far, c] = 0.6 * r * r / len(kids)
        for c in twisting:
            tw[far, c] = 0.8 * r / len(twisting)
        verts.append(v), faces.append(f + offset), anchor.append(anc), tw_rows.append(tw), sw_rows.append(sw)
        offset += len(v)
    return Model(np.concatenate(verts), np.concatenate(faces), sk, np.concatenate(anchor),
                 np.concatenate(tw_rows), np.concatenate(sw_rows))


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
    faces = _tube_faces(rings, sectors)
    heads = np.array([[-length, 0, 0], [0, 0, 0]], dtype=np.float64)
    tails = np.array([[0, 0, 0], [length, 0, 0]], dtype=np.float64)
    sk = Skeleton(["upper", "lower"], [-1, 0], heads, tails, frames_from_bones(heads, tails))
    ramp = np.clip(verts[:, 0] / blend_width + 0.5, 0, 1)
    twist = np.zeros((len(verts), 2), dtype=np.float32)
    swing = np.zeros((len(verts), 2), dtype=np.float32)
    twist[:, 1] = ramp
    swing[:, 1] = ramp if swing_ramp else (verts[:, 0] > 0)
    return Model(verts, faces.astype(np.int32), sk, np.zeros(len(verts), dtype=np.int32), twist, swing)


def cylinder(rings: int = 41, segments: int = 24, radius: float = 0.3) -> Model:
    """The candy-wrapper subject: two bones along Z (0..1 and 1..2, X axes = world X) and an open tube of
    ``rings`` rings of ``segments`` vertices, all anchored on the lower bone, with the twist weight of
    the upper bone ramping over z in [0.5, 1.5] and its swing weight over [0.8, 1.2]."""
    z = np.linspace(0.0, 2.0, rings)
    t = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    verts = np.stack([np.tile(radius * np.cos(t), rings), np.tile(radius * np.sin(t), rings),
                      np.repeat(z, segments)], axis=1)
    faces = _tube_faces(rings, segments)
    frames = np.stack([np.column_stack([(1, 0, 0), (0, 0, 1), (0, -1, 0)])] * 2)   # columns X, Y (up), Z
    sk = Skeleton(["lower", "upper"], [-1, 0], [(0, 0, 0), (0, 0, 1)], [(0, 0, 1), (0, 0, 2)], frames)
    tw = np.zeros((len(verts), 2), np.float32)
    sw = np.zeros((len(verts), 2), np.float32)
    tw[:, 1] = np.clip(verts[:, 2] - 0.5, 0, 1)
    sw[:, 1] = np.clip((verts[:, 2] - 0.8) / 0.4, 0, 1)
    return Model(verts, faces, sk, np.zeros(len(verts), np.int32), tw, sw)


def min_ring_radius_ratio(positions, rings: int, segments: int, radius: float) -> float:
    """Smallest mean ring radius / rest radius of a deformed :func:`cylinder` (positions (V, 3));
    1 = no candy-wrapper collapse."""
    ring = np.asarray(positions).reshape(rings, segments, 3)
    centre = ring.mean(axis=1, keepdims=True)
    return float(np.linalg.norm(ring - centre, axis=2).mean(axis=1).min() / radius)
