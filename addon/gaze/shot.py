"""A gaze shot in the scene: check the input, read the character's animation and the target's path over
the shot, solve (:mod:`solver.gaze.aim`) and add the correction as its own NLA layer (:mod:`.layer`).
Every check runs before anything changes; any failure while writing removes what was made and puts the
character's animation (active action, NLA) back as it was (:func:`addon.jobs.scene_guard`)."""
import time
from dataclasses import replace

import bpy
import numpy as np

from ...solver.errors import ArticulaInputError
from ...solver.gaze import aim, fade as fades
from ...solver.retarget.armature import local_from_pose, subset
from .. import compat
from ..jobs import scene_guard
from ..rig.actions import fcurve_values
from ..linked import check_editable
from ..retarget.armatures import check_scale, read_rest
from ..retarget.source_clip import local_from_fcurves, needs_evaluation, pose_from_scene
from . import chain as chains, layer


def animation_range(ob):
    """(first, last) frames the armature's animation spans (active action and NLA strips), or None."""
    ad = ob.animation_data
    spans = []
    if ad is not None and ad.action is not None:
        spans.append(tuple(ad.action.frame_range))
    if ad is not None:
        spans += [(s.frame_start, s.frame_end) for t in ad.nla_tracks if not t.mute for s in t.strips]
    if not spans:
        return None
    return int(np.floor(min(a for a, _ in spans))), int(np.ceil(max(b for _, b in spans)))


def check_shot(arm_ob, target_ob, start: int, end: int) -> None:
    """Refusals that need no solving: the target is part of the character, NLA tweak mode, bad frames,
    linked or scaled."""
    if target_ob is None:
        raise ArticulaInputError("choose a target object to look at")
    own = {arm_ob, *arm_ob.children_recursive}
    if target_ob in own or any(p in own for p in _parents(target_ob)):
        raise ArticulaInputError(f"the target {target_ob.name!r} is part of the character {arm_ob.name!r}: "
                                 "pick an object that is not parented to it")
    if end <= start:
        raise ArticulaInputError(f"the shot's last frame {end} must come after its first {start}")
    if arm_ob.animation_data is not None and arm_ob.animation_data.use_tweak_mode:
        raise ArticulaInputError(f"{arm_ob.name!r} is in NLA tweak mode: leave it (Tab in the NLA editor) "
                                 "before adding a gaze shot")
    span = animation_range(arm_ob)
    if span is not None and (start < span[0] or end > span[1]):
        raise ArticulaInputError(f"frames {start}-{end} lie outside the animation of {arm_ob.name!r} "
                                 f"(frames {span[0]}-{span[1]})")
    check_scale(arm_ob, "armature")
    check_editable(arm_ob, "armature")


def _parents(ob):
    while ob.parent is not None:
        ob = ob.parent
        yield ob


def target_path(context, target_ob, frames) -> np.ndarray:
    """(F, 3) world positions of the target's origin on ``frames`` (from its location F-curves when
    nothing else moves it, else read from the scene frame by frame)."""
    ad = target_ob.animation_data
    plain = target_ob.parent is None and not target_ob.constraints and not (ad and ad.drivers)
    if plain:
        base = np.array(target_ob.location, dtype=np.float64) + np.array(target_ob.delta_location)
        out = np.tile(base, (len(frames), 1))
        if ad is not None and ad.action is not None:
            for fc in compat.object_action_fcurves(target_ob, ad.action):
                if fc.data_path == "location":
                    out[:, fc.array_index] = fcurve_values(fc, frames) + target_ob.delta_location[fc.array_index]
        return out
    scene, keep = context.scene, context.scene.frame_current
    out = np.empty((len(frames), 3))
    try:
        for k, f in enumerate(frames):
            scene.frame_set(int(f))
            out[k] = np.array(target_ob.matrix_world.translation)
    finally:
        scene.frame_set(keep)
    return out


def _input_pose(arm_ob, rest, frames):
    """(F, J, 4, 4) pose-bone matrices of ``rest``'s bones (the gaze carriers) on ``frames`` before the
    shot: from the active action's F-curves, or from the evaluated scene when an NLA stack, constraints or
    drivers on these bones decide them."""
    ad = arm_ob.animation_data
    plain = _plain_base(arm_ob, frames)
    if plain is not None and not needs_evaluation(arm_ob, rest.bones, nla=False):
        return local_from_fcurves(arm_ob, rest, plain, frames)
    if ad is None or (ad.action is None and not len(ad.nla_tracks)):
        basis = np.array([np.array(arm_ob.pose.bones[n].matrix_basis, dtype=np.float64) for n in rest.bones])
        return np.repeat(basis[None], len(frames), axis=0)
    return local_from_pose(rest, pose_from_scene(arm_ob, rest, frames))


def carrier(rest, chain, eyes):
    """``(sub-armature, chain, eyes)`` restricted to the bones that carry the gaze: the head's and the
    eyes' ancestors (all the solve needs; reading and turning the rest would only cost time)."""
    keep = np.zeros(len(rest.bones), bool)
    for b in [chain.head, *[e for e, _ in eyes]]:
        while b >= 0:
            keep[b], b = True, rest.parents[b]
    new_index = {int(b): i for i, b in enumerate(np.flatnonzero(keep))}
    sub_chain = replace(chain, joints=[new_index[j] for j in chain.joints], head=new_index[chain.head])
    return subset(rest, keep), sub_chain, [(new_index[b], d) for b, d in eyes]


def _plain_base(arm_ob, frames):
    """The action that alone decides the pose on ``frames``: the active action with no NLA playing, or
    the one plain NLA strip (replace, full influence, unscaled, unrepeated, unshifted: how a base is
    pushed down) when no other unmuted strip reaches into ``frames``; else None."""
    ad = arm_ob.animation_data
    if ad is None:
        return None
    strips = [s for t in ad.nla_tracks if not t.mute for s in t.strips if not s.mute]
    if ad.action is not None:
        return ad.action if not strips else None
    base = [s for s in strips if s.frame_start <= frames[0] and s.frame_end >= frames[-1]
            and s.blend_type == 'REPLACE' and (not s.use_animated_influence or s.influence == 1.0) and s.scale == 1.0 and s.repeat == 1.0
            and s.action_frame_start == s.frame_start and s.action is not None]
    others = [s for s in strips if s not in base[:1] and s.frame_end >= frames[0] and s.frame_start <= frames[-1]]
    return base[0].action if len(base) == 1 and not others else None


def _rotations(local):
    R = local[..., :3, :3]
    return R / np.linalg.norm(R, axis=-2, keepdims=True)


def apply_shot(context, arm_ob, target_ob, start: int, end: int, fade: int = 10, overrides=None,
               shares=chains.SHARES, facing: str = ""):
    """Make ``arm_ob`` look at ``target_ob`` from ``start`` to ``end`` with ``fade`` frames of fade; returns
    the report dict."""
    t0 = time.perf_counter()
    check_shot(arm_ob, target_ob, start, end)
    frames = np.arange(start, end + 1)
    weights = fades.shot_weights(frames, start, end, fade)
    whole = read_rest(arm_ob)
    chain, eyes, how = chains.gaze_chain(arm_ob, whole, overrides, shares, facing=facing)
    rest, chain, eyes = carrier(whole, chain, eyes)
    bones = list(chain.joints) + [b for b, _ in eyes]
    layer.check_rotation_modes(arm_ob, [rest.bones[b] for b in bones])
    local = _input_pose(arm_ob, rest, frames)
    targets = rest.armature_points(target_path(context, target_ob, frames))
    new, report = aim.solve(rest, local, chain, targets, weights)
    eyes_limited = []
    if eyes:
        new, eyes_limited = aim.aim_eyes(rest, new, eyes, targets, weights)
    with scene_guard():
        note = layer.push_down_active_action(arm_ob)
        strip = layer.add_shot(arm_ob, rest, bones, frames, _rotations(local), _rotations(new),
                               f"Gaze {target_ob.name} {start}-{end}")
    full = (weights == 1.0) & ~np.isin(np.arange(len(frames)), report["limited"])
    return {"frames": len(frames), "first": start, "last": end, "strip": strip.name, "gaze_line": how,
            "bones": [rest.bones[b] for b in bones], "shares": [float(s) for s in chain.shares],
            "error_deg": float(report["error_deg"][full].max()) if full.any() else 0.0,
            "limited": [int(frames[i]) for i in report["limited"]], "reach_deg": report["reach_deg"],
            "eyes_limited": [int(frames[i]) for i in eyes_limited], "note": note,
            "seconds": time.perf_counter() - t0}


def summary(report: dict) -> str:
    text = (f"Gaze on frames {report['first']}-{report['last']} ({', '.join(report['bones'])}): at full "
            f"strength within {report['error_deg']:.2f} deg of the target, {report['seconds']:.2f} s")
    if report["limited"]:
        text += (f"; out of reach on {len(report['limited'])} frames (from {report['limited'][0]}): turned the "
                 f"most the joints allow, {report['reach_deg']:.0f} deg")
    return text
