"""The rig Blender builds deforms exactly like the solver's hybrid skin (ARCHITECTURE.md): evaluated
meshes compared with ``solver.skinning.hybrid_skin`` for random poses with ±170° twists, root
translation and scale; the candy-wrapper test in Blender."""
import numpy as np
import pytest

import bpy

from .rig_helpers import bbox_diagonal, evaluate_frames, poses, subject

TOL = 1e-5          # relative to the bounding-box diagonal


def _build_and_bake(pkg, model, p):
    rig = pkg("addon.rig_builder").build_rig(bpy.context, model, "Body")
    pkg("addon.actions").write_action(rig.armature, model.skeleton.names, p)
    return rig


def test_hundred_random_poses_match_the_solver(pkg):
    model = subject(pkg)
    assert model.skeleton.num_bones >= 18 and model.num_vertices > 2000
    p = poses(pkg, model.skeleton.num_bones, 100, seed=3)
    twist_deg = np.degrees(2 * np.arctan2(np.abs(p.rotations[..., 2]), np.abs(p.rotations[..., 0])))
    assert twist_deg.max() > 160                       # the poses do contain near-180° twists
    rig = _build_and_bake(pkg, model, p)
    assert not pkg("addon.dqs_alignment").blender_twist_flips(model, p).any()
    got = evaluate_frames(pkg, rig.mesh, range(1, 101))
    ref = pkg("solver.skinning").hybrid_skin(model, p)
    moved = np.linalg.norm(ref - model.rest_vertices, axis=2).max()
    assert moved > 0.5                                 # the poses really deform the mesh
    err = np.linalg.norm(got - ref, axis=2).max() / bbox_diagonal(model.rest_vertices)
    assert err < TOL, f"worst relative error {err:.3g}"


def test_fork_twist_blends_match_where_blender_aligns_like_the_solver(pkg):
    """With twist weights shared by several children at forks, Blender's running-sum alignment differs
    from the solver's neutral alignment exactly at the vertices dqs_alignment predicts, nowhere else."""
    model = subject(pkg, fork_twist="all")
    p = poses(pkg, model.skeleton.num_bones, 20, seed=1)
    rig = _build_and_bake(pkg, model, p)
    flips = pkg("addon.dqs_alignment").blender_twist_flips(model, p)
    assert flips.any() and not flips.all()
    got = evaluate_frames(pkg, rig.mesh, range(1, 21))
    ref = pkg("solver.skinning").hybrid_skin(model, p)
    err = np.linalg.norm(got - ref, axis=2) / bbox_diagonal(model.rest_vertices)
    assert err[~flips].max() < TOL
    assert np.array_equal(err > TOL, flips)


def test_fork_twists_within_human_range_are_exact(pkg):
    model = subject(pkg, fork_twist="all")
    p = poses(pkg, model.skeleton.num_bones, 20, seed=2, max_twist_deg=89.0)
    rig = _build_and_bake(pkg, model, p)
    assert not pkg("addon.dqs_alignment").blender_twist_flips(model, p).any()
    got = evaluate_frames(pkg, rig.mesh, range(1, 21))
    ref = pkg("solver.skinning").hybrid_skin(model, p)
    assert np.linalg.norm(got - ref, axis=2).max() / bbox_diagonal(model.rest_vertices) < TOL


def cylinder_model(pkg, rings=41, segments=24, radius=0.3):
    """Two bones along Z (0..1, 1..2), a closed-ring tube anchored on bone 0 with twist and swing weights
    ramping onto bone 1 around the joint."""
    model_mod = pkg("solver.model")
    z = np.linspace(0.0, 2.0, rings)
    t = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    verts = np.array([(radius * np.cos(a), radius * np.sin(a), h) for h in z for a in t])
    r, s = np.meshgrid(np.arange(rings - 1), np.arange(segments), indexing="ij")
    a, b = r * segments + s, r * segments + (s + 1) % segments
    faces = np.concatenate([np.stack([a, b, b + segments], -1).reshape(-1, 3),
                            np.stack([a, b + segments, a + segments], -1).reshape(-1, 3)])
    frames = np.stack([np.column_stack([(1, 0, 0), (0, 0, 1), (0, -1, 0)])] * 2)   # columns X, Y (up), Z
    sk = model_mod.Skeleton(["lower", "upper"], [-1, 0], [(0, 0, 0), (0, 0, 1)], [(0, 0, 1), (0, 0, 2)], frames)
    ramp = np.clip((verts[:, 2] - 0.5) / 1.0, 0, 1)
    w = np.zeros((len(verts), 2), np.float32)
    tw, sw = w.copy(), w.copy()
    tw[:, 1] = ramp
    sw[:, 1] = np.clip((verts[:, 2] - 0.8) / 0.4, 0, 1)
    return model_mod.Model(verts, faces, sk, np.zeros(len(verts), np.int32), tw, sw)


def min_ring_radius_ratio(pos, rings, segments, radius):
    """Smallest mean ring radius / rest radius of a deformed tube (rings of ``segments`` vertices)."""
    ring = pos.reshape(rings, segments, 3)
    centre = ring.mean(axis=1, keepdims=True)
    return float(np.linalg.norm(ring - centre, axis=2).mean(axis=1).min() / radius)


def test_candy_wrapper_does_not_collapse(pkg):
    model = cylinder_model(pkg)
    rig = pkg("addon.rig_builder").build_rig(bpy.context, model, "Tube")
    pb = rig.armature.pose.bones["upper"]
    pb.rotation_quaternion = (np.cos(np.radians(90)), 0, np.sin(np.radians(90)), 0)   # 180° twist
    bpy.context.view_layer.update()
    pos = pkg("addon.mesh_io").evaluated_positions(rig.mesh)
    assert min_ring_radius_ratio(pos, 41, 24, 0.3) >= 0.999
    twisted_top = pos[-24:]
    assert np.allclose(twisted_top[:, :2], -model.rest_vertices[-24:, :2], atol=1e-5)   # really turned 180°
