"""Baking a rig's poses never shortens the frame range a user set: it is widened to cover the action,
and set outright only when the scene holds nothing but the rig."""
import bpy

from ..rig_helpers import poses, subject


def _build(pkg, frames=6):
    model = subject(pkg)
    rig = pkg("addon.rig.builder").build_rig(bpy.context, model, "Rig")
    pkg("addon.rig.actions").write_action(rig.armature, model.skeleton.names,
                                         poses(pkg, model.skeleton.num_bones, frames))
    return rig


def test_baking_into_a_scene_with_a_longer_range_keeps_it(pkg):
    bpy.ops.mesh.primitive_cube_add()
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end = 1, 77
    _build(pkg)
    assert (scene.frame_start, scene.frame_end) == (1, 77)


def test_baking_widens_a_shorter_range(pkg):
    bpy.ops.mesh.primitive_cube_add()
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end = 3, 4
    _build(pkg, frames=6)
    assert (scene.frame_start, scene.frame_end) == (1, 6)


def test_a_scene_holding_only_the_rig_gets_the_actions_range(pkg):
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end = 1, 250
    _build(pkg, frames=6)
    assert (scene.frame_start, scene.frame_end) == (1, 6)
