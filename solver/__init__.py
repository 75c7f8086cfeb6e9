"""Articula's mathematics: pure numpy/scipy.  Never imports bpy or mathutils.

Conventions everywhere: lengths in metres, quaternions (w, x, y, z), rotation vectors with
angle = norm (full angle), bone-local +Y is the twist axis, frames are (3,3) matrices whose columns
are the local axes in world coordinates.
"""
