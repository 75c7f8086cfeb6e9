"""Axis conventions of scan files: which file axes point forward and up, and the matrix that stands a
file's coordinates up in Blender's world (Z up, -Y towards the viewer of the front view, +Y forward).

Axis names are Blender's importer enum items (``X``, ``Y``, ``Z``, ``NEGATIVE_X``...); ``AUTO`` means the
format's own convention, the default of Blender's importer for that format (docs/scans.md):
OBJ and Alembic forward -Z, up Y; PLY, STL, OFF, MDD and PC2 forward Y, up Z (used as written).
The solver always works in the file's coordinates; only Blender objects carry the conversion.
"""
from __future__ import annotations

import numpy as np

from ..errors import ArticulaInputError

AUTO = "AUTO"
AXES = ("X", "Y", "Z", "NEGATIVE_X", "NEGATIVE_Y", "NEGATIVE_Z")
BLENDER_AXES = ("Y", "Z")                     # forward, up of Blender's world: no conversion
FORMAT_AXES = {".obj": ("NEGATIVE_Z", "Y"), ".abc": ("NEGATIVE_Z", "Y")}   # every other format: BLENDER_AXES
_SHORT = {"X": "X", "Y": "Y", "Z": "Z", "-X": "NEGATIVE_X", "-Y": "NEGATIVE_Y", "-Z": "NEGATIVE_Z"}


def parse_axis(text: str) -> str:
    """``"-Z"``, ``"z"``, ``"NEGATIVE_Z"`` or ``"auto"`` -> the enum name (``NEGATIVE_Z``, ``AUTO``)."""
    t = str(text).strip().upper()
    if t in AXES or t == AUTO:
        return t
    if t in _SHORT:
        return _SHORT[t]
    raise ArticulaInputError(f"axis {text!r}: use one of X, Y, Z, -X, -Y, -Z (or auto)")


def _unit(axis: str) -> np.ndarray:
    v = np.zeros(3)
    v["XYZ".index(axis[-1])] = -1.0 if axis.startswith("NEGATIVE_") else 1.0
    return v


def format_axes(ext: str) -> tuple:
    """(forward, up) of the format with extension ``ext`` (``".obj"``...): Blender's importer defaults."""
    return FORMAT_AXES.get(ext.lower(), BLENDER_AXES)


def resolve(ext: str, forward: str = AUTO, up: str = AUTO) -> tuple:
    """(forward, up) with ``AUTO`` replaced by the format's axis; refuses two axes along one line."""
    default = format_axes(ext)
    forward = default[0] if parse_axis(forward) == AUTO else parse_axis(forward)
    up = default[1] if parse_axis(up) == AUTO else parse_axis(up)
    if forward[-1] == up[-1]:
        raise ArticulaInputError(f"axes: forward {forward} and up {up} lie on the same axis; pick two different axes")
    return forward, up


def axis_matrix(forward: str, up: str) -> np.ndarray:
    """(4, 4) rotation taking file coordinates with these axes to Blender's world: the file's forward axis
    becomes +Y, its up axis +Z and forward x up (its right) +X."""
    f, u = _unit(forward), _unit(up)
    if abs(f @ u) > 0.5:
        raise ArticulaInputError(f"axes: forward {forward} and up {up} lie on the same axis; pick two different axes")
    m = np.eye(4)
    m[:3, :3] = np.stack([np.cross(f, u), f, u])   # rows: file's right, forward, up -> world X, Y, Z
    return m


def conversion(ext: str, forward: str = AUTO, up: str = AUTO) -> np.ndarray:
    """(4, 4) file -> Blender world matrix of a file with extension ``ext`` read with these axes."""
    return axis_matrix(*resolve(ext, forward, up))


def world_to_file(points, ext: str) -> np.ndarray:
    """Blender world points (..., 3) in the axis convention of format ``ext``, as Blender's exporter
    writes them (OBJ: (x, y, z) -> (x, z, -y)); the inverse of :func:`conversion` with AUTO axes."""
    r = conversion(ext)[:3, :3]
    return np.asarray(points, np.float64) @ r              # r orthonormal: inverse = transpose
