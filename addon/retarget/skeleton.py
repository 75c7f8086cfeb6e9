"""Skeleton retargeting in the scene: check both armatures, find or take the mapping, read the source's
clip, solve (:mod:`solver.retarget.solve`) and write a new action on the target.  Every check runs before
the scene changes; a failure while writing removes what was made (:func:`addon.jobs.scene_guard`)."""
import time
from dataclasses import replace

from ...solver.errors import ArticulaInputError
from ...solver.retarget.mapping import Mapping, auto_roles, describe_missing
from ...solver.retarget.solve import NEEDED, RetargetOptions, retarget_clip
from ..jobs import scene_guard
from . import evaluated_target
from ..linked import check_editable
from .armatures import check_scale, constrained_bones, driven_bones, read_rest
from .clip_writer import write_clip
from .source_clip import active_action, read_clip


def auto_mapping(source_ob, target_ob):
    """``(Mapping, source finding, target finding)`` found automatically (presets, then the skeletons)."""
    return _auto_mapping(read_rest(source_ob), read_rest(target_ob))


def _auto_mapping(src, tgt):
    """:func:`auto_mapping` of rest armatures already read."""
    found_src, found_tgt = auto_roles(src), auto_roles(tgt)
    return Mapping.from_roles(found_src.roles, found_tgt.roles), found_src, found_tgt


def _missing_message(mapping: Mapping, source_ob, target_ob) -> str:
    rows = {r: (s, t) for r, s, t in mapping.rows}
    parts = []
    for side, col, ob in (("source", 0, source_ob), ("target", 1, target_ob)):
        lacking = [r for r in NEEDED if not rows.get(r, ("", ""))[col]]
        if lacking:
            parts.append(f"{describe_missing(lacking, side)} {ob.name!r}")
    return "; ".join(parts)


def check_pair(source_ob, target_ob, mapping: Mapping) -> None:
    """Every refusal that does not need the clip: scales, library links, target bones that constraints
    or drivers would override, unknown bones, missing roles."""
    if source_ob == target_ob:
        raise ArticulaInputError("the source and the target are the same armature")
    for ob, what in ((source_ob, "source"), (target_ob, "target")):
        check_scale(ob, what)
    check_editable(target_ob, "target")
    mapping.check([b.name for b in source_ob.data.bones], [b.name for b in target_ob.data.bones])
    lacking = _missing_message(mapping, source_ob, target_ob)
    if lacking:
        raise ArticulaInputError(lacking + " — map them in the Retarget panel's list or load a mapping preset")
    mapped = {t for _, (_, t) in mapping.pairs().items()}
    busy = sorted(set(constrained_bones(target_ob, mapped)) | (set(driven_bones(target_ob)) & mapped))
    if busy:
        raise ArticulaInputError(f"target bones {', '.join(map(repr, busy[:8]))} have constraints or drivers that "
                                 "would override the retargeted rotations: mute them, or map the FK controls")


def retarget(context, source_ob, target_ob, mapping: Mapping | None = None, options: RetargetOptions | None = None,
             action_name: str = "", progress=None):
    """Retarget ``source_ob``'s active action onto ``target_ob``; returns ``(action, report dict)``.
    ``progress(fraction, text)`` hears about the slow evaluated paths (constrained rigs)."""
    t0 = time.perf_counter()
    src, tgt = read_rest(source_ob), read_rest(target_ob)
    found = None
    if mapping is None:
        mapping, *found = _auto_mapping(src, tgt)
    check_pair(source_ob, target_ob, mapping)
    src_action = active_action(source_ob)
    options = replace(options or RetargetOptions(), fps=context.scene.render.fps / context.scene.render.fps_base)
    frames, pose, how = read_clip(source_ob, src, [s for s, _ in mapping.pairs().values()], progress)
    result = retarget_clip(src, tgt, mapping, pose, options)
    mapped = {t for _, t in mapping.pairs().values()}
    through = evaluated_target.needs_evaluation(target_ob, mapped)
    if through:
        evaluated_target.solve(context, target_ob, tgt, result, frames, progress)
    with scene_guard():
        action = write_clip(target_ob, tgt, result, frames,
                            action_name or f"{src_action.name} on {target_ob.name}")
    report = dict(result.report, action=action.name, source_read=how, first=int(frames[0]),
                  last=int(frames[-1]), seconds=time.perf_counter() - t0, mapped=len(mapping.pairs()),
                  root_bone=tgt.bones[result.root_bone], target_solved="evaluated (" + ", ".join(through) + ")"
                  if through else "directly")
    if found:
        report["source_preset"], report["target_preset"] = found[0].preset, found[1].preset
    return action, report


def summary(report: dict) -> str:
    """One line for the status bar."""
    text = (f"Retargeted frames {report['first']}–{report['last']} into action {report['action']!r}: "
            f"{report['mapped']} roles, leg ratio {report['leg_ratio']:.3f}, {report['seconds']:.1f} s")
    if report.get("unit_mismatch"):
        text += " (the rigs' units differ; root motion scaled by the leg ratio)"
    return text
