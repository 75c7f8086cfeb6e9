"""MPFB/MakeHuman rigs as plain bone arrays on a MakeHuman body (no bpy): retargeting targets with
MakeHuman's own A-pose rest, bone names and rolls.  Lengths in metres, Z up, the body facing −Y."""
from __future__ import annotations

import numpy as np

from .makehuman import load_base_mesh, shaped_vertices
from .mpfb_rig import load_rig, place_joints


def rig_bones(rig: str, shape: dict | None = None) -> dict:
    """``{names, parents, heads, tails, rolls}`` of MPFB rig ``rig`` ('default', 'game_engine', 'cmu_mb',
    'mixamo') placed on the MakeHuman body of ``shape`` (macro values; None = the average body).  Names are
    the rig file's own (``thigh_l``, ``mixamorig:Hips``, ``upperarm01.L``)."""
    spec = load_rig(rig)
    heads, tails = place_joints(spec, shaped_vertices(shape), load_base_mesh())
    short = np.linalg.norm(tails - heads, axis=1) < 1e-4
    tails[short] = heads[short] + [0.0, 0.0, 0.01]
    return {"names": list(spec.source_names), "parents": np.asarray(spec.parents), "heads": heads,
            "tails": tails, "rolls": np.asarray(spec.rolls, dtype=np.float64)}
