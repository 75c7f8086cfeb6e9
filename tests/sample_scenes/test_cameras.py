"""``samples depth`` / ``samples unregistered`` batch commands on the MakeHuman subject (parsed by
the ``samples`` command itself, without the bpy-dependent command modules of ``addon/cli/common.py``)."""
import argparse

import numpy as np
import pytest

from articula.sample_scenes import cli as samples_cli
from articula.solver.depth import camera
from articula.solver.formats.obj import read_obj
from articula.solver.formats import png16
from articula.solver.errors import ArticulaInputError


def run(argv) -> int:
    parser = argparse.ArgumentParser()
    samples_cli.add_commands(parser.add_subparsers(dest="command"))
    args = parser.parse_args(argv)
    return args.func(args)


def test_samples_depth_command(tmp_path, capsys):
    out = tmp_path / "depth"
    assert run(["samples", "depth", "--poses", "2", "--resolution", "80x60", "--seed", "1",
                     "--background", "--out", str(out)]) == 0
    assert "2 depth PNGs 80x60" in capsys.readouterr().out
    g = np.load(out / "ground_truth.npz")
    intr = camera.load_intrinsics(out / "intrinsics.json")
    assert g["posed_heads"].shape[0] == 2 and g["pose_rotations"].shape[0] == 2
    assert "posed_vertices" not in g.files
    depth = png16.read_png16(out / "depth_0001.png")
    assert depth.shape == (60, 80) and 0.2 < (depth > 0).mean() < 1.0
    # the posed root joint projects onto the subject (a measured pixel nearer than the wall)
    head = g["posed_heads"][1, 0]
    uv, z = camera.project(camera.world_to_camera(head[None], g["cam_to_world"][1]), intr)
    u, v = np.rint(uv[0]).astype(int)
    window = depth[v - 2:v + 3, u - 2:u + 3]
    assert window.max() > 0 and abs(np.median(window[window > 0]) / 1000 - z[0]) < 0.3


def test_samples_unregistered_command(tmp_path, capsys):
    out = tmp_path / "scans"
    assert run(["samples", "unregistered", "--poses", "2", "--cameras", "3", "--resolution", "96x72",
                     "--format", "obj", "--out", str(out)]) == 0
    g = np.load(out / "ground_truth.npz")
    counts = [len(read_obj(str(out / f"scan_{k:04d}.obj")).vertices) for k in range(2)]
    assert counts == list(g["vertex_counts"]) and counts[0] != counts[1]
    assert g["cam_to_world"].shape == (2, 3, 4, 4)


def test_bad_resolution_is_an_input_error(tmp_path):
    with pytest.raises(ArticulaInputError, match="WIDTHxHEIGHT"):
        run(["samples", "depth", "--resolution", "big", "--out", str(tmp_path)])
