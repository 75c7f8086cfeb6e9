"""Initial joints kept inside their cross-section (solver.learn.skeleton.rotation_centre with a radius):
closed-form answers for a ball joint and a hinge."""
import numpy as np

from articula.solver.learn.skeleton import rotation_centre, ring_radius, JOINT_INSIDE_FRACTION


def _rot(axis, angle):
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def _about(centre, rotations):
    """Parent still, child turning about ``centre``: the maps ``(Rp, tp, Rc, tc)``."""
    M = len(rotations)
    Rc = np.stack(rotations)
    tc = centre - np.einsum("mij,j->mi", Rc, centre)
    return np.broadcast_to(np.eye(3), (M, 3, 3)), np.zeros((M, 3)), Rc, tc


def test_ball_joint_within_the_radius_is_the_data_centre():
    rng = np.random.default_rng(0)
    c = np.array([0.1, 0.2, 0.3])
    maps = _about(c, [_rot(rng.normal(size=3), rng.uniform(0.3, 1.0)) for _ in range(10)])
    h0 = c + [0.01, 0.0, 0.0]
    assert np.allclose(rotation_centre(*maps, h0, mu=0.0, radius=0.05), c, atol=1e-9)


def test_ball_joint_outside_comes_to_the_radius_towards_the_data_centre():
    """Rotations about all axes alike give Σ DᵀD ≈ a multiple of I, so the bounded centre lies on the
    segment from h0 to the data's centre, at the radius."""
    angles = np.linspace(0.2, 1.2, 12)
    axes = np.eye(3)
    rotations = [_rot(ax, a) for a in angles for ax in axes]
    c = np.array([0.5, -0.2, 0.1])
    maps = _about(c, rotations)
    D = maps[0] - maps[2]
    A = np.einsum("mji,mjk->ik", D, D)
    assert np.allclose(A, A[0, 0] * np.eye(3), rtol=0.05)
    h0 = np.zeros(3)
    h = rotation_centre(*maps, h0, mu=0.0, radius=0.1)
    assert abs(np.linalg.norm(h - h0) - 0.1) < 1e-6
    u = (c - h0) / np.linalg.norm(c - h0)
    assert np.linalg.norm(np.cross(h - h0, u)) < 0.02 * 0.1


def test_hinge_slides_to_the_middle_of_its_axis():
    """A hinge fixes the centre across its axis only; bounded, the centre comes along the axis to the
    cross-section's middle (h0's place on the axis), where unbounded least squares with no prior could
    put it anywhere on the line."""
    axis = np.array([0.0, 0.0, 1.0])
    c = np.array([0.3, 0.0, 0.0])
    maps = _about(c, [_rot(axis, a) for a in np.linspace(0.2, 1.4, 8)])
    h0 = np.array([0.3, 0.0, 0.4])                   # ring centroid: on the axis, 0.4 above c
    h = rotation_centre(*maps, h0, mu=1e-4, radius=0.05)
    assert np.allclose(h, h0, atol=1e-3)
    h0_off = np.array([0.32, 0.0, 0.4])              # 2 cm off the axis: the data keep it on the axis
    h = rotation_centre(*maps, h0_off, mu=1e-4, radius=0.05)
    assert np.allclose(h[:2], c[:2], atol=1e-3) and abs(h[2] - 0.4) < 1e-3


def test_ring_radius_of_a_circle():
    t = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    ring = np.c_[0.08 * np.cos(t), 0.08 * np.sin(t), np.zeros_like(t)] + [1.0, 2.0, 3.0]
    assert abs(ring_radius(ring) - JOINT_INSIDE_FRACTION * 0.08) < 1e-12


def test_only_centres_outside_the_mesh_are_bounded():
    """The tube body, every part still but two: the forearm turning about its true elbow (inside: kept
    exactly) and the head turning about a point 0.5 m beside the neck (outside: brought within the
    neck's cross-section)."""
    from articula.solver.geometry.inside import winding_numbers
    from articula.solver.geometry.mesh_graph import edges_of
    from articula.solver.learn.skeleton import boundary_vertices, joint_heads

    from articula.sample_scenes.tube_scans import JOINTS, PARENTS, body
    rest, faces, labels = body()
    M = 8
    R = np.broadcast_to(np.eye(3), (M, 8, 3, 3)).copy()
    t = np.zeros((M, 8, 3))
    rng = np.random.default_rng(3)
    far = JOINTS[1] + [0.5, 0.0, 0.0]
    for part, centre in ((3, JOINTS[3]), (1, far)):
        for m in range(M):
            R[m, part] = _rot(rng.normal(size=3), rng.uniform(0.2, 0.8))
            t[m, part] = centre - R[m, part] @ centre
    heads = joint_heads(rest, labels, faces, np.arange(8), PARENTS, R, t)
    assert np.allclose(heads[3], JOINTS[3], atol=1e-4)            # the weak μ prior only (0.02 mm)
    ring = rest[boundary_vertices(labels, edges_of(faces), 0, 1)]
    assert np.linalg.norm(heads[1] - ring.mean(axis=0)) <= ring_radius(ring) + 1e-9
    assert abs(winding_numbers(far[None], rest, faces)[0]) < 0.5 < abs(winding_numbers(heads[1:2], rest, faces)[0])
