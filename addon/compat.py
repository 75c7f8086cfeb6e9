"""The one place where differences between Blender 4.2 LTS ... 5.2 LTS are handled.

Callers ask questions ("are actions slotted?") instead of comparing version numbers themselves.
"""
import bpy

VERSION = bpy.app.version  # (major, minor, patch)


def at_least(major: int, minor: int = 0) -> bool:
    """True when the running Blender is ``major.minor`` or newer."""
    return VERSION[:2] >= (major, minor)


def has_slotted_actions() -> bool:
    """Slotted (layered) actions: 4.4+.  From 5.0 on ``Action.fcurves`` no longer exists."""
    return at_least(4, 4)


def has_legacy_action_fcurves() -> bool:
    """``Action.fcurves`` exists (Blender < 5.0)."""
    return not at_least(5, 0)


# ----------------------------------------------------------------------------- actions (F-curves)

def new_object_action(name: str, ob):
    """A new action for object ``ob`` and the container to create its F-curves in.

    Returns ``(action, slot, channels)``: ``slot`` is None on legacy actions (< 4.4); ``channels``
    has ``fcurves.new(data_path, index=...)`` and ``groups``, which is the slot's channelbag on 4.4+
    and the action itself before.  Group the F-curves with :func:`fcurve_new`."""
    action = bpy.data.actions.new(name)
    if not has_slotted_actions():
        return action, None, action
    slot = action.slots.new(id_type='OBJECT', name=ob.name)
    strip = action.layers.new("Layer").strips.new(type='KEYFRAME')
    return action, slot, strip.channelbag(slot, ensure=True)


def fcurve_new(channels, data_path: str, index: int, group: str):
    """A new F-curve in ``channels`` (see :func:`new_object_action`) in the group named ``group``."""
    if has_slotted_actions():
        return channels.fcurves.new(data_path, index=index, group_name=group)
    return channels.fcurves.new(data_path, index=index, action_group=group)


def assign_action(ob, action, slot) -> None:
    """Make ``action`` (with ``slot`` on 4.4+) the active action of ``ob``."""
    ad = ob.animation_data or ob.animation_data_create()
    ad.action = action
    if slot is not None:
        ad.action_slot = slot


def object_action_fcurves(ob, action):
    """The F-curves of ``action`` that animate ``ob``: the slot assigned to ``ob`` (or, when the
    action is not assigned to it, the first object slot); every F-curve of a legacy action."""
    if not has_slotted_actions():
        return list(action.fcurves)
    ad = ob.animation_data
    slot = ad.action_slot if ad is not None and ad.action == action else None
    if slot is None:
        slot = next((s for s in action.slots
                     if getattr(s, "target_id_type", getattr(s, "id_root", 'OBJECT')) == 'OBJECT'), None)
    if slot is None:
        return []
    out = []
    for layer in action.layers:
        for strip in layer.strips:
            bag = strip.channelbag(slot)
            if bag is not None:
                out.extend(bag.fcurves)
    return out


def push_to_nla(ob, action, slot, start: int):
    """Put ``action`` on a new NLA track of ``ob`` starting at frame ``start``; returns the track."""
    ad = ob.animation_data or ob.animation_data_create()
    track = ad.nla_tracks.new()
    track.name = action.name
    strip = track.strips.new(action.name, int(start), action)
    if slot is not None and getattr(strip, "action_slot", None) != slot:
        strip.action_slot = slot
    return track


def blend_relative_path_options() -> set:
    """``options`` for FILE_PATH properties that hold ``//``-relative paths: newer Blender (the
    ``PATH_SUPPORTS_BLEND_RELATIVE`` flag exists, e.g. 5.x) warns without it, 4.2 rejects it."""
    supported = "is_path_supports_blend_relative" in bpy.types.Property.bl_rna.properties
    return {'PATH_SUPPORTS_BLEND_RELATIVE'} if supported else set()
