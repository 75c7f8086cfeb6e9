"""G12 (swing-weight QP with box + sum <= 1 constraints) and G13 (sampling-based BCD on weights)."""
import numpy as np
from scipy.optimize import minimize

from articula.solver.geometry.mesh_graph import uniform_laplacian
from articula.solver.rig.model import Model
from articula.solver.learn.objective import RigObjective
from articula.solver.rig.skinning import hybrid_skin
from articula.solver.learn.weights import (TwoRing, ACTIVE_SET_MIN_K, CandidateSkin, _children_table, _qp_group,
                                         _qp_group_enumerate, box_simplex_qp, candidates, optimise_weights)

from ..learn_data import body, hybrid_truth


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
        w2, f2 = _qp_group(H, b)                                 # the batched solver reports its value
        assert np.array_equal(w2, w)
        assert np.allclose(f2, np.einsum("ni,nij,nj->n", w, H, w) - 2 * np.sum(b * w, 1), atol=1e-12)
    for h, c in ((2.0, 1.0), (2.0, -1.0), (0.5, 3.0), (0.0, 1.0), (0.0, -1.0), (0.0, 0.0)):   # k = 1 closed form
        w, f = _qp_group(np.array([[[h]]]), np.array([[c]]))
        grid = np.linspace(0, 1, 100001)
        assert f[0] <= np.min(h * grid ** 2 - 2 * c * grid) + 1e-12 and 0 <= w[0, 0] <= 1
        assert np.isclose(f[0], h * w[0, 0] ** 2 - 2 * c * w[0, 0], atol=1e-15)


def _random_qps(rng, k, N, kind):
    """N random PSD problems with k variables: "full" rank, "singular" (rank k − 2, or 1), "tie" (two
    equal columns: a line of minimisers when the optimum uses them), "scaled" (badly scaled columns)."""
    r = k if kind in ("full", "scaled") else max(1, k - 2)
    G = rng.normal(size=(N, 3 * k + 2, r)) @ rng.normal(size=(N, r, k)) if kind == "singular" else \
        rng.normal(size=(N, 3 * k + 2, k)) + rng.normal(size=(N, 1, k))
    if kind == "tie" and k > 1:
        G[:, :, -1] = G[:, :, 0]
    if kind == "scaled":
        G *= 10.0 ** rng.uniform(-2, 2, (N, 1, k))
    H = np.einsum("nrk,nrl->nkl", G, G)
    b = np.einsum("nrk,nr->nk", G, rng.normal(size=(N, G.shape[1])) * rng.uniform(0.2, 3, (N, 1)) + 0.4)
    return H, b


def test_qp_certified_active_set_equals_enumeration():
    """The certified active-set solver (k ≥ ACTIVE_SET_MIN_K = 3) against the enumeration of every face
    (the reference, the solver before the active sets):
    the same objective to 1e-12 (relative to the problem's scale) everywhere, the same minimiser where it
    is unique (well-conditioned H); also with every problem sent to the fallback (guesses=0) and with
    problems that need several active-set steps."""
    assert ACTIVE_SET_MIN_K <= 4                                 # so that k = 4..6 below use it
    rng = np.random.default_rng(3)
    for k in range(1, 7):
        for kind in ("full", "singular", "tie", "scaled"):
            H, b = _random_qps(rng, k, 400, kind)
            w0, f0 = _qp_group_enumerate(H, b)
            scale = np.abs(b).max(1) + np.diagonal(H, axis1=1, axis2=2).max(1)
            ev = np.linalg.eigvalsh(H)
            unique = ev[:, 0] > 1e-6 * ev[:, -1]
            for guesses in (6, 0, 1):
                w, f = _qp_group(H, b, guesses=guesses)
                assert np.all(w >= 0) and np.all(w.sum(1) <= 1 + 1e-12)
                assert np.all(np.abs(f - f0) <= 1e-12 * scale), (k, kind, guesses)
                value = np.einsum("ni,nij,nj->n", w, H, w) - 2 * np.sum(b * w, 1)
                assert np.allclose(f, value, atol=1e-12 * scale.max())
                assert np.all(np.abs(w - w0)[unique] <= 1e-9), (k, kind, guesses)
                if kind == "full":
                    assert np.abs(w - w0)[unique].max() <= 1e-12, (k, guesses)
            if kind == "full":
                assert unique.mean() > 0.9
            assert box_simplex_qp(H, b, np.full(len(b), k)).shape == (len(b), k)


def test_qp_faces_of_every_kind():
    """Optima on every kind of face (interior, Σ w = 1, vertices e_j, 0, mixed) with k = 4 and 5: the
    enumeration and the active-set solver agree, and the enumeration's result satisfies the KKT conditions."""
    for k in (4, 5):
        cases = []
        H0 = np.eye(k) + 0.3
        for target in (np.full(k, 0.1), np.full(k, 0.5), np.eye(k)[1] * 3, -np.ones(k),
                       np.r_[0.9, -1, 0.5, np.zeros(k - 3)], np.r_[2.0, 2.0, -1.0, np.zeros(k - 3)], np.zeros(k)):
            cases.append((H0, H0 @ target))
        H = np.array([c[0] for c in cases])
        b = np.array([c[1] for c in cases])
        w0, f0 = _qp_group_enumerate(H, b)
        w, f = _qp_group(H, b)
        assert np.allclose(w, w0, atol=1e-12) and np.allclose(f, f0, atol=1e-12)
        g = np.einsum("nij,nj->ni", H, w) - b
        gap = np.sum(g * w, 1) - np.minimum(g.min(1), 0)
        assert np.all(gap <= 1e-12)


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
    for anchor, tw, valid, _ in candidates(model.anchor, model.twist_weights.astype(np.float64), sk.parents):
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
    fitted, log, _ = optimise_weights(start, poses, obj, max_sweeps=3, steps=(0.2, 0.05), jacobi=False)
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
    fitted, log, _ = optimise_weights(start, poses, obj, max_sweeps=3)
    e0 = np.linalg.norm(hybrid_skin(start, poses) - scans, axis=2).mean()
    e1 = np.linalg.norm(hybrid_skin(fitted, poses) - scans, axis=2).mean()
    assert e1 < 0.2 * e0
    assert abs(obj.value(hybrid_skin(fitted, poses)) - log[-1]) <= 1e-9 * log[-1]


def test_joint_move_never_increases_q_and_reports_it_exactly():
    from articula.solver.learn.weights import CandidateSkin, _State, joint_move
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
    from articula.solver.learn.weights import two_ring_colouring
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
    """The fast candidate path (per-anchor columns: closed-form single-child twist or component-wise DLB,
    one batched product for base and swing columns; normal equations) against the slow reference:
    ``hybrid_skin`` of a model carrying each candidate's anchor, twist and random swing weights, and the
    dense einsum normal equations (1e-9 relative)."""
    from articula.solver.learn.weights import _normal_equations
    model, poses, _ = hybrid_truth(3)
    sk = model.skeleton
    kids_table = _children_table(sk.parents)
    skin = CandidateSkin(sk, poses)
    rng = np.random.default_rng(2)
    tried = 0
    for anchor, tw, valid, _ in candidates(model.anchor, model.twist_weights.astype(np.float64), sk.parents):
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
        for a in np.unique(anchor[valid]):                 # the per-anchor columns and normal equations
            rows = np.flatnonzero(valid & (anchor == a))
            k = len(skin.kids[a])
            C = skin.columns(a, model.rest_vertices[rows].T, tw[rows][:, skin.kids[a]].T)
            assert np.abs(C[:, :3] - base[:, rows].transpose(0, 2, 1)).max() <= 1e-12 * scale
            if k == 0:
                continue
            Gr = G[:, rows, :, :k]
            r = ref[:, rows].transpose(0, 2, 1)
            H, b = _normal_equations(C, r)
            H_ref, b_ref = np.einsum("mvik,mvil->vkl", Gr, Gr), np.einsum("mvik,mvi->vk", Gr, ref[:, rows])
            assert np.allclose(H, H_ref, rtol=1e-9, atol=1e-12 * np.abs(H_ref).max())
            assert np.allclose(b, b_ref, rtol=1e-9, atol=1e-12 * np.abs(b_ref).max())
        tried += 1
    assert tried > 10


def test_solve_small_equals_lapack():
    """The closed-form batched solves of the swing QP (s ≤ 3) against np.linalg.solve (1e-9 relative),
    on SPD blocks and on the KKT matrices [[H, 1], [1ᵀ, 0]] the QP builds."""
    from articula.solver.learn.weights import solve_small
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


def _assert_candidate_skin_is_hybrid_skin(model, poses):
    """The candidate skin of the model's own anchors, twist and swing weights equals hybrid_skin (1e-12)."""
    sk = model.skeleton
    table = _children_table(sk.parents)[model.anchor]
    base, G = CandidateSkin(sk, poses).base_and_columns(model.rest_vertices, model.anchor,
                                                        model.twist_weights.astype(np.float64), table)
    ws = np.where(table >= 0, model.swing_weights[np.arange(model.num_vertices)[:, None], np.maximum(table, 0)], 0)
    ref = hybrid_skin(model, poses)
    assert np.abs(base + np.einsum("mvik,vk->mvi", G, ws) - ref).max() <= 1e-12 * np.abs(ref).max()


def test_candidate_skin_follows_the_running_hemisphere_rule():
    """Opposing 170° twists of two children of one anchor (as in test_skinning): hybrid_skin flips one
    twist quaternion; the candidate skin (component-wise blend with the same rule) matches it to 1e-12.
    Includes float32 weights 0.4 + 0.6 summing to 1 + 3e-8, where the rule flips the first child."""
    from articula.sample_scenes import synthetic
    from articula.solver.rig.model import Poses
    from articula.solver.geometry.rotations import rotvec_to_quat
    from articula.solver.rig.skinning import twist_flips
    sk = synthetic.human_skeleton()
    model = synthetic.random_model(200, seed=4)
    fork, kids = min(((a, (c, d)) for a in range(sk.num_bones) for c in sk.children(a) for d in sk.children(a)
                      if c < d), key=lambda ap: sk.frames[ap[1][0], :, 1] @ sk.frames[ap[1][1], :, 1])
    r = np.zeros((3, sk.num_bones, 3))
    r[:, list(kids), 1] = np.radians(170.0)
    r[1, kids[1], 1] = np.radians(-120.0)
    r[2] = 0.3 * np.random.default_rng(1).normal(size=(sk.num_bones, 3))
    poses = Poses(rotvec_to_quat(r), np.zeros((3, 3)), np.ones(3))
    sel = np.flatnonzero(model.anchor == fork)
    wt = np.zeros_like(model.twist_weights)
    wt[sel, kids[0]], wt[sel, kids[1]] = 0.4, np.linspace(0.1, 0.6, len(sel))
    model = Model(model.rest_vertices, model.faces, sk, model.anchor, wt, model.swing_weights)
    assert twist_flips(model, poses)[0, sel].any()
    _assert_candidate_skin_is_hybrid_skin(model, poses)


def _noisy_problem(M=5, seed=3):
    model, poses, scans = hybrid_truth(M)
    noisy = scans + 0.002 * np.random.default_rng(seed).normal(size=scans.shape)
    return _binary_start(model), poses, RigObjective(noisy, uniform_laplacian(model.faces, model.num_vertices), 100.0)


def test_active_set_gives_the_full_evaluation_result():
    """Skipping vertices whose own state and two-ring did not change (and reusing unchanged joint-move
    proposals) changes nothing: same Q log as evaluating every vertex every sweep, strictly decreasing
    and equal to a full recomputation of Q from the returned model."""
    start, poses, obj = _noisy_problem()
    fast, log_fast, _ = optimise_weights(start, poses, obj, max_sweeps=4, steps=(0.2, 0.05))
    full, log_full, _ = optimise_weights(start, poses, obj, max_sweeps=4, steps=(0.2, 0.05), active_set=False)
    assert len(log_fast) == len(log_full) == 4
    assert np.allclose(log_fast, log_full, rtol=1e-9, atol=0)
    assert all(b < a for a, b in zip(log_fast, log_fast[1:]))
    assert abs(obj.value(hybrid_skin(fast, poses)) - log_fast[-1]) <= 1e-9 * log_fast[-1]
    fast.validate()


def test_tracker_skips_only_vertices_without_improving_candidates():
    """After some sweeps, against a state rebuilt from scratch (hybrid_skin of the model): every vertex
    the tracker holds clean has no candidate gaining more than the acceptance floor, every cached
    joint-move proposal equals a fresh data-only evaluation, and the running Q is the recomputed Q."""
    from articula.solver.learn.weights import MIN_GAIN, _DataTargets, _setup, _State, _sweep, evaluate
    start, poses, obj = _noisy_problem()
    model, state, skin, Q, graph, tracker = _setup(start, poses, obj)
    for _ in range(3):
        Q, _ = _sweep(model, skin, state, obj, graph, tracker, Q, steps=(0.2, 0.05))
    fresh = _State(model, poses, obj)
    assert np.isclose(obj.value(fresh.P), Q, rtol=1e-9, atol=0)
    assert np.allclose(fresh.R, state.R, atol=1e-12) and np.allclose(fresh.P, state.P, atol=1e-12)
    clean = np.flatnonzero(~tracker.dirty)
    assert 0 < len(clean) < model.num_vertices
    gain = evaluate(model, skin, fresh, clean, steps=(0.2, 0.05))[0]
    assert gain.max() <= MIN_GAIN * Q + 1e-12 * Q
    dirty = np.flatnonzero(tracker.dirty)
    assert (evaluate(model, skin, fresh, dirty, steps=(0.2, 0.05))[0] > MIN_GAIN * Q).any()   # not vacuous
    cached = np.flatnonzero(~tracker.stale)
    g, *_, p = evaluate(model, skin, _DataTargets(fresh), cached, steps=(0.2, 0.05))
    assert np.allclose(tracker.proposal[0][cached], g, rtol=1e-9, atol=1e-15)
    moving = cached[g > 0]
    assert np.allclose(tracker.proposal[4][moving], p[g > 0], atol=1e-12)


def test_directions_name_moves_independently_of_the_step():
    """A candidate slot's direction is the same at every step δ and distinct between moves: the slots
    of steps (0.2,) and (0.05,) pair up one to one, and stepless slots (stay, re-expressions) are −1."""
    model, _, _ = hybrid_truth(2)
    sk = model.skeleton
    model.twist_weights[np.flatnonzero(model.twist_weights[:, 3] > 0)[:3], 3] = 1.0   # "forward" applies
    tw64 = model.twist_weights.astype(np.float64)
    big = [way for *_, way in candidates(model.anchor, tw64, sk.parents, (0.2,))]
    small = [way for *_, way in candidates(model.anchor, tw64, sk.parents, (0.05,))]
    assert big == small
    stepped = [w for w in big if w >= 0]
    assert len(stepped) == len(set(stepped)) and big.count(-1) == 3      # stay, backward at 1, forward at 0


def _screen_all(model, skin, state, idx, steps):
    """Reference for evaluate's screening: every candidate of every step, each vertex's best screened
    gain ``(n,)`` (0 where none gains)."""
    from articula.solver.learn.weights import _candidate_list, _screen
    g = state.targets(idx)
    kap = state.kappa[idx]
    d = state.Pv[idx] - g
    f_cur = kap * np.einsum("nmi,nmi->n", d, d)
    v, a, tw, _ = _candidate_list(model.anchor[idx], model.twist_weights[idx], model.skeleton.parents, steps)
    gain, _ = _screen(skin, model.rest_vertices[idx], np.ascontiguousarray(g.transpose(1, 2, 0)), kap, f_cur,
                      v, a, tw)
    best = np.zeros(len(idx))
    np.maximum.at(best, v, gain)
    return best


def test_coarse_to_fine_steps_lie_between_smallest_step_and_all_steps():
    """evaluate (smallest step everywhere, larger steps along the gaining directions) gains at least what
    the smallest step alone gains, more on some vertices (the widening is used), at most what every step
    gains (screened, brute force over all candidates) and on most vertices exactly that."""
    from articula.solver.learn.weights import _setup, _sweep, evaluate
    start, poses, obj = _noisy_problem()
    model, state, skin, Q, graph, tracker = _setup(start, poses, obj)
    for _ in range(2):                                    # interior twist weights: every move kind occurs
        Q, _ = _sweep(model, skin, state, obj, graph, tracker, Q)
    idx = np.arange(model.num_vertices)
    steps = (0.2, 0.1, 0.05, 0.02)
    coarse = evaluate(model, skin, state, idx, steps)[0]
    tol = 1e-8 * Q          # exact gains (float32-stored weights) vs screened ones: ~3e-5 of a gain apart
    small = _screen_all(model, skin, state, idx, (0.02,))
    assert np.all(coarse >= small - tol) and (coarse > small + tol).any()
    full = _screen_all(model, skin, state, idx, steps)
    assert np.all(coarse <= full + tol)
    assert np.mean(np.abs(coarse - full) <= tol) > 0.9


def test_step_pruning_counts_wins_and_keeps_the_smallest_step():
    from articula.solver.learn.weights import STEP_MIN_SHARE, _count_steps, _kept_steps
    steps = (0.2, 0.1, 0.05, 0.02)
    wins = np.zeros(4, dtype=np.int64)
    old = np.zeros((6, 3), dtype=np.float32)
    new = old.copy()
    new[0, 1], new[1, 1], new[2, 2], new[3, 0] = 0.02, 0.0199, 0.1, 0.2     # row 4: swing only, row 5 moved anchor
    new[5, 1] = 0.05
    _count_steps(wins, steps, np.array([True] * 5 + [False]), old, new)
    assert wins.tolist() == [1, 1, 0, 2]
    assert _kept_steps(steps, wins) == (0.2, 0.1, 0.02)
    assert _kept_steps(steps, np.array([0, 0, 0, 0])) == steps
    many = np.array([0, 0, int(STEP_MIN_SHARE * 1000) - 1, 1000])
    assert _kept_steps(steps, many) == (0.02,)


def test_pruned_steps_stay_close_to_all_steps():
    """With step pruning the BCD's Q log still decreases and ends within 1e-3 relative of the log with
    every step in every sweep (the pruned steps won almost nothing)."""
    start, poses, obj = _noisy_problem()
    _, pruned, _ = optimise_weights(start, poses, obj, max_sweeps=4)
    _, full, _ = optimise_weights(start, poses, obj, max_sweeps=4, prune_steps=False)
    assert all(b < a for a, b in zip(pruned, pruned[1:]))
    assert abs(pruned[-1] - full[-1]) <= 1e-3 * full[-1]


def test_single_child_twists_at_forks_equal_hybrid_skin():
    """At an anchor with several children, candidates with twist weight (0 … 1) on one child only equal
    hybrid_skin, also for twists beyond 180° (canonical twist quaternions: a lone child is never
    flipped by the running hemisphere rule)."""
    from articula.sample_scenes import synthetic
    from articula.solver.rig.model import Poses
    from articula.solver.geometry.rotations import rotvec_to_quat
    sk = synthetic.human_skeleton()
    model = synthetic.random_model(200, seed=4)
    fork = next(a for a in range(sk.num_bones) if len(sk.children(a)) >= 2)
    kids = sk.children(fork)
    r = np.zeros((4, sk.num_bones, 3))
    r[:, kids[0], 1] = np.radians([0.0, 150.0, 250.0, -300.0])
    r[3] += 0.2 * np.random.default_rng(3).normal(size=(sk.num_bones, 3))
    poses = Poses(rotvec_to_quat(r), np.zeros((4, 3)), np.ones(4))
    sel = np.flatnonzero(model.anchor == fork)
    wt = np.zeros_like(model.twist_weights)
    wt[sel, kids[0]] = np.linspace(0.0, 1.0, len(sel))               # includes 0 and 1
    model = Model(model.rest_vertices, model.faces, sk, model.anchor, wt, model.swing_weights)
    _assert_candidate_skin_is_hybrid_skin(model, poses)


def test_halves_are_more_than_two_rings_apart_and_balance_the_work():
    """TwoRing.halves: half_a, half_b and the band partition the vertices, no vertex of half_b lies in the
    two-ring of half_a (brute force over the ring2 pattern), and the halves' work differs by at most the
    work of the heaviest levels (the cut moves one level at a time)."""
    model, _, _ = hybrid_truth(2)
    graph = TwoRing(uniform_laplacian(model.faces, model.num_vertices))
    work = np.random.default_rng(1).uniform(1.0, 9.0, model.num_vertices)
    half_a, half_b, band = graph.halves(work)
    V = model.num_vertices
    assert len(half_a) and len(half_b) and band.sum() < 0.25 * V
    assert np.array_equal(np.sort(np.concatenate([half_a, half_b, np.flatnonzero(band)])), np.arange(V))
    assert not np.isin(graph.ring2[half_a].indices, half_b).any()
    per_level = np.bincount(graph.levels, weights=work)
    assert abs(work[half_a].sum() - work[half_b].sum()) <= 3 * per_level.max()


def test_split_sweeps_are_exact_and_the_same_with_or_without_fork(monkeypatch):
    """With every sweep cut into halves (SPLIT_MIN_WORK 0): the halves run in a forked child and here,
    or both here, with the same Q log and weights; the log is strictly decreasing and ends at the
    recomputed Q; the final Q is within 1 % of the unsplit BCD's (another visiting order), which is
    what runs where fork is unavailable."""
    from articula.solver import parallel
    from articula.solver.learn import weights as wb
    start, poses, obj = _noisy_problem()
    unsplit, log_unsplit, _ = optimise_weights(start, poses, obj, max_sweeps=3)
    monkeypatch.setattr(wb, "SPLIT_MIN_WORK", 0)
    calls = []
    real = wb._halves_in_parallel
    monkeypatch.setattr(wb, "_halves_in_parallel", lambda *a: calls.append(1) or real(*a))
    class InProcess(parallel.ForkedCall):                  # the split visit without the child
        def __init__(self, fn):
            self.fn, self.pid, self.fd = fn, None, None
    with parallel.using(2):
        forked, log_forked, _ = optimise_weights(start, poses, obj, max_sweeps=3)
        real_call = parallel.ForkedCall
        monkeypatch.setattr(parallel, "ForkedCall", InProcess)
        here, log_here, _ = optimise_weights(start, poses, obj, max_sweeps=3)
        monkeypatch.setattr(parallel, "ForkedCall", real_call)
        with parallel.allow_fork(False):                   # no fork: the unsplit visit, as everywhere else
            assert np.allclose(optimise_weights(start, poses, obj, max_sweeps=3)[1], log_unsplit, rtol=1e-12, atol=0)
    assert len(calls) == 6
    assert np.allclose(log_forked, log_here, rtol=1e-12, atol=0)
    for name in ("anchor", "twist_weights", "swing_weights"):
        assert np.allclose(getattr(forked, name), getattr(here, name), rtol=0, atol=1e-6)
    assert all(b < a for a, b in zip(log_forked, log_forked[1:]))
    assert abs(obj.value(hybrid_skin(forked, poses)) - log_forked[-1]) <= 1e-9 * log_forked[-1]
    assert abs(log_forked[-1] - log_unsplit[-1]) <= 0.01 * log_unsplit[-1]
    forked.validate()


def test_band_classes_are_two_ring_independent_and_cover_the_band():
    """_subset_classes: every masked vertex in exactly one class, no two vertices of a class within two
    rings (brute force over the ring2 pattern)."""
    from articula.solver.learn.weights import _subset_classes
    model, _, _ = hybrid_truth(2)
    graph = TwoRing(uniform_laplacian(model.faces, model.num_vertices))
    _, _, band = graph.halves(np.ones(model.num_vertices))
    classes = _subset_classes(graph.ring2, band)
    assert np.array_equal(np.sort(np.concatenate(classes)), np.flatnonzero(band))
    for idx in classes:
        block = graph.ring2[idx][:, idx].tocoo()
        assert np.all(block.row == block.col)                      # only each vertex with itself
    assert len(classes) <= len([c for c in graph.classes if band[c].any()])
    assert _subset_classes(graph.ring2, np.zeros(model.num_vertices, bool)) == []


def test_qp_two_variables_closed_form_on_every_face_and_degenerate_problems():
    """k = 2 (:func:`_qp_two` via _qp_group) against the enumeration of every face: optima inside, on each
    edge, at each vertex and at 0; flat problems (H = 0, a zero column, b = 0) included."""
    H0 = np.array([[1.0, 0.3], [0.3, 0.8]])
    targets = [(0.2, 0.3), (0.5, 0.7), (0.6, -0.5), (-0.5, 0.6), (2.0, 0.1), (0.1, 2.0), (-1.0, -1.0), (1.5, 1.5)]
    H = [H0] * len(targets) + [np.zeros((2, 2))] * 3 + [np.array([[1.0, 0.0], [0.0, 0.0]])] * 2
    b = [H0 @ t for t in targets] + [[0.0, 0.0], [1.0, -1.0], [1.0, 1.0], [0.5, 1.0], [0.5, 0.0]]
    H, b = np.array(H), np.array(b, dtype=np.float64)
    with np.errstate(over="ignore", invalid="ignore"):       # the enumeration's 1/ridge on H = 0
        w0, f0 = _qp_group_enumerate(H, b)
    w, f = _qp_group(H, b)
    assert np.all(np.isfinite(w)) and np.all(w >= 0) and np.all(w.sum(1) <= 1 + 1e-12)
    assert np.allclose(f, f0, atol=1e-12)
    assert np.allclose(f, np.einsum("ni,nij,nj->n", w, H, w) - 2 * np.sum(b * w, 1), atol=1e-12)
    assert np.allclose(w[:len(targets)], w0[:len(targets)], atol=1e-12)          # unique minimisers
    expect = [(0.2, 0.3), None, (0.45, 0.0), (0.0, 0.4125), None, None, (0.0, 0.0), None]   # 0.45 = b₁/h₁₁
    for got, want in zip(w, expect):
        if want is not None:
            assert np.allclose(got, want, atol=1e-9)
    assert np.isclose(w[1].sum(), 1.0) and np.isclose(w[7].sum(), 1.0)           # on the sum edge
    assert np.allclose(w[8:10], [[0, 0], [1, 0]]) and np.isclose(w[10].sum(), 1.0)   # H = 0: linear
