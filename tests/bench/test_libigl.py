"""libigl text formats (.tgf, .dmat, .Tmat; bench/_libigl.py, read by ``./run bench learn``): hand-written files, bad input, and the public skinning ground
truth reproduced exactly from its own weights and transforms."""
import glob
import os

import numpy as np
import pytest

from articula.bench import _libigl as igl_formats
from articula.solver.errors import ArticulaInputError
from articula.solver.formats.obj import read_obj

from ..conftest import SHARED_DATA

GT = os.path.join(SHARED_DATA, "skinning_gt")


def write(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text)
    return str(p)


def test_tgf(tmp_path):
    path = write(tmp_path, "s.tgf", "1 0 0 0\n2 1.5 0 0\n 3 1.5 2 -1\n#\n1 2\n2\t3\n#\n")
    joints, bones = igl_formats.read_tgf(path)
    np.testing.assert_array_equal(joints, [[0, 0, 0], [1.5, 0, 0], [1.5, 2, -1]])
    np.testing.assert_array_equal(bones, [[0, 1], [1, 2]])
    with pytest.raises(ArticulaInputError, match=r"bad.tgf: bone 1 refers to joint \[1 4\]"):
        igl_formats.read_tgf(write(tmp_path, "bad.tgf", "1 0 0 0\n2 1 0 0\n#\n1 4\n#\n"))
    with pytest.raises(ArticulaInputError, match="line 2: expected 4 numbers"):
        igl_formats.read_tgf(write(tmp_path, "short.tgf", "1 0 0 0\n2 1 0\n#\n1 2\n"))


def test_dmat_is_column_major(tmp_path):
    # 2 columns, 3 rows: values column by column
    m = igl_formats.read_dmat(write(tmp_path, "w.dmat", "2 3\n1\n2\n3\n4\n5\n6\n"))
    np.testing.assert_array_equal(m, [[1, 4], [2, 5], [3, 6]])
    with pytest.raises(ArticulaInputError, match="header says 3 x 2 = 6 values, found 5"):
        igl_formats.read_dmat(write(tmp_path, "b.dmat", "2 3\n1 2 3 4 5\n"))
    with pytest.raises(ArticulaInputError, match="binary"):
        igl_formats.read_dmat(write(tmp_path, "bin.dmat", "0 0\n"))


def test_tmat_row_vector_convention(tmp_path):
    # one bone: [v 1] T with T = [[R^T], [t]] -> x -> R x + t; R = 90° about z
    path = write(tmp_path, "p.Tmat", "0 1 0\n-1 0 0\n0 0 1\n5 6 7\n")
    A, t = igl_formats.read_tmat(path, num_bones=1)
    np.testing.assert_allclose(A[0] @ [1.0, 0, 0] + t[0], [5, 7, 7])
    with pytest.raises(ArticulaInputError, match="1 bone transforms, the skeleton has 2 bones"):
        igl_formats.read_tmat(path, num_bones=2)
    with pytest.raises(ArticulaInputError, match="4 rows per bone"):
        igl_formats.read_tmat(write(tmp_path, "q.Tmat", "1 0 0\n0 1 0\n"))


@pytest.mark.skipif(not os.path.isdir(GT), reason="shared skinning_gt data not present")
@pytest.mark.parametrize("name", ["cylinder", "wolf"])
def test_skinning_gt_is_reproduced_by_its_weights_and_transforms(name):
    d = os.path.join(GT, f"{name}-all")
    joints, bones = igl_formats.read_tgf(os.path.join(d, f"{name}.tgf"))
    W = igl_formats.read_dmat(os.path.join(d, f"{name}.DMAT"))
    rest = read_obj(os.path.join(d, f"{name}.obj")).vertices
    assert W.shape == (len(rest), len(bones))
    np.testing.assert_allclose(W.sum(axis=1), 1.0, atol=1e-9)
    poses = sorted(glob.glob(os.path.join(d, "poses-*", "*.obj")))
    assert len(poses) >= 8
    for obj in poses[:6]:
        A, t = igl_formats.read_tmat(obj[:-4] + ".Tmat", num_bones=len(bones))
        np.testing.assert_allclose(np.linalg.det(A), 1.0, atol=1e-4)           # rigid bones
        posed = np.einsum("vb,bvi->vi", W, np.einsum("bij,vj->bvi", A, rest) + t[:, None])
        target = read_obj(obj).vertices
        scale = np.linalg.norm(target.max(0) - target.min(0))
        assert np.abs(posed - target).max() < 1e-5 * scale                     # files are rounded
        wrong = np.einsum("vb,bvi->vi", W, np.einsum("bji,vj->bvi", A, rest) + t[:, None])
        assert np.abs(wrong - target).max() > 1e-2 * scale                      # transposed: far off
