"""Geometry without a rig: rotations (quaternions, matrices, rotation vectors), dual quaternions,
Procrustes fits, the mesh graph (edges, adjacency, Laplacian, components) and exact point-to-surface distances.
"""
