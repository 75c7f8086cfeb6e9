"""The farm's follow-up (solver.farm.follow.FarmRun with a TrackJob) against an in-process Manager that
speaks Flamenco's REST API (tests/solver/farm/flamenco_server.py), so re-submission stays tested where
Go (and so the real Flamenco of tests/blender/farm) is missing: a failed chunk is submitted again alone,
a chunk that settled on another solution is tracked again from its neighbour's pose (TrackJob.repair,
found by the real merge), and a chunk that keeps failing is named with its log after the retries."""
import os

import numpy as np
import pytest

from articula.sample_scenes import synthetic
from articula.solver.farm import chunks as chunk_plan
from articula.solver.farm.flamenco import FarmError, Manager
from articula.solver.farm.follow import FarmRun
from articula.solver.farm.track_job import TrackJob
from articula.solver.formats.bundle import load_bundle, save_bundle, temporary_path
from articula.solver.rig.model import Poses
from articula.solver.track import merge
from .flamenco_server import Farm, Server

N = 20


@pytest.fixture(scope="module")
def model():
    return synthetic.tube_body(rings=4, segments=6)


@pytest.fixture(scope="module")
def truth(model):
    return synthetic.random_poses(N, model.skeleton.num_bones, seed=0, max_angle=0.5)


def job_of(tmp_path):
    ranges = chunk_plan.plan(N, 8, 3)                       # [(0, 8), (5, 16), (13, 20)]
    return TrackJob(str(tmp_path / "m.npz"), str(tmp_path / "rec"), "scans", ranges, str(tmp_path / "work"),
                    str(tmp_path / "out.npz"))


class Worker:
    """Tracks chunk ``k`` by writing the true poses of its frames; ``fails(job number, k)`` -> an error
    text makes the task fail; chunk ``twisted`` settles on another solution (its bones turned 90 degrees)
    unless the job starts it from an earlier chunk's pose.  ``calls``: (job number, chunk) in order."""

    def __init__(self, model, truth, fails=lambda number, k: "", twisted=None):
        self.model, self.truth, self.fails, self.twisted, self.calls = model, truth, fails, twisted, []

    def __call__(self, number, k, settings):
        self.calls.append((number, k))
        error = self.fails(number, k)
        if error:
            return error
        a, b = chunk_plan.from_text(settings["chunks"])[k]
        rot = self.truth.rotations[a:b].copy()
        started = {int(item.split(":")[0]) for item in settings["start_from"].split(",") if item}
        if k == self.twisted and k not in started:
            rot[:, 1:] = np.array([np.cos(np.pi / 4), np.sin(np.pi / 4), 0, 0])
        prov = merge.track_provenance(merge.model_digest(self.model), "scans", N, a,
                                      [f"s{f}" for f in range(a, b)], {"adapt": "off"}, False)
        path = os.path.join(settings["work_dir"], chunk_plan.file_name(k, (a, b)))
        save_bundle(path, self.model, Poses(rot, self.truth.translations[a:b], self.truth.scales[a:b]), prov)
        return ""


def follow(worker, job, retries=2):
    farm, lines = Farm(worker), []
    with Server(farm) as url:
        run = FarmRun(Manager(url, timeout=5), job, retries)
        try:
            run.wait(poll_seconds=0.0, report=lines.append)
        finally:
            run.lines = lines
    return farm, run


def test_a_failed_chunk_is_submitted_again_alone(model, truth, tmp_path):
    worker = Worker(model, truth, fails=lambda number, k: "Worker lost" if (number, k) == (1, 1) else "")
    job = job_of(tmp_path)
    farm, run = follow(worker, job)
    assert [b["settings"]["run"] for b in farm.submitted] == ["0,1,2", "1,2"]   # chunk 2 was cancelled
    assert worker.calls == [(1, 0), (1, 1), (2, 1), (2, 2)]        # chunk 0 is not tracked again
    assert run.done == {0, 1, 2} and run.jobs == ["job-1", "job-2"]
    assert any("submitted again as job job-2" in line for line in run.lines), run.lines
    np.testing.assert_array_equal(load_bundle(job.out).poses.rotations, truth.rotations)


def test_a_chunk_on_another_solution_is_tracked_again_from_its_neighbours_pose(model, truth, tmp_path):
    worker = Worker(model, truth, twisted=1)
    job = job_of(tmp_path)
    farm, run = follow(worker, job)
    assert [b["settings"]["run"] for b in farm.submitted] == ["0,1,2", "1"]
    assert farm.submitted[1]["settings"]["start_from"] == "1:0:5"    # chunk 1 from chunk 0's pose 5 (frame 5)
    assert any("chunk 1 disagreed with chunk 0" in line for line in run.lines), run.lines
    np.testing.assert_array_equal(load_bundle(job.out).poses.rotations, truth.rotations)


def test_a_chunk_that_keeps_failing_is_named_with_its_log(model, truth, tmp_path):
    worker = Worker(model, truth, fails=lambda number, k: "Traceback ...\nMemoryError: out of memory" * (k == 1))
    job = job_of(tmp_path)
    os.makedirs(job.work_dir)
    with open(temporary_path(job.out), "wb") as fh:          # what a stopped merge leaves half-written
        fh.write(b"partial")
    with pytest.raises(FarmError) as caught:
        follow(worker, job, retries=1)
    text = str(caught.value)
    assert "chunk-0001 frames 5:16 failed in 2 submissions" in text and "MemoryError: out of memory" in text
    assert f"{job.out} was not written" in text and "1 of 3 chunks done" in text
    assert not os.path.exists(job.out) and not os.path.exists(temporary_path(job.out))
    assert worker.calls == [(1, 0), (1, 1), (2, 1)]
