"""Targets whose mapped bones hang from constrained or driven bones (Rigify's FK controls under its
MCH parents, rigs with 'follow' switches): the pose-bone channels are found through Blender itself.

Per frame, the mapped bones first take the solver's channels (exact wherever the parenting is plain);
then, level by level, the bones that hang from a constrained bone are given their wanted armature-space
matrix through ``PoseBone.matrix`` after the scene was re-evaluated, so they see their parent's
*evaluated* (constrained) matrix; the channels are read back.  Exact, at one scene update per
constraint level and frame: the fast path stays the rule and this one runs only when
:func:`needs_evaluation` says so.
"""
import bpy
import numpy as np
from mathutils import Matrix

from ...solver.geometry.rotations import matrix_to_quat, quat_sign_continuous, quat_to_matrix
from ...solver.retarget.armature import forward, local_matrices
from .armatures import constrained_bones, driven_bones
from .source_clip import with_ancestors


def needs_evaluation(ob, mapped) -> list:
    """Why the target's channels must come from the evaluated scene: bones above the ``mapped`` ones
    (not mapped themselves) that constraints, drivers or non-default inheritance move."""
    above = with_ancestors(ob, mapped) - set(mapped)
    why = []
    if constrained_bones(ob, above):
        why.append("constrained parents")
    if set(driven_bones(ob)) & above:
        why.append("driven parents")
    if any((not b.use_inherit_rotation or b.inherit_scale != 'FULL') for b in ob.data.bones if b.name in mapped | above):
        why.append("bones that do not inherit rotation or scale")
    return why


def _barrier_levels(ob, rest, mapped) -> dict:
    """``{bone index: level}`` of the mapped bones: the number of 'barriers' (a constrained, driven or
    non-inheriting unmapped bone between a mapped bone and its nearest mapped ancestor) above each,
    counting its own.  Bones of level 0 and bones below a barrier root by plain parenting need no
    evaluation; a barrier root is placed after the scene was updated for the level above it."""
    special = set(constrained_bones(ob)) | set(driven_bones(ob))
    special |= {b.name for b in ob.data.bones if not b.use_inherit_rotation or b.inherit_scale != 'FULL'}
    level, roots = {}, set()
    for b in sorted(mapped):                      # parents come first in ``rest``
        p, crossed = rest.parents[b], False
        while p >= 0 and p not in mapped:
            crossed |= rest.bones[p] in special
            p = rest.parents[p]
        level[b] = (level[p] if p >= 0 else 0) + crossed
        if crossed:
            roots.add(b)
    return {b: (lv, b in roots) for b, lv in level.items()}


def solve(context, ob, rest, result, frames, progress=None) -> None:
    """Replace ``result``'s channels of the mapped bones with the ones that put them where the solver
    wants them in Blender's evaluated pose (see module docstring).  The target's constraints are
    evaluated at the current frame (its own action is set aside meanwhile)."""
    loc = np.zeros(result.quaternions.shape[:2] + (3,))
    loc[:, result.root_bone] = result.root_locations
    local = local_matrices(quat_to_matrix(result.quaternions), loc)
    want = forward(rest, local)
    levels = _barrier_levels(ob, rest, set(result.mapped))
    top = max((lv for lv, _ in levels.values()), default=0)
    ad = ob.animation_data
    keep_action = ad.action if ad else None
    saved = {pb.name: pb.matrix_basis.copy() for pb in ob.pose.bones}
    if ad is not None:
        ad.action = None
    bones = [ob.pose.bones[name] for name in rest.bones]
    try:
        for k in range(len(frames)):
            for b in result.driven:
                bones[b].matrix_basis = Matrix(local[k, b].tolist())
            for lv in range(1, top + 1):
                ob.update_tag()                     # pose-bone writes alone do not tag the armature
                context.view_layer.update()
                for b, (level, root) in levels.items():
                    if root and level == lv:
                        M = Matrix(want[k, b].tolist())
                        if b != result.root_bone:
                            M.translation = bones[b].matrix.translation
                        bones[b].matrix = M
            for b in result.mapped:
                basis = np.array(bones[b].matrix_basis, dtype=np.float64)
                result.quaternions[k, b] = matrix_to_quat(basis[:3, :3] / np.linalg.norm(basis[:3, 0]))
                if b == result.root_bone:
                    result.root_locations[k] = basis[:3, 3]
            if progress is not None and k % 25 == 0:
                progress(k / len(frames), f"fitting the target's constrained rig, frame {frames[k]}")
    finally:
        for pb in ob.pose.bones:
            pb.matrix_basis = saved[pb.name]
        if ad is not None:
            ad.action = keep_action
        context.view_layer.update()
    result.quaternions[:] = quat_sign_continuous(result.quaternions)
