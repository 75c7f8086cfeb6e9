"""Learn a rig from registered scans (spec §3; issue 4): the orchestration of the rig-learning steps.

``learn_rig(scans, faces)`` →  :class:`LearnResult` ``(model, poses, report)``:

1. input checks (shapes, finite values, ≥ 3 scans, one connected mesh, some non-rigid motion, memory);
2. rest mesh = one scan chosen by the seed; segmentation into k rigid parts by motion
   (:mod:`solver.learn.segmentation`; k chosen from the motion unless given);
3. skeleton (:mod:`solver.learn.skeleton`): tree, joints (LS rotation centres), frames, mirror pairs;
   every joint must move (else the motion cannot separate that many parts);
4. per-scan poses from per-part Procrustes (:mod:`solver.fit.pose_init`); binary (rigid) skin;
5. alternating optimisation of ``E = Q + λ Q_sym + κ Q_prior`` (objective, bone-length symmetry, a
   weak prior on the joint centres, ρ = JOINT_PRIOR by default) until its relative decrease over one round is below
   ``tol``: (a) joints + poses by Levenberg–Marquardt (:mod:`solver.learn.joints_poses`), (b) weights by BCD
   (:mod:`solver.learn.weights`), (c) rest vertices by sparse least squares (:mod:`solver.learn.rest_shape`),
   each step accepted only if E does not increase;
6. long sequences: steps 2-5 run on at most ``key_scans`` scans (:mod:`solver.learn.key_scans`: the most different
   poses, rest scan included), then every other scan gets its pose fitted with the learned model fixed
   (:func:`poses_of_other_scans`).

Output conventions: the model and poses are in the input coordinates and vertex order; poses are in
scan order (one per scan), scale 1.  The report holds the vertex-to-surface error of every scan vertex
to the posed model surface in mm (mean, std, median, MAD, IQR, max), the vertex-to-vertex RMS, the
objective log, time per stage (s), the chosen rest scan, k and its selection curve, mirror pairs.
"""
import copy
import time
from dataclasses import dataclass, field

import numpy as np

from .. import parallel
from ..errors import ArticulaInputError, Cancelled  # noqa: F401
from ..parallel import single_blas_thread
from .key_scans import KEY_SCANS, select_key_scans
from .joints_poses import (Damping, JointPoseProblem, optimise_joints_and_poses, relative_joint_prior, sizes,
                            symmetry_residuals)
from ..geometry.mesh_graph import components, uniform_laplacian
from ..rig.model import Model, Poses
from ..fit.pose_fit import fit_poses
from ..fit.pose_init import poses_from_part_fits
from ..geometry.procrustes import fit_parts
from .rest_shape import ShapePreconditioner, solve_rest_vertices
from .objective import RigObjective
from ..geometry.rotations import quat_to_rotvec
from .segmentation import choose_num_parts, mirror_map, segment
from .skeleton import build_skeleton
from ..rig.skinning import hybrid_skin
from ..geometry.surface_distance import error_statistics, per_vertex_scan_distances
from .weights import TwoRing, optimise_weights

BYTES_PER_VERTEX_SCAN = 2600    # measured ~1,700 (see working_memory_bytes) x 1.5
MAX_WORK_BYTES = 4e9            # refuse inputs whose estimated working memory exceeds this (bytes)
MIN_JOINT_MOTION_DEG = 1.0      # a joint must rotate at least this much in some scan
OTHER_SCAN_ITERATIONS = 3       # LM iterations of the pose fit of each other scan (Bone_Anim, 360 other frames,
                                # 5 / 10 / 20 parts: mean RMS within 0.004 / 0.04 / 0.09 % of 5 iterations)
OTHER_SCAN_TOL = 1e-6           # ... stopping at this relative decrease
JOINT_PRIOR = 0.01              # default ρ of the joint-centre prior (learn_rig's joint_prior)
GN_GAIN_TOL = 1e-4              # step (a) ends early when its next LM iteration is expected to gain less
                                # than this fraction of E (joint_pose_gn.optimise_joints_and_poses gain_tol)


@dataclass
class LearnResult:
    """model, poses (one per scan, scan order), report (JSON-able dict, see :func:`learn_rig`) and
    scan_distances ``(M, V)``: the distance (metres) of every scan vertex to the posed model surface of its
    scan, the numbers the report's surface-error statistics summarise."""
    model: Model
    poses: Poses
    report: dict = field(default_factory=dict)
    scan_distances: np.ndarray = None


# ----------------------------------------------------------------------------- input checks

def working_memory_bytes(num_scans, num_vertices, num_parts):
    """Estimated peak working memory (bytes) of :func:`learn_rig`, from measurement: MakeHuman, 13,380
    vertices × 30 scans, 19 parts peaked at 1.01 GiB RSS of which 0.36 GiB were the interpreter and the
    data, i.e. ~1.7 kB per vertex-scan (posed copies, Laplacian residuals, the BCD's candidate arrays;
    the joint/pose step's compact Jacobians add only ~50 MB).  Taken with a safety factor of 1.5, plus
    the Gram blocks of the joint/pose step ``8 · M · (n_s + n_o + 1)²``."""
    n_s, n_o = sizes(num_parts)
    return BYTES_PER_VERTEX_SCAN * num_scans * num_vertices + 8 * num_scans * (n_s + n_o + 1) ** 2


def check_input(scans, faces, parts, k_max, key_scans=None):
    """Validate and convert; raises :class:`ArticulaInputError` naming the problem.  The memory estimate
    is for the scans learned from (at most ``key_scans`` of them) plus the array of all scans."""
    scans = np.asarray(scans, dtype=np.float64)
    faces = np.asarray(faces)
    if scans.ndim != 3 or scans.shape[2] != 3:
        raise ArticulaInputError(f"scans: expected shape (M, V, 3) (registered scans sharing one topology), got {scans.shape}")
    M, V = scans.shape[:2]
    if M < 3:
        raise ArticulaInputError(f"scans: {M} scan(s) given; learning a rig needs at least 3 registered scans")
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
    if key_scans and int(key_scans) < 3:
        raise ArticulaInputError(f"key_scans: {key_scans} given; learning a rig needs at least 3 scans "
                                 f"(0 or None: learn from every scan)")
    k_est = parts if parts is not None else k_max
    learned = M if not key_scans else min(M, int(key_scans))
    need = working_memory_bytes(learned, V, k_est) + 24 * M * V
    if need > MAX_WORK_BYTES:
        raise ArticulaInputError(
            f"scans: {M} scans x {V} vertices with {k_est} parts needs about {need / 1e9:.1f} GB of working memory "
            f"(limit {MAX_WORK_BYTES / 1e9:.0f} GB); decimate the meshes or learn from fewer (key) scans")
    n, lab = components(faces, V)
    if n > 1:
        sizes_ = np.sort(np.bincount(lab))[::-1]
        raise ArticulaInputError(f"mesh: {n} disconnected islands (vertex counts {sizes_[:5].tolist()}...); "
                                 f"rig learning needs one connected mesh: remove or join the islands")
    return scans, faces.astype(np.int32)


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

def _sym_pairs(skeleton, pairs):
    """(l, suc_l, r, suc_r) for mirror pairs whose bones continue into a mirrored child."""
    out = []
    for l, r in pairs:
        sl = [c for c in skeleton.children(l) if np.linalg.norm(skeleton.heads[c] - skeleton.tails[l]) < 1e-9]
        sr = [c for c in skeleton.children(r) if np.linalg.norm(skeleton.heads[c] - skeleton.tails[r]) < 1e-9]
        if sl and sr:
            out.append((l, sl[0], r, sr[0]))
    return out


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


def initialise(scans, faces, parts, seed, symmetry, initial_skeleton, k_max, progress, rest_index):
    """Steps 2-4 with scan ``rest_index`` as the initial rest mesh.  Returns (model, poses, info dict)."""
    rest = scans[rest_index].copy()
    check_motion(rest, scans, faces)
    info = dict(rest_scan=rest_index)
    if initial_skeleton is not None:
        initial_skeleton.validate()
        bone_labels = _labels_from_skeleton(rest, initial_skeleton)
        B = initial_skeleton.num_bones
        W, tau = fit_parts(rest, scans, bone_labels, B)
        skeleton, pairs = copy.deepcopy(initial_skeleton), []
        info.update(parts=B, k_curve_mm=None)
    else:
        if parts is None:
            k, curve = choose_num_parts(rest, scans, faces, k_max=k_max, seed=seed, progress=progress)
            info["k_curve_mm"] = (curve * 1e3).tolist()
        else:
            k = int(parts)
            info["k_curve_mm"] = None
        mirror = mirror_map(rest, scans, faces) if symmetry and k > 1 else None
        labels, rms = segment(rest, scans, faces, k, seed=seed, mirror=False if mirror is None else mirror)
        info.update(parts=k, segmentation_rms_mm=rms * 1e3)
        R, t = fit_parts(rest, scans, labels, k)
        skeleton, order, bone_of_part, pairs = build_skeleton(rest, labels, faces, k, R, t, symmetry=symmetry,
                                                              symmetry_scans=scans, mirror=mirror)
        bone_labels = bone_of_part[labels]
        W, tau = R[:, order], t[:, order]
    poses = poses_from_part_fits(skeleton, W, tau)
    check_joint_motion(skeleton, poses)
    V, B = len(rest), skeleton.num_bones
    model = Model(rest, faces, skeleton, bone_labels.astype(np.int32),
                  np.zeros((V, B), np.float32), np.zeros((V, B), np.float32))
    info["mirror_pairs"] = [(skeleton.names[l], skeleton.names[r]) for l, r in pairs]
    return model, poses, info, pairs


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
    damping: Damping = field(default_factory=Damping)
    joint_move: bool = True


@dataclass
class Settings:
    """Inner-step settings of one alternation round (see :func:`learn_rig` for their meaning), the mesh's
    BCD graph and the per-α state (:meth:`at`)."""
    gn_iterations: int = 3
    bcd_sweeps: int = 3
    bcd_steps: tuple = (0.2, 0.1, 0.05, 0.02)
    graph: object = None        # the mesh's weights_bcd.TwoRing, built once
    gn_gain_tol: float = GN_GAIN_TOL
    states: dict = field(default_factory=dict)          # α -> AlphaState

    def at(self, objective):
        """The :class:`AlphaState` of ``objective``'s α (made at the first use)."""
        if objective.alpha not in self.states:
            self.states[objective.alpha] = AlphaState(ShapePreconditioner(objective.L, objective.alpha))
        return self.states[objective.alpha]


def alternation_round(model, poses, problem, scans, settings, fix_joints, timings, progress=None, E=None):
    """One round of steps (a) joints + poses, (b) weights, (c) rest vertices for the objective of
    ``problem`` (:class:`JointPoseProblem`); each step is kept only if ``E = Q + λ Q_sym + κ Q_prior`` does
    not increase.  Once the BCD's joint move has been rejected at this α it is not tried again in later
    rounds (:class:`AlphaState`): late in the alternation it never gains (MakeHuman, 19 parts: rejected
    at its first try in every round at α = 100, ~0.9 s each).
    E: the problem's value at (model, poses) if known (computed otherwise).
    Returns ``(model, poses, [(step, E), ...])``; ``timings`` (dict of seconds per step) is added to."""
    objective = problem.objective
    state = settings.at(objective)
    sub = (lambda lo, hi, off=0.0: _sub_progress(progress, lo, hi, off))
    log = []
    t0 = time.perf_counter()
    E = problem.value(model, poses) if E is None else E
    model, poses, gn_log = optimise_joints_and_poses(
        model, poses, problem, iterations=settings.gn_iterations, progress=sub(0.0, 1 / 3),
        fix_joints=fix_joints, damping=state.damping, value=E, gain_tol=settings.gn_gain_tol)
    timings["joints_and_poses"] += time.perf_counter() - t0
    E = gn_log[-1] if gn_log else E
    log.append(("joints_and_poses", float(E)))
    sym_term = problem.shared_value(model.skeleton)           # E − Q: the terms of the skeleton alone
    t0 = time.perf_counter()
    model, w_log, state.joint_move = optimise_weights(
        model, poses, objective, max_sweeps=settings.bcd_sweeps, steps=settings.bcd_steps,
        progress=sub(1 / 3, 2 / 3, sym_term), jacobi=state.joint_move, graph=settings.graph)
    timings["weights"] += time.perf_counter() - t0
    E = min(E, w_log[-1] + sym_term) if w_log else E
    log.append(("weights", float(E)))
    t0 = time.perf_counter()
    trial = copy.copy(model)
    trial.rest_vertices, posed = solve_rest_vertices(model, poses, scans, objective.L, objective.alpha,
                                                     state.shape, with_posed=True)
    E_trial = objective.value(posed) + sym_term
    if E_trial <= E:
        model, E = trial, E_trial
    timings["rest_vertices"] += time.perf_counter() - t0
    log.append(("rest_vertices", float(E)))
    return model, poses, log


def poses_of_other_scans(model, key_poses, scans, keys, progress=None):
    """Poses ``(M frames, scan order)`` of all ``scans (M, V, 3)``: the learned ``key_poses`` for the scans
    ``keys`` and, for every other scan, a pose fitted with the model fixed (:func:`solver.fit.pose_fit.fit_poses`
    from per-part Procrustes, at most ``OTHER_SCAN_ITERATIONS`` LM iterations).  Returns
    ``(poses, fit report dict)``."""
    M = len(scans)
    others = np.setdiff1d(np.arange(M), keys)
    fit = fit_poses(model, scans[others], max_iterations=OTHER_SCAN_ITERATIONS, tol=OTHER_SCAN_TOL,
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
def learn_rig(scans, faces, parts=None, alpha=100.0, symmetry=True, max_iterations=4, seed=0,
              initial_skeleton=None, progress=None, lam=1e10, gn_iterations=3, bcd_sweeps=3, tol=1e-4,
              k_max=20, joint_warmup_rounds=1, bcd_steps=(0.2, 0.1, 0.05, 0.02), rest_scan=None,
              warm_start=(0.01, 0.1), joint_prior=JOINT_PRIOR, key_scans=KEY_SCANS, workers=None):
    """Learn a hybrid-skinned rig from registered scans.

    scans ``(M,V,3)`` metres (M ≥ 3, one topology), faces ``(F,3)`` int.  parts: number of parts k (= bones;
    None = chosen from the motion, up to k_max).  alpha: shape-conformance weight of the Laplacian term
    (dimensionless, see :mod:`solver.learn.objective`).  symmetry: cut mirror-image parts alike
    (:func:`solver.learn.segmentation.segment`), detect mirror pairs and equalise their bone lengths with
    weight lam (m⁻²).  max_iterations: outer rounds of (a)-(c) (stopping earlier when a
    round lowers E by less than ``tol`` relative).  gn_iterations: at most this many LM iterations in step
    (a), fewer when the next one is expected to gain less than ``GN_GAIN_TOL`` of E (measured on
    MakeHuman game_engine male,thin hybrid, whole learn_rig in one session: step (a) 25.0 → 16.1 s, final
    E 39.278 → 39.327, training error 2.516 → 2.519 mm; on Bone_Anim at 20 parts, α = 1, every round
    keeps its three iterations: RMSE 0.0141 either way).  seed: rest-scan choice and segmentation
    seeding.  rest_scan: index of the scan used as initial rest mesh (default: chosen by
    the seed).  initial_skeleton: a :class:`Skeleton` in the coordinates of the rest scan to start from
    instead of segmenting (parts = nearest bone segment).
    progress(fraction, stage, objective): called throughout; may raise :class:`Cancelled`; the objective
    passed never increases.  joint_warmup_rounds: in the first rounds step (a) updates poses only, with the
    joints held at their initial (rotation-centre) estimates: with binary initial weights and α = 100 the
    Laplacian term at the parts' seams otherwise pulls joints away from the true centres (measured on
    the tube body: up to 36 mm, vs ≤ 5 mm with α = 1).  bcd_steps: the BCD's weight steps δ.
    warm_start: rounds before the main alternation, one per value, with the Laplacian weight set to
    that fraction of ``alpha`` (a continuation: with the full shape term a vertex's weights can only move
    with its neighbours', so from binary weights the alternation crawls).  They are logged separately
    (``report["warm_start_log"]``; ``report["initial_objective"]`` is E at ``alpha`` before them) and
    kept only if they lower E at ``alpha`` (else the run continues from the initialisation); the main log of E at ``alpha`` starts where they end and never
    increases.  None with ``max_iterations = 0`` (initialisation only).  Measured on skinning_gt's cylinder (4 parts, 8 scans; Dem Bones' RMSE 0.0174): 10 rounds
    at α = 100 end at E 25.9, RMSE 0.041; warm start (0.01, 0.1) + 8 rounds at E 11.7, RMSE 0.024, in
    less time.
    joint_prior: ρ of a weak prior ``Σ_b κ_b ‖h_b − h⁰_b‖²`` on the joint centres (h⁰ = the initial
    rotation-centre estimates; κ_b = ρ × the joint's mean data curvature,
    :func:`solver.learn.joints_poses.relative_joint_prior`; 0 = none).  Without it near-hinge joints slide
    along their axes, where the data hardly determine them: on MakeHuman game_engine male,thin hybrid
    (19 parts) the right knee drifted 13 → 89 mm from the generating joint over the six rounds (a
    throw-away script following the joints round by round).  Default ``JOINT_PRIOR`` = 0.01; on the 8
    MakeHuman cases of ``./run bench learn --parts 19`` (19 parts, 30 scans; mean joint error mm without,
    the 18:57 run at cfae606 → with, the 21:08 run at 226e7ed; game_engine male,thin hybrid was also
    21.9 without at 96ae482): cmu_mb 15.8 → 15.5, 9.9 → 9.7, 11.5 → 10.6, 13.6 → 11.9, game_engine
    16.9 → 15.8, 12.6 → 12.4, 11.8 → 11.8, 21.8 → 16.6; training surface error within +0.03 mm
    (1.41 → 1.44 the largest change).  It costs data fit where the joints are free to serve it:
    Bone_Anim (α = 1, 5 / 10 / 20 parts, throw-away runs at 226e7ed) RMSE 0.0280 / 0.0181 / 0.0141 →
    0.0297 / 0.0197 / 0.0152, so the pure data-fit setting is ``alpha=1, joint_prior=0``.
    key_scans: learn the skeleton, weights and rest vertices from at most this many scans
    (:func:`solver.learn.key_scans.select_key_scans`, always including the rest scan; None = all) and fit the
    pose of every other scan with the learned model fixed (:func:`poses_of_other_scans`); the objective
    log is then that of the key scans, the report covers all scans (``report["key_scans"]``: the indices).
    Sequences of up to ``KEY_SCANS`` scans are learned from every scan.
    workers: solver threads (:mod:`solver.parallel`; None or 0 = one per CPU core, 1 = serial); the result
    depends on it only to rounding.
    Runs with numpy's BLAS on one thread (:func:`solver.parallel.single_blas_thread`): its many mid-size
    products lose more to thread hand-offs than they gain from a second core.
    Defaults (2 warm-start + 4 rounds of 3 LM iterations and 3 BCD sweeps) measured on MakeHuman, 13,380
    v x 30 scans, 19 parts (``./run bench learn_speed``): 2 + 5 rounds 64 s CPU, 1.44 mm mean surface error,
    vertex RMS 4.45 mm; 2 + 10 rounds with 5 + 5 inner steps 177 s CPU, 1.42 mm, 4.38 mm.
    Returns :class:`LearnResult`."""
    options = {k: v for k, v in locals().items() if k not in ("scans", "faces", "workers")}
    with parallel.using(workers) as threads:
        result = _learn_rig(scans, faces, **options)
    result.report["workers"] = threads
    return result


def _learn_rig(scans, faces, parts, alpha, symmetry, max_iterations, seed, initial_skeleton, progress, lam,
               gn_iterations, bcd_sweeps, tol, k_max, joint_warmup_rounds, bcd_steps, rest_scan, warm_start,
               joint_prior, key_scans):
    """The body of :func:`learn_rig` (same arguments)."""
    t_all = time.perf_counter()
    timings = {key: 0.0 for key in ("initialisation", "joints_and_poses", "weights", "rest_vertices")}
    all_scans, faces = check_input(scans, faces, parts, k_max, key_scans)
    rest_index = choose_rest_scan(len(all_scans), seed, rest_scan)
    keys = (select_key_scans(all_scans, int(key_scans), first=rest_index) if key_scans
            else np.arange(len(all_scans)))
    scans = all_scans[keys] if len(keys) < len(all_scans) else all_scans
    warm = [float(f) * alpha for f in warm_start] if max_iterations > 0 else []
    rounds = len(warm) + max_iterations
    end = 1.0 if len(keys) == len(all_scans) else 0.9          # the rest: poses of the other scans
    span = lambda r: (0.1 + (end - 0.1) * r / max(rounds, 1),   # noqa: E731
                      0.1 + (end - 0.1) * (r + 1) / max(rounds, 1))

    t0 = time.perf_counter()
    model, poses, info, pairs = initialise(scans, faces, parts, seed, symmetry, initial_skeleton, k_max,
                                           _sub_progress(progress, 0.0, 0.1), int(np.searchsorted(keys, rest_index)))
    info["rest_scan"] = rest_index
    timings["initialisation"] = time.perf_counter() - t0
    L = uniform_laplacian(faces, len(scans[0]))
    settings = Settings(gn_iterations, bcd_sweeps, tuple(bcd_steps), TwoRing(L))
    sym = _sym_pairs(model.skeleton, pairs) if symmetry else []

    prior_heads = model.skeleton.heads.copy()          # the initial rotation-centre estimates
    kappa = (relative_joint_prior(model, poses, RigObjective(scans, L, alpha), joint_prior)
             if joint_prior > 0 else 0.0)

    def problem_for(a):
        return JointPoseProblem(RigObjective(scans, L, a), sym, lam if sym else 0.0,
                                prior_heads=prior_heads, kappa=kappa)

    problem = problem_for(alpha)
    objective = problem.objective
    E_initial = problem.value(model, poses)
    if progress is not None:
        progress(0.1, "initialised", E_initial)
    start = (model, poses)
    warm_log = []
    for r, a in enumerate(warm):
        model, poses, steps = alternation_round(model, poses, problem_for(a), scans, settings,
                                                r < joint_warmup_rounds, timings,
                                                _quiet(progress, *span(r), f"warm start (alpha {a:g})"))
        warm_log += [(f"{name} (alpha {a:g})", e) for name, e in steps]
    E = problem.value(model, poses)
    if E > E_initial:                       # the warm start is kept only if it lowers E at α
        (model, poses), E = start, E_initial
        warm_log.append(("warm start discarded", float(E)))
    log = [("initial", float(E))]
    if progress is not None and warm:
        progress(span(len(warm))[0], "warm start done", E)
    converged = False
    it = -1
    for it in range(max_iterations):
        E_round = E
        r = len(warm) + it
        model, poses, steps = alternation_round(model, poses, problem, scans, settings,
                                                r < joint_warmup_rounds, timings,
                                                _sub_progress(progress, *span(r)), E)
        log += steps
        E = steps[-1][1]
        if progress is not None:
            progress(span(r)[1], f"round {it + 1} of {max_iterations}", E)
        if r >= joint_warmup_rounds and E_round - E <= tol * E_round:
            converged = True
            break

    info["key_scans"] = keys.tolist()
    if len(keys) < len(all_scans):
        t0 = time.perf_counter()
        poses, info["other_scans"] = poses_of_other_scans(model, poses, all_scans, keys,
                                                          _sub_progress(progress, end, 1.0))
        timings["other_scans"] = time.perf_counter() - t0
        objective = RigObjective(all_scans, L, alpha)
    t0 = time.perf_counter()
    report, distances = make_report(model, poses, all_scans, objective, sym, problem.lam)
    timings["report"] = time.perf_counter() - t0
    timings["total"] = time.perf_counter() - t_all
    report.update(info)
    report.update(objective_log=log, warm_start_log=warm_log, initial_objective=float(E_initial),
                  iterations=it + 1, converged=converged, timings_s=timings, alpha=alpha,
                  symmetry_lambda=problem.lam, joint_prior=joint_prior)
    model.validate()
    poses.validate(model.skeleton.num_bones)
    return LearnResult(model, poses, report, distances)


def _quiet(progress, lo, hi, stage):
    """Progress of a warm-start round: its fraction and stage name, no objective (it is not E at α)."""
    if progress is None:
        return None
    return lambda f, _stage, _obj: progress(lo + (hi - lo) * f, stage, None)


def make_report(model, poses, scans, objective, sym, lam):
    """``(report, distances (M,V))``: error statistics in mm of every scan vertex to the posed model
    surface (exact point-to-triangle), and those distances in metres."""
    posed = hybrid_skin(model, poses)
    d = per_vertex_scan_distances(scans, posed, model.faces)
    stats = {k: (v if k == "count" else v * 1e3) for k, v in error_statistics(d).items()}
    report = dict(surface_error_mm=stats,
                  vertex_rms_mm=float(np.sqrt(np.mean(np.sum((posed - scans) ** 2, axis=2))) * 1e3),
                  objective_Q=objective.value(posed))
    if sym:
        r, _ = symmetry_residuals(model.skeleton, sym)
        report["symmetry_length_difference_mm"] = (np.abs(r) * 1e3).tolist()
    return report, d
