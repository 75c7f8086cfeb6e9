"""Point-cloud frame files (NPY, XYZ, PLY) and the point-sequence cache."""
import numpy as np
import pytest

from articula.solver.errors import ArticulaInputError
from articula.solver.formats.point_files import PointSequence, read_point_file


def test_point_cloud_files(tmp_path):
    rng = np.random.default_rng(0)
    a = rng.uniform([-1, -1, 1], [1, 1, 3], size=(500, 3))
    np.save(tmp_path / "f_0.npy", a)
    np.savetxt(tmp_path / "f_1.xyz", np.c_[a[:100], np.full((100, 3), 255.0)])
    pts, col = read_point_file(str(tmp_path / "f_0.npy"))
    np.testing.assert_allclose(pts, a, rtol=1e-6)
    assert col is None
    pts, col = read_point_file(str(tmp_path / "f_1.xyz"))
    assert pts.shape == (100, 3) and np.allclose(col, 1.0)
    bad = a.copy()
    bad[7, 1] = np.nan
    np.save(tmp_path / "f_2.npy", bad)
    with pytest.raises(ArticulaInputError, match=r"f_2.npy: 1 point\(s\) with NaN/inf coordinates \(first at row 8\)"):
        read_point_file(str(tmp_path / "f_2.npy"))
    np.save(tmp_path / "f_3.npy", a[:, :2])
    with pytest.raises(ArticulaInputError, match=r"f_3.npy: expected a \(K, 3\) or \(K, 6\)"):
        read_point_file(str(tmp_path / "f_3.npy"))
    (tmp_path / "f_5.obj").write_text("v 0 0 0\n")
    with pytest.raises(ArticulaInputError, match=r"f_5.obj: unknown point-cloud format '.obj'"):
        read_point_file(str(tmp_path / "f_5.obj"))
    (tmp_path / "f_6.xyz").write_text("1 2 x\n")
    with pytest.raises(ArticulaInputError, match=r"f_6.xyz, line 1: not a point-cloud text file"):
        read_point_file(str(tmp_path / "f_6.xyz"))
    (tmp_path / "f_7.xyz").write_text("# x y z\n1 2 3\n\n4 5 6\n7 8\n")
    with pytest.raises(ArticulaInputError, match=r"f_7.xyz, line 5: cannot read point cloud \(expected 3 numbers"):
        read_point_file(str(tmp_path / "f_7.xyz"))
    bad = np.r_[a[:3], [[np.inf, 0, 1]]]
    np.savetxt(tmp_path / "f_8.xyz", bad, header="a comment line")
    with pytest.raises(ArticulaInputError, match=r"f_8.xyz: 1 point\(s\) with NaN/inf coordinates \(first at line 5\)"):
        read_point_file(str(tmp_path / "f_8.xyz"))
    # binary PLY point cloud (vertex element only, with colour properties that are skipped)
    rec = np.zeros(50, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("red", "u1"), ("green", "u1"), ("blue", "u1")])
    rec["x"], rec["y"], rec["z"] = a[:50].T
    header = ("ply\nformat binary_little_endian 1.0\nelement vertex 50\nproperty float x\nproperty float y\n"
              "property float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n")
    (tmp_path / "f_4.ply").write_bytes(header.encode() + rec.tobytes())
    pts, col = read_point_file(str(tmp_path / "f_4.ply"))
    np.testing.assert_allclose(pts, a[:50], rtol=1e-6)


class _Frame:
    def __init__(self, points, normals=None, colors=None):
        self.points, self.normals, self.colors = points, normals, colors


def test_sequence_concatenates_frames_and_round_trips_through_the_cache(tmp_path):
    rng = np.random.default_rng(1)
    frames = [_Frame(rng.normal(size=(n, 3)), rng.normal(size=(n, 3)), rng.uniform(size=(n, 3))) for n in (4, 0, 7)]
    world = np.arange(16.0).reshape(4, 4)
    seq = PointSequence.from_frames(frames, world_from_sensor=world, floor=(np.array([0, -1.0, 0]), 1.2),
                                    intrinsics=(160, 120, 140.0, 138.0, 81.3, 58.2), frame_names=["/a/f0", "f1", "f2"])
    assert seq.frame_count == 3 and seq.points.dtype == np.float32
    for k, f in enumerate(frames):
        np.testing.assert_array_equal(seq.points[seq.frame(k)], f.points.astype(np.float32))
        np.testing.assert_array_equal(seq.colors[seq.frame(k)], f.colors.astype(np.float32))
    seq.save(str(tmp_path / "c.npz"))
    back = PointSequence.load(str(tmp_path / "c.npz"))
    for name in ("points", "offsets", "normals", "colors", "world_from_sensor"):
        np.testing.assert_array_equal(getattr(back, name), getattr(seq, name))
    assert back.frame_names == ["f0", "f1", "f2"] and back.intrinsics == seq.intrinsics
    np.testing.assert_array_equal(back.floor[0], [0, -1, 0]) and back.floor[1] == 1.2
    no_normals = PointSequence.from_frames([_Frame(np.zeros((2, 3))), frames[0]], world_from_sensor=world)
    assert no_normals.normals is None and no_normals.colors is None
    np.save(tmp_path / "x.npz", np.zeros(3))
    with pytest.raises(ArticulaInputError, match="cannot read point cache"):
        PointSequence.load(str(tmp_path / "x.npz"))
    np.savez(tmp_path / "y.npz", format=np.array("other/1"))
    with pytest.raises(ArticulaInputError, match="not an Articula point cache"):
        PointSequence.load(str(tmp_path / "y.npz"))
