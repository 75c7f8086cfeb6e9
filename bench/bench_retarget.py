"""Retargeting benchmark: ``./run bench retarget [--quick] [--no-topology] [--no-scan]``.

Skeleton retargeting of the CMU BVH clips in ../shared/data/mocap (both naming styles, T-pose, imported
with Blender's own importer at CMU's scale: the panel's path) onto MakeHuman's A-pose rigs (default 163
bones with twist segments, game_engine = the Unreal mannequin's names, cmu_mb, mixamo = Mixamo's names)
and onto Articula rigs (the template body built as an exact swing/twist rig, a rig built from a model
bundle, a rig learned from registered scans):

* segment directions: angle between every mapped source and target segment of a role and its first mapped
  child (:func:`metrics.role_segment_angles`, whatever the rigs' hierarchies: the reversed chains of a
  learned rig count), both read back from Blender's evaluated poses at every frame, per segment for the
  learned rig; and hips to neck/head (the lean; not a segment where a rig lacks a spine or neck bone);
* ground contact: per frame, the target's lowest foot point (heads and tails of the mapped feet and
  toes, Blender's evaluated pose) above its ground against the source's above its own times the leg
  ratio; grounds: a BVH's floor is its object's origin (the file's floor), other rigs stand on their
  rest pose's lowest foot point, a learned rig on the floor its scans stood on (z = 0, its rest pose is
  a scan); median and max in cm;
* root travel: the target hips' horizontal path length / (source's x leg-length ratio) (target: within 10 %);
* foot sliding: the ankle's horizontal path during the source's foot contacts, in cm, clean-up off and on;
* speed: 1,000 frames onto the 163-bone MakeHuman default rig, operator wall time (target <= 5 s);
  and the slow path of constrained targets: cmu_131_01 onto Rigify's generated human (FK controls).

Then ground contact and angles for the other sources onto every target kind: the BVH through the
``retarget`` command's path (imported at scale 1, its object scaled to the target's legs) and an animated
armature appended from a .blend (the command's ``--source x.blend``).  Then the shared-topology fit
(:mod:`bench_retarget_topology`) and the scan binding (:mod:`bench_scan_binding`).
"""
import importlib
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))   # the bench command loads us by path
import _common  # noqa: E402  (makes ``import articula`` work)

import bpy  # noqa: E402
import numpy as np  # noqa: E402

from _armatures import new_armature  # noqa: E402
from articula.sample_scenes import mpfb_armature  # noqa: E402
import _retarget_metrics as metrics  # noqa: E402
from articula.solver.retarget import foot_plant  # noqa: E402
from articula.solver.retarget.armature import world_pose  # noqa: E402
from articula.solver.roles import LEG_ROLES  # noqa: E402

MOCAP = os.path.join(os.path.dirname(os.path.realpath(_common.REPO)), "shared", "data", "mocap")
CLIPS = ("cmu_01_01", "cmu_131_01")
RIGS = ("default", "game_engine", "cmu_mb", "mixamo")
CMU_SCALE = 0.056444
FEET = ("foot.L", "foot.R", "toe.L", "toe.R")


def _addon():
    """``pkg(name)`` importing a submodule of the enabled extension (the one whose operators run)."""
    sys.path.insert(0, _common.REPO)
    import batch
    mod = batch.enable_addon(bpy)
    return lambda name: importlib.import_module(f"{mod}.{name}")


def _bvh(name):
    path = os.path.join(MOCAP, name + ".bvh")
    if not os.path.isfile(path):
        raise SystemExit(f"missing {path} (../shared/data/mocap)")
    bpy.ops.import_anim.bvh(filepath=path, global_scale=CMU_SCALE, frame_start=1)
    return bpy.context.active_object


def _mpfb(pkg, rig):
    d = mpfb_armature.rig_bones(rig)
    return new_armature(
        bpy.context, f"MPFB {rig}", d["names"], d["parents"], d["heads"], d["tails"], d["rolls"])


def _articula_template(pkg):
    from articula.solver.track_depth.template import load_template
    rig = pkg("addon.rig.builder").build_rig(bpy.context, load_template().base, "Articula template")
    return rig.armature


def _scans(n=20):
    """A folder of registered MakeHuman scans (cmu_mb, female, range of motion) with its model bundle."""
    import tempfile
    from articula.sample_scenes.registered import generate_registered
    folder = tempfile.mkdtemp(prefix="articula_bench_scans_")
    generate_registered(folder, rig="cmu_mb", shape="female", n_poses=n, motion="rom", skin="hybrid",
                        fmt="obj", seed=0)
    return folder


def _bundle_rig(pkg, folder):
    """The Articula rig ``build-rig`` makes from the scans' model bundle (ground_truth_model.npz)."""
    rig, _ = pkg("addon.rig.bundle_io").build_from_bundle(
        bpy.context, os.path.join(folder, "ground_truth_model.npz"), "Articula bundle rig", False)
    return rig.armature


def _learned_rig(pkg, folder):
    """A rig learned by ``articula.learn_rig`` from the scans in ``folder`` (role names when it recognises a
    humanoid), as a user would make one."""
    before = set(bpy.data.objects)
    bpy.ops.articula.import_scans(directory=folder, files=[{"name": f} for f in sorted(os.listdir(folder))
                                                           if f.endswith(".obj")])
    seq = next(o for o in bpy.data.objects if o not in before)
    t0 = time.perf_counter()
    bpy.ops.articula.learn_rig(source_object=seq.name, name="Learned", max_iterations=2, seed=0)
    arm = next(o for o in bpy.data.objects if o.type == 'ARMATURE' and "articula_learn_report" in o)
    named = [b.name for b in arm.data.bones if not b.name.startswith(("SW-", "TW-", "part_"))]
    tree = {b.name: b.parent.name if b.parent else None for b in arm.data.bones if b.name in named}
    print(f"learned rig: {len(arm.data.bones)} bones, {len(named)} named by role, root "
          f"{arm.data.bones[0].name!r}, parents {tree}, {time.perf_counter() - t0:.1f} s", flush=True)
    seq.hide_set(True)
    return arm


def _rigify():
    """Rigify's human generated by Blender's own Rigify, limbs switched to FK (its FK controls hang from
    MCH bones that follow by constraints: the evaluated-target path)."""
    import addon_utils
    addon_utils.enable("rigify", default_set=True)
    bpy.ops.object.armature_human_metarig_add()
    bpy.ops.pose.rigify_generate()
    bpy.ops.object.mode_set(mode='OBJECT')
    rig = bpy.data.objects["rig"]
    for name in ("upper_arm_parent.L", "upper_arm_parent.R", "thigh_parent.L", "thigh_parent.R"):
        rig.pose.bones[name]["IK_FK"] = 1.0
    rig.location.x += 3.0
    return rig


def _evaluated(pkg, ob, frames):
    """``(rest, (world rotations, world heads), pose)`` of ``ob`` read from the evaluated scene."""
    rest = pkg("addon.retarget.armatures").read_rest(ob)
    pose = pkg("addon.retarget.source_clip").pose_from_scene(ob, rest, frames)
    return rest, world_pose(rest, pose), pose


def _sliding_cm(pkg, src, tgt, hs, ht, pairs, fps, scale):
    """Mean ankle slide (cm) over the source's contacts, per side, of evaluated heads ``hs``/``ht``."""
    leg = pkg("solver.retarget.root_motion").leg_length(src, {r: s for r, (s, _) in pairs.items()})
    out, own = [], []
    for side, (_, _, foot) in LEG_ROLES.items():
        ranges = foot_plant.contacts(hs[:, src.index[pairs[foot][0]]], leg, fps)
        out.append(100 * foot_plant.sliding(ht[:, tgt.index[pairs[foot][1]]], ranges))
        own.append(100 * foot_plant.sliding(hs[:, src.index[pairs[foot][0]]], ranges) * scale)
    return float(np.mean(out)), float(np.mean(own))


def _feet_low(ob, rest, pose, bones) -> np.ndarray:
    """(F,) world height of the lowest head or tail of ``bones`` in evaluated armature-space ``pose``."""
    idx = [rest.index[b] for b in bones]
    M = pose[:, idx]
    lengths = np.array([ob.data.bones[b].length for b in bones])
    heads = M[..., :3, 3]
    tails = heads + M[..., :3, 1] / np.linalg.norm(M[..., :3, 1], axis=-1, keepdims=True) * lengths[:, None]
    return rest.world_points(np.concatenate([heads, tails], axis=1))[..., 2].min(axis=1)


def ground(ob, kind: str, bones) -> float:
    """World height ``ob`` stands on: 'origin' (a BVH's floor), 'floor' (z = 0: a learned rig's scans) or
    'rest' (its rest pose's lowest foot point)."""
    if kind == "origin":
        return float(ob.matrix_world.translation.z)
    if kind == "floor":
        return 0.0
    M = np.array(ob.matrix_world, dtype=np.float64)
    pts = np.array([p for b in bones for p in (ob.data.bones[b].head_local, ob.data.bones[b].tail_local)])
    return float((pts @ M[:3, :3].T + M[:3, 3])[:, 2].min())


def contact_cm(pkg, source, target, src_read, tgt_read, pairs, grounds) -> np.ndarray:
    """(F,) cm: |target's lowest foot point above its ground − leg ratio × the source's above its own|."""
    feet = [r for r in FEET if r in pairs]
    legs = [pkg("solver.retarget.root_motion").leg_length(rest, {r: p[k] for r, p in pairs.items()})
            for k, rest in ((0, src_read[0]), (1, tgt_read[0]))]
    lows = [_feet_low(ob, read[0], read[2], [pairs[r][k] for r in feet]) - ground(ob, kind, [pairs[r][k] for r in feet])
            for k, (ob, read, kind) in enumerate(((source, src_read, grounds[0]), (target, tgt_read, grounds[1])))]
    return 100 * np.abs(lows[1] - legs[1] / legs[0] * lows[0])


def _angles_text(angles: dict) -> str:
    segs = np.stack([a for k, a in angles.items() if k != "hips-top"], axis=1)
    text = (f"{segs.shape[1]} segments, angle mean {segs.mean():.4f} deg p95 {np.percentile(segs, 95):.4f} "
            f"max {segs.max():.4f}")
    if "hips-top" in angles:
        text += f", hips to neck/head median {np.median(angles['hips-top']):.2f} max {angles['hips-top'].max():.2f}"
    return text


def _segments_line(label, angles: dict) -> str:
    return f"  {label} per segment (median / max deg): " + ", ".join(
        f"{k} {np.median(a):.4f} / {a.max():.4f}" for k, a in angles.items())


def measure(pkg, source, target, label, grounds, full=True):
    """One result line for ``source`` retargeted onto ``target`` (fresh actions each time); ``grounds`` =
    (source, target) ground kinds (:func:`ground`); ``full``: also travel, sliding and the clean-up run."""
    skeleton = pkg("addon.retarget.skeleton")
    fps = bpy.context.scene.render.fps
    t0 = time.perf_counter()
    bpy.ops.articula.retarget(source=source.name, target=target.name)
    seconds = time.perf_counter() - t0
    first, last = (int(x) for x in target.animation_data.action.frame_range)
    frames = np.arange(first, last + 1)
    pairs = skeleton.auto_mapping(source, target)[0].pairs()
    src_read, tgt_read = _evaluated(pkg, source, frames), _evaluated(pkg, target, frames)
    (src, (_, hs), _), (tgt, (_, ht), _) = src_read, tgt_read
    angles = metrics.role_segment_angles(pairs, src.index, tgt.index, hs, ht)
    contact = contact_cm(pkg, source, target, src_read, tgt_read, pairs, grounds)
    text = (f"{source.name} -> {label}: {len(frames)} frames, {_angles_text(angles)}; ground contact "
            f"median {np.median(contact):.2f} cm max {contact.max():.2f} cm")
    if full:
        report = skeleton.retarget(bpy.context, source, target)[1]
        hips_s, hips_t = src.index[pairs["hips"][0]], tgt.index[pairs["hips"][1]]
        travel = metrics.travel(ht[:, hips_t]) / (report["leg_ratio"] * metrics.travel(hs[:, hips_s]))
        scale = target.matrix_world.to_scale()[0] / source.matrix_world.to_scale()[0]
        slide_off, slide_src = _sliding_cm(pkg, src, tgt, hs, ht, pairs, fps, scale)
        bpy.ops.articula.retarget(source=source.name, target=target.name, foot_cleanup=True)
        tgt, (_, ht), _ = _evaluated(pkg, target, frames)
        slide_on, _ = _sliding_cm(pkg, src, tgt, hs, ht, pairs, fps, scale)
        text += (f"; travel / (source x leg ratio {report['leg_ratio']:.3f}) = {travel:.4f}; foot sliding per "
                 f"contact {slide_off:.2f} cm -> {slide_on:.2f} cm with clean-up (the source's own ankle: "
                 f"{slide_src:.2f} cm)")
    text += f"; {seconds:.2f} s"
    return text + ("\n" + _segments_line(label, angles) if "learned" in label else "")


def speed_line(pkg) -> str:
    """1,000 frames of cmu_01_01 onto the 163-bone MakeHuman default rig (operator wall time)."""
    source = bpy.data.objects["cmu_01_01"]
    action = source.animation_data.action
    action.use_frame_range, action.frame_start, action.frame_end = True, 1, 1000
    target = _mpfb(pkg, "default")
    runs = []
    for _ in range(3):
        t0 = time.perf_counter()
        bpy.ops.articula.retarget(source=source.name, target=target.name)
        runs.append(time.perf_counter() - t0)
    action.use_frame_range = False
    best = min(runs)
    return (f"speed: 1000 frames onto {len(target.data.bones)} bones: best {best:.2f} s of 3 "
            f"({', '.join(f'{r:.2f}' for r in runs)}); ratio to the 5 s target {best / 5.0:.3f}")


def _blend_source(pkg, clip):
    """An animated armature in a .blend, appended as ``retarget --source x.blend`` does: the Articula
    template body with ``clip`` retargeted onto it, saved alone to a file."""
    import tempfile
    body = _articula_template(pkg)
    body.name = "Dancer"
    bpy.ops.articula.retarget(source=clip.name, target=body.name)
    path = os.path.join(tempfile.mkdtemp(prefix="articula_bench_source_"), "dancer.blend")
    bpy.data.libraries.write(path, {body})
    for ob in [o for o in bpy.data.objects if o.parent == body] + [body]:
        bpy.data.objects.remove(ob)
    return path


def other_sources_lines(pkg, clip, targets):
    """Ground contact and angles onto every target from the BVH through the command's path (scale 1,
    object scaled to the target's legs) and from an armature appended from a .blend."""
    cli = pkg("addon.cli.retarget")
    path = os.path.join(MOCAP, clip + ".bvh")
    blend = _blend_source(pkg, bpy.data.objects[clip])
    for target, label, kind in targets:
        frames = (1, 200) if "Rigify" in label else None
        for how in ("command", "blend"):
            if how == "command":
                source = cli._import_bvh(path, 0.0)
                cli._match_size(source, target)
                grounds, what = ("origin", kind), f"BVH via the command (object scale {source.scale[0]:.4f})"
            else:
                source, grounds, what = cli._append(blend, "Dancer"), ("rest", kind), ".blend armature"
            action = source.animation_data.action
            if frames:
                action.use_frame_range, action.frame_start, action.frame_end = True, *frames
            yield f"[{what}] " + measure(pkg, source, target, label, grounds, full=False)
            bpy.data.objects.remove(source)


def main(argv=None) -> int:
    argv = list(argv or [])
    quick = "--quick" in argv
    pkg = _addon()
    bpy.ops.wm.read_homefile(use_empty=True)
    clips = CLIPS[1:] if quick else CLIPS
    for clip in clips:
        _bvh(clip)
    targets = [(_mpfb(pkg, rig), f"MPFB {rig}", "rest") for rig in (RIGS[:2] if quick else RIGS)]
    targets.append((_articula_template(pkg), "Articula template rig", "rest"))
    folder = _scans(4 if quick else 20)
    targets.append((_bundle_rig(pkg, folder), "Articula rig built from a bundle", "rest"))
    if not quick:
        targets.append((_learned_rig(pkg, folder), "Articula learned rig", "floor"))
    for clip in clips:
        for target, label, kind in targets:
            print(measure(pkg, bpy.data.objects[clip], target, label, ("origin", kind)), flush=True)
    if not quick:
        targets.append((_rigify(), "Rigify human (FK controls)", "rest"))
        print(measure(pkg, bpy.data.objects[clips[-1]], *targets[-1][:2], ("origin", "rest")), flush=True)
    for line in other_sources_lines(pkg, clips[-1], targets):
        print(line, flush=True)
    if not quick:
        print(speed_line(pkg), flush=True)
    if "--no-topology" not in argv:
        from bench_retarget_topology import topology_lines
        for line in topology_lines():
            print(line, flush=True)
    if "--no-scan" not in argv:
        from bench_scan_binding import scan_binding_lines
        for line in scan_binding_lines():
            print(line, flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
