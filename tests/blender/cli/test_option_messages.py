"""A bad learning setting is named as the user set it (issue 16, rough edges item 6): the batch command
names its flag (``--parts: 10000 given; ...``), the operator its property's UI name (``Parts: ...``);
one mapping each (``addon.cli.learn.FLAGS``, ``ARTICULA_OT_learn_rig.setting_names``)."""
import bpy
import pytest

from .test_blend_files import _scans


@pytest.mark.parametrize("args, message", [
    (["--parts", "10000"], "--parts: 10000 given; it must be from 0 to 64"),
    (["--key-scans", "2"], "--key-scans: 2 given; learning a rig needs at least"),
    (["--alpha", "nan"], "--alpha: nan given; expected a finite number"),
    (["--parts", "3"], ": --parts: 3 given for a mesh of 4 vertices"),     # validate_for, after the source
])
def test_cli_names_the_flag(pkg, tmp_path, capsys, args, message):
    folder = _scans(tmp_path / "scans", pkg)
    code = pkg("addon.cli.main").main(["learn-rig", "--scans", folder, *args, "--out", str(tmp_path / "m.npz")])
    err = capsys.readouterr().err
    assert code == 2 and message in err, err
    assert "parts:" not in err.replace("--parts:", "") and "key_scans" not in err


@pytest.mark.parametrize("props, message", [
    ({"parts": 10000}, "Parts: 10000 given; it must be from 0 to 64"),
    ({"key_scans": 2}, "Key Scans: 2 given; learning a rig needs at least"),
    ({"parts": 3}, ": Parts: 3 given for a mesh of 4 vertices"),
])
def test_operator_names_the_property(pkg, tmp_path, props, message):
    folder = _scans(tmp_path / "scans", pkg)
    with pytest.raises(RuntimeError) as info:
        bpy.ops.articula.learn_rig(directory=folder, **props)
    assert message in str(info.value) and "parts:" not in str(info.value)


def test_every_flag_maps_a_setting_to_an_option_of_the_command(pkg):
    fields = set(pkg("solver.learn.options").fields_by_name())
    flags = pkg("addon.cli.learn").FLAGS
    parser = pkg("addon.cli.main").build_parser()
    learn = parser._subparsers._group_actions[0].choices["learn-rig"]
    known = {s for a in learn._actions for s in a.option_strings}
    assert set(flags) <= fields and set(flags.values()) <= known
