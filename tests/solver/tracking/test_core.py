"""The tracking core (solver.tracking body, terms, priors, lm, frame, window) against independent
references: closest points by brute force, Jacobians by finite differences, eigen-lifting in closed form,
and fits of the exact model on noise-free captures reaching the truth."""
import dataclasses

import numpy as np
import pytest

from articula.sample_scenes import synthetic
from articula.solver.geometry.rotations import rotvec_to_quat
from articula.solver.rig.jacobians import apply_pose_increment
from articula.solver.rig.model import Poses
from articula.solver.rig.skinning import hybrid_skin
from articula.solver.track.metrics import closest_points
from articula.solver.tracking import window
from articula.solver.tracking.body import Body, closest_barycentric
from articula.solver.tracking.frame import (NOISE_REF, QUIET_FLOOR, SEARCH, SEARCH_HOLD, TRACKING, FrameSettings, Stage,
                                           capture_noise, end_chains, fit_frame, noise_share, small_bones)
from articula.solver.tracking.lm import State, minimise
from articula.solver.tracking.priors import TowardPose, pose_difference, weak_directions
from articula.solver.tracking.terms import ScanToModel, normal_jacobian


@pytest.fixture(scope="module")
def tube():
    model = synthetic.tube_body()
    return model, Body(model)


def _pose(model, seed, scale=0.3, shift=(0.05, -0.02, 0.03)):
    B = model.skeleton.num_bones
    r = np.random.default_rng(seed).normal(0.0, scale, (1, B, 3))
    return Poses(rotvec_to_quat(r), np.array([shift], float), np.ones(1))


def _surface_gap(model, fitted, truth, n=3000):
    """Largest distance (m) between the posed surfaces of two poses, both ways, on surface samples: a tube's
    twist moves vertices along its surface without changing it, so surfaces are compared, not vertices."""
    a = _surface_points(model, fitted, n, 1)[0]
    b = _surface_points(model, truth, n, 2)[0]
    return max(closest_points(a, hybrid_skin(model, truth)[0], model.faces)[0].max(),
               closest_points(b, hybrid_skin(model, fitted)[0], model.faces)[0].max())


def _surface_points(model, pose, n=6000, seed=0):
    """Points drawn uniformly on the posed surface with its face normals (an exact, noise-free capture)."""
    x = hybrid_skin(model, pose)[0]
    f = model.faces
    a, b, c = x[f[:, 0]], x[f[:, 1]], x[f[:, 2]]
    cross = np.cross(b - a, c - a)
    area = np.linalg.norm(cross, axis=1)
    rng = np.random.default_rng(seed)
    tri = rng.choice(len(f), n, p=area / area.sum())
    u, v = rng.random(n), rng.random(n)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    pts = a[tri] + u[:, None] * (b[tri] - a[tri]) + v[:, None] * (c[tri] - a[tri])
    return pts, cross[tri] / area[tri, None]


def test_closest_barycentric_matches_brute_force_over_regions():
    rng = np.random.default_rng(1)
    a, b, c = (rng.normal(size=(400, 3)) for _ in range(3))
    p = rng.normal(size=(400, 3)) * 2.0
    w = closest_barycentric(p, a, b, c)
    foot = w[:, :1] * a + w[:, 1:2] * b + w[:, 2:] * c
    s = np.linspace(0, 1, 201)
    uu, vv = np.meshgrid(s, s)
    keep = uu + vv <= 1
    uu, vv = uu[keep], vv[keep]
    for k in range(0, 400, 40):
        grid = a[k] + uu[:, None] * (b[k] - a[k]) + vv[:, None] * (c[k] - a[k])
        brute = np.linalg.norm(grid - p[k], axis=1).min()
        assert np.linalg.norm(foot[k] - p[k]) <= brute + 1e-9
        assert np.linalg.norm(foot[k] - p[k]) >= brute - 0.02 * np.linalg.norm(b[k] - a[k]) - 1e-9
    assert np.all(w >= -1e-12) and np.allclose(w.sum(axis=1), 1.0)


def test_one_ring_closest_point_is_the_surface_closest_point_near_the_surface(tube):
    """Points 2 mm off the surface: the closest point on the one-ring of the nearest vertex is the exact
    closest point of the whole mesh for nearly all (on this coarse body a long triangle's nearest vertex
    may lie on the next part's ring), and never closer than it."""
    model, body = tube
    pose = _pose(model, 2)
    pts, nrm = _surface_points(model, pose, 2000)
    pts = pts + 0.002 * nrm
    state = State(body, pose)
    _, _, foot, _ = state.surface.closest(pts)
    exact, _, _ = closest_points(pts, state.posed, model.faces)
    d = np.linalg.norm(pts - foot, axis=1)
    assert np.all(d >= exact - 1e-12)
    assert np.mean(np.abs(d - exact) < 1e-9) > 0.97


def test_closest_points_are_exact_on_a_fine_mesh_with_a_few_long_triangles():
    """A flat grid (5 mm) with a strip of two long slivers (60 mm): queries 3-100 mm above the strip get
    the mesh's exact closest point (brute force over every triangle), those near the slivers too,
    although none of the slivers' corners is among their nearest vertices."""
    from articula.solver.tracking.body import Surface, one_ring
    n = 41
    x, y = np.meshgrid(np.linspace(0, 0.2, n), np.linspace(0, 0.2, n))
    verts = np.stack([x.ravel(), y.ravel(), np.zeros(n * n)], axis=1)
    ids = np.arange(n * n).reshape(n, n)
    quads = [(ids[i, j], ids[i, j + 1], ids[i + 1, j + 1], ids[i + 1, j]) for i in range(n - 1) for j in range(n - 1)
             if not 18 <= j < 30 or i != 20]
    faces = [(a, b, c) for a, b, c, _ in quads] + [(a, c, d) for a, _, c, d in quads]
    faces += [(ids[20, 18], ids[20, 30], ids[21, 30]), (ids[20, 18], ids[21, 30], ids[21, 18])]
    faces = np.array(faces)
    surface = Surface(verts, faces, one_ring(faces, len(verts)))
    rng = np.random.default_rng(3)
    near = np.column_stack([rng.uniform(0, 0.2, (300, 2)), rng.uniform(0.0005, 0.0025, 300)])
    off = np.column_stack([rng.uniform(0.1, 0.14, 25), rng.uniform(0.1, 0.105, 25), rng.uniform(0.004, 0.03, 25)])
    q = np.concatenate([near, off])                       # a converging fit: a few queries far off
    _, _, foot, _ = surface.closest(q)
    exact, _, _ = closest_points(q, verts, faces)
    d = np.linalg.norm(q - foot, axis=1)
    assert np.all(d >= exact - 1e-12)
    far = exact > 0.004
    assert far.sum() >= 20
    np.testing.assert_allclose(d[far], exact[far], atol=1e-12)


def test_a_states_cached_pairs_belong_to_their_term(tube):
    """Terms made and dropped one after another on one state (as the scores of a search are) each get
    their own pairs: a dropped term's cache entry never answers for a new term (CPython gives a new
    object a freed one's id, so an id is not a key)."""
    model, body = tube
    state = State(body, _pose(model, 5))
    pts, nrm = _surface_points(model, _pose(model, 6), 400)
    for k in range(20):
        term = ScanToModel(pts, nrm, 100, 0.002, 0.2, seed=k)
        assert term.energy(body, state) == ScanToModel(pts, nrm, 100, 0.002, 0.2, seed=k).energy(
            body, State(body, state.pose))
        del term


def test_normal_jacobian_matches_finite_differences(tube):
    model, body = tube
    pose = _pose(model, 3)
    state = State(body, pose)
    vertex = np.arange(0, model.num_vertices, 7)
    n = np.random.default_rng(4).normal(size=(len(vertex), 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    nJ = normal_jacobian(body, state, vertex, n)
    h = 1e-6
    for col in range(0, body.size, 5):
        step = np.zeros(body.size)
        step[col] = h
        x1 = body.pose(body.moved(pose, step))[vertex]
        x0 = body.pose(body.moved(pose, -step))[vertex]
        fd = np.sum(n * (x1 - x0), axis=1) / (2 * h)
        assert np.allclose(nJ[:, col], fd, atol=1e-5), col


def test_jacobian_held_for_nearby_poses_is_exact_at_its_own_pose(tube):
    model, body = tube
    pose = _pose(model, 5)
    body.forget()
    J = body.jacobian_near(pose, np.arange(model.num_vertices))
    exact = body.jacobian(pose, np.arange(model.num_vertices))
    assert np.abs(J - exact).max() < 1e-5 * np.abs(exact).max()       # held as float32
    near = body.moved(pose, np.r_[np.zeros(3), np.full(body.size - 3, 0.005)])
    assert body.jacobian_near(near, [0]) is not None and body._jacobians[0][0] is pose
    far = body.moved(pose, np.r_[np.zeros(3), np.full(body.size - 3, 0.2)])
    body.jacobian_near(far, [0])
    assert body._jacobians[0][0] is far


def test_toward_pose_gradient_matches_finite_differences(tube):
    model, body = tube
    pose, target = _pose(model, 6), _pose(model, 7)
    W = np.diag(np.random.default_rng(8).uniform(0.5, 2.0, body.size))
    prior = TowardPose(target, W)
    lin = prior.linearise(body, State(body, pose))
    h = 1e-6
    for col in range(0, body.size, 4):
        step = np.zeros(body.size)
        step[col] = h
        e1 = prior.energy(body, State(body, body.moved(pose, step)))
        e0 = prior.energy(body, State(body, body.moved(pose, -step)))
        assert abs((e1 - e0) / (2 * h) - lin.g[col]) < 1e-6 * max(1.0, abs(lin.g[col]))
    assert np.allclose(pose_difference(target, target)[0], 0.0)


def test_weak_directions_lift_small_eigenvalues_to_the_ratio():
    rng = np.random.default_rng(9)
    Q, _ = np.linalg.qr(rng.normal(size=(6, 6)))
    lam = np.array([1e-8, 1e-6, 1e-3, 0.1, 1.0, 10.0])
    H = (Q * lam) @ Q.T
    lifted = np.linalg.eigvalsh(H + weak_directions(H, 1e-2))
    assert np.allclose(np.sort(lifted), [0.1, 0.1, 0.1, 0.1, 1.0, 10.0], rtol=1e-9, atol=1e-12)


def test_exact_model_on_a_noise_free_capture_reaches_the_truth(tube):
    """Started 0.05 rad per bone component and 3 cm off, the fit of the exact model ends within 0.1 mm of
    the true surface everywhere (the solver is right if the exact model reaches ~0; the tube's twists
    do not change its surface, so the surfaces are compared)."""
    model, body = tube
    truth = _pose(model, 10)
    pts, nrm = _surface_points(model, truth)
    B = model.skeleton.num_bones
    delta = np.r_[np.full(3, 0.03), np.zeros(1), np.random.default_rng(11).normal(0, 0.05, 3 * B)][None]
    start = apply_pose_increment(truth, delta)
    fit = fit_frame(body, pts, nrm, start, stages=SEARCH, weak_ratio=SEARCH_HOLD)
    assert _surface_gap(model, fit.pose, truth) < 1e-4


def test_noise_share_and_capture_noise_in_closed_form():
    """The hold's share is (noise / NOISE_REF)^2 within [QUIET_FLOOR, 1]; the noise of a median distance m
    is m / 0.6745 (a normal's median absolute value), None entries skipped."""
    assert noise_share(0.5 * NOISE_REF) == pytest.approx(0.25)
    assert noise_share(0.0) == QUIET_FLOOR and noise_share(3 * NOISE_REF) == 1.0
    assert capture_noise([None, 0.6745, 0.6745, 9.0]) == pytest.approx(1e-3)
    assert capture_noise([]) is None and capture_noise([None]) is None
    draws = np.abs(np.random.default_rng(3).normal(0.0, 2e-3, 200_000))
    assert capture_noise([np.median(draws) * 1e3]) == pytest.approx(2e-3, rel=0.01)


def test_a_quiet_stage_on_a_noise_free_capture_is_not_held_to_a_lagging_target(tube):
    """Held along its weak directions to a target 0.1 rad per component off, the tracking fit of a noise-free
    capture ends millimetres off with the full hold and within 0.1 mm of the true surface when told the
    capture is noise-free (its converging stage's hold then weighs QUIET_FLOOR)."""
    model, body = tube
    truth = _pose(model, 40, scale=0.2)
    pts, nrm = _surface_points(model, truth)
    target = body.moved(truth, np.random.default_rng(41).normal(0, 0.1, body.size))
    start = body.moved(truth, np.random.default_rng(42).normal(0, 0.01, body.size))
    held = fit_frame(body, pts, nrm, start, target=target)
    quiet = fit_frame(body, pts, nrm, start, target=target, noise=0.0)
    assert _surface_gap(model, held.pose, truth) > 1e-3
    assert _surface_gap(model, quiet.pose, truth) < 1e-4


def test_lm_never_raises_the_energy(tube):
    model, body = tube
    truth = _pose(model, 12)
    pts, nrm = _surface_points(model, truth)
    start = body.moved(truth, np.random.default_rng(13).normal(0, 0.05, body.size))
    term = ScanToModel(pts, nrm, 3000, 0.002, 0.1)
    before = term.energy(body, State(body, start))
    fit = minimise(body, start, [term])
    assert fit.energy <= before


def test_window_schedule_is_anchored_at_input_frame_numbers():
    frames = list(range(20))
    full = window.schedule(frames, frames, 6, 3)
    chunk = window.schedule(frames[7:], frames[7:], 6, 3)
    starts = {w[0] for w in full}
    assert {frames[7:][w[0]] for w in chunk[1:-1]} <= starts       # inner windows of a chunk are the run's
    owners = window.owner(full, 20)
    assert all(0 <= o < len(full) for o in owners) and len(owners) == 20


def test_temporal_term_is_zero_for_constant_velocity(tube):
    model, body = tube
    B = model.skeleton.num_bones
    rate = np.random.default_rng(14).normal(0, 0.05, (B, 3))
    states = [State(body, Poses(rotvec_to_quat(rate[None] * k), np.array([[0.01 * k, 0, 0]]), np.ones(1)))
              for k in range(4)]
    assert np.abs(window.second_differences(states)).max() < 1e-12


def test_window_fit_of_noise_free_frames_reaches_the_truth(tube):
    model, body = tube
    truths = [_pose(model, 20, scale=0.2, shift=(0.02 * k, 0, 0)) for k in range(4)]
    for k, t in enumerate(truths):
        t.rotations[0] = rotvec_to_quat(np.random.default_rng(20).normal(0, 0.2, (model.skeleton.num_bones, 3))
                                        * (1 + 0.05 * k))

    class Cap:
        def __init__(self, pose, seed):
            self.points, self.normals = _surface_points(model, pose, 5000, seed)

    starts = [body.moved(t, np.random.default_rng(30 + k).normal(0, 0.01, body.size)) for k, t in enumerate(truths)]

    out = window.fit_window(body, [Cap(t, k) for k, t in enumerate(truths)], starts, 1e-6, FrameSettings(samples=3000),
                            iterations=20)
    for fitted, t in zip(out, truths):
        assert _surface_gap(model, fitted, t) < 2e-4


def test_tracking_stages_end_unbiased():
    """The last stage of every schedule fits capture-to-model pairs alone (no coverage)."""
    assert TRACKING[-1].coverage == 0 and SEARCH[-1].coverage == 0


def _small_hand(model):
    """The tube body with most of its right hand's vertices anchored on the forearm: the hand becomes a
    small part branching off a larger one (as a finger off a hand)."""
    names = model.skeleton.names
    hand, forearm = names.index("hand.R"), names.index("forearm.R")
    anchor = model.anchor.copy()
    mine = np.flatnonzero(anchor == hand)
    anchor[mine[: int(0.8 * len(mine))]] = forearm
    return dataclasses.replace(model, anchor=anchor), hand


def test_small_bones_are_small_parts_off_a_larger_one(tube):
    """By vertex counts: none on the tube body as built (every part ~1/19 of the vertices); a hand left
    with a fifth of its vertices is one (under 2.5 % and under a quarter of its forearm's subtree)."""
    model, _ = tube
    assert len(small_bones(model)) == 0
    small, hand = _small_hand(model)
    assert small_bones(small).tolist() == [hand]
    assert small_bones(small, share=0.001).tolist() == []


def test_end_chains_are_the_unbranched_ends_by_vertex_count(tube):
    """The tube body's ends: the hands, feet and head (72 of 2,736 vertices each); the neck, forearms and
    shins (144 more) join their chains only when the share allows 216; a chain stops at a branching bone
    (the chest, the pelvis)."""
    model, _ = tube
    names = model.skeleton.names
    ends = lambda share: sorted(names[b] for c in end_chains(model, share) for b in c)
    assert ends(0.06) == ["foot.L", "foot.R", "hand.L", "hand.R", "head"]
    assert ends(0.08) == ["foot.L", "foot.R", "forearm.L", "forearm.R", "hand.L", "hand.R", "head", "neck",
                          "shin.L", "shin.R"]
    assert ends(0.02) == []
    assert "chest" not in ends(0.9) and "pelvis" not in ends(0.9)
    arm = [names.index(n) for n in ("hand.L", "forearm.L", "upper_arm.L", "shoulder.L")]
    assert any(c.tolist() == arm for c in end_chains(model, 0.9))            # one chain, the leaf first
    foot, shin = names.index("foot.L"), names.index("shin.L")
    bare = dataclasses.replace(model, anchor=np.where(model.anchor == foot, shin, model.anchor))
    assert [c.tolist() for c in end_chains(bare) if foot in c] == [[foot]]    # anchoring none, still an end


def test_a_stage_holding_small_parts_keeps_them_at_the_start(tube):
    """A searched stage with ``small_held``: the small hand stays at its start pose while the body
    converges to the capture; without it the hand moves too."""
    model, _ = tube
    small, hand = _small_hand(model)
    body = Body(small)
    truth = _pose(small, 7, scale=0.2)
    pts, nrm = _surface_points(small, truth, 5000, 3)
    start = body.moved(truth, np.random.default_rng(4).normal(0, 0.05, body.size))
    angle = lambda pose: 2 * np.arccos(min(1.0, abs(float(np.sum(pose.rotations[0, hand] * start.rotations[0, hand])))))
    fit = lambda stage: fit_frame(body, pts, nrm, start, stages=(stage,), weak_ratio=SEARCH_HOLD).pose
    held, free = fit(Stage(0.006, 0.08, 1.0, 10, small_held=True)), fit(Stage(0.006, 0.08, 1.0, 10))
    assert angle(held) < 2e-3 < 0.02 < angle(free)
    assert _surface_gap(small, held, truth) < 0.02


def test_a_ring_search_told_how_far_the_answer_is_gives_the_same_answer():
    """Closest points on the rings of the 16 nearest vertices with each query's known bound (the nearest
    vertex's distance, or a closer answer) are those of the unbounded search, bit for bit, on a curved
    mesh with queries near and far; with a bound below the answer no answer is within it, and many rows
    are left without one (their triangles all provably too far: the pruning works)."""
    from articula.solver.tracking.body import Surface, one_ring
    n = 30
    u, v = np.meshgrid(np.linspace(0, np.pi, n), np.linspace(0, 2 * np.pi, n, endpoint=False), indexing="ij")
    verts = np.stack([np.sin(u) * np.cos(v), np.sin(u) * np.sin(v), 1.5 * np.cos(u)], axis=1).reshape(-1, 3) * 0.1
    ids = np.arange(n * n).reshape(n, n)
    faces = np.array([f for i in range(n - 1) for j in range(n)
                      for f in ((ids[i, j], ids[i + 1, j], ids[i + 1, (j + 1) % n]),
                                (ids[i, j], ids[i + 1, (j + 1) % n], ids[i, (j + 1) % n]))])
    surface = Surface(verts, faces, one_ring(faces, len(verts)))
    rng = np.random.default_rng(5)
    q = verts[rng.integers(0, len(verts), 500)] + rng.normal(size=(500, 3)) * rng.choice([0.001, 0.01, 0.05], (500, 1))
    free = surface._on_rings(q, 16)
    nearest = surface.tree.query(q)[0]
    for bound in (nearest, free[3]):
        bounded = surface._on_rings(q, 16, bound)
        for a, b in zip(free, bounded):
            np.testing.assert_array_equal(a, b)
    below = surface._on_rings(q, 16, free[3] - 1e-3)[3]       # every answer's triangle provably too far?
    assert np.all(below > free[3] - 1e-3) and np.isinf(below).mean() > 0.2
