"""The Blender conventions the rig relies on, checked bone by bone against the solver (the exactness
tests check the mesh; these say which piece is wrong when one breaks):
* control bone b's pose matrix is M_b ∘ rest (root location = F0ᵀ t in bone axes, uniform scale s);
* swing helper SW-c's pose matrix is M_parent(c) ∘ Swing_c ∘ rest (Damped Track = shortest arc);
* twist bone TW-c's driven Y angle is the SWING_TWIST_Y twist 2·atan2(y, w) (w >= 0) of control c."""
import numpy as np

import bpy

from ..rig_helpers import poses, subject


def _affine(R, t):
    M = np.eye(4)
    M[:3, :3], M[:3, 3] = R, t
    return M


def _posed_rig(pkg, n=6):
    model = subject(pkg, rings=4, segments=6)
    p = poses(pkg, model.skeleton.num_bones, n, seed=8)
    rig = pkg("addon.rig.builder").build_rig(bpy.context, model, "Body")
    pkg("addon.rig.actions").write_action(rig.armature, model.skeleton.names, p)
    return model, p, rig


def _frames(n):
    for f in range(n):
        bpy.context.scene.frame_set(f + 1)
        yield f


def test_control_and_swing_bones_follow_the_solver_chain(pkg):
    model, p, rig = _posed_rig(pkg)
    sk = model.skeleton
    Rm, tm = pkg("solver.rig.kinematics").forward_kinematics(sk, p)
    rot = pkg("solver.geometry.rotations")
    q_sw, _ = rot.swing_twist_y(p.rotations)
    R_sw = sk.frames @ rot.quat_to_matrix(q_sw) @ np.swapaxes(sk.frames, -1, -2)      # (N, B, 3, 3)
    bones = rig.armature.data.bones
    for f in _frames(len(p)):
        for b, name in enumerate(sk.names):
            rest = np.array(bones[name].matrix_local)
            got = np.array(rig.armature.pose.bones[name].matrix)
            np.testing.assert_allclose(got, _affine(Rm[f, b], tm[f, b]) @ rest, atol=2e-5, err_msg=name)
        for c in range(1, sk.num_bones):
            a, h = sk.parents[c], sk.heads[c]
            swing = _affine(R_sw[f, c], h - R_sw[f, c] @ h)
            want = _affine(Rm[f, a], tm[f, a]) @ swing @ np.array(bones[sk.names[c]].matrix_local)
            got = np.array(rig.armature.pose.bones["SW-" + sk.names[c]].matrix)
            np.testing.assert_allclose(got, want, atol=2e-5, err_msg="SW-" + sk.names[c])


def test_twist_bones_carry_the_twist_angle(pkg):
    model, p, rig = _posed_rig(pkg)
    sk = model.skeleton
    q = p.rotations * np.where(p.rotations[..., :1] < 0, -1, 1)
    angle = 2 * np.arctan2(q[..., 2], q[..., 0])                                       # (N, B) in [-pi, pi]
    assert np.abs(angle[:, 1:]).max() > np.radians(150)
    for f in _frames(len(p)):
        got = np.array([rig.twist.pose.bones["TW-" + n].rotation_euler[1] for n in sk.names[1:]])
        diff = np.angle(np.exp(1j * (got - angle[f, 1:])))                              # wrap-safe
        assert np.abs(diff).max() < 1e-5


def test_root_location_is_stored_in_bone_axes(pkg):
    model, p, rig = _posed_rig(pkg, n=3)
    root = model.skeleton.names[0]
    F0 = np.array(rig.armature.data.bones[root].matrix_local)[:3, :3]
    for f in _frames(len(p)):
        pb = rig.armature.pose.bones[root]
        np.testing.assert_allclose(F0 @ np.array(pb.location), p.translations[f], atol=1e-6)
        np.testing.assert_allclose(np.array(pb.scale), [p.scales[f]] * 3, atol=1e-6)
