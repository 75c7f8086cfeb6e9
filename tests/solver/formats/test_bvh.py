"""The BVH check run before Blender's importer (``solver.formats.bvh.check_bvh``): the CMU clips pass with
their declared frames and one value per channel; a file cut anywhere, a value that is not a number or a
file that is not a BVH is refused with one line that starts with the file's path."""
import os

import pytest

from articula.solver.errors import ArticulaInputError
from articula.solver.formats.bvh import check_bvh
from ...conftest import SHARED_DATA

MOCAP = os.path.join(SHARED_DATA, "mocap")


def _data(name):
    path = os.path.join(MOCAP, name)
    assert os.path.isfile(path), f"missing fixture {path}"
    with open(path, "rb") as fh:
        return path, fh.read()


def _write(tmp_path, data, name="t.bvh"):
    path = tmp_path / name
    path.write_bytes(data)
    return str(path)


@pytest.mark.parametrize("name, frames", [("cmu_131_01.bvh", 994), ("cmu_01_01.bvh", 2752)])
def test_cmu_clips_pass(name, frames):
    path, data = _data(name)
    lines = data.decode("latin-1").splitlines()
    first = lines[lines.index("MOTION") + 3]                    # the first frame's values
    assert check_bvh(path) == (len(first.split()), frames, pytest.approx(1 / 120, rel=1e-4))


def test_windows_line_ends_and_trailing_blank_lines_pass(tmp_path):
    _, data = _data("cmu_131_01.bvh")
    path = _write(tmp_path, data.replace(b"\n", b"\r\n") + b"\r\n\r\n")
    assert check_bvh(path)[1] == 994


def test_a_file_cut_anywhere_is_refused_in_one_line(tmp_path):
    _, data = _data("cmu_131_01.bvh")
    # (a cut inside the very last number leaves a shorter number: a well-formed file, so not tested)
    for size in list(range(0, len(data), 7919)) + [len(data) - 8, len(data) - 700]:
        path = _write(tmp_path, data[:size])
        with pytest.raises(ArticulaInputError) as err:
            check_bvh(path)
        text = str(err.value)
        assert text.startswith(path + ": ") and "\n" not in text, (size, text)


def test_a_value_that_is_not_a_number_is_refused(tmp_path):
    _, data = _data("cmu_131_01.bvh")
    lines = data.decode("latin-1").splitlines()
    row = lines.index("MOTION") + 12                             # frame 10
    lines[row] = " ".join(["x"] + lines[row].split()[1:])
    path = _write(tmp_path, "\n".join(lines).encode("latin-1"))
    with pytest.raises(ArticulaInputError, match=r"line \d+: frame 10 holds something that is not a number"):
        check_bvh(path)


def test_not_a_bvh(tmp_path):
    path = _write(tmp_path, b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "mesh.bvh")
    with pytest.raises(ArticulaInputError, match="not a BVH file"):
        check_bvh(path)
    with pytest.raises(ArticulaInputError, match="file not found"):
        check_bvh(str(tmp_path / "none.bvh"))
