"""The skeleton's tree as the limb searches of both trackers walk it: each bone's depth, each bone's
subtree, and the directions a bone is tried in (a Fibonacci sphere)."""
from __future__ import annotations

import numpy as np


def bone_depths(parents):
    """``(B,)`` depth of every bone in the tree (roots 0); parents listed before their children."""
    depth = np.zeros(len(parents), dtype=np.int64)
    for b, p in enumerate(parents):
        depth[b] = 0 if p < 0 else depth[p] + 1
    return depth


def subtrees(parents) -> list:
    """``[bones of b's subtree]`` for every bone (b first); parents listed before their children."""
    out = [[b] for b in range(len(parents))]
    for b in range(len(parents) - 1, 0, -1):
        out[parents[b]].extend(out[b])
    return out


def sphere_directions(n: int) -> np.ndarray:
    """``(n, 3)`` unit vectors spread evenly over the sphere (Fibonacci lattice)."""
    k = np.arange(n) + 0.5
    z = 1.0 - 2.0 * k / n
    phi = np.pi * (1.0 + np.sqrt(5.0)) * k
    rho = np.sqrt(1.0 - z * z)
    return np.stack([rho * np.cos(phi), rho * np.sin(phi), z], axis=1)
