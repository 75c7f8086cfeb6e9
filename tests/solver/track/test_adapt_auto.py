"""Whether "auto" adapts the model (solver.track.adaptation.shape_offset, pipeline.adapting): a model whose
surface lies off the captures to one side over whole patches is another body's; zero-mean noise is not."""
import dataclasses

import numpy as np
import pytest

from articula.sample_scenes import synthetic
from articula.solver.geometry.rotations import rotvec_to_quat
from articula.solver.rig.model import Poses
from articula.solver.rig.skinning import hybrid_skin
from articula.solver.track import captures as cp
from articula.solver.track import pipeline
from articula.solver.track.adaptation import SHAPE_OFF, shape_offset
from articula.solver.track.options import ADAPT_MIN_FRAMES, TrackOptions
from articula.solver.track.recording import Recording
from articula.solver.track.report import adapt_note
from articula.solver.tracking.body import Body

GROWN = 0.004      # m: the "other body" lies this far outside the model along its normals


@pytest.fixture(scope="module")
def body():
    return synthetic.tube_body()


def _poses(model, n, seed=0):
    rate = np.random.default_rng(seed).normal(0.0, 0.05, (model.skeleton.num_bones, 3))
    return Poses(rotvec_to_quat(rate[None] * np.arange(n)[:, None, None]), np.zeros((n, 3)), np.ones(n))


def _normals(vertices, faces):
    """Area-weighted vertex normals ``(V, 3)``."""
    face = np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]], vertices[faces[:, 2]] - vertices[faces[:, 0]])
    out = np.zeros_like(vertices)
    for k in range(3):
        np.add.at(out, faces[:, k], face)
    return out / np.maximum(np.linalg.norm(out, axis=1, keepdims=True), 1e-12)


def _recording(model, poses, out=0.0, noise=0.0, seed=0):
    """The model posed by ``poses`` as meshes, moved ``out`` (m) along their normals plus zero-mean noise
    of ``noise`` (m) along them, as a recording of all its frames, read."""
    rng = np.random.default_rng(seed)
    meshes = []
    for x in hybrid_skin(model, poses):
        along = out + rng.normal(0.0, noise, len(x)) if noise else np.full(len(x), out)
        meshes.append(x + along[:, None] * _normals(x, model.faces))
    rec = Recording(cp.CaptureSource.from_arrays(meshes, [model.faces] * len(meshes)), TrackOptions(max_points=0))
    for i in range(len(rec)):          # read, as tracking reads them: each frame gets its report entry
        rec.capture(i)
    return rec


def _offset(body, rec, poses, frame=0):
    return shape_offset(Body(body), rec.capture(frame), poses.take([frame]))


def test_shape_offset_is_zero_on_the_models_own_surface_and_the_gap_of_another(body):
    poses = _poses(body, 1)
    assert _offset(body, _recording(body, poses), poses) < 1e-5
    assert abs(_offset(body, _recording(body, poses, out=GROWN), poses) - GROWN) < 0.2 * GROWN


def test_zero_mean_noise_averages_out_over_the_patches(body):
    """3 mm of noise along the normals: each patch's mean is off by about 3 / sqrt(30) mm, well under the
    threshold, while the noise itself is above it."""
    poses = _poses(body, 1)
    noisy = _offset(body, _recording(body, poses, noise=0.003, seed=1), poses)
    assert noisy < 0.4 * SHAPE_OFF < 0.003, noisy


def test_auto_adapts_another_body_on_enough_frames_and_never_the_models_own(body):
    n = ADAPT_MIN_FRAMES
    poses = _poses(body, n)
    fitted = {i: poses.take([i]) for i in range(n)}
    auto = TrackOptions()
    assert auto.adapt == "auto"
    own, other = _recording(body, poses), _recording(body, poses, out=GROWN)
    adapt, offset = pipeline.adapting(auto, own, Body(body), fitted)
    assert not adapt and offset < 1e-5 and adapt_note(own, offset, adapt) == []
    adapt, offset = pipeline.adapting(auto, other, Body(body), fitted)
    assert adapt and abs(offset - GROWN) < 0.2 * GROWN
    assert "adapted" in adapt_note(other, offset, adapt)[0]
    assert pipeline.adapting(dataclasses.replace(auto, adapt="off"), other, Body(body), fitted) == (False, None)
    assert pipeline.adapting(dataclasses.replace(auto, adapt="on"), own, Body(body), fitted) == (True, None)


def test_auto_names_a_model_off_the_captures_it_has_too_few_frames_to_adapt(body):
    poses = _poses(body, 3)
    rec = _recording(body, poses, out=GROWN)
    adapt, offset = pipeline.adapting(TrackOptions(), rec, Body(body), {i: poses.take([i]) for i in range(3)})
    assert not adapt and offset > SHAPE_OFF
    note = adapt_note(rec, offset, adapt)
    assert len(note) == 1 and "too few" in note[0] and f"{offset * 1e3:.1f} mm" in note[0], note
