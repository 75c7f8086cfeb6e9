"""The swing-weight QP (weights.qp): against brute force (grid, SLSQP), the enumeration of every face,
closed forms and LAPACK."""
import numpy as np
from scipy.optimize import minimize

from articula.solver.learn.weights.qp import ACTIVE_SET_MIN_K, _qp_group_enumerate, box_simplex_qp, qp_group, solve_small


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
        w2, f2 = qp_group(H, b)                                 # the batched solver reports its value
        assert np.array_equal(w2, w)
        assert np.allclose(f2, np.einsum("ni,nij,nj->n", w, H, w) - 2 * np.sum(b * w, 1), atol=1e-12)
    for h, c in ((2.0, 1.0), (2.0, -1.0), (0.5, 3.0), (0.0, 1.0), (0.0, -1.0), (0.0, 0.0)):   # k = 1 closed form
        w, f = qp_group(np.array([[[h]]]), np.array([[c]]))
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
                w, f = qp_group(H, b, guesses=guesses)
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
        w, f = qp_group(H, b)
        assert np.allclose(w, w0, atol=1e-12) and np.allclose(f, f0, atol=1e-12)
        g = np.einsum("nij,nj->ni", H, w) - b
        gap = np.sum(g * w, 1) - np.minimum(g.min(1), 0)
        assert np.all(gap <= 1e-12)


def test_qp_respects_number_of_variables():
    H = np.broadcast_to(np.eye(3), (2, 3, 3)).copy()
    b = np.array([[0.2, 0.3, 0.4], [0.2, 0.3, 0.4]])
    w = box_simplex_qp(H, b, np.array([1, 3]))
    assert np.allclose(w[0], [0.2, 0, 0]) and np.allclose(w[1], [0.2, 0.3, 0.4])


def test_qp_two_variables_closed_form_on_every_face_and_degenerate_problems():
    """k = 2 (:func:`_qp_two` via qp_group) against the enumeration of every face: optima inside, on each
    edge, at each vertex and at 0; flat problems (H = 0, a zero column, b = 0) included."""
    H0 = np.array([[1.0, 0.3], [0.3, 0.8]])
    targets = [(0.2, 0.3), (0.5, 0.7), (0.6, -0.5), (-0.5, 0.6), (2.0, 0.1), (0.1, 2.0), (-1.0, -1.0), (1.5, 1.5)]
    H = [H0] * len(targets) + [np.zeros((2, 2))] * 3 + [np.array([[1.0, 0.0], [0.0, 0.0]])] * 2
    b = [H0 @ t for t in targets] + [[0.0, 0.0], [1.0, -1.0], [1.0, 1.0], [0.5, 1.0], [0.5, 0.0]]
    H, b = np.array(H), np.array(b, dtype=np.float64)
    with np.errstate(over="ignore", invalid="ignore"):       # the enumeration's 1/ridge on H = 0
        w0, f0 = _qp_group_enumerate(H, b)
    w, f = qp_group(H, b)
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


def test_solve_small_equals_lapack():
    """The closed-form batched solves of the swing QP (s ≤ 3) against np.linalg.solve (1e-9 relative),
    on SPD blocks and on the KKT matrices [[H, 1], [1ᵀ, 0]] the QP builds."""
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
