"""Unregistered scans: re-triangulated depth grids from several cameras, exact surface provenance,
differing topology per frame, files readable by the scan readers."""
import dataclasses

import numpy as np
import pytest
import trimesh

from articula.sample_scenes import depth_noise as dn
from articula.sample_scenes import unregistered as unreg
from articula.solver.depth import camera
from articula.solver.formats.obj import read_obj
from articula.solver.formats.ply import read_ply
from articula.solver.errors import ArticulaInputError

RIG = unreg.ScanRig(resolution=(96, 72), n_cameras=3)


def _sphere_frames(n=3, radius=0.4):
    s = trimesh.creation.icosphere(subdivisions=3, radius=radius)
    centres = np.array([[0.05 * k, 0.0, 1.0] for k in range(n)])
    return s.vertices[None] + centres[:, None], np.asarray(s.faces), centres


def test_grid_triangles_drop_jumps_and_face_the_camera():
    depth = np.full((4, 5), 2.0)
    depth[:, 3:] = 3.0          # a jump between columns 2 and 3
    depth[0, 0] = 0.0           # a hole
    tris = unreg.grid_triangles(depth, 0.02, 0.02)
    z = depth.ravel()[tris]
    assert (z.max(1) - z.min(1) <= 0.06).all() and (z > 0).all()
    # 3 cells x 4 columns... counted: 2 per cell except the jump column and the hole's triangle
    assert len(tris) == 2 * 3 * 4 - 2 * 3 - 1
    intr = camera.Intrinsics(5, 4, 10.0, 10.0, 2.0, 1.5)
    v, f, pix = unreg.depth_mesh(depth, intr, np.eye(4), 0.02, 0.02)
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    assert (n[:, 2] < 0).all()  # towards the camera at the origin looking down +Z
    assert len(v) == len(np.unique(pix)) == len(np.unique(tris))


def test_noiseless_scans_lie_on_their_source_faces(tmp_path):
    frames, faces, centres = _sphere_frames()
    rig = dataclasses.replace(RIG, outlier_fraction=0.01)
    info = unreg.generate_unregistered(tmp_path, frames, faces, {"centres": centres}, rig=rig,
                                       noise=dn.NOISELESS, seed=4)
    g = np.load(tmp_path / "ground_truth.npz")
    assert len(set(info["vertex_counts"])) == 3                       # differ per frame
    np.testing.assert_allclose(g["centres"], centres)
    assert g["cam_to_world"].shape == (3, 3, 4, 4)
    for k in range(3):
        mesh = read_ply(str(tmp_path / f"scan_{k:04d}.ply"))
        v = mesh.vertices
        src = g["source_face"][g["source_offsets"][k]:g["source_offsets"][k + 1]]
        assert len(v) == len(src) == g["vertex_counts"][k]
        out = src < 0
        assert 0 < out.sum() <= 3 * 0.011 * len(v)
        seen_by = g["source_camera"][g["source_offsets"][k]:g["source_offsets"][k + 1]]
        assert np.array_equal(seen_by < 0, out) and set(seen_by[~out]) == {0, 1, 2}
        eyes = g["cam_to_world"][k][:, :3, 3]
        # each vertex is on the hemisphere facing the camera that saw it
        assert (np.einsum("ij,ij->i", v[~out] - centres[k], eyes[seen_by[~out]] - centres[k]) > 0).all()
        # noiseless: every measured vertex lies on the plane of the triangle it was seen on
        tri = frames[k][faces[src[~out]]]
        normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        normal /= np.linalg.norm(normal, axis=1, keepdims=True)
        dist = np.einsum("ij,ij->i", v[~out] - tri[:, 0], normal)
        assert np.abs(dist).max() < 1e-5                               # float32 file precision
        # partial views from all sides cover most of the sphere
        d = v[~out] - centres[k]
        sector = np.floor((np.arctan2(d[:, 1], d[:, 0]) + np.pi) / (np.pi / 4)).astype(int) % 8
        assert np.bincount(sector, minlength=8).min() > 20            # seen from all around
        # triangles face outwards (the camera that saw them was outside the sphere)
        tris = mesh.triangles()
        keep = ~out[tris].any(1)
        fn = np.cross(v[tris[keep, 1]] - v[tris[keep, 0]], v[tris[keep, 2]] - v[tris[keep, 0]])
        outward = np.einsum("ij,ij->i", fn, v[tris[keep]].mean(1) - centres[k]) > 0
        assert outward.mean() > 0.99


def test_noisy_scans_deterministic_and_near_surface(tmp_path):
    frames, faces, centres = _sphere_frames(2)
    a = unreg.scan_frame(frames[0], faces, np.random.default_rng([1, 0]), RIG)
    b = unreg.scan_frame(frames[0], faces, np.random.default_rng([1, 0]), RIG)
    c = unreg.scan_frame(frames[0], faces, np.random.default_rng([2, 0]), RIG)
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1]) and np.array_equal(a[3], b[3])
    assert len(a[0]) != len(c[0]) or not np.array_equal(a[0], c[0])
    r = np.linalg.norm(a[0][a[2] >= 0] - centres[0], axis=1)
    assert np.median(np.abs(r - 0.4)) < 0.01                            # Kinect noise at ~2.5 m


def test_bad_parameters(tmp_path):
    frames, faces, _ = _sphere_frames(1)
    with pytest.raises(ArticulaInputError, match="n_cameras"):
        unreg.generate_unregistered(tmp_path, frames, faces, rig=unreg.ScanRig(n_cameras=0))
    with pytest.raises(ArticulaInputError, match="format"):
        unreg.generate_unregistered(tmp_path, frames, faces, fmt="stl")


def test_obj_scans_are_written_y_up_like_blenders_exporter(tmp_path):
    """Same seed, two formats: the PLY scan holds world coordinates (Z up), the OBJ scan the same points in
    OBJ's Y-up convention, (x, y, z) -> (x, z, -y); ground_truth.npz says which (``file_axes``)."""
    frames, faces, _ = _sphere_frames()
    for fmt in ("ply", "obj"):
        unreg.generate_unregistered(tmp_path / fmt, frames[:1], faces, rig=RIG, noise=dn.NOISELESS, seed=2, fmt=fmt)
    world = read_ply(str(tmp_path / "ply" / "scan_0000.ply")).vertices
    in_obj = read_obj(str(tmp_path / "obj" / "scan_0000.obj")).vertices
    np.testing.assert_allclose(in_obj, np.c_[world[:, 0], world[:, 2], -world[:, 1]], atol=2e-6)
    assert np.load(tmp_path / "ply" / "ground_truth.npz")["file_axes"].tolist() == ["Y", "Z"]
    assert np.load(tmp_path / "obj" / "ground_truth.npz")["file_axes"].tolist() == ["NEGATIVE_Z", "Y"]
