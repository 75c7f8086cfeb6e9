"""The maths of the plain linear-blend version of an Articula rig (one Armature modifier, no Preserve
Volume; for FBX/glTF and game engines): its bones with twist segments, their skin weights and
deformation, and how far it deviates from the exact hybrid rig (:func:`deviation`, metres).  Pure numpy;
``addon/rig/linear_blend.py`` builds this rig in Blender (operator ``articula.export_lbs``, docs/RIG.md).

For every joint c (parent part a) and segments n the LBS rig has, besides the control bones and the
swing helpers ``SW-<c>`` (as in the hybrid rig):
* ``TWS-<c>.<k>`` (0 < k < n): child of ``SW-<c>`` at the rest of c, Y rotation driven by k/n of c's
  twist, so it deforms by ``M_a ∘ Swing_c ∘ Twist_c(k/n)``  (k = 0 is ``SW-<c>``, k = n is control c);
* ``TWN-<c>.<k>`` (0 < k <= n): child of control a at the rest of c, Y rotation driven by k/n of the
  twist: ``M_a ∘ Twist_c(k/n)``  (k = 0 is control a).
A vertex with swing weight s_c and twist weight t_c puts s_c on the two S bones and its neutral share
on the two N bones that bracket the twist fraction t_c (linear between them).  With one twisting joint
per vertex this is the hybrid skin with the dual-quaternion twist replaced by n linear segments;
where several children share a vertex it is an approximation; the deviation is measured, not assumed.

Such vertices get up to 4 bones per twisting child (11 on MakeHuman); :func:`limited_weights` keeps at
most k per vertex (glTF: 4) with the bones and weights fitted to the hybrid skin over seeded sample
poses (``influences`` module), not the k largest renormalised.
"""
import numpy as np

from ..errors import ArticulaInputError
from .kinematics import forward_kinematics
from ..geometry.rotations import quat_canonical, quat_normalize, quat_to_matrix, swing_twist_y
from . import influences
from . import names as rig_names
from . import pose_sampling

SEG_PREFIX_SWING = "TWS-"
SEG_PREFIX_NEUTRAL = "TWN-"
SAMPLE_POSES = 100            # random poses the deviation is measured on (no action) / weights fitted to
SAMPLE_TWIST_DEG = 90.0       # their twist range (swings up to pose_sampling's 110°)
MEASURE_SEED, FIT_SEED = 0, 1
MAX_SEGMENTS = 16             # limits of the operator and the batch command
MAX_INFLUENCES = 32


def bone_layout(skeleton, segments: int):
    """Bones of the LBS rig: list of ``(name, kind, c, k)`` with kind 'CONTROL' (c = part), 'SWING'
    (k = 0 of S), 'S' (0<k<n) or 'N' (0<k<=n); controls first, in bundle order."""
    if segments < 1:
        raise ArticulaInputError(f"segments must be >= 1, got {segments}")
    out = [(n, 'CONTROL', b, 0) for b, n in enumerate(skeleton.names)]
    for c in range(1, skeleton.num_bones):
        name = skeleton.names[c]
        out.append((rig_names.swing(name), 'SWING', c, 0))
        out += [(f"{SEG_PREFIX_SWING}{name}.{k}", 'S', c, k) for k in range(1, segments)]
        out += [(f"{SEG_PREFIX_NEUTRAL}{name}.{k}", 'N', c, k) for k in range(1, segments + 1)]
    for name, *_ in out:
        if len(name.encode("utf-8")) > rig_names.MAX_NAME_BYTES:
            raise ArticulaInputError(f"bone name {name!r} would exceed Blender's {rig_names.MAX_NAME_BYTES} bytes")
    return out


def _index(layout):
    """(kind, c, k) -> column, with the aliases S k=0 -> SW, S k=n -> control c, N k=0 -> control a."""
    return {(kind, c, k): j for j, (_, kind, c, k) in enumerate(layout)}


def _column(idx, skeleton, segments, kind, c, k):
    if kind == 'S':
        if k == 0:
            return idx[('SWING', c, 0)]
        if k == segments:
            return idx[('CONTROL', c, 0)]
        return idx[('S', c, k)]
    if k == 0:
        return idx[('CONTROL', int(skeleton.parents[c]), 0)]
    return idx[('N', c, k)]


def lbs_weights(model, segments: int):
    """Weights ``(V, J)`` float32 of the LBS rig's bones (:func:`bone_layout` order); rows sum to 1."""
    sk = model.skeleton
    layout = bone_layout(sk, segments)
    idx = _index(layout)
    V = model.num_vertices
    W = np.zeros((V, len(layout)))
    tw = model.twist_weights.astype(np.float64)
    sw = model.swing_weights.astype(np.float64)
    rows = np.arange(V)
    S, T = sw.sum(axis=1), tw.sum(axis=1)
    no_twist = T <= 0
    W[rows[no_twist], model.anchor[no_twist]] += 1.0 - S[no_twist]
    for c in range(1, sk.num_bones):
        alpha = tw[:, c] * segments
        k = np.minimum(np.floor(alpha).astype(int), segments - 1)
        frac = alpha - k
        neutral = np.where(no_twist, 0.0, (1.0 - S) * tw[:, c] / np.where(no_twist, 1.0, T))
        for kind, share in (('S', sw[:, c]), ('N', neutral)):
            live = share > 0
            for kk in np.unique(k[live]):
                sel = live & (k == kk)
                j0 = _column(idx, sk, segments, kind, c, kk)
                j1 = _column(idx, sk, segments, kind, c, kk + 1)
                np.add.at(W, (rows[sel], j0), share[sel] * (1 - frac[sel]))
                np.add.at(W, (rows[sel], j1), share[sel] * frac[sel])
    return layout, W.astype(np.float32)


def _rot_about(R, centre):
    """Affine (R, t) of 'rotate by R (..., 3, 3) about centre (3,)'."""
    return R, centre - np.einsum("...ij,j->...i", R, centre)


def _compose(A, B):
    """(A ∘ B) for affine maps given as (R, t) pairs (broadcasting)."""
    Ra, ta = A
    Rb, tb = B
    return Ra @ Rb, np.einsum("...ij,...j->...i", Ra, tb) + ta


def bone_maps(model, poses, segments: int):
    """Deformation maps ``(Rm (N, J, 3, 3), tm (N, J, 3))`` of the LBS rig's bones for ``poses``."""
    sk = model.skeleton
    layout = bone_layout(sk, segments)
    Rc, tc = forward_kinematics(sk, poses)
    q = quat_canonical(quat_normalize(poses.rotations))
    q_sw, q_tw = swing_twist_y(q)
    angle = 2 * np.arctan2(q_tw[..., 2], q_tw[..., 0])                          # (N, B)
    F = sk.frames
    R_sw = F @ quat_to_matrix(q_sw) @ np.swapaxes(F, -1, -2)                     # (N, B, 3, 3)
    N = len(poses)
    Rm = np.empty((N, len(layout), 3, 3))
    tm = np.empty((N, len(layout), 3))
    for j, (_, kind, c, k) in enumerate(layout):
        if kind == 'CONTROL':
            Rm[:, j], tm[:, j] = Rc[:, c], tc[:, c]
            continue
        a = sk.parents[c]
        phi = angle[:, c] * k / segments
        cos, sin = np.cos(phi), np.sin(phi)
        rot_y = np.zeros((N, 3, 3))
        rot_y[:, 0, 0], rot_y[:, 0, 2], rot_y[:, 1, 1], rot_y[:, 2, 0], rot_y[:, 2, 2] = cos, sin, 1, -sin, cos
        twist = _rot_about(F[c] @ rot_y @ F[c].T, sk.heads[c])
        chain = (Rc[:, a], tc[:, a])
        if kind == 'N':
            Rm[:, j], tm[:, j] = _compose(chain, twist)
        else:
            Rm[:, j], tm[:, j] = _compose(_compose(chain, _rot_about(R_sw[:, c], sk.heads[c])), twist)
    return Rm, tm


def sample_poses(num_bones: int, seed: int, count: int = SAMPLE_POSES):
    """Seeded random poses (``pose_sampling``, twists up to ±:data:`SAMPLE_TWIST_DEG`) for a rig without
    an action: seed :data:`MEASURE_SEED` to measure, :data:`FIT_SEED` to fit limited weights."""
    return pose_sampling.random_poses(count, num_bones, seed=seed, max_twist_deg=SAMPLE_TWIST_DEG)


def _chunks(poses, chunk):
    for n0 in range(0, len(poses), chunk):
        yield type(poses)(poses.rotations[n0:n0 + chunk], poses.translations[n0:n0 + chunk],
                          poses.scales[n0:n0 + chunk])


def limited_weights(model, segments: int, max_influences: int, poses, chunk: int = 16):
    """:func:`lbs_weights` with at most ``max_influences`` bones per vertex (0 = unlimited): on vertices
    with more, the bones and weights that minimise Σ |LBS − hybrid skin|² over ``poses`` (exact; see the
    ``influences`` module).  Returns ``(layout, W (V, J) float32)``, rows summing to 1."""
    from .skinning import hybrid_skin
    if max_influences < 0:
        raise ArticulaInputError(f"max influences must be >= 0 (0 = unlimited), got {max_influences}")
    layout, W = lbs_weights(model, segments)
    if max_influences == 0:
        return layout, W
    rows, cand = influences.candidates(W, max_influences)
    if len(rows) == 0:
        return layout, W
    G = np.zeros(cand.shape + cand.shape[1:])
    rest = model.rest_vertices[rows].astype(np.float64)
    for part in _chunks(poses, chunk):
        Rm, tm = bone_maps(model, part, segments)
        influences.add_gram(G, rest, cand, Rm, tm, hybrid_skin(model, part)[:, rows])
    w = influences.best_weights(G, cand, max_influences)
    out = W.astype(np.float64)
    out[rows] = 0.0
    np.add.at(out, (np.repeat(rows, cand.shape[1]), np.maximum(cand, 0).ravel()),
              np.where(cand >= 0, w, 0.0).ravel())
    return layout, out.astype(np.float32)


def deviation(model, poses, segments: int, chunk: int = 16, weights=None):
    """Per-frame maximum |LBS rig - hybrid skin| in metres ``(N,)`` and the overall mean; ``weights``
    (V, J) replaces :func:`lbs_weights` (e.g. :func:`limited_weights`)."""
    from .skinning import hybrid_skin, lbs
    W = lbs_weights(model, segments)[1] if weights is None else weights
    worst, total, count = [], 0.0, 0
    for part in _chunks(poses, chunk):
        Rm, tm = bone_maps(model, part, segments)
        d = np.linalg.norm(lbs(model.rest_vertices, W, Rm, tm) - hybrid_skin(model, part), axis=2)
        worst.append(d.max(axis=1))
        total += d.sum()
        count += d.size
    return np.concatenate(worst), total / max(count, 1)
