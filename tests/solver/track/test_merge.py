"""Joining tracked chunks (solver.track.merge): the frame choice against a brute-force reference, the
merged poses and report on synthetic chunks, bundle files round trip, and every refusal."""
import itertools

import numpy as np
import pytest

from articula.sample_scenes import synthetic
from articula.solver.errors import ArticulaInputError
from articula.solver.formats.bundle import load_bundle, save_bundle
from articula.solver.rig.model import Poses
from articula.solver.track import merge
from articula.solver.tracking.provenance import model_digest, track_provenance

N = 20


@pytest.fixture(scope="module")
def model():
    return synthetic.tube_body(rings=4, segments=6)


def truth_poses(model, n=N, seed=0):
    return synthetic.random_poses(n, model.skeleton.num_bones, seed=seed, max_angle=0.5)


def chunk(model, poses, a, b, name, noise=0.0, seed=1, options=None, digest=None, names=None):
    """Frames a..b-1 of ``poses`` as a tracked chunk, rotations perturbed by ``noise`` radians (renormalised)."""
    rng = np.random.default_rng(seed)
    rot = poses.rotations[a:b].copy()
    if noise:
        rot += noise * rng.normal(size=rot.shape)
        rot /= np.linalg.norm(rot, axis=-1, keepdims=True)
    part = Poses(rot, poses.translations[a:b].copy(), poses.scales[a:b].copy())
    names = names or [f"scan_{k:04d}.ply" for k in range(len(poses))]
    prov = track_provenance(digest or model_digest(model), "scans", len(poses), a, names[a:b],
                                  options or {"adapt": "off", "window": 11}, False,
                                  {"frames": [{"name": names[k], "lost": k == 13, "skipped": False}
                                              for k in range(a, b)]})
    return merge.TrackChunk(name, model, part, prov)


def brute_force_choice(ranges, lo, hi):
    out = []
    for f in range(lo, hi):
        best, score = None, None
        for i, (a, b) in enumerate(ranges):
            if not a <= f < b:
                continue
            cuts = [f - a] * (a > lo) + [b - 1 - f] * (b < hi)
            d = min(cuts) if cuts else float("inf")
            if score is None or d > score:
                best, score = i, d
        out.append(best)
    return out


def test_frame_choice_matches_brute_force():
    rng = np.random.default_rng(3)
    for _ in range(200):
        cuts = np.sort(rng.choice(np.arange(2, 40), size=rng.integers(1, 4), replace=False))
        starts = [0] + [int(c - rng.integers(1, 4)) for c in cuts]
        ends = [int(c) for c in cuts] + [45]
        ranges = list(zip(starts, ends))
        got = merge.choose_frames(ranges, 0, 45)
        assert got.tolist() == brute_force_choice(ranges, 0, 45), ranges


def test_overlap_frames_come_from_the_chunk_further_from_the_cut(model):
    """Chunks 0:12 and 8:20: frames 8, 9 are 3 and 2 frames from A's end but 0 and 1 from B's start, so
    they come from A; frames 10, 11 from B.  Every merged pose is the chosen chunk's pose exactly."""
    gt = truth_poses(model)
    a, b = chunk(model, gt, 0, 12, "a.npz", 0.01, 1), chunk(model, gt, 8, 20, "b.npz", 0.01, 2)
    got = merge.merge_chunks([b, a])                                  # any order
    assert got.report["frame_chunk"] == [0] * 10 + [1] * 10
    np.testing.assert_array_equal(got.poses.rotations[:10], a.poses.rotations[:10])
    np.testing.assert_array_equal(got.poses.rotations[10:], b.poses.rotations[2:])
    np.testing.assert_array_equal(got.poses.translations, gt.translations)
    assert len(got.poses) == N and got.provenance["first_frame"] == 0
    assert got.provenance["frame_names"] == [f"scan_{k:04d}.ply" for k in range(N)]
    assert [c["used"] for c in got.report["chunks"]] == [10, 10]
    (overlap,) = got.report["overlaps"]
    assert overlap["frames"] == [8, 12] and overlap["max_rotation_deg"] > 0
    assert got.report["lost"] == [13]                                 # from the chunks' per-frame rows
    assert [r["name"] for r in got.report["frame_rows"]] == got.provenance["frame_names"]


def test_a_frame_comes_from_the_chunk_whose_temporal_window_is_a_single_runs(model):
    """Chunks 0:10 and 4:14 (window 5, step 2): a single run over 0:14 takes frame 6 from window 4..8
    and frame 8 from 6..10.  Frame 6 lies nearer chunk A's end, but A took it from its end window 5..9
    and B from 4..8, so it comes from B; frame 8 is B's by the cut rule and stays there though neither
    chunk has its window; the other frames keep the cut rule's chunk."""
    gt = truth_poses(model, 14)
    options = {"adapt": "off", "temporal": True, "window": 5, "step": 2}
    a, b = chunk(model, gt, 0, 10, "a.npz", options=options), chunk(model, gt, 4, 14, "b.npz", options=options)
    single = {0: [0, 4], 1: [0, 4], 2: [0, 4], 3: [0, 4], 4: [2, 6], 5: [2, 6], 6: [4, 8], 7: [4, 8],
              8: [6, 10], 9: [8, 12], 10: [8, 12], 11: [9, 13], 12: [9, 13], 13: [9, 13]}
    for f, row in enumerate(a.provenance["report"]["frames"]):
        row["window"] = single[f] if f <= 5 else [5, 9]
    for f, row in enumerate(b.provenance["report"]["frames"], start=4):
        row["window"] = [4, 8] if f <= 6 else [5, 9] if f == 8 else single[f]
    cut_rule = merge.choose_frames([(0, 10), (4, 14)], 0, 14)
    assert cut_rule.tolist() == [0] * 7 + [1] * 7
    got = merge.merge_chunks([a, b])
    assert got.report["frame_chunk"] == [0] * 6 + [1] * 8
    for c in (a, b):
        c.provenance["options"].pop("step")              # without the windows' step: the cut rule alone
    assert merge.merge_chunks([a, b]).report["frame_chunk"] == cut_rule.tolist()


def test_three_chunks_inside_a_longer_input(model):
    """Chunks 4:11, 9:16, 14:20 of a 20-frame input: the merged range starts at 4, and identical chunk
    poses give the truth back."""
    gt = truth_poses(model)
    parts = [chunk(model, gt, a, b, f"c{a}.npz") for a, b in ((4, 11), (9, 16), (14, 20))]
    got = merge.merge_chunks(parts)
    assert got.provenance["first_frame"] == 4 and len(got.poses) == 16
    np.testing.assert_allclose(got.poses.rotations, gt.rotations[4:], atol=1e-12)
    assert got.report["frame_chunk"] == brute_force_choice([(4, 11), (9, 16), (14, 20)], 4, 20)
    assert got.report["overlaps"][0]["max_rotation_deg"] < 1e-4


def test_bundle_files_round_trip(model, tmp_path):
    gt = truth_poses(model)
    paths = []
    for c in (chunk(model, gt, 0, 12, "a"), chunk(model, gt, 9, 20, "b")):
        paths.append(str(tmp_path / f"{c.name}.npz"))
        save_bundle(paths[-1], c.model, c.poses, c.provenance)
    got = merge.merge_chunks(merge.load_chunks(paths))
    out = str(tmp_path / "merged.npz")
    save_bundle(out, got.model, got.poses, got.provenance)
    again = merge.chunk_from_bundle(load_bundle(out), "merged.npz")
    assert (again.start, again.end) == (0, N)
    np.testing.assert_allclose(again.poses.rotations, gt.rotations, atol=1e-12)
    assert again.provenance["model_sha256"] == model_digest(model)


@pytest.mark.parametrize("case, message", [
    ("one", "1 chunk given; merging needs at least two"),
    ("model", "were tracked with different models"),
    ("options", r"different options \(window\)"),
    ("gap", "frames 10:12 are missing between them"),
    ("touching", "do not overlap; track chunks with a few frames in common"),
    ("inside", "one chunk lies inside the other"),
    ("names", "input frame 8 is 'scan_0008.ply' in one and 'other.ply' in the other"),
    ("not_tracked", "not a tracked bundle"),
])
def test_refusals(model, case, message):
    gt = truth_poses(model)
    a = chunk(model, gt, 0, 10 if case in ("gap", "touching") else 12, "a.npz")
    b = chunk(model, gt, 8, 20, "b.npz")
    if case == "one":
        chunks = [a]
    elif case == "model":
        chunks = [a, chunk(model, gt, 8, 20, "b.npz", digest="0" * 64)]
    elif case == "options":
        chunks = [a, chunk(model, gt, 8, 20, "b.npz", options={"adapt": "off", "window": 9})]
    elif case == "gap":
        chunks = [a, chunk(model, gt, 12, 20, "b.npz")]
    elif case == "touching":
        chunks = [a, chunk(model, gt, 10, 20, "b.npz")]
    elif case == "inside":
        chunks = [a, chunk(model, gt, 2, 9, "b.npz")]
    elif case == "names":
        names = [f"scan_{k:04d}.ply" for k in range(N)]
        names[8] = "other.ply"
        chunks = [a, chunk(model, gt, 8, 20, "b.npz", names=names)]
    else:
        bundle = type("B", (), {"provenance": {"source": "learn_rig"}, "poses": b.poses, "model": model})
        with pytest.raises(ArticulaInputError, match=message):
            merge.chunk_from_bundle(bundle, "b.npz")
        return
    with pytest.raises(ArticulaInputError, match=message):
        merge.merge_chunks(chunks)


def test_every_split_of_identical_chunks_gives_the_whole(model):
    """Any two overlapping chunks cut from the same poses merge back to exactly those poses."""
    gt = truth_poses(model, 12)
    for cut, overlap in itertools.product(range(2, 10), range(1, 3)):
        got = merge.merge_chunks([chunk(model, gt, 0, cut + overlap, "a"), chunk(model, gt, cut, 12, "b")])
        np.testing.assert_array_equal(got.poses.rotations, gt.rotations)


def test_cut_differences_are_the_posed_vertex_distance_where_the_merge_switches(model):
    from articula.solver.rig.skinning import hybrid_skin
    poses = truth_poses(model)
    a, b = chunk(model, poses, 0, 12, "a.npz"), chunk(model, poses, 8, N, "b.npz", noise=0.05, seed=4)
    merged = merge.merge_chunks([a, b])
    (cut,) = merged.report["cuts"]
    f = cut["frame"]
    assert merged.report["frame_chunk"][f - 1] == 0 and merged.report["frame_chunk"][f] == 1
    va = hybrid_skin(model, a.poses.take(f))[0]                 # brute force on the switch frame
    vb = hybrid_skin(model, b.poses.take(f - 8))[0]
    assert cut["max_vertex_mm"] == pytest.approx(1000 * np.linalg.norm(va - vb, axis=1).max())
    assert cut["max_vertex_mm"] > 1.0
    with pytest.raises(ArticulaInputError, match=r"a.npz and b.npz disagree on frame \d+ .*--start-pose a.npz:8"):
        merge.merge_chunks([a, b], agree_mm=cut["max_vertex_mm"] - 0.01)
    assert merge.merge_chunks([a, b], agree_mm=cut["max_vertex_mm"] + 0.01).report["cuts"] == [cut]


def _with_pass1(c, poses):
    """``c`` with a pass-1 record whose poses are ``poses`` (its frames)."""
    from articula.solver.track.trail import Trail
    trail = Trail(len(c.poses), c.model.skeleton.num_bones)
    for k in range(len(c.poses)):
        trail.record(k, [poses.take([c.start + k])], [1.0], False)
    c.pass1 = trail.arrays()
    return c


def test_chunks_disagree_by_their_pass_1_poses_when_both_have_them(model):
    """With pass-1 records a cut is judged by the pass-1 poses: the same pass 1 (a chunk resumed from the
    other) agrees under any threshold though the final poses differ; another pass 1 is measured by brute
    force, and named in the message."""
    from articula.solver.rig.skinning import hybrid_skin
    poses = truth_poses(model)
    a = _with_pass1(chunk(model, poses, 0, 12, "a.npz"), poses)
    b = _with_pass1(chunk(model, poses, 8, N, "b.npz", noise=0.05, seed=4), poses)
    (cut,) = merge.merge_chunks([a, b]).report["cuts"]
    assert cut["max_vertex_mm"] > 1.0 and cut["pass1_mm"] == 0.0
    assert merge.merge_chunks([a, b], agree_mm=1e-6).report["cuts"] == [cut]
    other = Poses(poses.rotations, poses.translations + [0.0, 0.0, 0.03], poses.scales)
    b = _with_pass1(chunk(model, poses, 8, N, "b.npz", noise=0.05, seed=4), other)
    (cut,) = merge.disagreements([b, a], 29.0)
    f = cut["frame"]
    va, vb = hybrid_skin(model, poses.take(f))[0], hybrid_skin(model, other.take(f))[0]
    assert cut["pass1_mm"] == pytest.approx(1000 * np.linalg.norm(va - vb, axis=1).max()) == pytest.approx(30.0)
    assert merge.disagreements([a, b], 31.0) == []
    with pytest.raises(ArticulaInputError, match=r"disagree on frame \d+ by 30.0 mm in pass 1"):
        merge.merge_chunks([a, b], agree_mm=29.0)
