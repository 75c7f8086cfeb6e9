"""Vertex normals (solver.geometry.normals) against the closed form of a sphere: the unit radial direction."""
import numpy as np
import trimesh

from articula.solver.geometry.normals import vertex_normals


def test_vertex_normals_of_a_sphere_point_outwards():
    s = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    n = vertex_normals(s.vertices, s.faces)
    np.testing.assert_allclose(np.einsum("ij,ij->i", n, np.asarray(s.vertices)), 1.0, atol=2e-3)
