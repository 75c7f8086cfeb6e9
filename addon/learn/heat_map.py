"""The learned rig's error heat map: the per-vertex distance (mm) of the scans to the posed model, and its
colours on the rig mesh (FLOAT point attribute ``articula_error_mm`` and FLOAT_COLOR point attribute
``articula_error_color``, made the active and render colour)."""
import numpy as np

from ...solver.errors import ArticulaInputError
from ...solver.geometry.surface_distance import per_vertex_scan_distances
from ...solver.rig.skinning import hybrid_skin

ERROR_ATTRIBUTE = "articula_error_mm"
COLOR_ATTRIBUTE = "articula_error_color"
SCALE_PROPERTY = "articula_error_scale_mm"      # mesh ID property: the error the ramp's top colour means

# Heat-map colour ramp (linear RGB): 0 mm blue -> cyan -> green -> yellow -> red at the scale's top.
RAMP_POSITIONS = (0.0, 0.25, 0.5, 0.75, 1.0)
RAMP_COLORS = ((0.0, 0.05, 1.0), (0.0, 0.8, 1.0), (0.0, 1.0, 0.1), (1.0, 0.9, 0.0), (1.0, 0.0, 0.0))


def vertex_error_mm(model, poses, scans) -> np.ndarray:
    """Heat map ``(V,)``: for every vertex v, the mean over ``scans (M, V, 3)`` of the distance (mm) of scan
    vertex v to the surface of ``model`` posed by ``poses`` (the rig mesh keeps the scans' vertex order).
    This is the distance the solver's ``surface_error_mm`` statistics summarise, so the heat map's mean is
    their mean."""
    posed = hybrid_skin(model, poses)
    return 1000.0 * per_vertex_scan_distances(scans, posed, model.faces).mean(axis=0)


def error_colors(values_mm, scale_mm: float) -> np.ndarray:
    """RGBA ``(V, 4)`` float32 of errors through the heat-map ramp (0 -> blue, ``scale_mm`` and above -> red)."""
    t = np.clip(np.asarray(values_mm, np.float64) / max(float(scale_mm), 1e-12), 0.0, 1.0)
    rgb = np.stack([np.interp(t, RAMP_POSITIONS, [c[i] for c in RAMP_COLORS]) for i in range(3)], axis=1)
    return np.column_stack([rgb, np.ones(len(t))]).astype(np.float32)


def add_heat_map(me, values_mm, scale_mm: float = None) -> float:
    """Write the per-vertex error (mm) as ``articula_error_mm`` and its ramp colours as
    ``articula_error_color`` (active and render colour attribute) on mesh ``me``.  Returns the ramp's
    scale in mm (default: the largest value)."""
    values = np.ascontiguousarray(values_mm, np.float32)
    if len(values) != len(me.vertices):
        raise ArticulaInputError(f"{me.name}: {len(values)} error values for {len(me.vertices)} vertices")
    scale = float(values.max()) if scale_mm is None and len(values) else float(scale_mm or 0.0)
    scale = max(scale, 1e-3)
    for name in (ERROR_ATTRIBUTE, COLOR_ATTRIBUTE):
        old = me.attributes.get(name)
        if old is not None:
            me.attributes.remove(old)
    me.attributes.new(ERROR_ATTRIBUTE, 'FLOAT', 'POINT').data.foreach_set("value", values)
    color = me.color_attributes.new(COLOR_ATTRIBUTE, 'FLOAT_COLOR', 'POINT')
    color.data.foreach_set("color", error_colors(values, scale).ravel())
    me.color_attributes.active_color = color
    me.color_attributes.render_color_index = me.color_attributes.active_color_index
    me[SCALE_PROPERTY] = scale
    return scale
