"""The batch commands ``track`` and ``merge-tracks``: the tracked bundle (model, one pose per frame in the
files' coordinates, provenance), the report, the .blend with the scans and the rig over them, chunks
merged against one run, the same through ``batch.py``, and bad input (exit code 2, one line, nothing
written).  Data: the tube body captures of test_track.py; the real pipeline with its fast settings."""
import json
import os
import re
import subprocess
import sys

import bpy
import numpy as np
import pytest

from articula.solver.formats.bundle import load_bundle, save_bundle
from articula.solver.geometry.surface_distance import distance_to_surface
from articula.solver.rig.model import Model, Poses, Skeleton
from articula.solver.rig.skinning import hybrid_skin
from articula.solver.tracking.provenance import model_digest
from ...conftest import REPO
from .test_track import make_truth, write_captures

pytestmark = pytest.mark.usefixtures("cache_home")   # a fresh ARTICULA_HOME per test

FAST = ["--adapt", "off", "--prior", "none", "--no-temporal"]
N = 6


@pytest.fixture(scope="module")
def truth():
    return make_truth(N, seed=2)


@pytest.fixture
def files(tmp_path, truth):
    """(model bundle path, captures folder)."""
    model, poses, captures = truth
    path = str(tmp_path / "person.npz")
    save_bundle(path, model, Poses(poses.rotations[:3], poses.translations[:3], poses.scales[:3]))
    return path, write_captures(tmp_path / "scans", captures)


def surface_mm(model, poses, captures, first=0):
    posed = hybrid_skin(model, poses)
    return np.array([np.median(1000 * distance_to_surface(captures[first + k][0], posed[k], model.faces))
                     for k in range(len(poses))])


def test_track_writes_bundle_report_and_blend(pkg, tmp_path, truth, files):
    model, poses, captures = truth
    path, folder = files
    out, rep, blend = (str(tmp_path / "o" / n) for n in ("t.npz", "t.json", "t.blend"))
    os.makedirs(tmp_path / "o")
    assert pkg("addon.cli.main").main(["track", "--model", path, "--scans", folder, "--out", out, "--report", rep,
                                       "--blend", blend, *FAST]) == 0
    bundle = load_bundle(out)
    assert len(bundle.poses) == N and list(bundle.model.skeleton.names) == list(model.skeleton.names)
    np.testing.assert_allclose(bundle.model.rest_vertices, model.rest_vertices)       # not adapted: as given
    assert np.all(surface_mm(bundle.model, bundle.poses, captures) < 3.0)            # the files' coordinates
    prov = bundle.provenance
    assert prov["frame_names"] == [f"scan_{k:02d}.ply" for k in range(N)] and prov["first_frame"] == 0
    assert prov["model_sha256"] == model_digest(model) and prov["options"]["adapt"] == "off"
    doc = json.load(open(rep))
    assert len(doc["frames"]) == N and {"mean_mm", "median_mm", "mad_mm", "iqr_mm"} <= set(doc["frames"][0])
    assert doc["lost_frames"] == [] and doc["timings_s"] and doc["model"]["training_poses"] == 3
    assert os.path.isfile(blend)
    bpy.ops.wm.open_mainfile(filepath=blend)
    kinds = sorted(o.articula.kind for o in bpy.data.objects)
    assert kinds.count('SCAN_SEQUENCE') == 1 and kinds.count('RIG_ARMATURE') == 1
    arm = next(o for o in bpy.data.objects if o.articula.kind == 'RIG_ARMATURE')
    scans = next(o for o in bpy.data.objects if o.articula.kind == 'SCAN_SEQUENCE')
    assert tuple(arm.animation_data.action.frame_range) == (1, N)
    assert scans["articula_track_errors"].startswith("//t_articula/")
    bpy.context.scene.frame_set(3)
    assert len(scans.data.attributes["articula_error_mm"].data) == len(captures[2][0])


def test_chunks_merge_to_one_run(pkg, tmp_path, truth, files, capsys):
    """Frames 0:4 and 2:6 tracked separately and merged give one run's poses within the solver's tolerance
    (vertices within 5 mm, about twice each run's own worst error against the truth with 1 mm noise), each
    shared frame from the chunk where it lies further from the cut."""
    model, poses, captures = truth
    path, folder = files
    cli = pkg("addon.cli.main")
    outs = {name: str(tmp_path / f"{name}.npz") for name in ("all", "a", "b", "merged")}
    assert cli.main(["track", "--model", path, "--scans", folder, "--out", outs["all"], *FAST]) == 0
    assert cli.main(["track", "--model", path, "--scans", folder, "--frames", "0:4", "--out", outs["a"], *FAST]) == 0
    assert cli.main(["track", "--model", path, "--scans", folder, "--frames", "2:", "--out", outs["b"], *FAST]) == 0
    rep = str(tmp_path / "merge.json")
    capsys.readouterr()
    assert cli.main(["merge-tracks", outs["b"], outs["a"], "--out", outs["merged"], "--report", rep]) == 0
    assert "frames 0..5 from 2 chunks" in capsys.readouterr().out
    one, merged = load_bundle(outs["all"]), load_bundle(outs["merged"])
    assert len(merged.poses) == N and merged.provenance["frame_names"] == one.provenance["frame_names"]
    doc = json.load(open(rep))
    assert doc["frame_chunk"] == [0, 0, 0, 1, 1, 1]     # frame 2: 1 from a's end, 0 from b's start; 3: 0 and 1
    gap = 1000 * np.linalg.norm(hybrid_skin(model, merged.poses) - hybrid_skin(model, one.poses), axis=2)
    assert gap.max() < 5.0 and gap.mean() < 2.0
    chunk_b = load_bundle(outs["b"])
    np.testing.assert_array_equal(merged.poses.rotations[3:], chunk_b.poses.rotations[1:])
    assert doc["overlaps"][0]["frames"] == [2, 4]


def test_bad_input(pkg, tmp_path, truth, files, capsys):
    path, folder = files
    cli = pkg("addon.cli.main")
    out = str(tmp_path / "t.npz")
    cases = [
        (["--model", str(tmp_path / "none.npz"), "--scans", folder], "none.npz: no such bundle file"),
        (["--model", path, "--scans", str(tmp_path / "nothing")], "nothing: file or folder not found"),
        (["--model", path, "--scans", folder, "--frames", "2-5"], "--frames: expected A:B"),
        (["--model", path, "--scans", folder, "--frames", "3:99"], f"--frames 3:99: the input has {N} frames"),
        (["--model", path, "--scans", folder, "--frames", "5:5"], "--frames 5:5: expected 0 <= A < B"),
        (["--model", path, "--scans", folder, "--max-points", "20"], "--max-points: 20 is too few"),
        (["--model", path, "--scans", folder, "--report", str(tmp_path / "no" / "r.json")], "does not exist"),
    ]
    for args, message in cases:
        assert cli.main(["track", *args, "--out", out, *FAST]) == 2, args
        err = capsys.readouterr().err
        assert message in err, (args, err)
    pts = tmp_path / "points"
    pts.mkdir()
    np.save(pts / "p0.npy", np.zeros((10, 3)))
    assert cli.main(["track", "--model", path, "--scans", str(pts), "--out", out, "--blend",
                     str(tmp_path / "b.blend")]) == 2
    assert "--blend shows mesh scans" in capsys.readouterr().err
    assert not os.path.exists(out)
    assert cli.main(["merge-tracks", path, path, "--out", out]) == 2
    assert "person.npz: not a tracked bundle" in capsys.readouterr().err


def test_start_pose_of_a_tracked_bundle_goes_on_with_its_pass_1(pkg, tmp_path, truth, files, capsys):
    """``--start-pose TRACKED.npz:K`` of a bundle ``track`` wrote with the same model and captures: pass 1
    goes on from the state it left after frame K (the note says so) and repeats its frames exactly; the
    same bundle at a frame that is not this run's first, or tracked with another model, is a start pose."""
    model, poses, captures = truth
    path, folder = files
    cli = pkg("addon.cli.main")
    whole, part = str(tmp_path / "whole.npz"), str(tmp_path / "part.npz")
    assert cli.main(["track", "--model", path, "--scans", folder, "--out", whole, *FAST]) == 0
    assert {"pass1_last", "pass1_held"} <= set(load_bundle(whole).extra)
    capsys.readouterr()
    assert cli.main(["track", "--model", path, "--scans", folder, "--frames", "2:", "--start-pose", f"{whole}:2",
                     "--out", part, *FAST]) == 0
    assert "went on from the state another run left after input frame 2" in capsys.readouterr().out
    np.testing.assert_array_equal(load_bundle(part).poses.rotations, load_bundle(whole).poses.rotations[2:])
    assert cli.main(["track", "--model", path, "--scans", folder, "--frames", "1:", "--start-pose", f"{whole}:2",
                     "--out", part, *FAST]) == 0
    assert "went on" not in capsys.readouterr().out
    moved = str(tmp_path / "moved.npz")
    save_bundle(moved, Model(model.rest_vertices + 0.001, model.faces, model.skeleton, model.anchor,
                             model.twist_weights, model.swing_weights), poses)
    assert cli.main(["track", "--model", moved, "--scans", folder, "--frames", "2:", "--start-pose", f"{whole}:2",
                     "--out", part, *FAST]) == 0
    assert "went on" not in capsys.readouterr().out


def test_model_without_poses_says_generic_prior(pkg, tmp_path, truth, monkeypatch, capsys):
    """The note of the tracker (generic prior for a model without poses) is printed; the stub stands in for
    the tracker (the generic prior itself is the solver's to test)."""
    from .test_track import StubTracker
    model, poses, captures = truth
    path = str(tmp_path / "bare.npz")
    save_bundle(path, model)
    folder = write_captures(tmp_path / "scans", captures)
    note = "pose prior: the generic human prior (the model has fewer than 3 poses of its own)"
    tracker = StubTracker(pkg, model, poses, notes=[note])
    monkeypatch.setattr(pkg("addon.track.solve"), "track_sequence", tracker)
    assert pkg("addon.cli.main").main(["track", "--model", path, "--scans", folder, "--out",
                                       str(tmp_path / "t.npz")]) == 0
    assert tracker.calls[0]["training_poses"] is None
    assert f"bare.npz: {note}" in capsys.readouterr().out


def test_batch_py_track(tmp_path, files):
    """``python batch.py track ...`` in a fresh process: exit 0 and the bundle; bad --frames: exit 2."""
    path, folder = files
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "user"), ARTICULA_HOME=str(tmp_path / "home"))

    def run(*args):
        return subprocess.run([sys.executable, os.path.join(REPO, "batch.py"), "track", "--model", path, "--scans",
                               folder, *args, *FAST], capture_output=True, text=True, env=env, timeout=600)
    out = str(tmp_path / "t.npz")
    res = run("--frames", "1:4", "--out", out)
    assert res.returncode == 0, res.stderr[-2000:]
    assert len(load_bundle(out).poses) == 3 and "3 frames tracked (input frames 1..3)" in res.stdout
    res = run("--frames", "x", "--out", str(tmp_path / "u.npz"))
    assert res.returncode == 2 and res.stderr.strip().splitlines()[-1].startswith("articula track: error: --frames")


def test_start_pose_from_a_bundle(pkg, tmp_path, truth, files, monkeypatch, capsys):
    """``--start-pose B.npz:K``: the tracker starts the first tracked frame from pose K of B (checked on
    what it receives) and the report says so; a bundle with other bones, a pose number past its poses and a
    missing file are refused before any tracking, naming the flag."""
    model, poses, captures = truth
    path, folder = files
    start = str(tmp_path / "start.npz")
    save_bundle(start, model, poses)
    solve = pkg("addon.track.solve")
    real, seen = solve.track_sequence, []

    def recording(*args, **kwargs):
        seen.append(kwargs.get("start_pose"))
        return real(*args, **kwargs)

    monkeypatch.setattr(solve, "track_sequence", recording)
    cli = pkg("addon.cli.main")
    out, rep = str(tmp_path / "t.npz"), str(tmp_path / "t.json")
    assert cli.main(["track", "--model", path, "--scans", folder, "--frames", "2:4", "--start-pose", f"{start}:2",
                     "--out", out, "--report", rep, *FAST]) == 0
    np.testing.assert_array_equal(seen[0].rotations, poses.rotations[2:3])
    assert json.load(open(rep))["input"]["start"] == "pose 2 of start.npz"
    assert np.all(surface_mm(model, load_bundle(out).poses, captures, first=2) < 3.0)
    other = str(tmp_path / "other.npz")
    sk = model.skeleton
    renamed = Skeleton([f"{n}_x" for n in sk.names], sk.parents, sk.heads, sk.tails, sk.frames)
    save_bundle(other, Model(model.rest_vertices, model.faces, renamed, model.anchor, model.twist_weights,
                             model.swing_weights), poses)
    for spec, message in ((f"{other}:1", "--start-pose: .*other.npz has other bones than the model"),
                          (f"{start}:9", f"--start-pose: .*start.npz has {N} pose\\(s\\); pose 9 asked for"),
                          (str(tmp_path / "none.npz"), "--start-pose: .*none.npz: no such bundle file")):
        seen.clear()
        capsys.readouterr()
        assert cli.main(["track", "--model", path, "--scans", folder, "--start-pose", spec, "--out", out, *FAST]) == 2
        assert re.search(message, capsys.readouterr().err), spec
        assert not seen


def test_merge_refuses_chunks_that_disagree_by_default(pkg, tmp_path, capsys):
    """Chunks half a metre apart where the merge switches: refused by default (exit 2, the frame and both
    files named, how to accept it), nothing written; ``--agree 0`` accepts the same chunks."""
    from ...solver.track.test_merge import chunk, truth_poses
    from articula.sample_scenes import synthetic
    model = synthetic.tube_body(rings=4, segments=6)
    poses = truth_poses(model, 12)
    shifted = Poses(poses.rotations, poses.translations + [0.5, 0, 0], poses.scales)
    paths = {}
    for name, c in (("early.npz", chunk(model, poses, 0, 8, "early")),
                    ("late.npz", chunk(model, shifted, 5, 12, "late"))):
        paths[name] = str(tmp_path / name)
        save_bundle(paths[name], c.model, c.poses, c.provenance)
    cli, out, rep = pkg("addon.cli.main"), str(tmp_path / "m.npz"), str(tmp_path / "m.json")
    capsys.readouterr()
    assert cli.main(["merge-tracks", paths["early.npz"], paths["late.npz"], "--out", out, "--report", rep]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert re.search(r"early\.npz and late\.npz disagree on frame [67] by 500 mm", err), err
    assert "--agree 0" in err
    assert sorted(os.listdir(tmp_path)) == ["early.npz", "home", "late.npz"] or \
        sorted(os.listdir(tmp_path)) == ["early.npz", "late.npz"]
    assert cli.main(["merge-tracks", paths["early.npz"], paths["late.npz"], "--out", out, "--agree", "0"]) == 0
    assert len(load_bundle(out).poses) == 12
    assert cli.main(["merge-tracks", paths["early.npz"], paths["late.npz"], "--out", out, "--agree", "-1"]) == 2
    assert "--agree: expected millimetres >= 0" in capsys.readouterr().err
