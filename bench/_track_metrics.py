"""Error measures of ``./run bench track`` against the ground truth (never the tracker's residual), and the
world orientations its captures are seen in.  tests/bench/test_track_metrics.py checks them on tiny cases.

* Body and extremities: a vertex belongs to the extremities (hands with fingers, feet with toes, the head
  with the face) when the bone with its largest ground-truth skin weight is a ``wrist``, ``ankle`` or
  ``head`` bone (``sample_scenes.bone_roles``) or lies below one; the rest is the body.  The split is the
  subject's, so it applies to any model with the subject's vertex order (exact, another shape, learned).
  On MakeHuman bodies the extremities hold about 70% of the vertices (dense head, hands and feet), so
  they dominate the mean over all vertices.
* Vertex error: per frame, the mean over vertices of |tracked posed vertex - true posed vertex| (same vertex
  order), split into body and extremities.  Surface distance: every true posed vertex to the closest point
  of the tracked posed model's triangles (``solver.geometry.surface_distance``), for models that need not
  share the subject's vertices (another body, adapted).
* Joints: the 14 major joints (``bone_roles.major_joints``).  A model whose bones carry those roles gives
  its own posed bone heads; any other (a learned rig, ``part_NN``) gets them from its posed mesh by a
  :class:`JointRegressor` of the subject, against the same regressor on the true mesh (0 for the true mesh).
* Worlds: :data:`WORLDS` rotations taking the samples' Z-up world to another; captures and truth are both
  rotated, so the errors are measured in the rotated world.  :func:`rotated_poses` gives the poses that pose a
  model exactly as the rotated truth.

Lengths in metres (errors printed in mm by the bench); vertex arrays (N frames, V, 3).
"""
from __future__ import annotations

import numpy as np

EXTREMITY_ROLES = ("wrist", "ankle", "head")


def _rotation(axis, degrees):
    axis = np.asarray(axis, dtype=np.float64)
    axis = axis / np.linalg.norm(axis)
    a = np.radians(degrees)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * K @ K


#: name -> (3, 3) rotation applied to the Z-up world: "zup" as generated; "yup" the Y-up world of OBJ files
#: and many scanners (world z -> +y, y -> -z); "tilt30" tilted 30 degrees about a horizontal axis
#: halfway between x and y (the floor is not a coordinate plane).
WORLDS = {"zup": np.eye(3), "yup": _rotation([1, 0, 0], -90.0), "tilt30": _rotation([1, 1, 0], 30.0)}


def extremity_bones(names, parents) -> np.ndarray:
    """(B,) bool: bones of the roles :data:`EXTREMITY_ROLES` and every bone below them (parents first)."""
    from articula.sample_scenes.bone_roles import skeleton_roles
    roles = skeleton_roles(list(names))
    out = np.zeros(len(roles), dtype=bool)
    for b, role in enumerate(roles):
        out[b] = role in EXTREMITY_ROLES or (parents[b] >= 0 and out[parents[b]])
    return out


def extremity_vertices(weights, names, parents) -> np.ndarray:
    """(V,) bool: vertices whose largest weight in ``weights (V, B)`` is on an extremity bone."""
    return extremity_bones(names, parents)[np.argmax(np.asarray(weights), axis=1)]


def split_means(errors, extremities) -> dict:
    """Means of ``errors (N, V)`` per frame: ``{"all", "body", "extremities"}`` -> (N,) arrays."""
    errors = np.asarray(errors, dtype=np.float64)
    return {"all": errors.mean(axis=1), "body": errors[:, ~extremities].mean(axis=1),
            "extremities": errors[:, extremities].mean(axis=1)}


def vertex_errors(posed, truth) -> np.ndarray:
    """(N, V) distances between corresponding vertices of ``posed`` and ``truth`` (N, V, 3)."""
    return np.linalg.norm(np.asarray(posed) - np.asarray(truth), axis=-1)


def surface_distances(truth, posed, faces) -> np.ndarray:
    """(N, V): each true vertex ``truth (N, V, 3)`` to the surface of ``posed (N, W, 3)`` with ``faces``."""
    from articula.solver.geometry.surface_distance import distance_to_surface
    return np.stack([distance_to_surface(t, p, faces) for t, p in zip(truth, posed)])


class JointRegressor:
    """Joint positions as fixed affine combinations of mesh vertices: each joint ``j (3,)`` of a rest mesh
    ``x (V, 3)`` is ``sum_k w_k x_k`` over its ``k`` nearest vertices, ``sum_k w_k = 1``, the weights of
    least norm.  Affine combinations commute with affine maps, so a mesh moved rigidly around a joint
    carries the joint exactly; a skinned mesh carries it to within its local deformation."""

    def __init__(self, rest_vertices, joints, k: int = 40):
        from scipy.spatial import cKDTree
        x = np.asarray(rest_vertices, dtype=np.float64)
        joints = np.asarray(joints, dtype=np.float64)
        _, self.index = cKDTree(x).query(joints, k=k)
        self.weights = np.empty(self.index.shape)
        for j, (ids, p) in enumerate(zip(self.index, joints)):
            A = np.vstack([x[ids].T, np.ones(k)])                     # (4, k)
            self.weights[j] = np.linalg.lstsq(A, np.r_[p, 1.0], rcond=None)[0]

    def __call__(self, vertices) -> np.ndarray:
        """(..., J, 3) joints of ``vertices (..., V, 3)``."""
        v = np.asarray(vertices, dtype=np.float64)
        return np.einsum("jk,...jki->...ji", self.weights, v[..., self.index, :])


def posed_heads(skeleton, poses, bones) -> np.ndarray:
    """(N, len(bones), 3) posed heads of ``bones``."""
    from articula.solver.rig.kinematics import forward_kinematics
    Rm, tm = forward_kinematics(skeleton, poses)
    return (np.einsum("nbij,bj->nbi", Rm, skeleton.heads) + tm)[:, bones]


def major_bones(skeleton):
    """The bone indices of the 14 major joints, or None when the skeleton's names carry no such roles."""
    from articula.sample_scenes.bone_roles import major_joints
    from articula.solver.errors import ArticulaInputError
    try:
        return list(major_joints(skeleton).values())
    except ArticulaInputError:
        return None


def rotated_poses(skeleton, poses, R):
    """Poses that pose any model on ``skeleton`` as ``poses`` do, then rotated by ``R (3, 3)`` about the
    origin: the root's rotation is composed with R (in its rest axes) and its translation moved, from
    ``M_0(x) = s R_0 (x - h_0) + h_0 + t`` (``solver.rig.kinematics``): ``t' = R (h_0 + t) - h_0``."""
    from articula.solver.geometry.rotations import matrix_to_quat, quat_mul
    from articula.solver.rig.model import Poses
    F, h = skeleton.frames[0], skeleton.heads[0]
    rot = np.array(poses.rotations, dtype=np.float64, copy=True)
    rot[:, 0] = quat_mul(matrix_to_quat(F.T @ R @ F)[None], rot[:, 0])
    trans = (np.asarray(poses.translations) + h) @ R.T - h
    return Poses(rot, trans, np.array(poses.scales, copy=True))


def rotate_points(R, points) -> np.ndarray:
    """``points (..., 3)`` rotated by ``R (3, 3)``."""
    return np.asarray(points, dtype=np.float64) @ np.asarray(R).T


def rotate_cameras(R, cameras) -> list:
    """``[(cam_to_world (4, 4), intrinsics)]`` of cameras carried along with the world rotation ``R``."""
    M = np.eye(4)
    M[:3, :3] = R
    return [(M @ c2w, intr) for c2w, intr in cameras]
