"""A refused or failed gaze shot leaves the character exactly as it was: its active action, its NLA
tracks and strips, and no new datablocks (refusals come before anything changes; an unexpected error
while writing is rolled back by the scene guard)."""
import bpy
import pytest

from .test_facing import character, target_near


def animated(pkg):
    """The MPFB default rig with an active action (spine and head keyed on frames 1 and 40) and an
    earlier, muted NLA track of its own."""
    ob = character(pkg, "Hero")
    for frame, angle in ((1, 0.0), (40, 0.3)):
        for name in ("spine01", "head"):
            pb = ob.pose.bones[name]
            pb.rotation_quaternion = (1.0, angle, 0.0, 0.0)
            pb.keyframe_insert("rotation_quaternion", frame=frame)
    ad = ob.animation_data
    old = bpy.data.actions.new("Earlier take")
    track = ad.nla_tracks.new()
    track.name, track.mute = "Earlier", True
    track.strips.new(old.name, 1, old)
    bpy.context.scene.frame_start, bpy.context.scene.frame_end = 1, 40
    return ob


def state(ob):
    """What a failed shot must not change: the active action, the NLA stack, the datablocks."""
    ad = ob.animation_data
    return (ad.action, getattr(ad, "action_slot", None),
            [(t.name, t.mute, [(s.name, s.action, s.frame_start, s.frame_end) for s in t.strips])
             for t in ad.nla_tracks],
            {a.as_pointer() for a in bpy.data.actions}, {o.as_pointer() for o in bpy.data.objects})


def test_axis_angle_head_is_refused_before_anything_changes(pkg):
    ob = animated(pkg)
    target = target_near(pkg("addon.retarget.armatures").read_rest(ob))
    ob.pose.bones["head"].rotation_mode = 'AXIS_ANGLE'
    before = state(ob)
    assert before[0] is not None
    with pytest.raises(RuntimeError, match="axis-angle"):
        bpy.ops.articula.gaze(armature=ob.name, target=target.name, fade_frames=5)
    assert state(ob) == before


def test_unexpected_error_while_writing_is_rolled_back(pkg, monkeypatch):
    ob = animated(pkg)
    target = target_near(pkg("addon.retarget.armatures").read_rest(ob))
    before = state(ob)
    layer = pkg("addon.gaze.layer")
    real = layer.add_keys
    calls = []

    def fails_on_the_third_bone(*args, **kwargs):       # the action is half written when it fails
        calls.append(args[1])
        if len(set(calls)) == 3:
            raise OSError("the disk is full")
        return real(*args, **kwargs)
    monkeypatch.setattr(layer, "add_keys", fails_on_the_third_bone)
    with pytest.raises(RuntimeError, match="the disk is full"):
        bpy.ops.articula.gaze(armature=ob.name, target=target.name, fade_frames=5)
    assert len(set(calls)) == 3
    assert state(ob) == before
    monkeypatch.setattr(layer, "add_keys", real)
    assert bpy.ops.articula.gaze(armature=ob.name, target=target.name, fade_frames=5) == {'FINISHED'}
    assert state(ob) != before                              # the same shot, not failing, changes it


def test_nla_tweak_mode_is_refused_before_anything_changes(pkg):
    ob = animated(pkg)
    target = target_near(pkg("addon.retarget.armatures").read_rest(ob))
    assert bpy.ops.articula.gaze(armature=ob.name, target=target.name, fade_frames=5) == {'FINISHED'}
    ad = ob.animation_data
    base = next(t for t in ad.nla_tracks if t.strips[0].action.name == "HeroAction")   # pushed down by the shot
    for track in ad.nla_tracks:
        track.select = track == base
    base.strips[0].select = True
    ad.nla_tracks.active = base
    ad.use_tweak_mode = True                                # editing the base action in place
    before = state(ob)
    with pytest.raises(RuntimeError, match="tweak mode"):
        bpy.ops.articula.gaze(armature=ob.name, target=target.name, fade_frames=5)
    assert state(ob) == before and ad.use_tweak_mode
