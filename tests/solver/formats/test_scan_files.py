"""Scan sequences: natural order, registration check, point caches."""
import os
import random

import numpy as np
import pytest

from articula.solver.errors import ArticulaInputError
from articula.solver.formats.mesh_files import read_mesh
from articula.solver.formats.pointcache import read_point_cache
from articula.solver.formats.scan_files import (list_scan_files, natural_sorted, read_scan_files,
                                           sequence_from_cache)

from ..mesh_writers import CUBE_FACES, CUBE_VERTS, write_mdd, write_obj, write_pc2, write_ply


def test_natural_sort():
    names = ["scan10.obj", "scan2.obj", "scan1.obj", "Scan3.obj", "scan01b.obj", "a.obj"]
    random.Random(0).shuffle(names)
    assert natural_sorted(names) == ["a.obj", "scan1.obj", "scan01b.obj", "scan2.obj", "Scan3.obj", "scan10.obj"]


def make_frames(n, seed=0):
    rng = np.random.default_rng(seed)
    return CUBE_VERTS[None] + rng.normal(scale=0.1, size=(n, len(CUBE_VERTS), 3))


def test_folder_of_ply_in_natural_order(tmp_path):
    frames = make_frames(12)
    for k, f in enumerate(frames):
        write_ply(str(tmp_path / f"scan{k}.ply"), f, CUBE_FACES, "binary_little_endian")
    (tmp_path / "notes.txt").write_text("ignored")
    files = list_scan_files(str(tmp_path))
    assert [os.path.basename(p) for p in files] == [f"scan{k}.ply" for k in range(12)]
    seq = read_scan_files(files)
    assert seq.registered and seq.frames.shape == (12, 8, 3) and seq.frames.dtype == np.float32
    assert np.array_equal(seq.frames, frames.astype(np.float32))


def test_unregistered_accepted_and_explained(tmp_path):
    frames = make_frames(3)
    write_obj(str(tmp_path / "s1.obj"), frames[0], CUBE_FACES)
    write_obj(str(tmp_path / "s2.obj"), frames[1], CUBE_FACES[::-1])
    write_obj(str(tmp_path / "s3.obj"), frames[2][:7], [[0, 1, 2]])
    files = list_scan_files(str(tmp_path))
    seq = read_scan_files(files)
    assert not seq.registered and len(seq.meshes) == 3
    assert seq.why_unregistered.startswith("s2.obj differs from s1.obj: face 1 has 3 corners vs 4")
    assert np.array_equal(seq.meshes[2].vertices, frames[2][:7])
    with pytest.raises(ArticulaInputError, match="not registered: s2.obj differs from s1.obj: face 1 has"):
        read_scan_files(files, require_registered=True)


def test_vertex_count_mismatch_named(tmp_path):
    frames = make_frames(3)
    write_obj(str(tmp_path / "a1.obj"), frames[0], CUBE_FACES)
    write_obj(str(tmp_path / "a2.obj"), frames[1], CUBE_FACES)
    write_obj(str(tmp_path / "a3.obj"), np.vstack([frames[2], [[9, 9, 9]]]), CUBE_FACES)
    with pytest.raises(ArticulaInputError, match="a3.obj differs from a1.obj: vertex count 9 vs 8"):
        read_scan_files(list_scan_files(str(tmp_path)), require_registered=True)


def test_folder_errors(tmp_path):
    with pytest.raises(ArticulaInputError, match="folder not found"):
        list_scan_files(str(tmp_path / "missing"))
    with pytest.raises(ArticulaInputError, match="no scan files"):
        list_scan_files(str(tmp_path))
    write_obj(str(tmp_path / "a.obj"), CUBE_VERTS, CUBE_FACES)
    write_ply(str(tmp_path / "b.ply"), CUBE_VERTS, CUBE_FACES)
    with pytest.raises(ArticulaInputError, match="mixed file types"):
        list_scan_files(str(tmp_path))


def test_garbage_frame_named(tmp_path):
    write_obj(str(tmp_path / "f1.obj"), CUBE_VERTS, CUBE_FACES)
    (tmp_path / "f2.obj").write_bytes(b"v 1 2\n")
    with pytest.raises(ArticulaInputError, match="f2.obj, line 1: vertex 1 has fewer than 3"):
        read_scan_files(list_scan_files(str(tmp_path)))


@pytest.mark.parametrize("ext", ["mdd", "pc2"])
def test_point_caches(tmp_path, ext):
    frames = make_frames(5).astype(np.float32)
    path = str(tmp_path / f"anim.{ext}")
    (write_mdd if ext == "mdd" else write_pc2)(path, frames)
    got = read_point_cache(path)
    assert got.dtype == np.float32 and np.array_equal(got, frames)
    write_obj(str(tmp_path / "base.obj"), CUBE_VERTS, CUBE_FACES)
    base = read_mesh(str(tmp_path / "base.obj"))
    seq = sequence_from_cache(got, base, f"anim.{ext}", "base.obj")
    assert seq.registered and np.array_equal(seq.frames, frames)
    with pytest.raises(ArticulaInputError, match=f"anim.{ext} has 7 vertices per frame but the base mesh"):
        sequence_from_cache(got[:, :7], base, f"anim.{ext}", "base.obj")


def test_mdd_with_rest_frame_and_bad_sizes(tmp_path):
    frames = make_frames(4).astype(np.float32)
    path = str(tmp_path / "r.mdd")
    write_mdd(path, frames, rest_frame=True)
    assert np.array_equal(read_point_cache(path), frames)
    with open(path, "ab") as fh:
        fh.write(b"xx")
    with pytest.raises(ArticulaInputError, match="r.mdd: MDD header says 4 frames of 8 points"):
        read_point_cache(path)
    (tmp_path / "g.pc2").write_bytes(b"POINTCACHE1" + b"\0" * 40)
    with pytest.raises(ArticulaInputError, match="g.pc2: not a PC2 file"):
        read_point_cache(str(tmp_path / "g.pc2"))


def test_point_cache_nan_names_frame_and_vertex(tmp_path):
    frames = make_frames(4).astype(np.float32)
    frames[2, 6, 1] = np.nan
    path = str(tmp_path / "n.pc2")
    write_pc2(path, frames)
    with pytest.raises(ArticulaInputError, match="n.pc2: frame 3 vertex 7 has a non-finite"):
        read_point_cache(path)


@pytest.mark.parametrize("fmt", ["obj", "ply"])
def test_reads_the_sample_scenes_writer(tmp_path, fmt):
    """Cross-check with the project's own sequence writer (written independently of these readers)."""
    from articula.sample_scenes.mesh_files import SequenceWriter
    quads = np.array([f for f in CUBE_FACES if len(f) == 4])
    frames = make_frames(3, seed=7)
    writer = SequenceWriter(quads, fmt)
    for k, f in enumerate(frames):
        writer.write(str(tmp_path / f"q{k + 1}.{fmt}"), f)
    seq = read_scan_files(list_scan_files(str(tmp_path)))
    assert seq.registered and np.allclose(seq.frames, frames, atol=6e-7)   # OBJ: 6 decimals
    assert seq.topology.face_sizes.tolist() == [4] * len(quads)
    assert seq.topology.corner_verts.tolist() == quads.ravel().tolist()


def test_stl_sequence_is_registered_when_triangles_keep_their_order(tmp_path):
    from ..mesh_writers import write_stl
    frames = make_frames(3, seed=9).astype(np.float32)
    for k, f in enumerate(frames):
        write_stl(str(tmp_path / f"t{k}.stl"), f, CUBE_FACES, binary=k != 1)   # ascii and binary mixed
    seq = read_scan_files(list_scan_files(str(tmp_path)))
    assert seq.registered and seq.frames.shape == (3, 8, 3)
    # welded numbering = first use by the triangle list; same permutation in every frame
    order = seq.frames[0][:, None, :] == frames[0][None, :, :]
    perm = np.flatnonzero(order.all(axis=2)) % 8
    assert np.allclose(seq.frames, frames[:, perm], atol=1e-6)
