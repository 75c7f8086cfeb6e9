"""Pass 2 of tracking: overlapping sliding windows of consecutive frames whose poses are optimised
jointly with the temporal prior.

Model-adaptive mocap dissertation §4.1.4 (c) and the BUFF pipeline of §4.2: after the frames were fitted
one by one (pass 1, w_temp = 0; in :mod:`.pipeline`), windows of 11 frames advancing by 5
(:func:`window_schedule`) are optimised jointly with

    Q = (1/N) Σ_n (Q_n^data + w_pose Q_n^pose) + w_temp Q^temp           (N frames of the window)

(Eq. 4.3 without the shape terms; Q^temp of :mod:`.temporal`), each window starting from the current
poses with its first frame held fixed (the last window's result), so that frames are re-optimised where
windows overlap and the motion stays continuous across them.

ICP as in :mod:`.frame_fit`: before every update the correspondences of every free frame are refreshed
(:func:`.frame_fit._refresh`), then one damped Levenberg–Marquardt update with the Armijo line search
(:func:`solver.fit.least_squares.levenberg_marquardt`) minimises, with the pairs and IRLS weights held,
``(1/N) Σ_n E_n + w_temp Σ e²``: E_n the per-frame majoriser of :class:`.frame_fit._Update` (data and
pose prior, box limits in exp-map coordinates) and e the temporal residuals.  One system holds the
parameters of all free frames: block diagonal per frame, coupled by the temporal rows (block
penta-diagonal: a second difference spans three frames), solved densely (10 free frames × 97
parameters of a 31-bone rig: about 1,000 unknowns); a DoF pushed past its box is clamped onto the bound
and leaves the system (active set), as per frame.
Stopping: relative change of Q between refreshes below ``rel_tol``, ``max_updates`` updates (the windows
start from pass-1 poses: a small budget) or ``patience`` refreshes without a new best (the best is
returned).  w_temp = 0: the frames decouple (the temporal term is never evaluated).

A frame whose capture is None or empty, or which finds no correspondences, has no data term: its pose
follows the temporal term and the prior only (its root stays where it was: Q^temp has no root term).
The frames' refreshes, normal equations and energies go to the solver's threads
(:func:`solver.parallel.map_pieces`; serial unless the caller asks for workers).
Units: metres and radians.
"""
from __future__ import annotations

import numpy as np
import scipy.linalg

from ..errors import ArticulaInputError
from .. import parallel
from ..fit.least_squares import ArmijoLineSearch, FixedRatioDamping, Limits, levenberg_marquardt, solve_damped
from ..geometry.rotations import quat_canonical, quat_normalize, quat_to_rotvec
from ..rig.model import Poses
from ..rig.skinning import AnchorGroups, check_pose_shapes
from . import frame_fit as ff
from . import temporal
from .correspondences import Correspondences
from ..tracking.pose_prior import PosePrior

WINDOW, STEP = 11, 5     # the dissertation's window length and increment (frames)
WINDOW_UPDATES = 10      # updates per window (it starts from the per-frame fits)


def window_schedule(n_frames: int, size: int = WINDOW, step: int = STEP) -> list:
    """``[(start, stop), ...]`` half-open frame ranges of the sliding windows over ``n_frames`` frames:
    starts 0, step, 2 step, ... (each window shares ``size − step`` >= 1 frames with the previous one), the
    last clipped at ``n_frames`` and the first to reach it ending the list.  (11, 5): [0, 11), [5, 16),
    [10, 21), ..."""
    for name, value in (("n_frames", n_frames), ("size", size), ("step", step)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
            raise ArticulaInputError(f"window schedule: {name} must be an integer, got {value!r}")
    if n_frames < 0 or size < 2 or not 1 <= step <= size - 1:
        raise ArticulaInputError(f"window schedule: need n_frames >= 0, size >= 2 and 1 <= step <= size - 1 "
                                 f"(windows overlap by at least one frame), got {n_frames}, {size}, {step}")
    out, start = [], 0
    while start < n_frames:
        stop = min(start + size, n_frames)
        out.append((start, stop))
        if stop == n_frames:
            break
        start += step
    return out


def _no_pairs(num_vertices) -> Correspondences:
    """Correspondences of a frame without data (no rows)."""
    empty3, empty = np.zeros((0, 3)), np.zeros(0)
    return Correspondences(np.zeros((0, 3), np.int64), empty3, empty3, empty3, np.zeros(0, bool),
                           np.zeros(0, np.int64), empty, empty, 0.0, np.zeros(num_vertices, bool),
                           {"removed_capture": 0.0, "removed_model": 0.0})


class _Window(ff.QuadraticSteps):
    """One update of the free frames of a window as a problem of the LM core (size 1): a
    :class:`.frame_fit._Update` per free frame (its pairs, IRLS weights, bounds and steps) and the
    temporal rows over all frames of the window.  Steps ``z (1, Σ P_free)``: the frames' steps in order."""
    size = 1

    def __init__(self, model, groups, frames, free, pairs, prior, w_temp, options):
        self.frames, self.free, self.w_temp, self.N = list(frames), list(free), w_temp, len(frames)
        self.updates = [ff._Update(model, groups, frames[n], p, prior, options) for n, p in zip(free, pairs)]
        self.rows = [np.flatnonzero(u.free) for u in self.updates]
        self.cuts = np.cumsum([len(r) for r in self.rows])[:-1]

    def _split(self, z):
        return np.split(z, self.cuts)

    def energy_at(self, frames):
        E = sum(parallel.map_pieces(lambda k: self.updates[k].energy_at(frames[self.free[k]]),
                                    range(len(self.free)))) / self.N
        if self.w_temp:
            E += self.w_temp * temporal.value(np.concatenate([f.rotations for f in frames]))
        return E

    def energy(self, idx):
        return np.array([self.energy_at(self.frames)])

    def build(self, idx):
        E = sum(parallel.map_pieces(lambda u: float(u.build(None)[0]), self.updates)) / self.N
        H = scipy.linalg.block_diag(*[u.H for u in self.updates]) / self.N
        g = np.concatenate([u.g for u in self.updates]) / self.N
        if self.w_temp:
            rot = np.concatenate([f.rotations for f in self.frames])
            e = temporal.residuals(rot).ravel()
            Jt = temporal.jacobian(rot).reshape(len(e), self.N, -1)
            A = np.concatenate([Jt[:, n] @ u._reparametrisation()[:, u.free]
                                for u, n in zip(self.updates, self.free)], axis=1)
            H, g, E = H + self.w_temp * A.T @ A, g + self.w_temp * A.T @ e, E + self.w_temp * float(e @ e)
        self.H, self.g = H, g
        return np.array([E])

    def _violations(self, z):
        """Per entry of ``z``: whether it takes a bounded DoF outside its interval, and the step onto it."""
        parts = [u._violations(zk, rows) for u, zk, rows in zip(self.updates, self._split(z), self.rows)]
        return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])

    def solve(self, idx, mu):
        """The damped step with the box limits as an active set (:meth:`.frame_fit._Update.solve`)."""
        z = solve_damped(self.H[None], self.g[None], mu, ff.DAMP_FLOOR)[0]
        if not any(u.bounded.any() for u in self.updates):
            return z[None]
        return ff.active_set_solve(self.H, self.g, mu, z, self._violations)[None]

    def try_steps(self, idx, steps):
        self.trial = list(self.frames)
        for u, n, zk in zip(self.updates, self.free, self._split(steps[0])):
            self.trial[n] = u.moved(zk)
        return np.array([self.energy_at(self.trial)])

    def accept(self, which):
        if which[0]:
            self.frames = self.trial
            for u, n in zip(self.updates, self.free):   # the next step starts here (bounded bones too)
                u.pose, u.r0 = self.frames[n], quat_to_rotvec(self.frames[n].rotations[0])


def _frame(poses, n, normalise=True) -> Poses:
    one = poses.take(n)
    if normalise:
        one.rotations = quat_normalize(one.rotations)
    return one


def _pairs(model, groups, frame, capture, options):
    """The frame's correspondences, or None when it has no data (no capture, no points, no pairs)."""
    if capture is None or len(capture.points) == 0:
        return None
    pairs = ff._refresh(model, groups, frame, capture, options)
    return pairs if len(pairs.distances) else None


def _check(model, captures, init, w_temp, max_updates):
    check_pose_shapes(model, init)
    init.validate(model.skeleton.num_bones)
    if len(captures) != len(init):
        raise ArticulaInputError(f"window: {len(captures)} captures for {len(init)} poses")
    if not len(init):
        raise ArticulaInputError("window: no frames")
    if not (np.isfinite(w_temp) and w_temp >= 0):
        raise ArticulaInputError(f"w_temp must be finite and >= 0, got {w_temp}")
    if isinstance(max_updates, bool) or not isinstance(max_updates, (int, np.integer)) or max_updates < 0:
        raise ArticulaInputError(f"max_updates must be an integer >= 0, got {max_updates!r}")


def fit_window(model, captures, init: Poses, fix_first: bool, prior: PosePrior = None, w_temp: float = 0.0,
               options: ff.FrameFitOptions = ff.FrameFitOptions(), groups: AnchorGroups = None,
               max_updates: int = WINDOW_UPDATES, progress=None):
    """Optimise the poses of consecutive frames jointly (module docstring).  captures: one
    :class:`.frame_fit.Capture` (or None: no data) per frame; init: their starting poses (:class:`Poses`,
    same count); fix_first: hold frame 0 exactly (its arrays are returned bit for bit); prior, options:
    as :func:`.frame_fit.fit_frame` (w_pose, fit_scale, to_plane, lm_steps, rel_tol, patience,
    line_search and the correspondence settings are used; the coarse-to-fine stages are not);
    progress: optional ``progress(fraction, text)`` after each update (fraction of ``max_updates``; may
    raise ``Cancelled``).

    Returns ``(poses, log)``: poses (:class:`Poses`, one per frame, free frames with canonical unit
    quaternions) at the best Q seen; log: per refresh ``Q``, ``data`` (mean Q^data of the free frames, m),
    ``pose`` (their mean Q^pose), ``temp`` (Q^temp of the window), ``pairs`` (over the free frames), per
    update ``trials``; ``updates``, ``converged``, ``no_data`` (window frames without data).  Q leaves out
    the fixed frame's data and prior terms (constant)."""
    _check(model, captures, init, w_temp, max_updates)
    with parallel.single_blas_thread():
        return _fit_window(model, list(captures), init, bool(fix_first), prior, float(w_temp), options,
                           groups, max_updates, progress)


def _fit_window(model, captures, init, fix_first, prior, w_temp, options, groups, budget, progress):
    """The body of :func:`fit_window`: refresh-and-update rounds until the stopping rule."""
    groups = AnchorGroups(model) if groups is None else groups
    prior = PosePrior.none(model.skeleton) if prior is None else prior
    N = len(init)
    frames = [_frame(init, n, normalise=not (fix_first and n == 0)) for n in range(N)]
    free = list(range(1 if fix_first else 0, N))
    w_pose = options.w_pose if prior.num_pairs else 0.0
    damping = FixedRatioDamping([ff.MU0], decrease=10.0, increase=10.0, mu_min=ff.MU_MIN)
    search = ArmijoLineSearch() if options.line_search else None
    log = {key: [] for key in ("Q", "data", "pose", "temp", "pairs", "trials")}
    no_data, best, stale, converged, updates = set(), None, 0, False, 0
    while free:
        pairs = parallel.map_pieces(lambda n: _pairs(model, groups, frames[n], captures[n], options), free)
        no_data |= {n for n, p in zip(free, pairs) if p is None}
        pairs = [_no_pairs(model.num_vertices) if p is None else p for p in pairs]
        rot = np.concatenate([f.rotations for f in frames])
        q_data = np.array([p.energy for p in pairs])
        q_pose = prior.value(rot[free]) if prior.num_pairs else np.zeros(len(free))
        q_temp = temporal.value(rot) if w_temp else 0.0
        Q = float((q_data.sum() + w_pose * q_pose.sum()) / N + w_temp * q_temp)
        for key, value in (("Q", Q), ("data", q_data.mean()), ("pose", q_pose.mean()), ("temp", q_temp),
                           ("pairs", sum(len(p.distances) for p in pairs))):
            log[key].append(float(value))
        if best is not None and abs(log["Q"][-2] - Q) <= options.rel_tol * log["Q"][-2]:
            converged = True
        if best is None or Q < best[0]:
            best, stale = (Q, list(frames)), 0
        else:
            stale += 1
        if converged or stale >= options.patience or updates >= budget:
            break
        window = _Window(model, groups, frames, free, pairs, prior, w_temp, options)
        out = levenberg_marquardt(window, damping, Limits(steps=options.lm_steps, rejections=ff.REJECTIONS),
                                  line_search=search)
        log["trials"].append(int(out.trials[0]))
        updates += 1
        if progress is not None:
            progress(updates / budget, f"window update {updates} of at most {budget}, Q {Q:.4g}")
        if out.steps[0] == 0:                              # no decrease even for short steps: a minimum
            converged = True
            break
        frames = window.frames
    result = frames if best is None else best[1]
    poses = Poses(np.concatenate([f.rotations if n not in free else quat_canonical(quat_normalize(f.rotations))
                                  for n, f in enumerate(result)]),
                  np.concatenate([f.translations for f in result]), np.concatenate([f.scales for f in result]))
    log = {k: np.array(v) for k, v in log.items()}
    log.update(updates=updates, converged=converged, no_data=sorted(no_data))
    return poses, log


def fit_windows(model, source, poses: Poses, prior: PosePrior = None, w_temp: float = 0.0,
                options: ff.FrameFitOptions = ff.FrameFitOptions(), progress=None, size: int = WINDOW,
                step: int = STEP, fix_start: bool = False, max_updates: int = WINDOW_UPDATES):
    """Run :func:`fit_window` over every window of :func:`window_schedule` (``size``, ``step``) of a
    sequence: source: indexable captures (``len``, ``source[i]`` -> :class:`.frame_fit.Capture` or None),
    poses: the starting poses (pass 1), one per frame.  Each window starts from the current poses (so the
    overlap carries the previous window's result) with its first frame fixed; the first window's frame 0
    only if ``fix_start``.  progress: optional ``progress(fraction, text)`` after every update and every
    window (may raise ``Cancelled``).  Returns ``(poses, logs)``: the new poses (the input is not
    modified) and one :func:`fit_window` log per window with its ``start`` and ``stop``."""
    n = len(source)
    if len(poses) != n:
        raise ArticulaInputError(f"windows: {len(poses)} poses for {n} captures")
    schedule = window_schedule(n, size, step)
    out = Poses(poses.rotations.copy(), poses.translations.copy(), poses.scales.copy())
    groups = AnchorGroups(model)
    loaded, logs = {}, []
    for w, (a, b) in enumerate(schedule):
        inner = None if progress is None else _within(progress, w, len(schedule))
        loaded = {i: loaded[i] if i in loaded else source[i] for i in range(a, b)}   # overlap loaded once
        init = Poses(out.rotations[a:b], out.translations[a:b], out.scales[a:b])
        got, log = fit_window(model, [loaded[i] for i in range(a, b)], init, fix_start or w > 0, prior, w_temp,
                              options, groups, max_updates, inner)
        out.rotations[a:b], out.translations[a:b], out.scales[a:b] = got.rotations, got.translations, got.scales
        logs.append(dict(log, start=a, stop=b))
        if progress is not None:
            progress((w + 1) / len(schedule), f"temporal windows: {w + 1} of {len(schedule)} "
                                              f"(frames {a + 1}-{b} of {n})")
    return out, logs


def _within(progress, w, count):
    """``progress`` of window w of count for the updates inside it."""
    return lambda fraction, text: progress((w + fraction) / count, f"temporal window {w + 1} of {count}: {text}")
