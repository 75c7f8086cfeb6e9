"""Writing through a temporary name (solver.formats.atomic): the old file or the whole new one, never a
temporary file left behind; an unwritable path is one input error naming it."""
import pytest

from articula.solver.errors import ArticulaInputError
from articula.solver.formats.atomic import written_through


def test_the_new_file_replaces_the_old_only_when_complete(tmp_path):
    path, tmp = tmp_path / "a.txt", str(tmp_path / "a.txt.tmp")
    path.write_text("old")
    with pytest.raises(KeyError):
        with written_through(str(path), tmp, "the text") as t, open(t, "w") as fh:
            fh.write("half")
            raise KeyError("stopped half-way")
    assert path.read_text() == "old" and sorted(p.name for p in tmp_path.iterdir()) == ["a.txt"]
    with written_through(str(path), tmp, "the text") as t, open(t, "w") as fh:
        fh.write("new")
    assert path.read_text() == "new" and sorted(p.name for p in tmp_path.iterdir()) == ["a.txt"]


def test_a_folder_in_the_way_is_named_and_no_temporary_file_stays(tmp_path):
    (tmp_path / "out").mkdir()
    with pytest.raises(ArticulaInputError, match=r"out: cannot write the report \("):
        with written_through(str(tmp_path / "out"), str(tmp_path / "out.tmp"), "the report") as t:
            with open(t, "w") as fh:
                fh.write("{}")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]
