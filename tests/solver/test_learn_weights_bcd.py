"""G12 (swing-weight QP with box + sum <= 1 constraints) and G13 (sampling-based BCD on weights)."""
import numpy as np
from scipy.optimize import minimize

from articula.solver.laplacian import uniform_laplacian
from articula.solver.model import Model
from articula.solver.rig_objective import RigObjective
from articula.solver.skinning import hybrid_skin
from articula.solver.weights_bcd import (CandidateSkin, _children_table, box_simplex_qp, candidates,
                                         optimise_weights)

from .learn_data import body, hybrid_truth


def _qp_value(H, b, w):
    return w @ H @ w - 2 * b @ w


def test_qp_matches_brute_force_grid_and_slsqp():
    rng = np.random.default_rng(0)
    for k in (1, 2, 3):
        N = 40
        G = rng.normal(size=(N, 6, k))
        H = np.einsum("nrk,nrl->nkl", G, G)
        if k > 1:
            H[:5, :, -1] = H[:5, -1, :] = 0.0                  # a few singular problems
        b = rng.normal(size=(N, k)) * rng.uniform(0.1, 3, (N, 1))
        w = box_simplex_qp(H, b, np.full(N, k))
        assert np.all(w >= 0) and np.all(w <= 1) and np.all(w.sum(1) <= 1 + 1e-12)
        grid = np.stack(np.meshgrid(*[np.linspace(0, 1, 41)] * k, indexing="ij"), -1).reshape(-1, k)
        grid = grid[grid.sum(1) <= 1 + 1e-12]
        for n in range(N):
            f = _qp_value(H[n], b[n], w[n])
            f_grid = np.min(np.einsum("gi,ij,gj->g", grid, H[n], grid) - 2 * grid @ b[n])
            assert f <= f_grid + 1e-10
            res = minimize(lambda x: _qp_value(H[n], b[n], x), np.full(k, 0.5 / k), jac=lambda x: 2 * H[n] @ x - 2 * b[n],
                           bounds=[(0, 1)] * k, constraints=[{"type": "ineq", "fun": lambda x: 1 - x.sum()}],
                           method="SLSQP", options={"ftol": 1e-14, "maxiter": 500})
            assert f <= res.fun + 1e-9


def test_qp_respects_number_of_variables():
    H = np.broadcast_to(np.eye(3), (2, 3, 3)).copy()
    b = np.array([[0.2, 0.3, 0.4], [0.2, 0.3, 0.4]])
    w = box_simplex_qp(H, b, np.array([1, 3]))
    assert np.allclose(w[0], [0.2, 0, 0]) and np.allclose(w[1], [0.2, 0.3, 0.4])


def test_candidate_skin_equals_hybrid_skin():
    model, poses, _ = hybrid_truth(4)
    kids = _children_table(model.skeleton.parents)[model.anchor]
    base, G = CandidateSkin(model.skeleton, poses).base_and_columns(
        model.rest_vertices, model.anchor, model.twist_weights.astype(np.float64), kids)
    ws = np.where(kids >= 0, model.swing_weights[np.arange(model.num_vertices)[:, None], np.maximum(kids, 0)], 0)
    assert np.abs(base + np.einsum("mvik,vk->mvi", G, ws) - hybrid_skin(model, poses)).max() < 1e-12


def test_candidates_respect_bounds_and_anchor_rule():
    model, _, _ = hybrid_truth(2)
    sk = model.skeleton
    child = sk.child_matrix()
    model.twist_weights[np.flatnonzero(model.twist_weights[:, 3] > 0)[:3], 3] = 1.0   # "forward" applies
    n_back = n_fwd = 0
    for anchor, tw, valid in candidates(model.anchor, model.twist_weights.astype(np.float64), sk.parents):
        t = tw[valid]
        assert np.all(t >= 0) and np.all(t <= 1) and np.all(t.sum(1) <= 1 + 1e-9)
        assert not np.any((t != 0) & ~child[anchor[valid]])
        n_back += np.sum(valid & (anchor == sk.parents[model.anchor]))
        n_fwd += np.sum(valid & (sk.parents[anchor] == model.anchor))
    assert n_back > 0 and n_fwd > 0                          # both re-expressions occur on this body


def _binary_start(model):
    _, _, labels = body()
    V, B = model.num_vertices, model.skeleton.num_bones
    return Model(model.rest_vertices, model.faces, model.skeleton, labels.astype(np.int32),
                 np.zeros((V, B), np.float32), np.zeros((V, B), np.float32))


def test_bcd_decreases_q_exactly_by_the_incremental_gains():
    model, poses, scans = hybrid_truth(6)
    obj = RigObjective(scans, uniform_laplacian(model.faces, model.num_vertices), 100.0)
    start = _binary_start(model)
    q0 = obj.value(hybrid_skin(start, poses))
    fitted, log = optimise_weights(start, poses, obj, max_sweeps=3, steps=(0.2, 0.05), jacobi=False)
    assert len(log) == 3 and log[0] < q0 and all(b < a for a, b in zip(log, log[1:]))
    q_full = obj.value(hybrid_skin(fitted, poses))
    assert abs(q_full - log[-1]) <= 1e-9 * q_full               # incremental gains = full recomputation
    fitted.validate()                                             # bounds, sum <= 1, anchor rule


def test_bcd_recovers_smooth_weights_from_binary_start():
    """G13 at the default α = 100: the error falls by > 80 %; without the joint (Jacobi) move the
    single-vertex blocks are held back by the Laplacian coupling (measured: 72 % after 5 sweeps)."""
    model, poses, scans = hybrid_truth(6)
    obj = RigObjective(scans, uniform_laplacian(model.faces, model.num_vertices), 100.0)
    start = _binary_start(model)
    fitted, log = optimise_weights(start, poses, obj, max_sweeps=3)
    e0 = np.linalg.norm(hybrid_skin(start, poses) - scans, axis=2).mean()
    e1 = np.linalg.norm(hybrid_skin(fitted, poses) - scans, axis=2).mean()
    assert e1 < 0.2 * e0
    assert abs(obj.value(hybrid_skin(fitted, poses)) - log[-1]) <= 1e-9 * log[-1]


def test_joint_move_never_increases_q_and_reports_it_exactly():
    from articula.solver.weights_bcd import CandidateSkin, _State, joint_move
    model, poses, scans = hybrid_truth(4)
    rng = np.random.default_rng(5)
    noisy = scans + 0.002 * rng.normal(size=scans.shape)
    obj = RigObjective(noisy, uniform_laplacian(model.faces, model.num_vertices), 100.0)
    m = _binary_start(model)
    state = _State(m, poses, obj)
    Q0 = obj.value(state.P)
    Q1 = joint_move(m, CandidateSkin(m.skeleton, poses), state, obj, Q0)
    assert Q1 < Q0
    assert np.isclose(obj.value(hybrid_skin(m, poses)), Q1, rtol=1e-12)      # model and state agree
    assert np.allclose(state.R, obj.laplacian(state.P) - obj.scan_lap, atol=1e-12)
    m.validate()


def test_two_ring_colouring_separates_interacting_vertices():
    from articula.solver.weights_bcd import two_ring_colouring
    _, faces, _ = body()
    V = faces.max() + 1
    L = uniform_laplacian(faces, V)
    A1 = (L != 0).astype(float)
    ring2 = (A1 @ A1).tocsr()
    colour = two_ring_colouring(ring2)
    rows, cols = ring2.nonzero()
    off = rows != cols
    assert np.all(colour[rows[off]] != colour[cols[off]])
    assert colour.max() + 1 <= ring2.getnnz(axis=1).max()        # greedy bound: at most max degree + 1


def test_candidate_evaluation_equals_hybrid_skin_for_every_candidate():
    """The fast candidate path (twist blend over the anchor's children only, elementwise affine maps and
    normal equations) against the slow reference: ``hybrid_skin`` of a model carrying each candidate's
    anchor, twist and solved swing weights, and the dense einsum normal equations (1e-9 relative)."""
    from articula.solver.weights_bcd import _normal_equations
    model, poses, _ = hybrid_truth(3)
    sk = model.skeleton
    kids_table = _children_table(sk.parents)
    skin = CandidateSkin(sk, poses)
    rng = np.random.default_rng(2)
    tried = 0
    for anchor, tw, valid in candidates(model.anchor, model.twist_weights.astype(np.float64), sk.parents):
        if not valid.any():
            continue
        kids = kids_table[anchor]
        base, G = skin.base_and_columns(model.rest_vertices, anchor, tw, kids)
        ws = np.where(kids >= 0, rng.uniform(0, 0.3, size=kids.shape), 0.0)
        sw = np.zeros(model.swing_weights.shape)
        r, c = np.nonzero(kids >= 0)
        sw[r, c * 0 + kids[r, c]] = ws[r, c]
        ref_model = Model(model.rest_vertices, model.faces, sk, anchor.astype(np.int32), tw.astype(np.float32),
                          sw.astype(np.float32))
        ref_model.twist_weights = tw                       # float64 so both paths see the same numbers
        ref_model.swing_weights = sw
        ref = hybrid_skin(ref_model, poses)
        fast = base + np.einsum("mvik,vk->mvi", G, ws)
        scale = np.abs(ref).max()
        assert np.abs(fast - ref)[:, valid].max() <= 1e-9 * scale
        H, b = _normal_equations(G, ref)
        assert np.allclose(H, np.einsum("mvik,mvil->vkl", G, G), rtol=1e-9, atol=1e-12 * np.abs(H).max())
        assert np.allclose(b, np.einsum("mvik,mvi->vk", G, ref), rtol=1e-9, atol=1e-12 * np.abs(b).max())
        tried += 1
    assert tried > 10


def test_solve_small_equals_lapack():
    """The closed-form batched solves of the swing QP (s ≤ 3) against np.linalg.solve (1e-9 relative),
    on SPD blocks and on the KKT matrices [[H, 1], [1ᵀ, 0]] the QP builds."""
    from articula.solver.weights_bcd import solve_small
    rng = np.random.default_rng(4)
    for s in (1, 2, 3, 4):
        G = rng.normal(size=(50, 7, s))
        A = np.einsum("nrk,nrl->nkl", G, G) + 0.01 * np.eye(s)
        if s >= 2:
            A = A.copy()
            A[:, -1, :] = A[:, :, -1] = 1.0
            A[:, -1, -1] = 0.0
        B = rng.normal(size=(50, s, 2))
        ref = np.linalg.solve(A, B)
        assert np.abs(solve_small(A, B) - ref).max() <= 1e-9 * np.abs(ref).max()
