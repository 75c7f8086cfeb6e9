"""How well a retargeted clip follows its source: segment directions, root travel, foot sliding.

Inputs are world-space joint positions read back independently of the solver (e.g. from Blender's
evaluated pose); ``segs`` are :class:`.directions.Segment` (only those with a child joint count).
"""
from __future__ import annotations

import numpy as np


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


def travel(path: np.ndarray) -> float:
    """Horizontal path length of ``path (F, 3)`` (Z up)."""
    return float(np.linalg.norm(np.diff(path[:, :2], axis=0), axis=1).sum())


def vertical_range(path: np.ndarray) -> float:
    """Peak-to-peak height of ``path (F, 3)`` (the hip bob)."""
    return float(np.ptp(path[:, 2]))
