"""The main rounds' convergence test (pipeline.flattened) and that it stops real runs."""
import pytest

from articula.solver.learn.pipeline import flattened, learn_rig

from articula.sample_scenes.tube_scans import hybrid_truth


def test_flattened_compares_the_last_decrease_with_the_largest():
    assert flattened([2.0], 10.0, 0.25, 1, 8)[0] is False              # the first round has nothing to compare
    ok, why = flattened([2.0, 1.0, 0.6], 10.0, 0.25, 3, 8)
    assert ok is False and why == "round 3 lowered E by 6 %, 30 % of the largest round decrease (tol 25 %)"
    ok, why = flattened([2.0, 1.0, 0.6], 10.0, 0.35, 3, 8)
    assert ok and why.startswith("objective flattened: round 3 lowered E by 6 %, 30 % of the largest")
    assert flattened([1.0, 3.0, 0.7], 10.0, 0.25, 3, 8)[0]             # 0.7 <= 0.25 * 3
    assert flattened([0.0], 10.0, 0.25, 1, 8)[0]                       # a round that gains nothing
    ok, why = flattened([2.0, 1.0], 10.0, 0.25, 2, 2)
    assert not ok and why.startswith("max_iterations (2) reached: round 2")


def test_learn_rig_stops_when_the_rounds_flatten():
    """On the tube body the rounds' decreases shrink: the run stops at the first round that gains at most
    tol of the largest round decrease, before the cap, and says so; the log shows exactly that."""
    model, _, scans = hybrid_truth(6, seed=1)
    tol = 0.3
    rep = learn_rig(scans, model.faces, parts=8, max_iterations=12, tol=tol, bcd_sweeps=2,
                    bcd_steps=(0.2, 0.05)).report
    ends = [e for name, e in rep["objective_log"] if name in ("initial", "rest_vertices")]
    gains = [a - b for a, b in zip(ends, ends[1:])]
    assert rep["iterations"] == len(gains) < 12 and rep["converged"]
    assert rep["stopped"].startswith(f"objective flattened: round {len(gains)} lowered E")
    assert gains[-1] <= tol * max(gains) and all(g > tol * max(gains[:i + 1]) for i, g in enumerate(gains[:-1]))


def test_without_convergence_the_cap_stops_and_the_report_says_so():
    model, _, scans = hybrid_truth(4, seed=1)
    rep = learn_rig(scans, model.faces, parts=8, max_iterations=2, tol=0.0, bcd_sweeps=1,
                    bcd_steps=(0.2,)).report
    assert rep["iterations"] == 2 and not rep["converged"]
    assert rep["stopped"].startswith("max_iterations (2) reached")
