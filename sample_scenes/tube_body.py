"""A procedural human-like test subject: 19 bones (pelvis, spine, chest, neck, head, shoulders, arms,
forearms, hands, thighs, shins, feet; ``.L``/``.R`` names, Blender axes: Z up, -Y forward, left = +X)
and one open tube per bone, with non-trivial swing and twist weights that respect the anchor rule.
Pure numpy; used by the rig tests and benchmarks (and handy as a demo).

Skin of a vertex at parameter u in [0, 1] along bone b's tube: for u < 0.5 (and b not the root) the
anchor is parent(b) with twist weight 0.3 + 1.4u and swing weight 0.6 + 0.8u on b (both reach 1 at
u = 0.5, where the vertex moves rigidly with b); for u >= 0.5 the anchor is b and, with r = 2u - 1,
each child c of b gets swing 0.6r²/k (k = number of children), so forks blend several joints, and
twist 0.8r on the child nearest b's tail (or 0.8r/k on every child with ``fork_twist="all"``).
"""
import numpy as np

from ..solver.rig.model import Model, Skeleton

#          name,           parent,         head,                 tail,                  radius
BONES = [
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


def frame(head, tail, roll: float) -> np.ndarray:
    """(3, 3) right-handed frame: Y along head->tail, X from world X (or Y) projected, turned by roll."""
    y = np.subtract(tail, head, dtype=np.float64)
    y /= np.linalg.norm(y)
    ref = np.array([1.0, 0, 0]) if abs(y[0]) < 0.9 else np.array([0, 1.0, 0])
    x = ref - y * (ref @ y)
    x /= np.linalg.norm(x)
    z = np.cross(x, y)
    c, s = np.cos(roll), np.sin(roll)
    return np.stack([c * x - s * z, y, s * x + c * z], axis=1)


def skeleton(seed: int = 0) -> Skeleton:
    """The 19-bone skeleton; ``seed`` chooses random rolls (so frames are not axis-aligned)."""
    rng = np.random.default_rng(seed)
    names = [b[0] for b in BONES]
    parents = [-1 if b[1] is None else names.index(b[1]) for b in BONES]
    heads = np.array([b[2] for b in BONES], dtype=np.float64)
    tails = np.array([b[3] for b in BONES], dtype=np.float64)
    frames = np.array([frame(h, t, rng.uniform(-np.pi, np.pi)) for h, t in zip(heads, tails)])
    return Skeleton(names, parents, heads, tails, frames)


def _tube(head, tail, axes, radius, rings, segments):
    """Vertices (rings*segments, 3), u (rings*segments,) and triangles of an open tube along a bone."""
    u = np.linspace(0.0, 1.0, rings)
    t = np.linspace(0.0, 2 * np.pi, segments, endpoint=False)
    x, z = axes[:, 0], axes[:, 2]
    ring = radius * (np.cos(t)[:, None] * x + np.sin(t)[:, None] * z)            # (S, 3)
    centre = head + u[:, None] * (np.asarray(tail) - head)                        # (R, 3)
    verts = (centre[:, None, :] + ring[None]).reshape(-1, 3)
    r, s = np.meshgrid(np.arange(rings - 1), np.arange(segments), indexing="ij")
    a, b = r * segments + s, r * segments + (s + 1) % segments
    c, d = a + segments, b + segments
    faces = np.concatenate([np.stack([a, b, d], -1).reshape(-1, 3), np.stack([a, d, c], -1).reshape(-1, 3)])
    return verts, np.repeat(u, segments), faces


def model(rings: int = 12, segments: int = 12, seed: int = 0, fork_twist: str = "nearest") -> Model:
    """The tube body: ``19 * rings * segments`` vertices (12x12 -> 2,736; 26x26 -> 12,844).
    ``fork_twist``: at a fork the twist weights go to the child nearest the bone's tail ("nearest") or
    are shared by all children ("all"); swing weights are always shared."""
    sk = skeleton(seed)
    B = sk.num_bones
    verts, faces, anchor, tw_rows, sw_rows = [], [], [], [], []
    offset = 0
    for b in range(B):
        v, u, f = _tube(sk.heads[b], sk.tails[b], sk.frames[b], BONES[b][4], rings, segments)
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


def random_poses(num_bones: int, n: int, seed: int = 1, max_twist_deg: float = 170.0,
                 max_swing_deg: float = 110.0):
    """``n`` random poses: per joint a swing (random axis ⊥ Y, up to ``max_swing_deg``) times a twist
    (up to ±``max_twist_deg``); a random root rotation, translation (±0.5 m) and scale (0.7..1.4).
    Returns ``(rotations (n, B, 4), translations (n, 3), scales (n,))``."""
    rng = np.random.default_rng(seed)
    tw = np.radians(rng.uniform(-max_twist_deg, max_twist_deg, (n, num_bones)))
    sw = np.radians(rng.uniform(0, max_swing_deg, (n, num_bones)))
    phi = rng.uniform(0, 2 * np.pi, (n, num_bones))
    q_tw = np.stack([np.cos(tw / 2), 0 * tw, np.sin(tw / 2), 0 * tw], -1)
    q_sw = np.stack([np.cos(sw / 2), np.sin(sw / 2) * np.cos(phi), 0 * sw, np.sin(sw / 2) * np.sin(phi)], -1)
    w1, v1 = q_sw[..., :1], q_sw[..., 1:]
    w2, v2 = q_tw[..., :1], q_tw[..., 1:]
    q = np.concatenate([w1 * w2 - np.sum(v1 * v2, -1, keepdims=True),
                        w1 * v2 + w2 * v1 + np.cross(v1, v2)], -1)
    root = rng.normal(size=(n, 4))
    q[:, 0] = root / np.linalg.norm(root, axis=1, keepdims=True)
    return q, rng.uniform(-0.5, 0.5, (n, 3)), rng.uniform(0.7, 1.4, n)


def cylinder(rings: int = 41, segments: int = 24, radius: float = 0.3) -> Model:
    """The candy-wrapper subject: two bones along Z (0..1 and 1..2, X axes = world X) and an open tube of
    ``rings`` rings of ``segments`` vertices, all anchored on the lower bone, with the twist weight of
    the upper bone ramping over z in [0.5, 1.5] and its swing weight over [0.8, 1.2]."""
    z = np.linspace(0.0, 2.0, rings)
    t = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    verts = np.stack([np.tile(radius * np.cos(t), rings), np.tile(radius * np.sin(t), rings),
                      np.repeat(z, segments)], axis=1)
    r, s = np.meshgrid(np.arange(rings - 1), np.arange(segments), indexing="ij")
    a, b = r * segments + s, r * segments + (s + 1) % segments
    faces = np.concatenate([np.stack([a, b, b + segments], -1).reshape(-1, 3),
                            np.stack([a, b + segments, a + segments], -1).reshape(-1, 3)])
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
