"""Start poses: a broad set of body poses stored without any rig, and their transfer onto any rig by
segment direction.

A pose of the set (``data/start_poses.npz``, built by ``tools/make_start_poses.py`` from CMU clips and
MPFB2's walk cycle) is the position of every role joint of :data:`POSE_ROLES` (:mod:`solver.roles`; plus
the ends of head, hands and toes), relative to the hips joint, in the body's own frame (columns left,
back, up: up = the world up of the source, left = right thigh joint to left, level), in body heights.
The direction from one role joint to another is what transfers: a learned rig's rest pose and root differ
from the source's, so conjugating rotations by rest frames does not carry a pose over (issue 33).

Onto a rig (:class:`RigPoser`): the rig's roles come from its bone names (:func:`solver.roles.role_bones`;
MPFB/CMU/Unreal/Rigify namings and Articula's role names, which learned rigs get); each role's segment and
the bone that aims it are retargeting's (:func:`solver.retarget.directions.plan_segments`, reversed
chains of chest-rooted learned rigs included).  Top-down, every bone is carried by its parent at its rest
relation, then the aiming bone turns by the smallest rotation that points its segment along the pose's
direction (an end role: the bone's own head-to-tail axis, towards the end point); the hips and the chest
then twist about their segment so the thigh joints (shoulder joints) lie as the pose's do (the pelvis of
a chest-rooted rig: :meth:`RigPoser._pelvis`).  The pose's
body frame is put on the rig's rest body frame (:func:`solver.retarget.directions.body_frame`).
"""
from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from ..errors import ArticulaInputError
from ..geometry.rotations import matrix_to_quat, rotation_between
from ..retarget.armature import ArmatureRest
from ..retarget.directions import body_frame, plan_segments
from ..rig.model import Poses
from ..roles import NEXT, mirror, role_bones

START_POSES_PATH = os.path.join(os.path.dirname(os.path.abspath(__file__)), "data", "start_poses.npz")
FORMAT = "articula-start-poses/1"
SIDED = ("shoulder", "upper_arm", "forearm", "hand", "hand.end", "hip", "thigh", "shin", "foot", "toe", "toe.end")
POSE_ROLES = ("hips", "spine", "chest", "neck", "head", "head.end") + tuple(
    f"{r[:-4]}.{s}.end" if r.endswith(".end") else f"{r}.{s}" for s in ("L", "R") for r in SIDED)
END_PARENT = {r: r[:-4] for r in POSE_ROLES if r.endswith(".end")}
REQUIRED = ("hips", "thigh.L", "thigh.R", "shin.L", "shin.R", "upper_arm.L", "upper_arm.R", "forearm.L",
            "forearm.R")
#: Segments whose directions describe a pose (farthest-point selection, closeness of poses).
FEATURE_SEGMENTS = (("hips", "chest"), ("chest", "neck"), ("neck", "head.end"),
                    ("upper_arm.R", "upper_arm.L")) + tuple(
    (f"{a}.{s}", f"{b}.{s}") for s in ("L", "R") for a, b in (
        ("upper_arm", "forearm"), ("forearm", "hand"), ("thigh", "shin"), ("shin", "foot"))) + (
    ("foot.L", "toe.L.end"), ("foot.R", "toe.R.end"))
DEGENERATE = 0.01        # stored joints closer than this (body heights) give no direction


def mirror_role(role: str) -> str:
    """The pose role on the other side (``hand.L.end`` ↔ ``hand.R.end``)."""
    return mirror(role[:-4]) + ".end" if role.endswith(".end") else mirror(role)


def pose_features(joints) -> np.ndarray:
    """``(P, 3 S)`` unit directions of :data:`FEATURE_SEGMENTS` of poses ``joints (P, R, 3)``."""
    return np.concatenate([role_direction(joints, a, b) for a, b in FEATURE_SEGMENTS], axis=1)


@dataclass
class PoseSet:
    """``joints (P, R, 3)`` positions of :data:`POSE_ROLES` in the body frame (module docstring), body
    heights; ``source (P,)`` index of the source clip and ``frame (P,)`` its frame (for reports)."""
    joints: np.ndarray
    source: np.ndarray
    frame: np.ndarray

    def __len__(self) -> int:
        return len(self.joints)

    def take(self, index) -> "PoseSet":
        return PoseSet(self.joints[index], self.source[index], self.frame[index])


def load_pose_set(path: str = START_POSES_PATH) -> PoseSet:
    """The shipped start poses (module docstring); refuses a file of another format in one line."""
    try:
        with np.load(path, allow_pickle=False) as data:
            if str(data["format"]) != FORMAT or tuple(str(r) for r in data["roles"]) != POSE_ROLES:
                raise ArticulaInputError(f"{path}: not an Articula start-pose set ({FORMAT})")
            return PoseSet(data["joints"].astype(np.float64), data["source"], data["frame"])
    except (OSError, KeyError, ValueError) as exc:
        raise ArticulaInputError(f"{path}: cannot read the start poses ({exc})") from None


@dataclass
class _Aim:
    """Bone ``bone`` turns so that point ``b`` minus point ``a`` points along the pose's ``a`` → ``b``
    (roles ``want``); a point is ``(bone, 0 = head | 1 = tail)``.  ``lateral`` (roles A, B), or None: then
    it twists about that direction towards the pose's A → B (from the bone's joint when A does not turn
    with it)."""
    bone: int
    a: tuple
    b: tuple
    want: tuple
    lateral: tuple | None = None


class RigPoser:
    """Start poses onto one rig (module docstring).  ``roles {role: bone}``, ``frame (3, 3)`` the rig's rest
    body frame (columns left, back, up) in model coordinates."""

    def __init__(self, skeleton):
        self.sk = skeleton
        self.roles = role_bones(skeleton.names)
        missing = [r for r in REQUIRED if r not in self.roles]
        if missing:
            raise ArticulaInputError("start poses: the rig has no bone for the role(s) " + ", ".join(missing)
                                     + " (bones named by role, or an MPFB, CMU, Mixamo, Unreal or Rigify rig)")
        arm = _armature(skeleton)
        names = skeleton.names
        segs = plan_segments(arm, arm, {r: (names[b], names[b]) for r, b in self.roles.items()})
        self.frame = body_frame(skeleton.heads, segs, "target")
        self.below = subtree_masks(skeleton.parents)
        roles = self.roles
        self.carries_chest = "chest" in roles and bool(self.below[roles["hips"]][roles["chest"]])
        self.aims = self._aims(segs)

    def _aims(self, segs) -> dict:
        """``{bone: _Aim}``: a segment's aim where retargeting aims it, else the role's own bone by its
        axis; the hips' and chest's aims get their twist pair."""
        out, by = {}, self.roles
        for seg in segs:
            if seg.role not in POSE_ROLES:
                continue
            if seg.child in POSE_ROLES and seg.aim >= 0:
                out.setdefault(seg.aim, _Aim(seg.aim, (seg.target, 0), (seg.target_child, 0), (seg.role, seg.child)))
            elif seg.child is not None and seg.aim == seg.target and seg.role + ".end" in POSE_ROLES:
                out.setdefault(seg.aim, _Aim(seg.aim, (seg.target, 0), (seg.target_child, 0),
                                             (seg.role, seg.role + ".end")))       # a hand aimed at its fingers
        aimed = {a.want for a in out.values()}
        for seg in segs:
            if seg.target not in out and seg.role in POSE_ROLES and (seg.role, seg.child) not in aimed:
                end = next((r for r in [seg.role + ".end"] + NEXT.get(seg.role, []) if r in POSE_ROLES), None)
                if end is not None:
                    out[seg.target] = _Aim(seg.target, (seg.target, 0), (seg.target, 1), (seg.role, end))
        self._pelvis(out)
        for role, pair in (("hips", ("thigh.R", "thigh.L")), ("chest", ("shoulder.R", "shoulder.L")),
                           ("chest", ("upper_arm.R", "upper_arm.L"))):
            aim = out.get(by[role]) if role in by else None
            aim = aim if aim is not None else next((a for a in out.values() if a.want[0] == role), None)
            if aim is not None and aim.lateral is None and all(r in by for r in pair):
                aim.lateral = pair
        return out

    def _pelvis(self, out) -> None:
        """The hips bone's aim: at the chest joint when it carries the chest (a CMU clip's spine joint is its
        hips joint, and a rig's short lumbar segment would tilt the pelvis); when it hangs from the spine
        (a learned rig rooted at the chest), along the thigh line, turned about it by the thigh seen from
        the bone's joint (as from the spine's, or the chest's, joint in the pose)."""
        by, hips = self.roles, self.roles["hips"]
        aim = out.get(hips)
        if aim is not None and aim.want[0] == "hips" and self.carries_chest:
            aim.b, aim.want = (by["chest"], 0), ("hips", "chest")
        elif aim is None or aim.want[0] != "hips" or not self.carries_chest:      # its own axis may point down
            above = next((r for r in ("spine", "chest") if r in by and not self.below[hips][by[r]]), None)
            if above is not None:
                out[hips] = _Aim(hips, (by["thigh.R"], 0), (by["thigh.L"], 0), ("thigh.R", "thigh.L"),
                                 (above, "thigh.L"))

    def poses(self, pose_set: PoseSet) -> Poses:
        """``Poses (P, B)`` of the rig in each pose of ``pose_set``: root rotation in model coordinates
        (the pose's up along the rig's rest up), translation 0, scale 1."""
        W, _ = self.world(pose_set)
        F, parents = self.sk.frames, self.sk.parents
        local = np.empty_like(W)
        local[:, 0] = F[0].T @ W[:, 0]
        carried = W[:, parents[1:]] @ (np.swapaxes(F[parents[1:]], -1, -2) @ F[1:])
        local[:, 1:] = np.swapaxes(carried, -1, -2) @ W[:, 1:]
        return Poses(matrix_to_quat(local), np.zeros((len(W), 3)), np.ones(len(W)))

    def world(self, pose_set: PoseSet, base=None, only=None):
        """World bone rotations ``W (P, B, 3, 3)`` (columns: the bone's axes; ``W_b = Rm_b F_b``) and joint
        positions ``H (P, B, 3)`` of the posed rig, model coordinates.  ``base (W, H)`` of one pose and
        ``only (B,)`` bool: bones outside ``only`` keep ``base`` (faster when a limb alone changes)."""
        sk = self.sk
        J = pose_set.joints @ self.frame.T                     # (P, R, 3) model coordinates
        P, B = len(J), sk.num_bones
        F, h = sk.frames, sk.heads
        W, H = np.empty((P, B, 3, 3)), np.empty((P, B, 3))
        bones = range(B) if only is None else np.flatnonzero(only)
        if only is not None:
            W[:], H[:] = base[0], base[1]
        for b in bones:
            p = sk.parents[b]
            W[:, b] = np.broadcast_to(F[b], (P, 3, 3)) if p < 0 else W[:, p] @ (F[p].T @ F[b])
            H[:, b] = h[b] if p < 0 else H[:, p] + (W[:, p] @ (F[p].T @ (h[b] - h[p])))
            if b in self.aims:
                W[:, b] = self._aimed(self.aims[b], W, H, J, b)
        return W, H

    def _point(self, W, H, b, point):
        """Posed ``point`` (bone, head|tail) ``(P, 3)``: carried by its nearest ancestor already posed (bones
        ``<= b``)."""
        j, tail = point
        x = self.sk.tails[j] if tail else self.sk.heads[j]
        a = j
        while a > b:
            a = int(self.sk.parents[a])
        return H[:, a] + (W[:, a] @ (self.sk.frames[a].T @ (x - self.sk.heads[a])))

    def _aimed(self, aim: _Aim, W, H, J, b):
        """World rotation ``(P, 3, 3)`` of bone b after its aim (and twist)."""
        want = role_direction(J, *aim.want)
        moves = [self.below[b][aim.a[0]], self.below[b][aim.b[0]]]
        if not any(moves):
            return W[:, b]
        if all(moves):
            u = self._point(W, H, b, aim.b) - self._point(W, H, b, aim.a)
        elif moves[1]:
            u = self._point(W, H, b, aim.b) - H[:, b]
        else:
            u, want = self._point(W, H, b, aim.a) - H[:, b], -want
        R = rotation_between(_unit(u), want) @ W[:, b]
        if aim.lateral is None:
            return R
        Wb = W.copy()
        Wb[:, b] = R
        first, second = (self.roles[s] for s in aim.lateral)
        if not self.below[b][second]:
            return R
        start = self._point(Wb, H, b, (first, 0)) if self.below[b][first] else H[:, b]
        u = self._point(Wb, H, b, (second, 0)) - start
        return _twist_towards(want, u, role_direction(J, *aim.lateral)) @ R


def role_direction(J, a: str, b: str) -> np.ndarray:
    """``(P, 3)`` unit direction from pose role ``a``'s joint to ``b``'s; where they coincide (a CMU hips
    joint on its spine's), to the next joint along ``b``'s chain that is apart."""
    ia = POSE_ROLES.index(a)
    d = J[:, POSE_ROLES.index(b)] - J[:, ia]
    role = b
    while True:
        short = np.linalg.norm(d, axis=1) < DEGENERATE
        nxt = [r for r in NEXT.get(role, []) + [role + ".end"] if r in POSE_ROLES]
        if not short.any() or not nxt:
            return _unit(d)
        role = nxt[0]
        d = np.where(short[:, None], J[:, POSE_ROLES.index(role)] - J[:, ia], d)


def _twist_towards(axis, u, want) -> np.ndarray:
    """``(P, 3, 3)`` rotations about unit ``axis (P, 3)`` turning ``u``'s part across it towards ``want``'s."""
    u = u - np.einsum("pi,pi->p", u, axis)[:, None] * axis
    w = want - np.einsum("pi,pi->p", want, axis)[:, None] * axis
    ang = np.arctan2(np.einsum("pi,pi->p", axis, np.cross(u, w)), np.einsum("pi,pi->p", u, w))
    K = np.zeros(axis.shape + (3,))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -axis[:, 2], axis[:, 1], -axis[:, 0]
    K -= np.swapaxes(K, -1, -2)
    s, c = np.sin(ang)[:, None, None], np.cos(ang)[:, None, None]
    return np.eye(3) + s * K + (1.0 - c) * (K @ K)


def _unit(v):
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)


def _armature(sk) -> ArmatureRest:
    """The skeleton as retargeting's armature (rest matrices = frames and heads, identity object)."""
    B = sk.num_bones
    rest = np.zeros((B, 4, 4))
    rest[:, :3, :3], rest[:, :3, 3], rest[:, 3, 3] = sk.frames, sk.heads, 1.0
    parents = np.asarray(sk.parents, dtype=np.int64)
    connected = np.array([p >= 0 and np.allclose(sk.heads[b], sk.tails[p]) for b, p in enumerate(parents)])
    return ArmatureRest("model", list(sk.names), parents, rest, sk.tails, connected, np.eye(4))


def subtree_masks(parents) -> np.ndarray:
    """``(B, B)`` bool: ``[a, c]`` when bone c is a or below it."""
    B = len(parents)
    out = np.eye(B, dtype=bool)
    for c in range(B - 1, 0, -1):
        out[parents[c]] |= out[c]
    return out
