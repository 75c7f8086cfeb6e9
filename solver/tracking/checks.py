"""Truth-free checks of one tracked frame: does the fitted pose explain the capture, or is its residual low
only because parts lie on the wrong surfaces (a hand fitted onto the face, an arm onto the trunk)?

Checks, each naming the body part (regions from the bone roles: trunk, head and per side upper arm,
forearm, hand, thigh, lower leg, foot; docs/track.md):

* unexplained capture: capture points farther than ``explain_mm`` from the posed model, grouped into
  regions by voxel connectivity; a region's area (its points times the capture's area per point, the
  median k-nearest-neighbour area, so overlapping views count once) relative to the body's surface area
  makes the frame doubtful or lost.  The region is
  named by the limb it hangs from: the part explaining the capture next to it, or that part's child
  whose joint is there; else the nearest part.
* unsupported model (needs cameras): model vertices facing a camera and in front of every capture point
  around their pixel by more than ``explain_mm``: the camera saw through them (free space).
* lying on / intersecting: vertices of one region inside (signed distance along the nearest vertex's
  normal) or on the surface of a non-adjacent region.  A limb fitted onto another part's capture sinks
  into that part; real contact only touches (skinning and soft tissue: ``inside_mm``).
* joint limits: knee and elbow flexion about a hinge axis fixed to the upper segment (hyperextension,
  sideways bend), the head's rotation from the chest, and the trunk: the hips' twist from the chest about
  the spine (a trunk twists 40-60 deg at most; hips turned round with the legs swapped explain a
  near-symmetric capture well) and the chest bent backwards from the hips (a body fitted facing away
  bends back as far as the true one bends forward).

The verdict is the worst level of the findings ("good" when none).  Metres inside; the reason texts
use mm, cm, cm² and degrees.
"""
from __future__ import annotations

import dataclasses
import time

import numpy as np
import scipy.sparse as sp
from scipy.ndimage import minimum_filter
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from ..depth import camera as cam
from ..errors import ArticulaInputError
from ..geometry.mesh_graph import adjacency, edges_of
from ..geometry.normals import vertex_areas
from ..learn.role_names import recognise as recognise_geometry
from ..rig.kinematics import forward_kinematics
from ..rig.model import Poses
from ..roles import role_bones
from .joint_limits import foot_forwards, hinge_angles, hinges_of, trunk_back, trunk_of, trunk_twist

LEVELS = ("good", "doubtful", "lost")
SEGMENTS = {"upper_arm": "upper arm", "forearm": "forearm", "hand": "hand", "thigh": "thigh",
            "shin": "lower leg", "foot": "foot"}
REGION_OF_ROLE = {"hips": "trunk", "spine": "trunk", "chest": "trunk", "shoulder": "trunk", "hip": "trunk",
                  "neck": "head", "head": "head", "upper_arm": "upper_arm", "forearm": "forearm", "hand": "hand",
                  "thigh": "thigh", "shin": "shin", "foot": "foot", "toe": "foot", "thumb": "hand",
                  "index": "hand", "middle": "hand", "ring": "hand", "pinky": "hand"}
CHECK_POINTS = 6000     # capture points (a fixed random subset) tested for being explained by the model
KNN = 5                 # neighbours of the k-NN area of a capture point and of the naming of a region
RIM_RINGS = 3           # a region's rim: vertices this many edges from a neighbouring region (~4 cm)
SUPPORT_RINGS = 2       # a vertex this many edges from one a capture point matched is supported (~3 cm)
JOINT_REACH = 0.12      # m: capture this close to a limb's joint hangs from that joint (joint-to-skin ~5-8 cm)
AREA_SAMPLE = 2000      # unexplained points whose neighbours name their region (a random subset)
NORMAL_OFFSET = 0.5     # an offset counts as inside only when mostly along the surface normal (cos >= this)



@dataclasses.dataclass(frozen=True)
class CheckOptions:
    """Thresholds (mm, degrees, fractions of the body's surface area S or of a part's area).

    explain_mm: a capture point farther than this from the model is unexplained: above scanner noise
    (a few mm) plus a learned model's surface error (1-2 cm), below an arm's half thickness (~40 mm), so a
    limb moved by its thickness leaves its capture unexplained.  region_doubtful / region_lost: area of
    one unexplained capture region or unsupported model region as a fraction of S (0.5 %: a palm; 1.5 %:
    about a hand or half a forearm).  contact_mm: surfaces this close touch; inside_mm: deeper than this
    counts as inside (skin compressed at a real contact, skinning at folds).  lies_on: fraction of a
    part's area on or in another part, at least ``intersect`` of it inside and ``intersect_mm`` deep (a
    limb resting on the trunk touches along a strip, a hand laid flat on the chest with its palm; a limb
    fitted onto the trunk's capture sinks in); intersect / intersect_lost / intersect_mm: fraction of a
    part inside another and the 95th percentile of that depth.  knee_back / elbow_back: hyperextension
    (deg) allowed, then doubtful, and lost past the second value; side_bend: sideways bend of a hinge;
    head_turn: the head's rotation from the chest (deg); trunk_twist: the hips' rotation from the chest
    about the spine's rest direction (deg); trunk_back: the chest bent backwards from the hips (deg; lost
    soon after doubtful: a body fitted facing away bends its chest back this far, and only a lost best fit
    sends the start search on to its next candidates, docs/track.md "7 Dec, afternoon");
    facing_cos: vertices facing a camera at least this much."""
    explain_mm: float = 35.0
    region_doubtful: float = 0.005
    region_lost: float = 0.015
    contact_mm: float = 5.0
    inside_mm: float = 10.0
    lies_on: float = 0.5
    intersect: float = 0.1
    intersect_lost: float = 0.25
    intersect_mm: float = 20.0
    knee_back: tuple = (10.0, 25.0)
    elbow_back: tuple = (15.0, 30.0)
    side_bend: tuple = (30.0, 50.0)
    head_turn: tuple = (100.0, 130.0)
    trunk_twist: tuple = (80.0, 110.0)
    trunk_back: tuple = (45.0, 50.0)
    facing_cos: float = 0.3


@dataclasses.dataclass
class Finding:
    """One problem: ``check`` ("unexplained", "unsupported", "lies_on", "intersects", "joint_limit"),
    ``level`` ("doubtful" or "lost"), the ``part`` it names, the reason ``text`` and its ``numbers``."""
    check: str
    level: str
    part: str
    text: str
    numbers: dict


@dataclasses.dataclass
class FrameCheck:
    """The verdict of one frame ("good", "doubtful", "lost"), its ``reasons`` (one line per finding, worst
    first), the ``findings``, the checks ``skipped`` and why, and summary ``numbers`` (areas in cm², angles
    in degrees, ``seconds``)."""
    verdict: str
    reasons: list
    findings: list
    skipped: list
    numbers: dict

    def report(self) -> dict:
        """JSON-serialisable: verdict, reasons, skipped, numbers and per finding its check, level and part."""
        return {"verdict": self.verdict, "reasons": self.reasons, "skipped": self.skipped, "numbers": self.numbers,
                "findings": [{"check": f.check, "level": f.level, "part": f.part} for f in self.findings]}


@dataclasses.dataclass
class Body:
    """What the checks need of a model, computed once (:func:`prepare`): region names, ``vertex_region``
    (V,), ``adjacent`` (R, R) bool (same or neighbouring region), region tree ``depth``, ``parent_region``
    (-1 at the root) and ``joint_bone`` (the bone whose head joins the region to its parent; -1) (R,),
    vertex areas (V,) and region areas (R,) m², the body area ``area`` m², ``edge`` (95th percentile edge
    length, m), ``faces`` (F, 3), ``corners`` (V, F) CSR (1 where a vertex is a face's corner), the mesh
    ``graph`` (V, V) CSR, ``hinges``, ``head_chest`` bones or None, ``trunk`` (hips bone, chest bone,
    unit rest direction from the hips' joint to the chest's (3,), unit rest forward normal to it (3,) or
    None) or None, ``notes`` on checks left out,
    ``members`` (each region's vertex indices) and ``near_region`` (V, R) bool (within :data:`RIM_RINGS`
    edges of the region)."""
    regions: list
    vertex_region: np.ndarray
    adjacent: np.ndarray
    depth: np.ndarray
    parent_region: np.ndarray
    joint_bone: np.ndarray
    vertex_area: np.ndarray
    region_area: np.ndarray
    area: float
    edge: float
    faces: np.ndarray
    corners: sp.csr_matrix
    graph: sp.csr_matrix
    hinges: list
    head_chest: tuple
    trunk: tuple
    notes: list
    members: list
    near_region: np.ndarray


# ----------------------------------------------------------------------------- the model, once

def model_roles(model) -> dict:
    """``{role: bone}`` of the model's bones: from their names (:func:`solver.roles.role_bones`), else from
    the skeleton's shape (:func:`solver.learn.role_names.recognise`) when the names give no legs and arms."""
    roles = role_bones(model.skeleton.names)
    needed = ("thigh.L", "thigh.R", "upper_arm.L", "upper_arm.R")
    if all(r in roles for r in needed):
        return roles
    found, _ = recognise_geometry(model.skeleton, model.rest_vertices, model.anchor)
    return found if len(found) > len(roles) else roles


def _region_key(role: str) -> str:
    base, side = (role[:-2], role[-1]) if role[-2:] in (".L", ".R") else (role, "")
    region = REGION_OF_ROLE.get(base.split(".")[0], "trunk")
    return f"{region}.{side}" if side and region in SEGMENTS else region


def region_name(key: str) -> str:
    """``"upper_arm.L"`` -> ``"left upper arm"``; ``"trunk"`` and ``"head"`` as they are."""
    if key[-2:] in (".L", ".R"):
        return ("left " if key[-1] == "L" else "right ") + SEGMENTS[key[:-2]]
    return key


def _bone_regions(skeleton, roles):
    """Region key of every bone: its role's region, else its parent's (bone 0: trunk)."""
    by_bone = {b: r for r, b in roles.items()}
    out = []
    for b, p in enumerate(skeleton.parents):
        out.append(_region_key(by_bone[b]) if b in by_bone else (out[p] if p >= 0 else "trunk"))
    return out


def prepare(model) -> Body:
    """The per-model part of the checks (regions, areas, mesh graph, hinges); see :class:`Body`."""
    sk = model.skeleton
    roles = model_roles(model)
    bone_region = _bone_regions(sk, roles)
    regions = sorted(set(bone_region), key=bone_region.index)
    index = np.array([regions.index(r) for r in bone_region])
    R = len(regions)
    adjacent, depth = np.eye(R, dtype=bool), np.zeros(R, dtype=int)
    parent_region, joint_bone = np.full(R, -1), np.full(R, -1)
    for b in range(1, sk.num_bones):
        a, p = index[b], index[sk.parents[b]]
        if a != p:
            adjacent[a, p] = adjacent[p, a] = True
            depth[a], parent_region[a], joint_bone[a] = depth[p] + 1, p, b
    vertex_region = index[model.anchor]
    areas = vertex_areas(model.rest_vertices, model.faces)
    e = edges_of(model.faces)
    edge = float(np.percentile(np.linalg.norm(model.rest_vertices[e[:, 0]] - model.rest_vertices[e[:, 1]], axis=1),
                               95)) if len(e) else 0.0
    toes = foot_forwards(model, roles, vertex_region, regions)
    hinges, notes = hinges_of(sk, roles, toes)
    head_chest = (roles["head"], roles["chest"]) if "head" in roles and "chest" in roles else None
    if head_chest is None:
        notes.append("head rotation: the rig has no head or chest role")
    trunk = trunk_of(sk, roles, toes)
    if trunk is None:
        notes.append("trunk twist: the rig has no separate hips and chest roles")
    faces = np.asarray(model.faces, dtype=np.int64)
    corners = sp.csr_matrix((np.ones(faces.size), (faces.ravel(), np.repeat(np.arange(len(faces)), 3))),
                            shape=(model.num_vertices, len(faces)))
    graph = adjacency(model.faces, model.num_vertices)
    near = (vertex_region[:, None] == np.arange(R)).astype(np.float64)
    for _ in range(RIM_RINGS):
        near += graph @ near
    members = [np.flatnonzero(vertex_region == r) for r in range(R)]
    return Body(regions, vertex_region, adjacent, depth, parent_region, joint_bone, areas,
                np.bincount(vertex_region, areas, R), float(areas.sum()), edge, faces, corners, graph,
                hinges, head_chest, trunk, notes, members, near > 0)


# ----------------------------------------------------------------------------- one frame

def check_frame(model, pose: Poses, posed, capture, body: Body = None,
                options: CheckOptions = CheckOptions()) -> FrameCheck:
    """Check one tracked frame without the truth.  ``model`` (:class:`solver.rig.model.Model`), ``pose``
    (one frame of :class:`Poses`), ``posed`` (V, 3) the hybrid-skinned mesh of that pose, ``capture`` with
    ``points`` (N, 3) m and optional ``cameras`` [(cam_to_world (4, 4), Intrinsics)] (as
    ``solver.track.frame_fit.Capture``; its normals and triangles are not needed); ``body``: :func:`prepare`
    of the model, computed here when None (pass it to check many frames)."""
    start = time.perf_counter()
    body = prepare(model) if body is None else body
    posed, points, cameras = _inputs(model, pose, posed, capture)
    findings, skipped, numbers = [], list(body.notes), {}
    Rm, tm = forward_kinematics(model.skeleton, pose)
    Rm, tm = Rm[0], tm[0]
    if not len(points):
        findings.append(Finding("unexplained", "lost", "body", "the capture has no points", {}))
    else:
        rng = np.random.default_rng(0)
        sample = points if len(points) <= CHECK_POINTS else points[rng.choice(len(points), CHECK_POINTS, False)]
        model_tree, sample_tree = _tree(posed), _tree(sample)
        spacing, point_area = sampling(sample, sample_tree)
        numbers["capture_points_checked"] = len(sample)
        joints = region_joints(body, model.skeleton, Rm, tm)
        found, nums, matched = _unexplained(body, joints, sample, model_tree, sample_tree, spacing, point_area,
                                            options)
        findings += found
        numbers.update(nums)
        normals = _vertex_normals(posed, body)
        if cameras:
            full_spacing = spacing * np.sqrt(len(sample) / len(points))
            found, nums = _unsupported(body, posed, normals, points, matched, cameras, full_spacing, options)
            findings += found
            numbers.update(nums)
        else:
            skipped.append("unsupported model parts: the capture has no cameras")
        found, nums = _contacts(body, posed, normals, options)
        findings += found
        numbers.update(nums)
    found, nums = _joint_limits(body, Rm, tm, options)
    findings += found
    numbers.update(nums)
    findings.sort(key=lambda f: -LEVELS.index(f.level))
    verdict = LEVELS[max([LEVELS.index(f.level) for f in findings], default=0)]
    numbers["seconds"] = time.perf_counter() - start
    return FrameCheck(verdict, [f.text for f in findings], findings, skipped, numbers)


def region_joints(body, skeleton, Rm, tm):
    """Posed joint (R, 3) at which each region hangs from its parent region (NaN for the root region)."""
    out = np.full((len(body.regions), 3), np.nan)
    for r, b in enumerate(body.joint_bone):
        if b >= 0:
            out[r] = Rm[b] @ skeleton.heads[b] + tm[b]
    return out


def _inputs(model, pose, posed, capture):
    """Checked arrays: posed (V, 3), points (N, 3) and the camera list (empty when none)."""
    posed = np.asarray(posed, dtype=np.float64)
    if posed.shape != (model.num_vertices, 3) or not np.isfinite(posed).all():
        raise ArticulaInputError(f"checks: the posed mesh must be finite ({model.num_vertices}, 3), "
                                 f"got {posed.shape}")
    if len(pose) != 1 or pose.rotations.shape[1] != model.skeleton.num_bones:
        raise ArticulaInputError(f"checks: one frame of {model.skeleton.num_bones} bones expected, got pose "
                                 f"rotations of shape {pose.rotations.shape}")
    points = np.asarray(capture.points, dtype=np.float64).reshape(-1, 3)
    points = points[np.isfinite(points).all(axis=1)]
    return posed, points, list(getattr(capture, "cameras", None) or [])


def _tree(points):
    """A k-d tree built for few queries (unbalanced, uncompacted: builds about twice as fast)."""
    return cKDTree(points, balanced_tree=False, compact_nodes=False)


def _vertex_normals(vertices, body):
    """Unit area-weighted vertex normals (V, 3) of the posed mesh (zero on vertices of no triangle)."""
    f = body.faces
    out = body.corners @ np.cross(vertices[f[:, 1]] - vertices[f[:, 0]], vertices[f[:, 2]] - vertices[f[:, 0]])
    norm = np.linalg.norm(out, axis=1, keepdims=True)
    return np.divide(out, norm, out=np.zeros_like(out), where=norm > 0)


def voxel_components(points, size):
    """``(count, labels (N,))``: groups of points joined through occupied voxels of edge ``size`` (m) that
    touch (26-neighbourhood)."""
    key = np.floor(points / size).astype(np.int64)
    key -= key.min(axis=0) - 1
    dims = key.max(axis=0) + 2
    code = (key[:, 0] * dims[1] + key[:, 1]) * dims[2] + key[:, 2]
    cells, inverse = np.unique(code, return_inverse=True)
    rows, cols = [], []
    for dx, dy, dz in np.ndindex(3, 3, 3):
        delta = ((dx - 1) * dims[1] + (dy - 1)) * dims[2] + (dz - 1)
        if delta <= 0:
            continue
        pos = np.minimum(np.searchsorted(cells, cells + delta), len(cells) - 1)
        hit = np.flatnonzero(cells[pos] == cells + delta)
        rows.append(hit)
        cols.append(pos[hit])
    rows, cols = np.concatenate(rows), np.concatenate(cols)
    graph = sp.coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(len(cells), len(cells)))
    count, labels = connected_components(graph, directed=False)
    return count, labels[np.ravel(inverse)]


def sampling(points, tree, size=500):
    """``(spacing, area)``: the median distance (m) from a capture point to its nearest other point and the
    median surface area (m²) a point stands for, ``pi r² / (k - 1/3)`` with r the distance to its k-th
    other neighbour (k = :data:`KNN`; for uniform samples pi r² times the density has the Gamma(k) law,
    whose median is about k - 1/3), over ``size`` random points."""
    rng = np.random.default_rng(0)
    sample = points if len(points) <= size else points[rng.choice(len(points), size, replace=False)]
    d, _ = tree.query(sample, k=min(KNN + 1, len(points)))
    if d.shape[1] < KNN + 1:
        return 0.01, 1e-4
    return float(np.median(d[:, 1])), float(np.median(np.pi * d[:, -1] ** 2 / (KNN - 1.0 / 3.0)))


def _extent_cm(points):
    """The two largest extents (cm) of a point set along its principal axes, smaller first."""
    if len(points) < 3:
        return 0.0, 0.0
    p = points[:: max(1, len(points) // 3000)] - points.mean(axis=0)
    _, _, vt = np.linalg.svd(p, full_matrices=False)
    q = p @ vt[:2].T
    span = (q.max(axis=0) - q.min(axis=0)) * 100.0
    return float(span[1]), float(span[0])


def _level(area, body, options):
    """"lost", "doubtful" or None for a region of ``area`` m² (fractions of the body's area S)."""
    if area >= options.region_lost * body.area:
        return "lost"
    return "doubtful" if area >= options.region_doubtful * body.area else None


def _unexplained(body, joints, points, model_tree, capture_tree, spacing, point_area, options):
    """Findings on capture regions farther than ``explain_mm`` from the posed model, and the numbers.
    ``joints`` (R, 3): the posed joint each region hangs from (:func:`region_joints`); a region's area is
    its points times ``point_area`` (m², :func:`sampling`: a small region's own k-NN areas would be
    inflated by its border).  Also returns the model vertices nearest to an explained point."""
    tau = options.explain_mm / 1000.0
    d, near = model_tree.query(points, distance_upper_bound=tau + 0.5 * body.edge)
    explained = np.isfinite(d)
    far = np.flatnonzero(~explained)
    numbers = {"unexplained_fraction": len(far) / len(points), "unexplained_regions": []}
    if not len(far):
        return [], numbers, near[explained]
    rng = np.random.default_rng(0)
    sample = far if len(far) <= AREA_SAMPLE else np.sort(rng.choice(far, AREA_SAMPLE, replace=False))
    neighbours = capture_tree.query(points[sample], k=KNN + 1)[1][:, 1:]
    count, labels = voxel_components(points[far], max(2.0 * spacing, 0.01))
    sample_label = labels[np.searchsorted(far, sample)]
    region_area = np.bincount(labels, minlength=count) * point_area
    numbers["unexplained_area_cm2"] = float(region_area.sum() * 1e4)
    findings = []
    for c in np.argsort(-region_area):
        level = _level(region_area[c], body, options)
        if level is None:
            break
        mine = far[labels == c]
        part = region_name(body.regions[_region_part(body, joints, near, explained, neighbours[sample_label == c],
                                                     points[mine], model_tree)])
        dist = float(np.median(model_tree.query(points[mine[:: max(1, len(mine) // 500)]])[0])) * 1000.0
        small, large = _extent_cm(points[mine])
        nums = {"points": int(len(mine)), "area_cm2": float(region_area[c] * 1e4), "extent_cm": [small, large],
                "median_distance_mm": dist, "part": part, "centre": points[mine].mean(axis=0).tolist()}
        numbers["unexplained_regions"].append(nums)
        findings.append(Finding(
            "unexplained", level, part,
            f"capture region of {len(mine)} points ({small:.0f} x {large:.0f} cm, {region_area[c] * 1e4:.0f} cm²)"
            f" near the {part} not explained by the model ({dist:.0f} mm away)", nums))
    return findings, numbers, near[explained]


def _region_part(body, joints, near, explained, neighbours, cluster_points, model_tree):
    """The region a cluster of unexplained capture belongs to: the region explaining most of the capture
    next to it (its k-NN neighbours that are explained; the one nearest the root of the region tree among
    those with a quarter of the votes, or the most voted when none has) or, when a child region's joint
    lies within :data:`JOINT_REACH` of that capture, that child (a limb moved away leaves its capture
    hanging from its joint); without explained neighbours the region nearest to the cluster."""
    nb = neighbours.ravel()
    nb = nb[nb < len(explained)]
    nb = nb[explained[nb]]
    if not len(nb):
        _, idx = model_tree.query(cluster_points[:: max(1, len(cluster_points) // 200)])
        return int(np.argmax(np.bincount(body.vertex_region[idx], minlength=len(body.regions))))
    votes = np.bincount(body.vertex_region[near[nb]], minlength=len(body.regions))
    strong = np.flatnonzero(votes >= min(0.25 * votes.sum(), votes.max()))     # votes spread: the most voted
    best = strong[np.lexsort((-votes[strong], body.depth[strong]))[0]]
    children = np.flatnonzero(body.parent_region == best)
    if len(children):
        edge = model_tree.data[near[nb]]
        gap = np.array([np.min(np.linalg.norm(edge - joints[c], axis=1)) for c in children])
        if gap.min() <= JOINT_REACH:
            return int(children[np.argmin(gap)])
    return int(best)


def _seen_through(vertices, normals, points, cam_to_world, intr, pixel, tau, facing_cos):
    """``(n,)`` bool: which of the model ``vertices (n, 3)`` face the camera, fall inside its image and lie
    more than ``tau`` in front of the nearest capture point within one block of their block (blocks of
    about ``pixel`` metres at the vertices' depth; no capture there counts as infinitely far): the camera
    saw through them."""
    vc = cam.world_to_camera(vertices, cam_to_world)
    out = np.zeros(len(vertices), dtype=bool)
    if not (vc[:, 2] > 0).any():
        return out
    k = max(1, int(pixel * min(intr.fx, intr.fy) / np.median(vc[vc[:, 2] > 0, 2])))
    W, H = -(-intr.width // k), -(-intr.height // k)

    def blocks(p_cam):
        uv, z = cam.project(p_cam, intr)
        with np.errstate(invalid="ignore"):
            ok = (z > 0) & (uv[:, 0] > -0.5) & (uv[:, 0] < intr.width - 0.5) & (uv[:, 1] > -0.5) \
                & (uv[:, 1] < intr.height - 0.5)
        cell = np.floor((uv[ok] + 0.5) / k).astype(np.int64)
        return np.flatnonzero(ok), cell[:, 1] * W + cell[:, 0], z[ok]

    _, cell, z = blocks(cam.world_to_camera(points, cam_to_world))
    zbuf = np.full(W * H, np.inf)
    np.minimum.at(zbuf, cell, z)
    zbuf = minimum_filter(zbuf.reshape(H, W), size=3, mode="constant", cval=np.inf).ravel()
    idx, vcell, vz = blocks(vc)
    view = cam_to_world[:3, 3] - vertices[idx]
    facing = np.einsum("ij,ij->i", normals[idx], view) >= facing_cos * np.linalg.norm(view, axis=1)
    out[idx] = facing & (vz + tau < zbuf[vcell])
    return out


def _unsupported(body, posed, normals, points, matched, cameras, spacing, options):
    """Findings on model regions the cameras saw through (:func:`_seen_through`), and the numbers.  Only
    vertices farther than :data:`SUPPORT_RINGS` edges from every ``matched`` vertex (nearest to a sampled
    capture point) are tested: the others have capture on them.  ``spacing``: of all the points."""
    tau = options.explain_mm / 1000.0
    near = np.zeros(len(posed))
    near[matched] = 1.0
    for _ in range(SUPPORT_RINGS):
        near += body.graph @ near
    lonely = np.flatnonzero(near == 0)
    pixel = max(3.0 * spacing, 0.01)
    seen = np.array([_seen_through(posed[lonely], normals[lonely], points, c2w, intr, pixel, tau,
                                   options.facing_cos) for c2w, intr in cameras]).reshape(len(cameras), -1)
    bad = lonely[seen.any(axis=0)]
    numbers = {"unsupported_area_cm2": float(body.vertex_area[bad].sum() * 1e4), "unsupported_regions": []}
    if not len(bad):
        return [], numbers
    count, labels = connected_components(body.graph[bad][:, bad], directed=False)
    area = np.bincount(labels, body.vertex_area[bad], count)
    findings = []
    for c in np.argsort(-area):
        level = _level(area[c], body, options)
        if level is None:
            break
        mine = bad[labels == c]
        votes = np.bincount(body.vertex_region[mine], body.vertex_area[mine], len(body.regions))
        part = region_name(body.regions[int(np.argmax(votes))])
        camera = int(np.argmax(seen[:, np.isin(lonely, mine)].sum(axis=1)))
        nums = {"vertices": int(len(mine)), "area_cm2": float(area[c] * 1e4), "camera": camera, "part": part}
        numbers["unsupported_regions"].append(nums)
        findings.append(Finding("unsupported", level, part,
                                f"{part} not supported by the capture: {area[c] * 1e4:.0f} cm² of it face camera "
                                f"{camera}, which saw through it", nums))
    return findings, numbers


def _contacts(body, posed, normals, options):
    """Findings on parts lying on or intersecting non-adjacent parts, and the numbers: per ordered pair of
    regions (A, B) the area of A on B (closer than ``contact_mm`` to B's surface or inside it) and inside
    B (deeper than ``inside_mm``), by the signed distance along the normal of A's nearest vertex of B.
    Nearest vertices on B's rim towards A's own chain (near a region adjacent to A) tell nothing: B's
    surface is open there, and a learned rig's parts overlap there."""
    R = len(body.regions)
    on, inside, depth = np.zeros((R, R)), np.zeros((R, R)), np.zeros((R, R))
    contact, deep = options.contact_mm / 1000.0, options.inside_mm / 1000.0
    reach = contact + 0.5 * body.edge
    groups = body.members
    lo = np.array([posed[g].min(axis=0) if len(g) else np.full(3, np.inf) for g in groups]) - reach
    hi = np.array([posed[g].max(axis=0) if len(g) else np.full(3, -np.inf) for g in groups]) + reach
    for b, verts in enumerate(groups):
        near = np.flatnonzero(~body.adjacent[b] & np.all((lo <= hi[b]) & (hi >= lo[b]), axis=1))
        if not len(verts) or not len(near):
            continue
        cand = np.concatenate([groups[r] for r in near])
        cand = cand[np.all((posed[cand] >= lo[b]) & (posed[cand] <= hi[b]), axis=1)]
        if not len(cand):
            continue
        dist, j = _tree(posed[verts]).query(posed[cand])
        off = posed[cand] - posed[verts[j]]
        signed = np.einsum("ij,ij->i", off, normals[verts[j]])
        a = body.vertex_region[cand]
        rim = body.adjacent[a] & body.near_region[verts[j]]
        rim[:, b] = False
        along = (-signed >= NORMAL_OFFSET * dist) & ~rim.any(axis=1)
        is_on = (signed < contact) & ((dist < reach) | along)
        is_in = (signed < -deep) & along
        on[:, b] = np.bincount(a[is_on], body.vertex_area[cand[is_on]], R)
        inside[:, b] = np.bincount(a[is_in], body.vertex_area[cand[is_in]], R)
        for r in np.unique(a[is_in]):
            depth[r, b] = np.percentile(-signed[is_in & (a == r)], 95)
    frac_on = on / np.maximum(body.region_area, 1e-12)[:, None]
    frac_in = inside / np.maximum(body.region_area, 1e-12)[:, None]
    numbers = {"largest_on_fraction": float(frac_on.max(initial=0.0)),
               "largest_inside_fraction": float(frac_in.max(initial=0.0)), "contacts": []}
    findings = []
    for a, b in zip(*np.nonzero(np.triu(np.ones((R, R), dtype=bool), 1))):
        if frac_on[b, a] + frac_in[b, a] > frac_on[a, b] + frac_in[a, b]:
            a, b = b, a
        finding = _contact_finding(body, a, b, frac_on[a, b], frac_in[a, b], depth[a, b] * 1000.0, options)
        if finding is not None:
            findings.append(finding)
            numbers["contacts"].append(finding.numbers)
    return findings, numbers


def _contact_finding(body, a, b, on, inside, depth_mm, options):
    """The finding for part ``a`` on/in part ``b`` (fractions of a's area, 95th percentile depth), or None."""
    part, other = region_name(body.regions[a]), region_name(body.regions[b])
    nums = {"part": part, "other": other, "on_fraction": float(on), "inside_fraction": float(inside),
            "depth_mm": float(depth_mm)}
    if on >= options.lies_on and inside >= options.intersect and depth_mm >= options.intersect_mm:
        return Finding("lies_on", "lost", part, f"{part} lies on the {other} ({100 * on:.0f}% of it on or inside "
                                                f"it, up to {depth_mm:.0f} mm deep)", nums)
    if inside >= options.intersect and depth_mm >= options.intersect_mm:
        level = "lost" if inside >= options.intersect_lost else "doubtful"
        return Finding("intersects", level, part, f"{part} intersects the {other} ({100 * inside:.0f}% of it "
                                                  f"inside, up to {depth_mm:.0f} mm deep)", nums)
    return None


def _joint_limits(body, Rm, tm, options):
    """Findings on knees and elbows outside their range and the head turned too far from the chest."""
    findings, numbers = [], {"hinges": {}}
    for h in body.hinges:
        flexion, side = hinge_angles(h, Rm, tm)
        numbers["hinges"][h.name] = {"flexion_deg": flexion, "sideways_deg": side}
        back = options.knee_back if h.kind == "knee" else options.elbow_back
        checks = (("backwards", -flexion, back),) + ((("sideways", abs(side), options.side_bend),) if h.sideways
                                                     else ())
        for how, angle, (doubt, lost) in checks:
            if angle > doubt:
                findings.append(Finding("joint_limit", "lost" if angle > lost else "doubtful", h.name,
                                        f"{h.name} bent {how} beyond its limit ({angle:.0f} deg)",
                                        {"joint": h.name, "bend": how, "angle_deg": angle, "limit_deg": doubt}))
    if body.head_chest is not None:
        head, chest = body.head_chest
        rel = Rm[chest].T @ Rm[head] / np.linalg.det(Rm[chest]) ** (2.0 / 3.0)
        turn = float(np.degrees(np.arccos(np.clip((np.trace(rel) - 1.0) / 2.0, -1.0, 1.0))))
        numbers["head_turn_deg"] = turn
        doubt, lost = options.head_turn
        if turn > doubt:
            findings.append(Finding("joint_limit", "lost" if turn > lost else "doubtful", "head",
                                    f"head turned {turn:.0f} deg from the chest, beyond its limit ({doubt:.0f} deg)",
                                    {"joint": "head", "angle_deg": turn, "limit_deg": doubt}))
    if body.trunk is not None:
        twist, back = trunk_twist(body.trunk, Rm), trunk_back(body.trunk, Rm)
        numbers["trunk_twist_deg"], numbers["trunk_back_deg"] = twist, back
        limits = (("trunk twist", twist, options.trunk_twist, "hips twisted {:.0f} deg from the chest about the spine"),
                  ("trunk back", back, options.trunk_back, "chest bent backwards {:.0f} deg from the hips"))
        for joint, angle, (doubt, lost), text in limits:
            if angle is not None and angle > doubt:
                findings.append(Finding("joint_limit", "lost" if angle > lost else "doubtful", "trunk",
                                        f"{text.format(angle)}, beyond its limit ({doubt:.0f} deg)",
                                        {"joint": joint, "angle_deg": angle, "limit_deg": doubt}))
    return findings, numbers
