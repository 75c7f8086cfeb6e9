"""The rig Blender builds deforms exactly like the solver's hybrid skin (docs/RIG.md): evaluated
meshes compared with ``solver.rig.skinning.hybrid_skin`` for random poses with ±170° twists, root
translation and scale; the candy-wrapper test in Blender."""
import numpy as np

import bpy

from ..rig_helpers import bbox_diagonal, evaluate_frames, poses, subject

TOL = 1e-5          # relative to the bounding-box diagonal


def _build_and_bake(pkg, model, p):
    rig = pkg("addon.rig.builder").build_rig(bpy.context, model, "Body")
    pkg("addon.rig.actions").write_action(rig.armature, model.skeleton.names, p)
    return rig


def test_hundred_random_poses_match_the_solver(pkg):
    model = subject(pkg)
    assert model.skeleton.num_bones >= 18 and model.num_vertices > 2000
    p = poses(pkg, model.skeleton.num_bones, 100, seed=3)
    twist_deg = np.degrees(2 * np.arctan2(np.abs(p.rotations[..., 2]), np.abs(p.rotations[..., 0])))
    assert twist_deg.max() > 160                       # the poses do contain near-180° twists
    rig = _build_and_bake(pkg, model, p)
    got = evaluate_frames(pkg, rig.mesh, range(1, 101))
    ref = pkg("solver.rig.skinning").hybrid_skin(model, p)
    moved = np.linalg.norm(ref - model.rest_vertices, axis=2).max()
    assert moved > 0.5                                 # the poses really deform the mesh
    err = np.linalg.norm(got - ref, axis=2).max() / bbox_diagonal(model.rest_vertices)
    assert err < TOL, f"worst relative error {err:.3g}"


def test_large_opposing_fork_twists_match_the_solver(pkg):
    """Twist weights shared by several children at forks, with twists adding up to more than 180°:
    the solver's running-sum hemisphere rule is Blender's, so even the flipped blends are exact."""
    model = subject(pkg, fork_twist="all")
    p = poses(pkg, model.skeleton.num_bones, 20, seed=1)
    rig = _build_and_bake(pkg, model, p)
    flips = pkg("solver.rig.skinning").twist_flips(model, p)
    assert flips.any() and not flips.all()            # the case really occurs
    got = evaluate_frames(pkg, rig.mesh, range(1, 21))
    ref = pkg("solver.rig.skinning").hybrid_skin(model, p)
    err = np.linalg.norm(got - ref, axis=2) / bbox_diagonal(model.rest_vertices)
    assert err.max() < TOL, f"worst relative error {err.max():.3g} (at flipped vertices: {err[flips].max():.3g})"


def test_fork_twists_within_human_range_are_exact(pkg):
    model = subject(pkg, fork_twist="all")
    p = poses(pkg, model.skeleton.num_bones, 20, seed=2, max_twist_deg=89.0)
    rig = _build_and_bake(pkg, model, p)
    assert not pkg("solver.rig.skinning").twist_flips(model, p).any()
    got = evaluate_frames(pkg, rig.mesh, range(1, 21))
    ref = pkg("solver.rig.skinning").hybrid_skin(model, p)
    assert np.linalg.norm(got - ref, axis=2).max() / bbox_diagonal(model.rest_vertices) < TOL


def test_candy_wrapper_does_not_collapse(pkg):
    tube = pkg("sample_scenes.synthetic")
    model = tube.cylinder(41, 24, 0.3)
    rig = pkg("addon.rig.builder").build_rig(bpy.context, model, "Tube")
    pb = rig.armature.pose.bones["upper"]
    pb.rotation_quaternion = (np.cos(np.radians(90)), 0, np.sin(np.radians(90)), 0)   # 180° twist
    bpy.context.view_layer.update()
    pos = pkg("addon.scene.mesh_io").evaluated_positions(rig.mesh)
    assert tube.min_ring_radius_ratio(pos, 41, 24, 0.3) >= 0.999
    twisted_top = pos[-24:]
    assert np.allclose(twisted_top[:, :2], -model.rest_vertices[-24:, :2], atol=1e-5)   # really turned 180°


def test_makehuman_subject_matches_the_solver(pkg):
    """The 13,380-vertex MakeHuman sample subject (cmu_mb rig, hybrid skin) over range-of-motion poses."""
    registered = pkg("sample_scenes.registered")          # the assets come with ./run setup: missing ones fail
    _, _, gt = registered.posed_sequence(rig="cmu_mb", n_poses=12, skin="hybrid")
    M = pkg("solver.rig.model")
    sk = M.Skeleton(list(gt["bone_names"]), gt["parents"], gt["heads"], gt["tails"], gt["frames"])
    model = M.Model(gt["rest_vertices"], gt["faces"], sk, gt["anchor"], gt["twist_weights"], gt["swing_weights"])
    p = M.Poses(gt["pose_rotations"], gt["pose_translations"], gt["pose_scales"])
    rig = _build_and_bake(pkg, model, p)
    assert rig.frame_error < 1e-5
    got = evaluate_frames(pkg, rig.mesh, range(1, 13))
    err = np.linalg.norm(got - gt["posed_vertices"], axis=2).max() / bbox_diagonal(model.rest_vertices)
    assert err < TOL, f"worst relative error {err:.3g}"
