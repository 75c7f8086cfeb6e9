"""Walk cycle from MPFB2's ``walkcycles/crappy_experimental_female.json``, retargeted to any MPFB2 rig.

Format (see :mod:`.fcurves`): Blender F-curves for the ``default_no_toes`` rig, frames 0-40 (keys every
5 frames, Bezier), one gait cycle in which the root advances 0.78 m along its local +Y (world -Y,
forwards).  Forward-kinematic channels: ``root`` (location + rotation), ``spine01``-``spine05``,
``neck01``, ``head``, ``clavicle.L/R``, ``toe1-1.L/R`` (rotation_euler, XYZ, bone-local).  The limbs are
driven by IK helper bones: ``left/right_foot_ik`` (location + rotation), ``left/right_knee_ik``
(pole), ``left/right_hand_ik`` (location), ``left/right_elbow_ik`` (pole), unparented.

Reconstruction (the IK helper bones are not in the rig files, so their rest placement is an
assumption, documented here): each IK helper rests at the head of the corresponding deform bone
(foot, lower leg, hand) with that bone's orientation, so ``location`` is an offset in that bone's rest
axes.  This reproduces the file's geometry: the stance foot stays within a few cm of the ground, its
stride equals the root's travel (0.78 m), the knee poles stay in front of the knees and the hands
swing at hip height.  The elbow poles are not used (their placement is not recoverable): elbows bend
in the plane that holds a point 0.3 m behind and slightly outside the shoulder-hand midpoint.
Hand orientation stays at rest relative to the forearm.  The hand targets and elbow poles move with
the root (their offsets do not advance with the gait, unlike the foot targets and knee poles, which
are world-space).  The file's stance feet hover about 2 cm above the rest ankle height; the whole
motion is lowered by that constant (:func:`ground_offset`, computed over the full cycle); the file's
foot pitch still lets toes or heels dip below / hover above z = 0 by up to about 3.5 cm in some frames.

Retargeting (the source and target rigs sit on the same body, so world-axis rest-relative rotations
transfer): root, neck, head, clavicles and toes copy the world rotation of the file's bone; the
file's five-bone spine rotation is composed and split evenly (same world rotation vector / S) over
the target's S spine bones between the root and the neck that do not carry the legs.  Arms and legs
are solved by analytic two-bone IK on the target's own segments (:func:`_solve_limb`): the knee
(elbow) is a pure hinge about its anatomical axis (:func:`.bone_roles.hinge_geometry`) bent so the
limb spans the hip-target distance, then the thigh (upper arm) turns the limb onto the target and
twists about it to put the knee (elbow) towards the pole; the ankle (wrist) reaches the target
exactly when it is within reach.  The foot takes the IK target's orientation.  Twist segments stay at rest.  Location
offsets are scaled by the subject's leg length over the file's (0.764 m).

Timing: frame ``f_i = phase + i * step`` of the 40-frame cycle (24 fps in Blender: 0.47 m/s);
``phase`` is drawn from ``seed``.  The root keeps advancing over repeated cycles.  Optional heading
``root_yaw`` (degrees, drawn uniformly in [-root_yaw, root_yaw] once per sequence, about world Z) and
start offset ``root_shift`` (metres, horizontal).
"""
from __future__ import annotations

import json
from functools import lru_cache

import numpy as np

from ..solver.errors import ArticulaInputError
from ..solver.rig.kinematics import chain_from_world
from ..solver.rig.model import Poses
from ..solver.geometry.rotations import matrix_to_quat
from .assets import ensure_assets
from .bone_roles import hinge_geometry, skeleton_roles
from .fcurves import channel_curves, euler_xyz_to_matrix, evaluate
from .mpfb_rig import _axis_angle_matrices

WALK_FILE = "crappy_experimental_female.json"
CYCLE_FRAMES = 40.0
SOURCE_SPINE = ("spine05", "spine04", "spine03", "spine02", "spine01")
ELBOW_POLE_DISTANCE = 0.3


@lru_cache(maxsize=1)
def load_walk() -> tuple[dict, dict]:
    """(animation_data, metadata) of the walk-cycle file."""
    path = ensure_assets(verbose=False) / "walkcycles" / WALK_FILE
    data = json.loads(path.read_text())
    return data["animation_data"], data.get("metadata", {})


def _euler(bone, frames):
    """(N, 3, 3) local rotations of a file bone (identity if it has no rotation keys)."""
    curves = channel_curves(load_walk()[0].get(bone, {}), "rotation_euler", bone)
    if curves is None:
        return np.tile(np.eye(3), (len(frames), 1, 1))
    return euler_xyz_to_matrix(evaluate(curves, frames))


def _location(bone, frames, cycles):
    """(N, 3) local location offsets of a file bone, advanced by whole cycles (locomotion)."""
    curves = channel_curves(load_walk()[0][bone], "location", bone)
    loc = evaluate(curves, frames)
    per_cycle = evaluate(curves, np.array([CYCLE_FRAMES])) - evaluate(curves, np.array([0.0]))
    return loc + cycles[:, None] * per_cycle


def _to_world(F, R_local):
    return F @ R_local @ F.T


def _local_quat(F, R_world):
    return matrix_to_quat(F.T @ R_world @ F)


def _shortest_arc(a, b):
    """(N, 3, 3) rotations taking unit directions a to b (N, 3)."""
    axis = np.cross(a, b)
    s = np.linalg.norm(axis, axis=1)
    angle = np.arctan2(s, np.einsum("ni,ni->n", a, b))
    axis = axis / np.maximum(s, 1e-12)[:, None]
    return _axis_angle_matrices(axis, angle)


def _signed_angle(a, b, n):
    """Angle (N,) from a to b about unit axes n (N, 3), after projecting a, b on the plane of n."""
    return np.arctan2(np.einsum("ni,ni->n", np.cross(a, b), n), np.einsum("ni,ni->n", a, b))


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


class _Retarget:
    """Source (default rig) and target skeletons on the same body, with bone lookups."""

    def __init__(self, target, source):
        self.t, self.s = target, source
        self.roles = skeleton_roles(target.names)
        self.src_index = {n: i for i, n in enumerate(source.names)}
        self.hinge_axes, _ = hinge_geometry(target, self.roles)

    def src_frame(self, name):
        return self.s.frames[self.src_index[name]]

    def src_head(self, name):
        return self.s.heads[self.src_index[name]]

    def side_bones(self, role, side):
        return [b for b, r in enumerate(self.roles) if r == role and self.t.names[b].endswith("." + side)]

    def first(self, role, side=None):
        bones = self.side_bones(role, side) if side else [b for b, r in enumerate(self.roles) if r == role]
        if not bones:
            raise ArticulaInputError(f"walk: the rig has no {role} bone{' on side ' + side if side else ''}")
        return bones[0]

    def ancestors(self, b):
        out = []
        while b >= 0:
            out.append(b)
            b = self.t.parents[b]
        return out

    def spine_bones(self):
        neck = self.first("neck") if "neck" in self.roles else self.first("head")
        legs = {a for b, r in enumerate(self.roles) if r == "hip" for a in self.ancestors(b)}
        return [b for b in reversed(self.ancestors(self.t.parents[neck])) if b != 0 and b not in legs]


def _hinge_angle(c_upper, c_lower, k, d):
    """Hinge angles (N,) about unit k (3,) with |c_upper + R(k, phi) c_lower| = d (N,), on the flexing side.

    With Rodrigues, c_upper . R c_lower = alpha cos(phi) + beta sin(phi) + kappa; the straightest angle
    is atan2(beta, alpha) and a positive offset from it bends the joint.  Unreachable d are clamped."""
    ku, kl = k @ c_upper, k @ c_lower
    alpha, beta, kappa = c_upper @ c_lower - ku * kl, c_upper @ np.cross(k, c_lower), ku * kl
    gamma = 0.5 * (d * d - c_upper @ c_upper - c_lower @ c_lower) - kappa
    amp = np.hypot(alpha, beta)
    return np.arctan2(beta, alpha) + np.arccos(np.clip(gamma / amp, -1.0, 1.0))


def _solve_limb(rt, rot_world, Rm, upper, middle, end, H, A, P):
    """Set the world-axis rest rotations of ``upper`` and ``middle`` (in place) so that the head of
    ``end`` reaches A exactly (when reachable) with the middle joint on the side of the pole P.

    The middle joint is a hinge about its anatomical axis (:func:`.bone_roles.hinge_geometry`) bent
    so the limb spans |A - H|; the upper bone then takes the shortest-arc rotation onto A - H and a
    twist about it that turns the middle joint towards P.  rot_world (N, B, 3, 3) rest-world-axis
    rotations; Rm (N, B, 3, 3) posed chain rotations of the bones above the limb."""
    sk = rt.t
    G_p = Rm[:, sk.parents[upper]]
    c_upper = sk.heads[middle] - sk.heads[upper]
    c_lower = sk.heads[end] - sk.heads[middle]
    k = sk.frames[middle] @ rt.hinge_axes[middle]
    phi = _hinge_angle(c_upper, c_lower, k, np.linalg.norm(A - H, axis=1))
    R_mid = _axis_angle_matrices(np.tile(k, (len(phi), 1)), phi)
    limb = c_upper + np.einsum("nij,j->ni", R_mid, c_lower)
    u = _unit(A - H)
    Q = _shortest_arc(_unit(np.einsum("nij,nj->ni", G_p, limb)), u)
    knee = np.einsum("nij,njk,k->ni", Q, G_p, c_upper)
    to_pole = P - H
    psi = _signed_angle(knee - np.einsum("ni,ni->n", knee, u)[:, None] * u,
                        to_pole - np.einsum("ni,ni->n", to_pole, u)[:, None] * u, u)
    G_upper = _axis_angle_matrices(u, psi) @ Q @ G_p
    rot_world[:, upper] = np.swapaxes(G_p, 1, 2) @ G_upper
    rot_world[:, middle] = R_mid
    return G_upper @ R_mid


def _source_skeleton(subject):
    from .subjects import make_subject
    return make_subject("default", subject.macros).skeleton


def _heading(yaw):
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def walk_poses(subject, n: int, seed: int = 0, step: float = 1.0, root_yaw: float = 0.0,
               root_shift: float = 0.0) -> Poses:
    """``n`` walk-cycle poses of ``subject`` (a :class:`.subjects.Subject`), see the module docstring."""
    if int(n) != n or n < 1:
        raise ArticulaInputError(f"poses: the number of poses must be a positive integer, got {n}")
    if not 0 < step <= CYCLE_FRAMES:
        raise ArticulaInputError(f"step: frames per pose must be in (0, {CYCLE_FRAMES:g}], got {step}")
    if not 0 <= root_yaw <= 180 or root_shift < 0:
        raise ArticulaInputError(f"root_yaw must be in [0, 180] and root_shift >= 0 (got {root_yaw}, {root_shift})")
    rng = np.random.default_rng(seed)
    f = rng.uniform(0, CYCLE_FRAMES) + step * np.arange(n)
    cycles, frames = np.floor(f / CYCLE_FRAMES), np.mod(f, CYCLE_FRAMES)
    G = _heading(np.radians(rng.uniform(-root_yaw, root_yaw)))
    shift = np.append(rng.uniform(-root_shift, root_shift, 2), 0.0)
    rt = _Retarget(subject.skeleton, _source_skeleton(subject))
    return _pose(rt, subject, frames, cycles, G, shift)


def _scale(rt):
    legs = [rt.first(r, "L") for r in ("hip", "knee", "ankle")]
    h = rt.t.heads[legs]
    return (np.linalg.norm(h[1] - h[0]) + np.linalg.norm(h[2] - h[1])) / load_walk()[1].get("leg_length", 0.764)


def _pose(rt, subject, frames, cycles, G, shift):
    sk, N = rt.t, len(frames)
    scale = _scale(rt)
    rot_world = np.tile(np.eye(3), (N, sk.num_bones, 1, 1))
    F_root = rt.src_frame("root")
    R_root = G @ _to_world(F_root, _euler("root", frames))
    T = scale * _location("root", frames, cycles) @ F_root.T
    rot_world[:, 0] = R_root
    h_src, h0 = rt.src_head("root"), sk.heads[0]
    # the target root must move the body as the file's root does: x -> G (R (x - h_src) + h_src + T) + shift
    translation = np.einsum("nij,j->ni", R_root, h0 - h_src) - h0 + (h_src + T) @ G.T + shift
    down = np.array([0.0, 0.0, ground_offset(rt, scale)])
    translation = translation - down
    shift = shift - down                     # world-space IK targets are lowered with the body
    _copy_upper_body(rt, frames, rot_world)
    Rm, tm = chain_from_world(sk, rot_world, translation, np.ones(N))
    for side in ("L", "R"):
        _legs(rt, frames, cycles, scale, G, shift, rot_world, Rm, tm, side)
        _arms(rt, frames, cycles, scale, G, shift, rot_world, Rm, tm, side)
    rotations = np.stack([_local_quat(sk.frames[b], rot_world[:, b]) for b in range(sk.num_bones)], axis=1)
    return Poses(rotations, translation, np.ones(N))


def _copy_upper_body(rt, frames, rot_world):
    """Spine (composed and split), neck, head, clavicles: world-axis copies of the file's rotations."""
    total = np.tile(np.eye(3), (len(frames), 1, 1))
    for name in SOURCE_SPINE:
        total = total @ _to_world(rt.src_frame(name), _euler(name, frames))
    spine = rt.spine_bones()
    if spine:
        q = matrix_to_quat(total)
        angle = 2 * np.arctan2(np.linalg.norm(q[:, 1:], axis=1), q[:, 0])
        axis = q[:, 1:] / np.maximum(np.linalg.norm(q[:, 1:], axis=1), 1e-12)[:, None]
        part = _axis_angle_matrices(axis, angle / len(spine))
        for b in spine:
            rot_world[:, b] = part
    pairs = [("neck01", rt.first("neck")) if "neck" in rt.roles else None, ("head", rt.first("head"))]
    pairs += [(f"clavicle.{s}", rt.first("clavicle", s)) for s in "LR"]
    for name, b in filter(None, pairs):
        rot_world[:, b] = _to_world(rt.src_frame(name), _euler(name, frames))


def _posed_point(Rm, tm, b, x):
    return np.einsum("nij,j->ni", Rm[:, b], x) + tm[:, b]


def _foot_targets(rt, frames, cycles, scale, side):
    """Ankle targets (N, 3) in the walk frame (before heading/shift): rest ankle + the IK offset."""
    ankle = rt.first("ankle", side)
    prefix = "left" if side == "L" else "right"
    offset = scale * _location(f"{prefix}_foot_ik", frames, cycles) @ rt.src_frame(f"foot.{side}").T
    return rt.t.heads[ankle] + offset


def ground_offset(rt, scale) -> float:
    """Height (m) of the lowest ankle target over the whole cycle above the rest ankle height: the
    file's stance feet hover about 2 cm up, so the motion is lowered by this constant."""
    dense = np.linspace(0, CYCLE_FRAMES, 161)
    zero = np.zeros_like(dense)
    return min((_foot_targets(rt, dense, zero, scale, s)[:, 2] - rt.t.heads[rt.first("ankle", s), 2]).min()
               for s in "LR")


def _legs(rt, frames, cycles, scale, G, shift, rot_world, Rm, tm, side):
    sk = rt.t
    hip, knee, ankle = rt.first("hip", side), rt.first("knee", side), rt.first("ankle", side)
    prefix = "left" if side == "L" else "right"
    foot_src = f"foot.{side}"
    A = _foot_targets(rt, frames, cycles, scale, side) @ G.T + shift
    pole_src = f"lowerleg01.{side}"
    pole_off = scale * _location(f"{prefix}_knee_ik", frames, cycles) @ rt.src_frame(pole_src).T
    P = (rt.src_head(pole_src) + pole_off) @ G.T + shift
    H = _posed_point(Rm, tm, sk.parents[hip], sk.heads[hip])
    G_knee = _solve_limb(rt, rot_world, Rm, hip, knee, ankle, H, A, P)   # twist segments stay at rest
    R_foot = G @ _to_world(rt.src_frame(foot_src), _euler(f"{prefix}_foot_ik", frames))
    rot_world[:, ankle] = np.swapaxes(G_knee, 1, 2) @ R_foot
    for toe in (b for b in range(sk.num_bones) if sk.parents[b] == ankle and rt.roles[b] == "toe"):
        rot_world[:, toe] = _to_world(rt.src_frame(f"toe1-1.{side}"), _euler(f"toe1-1.{side}", frames))


def _arms(rt, frames, cycles, scale, G, shift, rot_world, Rm, tm, side):
    sk = rt.t
    upper, fore, wrist = rt.first("upper_arm", side), rt.first("forearm", side), rt.first("wrist", side)
    prefix = "left" if side == "L" else "right"
    wrist_src = f"wrist.{side}"
    offset = scale * _location(f"{prefix}_hand_ik", frames, cycles) @ rt.src_frame(wrist_src).T
    A = _posed_point(Rm, tm, 0, sk.heads[wrist]) + np.einsum("nij,nj->ni", Rm[:, 0], offset)   # moves with root
    S = _posed_point(Rm, tm, sk.parents[upper], sk.heads[upper])
    outward = 0.35 if side == "L" else -0.35
    back = _unit(np.array([outward, 1.0, 0.0])) @ G.T
    P = 0.5 * (S + A) + ELBOW_POLE_DISTANCE * back
    _solve_limb(rt, rot_world, Rm, upper, fore, wrist, S, A, P)
