"""Frames fitted together in overlapping windows with a temporal term (model-adaptive mocap
dissertation §4.1.5, Eq. 4.9-4.10, on the core's terms).

A window of consecutive tracked frames is one Levenberg–Marquardt problem over all their parameters:
each frame's capture-to-model term (:class:`.terms.ScanToModel`) gives a diagonal block, and the
temporal term ``w/2 sum_n |a_n|^2`` couples neighbours, with ``a_n`` the second difference of the
frames' parameters (root translation; per bone ``log(q_{n}^-1 q_{n+1}) - log(q_{n-1}^-1 q_n)``, zero for
constant velocity).  Its weight is ``w_temp`` times the frames' largest data curvature, so it decides
only the directions the data leave free.  Each frame is also held to its start (pass 1's pose) along
its data's weak directions at a tenth of the frame fit's ratio: the second differences leave an offset
shared by all frames of a window free, and without the hold fingers and twists wandered 0.1-0.3 rad
from where pass 1 left them (docs/track.md "Windows").

Windows are anchored at input frame numbers (a window starts where the input frame number is a multiple
of ``step``), and each frame keeps the pose of the window it is most central in (its report entry's
``window``: first and last input frame): a frame's result depends on its own window's data and pass-1
poses only (a Jacobian held from an earlier window is kept only when it was evaluated at the frame's
start), so a chunk of a recording gives what one run gives where it has the same window
(:func:`solver.track.merge.same_windows`, docs/track.md "7 Dec").
"""
from __future__ import annotations

import numpy as np

from ..geometry.rotations import quat_conj, quat_mul, quat_to_rotvec
from ..parallel import map_pieces
from .frame import capture_noise, noise_share
from .lm import State, Stopping, damped_step, small_step
from .priors import TowardPose, weak_directions
from .terms import ScanToModel

FINAL_EPS = 0.002       # Charbonnier scale of the windows' data term (m), as the frame fit's last stage
FINAL_REACH = 0.04
WINDOW_HOLD = 0.1       # frames held to their starts along weak directions at this share of the frame ratio
WINDOW_ITERATIONS = 4   # linearisations per window: the first window of a run started by the search needs
                        # them all to settle (docs/track.md "7 Dec, afternoon")
WINDOW_STOP = Stopping(step_rad=5e-4, step_m=1e-4, rel_energy=1e-3)   # every frame's step below these, or a
                                                   # step lowering the energy by less than this share, ends it


def schedule(frames, numbers, size: int, step: int) -> list:
    """Windows (lists of positions into ``frames``, consecutive) over the tracked ``frames`` whose
    input frame numbers are ``numbers``: one starting at every frame whose number is a multiple of
    ``step`` (and at the first), ``size`` frames long; the last one ends at the last frame."""
    n = len(frames)
    if n <= size:
        return [list(range(n))]
    starts = [k for k in range(n) if k == 0 or numbers[k] % step == 0]
    out = []
    for s in starts:
        s = min(s, n - size)
        if not out or out[-1][0] != s:
            out.append(list(range(s, s + size)))
        if s == n - size:
            break
    return out


def owner(windows, n: int) -> list:
    """For each position 0..n-1 the window it is most central in (ties: the earlier window)."""
    best = [None] * n
    for w, win in enumerate(windows):
        centre = 0.5 * (win[0] + win[-1])
        for k in win:
            d = abs(k - centre)
            if best[k] is None or d < best[k][0] - 1e-9:
                best[k] = (d, w)
    return [b[1] for b in best]


def fit_windows(body, rec, poses: dict, frames, options, settings, say=None) -> dict:
    """``{frame: pose}`` of ``frames`` (sorted tracked frames of ``rec`` with poses in ``poses``)
    refined in windows (module docstring)."""
    numbers = [rec.range[i] for i in frames]
    windows = schedule(frames, numbers, options.window, options.step)
    keep = owner(windows, len(frames))
    out = dict(poses)
    for w, win in enumerate(windows):
        mine = [k for k in win if keep[k] == w]
        if not mine:
            continue
        idx = [frames[k] for k in win]
        body.forget(keep={("frame", i) for i in idx if body.holds_at(("frame", i), poses[i])})
        noise = capture_noise([rec.entries[i].get("median_mm") for i in idx])
        fitted = fit_window(body, [rec.capture(i) for i in idx], [poses[i] for i in idx], options.w_temp,
                            settings, slots=[("frame", i) for i in idx], noise=noise)
        for k in mine:
            out[frames[k]] = fitted[win.index(k)]
            rec.entries[frames[k]]["window"] = [int(numbers[win[0]]), int(numbers[win[-1]])]
        if say is not None:
            say((w + 1) / len(windows))
    body.forget()
    return out


def fit_window(body, captures, starts, w_temp: float, settings, iterations: int = WINDOW_ITERATIONS, slots=None,
               noise=None) -> list:
    """One window: the frames' poses (list of one-frame Poses) fitted together from ``starts``;
    ``slots``: the frames' keys for held Jacobians (:meth:`.body.Body.jacobian_near`).  Each frame is
    held to its start along its data's weak directions, as in the frame fit (the temporal term sees
    second differences only: an offset shared by the window's frames is free without it).  Both priors
    weigh :func:`.frame.noise_share` of themselves for captures of ``noise`` (m; None: unknown, all)."""
    data = [ScanToModel(c.points, c.normals, settings.samples, FINAL_EPS, FINAL_REACH, seed=k)
            for k, c in enumerate(captures)]
    slots = slots or [("window", k) for k in range(len(starts))]
    P, n = body.size, len(starts)

    def started(k):
        state = State(body, starts[k], slots[k])
        return state, data[k].linearise(body, state)

    states, lins = map(list, zip(*map_pieces(started, range(n))))
    share = 1.0 if noise is None else noise_share(noise)
    weight = share * w_temp * float(np.mean([np.linalg.eigvalsh(l.H)[-1] for l in lins]))
    terms = [[t, TowardPose(s.pose, weak_directions(l.H, share * WINDOW_HOLD * settings.weak_ratio))]
             for t, s, l in zip(data, states, lins)]
    lins = [l + hold.linearise(body, s) for l, (_, hold), s in zip(lins, terms, states)]
    energy = sum(l.energy for l in lins) + temporal_energy(states, weight)
    mu = 1e-4
    for _ in range(iterations):
        H, g = _system(lins, states, weight, P)
        step = damped_step(H, g, mu).reshape(n, P)

        def tried(k):
            state = State(body, body.moved(states[k].pose, step[k]), states[k].slot)
            return state, state.energy(body, terms[k])

        trial, energies = map(list, zip(*map_pieces(tried, range(n))))
        e_trial = sum(energies) + temporal_energy(trial, weight)
        if e_trial < energy:
            done = (all(small_step(d, WINDOW_STOP) for d in step)
                    or energy - e_trial <= WINDOW_STOP.rel_energy * energy)
            states, energy, mu = trial, e_trial, mu / 3.0
            if done:
                break
            lins = map_pieces(lambda k: states[k].linearise(body, terms[k]), range(n))
            energy = sum(l.energy for l in lins) + temporal_energy(states, weight)
        else:
            mu *= 4.0
            if mu > 1e4:
                break
    return [s.pose for s in states]


def second_differences(states) -> np.ndarray:
    """``(n-2, P)`` second differences of the frames' parameters (module docstring)."""
    rot = np.stack([s.pose.rotations[0] for s in states])
    trans = np.stack([s.pose.translations[0] for s in states])
    rel = quat_to_rotvec(_short(quat_mul(quat_conj(rot[:-1]), rot[1:])))        # (n-1, B, 3)
    vel = np.concatenate([trans[1:] - trans[:-1], rel.reshape(len(rel), -1)], axis=1)
    return vel[1:] - vel[:-1]


def _short(q):
    return np.where(q[..., :1] < 0, -q, q)


def temporal_energy(states, weight) -> float:
    if len(states) < 3 or not weight:
        return 0.0
    a = second_differences(states)
    return 0.5 * weight * float(np.sum(a * a))


def _system(lins, states, weight, P):
    """The window's normal equations: data blocks on the diagonal, the temporal term's second
    differences with unit Jacobians (each frame's increment enters its neighbours' differences)."""
    n = len(lins)
    H = np.zeros((n * P, n * P))
    g = np.zeros(n * P)
    for k, lin in enumerate(lins):
        H[k * P:(k + 1) * P, k * P:(k + 1) * P] = lin.H
        g[k * P:(k + 1) * P] = lin.g
    if n >= 3 and weight:
        a = second_differences(states)
        D = np.zeros((n - 2, n))
        for m in range(n - 2):
            D[m, m:m + 3] = (1.0, -2.0, 1.0)
        H += weight * np.kron(D.T @ D, np.eye(P))
        g += weight * (D.T @ a).ravel()
    return H, g
