"""A small closed, connected test body for model adaptation: one capsule through both arms and the chest
(9 bones, about 1,000 vertices), elliptic cross-sections whose radius varies along the arms, smoothly
blended hybrid-skin weights around every joint.  Lengths in metres, Z up, facing -Y.

Why not ``sample_scenes.synthetic.tube_body``: its open tubes overlap at every joint (hidden tube ends
lie a few centimetres inside other tubes, where visibility and matching cannot work), its round tubes
are invariant under twists and slides along their axes, and its triangles face inwards; adapting rest
vertices and joint centres to scans of it is ill-posed in ways a human body is not.
"""
import numpy as np

from articula.solver.rig.model import Model, Skeleton, frames_from_bones

#        name,           parent,         head,                  tail
BONES = [("chest",       None,          (0.0, 0.0, 1.40),      (0.0, 0.0, 1.50)),
         ("shoulder.L",  "chest",       (0.04, 0.0, 1.46),     (0.18, 0.01, 1.45)),
         ("upper_arm.L", "shoulder.L",  (0.18, 0.01, 1.45),    (0.45, 0.02, 1.38)),
         ("forearm.L",   "upper_arm.L", (0.45, 0.02, 1.38),    (0.70, -0.02, 1.30)),
         ("hand.L",      "forearm.L",   (0.70, -0.02, 1.30),   (0.80, -0.03, 1.27)),
         ("shoulder.R",  "chest",       (-0.04, 0.0, 1.46),    (-0.18, 0.01, 1.45)),
         ("upper_arm.R", "shoulder.R",  (-0.18, 0.01, 1.45),   (-0.45, 0.02, 1.38)),
         ("forearm.R",   "upper_arm.R", (-0.45, 0.02, 1.38),   (-0.70, -0.02, 1.30)),
         ("hand.R",      "forearm.R",   (-0.70, -0.02, 1.30),  (-0.80, -0.03, 1.27))]
CHAIN_R = [8, 7, 6, 5]          # hand.R ... shoulder.R: the centre line runs from the right hand to the left
CHAIN_L = [1, 2, 3, 4]
BLEND = 0.025                   # half width of the blend zone around a joint (m)


def skeleton() -> Skeleton:
    names = [b[0] for b in BONES]
    parents = [-1 if b[1] is None else names.index(b[1]) for b in BONES]
    heads, tails = np.array([b[2] for b in BONES], float), np.array([b[3] for b in BONES], float)
    return Skeleton(names, parents, heads, tails, frames_from_bones(heads, tails))


def _centre_line(sk):
    """Nodes of the centre line (right hand tip ... left hand tip) and, per segment, its bone."""
    nodes = [sk.tails[8]] + [sk.heads[b] for b in CHAIN_R] + [sk.heads[b] for b in CHAIN_L] + [sk.tails[4]]
    bones = CHAIN_R + [0] + CHAIN_L
    return np.array(nodes), bones


def _smoothstep(t):
    t = np.clip(t, 0.0, 1.0)
    return t * t * (3 - 2 * t)


def _skin(sk, nodes, bones, s_vertex, knots):
    """anchor (V,), twist and swing weights (V, B) from the arc length s of each vertex: rigid with the
    segment's bone, blended over ±BLEND around every joint (anchor the parent, weight on the child)."""
    B, V = sk.num_bones, len(s_vertex)
    seg = np.clip(np.searchsorted(knots, s_vertex, side="right") - 1, 0, len(bones) - 1)
    anchor = np.array([bones[k] for k in seg], dtype=np.int32)
    w = np.zeros((V, B), np.float32)
    for k in range(1, len(knots) - 1):                     # joint between segments k-1 and k
        a, b = bones[k - 1], bones[k]
        parent, child, sign = (a, b, 1.0) if sk.parents[b] == a else (b, a, -1.0)
        d = sign * (s_vertex - knots[k])                   # > 0 on the child's side
        zone = np.abs(d) < BLEND
        anchor[zone] = parent
        w[zone, child] = _smoothstep((d[zone] + BLEND) / (2 * BLEND))
    return anchor, w


def arm_body(step: float = 0.02, segments: int = 12) -> Model:
    """The test body (module docstring); rings every ``step`` metres of ``segments`` vertices, a pole
    vertex closing each hand."""
    sk = skeleton()
    nodes, bones = _centre_line(sk)
    knots = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(nodes, axis=0), axis=1))])
    s = np.linspace(0.0, knots[-1], int(round(knots[-1] / step)) + 1)
    seg = np.clip(np.searchsorted(knots, s, side="right") - 1, 0, len(bones) - 1)
    tangent = (nodes[seg + 1] - nodes[seg]) / np.diff(knots)[seg, None]
    centre = nodes[seg] + (s - knots[seg])[:, None] * tangent
    up = np.array([0.0, 0.0, 1.0])
    n1 = up - (tangent @ up)[:, None] * tangent
    n1 /= np.linalg.norm(n1, axis=1, keepdims=True)
    n2 = np.cross(tangent, n1)
    x = np.abs(centre[:, 0])
    radius = 0.045 - 0.02 * np.clip(x / 0.8, 0, 1) + 0.006 * np.sin(2 * np.pi * x / 0.21)
    t = np.linspace(0.0, 2 * np.pi, segments, endpoint=False)
    ring = radius[:, None, None] * (np.cos(t)[None, :, None] * 1.25 * n1[:, None] + np.sin(t)[None, :, None] * 0.8
                                    * n2[:, None])
    R = len(s)
    verts = (centre[:, None] + ring).reshape(-1, 3)
    poles = np.array([centre[0] - 0.5 * step * tangent[0], centre[-1] + 0.5 * step * tangent[-1]])
    verts = np.concatenate([verts, poles])
    i, j = np.meshgrid(np.arange(R - 1), np.arange(segments), indexing="ij")
    a, b = i * segments + j, i * segments + (j + 1) % segments
    faces = np.concatenate([np.stack([a, b, a + segments], -1).reshape(-1, 3),
                            np.stack([b, b + segments, a + segments], -1).reshape(-1, 3)])
    first, last = R * segments, R * segments + 1
    k = np.arange(segments)
    caps = np.concatenate([np.stack([np.full(segments, first), (k + 1) % segments, k], -1),
                           np.stack([np.full(segments, last), (R - 1) * segments + k,
                                     (R - 1) * segments + (k + 1) % segments], -1)])
    s_vertex = np.concatenate([np.repeat(s, segments), [0.0, knots[-1]]])
    anchor, w = _skin(sk, nodes, bones, s_vertex, knots)
    return Model(verts, np.concatenate([faces, caps]).astype(np.int32), sk, anchor, w, w.copy())
