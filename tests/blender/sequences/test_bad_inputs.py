"""Bad inputs refused through the operators and the batch commands (issue 16 items 4 and 5): huge files from
their first bytes, implausible camera intrinsics and recordings with nothing in the depth range, each with
one clear message, the scene untouched and no cache left behind."""
import json
import os
import time

import bpy
import numpy as np
import pytest

from articula.solver.depth import camera
from articula.solver.formats.png16 import encode_png

from .test_import_depth import INTR, counts, make_recording

GB2 = 2 * 1024 ** 3


def _intrinsics_file(path, **change):
    data = {"format": camera.FORMAT, "width": INTR.width, "height": INTR.height, "fx": INTR.fx, "fy": INTR.fy,
            "cx": INTR.cx, "cy": INTR.cy}
    data.update(change)
    path.write_text(json.dumps(data))
    return str(path)


def _refused(op, match, **kw):
    """The operator raises with ``match``, fast, and leaves the scene's datablocks as they were."""
    before = counts()
    t = time.perf_counter()
    with pytest.raises(RuntimeError, match=match):
        op(**kw)
    assert counts() == before
    return time.perf_counter() - t


def _cli(pkg, capfd, *args):
    """Exit code and stderr lines of a batch command (the operator's own report filtered out: that
    duplicate is issue 16 item 11, another change)."""
    capfd.readouterr()
    code = pkg("addon.cli.main").main(list(args))
    err = capfd.readouterr().err
    return code, [ln for ln in err.splitlines() if ln.startswith("articula ")]


@pytest.mark.parametrize("focal, fov", [(1e12, r"9.17e-09"), (1e-6, r"180")])
def test_implausible_focal_lengths_are_refused(tmp_path, pkg, capfd, focal, fov):
    folder, _ = make_recording(tmp_path / "rec", n=2)
    bad = _intrinsics_file(tmp_path / "bad.json", fx=focal, fy=focal)
    message = rf"bad.json: fx = {focal:g} px gives a horizontal field of view of {fov} deg over 160 pixels"
    cache = tmp_path / "c.npz"
    _refused(bpy.ops.articula.import_depth, message.replace("+", r"\+"), directory=folder, intrinsics=bad,
             cache_file=str(cache))
    assert not cache.exists()
    code, lines = _cli(pkg, capfd, "import-depth", "--depth", folder, "--intrinsics", bad)
    assert code == 2 and len(lines) == 1
    assert lines[0].startswith("articula import-depth: error: ") and "field of view" in lines[0]


def test_principal_point_outside_the_image_is_refused(tmp_path, pkg, capfd):
    folder, _ = make_recording(tmp_path / "rec", n=2)
    bad = _intrinsics_file(tmp_path / "pp.json", cx=400.0)
    _refused(bpy.ops.articula.import_depth, r"pp.json: principal point \(cx, cy\) = \(400, 55.7\) is outside the "
             r"160x120 image", directory=folder, intrinsics=bad)
    code, lines = _cli(pkg, capfd, "import-depth", "--depth", folder, "--intrinsics", bad)
    assert code == 2 and len(lines) == 1 and "principal point" in lines[0]


def test_a_recording_outside_the_depth_range_is_refused(tmp_path, pkg, capfd):
    folder, _ = make_recording(tmp_path / "rec", n=3)
    cache = tmp_path / "c.npz"
    _refused(bpy.ops.articula.import_depth, r"rec: no point of the 3 frames lies in the depth range 0.05-0.25 m; the "
             r"frames measure [\d.]+-[\d.]+ m at a depth scale of 0.001 m per unit",
             directory=folder, depth_min=0.05, depth_max=0.25, cache_file=str(cache))
    assert not cache.exists()
    code, lines = _cli(pkg, capfd, "import-depth", "--depth", folder, "--depth-min", "0.05", "--depth-max", "0.25")
    assert code == 2 and len(lines) == 1 and "no point of the 3 frames lies in the depth range 0.05-0.25 m" in lines[0]
    code, lines = _cli(pkg, capfd, "import-depth", "--depth", folder, "--depth-scale", "0.000001")
    assert code == 2 and "at a depth scale of 1e-06 m per unit" in lines[0]


def test_a_2gb_depth_frame_is_refused_before_decoding(tmp_path, pkg, capfd):
    folder, _ = make_recording(tmp_path / "rec", n=2)
    with open(os.path.join(folder, "depth_0002.png"), "wb") as f:
        f.write(encode_png(np.zeros((INTR.height, INTR.width), np.uint16))[:33])   # signature + IHDR
        f.truncate(GB2)
    seconds = _refused(bpy.ops.articula.import_depth, r"depth_0002.png: 2.1 GB is far larger than a 160x120 PNG "
                       r"image can take", directory=folder)
    assert seconds < 2.0
    code, lines = _cli(pkg, capfd, "import-depth", "--depth", folder)
    assert code == 2 and len(lines) == 1 and "depth_0002.png: 2.1 GB" in lines[0]


def test_a_garbage_exr_frame_is_refused_before_blender_reads_it(tmp_path):
    folder = tmp_path / "exr"
    folder.mkdir()
    camera.save_intrinsics(folder / "intrinsics.json", INTR)
    (folder / "depth_0.exr").write_bytes(b"\x89PNG\r\n\x1a\n" + b"\0" * 100)
    _refused(bpy.ops.articula.import_depth, r"depth_0.exr: not a OpenEXR file \(EXR depth frame\)",
             directory=str(folder))


def test_a_2gb_scan_is_refused_before_reading(tmp_path, pkg, capfd):
    folder = tmp_path / "scans"
    folder.mkdir()
    tri = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"
    for k in range(2):
        (folder / f"s{k}.obj").write_text(tri)
    with open(folder / "s2.obj", "wb") as f:
        f.write((tri * 400).encode())          # valid OBJ beyond the checked first bytes
        f.truncate(GB2)
    seconds = _refused(bpy.ops.articula.import_scans, r"s2.obj: 2.1 GB is larger than the 1.0 GB limit for a single "
                       r"scan", directory=str(folder))
    assert seconds < 2.0
    code, lines = _cli(pkg, capfd, "import-scans", "--scans", str(folder))
    assert code == 2 and len(lines) == 1 and "s2.obj: 2.1 GB is larger than the 1.0 GB limit" in lines[0]
    os.remove(folder / "s2.obj")
    (folder / "s2.obj").write_bytes(b"solid cube\n  facet normal 0 0 1\n")       # an STL named .obj
    _refused(bpy.ops.articula.import_scans, r"s2.obj, line 1: not an OBJ file \(the line starts with 'solid'",
             directory=str(folder))


def test_reader_messages_number_vertices_from_1(tmp_path):
    folder = tmp_path / "scans"
    folder.mkdir()
    (folder / "a.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    (folder / "b.obj").write_text("# b\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n")
    _refused(bpy.ops.articula.import_scans, r"b.obj: face 1 uses vertex index 4, but the file has 3 vertices "
             r"\(indices 1..3\)", directory=str(folder))
    (folder / "b.obj").write_text("# b\nv 0 0 0\nv 1 0\nv 0 1 0\nf 1 2 3\n")
    _refused(bpy.ops.articula.import_scans, r"b.obj, line 3: vertex 2 has fewer than 3 coordinates",
             directory=str(folder))
    clouds = tmp_path / "clouds"
    clouds.mkdir()
    pts = np.random.default_rng(0).uniform(1, 2, size=(20, 3))
    pts[4, 0] = np.inf
    np.savetxt(clouds / "c_0.xyz", pts, header="x y z")
    _refused(bpy.ops.articula.import_depth, r"c_0.xyz: 1 point\(s\) with NaN/inf coordinates \(first at line 6\)",
             directory=str(clouds))
