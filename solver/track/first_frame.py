"""The pose of a frame with nothing to start from: the first frame, or a frame whose fit was lost.

Start hypotheses from the broad pose set in any world orientation (:func:`solver.tracking.start_search.
start_hypotheses`), from the capture's geodesic extremities and rings (:func:`solver.tracking.
geodesic_starts.geodesic_starts`) and the rest pose at the capture for a human body, rest poses turned onto the
capture's principal axes for any other rig (:func:`turned_rests`), plus the caller's own (the user's
start pose, the last good pose), each fitted with the coarse stage of the core's search
(:data:`solver.tracking.frame.SEARCH`), the best ``KEEP`` by :func:`coverage_score` through the finer
stages, the pose prior guiding the limbs; the fit that leaves the least of the capture and of the
model unexplained wins; its forearms and feet are tried turned about their own axis (:func:`_twisted`), a
hand turned over its forearm untwisted or at rest and a foot bent far at rest (:func:`_ends_put_back`), its end chains
(toes, fingers) at rest, whole and one by one (:func:`_ends_at_rest`), and its last stage is run again
while that improves it (:func:`_settled`).  When the truth-free checks
call every such fit lost, the limbs of the best lost fits are aimed at the capture regions they leave
unexplained (:func:`solver.tracking.aimed_starts.aimed_starts`: a forearm folded onto the belly while the
capture's hangs by the thigh) and those starts fitted too (:func:`_aimed`); if all are still lost, the
best whose trunk or hinges are beyond their limits are put right (hips turned half round under the chest
with the legs swapped, a body facing away, an elbow bent backwards under an upper arm turned half round:
:func:`_put_right`).  Independent fits run on the solver's threads, each with its own Jacobian slot.
"""
from __future__ import annotations

import dataclasses

import numpy as np
from scipy.spatial import cKDTree

from ..errors import ArticulaInputError
from ..parallel import map_pieces, workers
from ..rig.model import Poses
from ..tracking.aimed_starts import aimed_starts
from ..tracking.checks import check_frame
from ..tracking.geodesic_starts import geodesic_starts
from ..tracking.hinge_starts import flipped_hinge_start
from ..tracking.joint_limits import signed_twist
from ..tracking.lm import State
from ..tracking.frame import SEARCH, SEARCH_HOLD, FrameSettings, end_chains, fit_frame
from ..geometry.rotations import (matrix_to_quat, quat_mul, quat_to_matrix, quat_to_rotvec, rotvec_to_matrix,
                                  rotvec_to_quat)
from ..roles import role_bones
from ..tracking.start_poses import REQUIRED, subtree_masks
from ..tracking.start_search import start_hypotheses
from ..tracking.terms import ModelToScan, ScanToModel, charbonnier, sample
from ..tracking.trunk_starts import turned_round_start, untwisted_starts

SIZE_RATIO = (0.4, 2.5)  # a capture's extent (1st-99th percentile) over the model's height outside this is refused
KEEP = 2                # starts fitted to the end after the coarse stage
SCORE_EPS = 0.01        # Charbonnier scale of the score (m): a limb in the wrong place counts fully
SCORE_REACH = 0.2       # pairs farther than this count as this far (m)
FINE_EPS = 0.002        # Charbonnier scale of the capture score (m): that of the tracking stage
LOST_PENALTY = 2.0      # a fit the checks call lost ranks as if its score were this many times higher
SETTLE_RUNS = 3         # the winner's last stage is run again at most this often ...
SETTLE_GAIN = 0.05      # ... while each run lowers its coverage score by this share
AIM_ROUNDS = 2          # lost fits' unexplained capture is aimed at by their limbs this often at most,
AIM_FITS = 3            # ... from the best this many lost fits
AIM_REGIONS = 2         # ... at their largest this many regions,
AIM_KEEP = 4            # ... the aimed starts with the best unfitted coverage score fitted
CHAIN_REACH = 0.02      # capture points this near an end chain (m) judge how it is turned
CHAIN_SLACK = 0.05      # the chains' own judgement stands unless the whole-body score rises by this share
TWISTED = ("forearm.L", "forearm.R", "foot.L", "foot.R")      # the winner's segments tried turned about
TWISTS = (-0.5 * np.pi, 0.5 * np.pi, np.pi)                      # their own axis by these angles (rad)
HAND_TWIST = np.pi / 6      # a winner's hand turned further than this about its forearm is tried untwisted (rad)
FOOT_TURN = np.pi / 3       # ... and a foot turned further than this from its rest on the lower leg at rest


def check_units(model, points) -> None:
    """Refuse captures whose extent is not that of the model's body (``SIZE_RATIO``), naming both sizes:
    a capture in millimetres or centimetres against a model in metres is the usual cause."""
    if len(points) < 3:
        return
    lo, hi = np.percentile(points, [1, 99], axis=0)
    capture = float(np.max(hi - lo))
    body = float(np.ptp(model.rest_vertices, axis=0).max())
    ratio = capture / max(body, 1e-12)
    if not SIZE_RATIO[0] <= ratio <= SIZE_RATIO[1]:
        hint = ""
        for factor, unit in ((1000.0, "millimetres"), (100.0, "centimetres"), (1 / 0.0254, "inches")):
            if abs(np.log(ratio / factor)) < 0.7:
                hint = f" (about {factor:.4g}x: are the captures in {unit} and the model in metres?)"
        raise ArticulaInputError(f"captures and model differ in size: the capture spans {capture:.4g} units, "
                                 f"the model is {body:.4g} m tall{hint}; bring both to metres before tracking")


def find_pose(body, capture, priors=(), extra=(), count: int = 4, settings: FrameSettings = FrameSettings(),
              cancel=None, checked=None):
    """``(pose, score, candidates tried)``: the best fitted start on ``capture`` (module docstring);
    ``extra``: more one-frame Poses to try; ``count``: hypotheses from the pose set; ``checked``: the
    model prepared for :func:`solver.tracking.checks.check_frame`: a fit that fails the checks ranks after
    those that pass unless they explain the capture clearly worse (``LOST_PENALTY``: a subject touching
    itself fails the checks in its true pose), and while the best fails them the next coarse candidates
    are fitted too."""
    if humanoid(body.model.skeleton):
        starts = [pose for pose, _ in start_hypotheses(body.model, capture.points, capture.normals,
                                                       count=count)] + [centred_rest(body.model, capture.points)]
        starts += geodesic_starts(body.model, capture.points, capture.normals)
    else:
        starts = turned_rests(body.model, capture.points)
    starts += list(extra)

    def coarse_fit(item):
        fit = _fit(body, capture, item[1], priors, SEARCH[:1], settings, cancel, slot=("start", item[0]))
        return coverage_score(body, capture, fit.state), fit.pose

    coarse = sorted(map_pieces(coarse_fit, enumerate(starts)), key=lambda item: item[0])

    def fine_fit(item, stages=SEARCH[1:]):
        fit = _fit(body, capture, item[1], priors, stages, settings, cancel, slot=("start", item[0]))
        check = None if checked is None else check_frame(body.model, fit.pose, fit.state.posed, capture, checked)
        return fit.pose, coverage_score(body, capture, fit.state), int(_lost(check)), check

    fits = map_pieces(fine_fit, enumerate(pose for _, pose in coarse[:KEEP]))
    fits += _while_lost(fits, fine_fit, list(enumerate((pose for _, pose in coarse[KEEP:]), KEEP)))
    start_score = lambda start: coverage_score(body, capture, State(body, start))
    fits = _aimed(body.model, fits, fine_fit, start_score, len(starts))
    full_fit = lambda item: fine_fit(item, SEARCH)
    slot = len(starts) + AIM_ROUNDS * AIM_KEEP
    fits += _put_right(body.model, fits, full_fit, checked, slot)
    pose, score = _finished(body, capture, _ranked(fits)[0], priors, settings, cancel)
    if checked is not None:              # the finishing turns can bend a joint beyond its limits again
        check = check_frame(body.model, pose, State(body, pose).posed, capture, checked)
        final = (pose, score, int(_lost(check)), check)
        more = _put_right(body.model, [final], full_fit, checked, slot)
        if more and _penalised(_ranked(more)[0]) < _penalised(final):
            pose, score = _finished(body, capture, _ranked(more)[0], priors, settings, cancel)
    return pose, score, len(starts)


def _finished(body, capture, fit, priors, settings, cancel):
    """``(pose, score)`` of a ranked fit ``(pose, score, lost, check)`` after the finishing turns: forearms
    and feet about their axes, hands untwisted and feet put back, end chains at rest, the last stage settled."""
    pose, score = _twisted(body, capture, fit[0], fit[1], priors, settings, cancel)
    pose, score = _ends_put_back(body, capture, pose, score, priors, settings, cancel)
    return _settled(body, capture, pose, score, priors, settings, cancel)


def _while_lost(fits, fine_fit, items) -> list:
    """The fits of ``items`` (``(slot, start)``) taken in order while the best of ``fits`` and those before
    is lost: what fitting them one by one would keep, fitted as many at a time as the solver has threads
    (those after the first that passes are dropped)."""
    out, batch = [], max(1, workers())
    for k in range(0, len(items), batch):
        if not _ranked(fits + out)[0][2]:
            break
        for fit in map_pieces(fine_fit, items[k:k + batch]):
            out.append(fit)
            if not _ranked(fits + out)[0][2]:
                break
    return out


def _put_right(model, fits, full_fit, checked, slot) -> list:
    """While the best of ``fits`` is lost: the fits (``full_fit((slot, start))``, every search stage) of
    the starts made from the best ``AIM_FITS`` fits whose checks found a joint beyond its limits: hips
    twisted from the chest turned back under it (:func:`solver.tracking.trunk_starts.untwisted_starts`),
    a chest bent backwards turned round (:func:`solver.tracking.trunk_starts.turned_round_start`), a knee
    or elbow bent backwards bent the other way (:func:`solver.tracking.hinge_starts.flipped_hinge_start`:
    a tilted capture's reach fitted with the upper arm half round and the elbow 65 deg backwards, 14 mm
    off; from the flipped start 1.7 mm)."""
    if checked is None or not _ranked(fits)[0][2]:
        return []
    hinges = {h.name: h for h in checked.hinges}
    starts = []
    for fit in _ranked(fits)[:AIM_FITS]:
        numbers = [f.numbers for f in (fit[3].findings if fit[3] is not None else ())]
        found = {n.get("joint") for n in numbers}
        if "trunk twist" in found and checked.trunk is not None:
            starts += untwisted_starts(model, fit[0], checked.trunk)
        if "trunk back" in found and checked.trunk is not None:
            starts.append(turned_round_start(model, fit[0], checked.trunk))
        starts += [flipped_hinge_start(model, fit[0], hinges[n["joint"]]) for n in numbers
                   if n.get("bend") == "backwards" and n.get("joint") in hinges]
    return map_pieces(full_fit, enumerate(starts, slot))


def _aimed(model, fits, fine_fit, start_score, slot) -> list:
    """``fits`` and, while the best is lost (at most ``AIM_ROUNDS`` times), the fits of the starts that aim
    the limbs of the best ``AIM_FITS`` lost fits at the capture they leave unexplained, the ``AIM_KEEP``
    best of them by ``start_score(start)`` (a round's are kept when they beat every fit so far, and the
    next round aims from them).  ``fine_fit((slot, start))`` fits a start; fits are ``(pose, score,
    lost, check)``."""
    sources = fits
    for _ in range(AIM_ROUNDS):
        if not _ranked(fits)[0][2]:
            break
        aimed = [a for fit in _ranked(sources)[:AIM_FITS] if fit[2]
                 for a in aimed_starts(model, fit[0], unexplained_centres(fit[3]))]
        aimed = sorted(aimed, key=start_score)[:AIM_KEEP]
        more = map_pieces(fine_fit, enumerate(aimed, slot))
        slot += len(aimed)
        if not more or _penalised(_ranked(more)[0]) >= _penalised(_ranked(fits)[0]):
            break
        fits, sources = fits + more, more
    return fits


def _ranked(fits) -> list:
    """Fitted starts ``(pose, score, lost, check)`` best first by :func:`_penalised` (stable)."""
    return sorted(fits, key=_penalised)


def _penalised(fit) -> float:
    """A fit's coverage score, times ``LOST_PENALTY`` when the checks call it lost."""
    return fit[1] * LOST_PENALTY ** fit[2]


def _twisted(body, capture, pose, score, priors, settings, cancel):
    """``(pose, score)``: ``pose``, or its fit through the finer search stages with a forearm or a foot (by
    role, :data:`TWISTED`) turned about its own axis by one of :data:`TWISTS` when that explains the capture
    better (the segments turned as their best fits, fitted once more, when several are).  A forearm with
    its hand is near a cylinder: a learned rig's two forearms ended turned 90-180 deg with the hands 50-77
    mm off, while the turned fits scored 24-28 % lower: the score knew, the search had not tried.  A foot
    turned upside down about its ankle-to-toe line leaves little of a clean capture unexplained (the
    reach's right foot, 78 mm off after the legs were swapped back; turned, the frame 5.4 -> 1.0 mm)."""
    roles = role_bones(body.model.skeleton.names)
    starts = [(roles[r], _turned(pose, roles[r], angle)) for r in TWISTED if r in roles for angle in TWISTS]

    def fitted(item):
        k, (bone, start) = item
        fit = _fit(body, capture, start, priors, SEARCH[1:], settings, cancel, slot=("twist", k))
        return bone, fit.pose, coverage_score(body, capture, fit.state)

    best = {}
    for bone, fit, again in map_pieces(fitted, enumerate(starts)):
        if again < best.get(bone, (None, score))[1]:
            best[bone] = (fit, again)
    if not best:
        return pose, score
    winner = min(best.values(), key=lambda c: c[1])
    if len(best) == 1:
        return winner
    below = subtree_masks(body.model.skeleton.parents)
    both = pose.rotations.copy()
    for bone, (fit, _) in best.items():
        both[:, below[bone]] = fit.rotations[:, below[bone]]
    fit = _fit(body, capture, Poses(both, winner[0].translations, winner[0].scales), priors, SEARCH[1:], settings,
               cancel)
    return min(winner, (fit.pose, coverage_score(body, capture, fit.state)), key=lambda c: c[1])


def _ends_put_back(body, capture, pose, score, priors, settings, cancel):
    """``(pose, score)``: ``pose``, with each hand in turn that is turned further than :data:`HAND_TWIST`
    about its forearm's rest direction tried untwisted (that twist taken out of its local rotation) and at
    rest, and each foot turned further than :data:`FOOT_TURN` from its rest on the lower leg tried at rest,
    each fitted through the finer search stages and kept when it explains the capture better by the
    capture-to-model score (:func:`capture_score`; the coverage score's model-to-capture half counts true
    fingers hidden between a hand and a thigh against the truth: an own-model walk's hand 37 deg round with
    its fingers on the thigh scored 1.23e-5 against 1.43e-5 for the hand at rest, 6.0 against 0.6 mm off;
    the capture score 3.54e-7 against 2.97e-7).  A wrist does not turn about the forearm, but a fit can: a
    walk's forearm turned by :func:`_twisted` brought its hand 179 deg round (palm out, the thumb 148 mm
    off); untwisted, 0.5 mm.  An ankle does not bend 125 deg, as a thin body's model fitted to a heavy
    subject's capture had its left foot.  ``score``: the coverage score of the pose returned."""
    sk, roles = body.model.skeleton, role_bones(body.model.skeleton.names)
    judged = capture_score(body, capture, State(body, pose))
    for s in "LR":
        for start in (_untwisted_hand(sk, roles, pose, s), _at_rest(roles, pose, f"hand.{s}", HAND_TWIST),
                      _at_rest(roles, pose, f"foot.{s}", FOOT_TURN)):
            if start is None:
                continue
            fit = _fit(body, capture, start, priors, SEARCH[1:], settings, cancel)
            again = capture_score(body, capture, fit.state)
            if again < judged:
                pose, judged, score = fit.pose, again, coverage_score(body, capture, fit.state)
    return pose, score


def _untwisted_hand(sk, roles, pose, side):
    """``pose`` with the ``side`` hand's twist about its forearm's rest direction taken out when it exceeds
    :data:`HAND_TWIST`, else None."""
    hand, forearm = roles.get(f"hand.{side}"), roles.get(f"forearm.{side}")
    along = None if hand is None or forearm is None else sk.heads[hand] - sk.heads[forearm]
    if along is None or np.linalg.norm(along) < 1e-6:
        return None
    axis = sk.frames[hand].T @ (along / np.linalg.norm(along))        # in the hand's rest frame
    twist = signed_twist(quat_to_matrix(pose.rotations[0, hand]), axis)
    if abs(twist) <= HAND_TWIST:
        return None
    rot = pose.rotations.copy()
    rot[:, hand] = quat_mul(rot[:, hand], rotvec_to_quat(-twist * axis))
    return Poses(rot, pose.translations, pose.scales)


def _at_rest(roles, pose, role, limit):
    """``pose`` with the ``role``'s bone at rest on its parent when it is turned further than ``limit``
    (rad) from there, else None."""
    bone = roles.get(role)
    if bone is None or np.linalg.norm(quat_to_rotvec(pose.rotations[0, bone])) <= limit:
        return None
    rot = pose.rotations.copy()
    rot[:, bone] = (1.0, 0.0, 0.0, 0.0)
    return Poses(rot, pose.translations, pose.scales)


def _turned(pose, bone, angle) -> Poses:
    """``pose`` with ``bone`` turned by ``angle`` (rad) about its own axis (the bone's local Y)."""
    rot = pose.rotations.copy()
    rot[:, bone] = quat_mul(rot[:, bone], rotvec_to_quat(np.array([0.0, angle, 0.0])))
    return Poses(rot, pose.translations, pose.scales)


def _settled(body, capture, pose, score, priors, settings, cancel):
    """``(pose, score)``: ``pose`` with its end chains tried at rest (:func:`_ends_at_rest`), then the last
    search stage run again from its own result, without the hold on small parts, while the coverage score
    drops by ``SETTLE_GAIN`` (at most ``SETTLE_RUNS`` times): a stage
    holds weakly seen directions at its start and the search holds small parts there, so a part the
    hypothesis had wrong (a learned rig's head anchoring few vertices, turned 37 deg) moves only so far."""
    last = dataclasses.replace(SEARCH[-1], small_held=False)
    pose, score = _ends_at_rest(body, capture, pose, score, priors, last, settings, cancel)
    for _ in range(SETTLE_RUNS):
        fit = _fit(body, capture, pose, priors, (last,), settings, cancel)
        again = coverage_score(body, capture, fit.state)
        if again > (1.0 - SETTLE_GAIN) * score:
            break
        pose, score = fit.pose, again
    return pose, score


def _ends_at_rest(body, capture, pose, score, priors, stage, settings, cancel):
    """``(pose, score)``: the fit of ``stage`` from ``pose`` with the rig's end chains (toes, fingers:
    :func:`solver.tracking.frame.end_chains`) at rest when its coverage score is lower; else the fit from
    ``pose`` with those chains turned as there that explain their own surroundings better there
    (:func:`chain_errors`), unless its score is over ``CHAIN_SLACK`` higher; else ``pose``.  The coarse
    search stages reach far, and a toe a few points see can end turned through its foot (114 deg on a
    tilted capture), a minimum the finer stages do not leave; from rest it is in reach.  The whole-body
    score does not resolve one toe (a walk's right toe put right scored 1.3 % worse, within the score's
    sampling), so each chain is judged by its own surroundings; a learned rig's feet at rest brought its
    shins right too (score 46 % lower), which the chains' turns alone do not."""
    chains = end_chains(body.model)
    if not chains:
        return pose, score
    rest = pose.rotations.copy()
    rest[:, np.concatenate(chains)] = (1.0, 0.0, 0.0, 0.0)
    rested = _fit(body, capture, Poses(rest, pose.translations, pose.scales), priors, (stage,), settings, cancel)
    rested_score = coverage_score(body, capture, rested.state)
    if rested_score < score:
        return rested.pose, rested_score
    states, tree = (State(body, pose), rested.state), cKDTree(capture.points)
    better = [c for c in chains if np.argmin(chain_errors(body.model, capture.points, tree, states, c)) == 1]
    if not better:
        return pose, score
    mixed = pose.rotations.copy()
    turned = np.concatenate(better)
    mixed[:, turned] = rested.pose.rotations[:, turned]
    fit = _fit(body, capture, Poses(mixed, pose.translations, pose.scales), priors, (stage,), settings, cancel)
    mixed_score = coverage_score(body, capture, fit.state)
    return (fit.pose, mixed_score) if mixed_score < (1.0 + CHAIN_SLACK) * score else (pose, score)


def chain_errors(model, points, tree, states, chain) -> list:
    """For each of ``states``: how badly it explains the capture around the bones ``chain`` (Charbonnier
    at ``SCORE_EPS``, m^2): the mean over the chain's vertices of their distance to the capture
    ``points`` (``tree``: their KD-tree) plus the mean over the capture points within ``CHAIN_REACH`` of
    the chain in any of the states of their distance to that state's surface.  The same points judge
    every state."""
    verts = np.isin(model.anchor, chain)
    near = set()
    for state in states:
        for hits in tree.query_ball_point(state.posed[verts], CHAIN_REACH):
            near.update(hits)
    near = points[np.fromiter(near, dtype=int, count=len(near))]
    rho = lambda d: charbonnier(d, SCORE_EPS)[0]
    out = []
    for state in states:
        err = float(rho(tree.query(state.posed[verts])[0]).mean()) if verts.any() else 0.0
        if len(near):
            err += float(rho(np.linalg.norm(near - state.surface.closest(near)[2], axis=1)).mean())
        out.append(err)
    return out


def _lost(check) -> bool:
    """True when the truth-free checks call the fit lost (a doubtful fit ranks with the good: a body whose
    parts touch at rest is doubtful in its true pose)."""
    return check is not None and check.verdict == "lost"


def unexplained_centres(check) -> list:
    """Centres ``[(3,)]`` of the capture regions the checks found unexplained, largest first (at most
    ``AIM_REGIONS``)."""
    if check is None:
        return []
    return [f.numbers["centre"] for f in check.findings if f.check == "unexplained"][:AIM_REGIONS]


def _fit(body, capture, start, priors, stages, settings, cancel, slot=0):
    try:
        return fit_frame(body, capture.points, capture.normals, start, priors=priors, stages=stages,
                         settings=settings, cancel=cancel, weak_ratio=SEARCH_HOLD, slot=slot)
    finally:
        body.release(slot)


def humanoid(skeleton) -> bool:
    """True when the rig has the roles the start poses need (a human body, named any known way)."""
    roles = role_bones(skeleton.names)
    return all(r in roles for r in REQUIRED)


def turned_rests(model, points, turns: int = 4) -> list:
    """Rest poses of a rig that is not a human body: its longest principal axis on the capture's (both
    ways), ``turns`` turns about it, centred on the capture; the untouched rest pose first."""
    out = [centred_rest(model, points)]
    model_axes, capture_axes = _principal(model.rest_vertices), _principal(points)
    for sign in (1.0, -1.0):
        for k in range(turns):
            spin = rotvec_to_matrix(capture_axes[:, 0] * (2.0 * np.pi * k / turns))
            R = spin @ capture_axes @ np.diag([sign, sign, 1.0]) @ model_axes.T
            out.append(rotated_rest(model, points, R))
    return out


def _principal(x):
    """``(3, 3)`` principal axes of points as columns, longest first, right-handed."""
    _, _, vt = np.linalg.svd(x - x.mean(axis=0), full_matrices=False)
    axes = vt.T
    if np.linalg.det(axes) < 0:
        axes[:, 2] *= -1
    return axes


def rotated_rest(model, points, R) -> Poses:
    """The rest pose turned by the world rotation ``R (3, 3)`` about the root's joint and centred on the
    capture."""
    pose = Poses.identity(1, model.skeleton.num_bones)
    F = model.skeleton.frames[0]
    pose.rotations[0, 0] = matrix_to_quat(F.T @ R @ F)
    head = model.skeleton.heads[0]
    turned = (model.rest_vertices - head) @ R.T + head
    pose.translations[0] = _box_centre(points) - _box_centre(turned)
    return pose


def centred_rest(model, points) -> Poses:
    """The rest pose moved so that the model's box centre is the capture's: the start of a rig that is
    not a human body (no start poses fit it)."""
    pose = Poses.identity(1, model.skeleton.num_bones)
    pose.translations[0] = _box_centre(points) - _box_centre(model.rest_vertices)
    return pose


def _box_centre(x):
    """``(3,)`` centre of the box between the 2nd and 98th percentiles of points ``x (N, 3)``."""
    return 0.5 * (np.percentile(x, 2, axis=0) + np.percentile(x, 98, axis=0))


def coverage_score(body, capture, state) -> float:
    """Robust two-way distance (m^2 units of the Charbonnier penalty) between the capture and the
    posed model: what a limb on the wrong surface leaves unexplained either way."""
    return _score(body, capture, state, SCORE_EPS, True)


def capture_score(body, capture, state) -> float:
    """The capture-to-model half of :func:`coverage_score` at the tracking scale (``FINE_EPS``): the
    measure a tracked fit minimises, so a search that lowers it has found a better fit of the capture
    (the model-to-capture half also counts model parts the cameras cannot see)."""
    return _score(body, capture, state, FINE_EPS, False)


def _score(body, capture, state, eps, both) -> float:
    scan = ScanToModel(capture.points, capture.normals, 2000, eps, SCORE_REACH, min_cos=-1.0, seed=7)
    terms = [scan]
    if both:
        terms.append(ModelToScan(capture.points, capture.normals, sample(body.model.num_vertices, 1500, 8), eps,
                                 SCORE_REACH, min_cos=-1.0))
    # pairs beyond the reach are left out of the energies: each counts as a pair at the reach
    far = eps * eps * (np.sqrt(1.0 + (SCORE_REACH / eps) ** 2) - 1.0)
    return sum(t.energy(body, state) + far * float((~t.pairs(state)[-1]).mean()) for t in terms)


def as_start(model, pose: Poses) -> Poses:
    """A user's start pose checked against the model (one frame, its bones)."""
    pose.validate(model.skeleton.num_bones)
    if len(pose) != 1:
        raise ArticulaInputError(f"start pose: expected one frame, got {len(pose)}")
    return pose
