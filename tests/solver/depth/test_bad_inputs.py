"""Implausible camera intrinsics and recordings with nothing in the depth range are refused with a message
naming the value, the plausible bounds and what the frames measure (issue 16 item 5)."""
import json

import numpy as np
import pytest

from articula.solver.depth import camera
from articula.solver.depth import frames as dp
from articula.solver.depth import recording as ps
from articula.solver.errors import ArticulaInputError
from articula.solver.formats.png16 import write_png16

from articula.sample_scenes.depth_scene import floor_box_scene

INTR = camera.Intrinsics(160, 120, 140.0, 138.0, 81.3, 58.2)
GOOD = {"format": camera.FORMAT, "width": 640, "height": 480, "fx": 580.0, "fy": 580.0, "cx": 319.5, "cy": 239.5}


@pytest.mark.parametrize("change, message", [
    ({"fx": 1e12, "fy": 1e12}, r"fx = 1e\+12 px gives a horizontal field of view of 3.67e-08 deg over 640 pixels; "
                               r"a depth camera's is between 1 and 170 deg .*fx must be between 28 and 3.67e\+04 px"),
    ({"fx": 1e-6, "fy": 1e-6}, r"fx = 1e-06 px gives a horizontal field of view of 180 deg"),
    ({"fy": 1e9}, r"fy = 1e\+09 px gives a vertical field of view of .* over 480 pixels"),
    ({"fy": 5000.0}, r"fx = 580 and fy = 5000 px differ by more than 4 times"),
    ({"cx": -3.0}, r"principal point \(cx, cy\) = \(-3, 239.5\) is outside the 640x480 image"),
    ({"cy": 480.0}, r"principal point \(cx, cy\) = \(319.5, 480\) is outside the 640x480 image"),
    ({"fx": float("inf")}, r"fx must be a finite number"),
    ({"intrinsic_matrix": ["a"] * 9, "fx": None}, r"intrinsic_matrix must hold 9 numbers"),
])
def test_implausible_intrinsics_are_refused(tmp_path, change, message):
    data = dict(GOOD, **change)
    if data.get("fx", 0) is None:
        del data["fx"]
    path = tmp_path / "intrinsics.json"
    path.write_text(json.dumps(data))
    with pytest.raises(ArticulaInputError, match=message) as err:
        camera.load_intrinsics(path)
    assert str(err.value).startswith(str(path))


def test_the_presets_and_their_rescaled_versions_are_plausible():
    for name in camera.PRESETS:
        for res in (None, (320, 240), (64, 48)):
            intr = camera.preset(name, None if res is None else (res[0], round(res[0] * camera.PRESETS[name].height
                                                                              / camera.PRESETS[name].width)))
            intr.validate(name)
            h, v = intr.fov_deg()
            assert camera.MIN_FOV_DEG < min(h, v) and max(h, v) < camera.MAX_FOV_DEG


def test_the_field_of_view_bounds_are_where_the_message_says(tmp_path):
    """The bounds quoted in the message are accepted; just outside them is refused."""
    lo = 320 / np.tan(np.radians(camera.MAX_FOV_DEG) / 2)
    hi = 320 / np.tan(np.radians(camera.MIN_FOV_DEG) / 2)
    for fx in (lo * 1.0001, hi * 0.9999):
        camera.Intrinsics(640, 480, fx, fx * 0.75 * 1.0, 319.5, 239.5).validate()
    for fx in (lo * 0.999, hi * 1.001):
        with pytest.raises(ArticulaInputError, match="horizontal field of view"):
            camera.Intrinsics(640, 480, fx, fx, 319.5, 239.5).validate()


def test_the_solver_import_validates_intrinsics_too():
    depth, _, _ = floor_box_scene(INTR)
    frame = ps.DepthFrame("d.png", lambda: (depth * 1000).round().astype(np.uint16))
    bad = camera.Intrinsics(160, 120, 1e12, 1e12, 81.3, 58.2)
    with pytest.raises(ArticulaInputError, match="field of view"):
        ps.import_depth([frame], bad, dp.DepthOptions(remove_floor=False))


def _recording(folder, scale=1.0, n=3):
    folder.mkdir()
    depth, _, _ = floor_box_scene(INTR, wall_y=3.5)     # a wall: every depth below 4 m
    for k in range(n):
        write_png16(folder / f"depth_{k}.png", (depth * 1000 * scale).round().astype(np.uint16))
    return ps.png_frames(ps.list_frames(str(folder), ps.DEPTH_EXTENSIONS)), depth[depth > 0]


def test_a_recording_with_every_point_outside_the_depth_range_is_refused(tmp_path):
    frames, z = _recording(tmp_path / "rec")
    lo, hi = z.min(), z.max()
    with pytest.raises(ArticulaInputError, match=(
            rf"rec: no point of the 3 frames lies in the depth range 8-12 m; the frames measure "
            rf"{lo:.3g}-{hi:.3g} m at a depth scale of 0.001 m per unit: set the depth range")):
        ps.import_depth(frames, INTR, dp.DepthOptions(depth_min=8.0, depth_max=12.0))
    with pytest.raises(ArticulaInputError, match=r"measure .* at a depth scale of 1e-06 m per unit"):
        ps.import_depth(frames, INTR, dp.DepthOptions(depth_scale=1e-6))
    seq = ps.import_depth(frames, INTR, dp.DepthOptions(depth_min=0.3, depth_max=5.0))   # the right range works
    assert seq.frame_count == 3 and len(seq.points) > 1000


def test_one_frame_in_range_is_enough_and_all_empty_frames_are_refused(tmp_path):
    frames, _ = _recording(tmp_path / "rec")
    write_png16(tmp_path / "rec" / "depth_0.png", np.zeros((120, 160), np.uint16))
    write_png16(tmp_path / "rec" / "depth_1.png", np.full((120, 160), 20000, np.uint16))   # 20 m: out of range
    seq = ps.import_depth(frames, INTR, dp.DepthOptions(remove_floor=False))
    assert [len(seq.points[seq.frame(k)]) for k in range(3)][:2] == [0, 0] and seq.frame(2).stop > 0
    write_png16(tmp_path / "rec" / "depth_2.png", np.zeros((120, 160), np.uint16))
    write_png16(tmp_path / "rec" / "depth_1.png", np.zeros((120, 160), np.uint16))
    with pytest.raises(ArticulaInputError, match=r"rec: all 3 frames are empty \(no depth measured\)"):
        ps.import_depth(frames, INTR, dp.DepthOptions(remove_floor=False))


def test_point_clouds_all_outside_the_depth_range_are_refused(tmp_path):
    rng = np.random.default_rng(0)
    paths = []
    for k in range(2):
        np.save(tmp_path / f"c_{k}.npy", rng.uniform([-1, -1, 7], [1, 1, 9], size=(200, 3)))
        paths.append(str(tmp_path / f"c_{k}.npy"))
    with pytest.raises(ArticulaInputError, match=r"no point of the 2 frames lies in the depth range 0.3-5 m; the "
                                                 r"frames measure 7(\.\d+)?-9 m: set the depth range"):
        ps.import_clouds(paths, dp.DepthOptions())
    assert ps.import_clouds(paths, dp.DepthOptions(depth_max=10.0, remove_floor=False)).frame_count == 2


def test_png_frames_are_checked_from_their_headers_before_decoding(tmp_path):
    """A bad last frame is refused before the first is decoded (here: the first frame cannot be decoded
    at all, so reaching it would give another message)."""
    frames, _ = _recording(tmp_path / "rec")
    data = (tmp_path / "rec" / "depth_0.png").read_bytes()
    (tmp_path / "rec" / "depth_0.png").write_bytes(data[:60])                # decodable header, data cut
    write_png16(tmp_path / "rec" / "depth_2.png", np.zeros((60, 80), np.uint16))
    with pytest.raises(ArticulaInputError, match=r"depth_2.png: 80x60 pixels, but depth_0.png is 160x120"):
        ps.import_depth(frames, INTR, dp.DepthOptions())
