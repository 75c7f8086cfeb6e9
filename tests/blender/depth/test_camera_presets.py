"""One table of camera presets (``solver.depth.camera.CAMERA_PRESETS``, issue 32 item 11): the import
panel's Camera list, the commands' ``--preset`` / ``--camera`` choices, the no-camera errors and the
README/docs name the same presets; older spellings that scripts, scenes and farm jobs may hold are read."""
import os

import bpy
import numpy as np
import pytest

from articula.solver.depth import camera
from articula.solver.formats.png16 import write_png16

from ...conftest import REPO

NAMES = ("kinect_v1", "kinect_v2", "azure_kinect_nfov", "realsense_d435")


def _flag(parser, *commands_and_flag):
    """The argparse action of ``flag`` under the (nested) sub-commands ``commands``."""
    *commands, flag = commands_and_flag
    for command in commands:
        parser = next(a for a in parser._actions if a.choices and command in a.choices).choices[command]
    return next(a for a in parser._actions if flag in a.option_strings)


def test_table_names_every_place(pkg):
    assert tuple(camera.PRESETS) == tuple(p.name for p in camera.CAMERA_PRESETS) == NAMES
    enum = bpy.ops.articula.import_depth.get_rna_type().properties["preset"].enum_items
    assert [i.identifier for i in enum] == ["FOLDER", *NAMES]
    assert [i.name for i in enum][1:] == [p.label for p in camera.CAMERA_PRESETS]
    parser = pkg("addon.cli.main").build_parser()
    assert tuple(_flag(parser, "import-depth", "--preset").choices) == NAMES
    assert tuple(_flag(parser, "track", "--camera").choices) == NAMES
    assert tuple(_flag(parser, "farm", "track", "--camera").choices) == NAMES
    assert tuple(_flag(parser, "samples", "depth", "--camera").choices) == NAMES


def test_readme_and_docs_list_the_table():
    def text(*path):
        with open(os.path.join(REPO, *path), encoding="utf-8") as f:
            return " ".join(f.read().split())
    quoted = ", ".join(f"`{n}`" for n in NAMES)
    assert f"`--camera` ({quoted})" in text("README.md")
    labels = ", ".join(p.label for p in camera.CAMERA_PRESETS)
    assert f"camera preset ({labels})" in text("README.md")
    assert f"Camera: {quoted};" in text("docs", "import_depth.md")
    assert f"--camera {'|'.join(NAMES)}" in text("docs", "depth_samples.md")
    assert f"`--camera` ({quoted};" in text("docs", "track_depth.md")


@pytest.mark.parametrize("spelling", ["AZURE_KINECT", "azure_kinect", "Azure Kinect (NFOV)", "azure_kinect_nfov"])
def test_older_spellings_are_read(pkg, spelling):
    parser = pkg("addon.cli.main").build_parser()
    args = parser.parse_args(["import-depth", "--depth", "x", "--preset", spelling])
    assert args.preset == "azure_kinect_nfov"
    args = parser.parse_args(["track", "--depth", "x", "--camera", spelling, "--out", "t.npz"])
    assert args.camera == "azure_kinect_nfov"
    assert camera.preset(spelling) is camera.PRESETS["azure_kinect_nfov"]


def test_unknown_camera_is_refused_with_the_names(pkg, capsys):
    parser = pkg("addon.cli.main").build_parser()
    with pytest.raises(SystemExit):
        parser.parse_args(["track", "--depth", "x", "--camera", "kinect_v3", "--out", "t.npz"])
    assert "kinect_v3" in capsys.readouterr().err
    with pytest.raises(Exception, match="azure_kinect_nfov"):
        camera.preset("kinect_v3")


def test_preset_import_and_no_camera_error(tmp_path):
    """A folder without intrinsics.json: refused naming the table's presets; imported with each preset
    name, the camera's intrinsics are the table's."""
    folder = tmp_path / "rec"
    folder.mkdir()
    intr = camera.PRESETS["azure_kinect_nfov"]
    z = np.zeros(intr.shape, np.uint16)
    z[200:400, 250:400] = 2000
    write_png16(str(folder / "depth_0000.png"), z)
    with pytest.raises(RuntimeError, match=", ".join(NAMES)):
        bpy.ops.articula.import_depth(directory=str(folder), remove_floor=False)
    assert bpy.ops.articula.import_depth(directory=str(folder), preset="azure_kinect_nfov",
                                         remove_floor=False) == {'FINISHED'}
    cam_ob = bpy.context.scene.camera
    assert cam_ob is not None and cam_ob.data.lens == pytest.approx(
        camera.blender_camera_settings(intr)["lens"], rel=1e-6)
