"""Skeleton retargeting (solver.retarget.solve / directions / root_motion): exact segment directions
under different rest poses, rolls, proportions, facings and twist splits; identical rigs reproduce the
source's channels; the root travel scales with the leg ratio; refusals."""
import numpy as np
import pytest

from articula.solver.errors import ArticulaInputError
from articula.bench import _retarget_metrics as metrics
from articula.solver.retarget import directions
from articula.solver.retarget.armature import forward, local_matrices, world_pose
from articula.solver.geometry.rotations import quat_to_matrix
from articula.solver.retarget.mapping import Mapping
from articula.solver.retarget.solve import RetargetOptions, retarget_clip

from .humanoids import humanoid, random_clip


def _target_pose(target, result):
    """The target's world rotations and heads from the result's channels (forward kinematics)."""
    loc = np.zeros(result.quaternions.shape[:2] + (3,))
    loc[:, result.root_bone] = result.root_locations
    return world_pose(target, forward(target, local_matrices(quat_to_matrix(result.quaternions), loc)))


def _run(source, src_roles, target, tgt_roles, frames=25, seed=0, **opts):
    clip = random_clip(source, frames, seed=seed)
    mapping = Mapping.from_roles(src_roles, tgt_roles)
    result = retarget_clip(source, target, mapping, clip, RetargetOptions(**opts))
    return clip, mapping, result


def test_identical_rigs_reproduce_the_source_channels():
    rng = np.random.default_rng(3)
    source, roles = humanoid(rng=rng)
    clip, _, result = _run(source, roles, source, roles)
    _, heads_s = world_pose(source, clip)
    R, heads_t = _target_pose(source, result)
    assert np.abs(heads_t - heads_s).max() < 1e-9
    R_s, _ = world_pose(source, clip)
    assert np.abs(R - R_s).max() < 1e-9


@pytest.mark.parametrize("twist,clavicle,girdle", [(False, True, False), (True, False, True), (True, True, True)])
def test_segments_follow_the_source_across_rest_pose_roll_scale_and_facing(twist, clavicle, girdle):
    """T-pose source, A-pose target (other rolls, proportions, bone splits, facing, units): every mapped
    segment points exactly where the source's points."""
    rng = np.random.default_rng(5)
    source, src_roles = humanoid(1.0, 0.0, rng=rng, world_scale=17.0, name="bvh")
    target, tgt_roles = humanoid(1.85, 45.0, twist, clavicle, girdle, rng=rng, yaw_deg=160.0, offset=(3, 1, 0),
                                 names=lambda r: "tgt_" + r.replace(".", "_"))
    clip, mapping, result = _run(source, src_roles, target, tgt_roles)
    _, heads_s = world_pose(source, clip)
    _, heads_t = _target_pose(target, result)
    segs = directions.plan_segments(source, target, mapping.pairs())
    angles = metrics.segment_angles(segs, heads_s, heads_t)
    assert angles.shape[1] >= 14
    assert angles.max() < 1e-5


def test_twist_follows_the_source_bone():
    """Same rest directions, other rolls: each mapped bone turns by the source bone's world rotation."""
    source, roles = humanoid(rng=np.random.default_rng(1))
    target, _ = humanoid(rng=np.random.default_rng(2))
    clip, mapping, result = _run(source, roles, target, roles)
    R_s, _ = world_pose(source, clip)
    R_t, _ = _target_pose(target, result)
    for role, (s, t) in mapping.pairs().items():
        i, j = source.index[s], target.index[t]
        delta_s = R_s[:, i] @ source.rest[i, :3, :3].T
        delta_t = R_t[:, j] @ target.rest[j, :3, :3].T
        assert np.abs(delta_s - delta_t).max() < 1e-9, role


def test_root_travel_scales_with_the_leg_ratio_and_in_place_removes_it():
    source, roles = humanoid(1.0)
    target, _ = humanoid(1.6)
    clip, mapping, result = _run(source, roles, target, roles, frames=60)
    assert result.ratio == pytest.approx(1.6, rel=1e-9)
    _, heads_s = world_pose(source, clip)
    _, heads_t = _target_pose(target, result)
    hips = source.index["hips"]
    assert metrics.travel(heads_t[:, hips]) == pytest.approx(1.6 * metrics.travel(heads_s[:, hips]), rel=1e-9)
    assert metrics.vertical_range(heads_t[:, hips]) == pytest.approx(1.6 * metrics.vertical_range(heads_s[:, hips]))
    _, _, still = _run(source, roles, target, roles, frames=60, in_place=True)
    _, heads_p = _target_pose(target, still)
    assert metrics.travel(heads_p[:, hips]) < 0.3 * metrics.travel(heads_t[:, hips])


def test_missing_roles_and_bad_clips_are_refused():
    source, roles = humanoid()
    target, tgt_roles = humanoid()
    clip = random_clip(source, 3)
    no_legs = {r: b for r, b in tgt_roles.items() if not r.startswith("shin")}
    with pytest.raises(ArticulaInputError, match="shin.L, shin.R"):
        retarget_clip(source, target, Mapping.from_roles(roles, no_legs), clip)
    bad = clip.copy()
    bad[1, 3, 0, 0] = np.nan
    with pytest.raises(ArticulaInputError, match="NaN"):
        retarget_clip(source, target, Mapping.from_roles(roles, tgt_roles), bad)
    with pytest.raises(ArticulaInputError, match="frames"):
        retarget_clip(source, target, Mapping.from_roles(roles, tgt_roles), clip[:, :4])
    with pytest.raises(ArticulaInputError, match="does not have"):
        retarget_clip(source, target, Mapping.from_roles(roles, {**tgt_roles, "head": "nope"}), clip)


def test_root_motion_goes_on_the_bone_that_carries_the_body():
    """A learned rig whose root part is the chest (hips a child of it): the root moves, and the hips land
    where they should; a rig with a floor root bone above the hips moves the hips."""
    source, roles = humanoid(1.0)
    target, _ = humanoid(1.0)
    order = ["chest", "hips"] + [b for b in target.bones if b not in ("chest", "hips")]
    idx = [target.index[b] for b in order]
    parent_name = {b: (target.bones[p] if p >= 0 else None) for b, p in zip(target.bones, target.parents)}
    parent_name["chest"], parent_name["hips"], parent_name["spine"] = None, "chest", "hips"
    from articula.solver.retarget.armature import ArmatureRest
    chest_root = ArmatureRest("learned", order, [order.index(parent_name[b]) if parent_name[b] else -1 for b in order],
                              target.rest[idx], target.tails[idx], np.zeros(len(order), bool), target.world)
    clip, mapping, result = _run(source, roles, chest_root, roles, frames=30)
    assert chest_root.bones[result.root_bone] == "chest"
    _, heads_s = world_pose(source, clip)
    _, heads_t = _target_pose(chest_root, result)
    i, j = source.index["hips"], chest_root.index["hips"]
    assert np.abs((heads_t[:, j] - heads_t[0, j]) - (heads_s[:, i] - heads_s[0, i])).max() < 1e-9


def _chest_rooted(arm, part=True):
    """A learned-like rig from humanoid ``arm``: rooted at the chest, its spine chain reversed (each bone
    runs down from its upper joint), an unmapped part between the chest and the spine (or not)."""
    from articula.sample_scenes.mpfb_rig import roll_frames
    from articula.solver.retarget.armature import ArmatureRest
    h = {b: arm.rest[i, :3, 3] for i, b in enumerate(arm.bones)}
    mid = (h["chest"] + h["spine"]) / 2
    spec = [("chest", None, h["chest"], mid), ("part", "chest", mid, h["spine"]),
            ("spine", "part", h["spine"], h["hips"]), ("hips", "spine", h["hips"], h["hips"] - [0, 0, 0.05])]
    if not part:
        spec = [spec[0][:3] + (h["spine"],), ("spine", "chest") + spec[2][2:], spec[3]]
    for i, b in enumerate(arm.bones):
        if b not in ("hips", "spine", "chest"):
            spec.append((b, arm.bones[arm.parents[i]], h[b], arm.tails[i]))
    names = [s[0] for s in spec]
    heads, tails = np.array([s[2] for s in spec]), np.array([s[3] for s in spec])
    rest = np.tile(np.eye(4), (len(spec), 1, 1))
    rest[:, :3, :3], rest[:, :3, 3] = roll_frames(heads, tails, np.zeros(len(spec))), heads
    parents = [names.index(s[1]) if s[1] else -1 for s in spec]
    return ArmatureRest("learned", names, parents, rest, tails, np.zeros(len(spec), bool), arm.world)


def _heads(arm, pose):
    return world_pose(arm, pose)[1]


def test_reversed_chains_of_a_chest_rooted_rig_follow_every_segment():
    """Hips and spine hang below the chest (their segments' child joints are their ancestors): the bones
    above them aim those segments, exactly, as every other segment."""
    source, roles = humanoid(1.0, rng=np.random.default_rng(4))
    learned = _chest_rooted(humanoid(1.7, 40.0)[0])
    clip, mapping, result = _run(source, roles, learned, roles, frames=30)
    _, heads_t = _target_pose(learned, result)
    angles = metrics.role_segment_angles(mapping.pairs(), source.index, learned.index, _heads(source, clip), heads_t,
                                         trunk=False)
    assert {"hips-spine", "spine-chest", "thigh.L-shin.L", "chest-neck"} <= set(angles)
    assert max(a.max() for a in angles.values()) < 1e-4, {k: round(a.max(), 5) for k, a in angles.items() if a.max() > 1e-4}


def _lowest_foot(arm, heads):
    feet = [arm.index[b] for b in ("foot.L", "foot.R", "toe.L", "toe.R")]
    tails_z = [arm.world_points(arm.tails[f])[2] for f in feet]
    return heads[:, feet, 2].min(axis=1), min(tails_z)


def test_feet_meet_the_ground_of_a_skeleton_that_hangs_from_its_origin():
    """A BVH-like source: its rest skeleton hangs from the origin (root offset zero) while the clip walks
    on the floor through it: the target's feet stay on its ground, as onto a standing source."""
    source, roles = humanoid(1.0)
    target, _ = humanoid(1.7, 40.0, yaw_deg=30.0, world_scale=2.0, offset=(1, 2, 0.5))
    clip = random_clip(source, 40, amplitude=0.3, seed=2)
    clip[:, :, 2, 3] -= _lowest_foot(source, _heads(source, clip))[0].min()       # the clip stands on z = 0
    hanging = source.__class__(**{k: getattr(source, k) for k in ("name", "bones", "parents", "rest", "tails",
                                                                 "connected", "world")})
    hanging.rest = source.rest.copy()
    hanging.rest[:, 2, 3] -= 0.53                                                 # hips at the origin
    hanging.tails = source.tails - [0, 0, 0.53]
    mapping = Mapping.from_roles(roles, roles)
    for src in (source, hanging):
        result = retarget_clip(src, target, mapping, clip)
        _, heads_t = _target_pose(target, result)
        t_low, _ = _lowest_foot(target, heads_t)
        rest_low = min(_lowest_foot(target, world_pose(target, target.rest[None])[1])[0].min(),
                       _lowest_foot(target, world_pose(target, target.rest[None])[1])[1])
        s_low = _lowest_foot(src, _heads(src, clip))[0]
        ground = 0.0 if src is hanging else min(_lowest_foot(source, world_pose(source, source.rest[None])[1])[0].min(),
                                                _lowest_foot(source, world_pose(source, source.rest[None])[1])[1])
        assert np.abs((t_low - rest_low) - result.ratio * (s_low - ground)).max() < 1e-9


def test_a_chest_that_carries_neck_and_spine_aims_the_longer_segment():
    """No part between chest and spine: the chest bone spans the reversed spine segment and carries the
    neck; it aims the longer (the spine: the lean), the neck bone still aims neck to head."""
    source, roles = humanoid(1.0, rng=np.random.default_rng(6))
    learned = _chest_rooted(humanoid(1.7, 40.0)[0], part=False)
    clip, mapping, result = _run(source, roles, learned, roles, frames=30)
    _, heads_t = _target_pose(learned, result)
    angles = metrics.role_segment_angles(mapping.pairs(), source.index, learned.index, _heads(source, clip), heads_t,
                                         trunk=False)
    assert angles["chest-neck"].max() > 1.0                          # the shorter one gives way
    off = {k: round(a.max(), 5) for k, a in angles.items() if k != "chest-neck" and a.max() > 1e-4}
    assert not off and {"hips-spine", "spine-chest"} <= set(angles), off
