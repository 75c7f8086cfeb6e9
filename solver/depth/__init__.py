"""Depth recordings: pinhole cameras, depth frames to points (range, background, floor, voxels,
normals) and the import of a whole recording into a point sequence.
"""
