"""Chunk plans (solver.farm.chunks) and the causal merge rule (solver.track.merge.choose_frames_causal),
checked by brute force over many recording lengths."""
import numpy as np
import pytest

from articula.solver.errors import ArticulaInputError
from articula.solver.farm import chunks
from articula.solver.track.merge import choose_frames, choose_frames_causal


@pytest.mark.parametrize("size,overlap", [(10, 1), (10, 4), (50, 40), (2, 1)])
def test_plans_cover_every_frame_with_the_overlap(size, overlap):
    for frames in range(1, 130):
        ranges = chunks.plan(frames, size, overlap)
        assert ranges[0][0] == 0 and ranges[-1][1] == frames
        for (a0, b0), (a1, b1) in zip(ranges, ranges[1:]):
            assert b0 - a1 == overlap, (frames, ranges)          # consecutive chunks share `overlap` frames
            assert a1 > a0 and b1 > b0
        owned = [b - max(a + overlap * (k > 0), 0) if k else b - a for k, (a, b) in enumerate(ranges)]
        assert sum(owned) == frames
        assert all(b - a > overlap for a, b in ranges[1:])      # no chunk of warm-up only


def test_a_short_tail_is_folded_into_the_last_chunk():
    assert chunks.plan(305, 150, 40) == [(0, 150), (110, 305)]
    assert chunks.plan(300, 150, 40) == [(0, 150), (110, 300)]
    assert chunks.plan(100, 300, 40) == [(0, 100)]


def test_text_round_trip_and_file_names():
    ranges = chunks.plan(1000, 300, 40)
    assert chunks.from_text(chunks.to_text(ranges)) == ranges
    assert chunks.file_name(1, (260, 600)) == "chunk_0001_0260-0600.npz"
    with pytest.raises(ArticulaInputError, match="START:STOP"):
        chunks.from_text("0:10,abc")


@pytest.mark.parametrize("frames,size,overlap,message", [
    (0, 10, 2, "no frames"), (100, 1, 0, "chunk size"), (100, 10, 0, "overlap"), (100, 10, 10, "smaller"),
    (10**7, 2, 1, "more than")])
def test_bad_plans_are_refused(frames, size, overlap, message):
    with pytest.raises(ArticulaInputError, match=message):
        chunks.plan(frames, size, overlap)


def test_overhead_is_the_overlap_share():
    assert chunks.overhead(300, 60) == pytest.approx(0.2)


@pytest.mark.parametrize("look_ahead", [0, 1, 3])
def test_causal_choice_takes_shared_frames_from_the_earlier_chunk(look_ahead):
    rng = np.random.default_rng(0)
    for _ in range(200):
        frames, size = int(rng.integers(20, 200)), int(rng.integers(6, 40))
        overlap = int(rng.integers(look_ahead + 1, size))
        ranges = chunks.plan(frames, size, overlap)
        got = choose_frames_causal(ranges, 0, frames, look_ahead)
        for f in range(frames):          # brute force: the earliest chunk unless f is in its last look_ahead frames
            want = next(i for i, (a, b) in enumerate(ranges)
                        if a <= f < b and (i == len(ranges) - 1 or f < b - look_ahead))
            assert got[f] == want, (ranges, f)


def test_symmetric_choice_is_unchanged_for_chunks_without_look_ahead():
    ranges = [(0, 10), (6, 20)]
    assert list(choose_frames(ranges, 0, 20)) == [0] * 8 + [1] * 12
    assert list(choose_frames_causal(ranges, 0, 20, 1)) == [0] * 9 + [1] * 11


@pytest.mark.parametrize("size,overlap,want", [(0, 0, (300, 60)), (10, 0, (10, 5)), (3, 0, (3, 1)),
                                               (500, 0, (500, 60)), (10, 3, (10, 3)), (0, 20, (300, 20))])
def test_a_chunk_given_alone_gets_an_overlap_that_fits(size, overlap, want):
    """``--chunk N`` without ``--overlap``: min(default, N // 2), said in the note; the plan then works."""
    got_size, got_overlap, note = chunks.settings(size, overlap, 300, 60)
    assert (got_size, got_overlap) == want
    assert (f"overlap {want[1]} frames" in note) == (overlap == 0 and want[1] != 60), note
    chunks.check(100, got_size, got_overlap)
