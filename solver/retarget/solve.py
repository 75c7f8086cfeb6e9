"""Skeleton retargeting of a whole clip: source pose matrices in, target pose-bone channels out.

``retarget_clip`` runs :mod:`.directions` (segment directions and twist), :mod:`.root_motion` (hips
path scaled by the leg-length ratio) and, when asked, :mod:`.foot_plant` (feet that rest on the ground
in the source stay planted).  Arrays: ``F`` frames, ``Js``/``Jt`` source/target bones.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import ArticulaInputError
from ..geometry.rotations import matrix_to_quat, quat_sign_continuous
from . import directions, foot_plant, root_motion
from .armature import ArmatureRest, rest_world, world_pose
from .mapping import Mapping, describe_missing

UNIT_MISMATCH = 4.0     # leg-length ratios beyond this (or below its inverse) are reported as unit mismatches
NEEDED = ("hips", "thigh.L", "shin.L", "foot.L", "thigh.R", "shin.R", "foot.R")


@dataclass
class RetargetOptions:
    root_motion: bool = True       # move the hips (else they stay at the target's rest position)
    in_place: bool = False         # remove the travel, keep the sway and the bob
    foot_cleanup: bool = False     # keep feet that touch the ground in the source planted
    fps: float = 24.0


@dataclass
class RetargetResult:
    quaternions: np.ndarray        # (F, Jt, 4) pose-bone rotations (w, x, y, z), sign-continuous
    driven: list                   # indices of the target bones the clip keys
    mapped: list                   # the mapped ones among them (the others are kept at rest)
    root_bone: int                 # index of the bone that carries the root location
    root_locations: np.ndarray     # (F, 3) its pose location
    ratio: float                   # target / source leg length
    report: dict = field(default_factory=dict)


def _check_needed(mapping: Mapping) -> dict:
    pairs = mapping.pairs()
    missing = [r for r in NEEDED if r not in pairs]
    if missing:
        raise ArticulaInputError(describe_missing(missing) + " (the hips and both legs are needed; map them "
                                 "in the panel's list or load a mapping preset)")
    return pairs


def retarget_clip(source: ArmatureRest, target: ArmatureRest, mapping: Mapping, source_pose: np.ndarray,
                  options: RetargetOptions | None = None) -> RetargetResult:
    """Retarget the clip ``source_pose (F, Js, 4, 4)`` (armature-space pose matrices of the source)."""
    options = options or RetargetOptions()
    if source_pose.ndim != 4 or source_pose.shape[1:] != (len(source.bones), 4, 4) or not len(source_pose):
        raise ArticulaInputError(f"the source clip must be (frames, {len(source.bones)}, 4, 4) pose matrices")
    if not np.isfinite(source_pose).all():
        raise ArticulaInputError("the source clip has NaN or infinite values")
    mapping.check(source.bones, target.bones)
    pairs = _check_needed(mapping)
    segs = directions.plan_segments(source, target, pairs)
    src_rot, src_heads = world_pose(source, source_pose)
    world = directions.target_world_rotations(source, target, segs, src_rot, src_heads)
    local = directions.local_rotations(target, segs, world, src_heads)
    src_roles = {r: s for r, (s, _) in pairs.items()}
    tgt_roles = {r: t for r, (_, t) in pairs.items()}
    ratio = root_motion.leg_length(target, tgt_roles) / root_motion.leg_length(source, src_roles)
    hips_s, hips_t = source.index[pairs["hips"][0]], target.index[pairs["hips"][1]]
    _, rest_t = rest_world(target)
    if options.root_motion:
        heights = root_motion.hips_heights(source, target, pairs, source_pose, local, ratio)
        want = root_motion.hips_path(src_heads[:, hips_s], rest_t[hips_t], heights, ratio, options.in_place,
                                     options.fps)
    else:
        want = np.repeat(rest_t[hips_t][None], len(source_pose), axis=0)
    report = {"frames": len(source_pose), "segments": len(segs), "leg_ratio": ratio,
              "unit_mismatch": bool(ratio > UNIT_MISMATCH or ratio < 1.0 / UNIT_MISMATCH)}
    if options.foot_cleanup:
        local, plant = foot_plant.plant_feet(source, target, pairs, src_heads, local, want, options.fps)
        report["foot_contacts"] = plant
    bone = root_motion.translation_bone(target, hips_t, [seg.target for seg in segs])
    loc = root_motion.root_locations(target, local, hips_t, bone, want)
    mapped = {seg.target for seg in segs} | {seg.aim for seg in segs if seg.aim >= 0} | {bone}
    q = quat_sign_continuous(matrix_to_quat(local))
    return RetargetResult(q, sorted(mapped | _path_bones(target, segs)), sorted(mapped), bone, loc, ratio, report)


def _path_bones(target: ArmatureRest, segs) -> set:
    """Target bones between a segment's bone and its child's bone (kept at their rest pose); none when the
    child does not hang from the segment's bone (a rig whose bones follow each other by constraints)."""
    out = set()
    for seg in segs:
        chain, b = [], target.parents[seg.target_child] if seg.target_child >= 0 else -1
        while b >= 0 and b != seg.target:
            chain.append(int(b))
            b = target.parents[b]
        if b == seg.target:
            out.update(chain)
    return out
