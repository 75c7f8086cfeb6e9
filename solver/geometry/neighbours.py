"""Exact nearest-neighbour search among 3-D points (scipy's k-d tree).

Two tree shapes, chosen by where the queries lie.  Both search exactly; they can differ only in which
of several equidistant points they return, so each caller keeps the shape it was written with.
Units: whatever the points are in (metres in the solver).
"""
from scipy.spatial import cKDTree


def nearest(points, queries):
    """Nearest of ``points (N,3)`` to every row of ``queries (Q,3)``: ``(distance (Q,), index (Q,))``
    (scipy's default k-d tree, for queries on or near the points)."""
    return cKDTree(points).query(queries)


def far_query_tree(points):
    """k-d tree over ``points (N,3)`` for many queries that lie off the point set (reflected points,
    most of them away from the surface): sliding-midpoint splits, unshrunk node boxes and 64-point
    leaves answer those faster than the default tree.  Use ``.query(queries, distance_upper_bound=...)``."""
    return cKDTree(points, leafsize=64, compact_nodes=False, balanced_tree=False)
