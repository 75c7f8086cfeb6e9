"""Gaze shots on an MPFB rig and the template body: gaze error (deg), chain shares, fades, speed.

Usage: ``./run bench gaze [--tracked TRACKED.blend]``.

Two characters (spec test A1 on real rigs; targets from the issue):

* an MPFB/MakeHuman default rig (163 bones, eye bones) with an idle animation (slow sway of spine, neck and
  head, shifting weight) looking at a target that circles in front of it, on the average body and on the
  stooped "old" body;
* the Articula template body (exact swing/twist rig, gaze line from the annotated MakeHuman eyes and back
  of the head) moved by a tracked-like motion: CMU 131_01 retargeted onto it.

For each: the gaze error at full strength (deg, read back from Blender's evaluated pose; on the MPFB rigs also
the face's: the head's rest front −Y from the eyes' midpoint, the eyes' from each eye), the chest/neck/
head shares of the turn, whether frames outside the shot are bit-identical, whether the fade is monotone,
and the time of the shot; then the speed of a 1,000-frame shot (target <= 1 s).  ``--tracked`` adds the
rig of a tracked sample (e.g. ``out/tracked_depth.blend`` of the README's batch sequence).
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
from articula.sample_scenes.subjects import resolve_macros  # noqa: E402
from articula.solver.gaze import fade  # noqa: E402
from articula.solver.gaze.aim import gaze_line  # noqa: E402
from articula.solver.geometry.rotations import matrix_to_quat, quat_to_rotvec, rotvec_to_quat  # noqa: E402
from articula.solver.rig.model import Poses  # noqa: E402

MOCAP = os.path.join(os.path.dirname(os.path.realpath(_common.REPO)), "shared", "data", "mocap")


def _addon():
    sys.path.insert(0, _common.REPO)
    import batch
    mod = batch.enable_addon(bpy)
    return lambda name: importlib.import_module(f"{mod}.{name}")


def idle_rig(pkg, frames=240, shape=None):
    """MakeHuman default rig (body of preset ``shape``, None = average) with a procedural idle: spine, neck
    and head sway a few degrees, hips shift."""
    d = mpfb_armature.rig_bones("default", resolve_macros(shape) if shape else None)
    ob = new_armature(
        bpy.context, "Idle", d["names"], d["parents"], d["heads"], d["tails"], d["rolls"])
    names = d["names"]
    t = np.arange(frames) / 24.0
    rv = np.zeros((frames, len(names), 3))
    for name, amp, period in (("spine03", 3.0, 4.0), ("neck02", 4.0, 5.5), ("head", 5.0, 3.3), ("spine05", 2.0, 6.0)):
        b = names.index(name)
        rv[:, b, 0] = np.radians(amp) * np.sin(2 * np.pi * t / period)
        rv[:, b, 2] = np.radians(amp) * np.sin(2 * np.pi * t / (1.7 * period))
    trans = np.stack([0.03 * np.sin(2 * np.pi * t / 6.0), np.zeros(frames), np.zeros(frames)], axis=1)
    for pb in ob.pose.bones:
        pb.rotation_mode = 'QUATERNION'
    pkg("addon.rig.actions").write_action(ob, names, Poses(rotvec_to_quat(rv), trans, np.ones(frames)), name="Idle")
    return ob


def tracked_body(pkg):
    """The Articula template body moved by CMU 131_01 (994 frames) retargeted onto it."""
    from articula.solver.track_depth.template import load_template
    bpy.ops.import_anim.bvh(filepath=os.path.join(MOCAP, "cmu_131_01.bvh"), global_scale=0.056444, frame_start=1)
    source = bpy.context.active_object
    rig = pkg("addon.rig.builder").build_rig(bpy.context, load_template().base, "Body")
    bpy.ops.articula.retarget(source=source.name, target=rig.armature.name)
    rig.armature.location.x += 3.0
    return rig.armature


def circling_target(centre, frames, radius=1.2, name="Look"):
    ob = bpy.data.objects.new(name, None)
    bpy.context.scene.collection.objects.link(ob)
    for f in np.linspace(frames[0], frames[-1], 9):
        a = 2 * np.pi * (f - frames[0]) / (frames[-1] - frames[0])
        ob.location = (centre[0] + radius * np.sin(a), centre[1] - 2.5, centre[2] + 0.3 * np.cos(a))
        ob.keyframe_insert("location", frame=int(f))
    return ob


def measure(pkg, ob, target, first, last, fade_frames, label):
    shot, chain_mod = pkg("addon.gaze.shot"), pkg("addon.gaze.chain")
    read_rest, pose_from_scene = pkg("addon.retarget.armatures").read_rest, pkg("addon.retarget.source_clip").pose_from_scene
    span = shot.animation_range(ob)
    frames = np.arange(span[0], span[1] + 1)
    rest = read_rest(ob)
    before = pose_from_scene(ob, rest, frames)
    report = shot.apply_shot(bpy.context, ob, target, first, last, fade_frames)
    after = pose_from_scene(ob, rest, frames)
    chain, _, how = chain_mod.gaze_chain(ob, rest)
    w = fade.shot_weights(frames, first, last, fade_frames)
    full = (w == 1.0) & ~np.isin(frames, report["limited"])
    p, d = gaze_line(rest, after[full], chain)
    goal = rest.armature_points(shot.target_path(bpy.context, target, frames[full])) - p
    err = np.degrees(np.arccos(np.clip(np.einsum("fi,fi->f", d, goal) / np.linalg.norm(goal, axis=1), -1, 1)))
    rel = rest.relative_rest()
    turns = []
    for j in chain.joints:
        Pb = before[full][:, rest.parents[j], :3, :3] @ rel[j][:3, :3]
        Pa = after[full][:, rest.parents[j], :3, :3] @ rel[j][:3, :3]
        Lb, La = np.linalg.solve(Pb, before[full][:, j, :3, :3]), np.linalg.solve(Pa, after[full][:, j, :3, :3])
        D = Pb @ La @ np.linalg.inv(Lb) @ np.swapaxes(Pb, 1, 2)
        turns.append(np.linalg.norm(quat_to_rotvec(matrix_to_quat(D)), axis=1))
    turns = np.stack(turns, axis=1)
    shares = (turns / turns.sum(axis=1, keepdims=True)).mean(axis=0)
    face = _face_errors(rest, after[full], rest.armature_points(shot.target_path(bpy.context, target, frames[full])))
    outside = (frames < first) | (frames > last)
    same = np.array_equal(after[outside], before[outside])
    ramp = w[(frames >= first) & (frames <= first + fade_frames)]
    return (f"{label}: shot {first}-{last} (fade {fade_frames}), gaze line from {how}; at full strength error "
            f"mean {err.mean():.4f} deg max {err.max():.4f} deg{face}; shares chest/neck/head "
            f"{' / '.join(f'{s:.4f}' for s in shares)}; frames outside the shot bit-identical: {same}; fade "
            f"monotone: {bool(np.all(np.diff(ramp) > 0))}; out of reach (limited, left out of the error) on "
            f"{len(report['limited'])} frames; "
            f"{report['seconds']:.3f} s for {report['frames']} frames")


def _face_errors(rest, pose, goal) -> str:
    """Largest angle (deg) between the target and the face (head's rest −Y from the eyes' midpoint) and each
    eye (its rest −Y from its centre) in poses ``pose``; '' without MPFB eye bones."""
    if not {"eye.L", "eye.R"} <= set(rest.index):
        return ""

    def front(bone):
        j = rest.index[bone]
        return pose[:, j, :3, :3] @ (rest.rest[j, :3, :3].T @ [0.0, -1.0, 0.0]), pose[:, j, :3, 3]

    def worst(d, g):
        return np.degrees(np.arccos(np.clip(np.einsum("fi,fi->f", d, g) / np.linalg.norm(g, axis=1), -1, 1))).max()
    (d, _), (dl, pl), (dr, pr) = front("head"), front("eye.L"), front("eye.R")
    return (f"; face (head's rest -Y) max {worst(d, goal - (pl + pr) / 2):.4f} deg, eyes max "
            f"{max(worst(dl, goal - pl), worst(dr, goal - pr)):.4f} deg")


def speed_line(pkg, body) -> str:
    """A 1,000-frame shot on the template body (frames 1-1000 of the retargeted clip; 994 keyed, held)."""
    target = circling_target((3.0, 0.0, 1.6), np.arange(1, 995), name="Far")
    runs = []
    for _ in range(3):
        t0 = time.perf_counter()
        report = pkg("addon.gaze.shot").apply_shot(bpy.context, body, target, 1, 994, 10)
        runs.append(time.perf_counter() - t0)
        for track in [t for t in body.animation_data.nla_tracks if t.name.startswith("Articula Gaze")]:
            body.animation_data.nla_tracks.remove(track)
    return (f"speed: a {report['frames']}-frame shot on the template body: best {min(runs):.3f} s of 3 "
            f"({', '.join(f'{r:.3f}' for r in runs)}); ratio to the 1 s target {min(runs):.3f} "
            "(a first shot: the base action read from its F-curves)")


def tracked_line(pkg, blend: str) -> str:
    """The rig of a tracked sample (``./run track --depth … --blend FILE``) looking at a circling target."""
    bpy.ops.wm.open_mainfile(filepath=os.path.abspath(blend))
    arm = next(o for o in bpy.data.objects if o.type == 'ARMATURE' and o.articula.kind == 'RIG_ARMATURE'
               and o.animation_data and o.animation_data.action)
    first, last = pkg("addon.gaze.shot").animation_range(arm)
    centre = np.array(arm.matrix_world.translation) + [0.0, 0.0, 1.6]
    target = circling_target(centre, np.arange(first, last + 1), name="Tracked look")
    return measure(pkg, arm, target, first, last, max(1, (last - first) // 6), f"tracked sample {blend}")


def main(argv=None) -> int:
    argv = list(argv or [])
    pkg = _addon()
    if "--tracked" in argv:
        print(tracked_line(pkg, argv[argv.index("--tracked") + 1]), flush=True)
    bpy.ops.wm.read_homefile(use_empty=True)
    idle = idle_rig(pkg)
    line = measure(pkg, idle, circling_target((0.0, 0.0, 1.6), np.arange(1, 241)), 20, 220, 12,
                   "MakeHuman default rig, idle")
    print(line, flush=True)
    old = idle_rig(pkg, shape="old")
    old.location.x -= 3.0
    line = measure(pkg, old, circling_target((-3.0, 0.0, 1.6), np.arange(1, 241), name="Look old"), 20, 220, 12,
                   "MakeHuman default rig on the stooped old body, idle")
    print(line, flush=True)
    body = tracked_body(pkg)
    print(speed_line(pkg, body), flush=True)
    line = measure(pkg, body, circling_target((3.0, 0.0, 1.6), np.arange(1, 995), name="Look2"), 100, 900, 15,
                   "Articula template body, CMU 131_01 retargeted")
    print(line, flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
