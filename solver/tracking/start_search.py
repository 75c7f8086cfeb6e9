"""The first frame's start hypotheses from any pose and any world orientation (issue 33, build item 3).

The dissertation places the first frame by hand (model-adaptive mocap dissertation §4.1.2); here the
start-pose set (:mod:`.start_poses`) is put on the rig and searched against one capture KD-tree:

1. **Samples**: model vertices spread over the surface (drawn with probability proportional to their
   area), all of them and the trunk's (not anchored in an arm or leg), and capture points.  Nothing
   assumes the world's up: the model's up is its rest body frame's (hips to head), the capture's one
   of its principal axes, both signs (the least one only when its spread is near the middle one's: a
   body is rarely up along its depth).
2. **Orientations**: ``TRUNK_POSES`` trunk shapes of the set (farthest points on the trunk's
   directions), the model's up on each signed principal axis of the capture, ``SPINS`` facings about
   it; placed by the whole body's centroid and ``SHIFTS`` median shifts of the trunk; scored by the mean
   truncated distance of the trunk samples to the capture.  The best ``REFINE`` get a rigid ICP of the
   trunk and are ranked again.
3. **Limbs**: for the best ``RECOMBINE`` distinct orientations, each limb (legs, arms, head) in turn takes
   the direction set, relative to its root joint, of each of the first ``LIMB_CANDIDATES`` start poses
   (or stays), chosen by a robust symmetric score: the mean of ``min(d, TRUNCATE_M)`` from the model
   samples to the capture (the KD-tree) plus from the capture samples to the model samples, so a limb
   where the capture has none costs as much as capture left unexplained (truncated at ``LIMB_TRUNCATE_M``
   there, so a limb far from its capture is still pulled towards it rather than onto the trunk); then
   each thigh, shin, upper arm and forearm in turn is pointed along the best of ``DIRECTIONS`` directions.
   A rigid ICP of the whole body on the pairs of both directions ends it, and the hypotheses are ranked
   by the same score on ``FINAL_SAMPLES`` vertices and points.

:func:`start_hypotheses` returns them best first as one-frame :class:`Poses` in the capture's world.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ..errors import ArticulaInputError
from ..geometry.normals import vertex_areas
from ..geometry.rotations import matrix_to_quat, quat_mul, rotation_between
from ..rig.model import Model, Poses
from ..rig.skinning import hybrid_skin
from .limbs import sphere_directions
from .start_poses import POSE_ROLES, PoseSet, RigPoser, load_pose_set, role_direction

MODEL_SAMPLES = 200      # model vertices scoring a hypothesis
CAPTURE_SAMPLES = 200    # capture points scoring a hypothesis
FINAL_SAMPLES = 800      # model vertices and capture points of the final ranking
SPINS = 12               # turns about the capture's major axis (30 deg apart)
TRUNK_POSES = 12         # trunk shapes tried in the orientation stage
TRUNK_SAMPLES = 48       # trunk vertices scoring an orientation
MINOR_UP = 0.7           # the least principal axis is tried as up when its spread is this near the middle's
COARSE_POINTS = 8000     # capture points of the tree the orientation and limb stages query
SHIFTS = 2               # median shifts placing an orientation
TRUNCATE_M = 0.10        # a distance counts at most this much (metres)
LIMB_TRUNCATE_M = 0.30   # the same in the limb searches: a limb far from its capture still pulls
COARSE_TRUNCATE_M = 0.25 # capture points farther than this do not move an orientation's placement
REFINE = 24              # orientations refined by a rigid ICP of the trunk
ICP_ROUNDS = 6
DISTINCT_DEG = 20.0      # recombined orientations differ by more than this
RECOMBINE = 3            # refined hypotheses whose limbs are recombined
LIMB_CANDIDATES = 48     # start poses whose limbs are tried (the set is in farthest-point order)
DIRECTIONS = 48          # directions tried per segment in the segment search (about 30 deg apart)
PLACING = ("neck", "upper_arm.L", "upper_arm.R", "forearm.L", "forearm.R", "thigh.L", "thigh.R", "shin.L",
           "shin.R")            # joints placing a start whose hips bone starts at the chest
SEGMENT_SEARCH = tuple((f"{a}.{s}", f"{b}.{s}") for s in "LR" for a, b in (
    ("thigh", "shin"), ("shin", "foot"), ("upper_arm", "forearm"), ("forearm", "hand")))
TRUNK_SEGMENTS = (("hips", "chest"), ("chest", "neck"), ("neck", "head.end"), ("upper_arm.R", "upper_arm.L"),
                  ("thigh.R", "thigh.L"))
LIMBS = (("thigh.L", ("thigh.L", "shin.L", "foot.L", "toe.L", "toe.L.end")),
         ("thigh.R", ("thigh.R", "shin.R", "foot.R", "toe.R", "toe.R.end")),
         ("upper_arm.L", ("upper_arm.L", "forearm.L", "hand.L", "hand.L.end")),
         ("upper_arm.R", ("upper_arm.R", "forearm.R", "hand.R", "hand.R.end")),
         ("neck", ("neck", "head", "head.end")))


def start_hypotheses(model: Model, points, normals=None, count: int = 8, pose_set: PoseSet = None,
                     seed: int = 0) -> list:
    """``[(Poses (one frame, the capture's world), score (m))]``, best first, at most ``count``: start
    hypotheses of ``model`` on the capture ``points (N, 3)`` (metres; ``normals`` are accepted for the
    caller's convenience and not used).  ``pose_set``: the start poses (default: the shipped set)."""
    points = _check(points, count)
    pose_set = load_pose_set() if pose_set is None else pose_set
    rng = np.random.default_rng(seed)
    poser = RigPoser(model.skeleton)
    sample = _Sampled(model, _area_sample(model, MODEL_SAMPLES, rng))
    trunk = _Sampled(model, _area_sample(model, TRUNK_SAMPLES, rng, _trunk_vertices(model, poser)))
    tree = cKDTree(points)
    coarse = cKDTree(points[rng.choice(len(points), min(COARSE_POINTS, len(points)), replace=False)])
    cap = points[rng.choice(len(points), min(CAPTURE_SAMPLES, len(points)), replace=False)]
    shapes = pose_set.take(_trunk_poses(pose_set, TRUNK_POSES))
    bodies = poser.poses(shapes)
    Xt = trunk.posed(bodies)                                   # (T, St, 3) model coordinates
    found = _orientations(Xt, sample.posed(bodies).mean(axis=1), points, coarse, poser.frame[:, 2])
    refined = []
    for _, k, R, t in found[:REFINE]:
        R, t = _icp(Xt[k], None, tree, R, t)
        d = np.minimum(tree.query(Xt[k] @ R.T + t, distance_upper_bound=TRUNCATE_M)[0], TRUNCATE_M)
        refined.append((float(d.mean()), k, R, t))
    refined.sort(key=lambda item: item[0])
    out = [_recombined(poser, sample, pose_set, shapes.joints[k], R, t, cap, (tree, coarse))
           for _, k, R, t in _distinct(refined, RECOMBINE)]
    final = _Sampled(model, _area_sample(model, FINAL_SAMPLES, rng))
    cap = points[rng.choice(len(points), min(FINAL_SAMPLES, len(points)), replace=False)]
    out = [(_score(final.posed(body)[0] @ R.T + t, cap, tree), body, R, t) for _, body, R, t in out]
    out.sort(key=lambda item: item[0])
    return [(_placed(model.skeleton, body, R, t), float(s)) for s, body, R, t in out[:count]]


def recombined_start(model: Model, poser: RigPoser, joints, points, pose_set: PoseSet = None,
                     seed: int = 0) -> Poses:
    """One-frame :class:`Poses` of ``model`` from ``joints (R, 3)``: the :data:`POSE_ROLES` joints
    estimated on the capture ``points (N, 3)`` (its world, metres), put on the rig by ``poser`` and each
    limb then searched as the start poses' are (:func:`_recombined`); placed by its hips joint, or by the
    joints of :data:`PLACING` when its hips bone does not carry the chest (a learned rig's starts there)."""
    ix = POSE_ROLES.index
    placing = ("hips",) if poser.carries_chest else PLACING
    rows, bones = (np.array(x) for x in zip(*[(ix(r), poser.roles[r]) for r in placing]))
    origin = joints[ix("hips")] if poser.carries_chest else 0.5 * (joints[ix("thigh.L")] + joints[ix("thigh.R")])
    up = _unit_vector(joints[ix("neck")] - origin)
    left = joints[ix("thigh.L")] - joints[ix("thigh.R")]
    left = _unit_vector(left - up * (left @ up))
    frame = np.stack([left, np.cross(up, left), up], axis=1)           # columns left, back, up
    height = float(np.ptp(model.rest_vertices @ poser.frame[:, 2]))
    body = (joints - origin) @ frame / height
    R = frame @ poser.frame.T
    _, H = poser.world(_as_set(body[None]))
    t = (joints[rows] - H[0, bones] @ R.T).mean(axis=0)
    rng = np.random.default_rng(seed)
    points = _check(points, 1)
    sample = _Sampled(model, _area_sample(model, MODEL_SAMPLES, rng))
    coarse = cKDTree(points[rng.choice(len(points), min(COARSE_POINTS, len(points)), replace=False)])
    cap = points[rng.choice(len(points), min(CAPTURE_SAMPLES, len(points)), replace=False)]
    pose_set = load_pose_set() if pose_set is None else pose_set
    _, pose, R, t = _recombined(poser, sample, pose_set, body, R, t, cap, (cKDTree(points), coarse))
    return _placed(model.skeleton, pose, R, t)


def _unit_vector(v):
    return v / max(float(np.linalg.norm(v)), 1e-12)


def _distinct(found, count) -> list:
    """The first ``count`` of ``found [(score, k, R, t)]`` whose rotations differ from every earlier one's
    by more than ``DISTINCT_DEG``."""
    out = []
    for item in found:
        if all(np.trace(item[2].T @ o[2]) < 1 + 2 * np.cos(np.radians(DISTINCT_DEG)) for o in out):
            out.append(item)
        if len(out) == count:
            break
    return out


def _check(points, count):
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3 or len(points) < 50:
        raise ArticulaInputError(f"start search: the capture needs at least 50 points (N, 3), got {points.shape}")
    if not np.isfinite(points).all():
        raise ArticulaInputError("start search: the capture has NaN or infinite coordinates")
    if int(count) != count or count < 1:
        raise ArticulaInputError(f"start search: count must be a positive integer, got {count}")
    return points


def _area_sample(model, n, rng, mask=None) -> np.ndarray:
    """Indices of ``n`` distinct vertices (among ``mask (V,)`` if given) drawn with probability
    proportional to their area (a third of their triangles'), so dense hands and faces do not outweigh
    the body."""
    v = model.rest_vertices
    w = vertex_areas(v, model.faces) + 1e-12
    if mask is not None:
        w = w * mask
    return np.sort(rng.choice(len(v), min(n, int(np.count_nonzero(w))), replace=False, p=w / w.sum()))


def _trunk_vertices(model, poser) -> np.ndarray:
    """``(V,)`` bool: vertices anchored outside the arms and legs (from the thighs and upper arms down)."""
    below = poser.below
    limbs = np.zeros(model.skeleton.num_bones, dtype=bool)
    for role in ("thigh.L", "thigh.R", "upper_arm.L", "upper_arm.R"):
        limbs |= below[poser.roles[role]]
    return ~limbs[model.anchor]


def _trunk_poses(pose_set, count) -> np.ndarray:
    """Indices of ``count`` start poses whose trunks differ most (farthest points on the directions of
    the hips-chest-neck-head line and the shoulder line), the first pose first."""
    f = np.concatenate([role_direction(pose_set.joints, a, b) for a, b in TRUNK_SEGMENTS], axis=1)
    chosen = [0]
    d = np.linalg.norm(f - f[0], axis=1)
    while len(chosen) < min(count, len(f)):
        chosen.append(int(np.argmax(d)))
        d = np.minimum(d, np.linalg.norm(f - f[chosen[-1]], axis=1))
    return np.array(chosen)


class _Sampled:
    """The model restricted to sample vertices ``index`` (skinning only those)."""

    def __init__(self, model, index):
        self.anchor = model.anchor[index]
        self.sub = Model(model.rest_vertices[index], np.zeros((0, 3), np.int32), model.skeleton,
                         model.anchor[index], model.twist_weights[index], model.swing_weights[index])

    def rigid(self, world, mask) -> np.ndarray:
        """``(P, M, 3)`` the samples where ``mask (S,)``, each carried rigidly by its anchor part in the
        posed rig ``world = (W (P, B, 3, 3), H (P, B, 3))`` (:meth:`.RigPoser.world`): the hybrid skin's
        blending near the joints left out, which the limb searches' scores do not need."""
        W, H = world
        a, sk = self.anchor[mask], self.sub.skeleton
        y = np.einsum("sji,sj->si", sk.frames[a], self.sub.rest_vertices[mask] - sk.heads[a])
        return np.einsum("psij,sj->psi", W[:, a], y) + H[:, a]

    def posed(self, poses: Poses, mask=None) -> np.ndarray:
        """``(N, S, 3)`` the samples (those where ``mask (S,)``, if given) in each of ``poses``."""
        if mask is None:
            return hybrid_skin(self.sub, poses)
        m = self.sub
        return hybrid_skin(Model(m.rest_vertices[mask], m.faces, m.skeleton, m.anchor[mask],
                                 m.twist_weights[mask], m.swing_weights[mask]), poses)


def _axes(X):
    """Centroid ``(3,)``, principal axes ``(3, 3)`` (columns, major last) and spreads ``(3,)`` of ``X (N, 3)``."""
    c = X.mean(axis=-2)
    Y = X - c[..., None, :]
    w, V = np.linalg.eigh(np.swapaxes(Y, -1, -2) @ Y / X.shape[-2])
    return c, V, np.sqrt(np.maximum(w, 1e-12))


def _spin(axis, angles):
    """``(A, 3, 3)`` rotations by ``angles (A,)`` about unit ``axis (3,)``."""
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    s, c = np.sin(angles)[:, None, None], np.cos(angles)[:, None, None]
    return np.eye(3) + s * K + (1 - c) * (K @ K)


def _orientations(Xt, centres, points, tree, up) -> list:
    """``[(score, trunk pose, R, t)]``, best first: every trunk pose ``Xt (T, S, 3)`` (model coordinates)
    with the model's ``up (3,)`` on each signed principal axis of the capture, turned ``SPINS`` times
    about it, placed (the whole body's centroid ``centres (T, 3)`` on the capture's, then ``SHIFTS``
    median shifts) and scored by the mean truncated distance of its samples to the capture."""
    cc, Vc, spread = _axes(points)
    keep = [2, 1] + ([0] if spread[0] > MINOR_UP * spread[1] else [])      # the depth axis is up rarely
    axes = np.concatenate([Vc.T[keep], -Vc.T[keep]])
    R = np.concatenate([_spin(u, 2 * np.pi * np.arange(SPINS) / SPINS) @ rotation_between(up, u) for u in axes])
    T = len(Xt)
    R = np.repeat(R[None], T, axis=0).reshape(-1, 3, 3)
    pose = np.repeat(np.arange(T), len(axes) * SPINS)
    Y = np.einsum("hij,hsj->hsi", R, Xt[pose])
    t = cc - np.einsum("hij,hj->hi", R, centres[pose])
    for _ in range(SHIFTS):
        d, i = tree.query((Y + t[:, None]).reshape(-1, 3), distance_upper_bound=COARSE_TRUNCATE_M)
        near = np.where(np.isfinite(d)[:, None], tree.data[np.minimum(i, len(tree.data) - 1)], np.nan).reshape(Y.shape)
        step = np.nanmedian(near - Y - t[:, None], axis=1)
        t += np.nan_to_num(step)
    d = np.minimum(tree.query((Y + t[:, None]).reshape(-1, 3), distance_upper_bound=TRUNCATE_M)[0], TRUNCATE_M)
    scores = d.reshape(Y.shape[:2]).mean(axis=1)
    return [(float(scores[h]), int(pose[h]), R[h], t[h]) for h in np.argsort(scores)]


def _scores(Y, cap, tree, truncate: float = TRUNCATE_M) -> np.ndarray:
    """``(H,)`` robust symmetric scores of posed samples ``Y (H, S, 3)`` against the capture (metres)."""
    d_model = np.minimum(tree.query(Y.reshape(-1, 3), distance_upper_bound=truncate)[0], truncate)
    d_cap = np.minimum(np.sqrt(_nearest_sq(cap, Y)), truncate)
    return d_model.reshape(Y.shape[:2]).mean(axis=1) + d_cap.mean(axis=1)


def _score(Y, cap, tree) -> float:
    return float(_scores(Y[None], cap, tree)[0])


def _icp(X, cap, tree, R, t, rounds: int = ICP_ROUNDS):
    """Rigid ICP of model samples ``X (S, 3)`` (model coordinates) on the capture from ``(R, t)``: Kabsch
    on the pairs closer than ``TRUNCATE_M``, model to capture and, when ``cap`` is given, capture samples
    to the model."""
    for _ in range(rounds):
        Y = X @ R.T + t
        d, i = tree.query(Y, distance_upper_bound=TRUNCATE_M)
        ok = np.isfinite(d)
        src, dst = X[ok], tree.data[i[ok]]
        if cap is not None:
            j = np.argmin(((cap[:, None] - Y[None]) ** 2).sum(axis=2), axis=1)
            near = np.linalg.norm(cap - Y[j], axis=1) < TRUNCATE_M
            src, dst = np.concatenate([src, X[j[near]]]), np.concatenate([dst, cap[near]])
        if len(src) < 10:
            break
        ms, md = src.mean(axis=0), dst.mean(axis=0)
        U, _, Vt = np.linalg.svd((dst - md).T @ (src - ms))
        R = U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt
        t = md - R @ ms
    return R, t


def _recombined(poser, sample, pose_set, joints, R, t, cap, trees):
    """``(score, Poses, R, t)``: pose ``joints (R, 3)`` placed by ``(R, t)`` with each limb (:data:`LIMBS`)
    in turn given the direction set, relative to its root joint, of the first ``LIMB_CANDIDATES`` start
    poses (or kept), each choice by the symmetric score (on the ``coarse`` tree of ``trees = (tree,
    coarse)``); then the segment search and a rigid ICP of the whole body."""
    tree, coarse = trees
    tried = pose_set.take(slice(0, LIMB_CANDIDATES))
    joints = joints.copy()
    Y = sample.posed(_one(poser, joints))[0] @ R.T + t
    base = [x[0] for x in poser.world(_as_set(joints[None]))]
    for root, roles in LIMBS:
        cols, r = [POSE_ROLES.index(x) for x in roles], POSE_ROLES.index(root)
        cand = np.repeat(joints[None], len(tried) + 1, axis=0)
        cand[1:, cols] = tried.joints[:, cols] - tried.joints[:, r:r + 1] + joints[r]
        joints, base = _best_limb(poser, sample, root, cand, base, Y, R, t, cap, coarse)
    joints = _aim_segments(poser, sample, joints, base, Y, R, t, cap, coarse)
    body = _one(poser, joints)
    X = sample.posed(body)[0]
    R, t = _icp(X, cap, tree, R, t)
    return _score(X @ R.T + t, cap, tree), body, R, t


def _best_limb(poser, sample, root, cand, base, Y, R, t, cap, tree):
    """``(joints, base)`` of the candidate poses ``cand (H, R, 3)`` (differing in the limb below role
    ``root``) whose samples score best, ``Y (S, 3)`` (the placed samples) updated in place; ``base``:
    the rig's world pose ``[W (B, 3, 3), H (B, 3)]`` of the current joints, also kept for the others."""
    if root not in poser.roles:
        return cand[0], base
    below = poser.below[poser.roles[root]]
    limb = below[sample.anchor]
    if not limb.any():
        return cand[0], base
    W, H = poser.world(_as_set(cand), base, below)
    Yl = sample.rigid((W, H), limb) @ R.T + t
    k = int(np.argmin(_limb_scores(Y[~limb], Yl, cap, tree)))
    Y[limb] = Yl[k]
    return cand[k], [W[k], H[k]]


def _as_set(joints) -> PoseSet:
    return PoseSet(joints, np.zeros(len(joints)), np.zeros(len(joints)))


def _aim_segments(poser, sample, joints, base, Y, R, t, cap, tree):
    """``joints`` with each segment of :data:`SEGMENT_SEARCH` in turn pointed along the best of
    ``DIRECTIONS`` directions spread over the sphere (or kept), the joints below it turning with it about
    its joint; each choice by the symmetric score (``Y (S, 3)``, the samples as placed, is updated)."""
    for a, b in SEGMENT_SEARCH:
        if a not in poser.roles:
            continue
        moved = [POSE_ROLES.index(r) for r in _below_role(b)]
        ia = POSE_ROLES.index(a)
        now = joints[POSE_ROLES.index(b)] - joints[ia]
        G = rotation_between(now / np.linalg.norm(now), sphere_directions(DIRECTIONS))   # (D, 3, 3)
        cand = np.repeat(joints[None], len(G) + 1, axis=0)
        cand[1:, moved] = np.einsum("dij,mj->dmi", G, joints[moved] - joints[ia]) + joints[ia]
        joints, base = _best_limb(poser, sample, a, cand, base, Y, R, t, cap, tree)
    return joints


def _below_role(role: str) -> list:
    """Pose roles of ``role``'s chain from it to the end (``shin.L`` → shin, foot, toe, toe end)."""
    for _, roles in LIMBS:
        if role in roles:
            return list(roles[roles.index(role):])
    return [role]


def _one(poser, joints) -> Poses:
    return poser.poses(_as_set(joints[None]))


def _limb_scores(fixed, Yl, cap, tree, truncate: float = LIMB_TRUNCATE_M) -> np.ndarray:
    """``(H,)`` the symmetric score (:func:`_scores`, truncated at ``truncate``) of the samples ``fixed
    (F, 3)`` with each of the limb's sample sets ``Yl (H, L, 3)``, from the limb's distances only."""
    S = len(fixed) + Yl.shape[1]
    d_fixed = np.minimum(tree.query(fixed, distance_upper_bound=truncate)[0], truncate).sum()
    d_limb = np.minimum(tree.query(Yl.reshape(-1, 3), distance_upper_bound=truncate)[0], truncate)
    out = (d_fixed + d_limb.reshape(Yl.shape[:2]).sum(axis=1)) / S
    to_fixed = _nearest_sq(cap, fixed[None])[0] if len(fixed) else np.full(len(cap), np.inf)
    to_limb = _nearest_sq(cap, Yl)
    return out + np.minimum(np.sqrt(np.minimum(to_limb, to_fixed[None])), truncate).mean(axis=1)


def _nearest_sq(cap, Y) -> np.ndarray:
    """``(H, C)`` squared distance of each capture sample ``cap (C, 3)`` to the nearest of ``Y (H, S, 3)``."""
    out = np.empty((len(Y), len(cap)))
    cc = (cap * cap).sum(axis=1)
    for h0 in range(0, len(Y), 256):
        block = Y[h0:h0 + 256]
        d2 = cc[None, :, None] + (block * block).sum(axis=2)[:, None, :] - 2.0 * (cap @ np.swapaxes(block, 1, 2))
        out[h0:h0 + 256] = np.maximum(d2.min(axis=2), 0.0)
    return out


def _placed(sk, body: Poses, G, offset) -> Poses:
    """``body`` (one frame, model coordinates, translation 0) moved rigidly: x -> ``G x + offset``."""
    F0, h0 = sk.frames[0], sk.heads[0]
    rot = body.rotations.copy()
    rot[:, 0] = quat_mul(matrix_to_quat(F0.T @ G @ F0)[None], rot[:, 0])
    trans = (G @ h0 + offset - h0)[None] + body.translations @ G.T
    return Poses(rot, trans, body.scales.copy())

