"""Options whose values start with a minus sign (``--facing -Y``, ``--up -Z``) take them as two words, as the docs
write them: argparse would read ``-Y`` as an unknown option (issue 32, tried as a new user)."""


def _subparsers(parser):
    return parser._subparsers._group_actions[0].choices


def test_gaze_facing_and_scan_axes_take_signed_values(pkg):
    parser = pkg("addon.cli.main").build_parser()
    args = parser.parse_args(["gaze", "--blend", "a.blend", "--armature", "A", "--target", "T",
                              "--facing", "-Y", "--out", "o.blend"])
    assert args.facing == "-Y"
    args = parser.parse_args(["import-scans", "--scans", "d", "--forward", "-Z", "--up", "-Y"])
    assert (args.forward, args.up) == ("NEGATIVE_Z", "NEGATIVE_Y")


def test_every_option_with_signed_choices_accepts_them(pkg):
    parser = pkg("addon.cli.main").build_parser()
    checked = 0
    for name, sub in _subparsers(parser).items():
        for action in sub._actions:
            for value in action.choices or ():
                if isinstance(value, str) and value.startswith("-"):
                    checked += 1
                    assert sub._negative_number_matcher.match(value), f"{name} {action.option_strings}: {value}"
    assert checked >= 2
