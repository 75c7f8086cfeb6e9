"""optimise_weights (weights.optimise): exact Q logs, recovery from binary weights, active set and step
pruning against the full evaluation."""
import numpy as np

from articula.solver.geometry.mesh_graph import uniform_laplacian
from articula.solver.learn.objective import RigObjective
from articula.solver.rig.skinning import hybrid_skin
from articula.solver.learn.weights.optimise import optimise_weights

from articula.sample_scenes.tube_scans import hybrid_truth
from .problems import binary_start, noisy_problem


def test_bcd_decreases_q_exactly_by_the_incremental_gains():
    model, poses, scans = hybrid_truth(6)
    obj = RigObjective(scans, uniform_laplacian(model.faces, model.num_vertices), 100.0)
    start = binary_start(model)
    q0 = obj.value(hybrid_skin(start, poses))
    fitted, log, _ = optimise_weights(start, poses, obj, max_sweeps=3, steps=(0.2, 0.05), jacobi=False)
    assert len(log) == 3 and log[0] < q0 and all(b < a for a, b in zip(log, log[1:]))
    q_full = obj.value(hybrid_skin(fitted, poses))
    assert abs(q_full - log[-1]) <= 1e-9 * q_full               # incremental gains = full recomputation
    fitted.validate()                                             # bounds, sum <= 1, anchor rule


def test_bcd_recovers_smooth_weights_from_binary_start():
    """G13 at the default α = 100: the error falls by > 80 %; without the joint (Jacobi) move the
    single-vertex blocks are held back by the Laplacian coupling."""
    model, poses, scans = hybrid_truth(6)
    obj = RigObjective(scans, uniform_laplacian(model.faces, model.num_vertices), 100.0)
    start = binary_start(model)
    fitted, log, _ = optimise_weights(start, poses, obj, max_sweeps=3)
    e0 = np.linalg.norm(hybrid_skin(start, poses) - scans, axis=2).mean()
    e1 = np.linalg.norm(hybrid_skin(fitted, poses) - scans, axis=2).mean()
    assert e1 < 0.2 * e0
    assert abs(obj.value(hybrid_skin(fitted, poses)) - log[-1]) <= 1e-9 * log[-1]


def test_active_set_gives_the_full_evaluation_result():
    """Skipping vertices whose own state and two-ring did not change (and reusing unchanged joint-move
    proposals) changes nothing: same Q log as evaluating every vertex every sweep, strictly decreasing
    and equal to a full recomputation of Q from the returned model."""
    start, poses, obj = noisy_problem()
    fast, log_fast, _ = optimise_weights(start, poses, obj, max_sweeps=4, steps=(0.2, 0.05))
    full, log_full, _ = optimise_weights(start, poses, obj, max_sweeps=4, steps=(0.2, 0.05), active_set=False)
    assert len(log_fast) == len(log_full) == 4
    assert np.allclose(log_fast, log_full, rtol=1e-9, atol=0)
    assert all(b < a for a, b in zip(log_fast, log_fast[1:]))
    assert abs(obj.value(hybrid_skin(fast, poses)) - log_fast[-1]) <= 1e-9 * log_fast[-1]
    fast.validate()


def test_pruned_steps_stay_close_to_all_steps():
    """With step pruning the BCD's Q log still decreases and ends within 1e-3 relative of the log with
    every step in every sweep (the pruned steps won almost nothing)."""
    start, poses, obj = noisy_problem()
    _, pruned, _ = optimise_weights(start, poses, obj, max_sweeps=4)
    _, full, _ = optimise_weights(start, poses, obj, max_sweeps=4, prune_steps=False)
    assert all(b < a for a, b in zip(pruned, pruned[1:]))
    assert abs(pruned[-1] - full[-1]) <= 1e-3 * full[-1]
