"""Shared by the rig tests: the tube-body subject, random poses, raw bundle writing, evaluation."""
import numpy as np

import bpy


def subject(pkg, **kw):
    return pkg("sample_scenes.synthetic").tube_body(**kw)


def poses(pkg, num_bones, n, **kw):
    return pkg("solver.rig.pose_sampling").random_poses(n, num_bones, **kw)


def write_raw_bundle(path, arrays):
    """Write ``arrays`` as an .npz without validation (to make broken bundles)."""
    np.savez(path, **arrays)


def bundle_arrays(pkg, model, poses=None):
    """The key -> array dict of a bundle (as save_bundle writes it)."""
    sk = model.skeleton
    a = {"format": np.array("articula-model/1"), "rest_vertices": model.rest_vertices,
         "faces": model.faces, "bone_names": np.array(sk.names), "parents": sk.parents, "heads": sk.heads,
         "tails": sk.tails, "frames": sk.frames, "anchor": model.anchor,
         "twist_weights": model.twist_weights, "swing_weights": model.swing_weights}
    if poses is not None:
        a.update(pose_rotations=poses.rotations, pose_translations=poses.translations, pose_scales=poses.scales)
    return a


def evaluate_frames(pkg, mesh_ob, frames):
    """Evaluated mesh positions (len(frames), V, 3) at the given scene frames."""
    mesh_io = pkg("addon.scene.mesh_io")
    out = []
    for f in frames:
        bpy.context.scene.frame_set(int(f))
        out.append(mesh_io.evaluated_positions(mesh_ob))
    return np.array(out)


def bbox_diagonal(vertices):
    return float(np.linalg.norm(vertices.max(0) - vertices.min(0)))


def key_frames(pkg, arm):
    """The keyed frames of every F-curve of ``arm``'s active action, one tuple of ints per F-curve (a set:
    equal tuples collapse, so one baked pose per frame gives one tuple)."""
    compat = pkg("addon.compat")
    frames = set()
    for fc in compat.object_action_fcurves(arm, arm.animation_data.action):
        co = np.empty(2 * len(fc.keyframe_points), np.float32)
        fc.keyframe_points.foreach_get("co", co)
        frames.add(tuple(co[0::2].astype(int).tolist()))
    return frames
