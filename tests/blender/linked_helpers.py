"""Characters linked from another .blend (the usual production set-up), shared by the tests of linked and
library-override targets: a library file holding an MPFB character keyed with a short action (collection
``HeroChar``) and an Articula rig built from a bundle (collection ``RigChar``); a scene that links them
plainly or through a library override made as Object › Library Override › Make does."""
import os

import bpy
import numpy as np

from articula.bench._armatures import new_armature
from articula.sample_scenes import mpfb_armature
from .rig_helpers import poses, subject

HERO, HERO_CHAR, RIG_CHAR = "Hero", "HeroChar", "RigChar"


def _collect(name, obs):
    coll = bpy.data.collections.new(name)
    bpy.context.scene.collection.children.link(coll)
    for ob in obs:
        for c in list(ob.users_collection):
            c.objects.unlink(ob)
        coll.objects.link(ob)


def _hero(pkg, frames=40):
    """An MPFB 'default' character keyed with small random turns of every bone over ``frames`` frames."""
    from articula.solver.geometry.rotations import rotvec_to_quat
    from articula.solver.rig.model import Poses
    d = mpfb_armature.rig_bones("default")
    ob = new_armature(bpy.context, HERO, d["names"], d["parents"], d["heads"], d["tails"], d["rolls"])
    names = [b.name for b in ob.data.bones]
    for pb in ob.pose.bones:
        pb.rotation_mode = 'QUATERNION'
    q = rotvec_to_quat(np.random.default_rng(3).normal(0, 0.08, (frames, len(names), 3)))
    pkg("addon.rig.actions").write_action(ob, names, Poses(q, np.zeros((frames, 3)), np.ones(frames)), name="idle")
    return ob


def write_library(pkg, folder) -> tuple:
    """``(library .blend path, the Articula rig's armature name, its poses bundle path)``, made in ``folder``;
    leaves an empty scene."""
    _collect(HERO_CHAR, [_hero(pkg)])
    model = subject(pkg, rings=6, segments=8)
    save = pkg("solver.formats.bundle").save_bundle
    rig_path, take = os.path.join(folder, "rig.npz"), os.path.join(folder, "take.npz")
    save(rig_path, model)
    save(take, model, poses(pkg, model.skeleton.num_bones, 5, seed=7))
    assert bpy.ops.articula.build_rig(filepath=rig_path) == {'FINISHED'}
    arm = bpy.context.view_layer.objects.active
    rig = arm.name
    _collect(RIG_CHAR, [arm, *arm.children_recursive])
    lib = os.path.join(folder, "lib.blend")
    bpy.ops.wm.save_as_mainfile(filepath=lib)
    bpy.ops.wm.read_homefile(use_empty=True)
    return lib, rig, take


def link_plain(lib, names) -> list:
    """Link the objects ``names`` from ``lib`` into the scene, without an override (read-only)."""
    with bpy.data.libraries.load(lib, link=True) as (_, dst):
        dst.objects = list(names)
    for ob in dst.objects:
        bpy.context.scene.collection.objects.link(ob)
    return dst.objects


def link_override(lib, collection):
    """Link ``collection`` from ``lib`` as an instance and make it a library override with Blender's
    operator (Object › Library Override › Make); returns the override collection."""
    with bpy.data.libraries.load(lib, link=True) as (_, dst):
        dst.collections = [collection]
    inst = bpy.data.objects.new(collection, None)
    inst.instance_type, inst.instance_collection = 'COLLECTION', dst.collections[0]
    bpy.context.scene.collection.objects.link(inst)
    bpy.context.view_layer.update()                 # the instance must be in the view layer to be selected
    for ob in bpy.context.view_layer.objects:
        ob.select_set(ob == inst)
    bpy.context.view_layer.objects.active = inst
    assert bpy.ops.object.make_override_library() == {'FINISHED'}
    made = [c for c in bpy.data.collections if c.name == collection and c.override_library is not None]
    assert len(made) == 1
    return made[0]


def overridden(collection, name):
    """The object ``name`` of the override ``collection`` (a local override, not the linked original)."""
    ob = next(o for o in collection.all_objects if o.name == name)
    assert ob.library is None and ob.override_library is not None
    return ob


def bone_matrices(ob, frames) -> np.ndarray:
    """(F, B, 4, 4) pose-bone matrices (armature space) of ``ob`` as Blender evaluates them on ``frames``."""
    out = []
    for f in frames:
        bpy.context.scene.frame_set(int(f))
        out.append([np.array(pb.matrix) for pb in ob.pose.bones])
    return np.array(out)


def counts() -> dict:
    """Numbers of the datablocks an operator could add (for "nothing changed" checks)."""
    return {k: len(getattr(bpy.data, k)) for k in ("objects", "meshes", "armatures", "actions", "collections")}


def animation_state(ob) -> tuple:
    """What the animation of ``ob`` is: its active action and its NLA tracks with their strips."""
    ad = ob.animation_data
    if ad is None:
        return None, ()
    return ad.action, tuple((t.name, tuple(s.name for s in t.strips)) for t in ad.nla_tracks)
