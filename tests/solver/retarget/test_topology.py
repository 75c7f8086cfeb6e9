"""Retargeting through shared topology (solver.retarget.topology; dissertation (model-adaptive mocap)
Sec. 4.2.3, test A2): identical models reproduce the source exactly, two MakeHuman bodies of the same rig
are fitted closer than parameter copying gets them, the size ratio, and mismatched topology is refused."""
import re
from dataclasses import replace

import numpy as np
import pytest

from articula.sample_scenes import synthetic
from articula.sample_scenes.poses import rom_poses
from articula.sample_scenes.subjects import make_subject
from articula.solver.errors import ArticulaInputError
from articula.solver.rig.model import Skeleton
from articula.solver.rig.skinning import hybrid_skin
from articula.solver.retarget import topology


@pytest.fixture(scope="module")
def bodies():
    """Source (female, thin), target (male, heavy; same rig and mesh) and tall target models."""
    return {shape: make_subject("cmu_mb", shape).hybrid_model()
            for shape in ("female,thin", "male,heavy", "male,heavy,tall")}


def _motion(model, n=3, seed=1):
    return rom_poses(model.skeleton, n, seed=seed, amplitude=0.6, root_yaw=40.0, root_shift=0.3)


def _rms(a, b):
    return np.sqrt(((a - b) ** 2).sum(axis=-1).mean(axis=-1))


def _canonical(q):
    return np.where(q[..., :1] < 0, -q, q)


def test_identical_models_reproduce_the_source_poses(bodies):
    src = bodies["female,thin"]
    p = _motion(src, 4)
    poses, rep = topology.retarget_topology(src, p, replace(src))
    assert rep["rms_fit"].max() <= 1e-6 and rep["rms_copy"].max() <= 1e-6
    assert rep["from_copy"].all() and rep["bones_copied"] == src.skeleton.num_bones
    np.testing.assert_allclose(_canonical(poses.rotations), _canonical(p.rotations), atol=1e-9)
    np.testing.assert_allclose(poses.translations, p.translations, atol=1e-9)
    np.testing.assert_allclose(poses.scales, p.scales)


def test_fit_to_another_body_beats_parameter_copying(bodies):
    src, tgt = bodies["female,thin"], bodies["male,heavy"]
    p = _motion(src)
    progress = []
    poses, rep = topology.retarget_topology(src, p, tgt, progress=lambda f, text: progress.append(f))
    assert progress and progress[-1] == 1.0
    y = hybrid_skin(src, p)
    np.testing.assert_allclose(rep["rms_fit"], _rms(hybrid_skin(tgt, poses), y), rtol=1e-9)
    copied = topology.copy_parameters(src, p, tgt)
    np.testing.assert_allclose(rep["rms_copy"], _rms(hybrid_skin(tgt, copied), y), rtol=1e-9)
    assert np.all(rep["rms_fit"] < 0.5 * rep["rms_copy"]), (rep["rms_fit"], rep["rms_copy"])
    assert np.all(rep["rms_fit"] < 0.03)              # metres; the bodies' rest meshes are 0.11 m apart (RMS)
    assert rep["rms_rest"] > 0.1 and rep["scale"] == 1.0 and rep["frames"] == 3


def test_height_ratio_scales_the_motion_of_a_taller_target(bodies):
    src, tgt = bodies["female,thin"], bodies["male,heavy,tall"]
    p = _motion(src, 2)
    ratio = topology.height(tgt) / topology.height(src)
    assert 1.2 < ratio < 1.35
    copied = topology.copy_parameters(src, p, tgt, scale="height")
    np.testing.assert_allclose(copied.translations, ratio * p.translations)
    np.testing.assert_array_equal(copied.rotations, p.rotations)
    _, plain = topology.retarget_topology(src, p, tgt)
    _, scaled = topology.retarget_topology(src, p, tgt, scale="height")
    assert scaled["scale"] == pytest.approx(ratio)
    assert np.all(scaled["rms_fit"] < scaled["rms_copy"]) and np.all(plain["rms_fit"] < plain["rms_copy"])
    # unscaled, the fit drags the taller body into the source's place (its root drops by decimetres)
    assert plain["root_offset"].min() > 0.15 and scaled["root_offset"].max() < 0.08
    y = topology.target_vertices(src, p, tgt, scale=ratio)
    floor_s, floor_t = topology.floor_point(src), topology.floor_point(tgt)
    np.testing.assert_allclose(y, floor_t + ratio * (hybrid_skin(src, p) - floor_s))


def test_renamed_bones_start_from_procrustes(bodies):
    src = bodies["female,thin"]
    sk = src.skeleton
    renamed = replace(src, skeleton=Skeleton([f"bone{b}" for b in range(sk.num_bones)], sk.parents,
                                             sk.heads, sk.tails, sk.frames))
    p = _motion(src, 2, seed=4)
    poses, rep = topology.retarget_topology(src, p, renamed)
    assert rep["bones_copied"] == 0 and not rep["from_copy"].any()
    assert np.all(rep["rms_fit"] < 0.1 * rep["rms_copy"]) and rep["rms_fit"].max() < 2e-3


def test_copy_parameters_by_name_leaves_unmatched_bones_at_rest():
    src = synthetic.tube_body(rings=3, segments=4)
    sk = src.skeleton
    names = list(sk.names)
    names[3] = "elsewhere"
    tgt = replace(src, skeleton=Skeleton(names, sk.parents, sk.heads, sk.tails, sk.frames))
    p = synthetic.random_poses(3, sk.num_bones, seed=2)
    out = topology.copy_parameters(src, p, tgt, scale=2.0)
    keep = np.arange(sk.num_bones) != 3
    np.testing.assert_array_equal(out.rotations[:, keep], p.rotations[:, keep])
    np.testing.assert_array_equal(out.rotations[:, 3], np.tile([1.0, 0, 0, 0], (3, 1)))
    np.testing.assert_allclose(out.translations, 2.0 * p.translations)
    np.testing.assert_array_equal(out.scales, p.scales)
    np.testing.assert_array_equal(topology.bone_map(sk, tgt.skeleton), np.where(keep, np.arange(sk.num_bones), -1))


def test_mismatched_topology_is_refused(bodies):
    src = bodies["female,thin"]
    V, F = src.num_vertices, len(src.faces)
    fewer = replace(src, rest_vertices=src.rest_vertices[:-1])
    with pytest.raises(ArticulaInputError, match=f"source has {V} vertices and {F} faces, the target {V - 1} "
                                                 f"vertices and {F} faces"):
        topology.check_shared_topology(src, fewer)
    with pytest.raises(ArticulaInputError, match="do not share their topology"):
        topology.retarget_topology(src, _motion(src, 1), fewer)
    faces = src.faces.copy()
    faces[7] = faces[7][[0, 2, 1]]                                  # the same vertices, flipped
    message = f"face 7 joins vertices {src.faces[7].tolist()} in the source"
    with pytest.raises(ArticulaInputError, match=re.escape(message)):
        topology.check_shared_topology(src, replace(src, faces=faces))
    rolled = np.roll(src.faces, 1, axis=1)                          # every triangle from another corner
    topology.check_shared_topology(src, replace(src, faces=rolled))


@pytest.mark.parametrize("scale", [-1.0, 0.0, float("nan"), "tall"])
def test_bad_scale_is_refused(scale):
    src = synthetic.tube_body(rings=3, segments=4)
    with pytest.raises(ArticulaInputError, match="scale"):
        topology.size_ratio(src, src, scale)
