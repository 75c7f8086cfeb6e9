"""How well a retargeted clip follows its source: segment directions, root travel, foot sliding.

Inputs are world-space joint positions read back independently of the solver (e.g. from Blender's
evaluated pose); ``segs`` are :class:`solver.retarget.directions.Segment` (only those with a child joint
count).  Used by ``./run bench retarget`` and the retargeting tests (as ``articula.bench._retarget_metrics``).
"""
from __future__ import annotations

import numpy as np

from articula.solver.roles import NEXT


def segment_angles(segs, src_heads: np.ndarray, tgt_heads: np.ndarray) -> np.ndarray:
    """(F, S) angles (degrees) between each source segment and its target segment, per frame."""
    cols = []
    for seg in segs:
        if seg.child is None:
            continue
        a = src_heads[:, seg.source_child] - src_heads[:, seg.source]
        b = tgt_heads[:, seg.target_child] - tgt_heads[:, seg.target]
        cos = np.einsum("fi,fi->f", a, b) / np.maximum(np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1), 1e-12)
        cols.append(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))
    return np.stack(cols, axis=1) if cols else np.zeros((len(src_heads), 0))


def role_segment_angles(pairs: dict, source_index: dict, target_index: dict, src_heads: np.ndarray,
                        tgt_heads: np.ndarray, min_length: float = 1e-3, trunk: bool = True) -> dict:
    """``{'role-child': (F,) degrees}`` between the source's and the target's segment of every role to its
    first primary child (:data:`.roles.NEXT`) mapped on both rigs, whatever either rig's bone hierarchy;
    ``pairs`` = ``{role: (source bone, target bone)}``, ``*_index`` = ``{bone: index}``, heads ``(F, J, 3)``
    world; segments shorter than ``min_length`` of the rig's height on either rig have no counterpart.
    With ``trunk``, also the hips to the highest of neck/head mapped on both (``'hips-top'``: the lean)."""
    out = {}
    for role, (s, t) in pairs.items():
        child = next((c for c in NEXT.get(role, []) if c in pairs), None)
        if child is None:
            continue
        a = src_heads[:, source_index[pairs[child][0]]] - src_heads[:, source_index[s]]
        b = tgt_heads[:, target_index[pairs[child][1]]] - tgt_heads[:, target_index[t]]
        if min(_shortest(a, src_heads), _shortest(b, tgt_heads)) >= min_length:
            out[f"{role}-{child}"] = _angles(a, b)
    top = next((r for r in ("neck", "head") if r in pairs), None)
    if trunk and top and "hips" in pairs:
        ends = [(src_heads, source_index, 0), (tgt_heads, target_index, 1)]
        a, b = (h[:, i[pairs[top][k]]] - h[:, i[pairs["hips"][k]]] for h, i, k in ends)
        out["hips-top"] = _angles(a, b)
    return out


def _angles(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    cos = np.einsum("fi,fi->f", a, b) / (np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1))
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def _shortest(seg: np.ndarray, heads: np.ndarray) -> float:
    """Shortest length of ``seg (F, 3)`` over the frames, as a fraction of the rig's height in frame 0."""
    return float(np.linalg.norm(seg, axis=1).min() / max(np.ptp(heads[0], axis=0).max(), 1e-12))


def travel(path: np.ndarray) -> float:
    """Horizontal path length of ``path (F, 3)`` (Z up)."""
    return float(np.linalg.norm(np.diff(path[:, :2], axis=0), axis=1).sum())


def vertical_range(path: np.ndarray) -> float:
    """Peak-to-peak height of ``path (F, 3)`` (the hip bob)."""
    return float(np.ptp(path[:, 2]))
