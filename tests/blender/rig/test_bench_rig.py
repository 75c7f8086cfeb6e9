"""``./run bench rig`` fails loudly: an error in its MakeHuman part propagates (the batch command then exits
non-zero with the message) instead of being printed as "skipped"; only assets that cannot be downloaded
are reported as skipped, by name."""
import importlib
import importlib.util
import os

import bpy
import pytest

from ...conftest import REPO
from ..conftest import MODULE


def _bench_rig():
    spec = importlib.util.spec_from_file_location("articula_bench_rig_under_test",
                                                  os.path.join(REPO, "bench", "bench_rig.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_an_error_in_the_makehuman_part_is_not_reported_as_skipped(pkg, capsys):
    bench = _bench_rig()
    with pytest.raises(pkg("solver.errors").ArticulaInputError, match="unknown rig 'no_such_rig'"):
        bench.makehuman(bpy, importlib.import_module(MODULE), 1, n=2, rig="no_such_rig")
    assert "skipped" not in capsys.readouterr().out
