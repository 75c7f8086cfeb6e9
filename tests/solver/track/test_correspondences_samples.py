"""Correspondences of a MakeHuman subject's exact posed model to its own noisy, partial 4-view scan
(sample_scenes.unregistered): distances at the noise level, the back side hidden from one camera
(checked against the sample renderer's picture)."""
import numpy as np
import pytest
from scipy.spatial import cKDTree

from articula.sample_scenes import registered, unregistered as unreg
from articula.sample_scenes.depth_render import render_depth
from articula.solver.depth import camera
from articula.solver.geometry.surface_distance import distance_to_surface
from articula.solver.track import correspondences as corr
from articula.solver.geometry.normals import vertex_normals
from articula.solver.track.visibility import visible_vertices


@pytest.fixture(scope="module")
def scan():
    frames, faces, _ = registered.posed_sequence(n_poses=2, motion="rom", seed=1)
    model = frames[1]
    points, tris, source, seen_by, cams = unreg.scan_frame(model, faces, np.random.default_rng([0, 1]))
    return model, faces, points, tris, source, cams, seen_by


def test_exact_model_matches_its_scan_at_the_noise_level(scan):
    model, faces, points, tris, source, cams, _ = scan
    opts = corr.CorrespondenceOptions(trim=False)
    out = corr.correspondences(model, faces, vertex_normals(model, faces), points, vertex_normals(points, tris),
                               tris, cams, opts)
    on_body = source[out.capture_index] >= 0
    cap = out.from_capture & on_body
    noise = np.median(distance_to_surface(points[source >= 0], model, faces))
    assert 0.9 * noise < np.median(out.distances[cap]) < 1.2 * noise
    assert 0.0005 < noise < 0.01
    trimmed = corr.correspondences(model, faces, vertex_normals(model, faces), points,
                                   vertex_normals(points, tris), tris, cams)
    assert 0.3 < trimmed.stats["removed_capture"] < 0.7 and 0.3 < trimmed.stats["removed_model"] < 0.75
    assert np.median(trimmed.distances) < np.median(out.distances)


def test_one_camera_sees_only_the_front(scan):
    """Reference: the faces the sample renderer (``sample_scenes.depth_render``) shows camera 0."""
    model, faces, _, _, _, cams, _ = scan
    c2w, intr = cams[0]
    normals = vertex_normals(model, faces)
    seen = visible_vertices(model, normals, faces, [cams[0]])
    _, tri_id = render_depth(camera.world_to_camera(model, c2w), faces, intr)
    rendered = np.zeros(len(model), bool)
    rendered[faces[np.unique(tri_id[tri_id >= 0])].ravel()] = True
    far = cKDTree(model[rendered]).query(model)[0] > 0.03      # 3 cm from anything camera 0 shows
    assert 0.25 < seen.mean() < 0.6 and far.mean() > 0.1
    assert seen[rendered].mean() > 0.95
    view = c2w[:3, 3] - model
    cos = np.einsum("ij,ij->i", normals, view) / np.linalg.norm(view, axis=1)
    assert (cos[far] > 0).sum() > 50 and seen[far].mean() < 0.03      # the back side, turned away or occluded
    assert not seen[far & (cos > 0.5)].any()     # only grazing ones (edge pixels the renderer missed) remain
