"""``./run help`` lists every command: those of ``./run`` itself (test, package, setup, help) and every batch
command of the parser (bench and demo included)."""
import argparse
import os
import re
import subprocess

from ...conftest import REPO


def test_run_help_lists_every_command(pkg):
    res = subprocess.run(["bash", os.path.join(REPO, "run"), "help"], capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stdout + res.stderr
    listed = set(re.findall(r"^ {2,4}([a-z][a-z0-9-]*)\b", res.stdout, flags=re.M))
    parser = pkg("addon.cli.main").build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    batch = set(sub.choices)
    assert {"bench", "demo", "samples", "build-rig", "bake", "export-bundle", "learn-rig", "track", "merge-tracks"} <= batch
    missing = ({"test", "package", "setup", "help"} | batch) - listed
    assert not missing, f"./run help does not list {sorted(missing)}:\n{res.stdout}"
    # every case of the run script's own dispatch is listed too
    script = open(os.path.join(REPO, "run"), encoding="utf-8").read()
    own = {c for case in re.findall(r"^    ([a-z|-]+)\)$", script, flags=re.M) for c in case.split("|")}
    assert own - {"-h", "--help"} <= listed, own
