"""Generalized winding numbers and the distance outside a mesh (solver.geometry.inside) against closed forms:
a box, a sphere, a sphere with a hole (solid angle of the hole by the spherical excess, Girard's theorem)."""
import numpy as np
import pytest

from articula.solver.geometry import inside
from articula.solver.geometry.inside import distance_outside, winding_numbers

RNG = np.random.default_rng(3)
LO, HI = np.array([-1.0, -0.5, 0.0]), np.array([2.0, 1.0, 0.7])


def box():
    """Axis-aligned box [LO, HI] as 12 triangles, counter-clockwise seen from outside."""
    v = np.array([[x, y, z] for x in (LO[0], HI[0]) for y in (LO[1], HI[1]) for z in (LO[2], HI[2])])
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    faces = np.array([t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))])
    n = np.cross(v[faces[:, 1]] - v[faces[:, 0]], v[faces[:, 2]] - v[faces[:, 0]])
    centre = v[faces].mean(axis=1) - (LO + HI) / 2
    assert (np.einsum("fi,fi->f", n, centre) > 0).all()            # outward, as the docstring assumes
    return v, faces


def uv_sphere(radius=1.0, rings=24, segments=32):
    """Sphere: poles 0 (north, +z) and 1, rings of ``segments`` vertices; outward triangles."""
    theta = np.pi * np.arange(1, rings) / rings
    phi = 2 * np.pi * np.arange(segments) / segments
    ring = np.stack([np.sin(theta)[:, None] * np.cos(phi), np.sin(theta)[:, None] * np.sin(phi),
                     np.cos(theta)[:, None] * np.ones_like(phi)], axis=-1).reshape(-1, 3)
    v = radius * np.vstack([[0, 0, 1], [0, 0, -1], ring])

    def idx(r, s):
        return 2 + r * segments + s % segments

    faces = [(0, idx(0, s), idx(0, s + 1)) for s in range(segments)]
    for r in range(rings - 2):
        for s in range(segments):
            faces += [(idx(r, s), idx(r + 1, s), idx(r + 1, s + 1)), (idx(r, s), idx(r + 1, s + 1), idx(r, s + 1))]
    faces += [(1, idx(rings - 2, s + 1), idx(rings - 2, s)) for s in range(segments)]
    return v, np.array(faces)


def box_distance(p):
    """Closed form: distance of points to the box [LO, HI] (0 inside)."""
    c, h = (LO + HI) / 2, (HI - LO) / 2
    return np.linalg.norm(np.maximum(np.abs(p - c) - h, 0.0), axis=1)


def spherical_polygon_area(p, corners):
    """Solid angle of the convex polygon ``corners (n, 3)`` seen from ``p``: its corners projected to the
    unit sphere about p, area = Σ interior angles − (n − 2)π (Girard)."""
    u = corners - p
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    n, total = len(u), 0.0
    for i in range(n):
        t1 = u[i - 1] - (u[i - 1] @ u[i]) * u[i]
        t2 = u[(i + 1) % n] - (u[(i + 1) % n] @ u[i]) * u[i]
        total += np.arccos(np.clip(t1 @ t2 / np.linalg.norm(t1) / np.linalg.norm(t2), -1, 1))
    return total - (n - 2) * np.pi


def test_box_inside_and_outside():
    v, f = box()
    p = LO + RNG.uniform(-0.5, 1.5, (400, 3)) * (HI - LO)
    margin = np.minimum(np.abs(p - LO), np.abs(p - HI)).min(axis=1)
    p = p[margin > 1e-3]
    expected = ((p > LO) & (p < HI)).all(axis=1).astype(float)
    np.testing.assert_allclose(winding_numbers(p, v, f), expected, atol=1e-9)
    np.testing.assert_allclose(winding_numbers(p, v, f[:, ::-1]), -expected, atol=1e-9)   # inward faces


def test_sphere_inside_and_outside():
    v, f = uv_sphere(0.8)
    d = RNG.normal(size=(300, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    r = RNG.uniform(0.0, 2.0, 300)
    r = r[np.abs(r - 0.8) > 0.05]                          # away from the polygonal surface
    p = d[:len(r)] * r[:, None]
    np.testing.assert_allclose(winding_numbers(p, v, f), (r < 0.8).astype(float), atol=1e-9)


def test_sphere_with_a_hole_matches_the_solid_angle_of_the_hole():
    v, f = uv_sphere(1.0, rings=12, segments=16)
    open_faces = f[(f != 0).all(axis=1)]                    # the fan at the north pole removed
    rim = v[2:2 + 16]                                       # the hole's rim: the first ring (planar, convex)
    p = np.array([[0, 0, 0], [0.3, -0.2, 0.1], [0, 0, -0.9], [0.1, 0.5, 0.6], [-0.4, 0.0, -0.5]])
    w = winding_numbers(p, v, open_faces)
    expected = np.array([1 - spherical_polygon_area(q, rim) / (4 * np.pi) for q in p])
    np.testing.assert_allclose(w, expected, atol=1e-9)
    assert (w > 0.9).all() and (w < 1).all()                # still "inside"
    np.testing.assert_array_equal(distance_outside(p, v, open_faces), 0.0)


def test_distance_outside_a_box_is_the_closed_form():
    v, f = box()
    p = LO + RNG.uniform(-1.0, 2.0, (500, 3)) * (HI - LO)
    np.testing.assert_allclose(distance_outside(p, v, f), box_distance(p), atol=1e-12)
    np.testing.assert_allclose(distance_outside(p, v, f[:, ::-1]), box_distance(p), atol=1e-12)


def test_chunks_give_the_same_numbers(monkeypatch):
    v, f = uv_sphere(1.0, rings=6, segments=8)
    p = RNG.uniform(-1.5, 1.5, (37, 3))
    whole = winding_numbers(p, v, f)
    for chunk in (1, 7, 50, len(f) + 3):
        monkeypatch.setattr(inside, "CHUNK_PAIRS", chunk)
        np.testing.assert_allclose(winding_numbers(p, v, f), whole, atol=1e-12)


def test_empty_inputs_and_bad_faces():
    v, f = box()
    assert winding_numbers(np.zeros((0, 3)), v, f).shape == (0,)
    assert distance_outside(np.zeros((0, 3)), v, f).shape == (0,)
    np.testing.assert_array_equal(winding_numbers(np.ones((2, 3)), v, np.zeros((0, 3), int)), 0.0)
    with pytest.raises(ValueError):
        winding_numbers(np.zeros((1, 3)), v, f + 8)
