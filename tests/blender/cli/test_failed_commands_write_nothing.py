"""A command that fails writes nothing (issue 32 item 7), checked once for every batch command of
``addon/cli/main``'s parser: each is given real inputs and an output that makes it fail, where possible
after it wrote an earlier output (``--report`` at an existing folder after the bundle, ``--out`` at an
existing folder after the work); it must exit non-zero and leave the output folder as it was (no
bundle, report, temporary file, .blend or cache; a replaced file back to its bytes), and no cache in
``ARTICULA_HOME``."""
import collections
import hashlib
import os

import pytest

from articula.sample_scenes.tube_scans import hybrid_truth
from ...conftest import SHARED_DATA
from ...solver.track.test_merge import chunk, truth_poses
from ..rig_helpers import poses, subject
from ..sequences.test_import_depth import make_recording
from ..track.test_track import make_truth, write_captures
from .test_blend_files import _scans

NOBODY = "http://127.0.0.1:9"            # the discard port: nothing listens there
FAST_TRACK = ["--adapt", "off", "--prior", "none", "--no-temporal", "--frames", "0:2"]


def _walk(folder) -> dict:
    """Every file and folder under ``folder`` with its content digest (folders: None)."""
    out = {}
    for d, subdirs, names in os.walk(folder):
        for n in subdirs:
            out[os.path.relpath(os.path.join(d, n), folder)] = None
        for n in names:
            with open(os.path.join(d, n), "rb") as fh:
                out[os.path.relpath(os.path.join(d, n), folder)] = hashlib.sha256(fh.read()).hexdigest()
    return out


@pytest.fixture(scope="module")
def inputs(tmp_path_factory, addon):
    """Real inputs of every command, outside the output folder."""
    import importlib
    pkg = lambda name: importlib.import_module(f"{addon.__name__}.{name}")  # noqa: E731
    root = tmp_path_factory.mktemp("inputs")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("ARTICULA_HOME", str(tmp_path_factory.mktemp("home")))
        return _make_inputs(pkg, root)


def _make_inputs(pkg, root) -> dict:
    import bpy
    bundle = str(root / "subject.npz")
    model = subject(pkg, rings=6, segments=8)
    pkg("solver.formats.bundle").save_bundle(bundle, model, poses(pkg, model.skeleton.num_bones, 3, seed=4))
    rig = str(root / "rig.blend")
    assert pkg("addon.cli.main").main(["build-rig", "--bundle", bundle, "--blend", rig]) == 0
    bpy.ops.wm.read_homefile(use_empty=True)
    learn_model, _, learn_scans = hybrid_truth(M=4, seed=4, max_angle=0.6)
    track_model, _, captures = make_truth(3, seed=2)
    person = str(root / "person.npz")
    pkg("solver.formats.bundle").save_bundle(person, track_model)
    tube = synthetic_tube()
    gt = truth_poses(tube, 12)
    chunks = []
    for name, (a, b) in (("a.npz", (0, 8)), ("b.npz", (5, 12))):
        c = chunk(tube, gt, a, b, name)
        chunks.append(str(root / name))
        pkg("solver.formats.bundle").save_bundle(chunks[-1], c.model, c.poses, c.provenance)
    subjects = root / "subjects"
    _scans(subjects / "one", pkg)
    return {"bundle": bundle, "rig": rig, "scans": _scans(root / "scans", pkg),
            "learn_scans": _scans(root / "learn", pkg, faces=learn_model.faces, frames=learn_scans),
            "person": person, "captures": write_captures(root / "captures", captures),
            "depth": make_recording(root / "rec", n=3)[0], "chunks": chunks, "subjects": str(subjects),
            "bvh": os.path.join(SHARED_DATA, "mocap", "cmu_01_01.bvh")}


def synthetic_tube():
    from articula.sample_scenes import synthetic
    return synthetic.tube_body(rings=4, segments=6)


def commands(i, out) -> dict:
    """Command (as the parser names it) -> arguments that make it fail; ``out`` is the output folder,
    ``out/taken`` an existing folder in it and ``out/mine.txt`` an existing file."""
    taken, mine = os.path.join(out, "taken"), os.path.join(out, "mine.txt")
    return {
        "bench": ["bench", "no_such_benchmark"],
        "samples registered": ["samples", "registered", "--poses", "2", "--out", mine],
        "samples subject": ["samples", "subject", "--out", taken],
        "samples depth": ["samples", "depth", "--poses", "2", "--resolution", "64x48", "--out", mine],
        "samples unregistered": ["samples", "unregistered", "--poses", "2", "--out", mine],
        "build-rig": ["build-rig", "--bundle", i["bundle"], "--blend", taken],
        "bake": ["bake", "--bundle", i["bundle"], "--blend", i["rig"], "--out", taken],
        "export-bundle": ["export-bundle", "--blend", i["rig"], "--out", taken],
        "export-lbs": ["export-lbs", "--blend", i["rig"], "--out", taken],
        "import-scans": ["import-scans", "--scans", i["scans"], "--blend", taken],
        "import-depth": ["import-depth", "--depth", i["depth"], "--blend", taken],
        "learn-rig": ["learn-rig", "--scans", i["learn_scans"], "--parts", "4", "--iterations", "0", "--threads",
                      "1", "--out", os.path.join(out, "learned.npz"), "--report", taken,
                      "--blend", os.path.join(out, "learned.blend")],
        "track": ["track", "--model", i["person"], "--scans", i["captures"], *FAST_TRACK, "--out",
                  os.path.join(out, "tracked.npz"), "--report", taken, "--blend", os.path.join(out, "t.blend")],
        "merge-tracks": ["merge-tracks", *i["chunks"], "--agree", "0", "--out", os.path.join(out, "merged.npz"),
                         "--report", taken],
        "retarget": ["retarget", "--source", i["bvh"], "--target", i["rig"], "--out", taken],
        "bind-scan": ["bind-scan", "--blend", i["rig"], "--scan", os.path.join(i["scans"], "s0.obj"), "--out", taken],
        "gaze": ["gaze", "--blend", i["rig"], "--armature", "subject", "--target", "subject", "--out", taken],
        "farm job-types": ["farm", "job-types", "--to", mine],
        "farm track": ["farm", "track", "--manager", NOBODY, "--model", i["bundle"], "--depth", i["depth"],
                       "--out", os.path.join(out, "farm.npz"), "--blend", os.path.join(out, "farm.blend")],
        "farm learn": ["farm", "learn", "--manager", NOBODY, "--subjects", i["subjects"], "--out-dir",
                       os.path.join(out, "rigs")],
        "farm import": ["farm", "import", "--manager", NOBODY, "--subjects", i["subjects"], "--out-dir",
                        os.path.join(out, "blends")],
        "farm status": ["farm", "status", "--manager", NOBODY, "1234"],
        "farm cancel": ["farm", "cancel", "--manager", NOBODY, "1234"],
        "demo": ["demo", "--out", mine],
    }


def parser_commands(main) -> set:
    """Every command the parser offers, nested ones as "farm track"."""
    import argparse

    def names(parser, prefix=""):
        out = set()
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, sub in action.choices.items():
                    inner = names(sub, f"{prefix}{name} ")
                    out |= inner or {f"{prefix}{name}"}
        return out
    return names(main.build_parser()) - {"help"}


NAMES = sorted(commands(collections.defaultdict(str), ""))


def test_every_command_is_covered(pkg):
    assert parser_commands(pkg("addon.cli.main")) == set(NAMES)


@pytest.mark.parametrize("command", NAMES)
def test_a_failed_command_writes_nothing(pkg, inputs, tmp_path, command, monkeypatch):
    home = tmp_path / "home"
    if not command.startswith(("samples", "demo")):       # those read the MakeHuman assets cached there
        monkeypatch.setenv("ARTICULA_HOME", str(home))
    out = tmp_path / "out"
    (out / "taken").mkdir(parents=True)
    (out / "mine.txt").write_text("the user's file\n")
    before, inputs_before = _walk(out), _walk(os.path.dirname(inputs["rig"]))
    code = pkg("addon.cli.main").main(commands(inputs, str(out))[command])
    assert code != 0
    assert _walk(out) == before
    assert _walk(os.path.dirname(inputs["rig"])) == inputs_before          # inputs untouched, no cache beside
    assert not [n for _d, _s, names in os.walk(home) for n in names]


@pytest.mark.parametrize("kind", ["learn", "import"])
def test_a_failed_farm_subjects_job_keeps_the_subjects_it_finished(pkg, tmp_path, kind):
    """``farm learn``/``farm import`` write one result per subject: when one subject fails (exit 2), the others'
    results stay in ``--out-dir`` (hours of farm work)."""
    args = pkg("addon.cli.main").build_parser().parse_args(
        ["farm", kind, "--manager", NOBODY, "--subjects", str(tmp_path), "--out-dir", str(tmp_path / "rigs")])
    outputs = pkg("addon.cli.outputs")
    with outputs.kept_on_failure(outputs.output_paths(args)) as outcome:
        os.makedirs(tmp_path / "rigs")
        (tmp_path / "rigs" / "alice.blend").write_bytes(b"done")
        outcome["ok"] = False
    assert (tmp_path / "rigs" / "alice.blend").read_bytes() == b"done"
