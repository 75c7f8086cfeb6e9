"""Farm batch on a real Flamenco: Manager and two Workers built from the Flamenco source (cached under
$ARTICULA_HOME) and run on 127.0.0.1 (tools/flamenco_local.py); tasks run this checkout's ``./run``.
A chunked tracking job of a sample depth recording, with one chunk made to fail once, against a
one-process ``./run track``; a cancelled job; a Manager without the job types.  ``./run test`` runs
these when Go >= 1.26 is present and says so when it is not (ARTICULA_FARM_TESTS=0)."""
import os
import subprocess
import sys
import time

import numpy as np
import pytest

from tests.conftest import REPO

sys.path.insert(0, os.path.join(REPO, "tools"))
import flamenco_local  # noqa: E402

REASON = flamenco_local.availability()
if os.environ.get("ARTICULA_FARM_TESTS") == "0" or REASON:
    pytest.skip(f"farm tests not run: {REASON or 'ARTICULA_FARM_TESTS=0'}", allow_module_level=True)

RUN = os.path.join(REPO, "run")
JOB_SECONDS = 600
FRAMES, CHUNK, OVERLAP = 100, 50, 45


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    from articula.sample_scenes.depth_bench import bench_recording
    return bench_recording(str(tmp_path_factory.mktemp("rec")), 1, (320, 240), FRAMES)


@pytest.fixture(scope="module")
def views(tmp_path_factory):
    """The shared storage as Linux Workers see it and as a macOS submitter would name it (two folders here,
    so a path that reached a Worker unmapped would point at the empty one)."""
    root = tmp_path_factory.mktemp("storage")
    (root / "linux").mkdir()
    (root / "mac").mkdir()
    return {"linux": str(root / "linux"), "darwin": str(root / "mac")}


@pytest.fixture(scope="module")
def farm(tmp_path_factory, addon, views):
    from articula.addon.farm import job_types
    with flamenco_local.LocalFarm(str(tmp_path_factory.mktemp("farm")), job_types.FOLDER, RUN,
                                  two_way={"storage": views}) as f:
        yield f


@pytest.fixture(scope="module")
def one_process(recording, tmp_path_factory):
    out = str(tmp_path_factory.mktemp("one") / "one.npz")
    subprocess.run([RUN, "track", "--model", recording["model_path"], "--depth", recording["out_dir"], "--out", out],
                   check=True, timeout=JOB_SECONDS, capture_output=True)
    return out


def _vertices(path):
    from articula.solver.formats.bundle import load_bundle
    from articula.solver.rig.skinning import hybrid_skin
    b = load_bundle(path)
    return hybrid_skin(b.model, b.poses), b


def _blend_contents(path):
    """(objects, actions) of a .blend the Workers wrote, read by the Blender that wrote it (``./run``'s
    primary bpy: a newer file than the bpy of this test run may read)."""
    home = os.environ.get("ARTICULA_HOME", os.path.expanduser("~/.cache/articula"))
    code = ("import bpy, sys; bpy.ops.wm.open_mainfile(filepath=sys.argv[-1]); "
            "print('OBJECTS=' + '|'.join(o.name for o in bpy.data.objects)); "
            "print('ACTIONS=' + '|'.join(a.name for a in bpy.data.actions))")
    r = subprocess.run([os.path.join(home, "venv-bpy52", "bin", "python"), "-c", code, path], capture_output=True,
                       text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    found = dict(line.split("=", 1) for line in r.stdout.splitlines() if line.startswith(("OBJECTS=", "ACTIONS=")))
    return found["OBJECTS"].split("|"), [a for a in found["ACTIONS"].split("|") if a]


def _follow(run, on_poll=lambda run, status: None):
    deadline = time.monotonic() + JOB_SECONDS
    while time.monotonic() < deadline:
        status = run.poll()
        on_poll(run, status)
        if status.job_status == "completed":
            return status
        time.sleep(1.0)
    raise AssertionError(f"the farm job did not finish in {JOB_SECONDS} s: {run.last.text}")


def test_a_chunk_that_fails_is_run_again_and_the_merge_matches_one_process(farm, recording, one_process, tmp_path):
    from articula.addon.farm.inputs import track_job
    from articula.solver.farm.flamenco import Manager
    from articula.solver.farm.follow import FarmRun
    out = str(tmp_path / "shared" / "farm.npz")
    os.makedirs(os.path.dirname(out))
    job = track_job(recording["model_path"], recording["out_dir"], "depth", out, chunk=CHUNK, overlap=OVERLAP)
    assert job.ranges == [(0, 50), (5, 100)]
    blocker = job.chunk_path(1)
    os.makedirs(blocker)                 # chunk 1 cannot write its bundle: its task fails, so does the job

    def unblock(run, status):
        if run.attempt >= 2 and os.path.isdir(blocker):
            os.rmdir(blocker)

    run = FarmRun(Manager(farm.url), job, retries=3)
    run.start()
    status = _follow(run, unblock)
    assert run.attempt >= 2 and status.unit_status == ["completed", "completed"]
    names = [t["name"] for t in run.manager.tasks(run.jobs[-1])]
    assert not any(n.startswith("chunk-0000") for n in names), names      # the done chunk was not run again
    farm_v, bundle = _vertices(out)
    one_v, _ = _vertices(one_process)
    used = bundle.provenance["report"]["merge"]["frame_chunk"]
    assert used == [0] * 49 + [1] * 51                 # causal merge: chunk 0's frames but its last one
    diff = np.linalg.norm(farm_v - one_v, axis=2).max(axis=1) * 1000
    assert diff[:49].max() < 1e-6, diff[:49].max()     # the same computation as the one process
    assert diff[49:].max() < 2.0, diff[49:].max()      # chunk 1 after 44 frames of settling
    assert not os.path.exists(out + ".tmp.npz")


def test_a_cancelled_job_writes_nothing_at_the_output(farm, recording, tmp_path):
    from articula.addon.farm.inputs import track_job
    from articula.solver.farm.flamenco import FarmError, Manager
    from articula.solver.farm.follow import FarmRun
    out = str(tmp_path / "cancelled.npz")
    run = FarmRun(Manager(farm.url), track_job(recording["model_path"], recording["out_dir"], "depth", out,
                                               chunk=CHUNK, overlap=OVERLAP))
    run.start()
    text = run.cancel()
    assert "was not written" in text
    with pytest.raises(FarmError, match="cancelled"):
        _follow(run)
    assert not os.path.exists(out) and not os.path.exists(out + ".tmp.npz")


def test_a_manager_without_the_job_types_names_the_folder(tmp_path, recording, addon):
    from articula.addon.farm.inputs import track_job
    from articula.solver.farm.flamenco import FarmError, Manager
    from articula.solver.farm.follow import FarmRun
    empty = tmp_path / "no_job_types"
    empty.mkdir()
    with flamenco_local.LocalFarm(str(tmp_path / "farm"), str(empty), RUN, workers=0) as bare:
        run = FarmRun(Manager(bare.url), track_job(recording["model_path"], recording["out_dir"], "depth",
                                                   str(tmp_path / "x.npz")))
        with pytest.raises(FarmError, match="no job type 'articula-track'.*scripts"):
            run.start()


def test_the_batch_command_refuses_an_unreachable_manager(recording, tmp_path):
    out = tmp_path / "t.npz"
    r = subprocess.run([RUN, "farm", "track", "--manager", "http://127.0.0.1:9", "--model", recording["model_path"],
                        "--depth", recording["out_dir"], "--out", str(out)], capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 2 and "unreachable" in r.stderr, r.stderr
    assert not out.exists()


def _panel_inputs(scene, farm, recording, out, **kw):
    state = scene.articula_farm
    state.manager_url, state.model, state.input_dir = farm.url, recording["model_path"], recording["out_dir"]
    state.kind, state.out, state.chunk, state.overlap = 'DEPTH', out, CHUNK, OVERLAP
    for key, value in kw.items():
        setattr(state, key, value)
    return state


def test_the_panel_submits_follows_and_bakes_into_a_blend(farm, recording, tmp_path, pkg):
    import bpy
    jobs = pkg("addon.farm.panel_jobs")
    scene, out, blend = bpy.context.scene, str(tmp_path / "panel.npz"), str(tmp_path / "panel.blend")
    state = _panel_inputs(scene, farm, recording, out, blend=blend)
    assert bpy.ops.articula.farm_submit() == {'FINISHED'}
    run = jobs.RUNS[scene.name]
    seen, deadline = set(), time.monotonic() + JOB_SECONDS
    while time.monotonic() < deadline:
        ended, error = jobs.poll_once(scene.name, run)
        seen.update(c.status for c in state.chunks)
        if ended:
            break
        time.sleep(1.0)
    assert (ended, error) == (True, "")
    assert [(c.name, c.status) for c in state.chunks] == [("chunk 1", "completed"), ("chunk 2", "completed"),
                                                         ("merge", "completed")]
    assert state.progress == 1.0 and "completed" in state.status_text and scene.name not in jobs.RUNS
    assert len(seen) > 1                                  # the rows went through other states on the way
    objects, actions = _blend_contents(blend)
    assert any("panel" in n for n in objects) and actions, (objects, actions)
    _, bundle = _vertices(out)
    assert len(bundle.poses) == FRAMES


def test_cancel_in_the_panel_stops_the_job_on_the_manager(farm, recording, tmp_path, pkg):
    import bpy
    from articula.solver.farm.flamenco import Manager
    jobs = pkg("addon.farm.panel_jobs")
    scene, out = bpy.context.scene, str(tmp_path / "panel_cancel.npz")
    _panel_inputs(scene, farm, recording, out)
    assert bpy.ops.articula.farm_submit() == {'FINISHED'}
    job = jobs.RUNS[scene.name].job_id
    assert bpy.ops.articula.farm_cancel() == {'FINISHED'}
    assert scene.name not in jobs.RUNS and "was not written" in scene.articula_farm.status_text
    deadline = time.monotonic() + 120
    while Manager(farm.url).job(job)["status"] != "canceled" and time.monotonic() < deadline:
        time.sleep(0.5)
    assert Manager(farm.url).job(job)["status"] == "canceled"
    assert not os.path.exists(out)


def test_paths_from_another_platform_reach_the_workers_through_two_way_variables(farm, recording, views):
    """A submitter on macOS names the storage /Volumes/...-like; the Manager maps it to {storage} and the
    Linux Workers get their own path."""
    from articula.solver.farm import chunks
    from articula.solver.farm.flamenco import Manager
    from articula.solver.farm.follow import FarmRun
    from articula.solver.farm.track_job import TrackJob
    os.symlink(recording["out_dir"], os.path.join(views["linux"], "rec"))
    mac = views["darwin"]
    job = TrackJob(os.path.join(mac, "rec", "model.npz"), os.path.join(mac, "rec"), "depth",
                   chunks.plan(FRAMES, CHUNK, OVERLAP), os.path.join(mac, "work"), os.path.join(mac, "mac.npz"))
    os.makedirs(os.path.join(views["linux"], "work"))
    run = FarmRun(Manager(farm.url, platform="darwin"), job, retries=0)
    run.start()
    _follow(run)
    assert os.path.isfile(os.path.join(views["linux"], "mac.npz"))          # written where Linux sees it
    assert not os.path.exists(os.path.join(mac, "mac.npz"))
    _, bundle = _vertices(os.path.join(views["linux"], "mac.npz"))
    assert len(bundle.poses) == FRAMES


def test_many_subjects_one_task_each_and_a_bad_one_is_named_with_its_log(farm, tmp_path):
    root, out = tmp_path / "people", tmp_path / "blends"
    for name, seed in (("alice", 0), ("bob", 3)):
        subprocess.run([RUN, "samples", "registered", "--poses", "3", "--seed", str(seed), "--out",
                        str(root / name)], check=True, capture_output=True, timeout=300)
    (root / "carol").mkdir()                                  # no scans: her task fails every time
    r = subprocess.run([RUN, "farm", "import", "--manager", farm.url, "--subjects", str(root), "--out-dir",
                        str(out), "--retries", "1", "--poll", "1"], capture_output=True, text=True, timeout=JOB_SECONDS)
    assert r.returncode == 2, r.stdout + r.stderr
    assert "import-scans carol failed in 2 submissions" in r.stderr and "2 of 3 subjects done" in r.stderr
    assert "carol.blend was not written" in r.stderr and "alice.blend" not in r.stderr
    assert "no scan files" in r.stderr.split("log:")[-1]            # the task's own error, from its log
    assert (out / "alice.blend").is_file() and (out / "bob.blend").is_file() and not (out / "carol.blend").exists()
    assert "alice" in _blend_contents(str(out / "alice.blend"))[0]


def test_submit_without_waiting_then_status_and_cancel_from_the_command_line(farm, recording, tmp_path):
    from articula.solver.farm.flamenco import Manager
    out = tmp_path / "later.npz"
    r = subprocess.run([RUN, "farm", "track", "--manager", farm.url, "--model", recording["model_path"], "--depth",
                        recording["out_dir"], "--out", str(out), "--chunk", str(CHUNK), "--overlap", str(OVERLAP),
                        "--no-wait"], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    job = r.stdout.split("submitted job ", 1)[1].split()[0]
    r = subprocess.run([RUN, "farm", "status", "--manager", farm.url, job], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and f"job {job}" in r.stdout and "chunk-0001 frames 5:100" in r.stdout, r.stdout
    r = subprocess.run([RUN, "farm", "cancel", "--manager", farm.url, job], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    deadline = time.monotonic() + 120
    while Manager(farm.url).job(job)["status"] != "canceled" and time.monotonic() < deadline:
        time.sleep(0.5)
    assert Manager(farm.url).job(job)["status"] == "canceled" and not out.exists()


def test_without_a_model_a_first_task_adapts_the_template_and_the_chunks_share_it(farm, recording, tmp_path):
    from articula.addon.farm.inputs import track_job
    from articula.solver.farm.flamenco import Manager
    from articula.solver.farm.follow import FarmRun
    from articula.solver.formats.bundle import load_bundle
    from articula.solver.tracking.provenance import model_digest
    out = str(tmp_path / "template.npz")
    job = track_job("", recording["out_dir"], "depth", out, chunk=CHUNK, overlap=OVERLAP)
    job.adapt_frames = 20
    run = FarmRun(Manager(farm.url), job, retries=0)
    run.start()
    _follow(run)
    names = [t["name"] for t in run.manager.tasks(run.job_id)]
    assert names.count("adapt frames 0:20") == 1 and run.prep_status == "completed", names
    assert job.model == job.adapted_model                    # a re-submission would track with it
    adapted = load_bundle(job.adapted_model)
    merged = load_bundle(out)
    assert len(merged.poses) == FRAMES and merged.model.skeleton.num_bones == adapted.model.skeleton.num_bones
    chunks = [load_bundle(job.chunk_path(k)) for k in range(2)]
    assert {c.provenance["model_sha256"] for c in chunks} == {model_digest(adapted.model)}



SCAN_FRAMES, SCAN_CHUNK, SCAN_OVERLAP = 15, 5, 2
FAST = ["--adapt", "off", "--prior", "none", "--no-temporal"]      # the capture tracker's quick settings


@pytest.fixture(scope="module")
def captures(tmp_path_factory):
    """The tube body's captures (tests/blender/track), its model bundle and a one-process ``./run track``."""
    from articula.solver.formats.bundle import save_bundle
    from articula.solver.rig.model import Poses
    from ..track.test_track import make_truth, write_captures
    root = tmp_path_factory.mktemp("captures")
    model, poses, scans = make_truth(SCAN_FRAMES, seed=2)
    person = str(root / "person.npz")
    save_bundle(person, model, Poses(poses.rotations[:3], poses.translations[:3], poses.scales[:3]))
    folder = write_captures(root / "scans", scans)
    one = str(root / "one.npz")
    subprocess.run([RUN, "track", "--model", person, "--scans", folder, "--out", one, *FAST], check=True,
                   timeout=JOB_SECONDS, capture_output=True)
    return {"model": model, "poses": poses, "person": person, "folder": folder, "one": one, "root": root}


def _track_from_a_wrong_start(captures, job, k, axis):
    """Chunk ``k`` of ``job`` on another solution, metres from the truth: tracked here from its first
    frame's true pose with the root turned half a turn about ``axis``, and, since the tracker may find its
    way back from there, every pose of the written chunk turned so about its root as well."""
    from articula.solver.formats.bundle import load_bundle, save_bundle
    from articula.solver.geometry.rotations import quat_mul, rotvec_to_quat
    from articula.solver.rig.model import Poses
    a, b = job.ranges[k]
    turn = rotvec_to_quat(np.pi * np.asarray(axis, float))
    rot = captures["poses"].rotations[a:a + 1].copy()
    rot[0, 0] = quat_mul(turn, rot[0, 0])
    wrong = str(captures["root"] / f"wrong_start_{k}.npz")
    save_bundle(wrong, captures["model"], Poses(rot, captures["poses"].translations[a:a + 1], np.ones(1)))
    subprocess.run([RUN, "track", "--model", captures["person"], "--scans", captures["folder"], "--frames",
                    f"{a}:{b}", "--start-pose", wrong, "--out", job.chunk_path(k), *FAST], check=True,
                   timeout=JOB_SECONDS, capture_output=True)
    chunk = load_bundle(job.chunk_path(k))
    chunk.poses.rotations[:, 0] = quat_mul(turn, chunk.poses.rotations[:, 0])
    save_bundle(job.chunk_path(k), chunk.model, chunk.poses, chunk.provenance)


def test_chunks_on_other_solutions_are_tracked_again_and_the_merge_matches_one_process(farm, captures, tmp_path):
    """Chunks 1 and 2 tracked on two other solutions (planted: a resumed job whose chunks 1 and 2 were
    tracked from wrong starts): each refused cut gets its later chunk tracked again from the earlier
    chunk's pose where they overlap (chunk 1, then chunk 2 from chunk 1's new pose), no job re-runs a
    merge of unchanged chunks, a repair is not one of the retries, and the job ends with the one process's
    track: a chunk tracked again goes on with the earlier chunk's pass 1 (solver.track.trail)."""
    from articula.solver.farm import chunks
    from articula.solver.farm.flamenco import Manager
    from articula.solver.farm.follow import FarmRun
    from articula.solver.farm.track_job import TrackJob
    from articula.solver.formats.bundle import load_bundle
    from articula.solver.rig.skinning import hybrid_skin
    out = str(tmp_path / "shared" / "scans.npz")
    job = TrackJob(captures["person"], captures["folder"], "scans", chunks.plan(SCAN_FRAMES, SCAN_CHUNK, SCAN_OVERLAP),
                   str(tmp_path / "shared" / "work"), out, options=list(FAST))
    assert job.ranges == [(0, 5), (3, 10), (8, 15)]
    job.prepare()
    _track_from_a_wrong_start(captures, job, 1, (0, 0, 1))
    _track_from_a_wrong_start(captures, job, 2, (1, 0, 0))
    run = FarmRun(Manager(farm.url), job, retries=1)
    run.done.update({1, 2})                           # resumed: chunks 1 and 2 are tracked already
    lines = []
    run.start()
    status = _follow(run, lambda run, status: lines.append(status.text))
    assert status.unit_status == ["completed"] * 3
    names = [[t["name"] for t in run.manager.tasks(j)] for j in run.jobs]
    assert names == [["chunk-0000 frames 0:5", "merge"], ["chunk-0001 frames 3:10", "merge"],
                     ["chunk-0002 frames 8:15", "merge"]], names
    assert job.start_from == {1: (0, 3), 2: (1, 5)}, job.start_from
    assert any("chunk 1 disagreed with chunk 0" in line for line in lines), lines
    assert any("chunk 2 disagreed with chunk 1" in line for line in lines), lines
    merged, one = load_bundle(out), load_bundle(captures["one"])
    model = captures["model"]
    diff = 1000 * np.linalg.norm(hybrid_skin(model, merged.poses) - hybrid_skin(model, one.poses), axis=2)
    assert len(merged.poses) == SCAN_FRAMES and diff.max() < 1e-6, diff.max(axis=1)
    cuts = merged.provenance["report"]["merge"]["cuts"]
    assert [c["frame"] for c in cuts] == [4, 9] and max(c["pass1_mm"] for c in cuts) < 1e-6, cuts
