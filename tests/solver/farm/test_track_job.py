"""The tracking job's settings and its repair of a chunk that started on another solution
(solver.farm.track_job), on synthetic tracked chunks written as real bundles."""
import numpy as np
import pytest

from articula.sample_scenes import synthetic
from articula.solver.errors import ArticulaInputError
from articula.solver.farm.track_job import TrackJob
from articula.solver.formats.bundle import save_bundle
from articula.solver.rig.model import Poses
from articula.solver.tracking.provenance import model_digest, track_provenance

N = 20


@pytest.fixture(scope="module")
def model():
    return synthetic.tube_body(rings=4, segments=6)


def write_chunks(model, job, twisted=None):
    """Save each chunk of ``job`` as a tracked bundle of one motion; chunk ``twisted`` gets its arms'
    rotations turned by 90 degrees (another solution)."""
    poses = synthetic.random_poses(N, model.skeleton.num_bones, seed=0, max_angle=0.5)
    digest = model_digest(model)
    for k, (a, b) in enumerate(job.ranges):
        rot = poses.rotations[a:b].copy()
        if k == twisted:
            rot[:, 1:] = np.array([np.cos(np.pi / 4), np.sin(np.pi / 4), 0, 0])
        prov = track_provenance(digest, "scans", N, a, [f"s{f}" for f in range(a, b)], {"adapt": "off"}, False)
        save_bundle(job.chunk_path(k), model, Poses(rot, poses.translations[a:b], poses.scales[a:b]), prov)


def job_of(tmp_path, kind="scans"):
    return TrackJob(str(tmp_path / "m.npz"), str(tmp_path / "rec"), kind, [(0, 12), (8, 20)], str(tmp_path),
                    str(tmp_path / "out.npz"))


def test_a_chunk_on_another_solution_is_tracked_again_from_its_neighbours_pose(model, tmp_path):
    job = job_of(tmp_path)
    write_chunks(model, job, twisted=1)
    done = {0, 1}
    text = job.repair(done)
    assert "chunk 1 disagreed with chunk 0" in text
    assert job.start_from == {1: (0, 8)} and done == {0}
    assert job.body([1])["settings"]["start_from"] == "1:0:8"
    with pytest.raises(ArticulaInputError, match="chunk 1 still disagrees with chunk 0 on frame 10 by .* after it "
                                                 "was tracked again from chunk 0's pose at frame 8"):
        job.repair({0, 1})                       # started from its neighbour already: no second repair


def test_a_chunk_started_from_a_neighbour_that_changed_since_may_be_repaired_again(model, tmp_path):
    job = TrackJob(str(tmp_path / "m.npz"), str(tmp_path / "rec"), "scans", [(0, 8), (5, 14), (11, 20)],
                   str(tmp_path), str(tmp_path / "out.npz"))
    write_chunks(model, job, twisted=2)
    assert "chunk 2 disagreed with chunk 1" in job.repair({0, 1, 2}) and job.tracked_in == {2: 1}
    job.start_from[1], job.tracked_in[1] = (0, 5), 2          # chunk 1 tracked again after chunk 2 was
    job.repairs = 2
    assert "chunk 2 disagreed with chunk 1" in job.repair({0, 1, 2}) and job.tracked_in == {1: 2, 2: 3}
    job.tracked_in[1] = 4
    with pytest.raises(ArticulaInputError, match="still disagrees .* after 3 repair round"):
        job.repair({0, 1, 2})


def test_a_later_cut_waits_while_its_earlier_chunk_is_tracked_again(model, tmp_path):
    job = TrackJob(str(tmp_path / "m.npz"), str(tmp_path / "rec"), "scans", [(0, 8), (5, 14), (11, 20)],
                   str(tmp_path), str(tmp_path / "out.npz"))
    write_chunks(model, job, twisted=1)                        # cuts 0|1 and 1|2 both disagree
    done = {0, 1, 2}
    text = job.repair(done)
    assert "chunk 1 disagreed with chunk 0" in text and "chunk 2" not in text
    assert job.start_from == {1: (0, 5)} and done == {0, 2}


def test_agreeing_chunks_and_depth_chunks_are_not_repaired(model, tmp_path):
    job = job_of(tmp_path)
    write_chunks(model, job)
    assert job.repair({0, 1}) == "" and job.start_from == {}
    depth = job_of(tmp_path, "depth")
    write_chunks(model, depth, twisted=1)
    assert depth.repair({0, 1}) == ""                    # the depth tracker takes no start pose


def test_the_job_carries_every_path_as_its_own_setting(tmp_path):
    settings = job_of(tmp_path).body([0, 1])["settings"]
    assert settings["chunks"] == "0:12,8:20" and settings["run"] == "0,1" and settings["agree_mm"] == 1.0
    assert job_of(tmp_path, "depth").body([0])["settings"]["agree_mm"] == 100.0     # depth: the merge's default
    many = TrackJob("m.npz", "rec", "scans", [(10 * k, 10 * k + 14) for k in range(8)], str(tmp_path), "o.npz")
    assert job_of(tmp_path).max_repairs == 3 and many.max_repairs == 7     # enough rounds to go front to back
    for key in ("model", "input", "work_dir", "out"):        # two-way variables map whole settings only
        assert settings[key].startswith(str(tmp_path))
    assert job_of(tmp_path).body([])["settings"]["run"] == "none"
