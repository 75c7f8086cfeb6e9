"""The number of parts chosen from the motion: every independently moving segment, and no more.

Two phases on the cell subsample of :mod:`solver.learn.segmentation` (centred rest ``(V,3)`` and scans
``(M,V,3)``, metres):

1. the curve phase: the hierarchy splits the worst-fitting part until the rigid-fit error E(k) is at
   most 3 % of E(1) (:func:`solver.learn.segmentation.choose_num_parts`).  This finds the torso and
   limbs, but a global threshold stops before small segments whose motion carries little of the total
   error (a foot on its shin, the head on the neck, a hand on the forearm);
2. the articulation phase: a part is split further when its own residual shows two rigid motions.  For
   every part the best rigid 2-clustering of its points is tried; the split is an articulation when it
   removes at least SPLIT_GAIN of the part's squared error, the two halves rotate against each other by
   at least SPLIT_ANGLE_DEG (90th percentile over the scans, so one odd scan does not decide) and each
   half holds at least MIN_HALF_FRACTION of the mesh's vertices.  Among the parts that qualify the one
   whose split removes most error goes first; the phase ends when none qualifies or at ``k_max``.

The thresholds are scale-free (fractions and an angle), so they hold for any body size or unit.  Why
they separate: a blend zone between two bones (vertices following an interpolated motion) or skin and
soft-tissue deformation is not two rigid motions, so a 2-clustering of it removes about half of its
error (measured 0.3-0.65 on MakeHuman; docs/learn_rig_solver.md), while a segment that moves on its own
leaves rigid halves (0.8-0.96) that turn by tens of degrees.  Noise is never two rigid motions.
"""
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from .segmentation import choose_num_parts, hierarchy, part_errors, split_part, two_motions

SPLIT_GAIN = 0.75           # a split must remove this fraction of the part's squared error ...
SPLIT_ANGLE_DEG = 15.0      # ... with the halves turning this much against each other (90th percentile)
MIN_HALF_FRACTION = 0.005   # ... and each half holding this fraction of the mesh's vertices ...
MIN_HALF_POINTS = 6         # ... and this many sample points, not all on a line (else its rotation is
MIN_SPREAD = 0.05           # undetermined): second / first singular value of its rest points
ITERATIONS = 50             # rounds of the 2-clustering and of the refinement after a split


@dataclass
class Trial:
    """A part's best 2-clustering: the part, its point mask, the clustering, the fraction of the part's
    squared error it removes, the 90th-percentile angle between the halves (degrees) and the halves'
    vertex counts."""
    part: int
    mask: np.ndarray
    two: object
    gain: float
    angle_deg: float
    halves: tuple

    def qualifies(self, min_half):
        return (self.gain >= SPLIT_GAIN and self.angle_deg >= SPLIT_ANGLE_DEG
                and min(self.halves) >= min_half and self.determined)

    @cached_property
    def determined(self):
        """Both halves have enough sample points, not on a line: their rotations are determined."""
        x = self.two.points.rest_points()
        for h in (0, 1):
            xs = x[self.two.labels == h]
            if len(xs) < MIN_HALF_POINTS:
                return False
            sv = np.linalg.svd(xs - xs.mean(axis=0), compute_uv=False)
            if sv[1] < MIN_SPREAD * sv[0]:
                return False
        return True

    def as_dict(self):
        return dict(part_vertices=int(round(sum(self.halves))), halves=[int(round(h)) for h in self.halves],
                    gain=round(float(self.gain), 3), angle_deg=round(float(self.angle_deg), 1))


def relative_angles_deg(R_a, R_b):
    """Angle (degrees) of ``R_aᵀ R_b`` per scan: ``R_a``, ``R_b`` ``(M,3,3)`` rest → scan rotations of
    two parts; 0 when they move as one."""
    rel = np.einsum("mji,mjk->mik", R_a, R_b)
    return np.degrees(np.arccos(np.clip((np.trace(rel, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0)))


def trial_split(cl, part, error, rng):
    """:class:`Trial` of ``part`` of ``cl`` (:class:`solver.learn.segmentation.Clustering`) whose
    weighted squared error is ``error``; None for a part of fewer than 4 points."""
    mask = cl.labels == part
    if mask.sum() < 4:
        return None
    two = two_motions(cl, mask, rng, ITERATIONS)
    gain = 1.0 - two.total() / error if error > 0 else 0.0
    angle = float(np.percentile(relative_angles_deg(two.R[:, 0], two.R[:, 1]), 90))
    halves = tuple(np.bincount(two.labels, weights=two.points.w, minlength=2))
    return Trial(part, mask, two, gain, angle, halves)


class TrialCache:
    """Trials by the exact point set of a part: a part untouched by the refinement after a split keeps
    its trial (the 2-clustering of the same points would be redrawn otherwise)."""

    def __init__(self, rng):
        self.rng, self.trials = rng, {}

    def of(self, cl):
        """The trials of every part of ``cl`` (None for parts too small to split)."""
        errors, out, keep = part_errors(cl), [], {}
        for p in range(cl.k):
            key = np.flatnonzero(cl.labels == p).tobytes()
            trial = self.trials.get(key)
            if trial is None:
                trial = trial_split(cl, p, errors[p], self.rng)
            else:
                trial.part, trial.mask = p, cl.labels == p
            keep[key] = trial
            out.append(trial)
        self.trials = keep
        return out


def articulated_parts(rest, scans, faces, k_max=20, seed=0, progress=None):
    """Parts of the motion by the two phases of the module docstring.  Centred ``rest (V,3)``, ``scans
    (M,V,3)`` (metres).  Returns ``(clustering, info)``: the sample
    :class:`solver.learn.segmentation.Clustering` (its ``R``, ``t`` start the full-resolution
    segmentation) and a JSON-able dict: ``curve_mm`` (E(k) of the curve phase), ``curve_parts`` (its
    choice), ``splits`` (each articulation split: vertices, halves, gain, angle), ``parts`` and
    ``reason`` (why the count stopped there).  ``progress(fraction, stage, None)`` as the phases go."""
    sub = None if progress is None else (lambda f, text, obj: progress(0.5 * f, text, obj))
    k0, curve = choose_num_parts(rest, scans, faces, k_max=k_max, seed=seed, progress=sub)
    cl = None
    for _, cl in hierarchy(rest, scans, k0, seed):
        pass
    min_half = MIN_HALF_FRACTION * len(rest)
    cache, splits = TrialCache(np.random.default_rng(seed + 1)), []
    reason = f"the most parts allowed (k_max = {k_max})"
    while cl.k < k_max:
        if progress is not None:
            progress(0.5 + 0.5 * cl.k / k_max, f"looking for segments that move on their own ({cl.k} parts)", None)
        trials = [t for t in cache.of(cl) if t is not None and t.qualifies(min_half)]
        if not trials:
            reason = (f"no part's residual shows two rigid motions (a split removing >= {SPLIT_GAIN:.0%} of a "
                      f"part's error, halves turning >= {SPLIT_ANGLE_DEG:g} deg)")
            break
        errors = part_errors(cl)
        best = max(trials, key=lambda t: t.gain * errors[t.part])
        splits.append(best.as_dict())
        split_part(cl, best.mask, best.two, ITERATIONS)
    info = dict(curve_mm=(np.asarray(curve) * 1e3).tolist(), curve_parts=int(k0), splits=splits,
                parts=int(cl.k), reason=reason)
    return cl, info

