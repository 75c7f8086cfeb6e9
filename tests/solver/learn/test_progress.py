"""Progress inside learn_rig's long stages (issue 16 item 7): every step of a round and the report call
progress from within, fractions never go back, the numbers do not depend on the callback, and a
Cancelled raised inside the weight sweep or the rest-vertex solve stops the run at that call."""
import numpy as np
import pytest

from articula.solver.errors import Cancelled
from articula.solver.learn import report, rest_shape
from articula.solver.learn.pipeline import learn_rig
from articula.solver.learn.weights import optimise, sweeps

from articula.sample_scenes.tube_scans import hybrid_truth

SETTINGS = dict(parts=8, max_iterations=2, bcd_sweeps=2, gn_iterations=3, bcd_steps=(0.2, 0.05), warm_start=(),
                seed=0, workers=2)
JOINTS = "joints and poses (Levenberg-Marquardt)"


@pytest.fixture(scope="module")
def tube():
    model, _, scans = hybrid_truth(6, seed=1)
    return scans, model.faces


@pytest.fixture(scope="module")
def run(tube):
    calls = []
    res = learn_rig(*tube, progress=lambda f, s, o: calls.append((f, s, o)), **SETTINGS)
    return res, calls


def _round_calls(calls):
    """The calls of each main round: between 'initialised' and the 'round k of n' calls."""
    rounds, current = [], None
    for f, s, o in calls:
        if s == "initialised":
            current = []
        elif s.startswith("round "):
            rounds.append(current)
            current = []
        elif current is not None:
            current.append(s)
    return rounds


def test_every_stage_of_a_round_and_the_report_report_from_inside(run):
    res, calls = run
    rounds = _round_calls(calls)
    assert len(rounds) == res.report["iterations"] >= 1
    for stages in rounds:
        for stage in (JOINTS, optimise.STAGE, rest_shape.STAGE):
            assert stage in stages, (stage, stages)
        # the weight step reports within its sweeps (no objective), not only after each sweep
    inside = [c for c in calls if c[1] == optimise.STAGE and c[2] is None]
    assert len(inside) >= 2 * len(rounds)
    assert sum(s == report.STAGE for _, s, _ in calls) >= 3       # announced, per frame batch
    fr = [f for f, _, _ in calls]
    assert all(0.0 <= f <= 1.0 for f in fr)
    assert all(b >= a - 1e-12 for a, b in zip(fr, fr[1:]))


def test_numbers_do_not_depend_on_the_callback(run, tube):
    res, _ = run
    quiet = learn_rig(*tube, **SETTINGS)
    assert quiet.report["objective_log"] == res.report["objective_log"]
    assert quiet.report["surface_error_mm"] == res.report["surface_error_mm"]
    assert np.array_equal(quiet.scan_distances, res.scan_distances)
    for name in ("rest_vertices", "anchor", "twist_weights", "swing_weights"):
        assert np.array_equal(getattr(quiet.model, name), getattr(res.model, name)), name


class CancelAt:
    """Progress that raises Cancelled at the k-th call matching ``wanted(stage, objective)``."""

    def __init__(self, k, wanted):
        self.k, self.wanted, self.seen, self.after = k, wanted, 0, 0

    def __call__(self, fraction, stage, objective):
        if self.seen >= self.k:
            self.after += 1                     # a call after the cancel: the run went on
        if self.wanted(stage, objective):
            self.seen += 1
            if self.seen == self.k:
                raise Cancelled()


@pytest.mark.parametrize("forked", [False, True])
def test_cancel_inside_the_weight_sweep(tube, monkeypatch, forked):
    if forked:                       # halves and joint-move proposals in a forked child, even on the tube
        monkeypatch.setattr(sweeps, "SPLIT_MIN_WORK", 1)
    cancel = CancelAt(3, lambda stage, obj: stage == optimise.STAGE and obj is None)
    with pytest.raises(Cancelled):
        learn_rig(*tube, progress=cancel, **SETTINGS)
    assert cancel.seen == 3 and cancel.after == 0


def test_cancel_inside_the_rest_vertex_solve(tube):
    cancel = CancelAt(2, lambda stage, obj: stage == rest_shape.STAGE)
    with pytest.raises(Cancelled):
        learn_rig(*tube, progress=cancel, **SETTINGS)
    assert cancel.seen == 2 and cancel.after == 0


def test_forked_sweep_reports_with_the_same_numbers(tube, monkeypatch):
    monkeypatch.setattr(sweeps, "SPLIT_MIN_WORK", 1)     # halves and proposals in a forked child
    calls = []
    forked = learn_rig(*tube, progress=lambda f, s, o: calls.append((f, s, o)), **SETTINGS)
    assert sum(s == optimise.STAGE and o is None for _, s, o in calls) >= 2 * forked.report["iterations"]
    quiet = learn_rig(*tube, **SETTINGS)
    assert quiet.report["objective_log"] == forked.report["objective_log"]
    assert np.array_equal(quiet.model.twist_weights, forked.model.twist_weights)
