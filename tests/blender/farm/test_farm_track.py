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
def farm(tmp_path_factory, addon):
    from articula.addon.farm import job_types
    with flamenco_local.LocalFarm(str(tmp_path_factory.mktemp("farm")), job_types.FOLDER, RUN) as f:
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
