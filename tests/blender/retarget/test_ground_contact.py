"""Retargeting keeps the feet on the ground and every segment on the source's direction, on Articula
targets: a CMU BVH through the ``retarget`` command onto a rig built from a model bundle (the BVH's
skeleton hangs from its origin at rest: its floor is the file's), and through the operator onto a rig
learned from scans (rooted at the chest, its spine chain reversed, no neck; its rest pose is a scan).

Ground contact, per frame, read from Blender's evaluated pose bones: the target's lowest foot point
(heads and tails of the mapped feet and toes) above its ground against the source's above its own,
times the leg ratio (thigh + shin, rest)."""
import os

import bpy
import numpy as np
import pytest

from articula.sample_scenes.registered import generate_registered, posed_sequence
from articula.bench import _retarget_metrics as metrics
from articula.solver.retarget.armature import world_pose
from ...conftest import SHARED_DATA
from ..learn.test_learn_rig import import_sequence

WALK = os.path.join(SHARED_DATA, "mocap", "cmu_01_01.bvh")
CLIMB = os.path.join(SHARED_DATA, "mocap", "cmu_131_01.bvh")
CMU_SCALE = 0.056444
FEET = ("foot.L", "foot.R", "toe.L", "toe.R")

pytestmark = pytest.mark.usefixtures("cache_home")


def _world(ob, points):
    M = np.array(ob.matrix_world, dtype=np.float64)
    return np.asarray(points, dtype=np.float64) @ M[:3, :3].T + M[:3, 3]


def lowest_foot(ob, bones, frames) -> np.ndarray:
    """(F,) world height of the lowest head or tail of pose bones ``bones`` at ``frames`` (evaluated)."""
    out = []
    for f in frames:
        bpy.context.scene.frame_set(int(f))
        pts = [p for n in bones for p in (ob.pose.bones[n].head, ob.pose.bones[n].tail)]
        out.append(_world(ob, pts)[:, 2].min())
    return np.array(out)


def rest_lowest_foot(ob, bones) -> float:
    pts = [p for n in bones for p in (ob.data.bones[n].head_local, ob.data.bones[n].tail_local)]
    return float(_world(ob, pts)[:, 2].min())


def leg(ob, names) -> float:
    """Mean over the sides of thigh + shin rest length in world units; ``names`` = ``{role: bone}``."""
    total = []
    for s in ("L", "R"):
        a, b, c = (_world(ob, [ob.data.bones[names[f"{r}.{s}"]].head_local])[0] for r in ("thigh", "shin", "foot"))
        total.append(np.linalg.norm(b - a) + np.linalg.norm(c - b))
    return float(np.mean(total))


def _angle(a, b) -> float:
    return float(np.degrees(np.arccos(np.clip(a @ b / np.linalg.norm(a) / np.linalg.norm(b), -1.0, 1.0))))


def _rest_heads(ob) -> dict:
    return {b.name: _world(ob, [b.head_local])[0] for b in ob.data.bones}


def _names(mapping, side) -> dict:
    return {r: pair[side] for r, pair in mapping.pairs().items()}


def contact_errors(pkg, source, target, frames, source_ground, target_ground) -> np.ndarray:
    """(F,) |target's lowest foot point above ``target_ground`` − leg ratio × the source's above
    ``source_ground``| (world units)."""
    pairs = pkg("addon.retarget.skeleton").auto_mapping(source, target)[0].pairs()
    feet = [r for r in FEET if r in pairs]
    src = {r: s for r, (s, _) in pairs.items()}
    tgt = {r: t for r, (_, t) in pairs.items()}
    ratio = leg(target, tgt) / leg(source, src)
    s = lowest_foot(source, [src[r] for r in feet], frames) - source_ground
    t = lowest_foot(target, [tgt[r] for r in feet], frames) - target_ground
    return np.abs(t - ratio * s)


def test_bvh_through_the_command_onto_a_bundle_rig_keeps_its_feet_on_the_ground(pkg, tmp_path):
    """Before the fix the rig floated 0.9 m: the vertical motion was measured from the BVH's rest hips,
    which sit at its origin (the floor)."""
    assert os.path.isfile(WALK), f"missing fixture {WALK}"
    folder = tmp_path / "sample"
    generate_registered(str(folder), rig="cmu_mb", shape="female", n_poses=1, motion="rom", skin="hybrid",
                        fmt="obj", seed=0)
    cli = pkg("addon.cli.main")
    character, out = str(tmp_path / "character.blend"), str(tmp_path / "out.blend")
    assert cli.main(["build-rig", "--bundle", str(folder / "ground_truth_model.npz"), "--no-bake",
                     "--blend", character]) == 0
    assert cli.main(["retarget", "--source", WALK, "--target", character, "--out", out]) == 0
    bpy.ops.wm.open_mainfile(filepath=out)
    source = bpy.data.objects["cmu_01_01"]
    target = next(o for o in bpy.data.objects if o.type == 'ARMATURE' and o is not source
                  and o.animation_data and o.animation_data.action)
    assert source.scale[0] != pytest.approx(1.0)              # the command scaled the BVH to the target's legs
    pairs = pkg("addon.retarget.skeleton").auto_mapping(source, target)[0].pairs()
    floor = rest_lowest_foot(target, [pairs[r][1] for r in FEET if r in pairs])
    err = contact_errors(pkg, source, target, np.arange(1, 2752, 11), 0.0, floor)
    assert np.median(err) < 0.01 and err.max() < 0.03, (np.median(err), err.max())


@pytest.fixture
def learned(pkg, tmp_path):
    """A rig learned from 8 registered MakeHuman scans (range of motion), and the scans' floor."""
    scans, faces, _ = posed_sequence("cmu_mb", None, 8, "rom", "lbs", seed=0)
    options = pkg("solver.learn.options").LearnOptions(max_iterations=0, workers=2)
    ob = import_sequence(pkg, tmp_path, scans, faces, name="human")
    rig, _, _ = pkg("addon.learn.result").learn_from_object(bpy.context, ob, options, name="Learned")
    return rig.armature, float(scans[..., 2].min())


def test_learned_rig_target_follows_every_segment_and_the_ground(pkg, learned):
    target, floor = learned
    bpy.ops.import_anim.bvh(filepath=CLIMB, global_scale=CMU_SCALE, frame_start=1)
    source = bpy.context.active_object
    action = source.animation_data.action
    action.use_frame_range, action.frame_start, action.frame_end = True, 1, 300
    assert bpy.ops.articula.retarget(source=source.name, target=target.name) == {'FINISHED'}
    frames = np.arange(1, 301, 7)
    mapping = pkg("addon.retarget.skeleton").auto_mapping(source, target)[0]
    read = pkg("addon.retarget.armatures").read_rest
    src, tgt = read(source), read(target)
    clip = pkg("addon.retarget.source_clip").pose_from_scene
    hs, ht = (world_pose(a, clip(o, a, frames))[1] for a, o in ((src, source), (tgt, target)))
    angles = metrics.role_segment_angles(mapping.pairs(), src.index, tgt.index, hs, ht)
    assert {"hips-chest", "thigh.L-shin.L", "shin.R-foot.R", "upper_arm.L-forearm.L", "neck-head"} <= set(angles)
    assert all(v.max() < 0.05 for k, v in angles.items() if k != "hips-top"), angles
    # hips to neck crosses the chest's rest shape: off by at most the rests' difference in that bend
    bend = [_angle(h[i["chest"]] - h[i["hips"]], h[i["neck"]] - h[i["hips"]])
            for h, i in ((_rest_heads(source), _names(mapping, 0)), (_rest_heads(target), _names(mapping, 1)))]
    assert angles["hips-top"].max() < abs(bend[1] - bend[0]) + 2.0, (angles["hips-top"].max(), bend)
    err = contact_errors(pkg, source, target, frames, 0.0, floor)
    assert np.median(err) < 0.03, (np.median(err), err.max())
