"""One frame's fit on the core: stages of terms minimised by :func:`.lm.minimise`.

A stage is a Charbonnier scale, a reach and whether the coverage term (model to capture) takes part.
A frame tracked from its predecessor's prediction fits capture-to-model pairs alone, whose minimum is
unbiased (the coverage pairs' residual runs along the noisy capture's normal, docs/track.md "Design");
a frame searched from a start hypothesis first fits coarse-to-fine with coverage (parts the capture
does not yet explain are pulled towards it, so a limb leaves the wrong surface) and ends the same way,
its small parts (fingers, toes: :func:`small_bones`) kept where the start has them: the start poses
describe the body's posture, and a finger's few points, matched while the body is centimetres off,
pull it onto a surface it cannot leave (tracking fits them from there).  Every stage also holds the
pose near ``target`` along the directions the data barely constrain (:func:`.priors.weak_directions`)
and adds the caller's priors.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from .lm import State, Stopping, minimise
from .priors import TowardPose, toward_bones, weak_directions
from .terms import ModelToScan, Sample, ScanToModel, sample


@dataclasses.dataclass(frozen=True)
class Stage:
    """eps: Charbonnier scale (m); reach: pairs farther than this are left out (m); coverage: weight of
    the model-to-capture term (0: none); iterations: at most this many linearisations; guided: the
    caller's priors take part (a pose prior guides a search, and biases the minimum it ends in);
    rel_energy: the stage ends when a step lowers the energy by less than this share (a coarse stage
    only brings the pose near, the next one converges); small_held: the bones of small parts (fingers,
    toes: :func:`small_bones`) stay at the start (while the body is centimetres off, their few points
    pull them onto surfaces they cannot leave later); quiet: the weak directions' hold follows the
    capture's noise (:func:`noise_share`; a converging stage: a coarse one keeps the full hold, which
    keeps weak parts off wrong surfaces while the body is still off)."""
    eps: float
    reach: float
    coverage: float
    iterations: int
    guided: bool = True
    rel_energy: float = 1e-4
    small_held: bool = False
    quiet: bool = False


TRACKING = (Stage(0.01, 0.1, 0.0, 8, rel_energy=1e-3), Stage(0.002, 0.05, 0.0, 12, quiet=True))
NOISE_REF = 1e-3        # capture noise (m) at which a quiet stage holds its weak directions fully ...
QUIET_FLOOR = 1e-2      # ... and the least share of that hold it keeps on noise-free captures
SEARCH_HOLD = 1e-6      # weak-direction ratio of a searched frame: only what the data cannot see is held
SEARCH = (Stage(0.02, 0.25, 1.0, 12, small_held=True), Stage(0.006, 0.08, 1.0, 10, small_held=True),
          Stage(0.002, 0.04, 0.0, 12, guided=False, small_held=True))
SMALL_SHARE = 0.025     # a bone whose subtree holds less than this share of the vertices is a small part's
END_SHARE = 0.06        # an end chain (a toe, a finger) anchors less than this share of the vertices


@dataclasses.dataclass(frozen=True)
class FrameSettings:
    """samples: capture points used per frame (a fixed seeded sample); coverage_vertices: model vertices
    of the coverage term (spread); weak_ratio: eigenvalues of the data's normal matrix below this share
    of the largest are held towards the target (:func:`.priors.weak_directions`); hold: weight of a
    pull towards the target on every parameter, relative to the largest eigenvalue (0: none)."""
    samples: int = 4000
    coverage_vertices: int = 1500
    weak_ratio: float = 1e-5
    hold: float = 0.0
    step_rad: float = 2e-4
    step_m: float = 5e-5


@dataclasses.dataclass
class FrameFit:
    """The fitted pose (one frame), its data energy per capture point (m^2), linearisations used."""
    pose: object
    energy: float
    iterations: int
    state: State


def fit_frame(body, points, normals, start, target=None, priors=(), stages=TRACKING,
              settings: FrameSettings = FrameSettings(), cancel=None, seed: int = 0, weak_ratio=None,
              slot=0, noise=None) -> FrameFit:
    """Fit one frame of capture ``points``/``normals`` ``(N, 3)`` from ``start`` (Poses, one frame);
    ``target``: the pose the weak directions are held to (default ``start``); ``priors``: extra terms;
    ``weak_ratio``: of the hold (default ``settings.weak_ratio``; a start that is only a guess, as a
    searched frame's, should hold little: :data:`SEARCH_HOLD`); ``slot``: where the body keeps the fit's
    Jacobian (:meth:`.body.Body.jacobian_near`; fits running side by side need their own); ``noise``:
    the capture's noise (m, along the normal; None: unknown), which scales the hold of quiet stages."""
    target = start if target is None else target
    ratio = settings.weak_ratio if weak_ratio is None else weak_ratio
    spread = sample(body.model.num_vertices, settings.coverage_vertices, seed + 1)
    shared = Sample(points, normals, settings.samples, seed)           # closest points found once per state
    at, used, H, hold, largest = State(body, start, slot), 0, None, None, 0.0
    for stage in stages:
        data = [ScanToModel(points, normals, eps=stage.eps, reach=stage.reach, shared=shared)]
        if stage.coverage:
            data.append(ModelToScan(points, normals, spread, stage.eps, stage.reach, weight=stage.coverage))
        if H is None:               # from the finest stage's pairs at the start (see docs/track.md "Design")
            last = stages[-1]
            H, largest = _curvature(body, at, [ScanToModel(points, normals, eps=last.eps, reach=last.reach,
                                                           shared=shared)])
            hold = TowardPose(target, _weight(H, ratio, largest, settings))
        elif priors and not stage.guided:     # what the priors decided where the data are weak is kept
            hold = TowardPose(at.pose, hold.W)
        if stage.quiet and noise is not None:
            hold = TowardPose(hold.target, _weight(H, ratio * noise_share(noise), largest, settings))
        held = [_small_held(body, start, largest)] if stage.small_held else []
        fit = minimise(body, at, data + [hold] + held + (list(priors) if stage.guided else []),
                       Stopping(stage.iterations, settings.step_rad, settings.step_m, stage.rel_energy), cancel)
        at, used = fit.data, used + fit.iterations
    final = data[0].energy(body, fit.data)
    return FrameFit(fit.pose, final, used, fit.data)


def small_bones(model, share: float = SMALL_SHARE) -> np.ndarray:
    """Bones (indices, sorted) of small parts branching off a larger one, and everything below them: a
    bone whose subtree anchors fewer than ``share`` of the model's vertices and under a quarter of its
    parent's subtree (fingers off a hand; a coarse learned rig's hand, a third of its forearm's subtree,
    is no such part).  Any rig: by vertex counts, not names."""
    parents = model.skeleton.parents
    count = np.bincount(model.anchor, minlength=len(parents)).astype(float)
    for b in range(len(parents) - 1, 0, -1):             # parents[b] < b: children before their parents
        if parents[b] >= 0:
            count[parents[b]] += count[b]
    small = np.zeros(len(parents), bool)
    for b in range(1, len(parents)):                     # parents first
        p = parents[b]
        small[b] = p >= 0 and (small[p] or (count[b] < share * model.num_vertices and count[b] < 0.25 * count[p]))
    return np.flatnonzero(small)


def end_chains(model, share: float = END_SHARE) -> list:
    """The rig's end chains, each an array of bone indices (the leaf first): the unbranched chains that end
    a branch of the skeleton (a finger, a toe, a head on its neck) whose bones together anchor fewer than
    ``share`` of the model's vertices (none counts: a learned rig's foot anchoring no vertex can still
    move a thousand by its swing weights).  Any rig: by the hierarchy and vertex counts, not names."""
    parents = model.skeleton.parents
    B = len(parents)
    children = np.bincount(parents[parents >= 0], minlength=B)
    count = np.bincount(model.anchor, minlength=B).astype(float)
    out = []
    for leaf in np.flatnonzero(children == 0):
        chain, b, total = [], leaf, 0.0
        while b >= 0 and children[b] <= 1 and parents[b] >= 0 and total + count[b] < share * model.num_vertices:
            chain.append(b)
            total += count[b]
            b = parents[b]
        if chain:
            out.append(np.array(chain, dtype=int))
    return out


def _small_held(body, start, largest):
    """A pull keeping the small parts' bones at ``start``, weighing 1 % of the data's ``largest``
    curvature (a finger's own is ~1e-5 of it: firm, and the system stays well conditioned)."""
    return toward_bones(start, body.size, small_bones(body.model), 1e-2 * largest)


def noise_share(noise: float) -> float:
    """The share of the weak directions' hold a quiet stage keeps on captures of ``noise`` (m):
    ``(noise / NOISE_REF)^2`` within ``[QUIET_FLOOR, 1]``.  The data term sums squared distances
    unweighted, so a prior's weight against it grows with the noise variance; on noise-free captures
    the full hold pulled the exact model's fingers 3-4 mm towards the lagging hold target
    (docs/track.md "7 Dec, day"); none at all lets a fingertip turn about its own axis unseen."""
    return float(np.clip((noise / NOISE_REF) ** 2, QUIET_FLOOR, 1.0))


def capture_noise(medians):
    """The captures' noise (m, a standard deviation along the surface normal) from fitted frames' median
    capture-to-model distances ``medians`` (mm; None entries skipped): the median of a normal's absolute
    value is 0.6745 of its standard deviation (a model that is not the subject's reads as noisier); None
    without any."""
    known = [m for m in medians if m is not None]
    return float(np.median(known)) * 1e-3 / 0.6745 if known else None


def _curvature(body, state, data):
    """``(H (P, P), largest)``: the data's normal matrix at ``state`` and its largest eigenvalue (the
    scale of the pulls)."""
    H = state.linearise(body, data).H
    return H, float(np.linalg.eigvalsh(H)[-1])


def _weight(H, ratio, largest, settings):
    """The hold's weight: the weak directions of ``H`` below ``ratio`` of its largest curvature
    (:func:`.priors.weak_directions`), plus ``settings.hold`` of it on every parameter."""
    W = weak_directions(H, ratio)
    if settings.hold:
        W = W + settings.hold * largest * np.eye(len(W))
    return W
