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
from articula.solver.tracking.provenance import model_digest, track_provenance
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
    text makes the task fail; the chunks in ``twisted`` settle on another solution (their bones turned
    by k x 45 degrees: each its own) unless the job starts them from an earlier chunk's pose (or always,
    when ``stubborn``).  ``calls``: (job number, chunk) in order."""

    def __init__(self, model, truth, fails=lambda number, k: "", twisted=(), stubborn=False):
        self.model, self.truth, self.fails, self.calls = model, truth, fails, []
        self.twisted, self.stubborn = set(twisted), stubborn

    def __call__(self, number, k, settings):
        self.calls.append((number, k))
        error = self.fails(number, k)
        if error:
            return error
        a, b = chunk_plan.from_text(settings["chunks"])[k]
        rot = self.truth.rotations[a:b].copy()
        started = {int(item.split(":")[0]) for item in settings["start_from"].split(",") if item}
        if k in self.twisted and (k not in started or self.stubborn):
            rot[:, 1:] = np.array([np.cos(k * np.pi / 8), np.sin(k * np.pi / 8), 0, 0])
        prov = track_provenance(model_digest(self.model), "scans", N, a,
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
    worker = Worker(model, truth, twisted={1})
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


def test_two_chunks_on_other_solutions_are_repaired_in_turn_and_repairs_are_not_retries(model, truth, tmp_path):
    """Chunks 1 and 2 each on their own solution: chunk 1 is tracked again from chunk 0, then chunk 2 from
    chunk 1's new pose; with no retries for failed tasks (repairs are bounded on their own)."""
    worker = Worker(model, truth, twisted={1, 2})
    job = job_of(tmp_path)
    farm, run = follow(worker, job, retries=0)
    assert [b["settings"]["run"] for b in farm.submitted] == ["0,1,2", "1", "2"]
    assert farm.submitted[2]["settings"]["start_from"] == "1:0:5,2:1:8"
    assert worker.calls == [(1, 0), (1, 1), (1, 2), (2, 1), (3, 2)]
    assert job.repairs == 2 and run.repairs == 2
    np.testing.assert_array_equal(load_bundle(job.out).poses.rotations, truth.rotations)


def test_a_cut_that_still_disagrees_after_its_repair_stops_the_job_without_the_same_merge_again(model, truth,
                                                                                               tmp_path):
    """Chunk 1 lands on its other solution even when started from chunk 0's pose: after that one repair
    the job stops with a line saying so (no merge of the same chunks submitted again), nothing written."""
    worker = Worker(model, truth, twisted={1}, stubborn=True)
    job = job_of(tmp_path)
    with pytest.raises(FarmError) as caught:
        follow(worker, job, retries=2)
    text = str(caught.value)
    assert "chunk 1 still disagrees with chunk 0 on frame" in text, text
    assert "after it was tracked again from chunk 0's pose at frame 5" in text and "--agree 0" in text, text
    assert f"{job.out} was not written" in text and "3 of 3 chunks done" in text, text
    assert worker.calls == [(1, 0), (1, 1), (1, 2), (2, 1)]          # two jobs: the repair, then no more
    assert not os.path.exists(job.out)


def test_a_merge_that_fails_for_another_reason_is_not_submitted_again(model, truth, tmp_path):
    """Every chunk tracked and on one solution, yet the merge fails (here: the output's folder is a file):
    re-running the same merge would fail the same way, so the job stops after it, naming its log."""
    job = job_of(tmp_path)
    job.out = str(tmp_path / "blocked" / "out.npz")
    (tmp_path / "blocked").write_text("a file where the output's folder should be")
    worker = Worker(model, truth)
    with pytest.raises(FarmError, match="merge failed with every chunk done .*not submitted again") as caught:
        farm, _ = follow(worker, job, retries=2)
    assert "3 of 3 chunks done" in str(caught.value)
    assert worker.calls == [(1, 0), (1, 1), (1, 2)]
