"""Learn a rig from registered scans (dissertation (model-adaptive mocap) §3.2-3.4): the orchestration
of the rig-learning steps.

``learn_rig(scans, faces, options)`` →  :class:`LearnResult` ``(model, poses, report)``, the settings in
:class:`solver.learn.options.LearnOptions`:

1. input checks (shapes, ≥ 3 scans, parts for the vertex count, memory budget: fewer key scans if needed,
   finite values, islands (the largest is learned from, the others carried rigidly), some non-rigid motion);
2. rest mesh = one scan chosen by the seed; segmentation into k rigid parts by motion (§3.2,
   :mod:`solver.learn.segmentation`; k chosen from the motion unless given);
3. skeleton (§3.2, :mod:`solver.learn.skeleton`): tree, joints (LS rotation centres), frames, mirror pairs;
   every joint must move (else the motion cannot separate that many parts);
4. per-scan poses from per-part Procrustes (:mod:`solver.fit.pose_init`); binary (rigid) skin;
5. alternating optimisation (§3.4) of ``E = Q + λ Q_sym + κ Q_prior`` (objective §3.3, bone-length
   symmetry, a weak prior on the joint centres) until a round lowers it by at most ``tol`` of the largest
   round decrease (:func:`flattened`): (a) joints + poses by Levenberg–Marquardt (:mod:`solver.learn.joints_poses`;
   on a weighted vertex subset while the full E accepts it, :mod:`solver.learn.coarse`), (b) weights by BCD
   (:mod:`solver.learn.weights`), (c) rest vertices by sparse least squares (:mod:`solver.learn.rest_shape`),
   each step accepted only if E does not increase; warm-start rounds at a smaller α come first;
6. long sequences: steps 2-5 run on at most ``key_scans`` scans (:mod:`solver.learn.key_scans`: the most
   different poses, rest scan included), then every other scan gets its pose fitted with the learned
   model fixed (:func:`poses_of_other_scans`).

Output conventions: the model and poses are in the input coordinates and vertex order; poses are in
scan order (one per scan), scale 1.  The report (:mod:`solver.learn.report`) holds the vertex-to-surface
error of every scan vertex to the posed model surface in mm, the vertex-to-vertex RMS, the objective
log, time per stage (s), the chosen rest scan, k and its selection curve, mirror pairs.
"""
import copy
import time
from dataclasses import dataclass, field, replace

import numpy as np

from .. import parallel
from ..errors import ArticulaInputError
from ..parallel import single_blas_thread
from .islands import carry_islands, split_islands
from .coarse import vertex_subset
from .key_scans import select_key_scans, time_budget_count
from .memory import check_sizes
from ..fit.least_squares import GainRatioDamping
from .joints_poses import JointPoseProblem, optimise_joints_and_poses, relative_joint_prior
from ..geometry.mesh_graph import uniform_laplacian
from ..rig.model import Model, Poses
from ..fit.pose_fit import fit_poses
from ..fit.pose_init import poses_from_part_fits
from ..geometry.procrustes import fit_parts
from .rest_shape import ShapePreconditioner, solve_rest_vertices
from .objective import RigObjective
from ..geometry.rotations import quat_to_rotvec
from .mirror_map import mirror_map
from .part_count import articulated_parts
from .prune import drop_bones, empty_leaves, remap_pairs
from .role_names import name_bones
from .seams import Seams
from .segmentation import centred, segment
from .symmetry import continuing_pairs
from .skeleton import build_skeleton
from .options import MIN_SCANS, LearnOptions
from .report import make_report
from .weights.colouring import TwoRing
from .weights.optimise import optimise_weights

REPORT_START = 0.97            # fraction of the run's progress at which the report's distances start
MIN_JOINT_MOTION_DEG = 1.0      # a joint must rotate at least this much in some scan


@dataclass
class LearnResult:
    """model, poses (one per scan, scan order), report (JSON-able dict: :func:`solver.learn.report.make_report`
    and the run's log, times and choices, see the module docstring) and
    scan_distances ``(M, V)``: the distance (metres) of every scan vertex to the posed model surface of its
    scan, the numbers the report's surface-error statistics summarise."""
    model: Model
    poses: Poses
    report: dict = field(default_factory=dict)
    scan_distances: np.ndarray = None


# ----------------------------------------------------------------------------- input checks

def check_input(scans, faces, options):
    """Validate and convert ``scans (M,V,3)`` and ``faces (F,3)`` for a run with :class:`LearnOptions`
    ``options``; raises :class:`ArticulaInputError` naming the problem.  Returns ``(scans float64, faces
    int32, islands, memory plan)`` (:func:`solver.learn.islands.split_islands`,
    :class:`solver.learn.memory.MemoryPlan`).  The settings are checked against the input
    (:meth:`LearnOptions.validate_for`) and the memory budget (:func:`solver.learn.memory.check_sizes`: how
    many of the key scans fit, refused if not even 3) before the scans are converted or scanned for
    non-finite values."""
    shape = np.shape(scans)
    if len(shape) != 3 or shape[2] != 3:
        raise ArticulaInputError(f"scans: expected shape (M, V, 3) (registered scans sharing one topology), got {shape}")
    M, V = shape[:2]
    memory = check_sizes(options, M, V)
    scans, faces = _check_arrays(scans, faces)
    islands = split_islands(faces, V)
    if islands.others:
        options.validate_for(M, len(islands.main))
    return scans, faces.astype(np.int32), islands, memory


def _check_arrays(scans, faces):
    """``(scans float64, faces)`` after checking shapes, the scan count, finite coordinates and that the
    faces index every vertex and nothing else."""
    scans = np.asarray(scans, dtype=np.float64)
    faces = np.asarray(faces)
    if scans.ndim != 3 or scans.shape[2] != 3:
        raise ArticulaInputError(f"scans: expected shape (M, V, 3) (registered scans sharing one topology), got {scans.shape}")
    M, V = scans.shape[:2]
    if M < MIN_SCANS:
        raise ArticulaInputError(f"scans: {M} scan(s) given; learning a rig needs at least {MIN_SCANS} registered "
                                 f"scans")
    bad = np.argwhere(~np.isfinite(scans))
    if len(bad):
        m, v, _ = bad[0]
        raise ArticulaInputError(f"scans: scan {m}, vertex {v} has a non-finite coordinate ({scans[m, v]})")
    if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0:
        raise ArticulaInputError(f"faces: expected triangles of shape (F, 3), got {faces.shape}")
    if not np.issubdtype(faces.dtype, np.integer):
        raise ArticulaInputError(f"faces: expected integer vertex indices, got {faces.dtype}")
    if faces.min() < 0 or faces.max() >= V:
        raise ArticulaInputError(f"faces: vertex index {faces.max() if faces.max() >= V else faces.min()} "
                                 f"outside 0..{V - 1}: the scans do not share the faces' topology")
    unused = np.setdiff1d(np.arange(V), faces)
    if len(unused):
        raise ArticulaInputError(f"faces: vertex {unused[0]} (and {len(unused) - 1} more) is in no triangle")
    return scans, faces


def check_motion(rest, scans, faces):
    """Refuse sequences whose scans are (almost) rigid copies of each other."""
    _, rms1 = segment(rest, scans, faces, 1)
    size = np.linalg.norm(np.ptp(rest, axis=0))
    if rms1 < 1e-4 * size:
        raise ArticulaInputError(f"scans: the scans differ only by a rigid motion (non-rigid RMS {rms1 * 1e3:.3g} mm "
                                 f"for a {size:.3g} m object); there is no articulation to learn")


def check_joint_motion(skeleton, poses):
    """Every joint must rotate in some scan, else two parts move as one."""
    ang = np.degrees(np.linalg.norm(quat_to_rotvec(poses.rotations[:, 1:]), axis=2)).max(axis=0)
    still = np.flatnonzero(ang < MIN_JOINT_MOTION_DEG)
    if len(still):
        b = int(still[0]) + 1
        raise ArticulaInputError(
            f"parts: joint {skeleton.names[b]!r} rotates at most {ang[b - 1]:.2g} degrees over all scans: the motion "
            f"cannot separate {skeleton.num_bones} parts; use fewer parts")


# ----------------------------------------------------------------------------- steps

def _labels_from_skeleton(rest, skeleton):
    """Parts of a given skeleton: every vertex to its nearest bone segment (head→tail)."""
    h, t = skeleton.heads, skeleton.tails
    d = t - h
    s = np.clip(np.einsum("vbi,bi->vb", rest[:, None] - h, d) / np.einsum("bi,bi->b", d, d), 0, 1)
    dist = np.linalg.norm(rest[:, None] - (h + s[..., None] * d), axis=2)
    return np.argmin(dist, axis=1)


def choose_rest_scan(num_scans, seed, rest_scan=None):
    """Index of the scan that gives the initial rest mesh: ``rest_scan`` if given (checked), else drawn
    from the seed."""
    rest_index = int(np.random.default_rng(seed).integers(num_scans)) if rest_scan is None else int(rest_scan)
    if not 0 <= rest_index < num_scans:
        raise ArticulaInputError(f"rest_scan: {rest_index} is not a scan index (0..{num_scans - 1})")
    return rest_index


def initialise(scans, faces, options, progress, rest_index):
    """Steps 2-4 with scan ``rest_index`` of ``scans (M,V,3)`` as the initial rest mesh, from
    ``options.initial_skeleton`` or by segmentation.  Returns ``(model, poses, info dict, mirror pairs)``."""
    rest = scans[rest_index].copy()
    say = _say(progress)
    say(0.0, "checking the motion")
    check_motion(rest, scans, faces)
    info = dict(rest_scan=rest_index)
    if options.initial_skeleton is not None:
        skeleton, bone_labels, W, tau = _start_from_skeleton(rest, scans, options.initial_skeleton, info)
        pairs = []
    else:
        skeleton, bone_labels, W, tau, pairs = _start_from_segmentation(rest, scans, faces, options, progress, info)
    say(0.95, "first poses from the parts' rigid motions")
    poses = poses_from_part_fits(skeleton, W, tau)
    check_joint_motion(skeleton, poses)
    V, B = len(rest), skeleton.num_bones
    model = Model(rest, faces, skeleton, bone_labels.astype(np.int32),
                  np.zeros((V, B), np.float32), np.zeros((V, B), np.float32))
    info["mirror_pairs"] = [(skeleton.names[l], skeleton.names[r]) for l, r in pairs]
    return model, poses, info, pairs


def _start_from_skeleton(rest, scans, initial_skeleton, info):
    """A given skeleton's parts (nearest bone) and their rigid fits ``(skeleton copy, labels (V,), R, t)``."""
    initial_skeleton.validate()
    bone_labels = _labels_from_skeleton(rest, initial_skeleton)
    B = initial_skeleton.num_bones
    W, tau = fit_parts(rest, scans, bone_labels, B)
    info.update(parts=B, k_curve_mm=None)
    return copy.deepcopy(initial_skeleton), bone_labels, W, tau


def _start_from_segmentation(rest, scans, faces, options, progress, info):
    """Segmentation into k parts (chosen from the motion unless ``options.parts``), the skeleton built on
    it and the parts' rigid fits in bone order: ``(skeleton, labels (V,), R, t, mirror pairs)``."""
    symmetry, seed, say = options.symmetry, options.seed, _say(progress)
    start = None
    if options.parts:
        k = int(options.parts)
        info["k_curve_mm"] = None
    else:
        cl, count = articulated_parts(*centred(rest, scans), faces, k_max=options.k_max, seed=seed,
                                      progress=_sub_progress(progress, 0.02, 0.3))
        k, start = cl.k, (cl.R, cl.t)
        info["k_curve_mm"] = count.pop("curve_mm")
        info["part_count"] = count
    say(0.3, "finding the mesh's mirror map")
    mirror = mirror_map(rest, scans, faces) if symmetry and k > 1 else None
    labels, rms = segment(rest, scans, faces, k, seed=seed, mirror=False if mirror is None else mirror,
                          progress=_sub_progress(progress, 0.35, 0.8), start=start)
    chosen, k = k, int(labels.max()) + 1    # a chosen count loses the parts too small at full resolution
    if k < chosen:
        info["part_count"].update(parts=k, dropped_at_full_resolution=chosen - k)
    info.update(parts=k, segmentation_rms_mm=rms * 1e3)
    say(0.8, f"building the skeleton of {k} parts")
    R, t = fit_parts(rest, scans, labels, k)
    skeleton, order, bone_of_part, pairs = build_skeleton(rest, labels, faces, k, R, t, symmetry=symmetry,
                                                          symmetry_scans=scans, mirror=mirror)
    return skeleton, bone_of_part[labels], R[:, order], t[:, order], pairs


def _say(progress):
    """``say(fraction, stage)``: ``progress(fraction, stage, None)``, or nothing without a callback."""
    return (lambda f, stage: None) if progress is None else (lambda f, stage: progress(f, stage, None))


def _sub_progress(progress, lo, hi, offset=0.0):
    """Map a step's progress (fraction in [0,1], its own objective) into [lo, hi] of the whole run, adding
    a constant to the objective (the symmetry term that the weight/rest steps do not change)."""
    if progress is None:
        return None
    return lambda f, stage, obj: progress(lo + (hi - lo) * f, stage, None if obj is None else obj + offset)


@dataclass
class AlphaState:
    """What the rounds at one α carry from round to round: the rest-vertex preconditioner (factored once),
    the LM damping, and whether the BCD's joint move is still tried."""
    shape: ShapePreconditioner
    damping: GainRatioDamping = field(default_factory=GainRatioDamping)
    joint_move: bool = True


@dataclass
class Settings:
    """What every alternation round uses: the run's :class:`LearnOptions` (the inner steps' iteration
    counts and tolerances), the mesh's BCD graph and the per-α state (:meth:`at`)."""
    options: LearnOptions
    graph: object               # the mesh's weights.colouring.TwoRing, built once
    states: dict = field(default_factory=dict)          # α -> AlphaState
    subset: object = None       # step (a)'s solver.learn.coarse.VertexSubset; None: all vertices
    coarse_rounds: int = 0      # rounds whose step (a) was kept from the subset

    def at(self, objective):
        """The :class:`AlphaState` of ``objective``'s α (made at the first use)."""
        if objective.alpha not in self.states:
            self.states[objective.alpha] = AlphaState(ShapePreconditioner(objective.L, objective.alpha))
        return self.states[objective.alpha]


def alternation_round(model, poses, problem, scans, settings, fix_joints, timings, progress=None, E=None):
    """One round of steps (a) joints + poses, (b) weights, (c) rest vertices for the objective of
    ``problem`` (:class:`JointPoseProblem`); each step is kept only if ``E = Q + λ Q_sym + κ Q_prior`` does
    not increase.  Once the BCD's joint move has been rejected at this α it is not tried again in later
    rounds (:class:`AlphaState`): late in the alternation it hardly ever gains and costs a weight sweep.
    E: the problem's value at (model, poses) if known (computed otherwise).
    Returns ``(model, poses, [(step, E), ...])``; ``timings`` (dict of seconds per step) is added to."""
    objective, options = problem.objective, settings.options
    state = settings.at(objective)
    sub = (lambda lo, hi, off=0.0: _sub_progress(progress, lo, hi, off))
    log = []
    if progress is not None:                  # after the preconditioner's factorisation at a new α
        progress(0.0, "starting the round", None)
    t0 = time.perf_counter()
    E = problem.value(model, poses) if E is None else E
    model, poses, E = _joints_and_poses(model, poses, problem, settings, fix_joints, state, E, sub(0.0, 1 / 3))
    timings["joints_and_poses"] += time.perf_counter() - t0
    log.append(("joints_and_poses", float(E)))
    sym_term = problem.shared_value(model.skeleton)           # E − Q: the terms of the skeleton alone
    t0 = time.perf_counter()
    model, w_log, state.joint_move = optimise_weights(
        model, poses, objective, max_sweeps=options.bcd_sweeps, steps=options.bcd_steps,
        progress=sub(1 / 3, 2 / 3, sym_term), jacobi=state.joint_move, graph=settings.graph)
    timings["weights"] += time.perf_counter() - t0
    E = min(E, w_log[-1] + sym_term) if w_log else E
    log.append(("weights", float(E)))
    t0 = time.perf_counter()
    trial = copy.copy(model)
    trial.rest_vertices, posed = solve_rest_vertices(model, poses, scans, objective.L, objective.alpha,
                                                     state.shape, with_posed=True, progress=sub(2 / 3, 1.0))
    E_trial = objective.value(posed) + sym_term
    if E_trial <= E:
        model, E = trial, E_trial
    timings["rest_vertices"] += time.perf_counter() - t0
    log.append(("rest_vertices", float(E)))
    return model, poses, log


def _joints_and_poses(model, poses, problem, settings, fix_joints, state, E, progress):
    """Step (a) from E: on ``settings.subset`` (:mod:`solver.learn.coarse`), kept if the full E does not
    increase; once the full E rejects it (the subset has done what it can: coarse to fine), on all
    vertices from then on.  Returns ``(model, poses, E)``."""
    options, subset = settings.options, settings.subset
    if subset is not None:
        trial, new_poses, E_trial = _joints_and_poses_on_subset(model, poses, problem, settings, fix_joints, state,
                                                                progress)
        if E_trial <= E:
            settings.coarse_rounds += 1
            return trial, new_poses, E_trial
        settings.subset = None
    model, poses, gn_log = optimise_joints_and_poses(
        model, poses, problem, iterations=options.gn_iterations, progress=progress, fix_joints=fix_joints,
        damping=state.damping, value=E, gain_tol=options.gn_gain_tol)
    return model, poses, (gn_log[-1] if gn_log else E)


def _joints_and_poses_on_subset(model, poses, problem, settings, fix_joints, state, progress):
    """Step (a) on ``settings.subset``: ``(model, poses, full E)`` after it (E infinite if no step was taken)."""
    subset, options = settings.subset, settings.options
    quiet = None if progress is None else (lambda f, stage, _obj: progress(f, stage, None))  # E_U is not E
    sub, new_poses, gn_log = optimise_joints_and_poses(
        subset.model(model), poses, subset.problem(problem), iterations=options.gn_iterations, progress=quiet,
        fix_joints=fix_joints, damping=state.damping, gain_tol=options.gn_gain_tol,
        correction=subset.correction(model, poses, problem, fix_joints) if options.joint_correction else None)
    if not gn_log:
        return model, poses, np.inf
    trial = copy.copy(model)
    trial.skeleton = sub.skeleton
    return trial, new_poses, problem.value(trial, new_poses)


def poses_of_other_scans(model, key_poses, scans, keys, options, progress=None):
    """Poses ``(M frames, scan order)`` of all ``scans (M, V, 3)``: the learned ``key_poses`` for the scans
    ``keys`` and, for every other scan, a pose fitted with the model fixed (:func:`solver.fit.pose_fit.fit_poses`
    from per-part Procrustes, at most ``options.other_scan_iterations`` LM iterations).  Returns
    ``(poses, fit report dict)``."""
    M = len(scans)
    others = np.setdiff1d(np.arange(M), keys)
    fit = fit_poses(model, scans[others], max_iterations=options.other_scan_iterations,
                    tol=options.other_scan_tol,
                    progress=None if progress is None else (lambda f, text: progress(f, text, None)))
    B = model.skeleton.num_bones
    poses = Poses(np.zeros((M, B, 4)), np.zeros((M, 3)), np.ones(M))
    for idx, src in ((keys, key_poses), (others, fit.poses)):
        poses.rotations[idx], poses.translations[idx], poses.scales[idx] = (src.rotations, src.translations,
                                                                           src.scales)
    info = dict(scans=int(len(others)), mean_iterations=float(fit.iterations.mean()),
                converged=int(fit.converged.sum()), rms_mm_max=float(fit.rms.max() * 1e3))
    return poses, info


@single_blas_thread()
def learn_rig(scans, faces, options=None, progress=None, **settings):
    """Learn a hybrid-skinned rig from registered ``scans (M,V,3)`` metres (M ≥ 3, one topology) with
    triangles ``faces (F,3)``.  Returns :class:`LearnResult`.

    options: :class:`LearnOptions` (None: the defaults); ``settings`` replace fields of it by name
    (``learn_rig(scans, faces, parts=8)`` is ``learn_rig(scans, faces, LearnOptions(parts=8))``).  Settings
    out of their bounds are refused (:meth:`LearnOptions.validate`).
    progress(fraction, stage, objective): called throughout; may raise :class:`solver.errors.Cancelled`;
    the objective passed never increases.

    Why some settings exist.  warm_start: with the full shape term a vertex's weights can only move with
    its neighbours', so from binary weights the alternation crawls; rounds at a fraction of α first are a
    continuation (logged in ``report["warm_start_log"]``; ``report["initial_objective"]`` is E at α before
    them; the main log of E at α starts where they end).  joint_warmup_rounds: with binary initial weights
    and a large α the Laplacian term at the parts' seams pulls the joints away from the true rotation
    centres.  joint_prior: ``Σ_b κ_b ‖h_b − h⁰_b‖²`` with h⁰ the initial rotation-centre estimates and
    κ_b = ρ × the joint's mean data curvature (:func:`solver.learn.joints_poses.relative_joint_prior`):
    without it near-hinge joints slide along their axes, where the data hardly determine them; it costs
    data fit where the joints are free to serve it, so the pure data-fit setting is ``alpha=1,
    joint_prior=0``.  key_scans: the objective log is that of the key scans, the report covers all scans
    (``report["key_scans"]``: the indices).  docs/learn_rig_solver.md has the measurements behind the
    defaults.
    Runs with numpy's BLAS on one thread (:func:`solver.parallel.single_blas_thread`): its many mid-size
    products lose more to thread hand-offs than they gain from a second core."""
    options = replace(options or LearnOptions(), **settings)
    options.validate()
    with parallel.using(options.workers) as threads:
        result = _learn_welded(scans, faces, options, progress)
    result.report["workers"] = threads
    return result


def _learn_welded(scans, faces, options, progress):
    """:func:`_learn_rig` on the mesh with the vertex copies at its seams welded
    (:mod:`solver.learn.seams`), the result given back for every input vertex.  Input that
    :func:`check_input` would refuse is passed on as it is, so that its message names the input's
    scan and vertex."""
    arr = np.asarray(scans)
    f = np.asarray(faces)
    if (arr.ndim != 3 or arr.shape[2] != 3 or arr.shape[0] < MIN_SCANS or f.ndim != 2 or f.shape[1:] != (3,)
            or not np.issubdtype(f.dtype, np.integer) or not np.issubdtype(arr.dtype, np.number)
            or not np.isfinite(arr).all()):
        return _learn_rig(scans, faces, options, progress)
    seams = Seams.of(arr)
    if seams is None:
        return _learn_rig(arr, f, options, progress)
    return seams.expand(_learn_rig(*seams.weld(arr, f), options, progress), f)


def _learn_rig(scans, faces, options, progress):
    """The body of :func:`learn_rig` (validated ``options``): steps 1-6 of the module docstring, on the
    largest island of the mesh; the other islands are then carried rigidly (:mod:`solver.learn.islands`)."""
    t_all = time.perf_counter()
    timings = {key: 0.0 for key in ("initialisation", "joints_and_poses", "weights", "rest_vertices")}
    all_scans, faces, islands, memory = check_input(scans, faces, options)
    main_scans = all_scans[:, islands.main] if islands.others else all_scans
    rest_index, keys, scans = _scans_to_learn_from(main_scans, options, memory.learned)
    timed = time_budget_count(main_scans.shape[1], options.key_scans, options.key_scan_budget)
    learned = min(len(keys), timed) if timed else len(keys)
    end = REPORT_START if learned == len(all_scans) else REPORT_START - 0.1   # then the other scans' poses
    if progress is not None:
        progress(0.0, f"learning from {learned} scans x {len(islands.main)} vertices"
                      + (f" ({len(islands.others)} islands carried)" if islands.others else "")
                      + (f" ({memory.note()})" if memory.reduced else ""), None)

    t0 = time.perf_counter()
    model, poses, info, pairs = initialise(scans, islands.main_faces, options, _sub_progress(progress, 0.0, 0.1),
                                           int(np.searchsorted(keys, rest_index)))
    keys, scans, poses = _within_time_budget(keys, scans, poses, learned, rest_index)
    info["rest_scan"] = rest_index
    timings["initialisation"] = time.perf_counter() - t0
    L = uniform_laplacian(islands.main_faces, len(scans[0]))
    sym = continuing_pairs(model.skeleton, pairs) if options.symmetry else []
    subset = vertex_subset(model.rest_vertices, L, options.joint_vertices)
    info["joint_vertices"] = len(L.indptr) - 1 if subset is None else len(subset.vertices)
    alternation = Alternation(scans, options, Settings(options, TwoRing(L), subset=subset),
                              _problems(model, poses, scans, L, sym, options, subset), timings, progress, end)
    problem = alternation.problem_for(options.alpha)
    E_initial = problem.value(model, poses)
    if progress is not None:
        progress(0.1, "initialised", E_initial)
    model, poses, E, warm_log = alternation.warm_start(model, poses, problem, E_initial)
    model, poses, log, rounds, converged, stopped = alternation.main_rounds(model, poses, problem, E)
    if options.initial_skeleton is None:                # a given skeleton keeps every bone it has
        model, poses, sym = _without_empty_leaves(model, poses, sym, info)
        info["bone_names"] = (name_bones(model, info) if options.name_roles else
                              dict(scheme="parts", roles=0, why="name_roles is off"))

    info["key_scans"] = keys.tolist()
    if 0 < timed < min(memory.learned, len(all_scans)):
        info["key_scans_note"] = (f"learned from {timed} of {len(all_scans)} scans (the parts from "
                                  f"{memory.learned}) to hold the time of a {main_scans.shape[1]}-vertex mesh "
                                  f"(key_scan_budget {options.key_scan_budget})")
    if len(keys) < len(all_scans):
        t0 = time.perf_counter()
        poses, info["other_scans"] = poses_of_other_scans(model, poses, main_scans, keys, options,
                                                          _sub_progress(progress, end, REPORT_START))
        timings["other_scans"] = time.perf_counter() - t0
    model, info["islands"] = carry_islands(model, poses, all_scans, all_scans[rest_index], islands)
    objective = (problem.objective if len(keys) == len(all_scans) and not islands.others else
                 RigObjective(all_scans, uniform_laplacian(faces, all_scans.shape[1]), options.alpha))
    info.update(objective_log=log, warm_start_log=warm_log, initial_objective=float(E_initial),
                iterations=rounds, converged=converged, timings_s=timings, alpha=options.alpha,
                coarse_rounds=alternation.settings.coarse_rounds, stopped=stopped, memory=memory.report(),
                symmetry_lambda=problem.lam, joint_prior=options.joint_prior)
    t0 = time.perf_counter()
    if progress is not None:
        progress(REPORT_START, "report: distances of every scan to the learned surface", None)
    report, distances = make_report(model, poses, all_scans, objective, sym,
                                    _sub_progress(progress, REPORT_START, 1.0))
    report.update(info)
    timings["report"] = time.perf_counter() - t0
    timings["total"] = time.perf_counter() - t_all
    model.validate()
    poses.validate(model.skeleton.num_bones)
    return LearnResult(model, poses, report, distances)


def _without_empty_leaves(model, poses, sym, info):
    """``(model, poses, sym)`` less the leaf bones that hold no vertex (:mod:`solver.learn.prune`), the
    symmetry terms renumbered; ``info["empty_parts_removed"]`` names them, mirror pairs losing one go."""
    drop = empty_leaves(model)
    info["empty_parts_removed"] = [model.skeleton.names[b] for b in drop]
    if len(drop) == 0:
        return model, poses, sym
    model, poses, new_index = drop_bones(model, poses, drop)
    info["parts"] = model.skeleton.num_bones
    names = set(model.skeleton.names)
    info["mirror_pairs"] = [pr for pr in info.get("mirror_pairs", []) if set(pr) <= names]
    return model, poses, remap_pairs(sym, new_index)


def _within_time_budget(keys, scans, poses, count, rest_index):
    """``(keys, scans, poses)`` of the ``count`` most different of the key ``scans`` (rest scan included;
    :func:`solver.learn.key_scans.select_key_scans`): the parts, skeleton and first poses come from all
    key scans (a part count read from fewer poses misses segments), the alternation runs on these."""
    if count >= len(keys):
        return keys, scans, poses
    sub = select_key_scans(scans, count, first=int(np.searchsorted(keys, rest_index)))
    return keys[sub], scans[sub], Poses(poses.rotations[sub], poses.translations[sub], poses.scales[sub])


def _scans_to_learn_from(all_scans, options, count=None):
    """``(rest scan index, key scan indices (sorted), the key scans (K,V,3))`` of ``all_scans (M,V,3)``:
    every scan unless there are more than ``count`` (default ``options.key_scans``; the memory plan's
    count when fewer fit, :func:`solver.learn.memory.plan_memory`)."""
    rest_index = choose_rest_scan(len(all_scans), options.seed, options.rest_scan)
    count = options.key_scans if count is None else count
    keys = (select_key_scans(all_scans, count, first=rest_index) if 0 < count < len(all_scans)
            else np.arange(len(all_scans)))
    return rest_index, keys, (all_scans[keys] if len(keys) < len(all_scans) else all_scans)


def _problems(model, poses, scans, L, sym, options, subset=None):
    """``α -> JointPoseProblem``: E of ``scans`` at Laplacian weight α with the mirror pairs ``sym``
    (weight ``options.lam``) and the joint-centre prior (centres: ``model``'s initial joints; κ from
    ρ = ``options.joint_prior`` at ``options.alpha``, :func:`solver.learn.joints_poses.relative_joint_prior`,
    on step (a)'s vertex ``subset`` if there is one: its Q estimates the full Q)."""
    prior_heads = model.skeleton.heads.copy()          # the initial rotation-centre estimates
    objective = RigObjective(scans, L, options.alpha)
    if subset is not None:
        model, objective = subset.model(model), subset.objective(objective)
    kappa = (relative_joint_prior(model, poses, objective, options.joint_prior)
             if options.joint_prior > 0 else 0.0)
    lam = options.lam if sym else 0.0
    return lambda a: JointPoseProblem(RigObjective(scans, L, a), sym, lam, prior_heads=prior_heads, kappa=kappa)


@dataclass
class Alternation:
    """Step 5 of one run: warm-start rounds at α × ``options.warm_start`` (:meth:`warm_start`), then rounds
    at α (:meth:`main_rounds`).  Progress spans [0.1, ``end``] of the run, evenly over the rounds."""
    scans: np.ndarray
    options: LearnOptions
    settings: Settings
    problem_for: object         # α -> JointPoseProblem (:func:`_problems`)
    timings: dict               # seconds per step, added to
    progress: object = None
    end: float = 1.0

    @property
    def warm_alphas(self):
        """The warm-start rounds' α (none without main rounds: ``max_iterations = 0`` initialises only)."""
        o = self.options
        return [float(f) * o.alpha for f in o.warm_start] if o.max_iterations > 0 else []

    def span(self, r):
        """``(lo, hi)``: the fraction of the run that round ``r`` (warm-start rounds counted) covers."""
        rounds = max(len(self.warm_alphas) + self.options.max_iterations, 1)
        return 0.1 + (self.end - 0.1) * r / rounds, 0.1 + (self.end - 0.1) * (r + 1) / rounds

    def _round(self, model, poses, problem, r, progress, E=None):
        return alternation_round(model, poses, problem, self.scans, self.settings,
                                 r < self.options.joint_warmup_rounds, self.timings, progress, E)

    def warm_start(self, model, poses, problem, E_initial):
        """The warm-start rounds from ``(model, poses)``, kept only if they lower E of ``problem`` (at α)
        below ``E_initial``.  Returns ``(model, poses, E, log)``; the log names each step with its α."""
        start, log, warm = (model, poses), [], self.warm_alphas
        for r, a in enumerate(warm):
            model, poses, steps = self._round(model, poses, self.problem_for(a), r,
                                              _quiet(self.progress, *self.span(r), f"warm start (alpha {a:g})"))
            log += [(f"{name} (alpha {a:g})", e) for name, e in steps]
        E = problem.value(model, poses)
        if E > E_initial:
            (model, poses), E = start, E_initial
            log.append(("warm start discarded", float(E)))
        if self.progress is not None and warm:
            self.progress(self.span(len(warm))[0], "warm start done", E)
        return model, poses, E, log

    def main_rounds(self, model, poses, problem, E):
        """Rounds at α from E until the objective has flattened (:func:`flattened`, after the joint
        warm-up) or ``max_iterations`` are done.  Returns ``(model, poses, log, rounds done, converged,
        stopped)``, stopped: why, in words (with the numbers of the last round)."""
        o, first = self.options, len(self.warm_alphas)
        log, converged, it, gains = [("initial", float(E))], False, -1, []
        stopped = "max_iterations is 0: initialisation only"
        for it in range(o.max_iterations):
            E_round, r = E, first + it
            model, poses, steps = self._round(model, poses, problem, r, _sub_progress(self.progress, *self.span(r)), E)
            log += steps
            E = steps[-1][1]
            if self.progress is not None:
                self.progress(self.span(r)[1], f"round {it + 1} of at most {o.max_iterations}", E)
            if r < o.joint_warmup_rounds:
                stopped = f"max_iterations ({o.max_iterations}) reached in the joint warm-up"
                continue
            gains.append(E_round - E)
            converged, stopped = flattened(gains, E_round, o.tol, it + 1, o.max_iterations)
            if converged:
                break
        return model, poses, log, it + 1, converged, stopped


def flattened(gains, E_before, tol, round_number, max_rounds):
    """The convergence test of the main rounds: ``(converged, reason)``.  Converged when the last round's
    decrease of E ``gains[-1]`` is at most ``tol`` times the largest decrease of a round so far (the
    objective has flattened: later rounds gain ever less), or is not positive; ``E_before``: E before the
    last round (for the reason's percentage)."""
    gain, best = gains[-1], max(gains)
    share = gain / best if best > 0 else 0.0
    numbers = (f"round {round_number} lowered E by {100 * gain / max(E_before, 1e-300):.2g} %, "
               f"{100 * share:.0f} % of the largest round decrease (tol {100 * tol:.0f} %)")
    if gain <= 0 or (len(gains) > 1 and share <= tol):
        return True, "objective flattened: " + numbers
    if round_number >= max_rounds:
        return False, f"max_iterations ({max_rounds}) reached: " + numbers
    return False, numbers


def _quiet(progress, lo, hi, stage):
    """Progress of a warm-start round: its fraction and stage name, no objective (it is not E at α)."""
    if progress is None:
        return None
    return lambda f, _stage, _obj: progress(lo + (hi - lo) * f, stage, None)
