"""Evaluation of rig learning (issue 4) against exact ground truth and the peer tool Dem Bones: training
error, held-out error, joint-centre error, time and memory of ``solver.learn.pipeline.learn_rig``.
(``bench_learn_speed.py`` times the learner's stages; this one evaluates the result.)

Sections (every number with its unit; the output is also written to ``bench/results/``):

1. MakeHuman sequences (``sample_scenes.registered.posed_sequence``; 13,380 vertices; rigs ``cmu_mb`` and
   ``game_engine``; shapes ``female,heavy`` and ``male,thin``; generating skins ``lbs`` and ``hybrid``;
   30 random range-of-motion training poses + 10 held-out poses from another seed):
   * training error: every training-scan vertex to the surface of the learned model posed with its learned
     pose (mm: mean, std, median, MAD, IQR, max — spec §4.1 / §6.1, ``solver.fit.metrics``);
   * held-out error: the learned model FIXED, one pose per held-out scan fitted by ``solver.fit.pose_fit``
     (Levenberg–Marquardt from a per-part Procrustes start), the same distance;
   * joint-centre error: learned joint centres matched to the generating rig's joints (Hungarian
     assignment, ``solver.fit.metrics.match_joints``), both posed in every training scan (the learned rest pose
     is one of the scans), mean distance over the scans per matched pair, mm;
   * wall and CPU time, and peak resident memory of the learning process (a fresh child process per
     run, ``VmHWM``; its baseline after the imports is printed too).
   A reference row needs no learner: ``pose_fit`` with the generating rig's own hybrid model on the held-out
   scans (0 mm for hybrid-skinned data: checks the fitter and the metric end to end).
2. ``../shared/data/skinning_gt`` cylinder and wolf (libigl .tgf skeleton, .DMAT weights, .Tmat transforms,
   posed OBJ meshes; ``solver.formats.libigl``): the exact rig's own reproduction error (reader check), Dem Bones
   with as many bones as the rig, and ``learn_rig`` with as many parts: reconstruction error and joint-centre
   error against the rig's joints, in the files' units and relative to the bounding-box diagonal.
3. Dem Bones (``py-dem-bones`` 0.13.1 from PyPI, in its own virtual environment
   ``$ARTICULA_HOME/venv-dembones``, run in a subprocess by ``bench/dembones_runner.py``; never imported by
   Articula) with its default parameters, on its own example ``Bone_Anim`` (400 frames x 754 vertices, rest
   ``Bone_Geom_rest.obj``, whose vertex order equals the frames') at 5, 10 and 20 bones and on the first
   MakeHuman training sequence at our part count, next to ``learn_rig`` with parts = 5 / 10 / 20 / ours.
   On Bone_Anim ours runs three times per count: with the defaults (α = 100, joint prior ρ = 0.01) and
   with α = 1 and no joint prior (both with the default key scans: learned from 40 of the 400 frames, the
   other frames' poses fitted with the learned model), and with α = 1, no prior, learned from all 400
   frames (``key_scans=None``).  Every "ours" row gives wall
   time, process CPU time and the solver's thread count (its default: one per core, as Dem Bones' OpenMP).
   RMSE measures the data term alone, which is all Dem Bones minimises; our objective adds α × the Laplacian (local shape) term,
   and the prior holds joints near their initial estimates, so α = 1 without the prior is the setting that
   optimises what the RMSE measures (the shape term still regularises).
   Dem Bones runs with its OpenMP threads (all cores) and OMP_WAIT_POLICY=PASSIVE (spinning threads made it
   ~10x slower on the shared machine).
   RMSE exactly as Dem Bones defines it (``DemBones::rmse``): sqrt(Σ_frames Σ_vertices ‖x̂ − x‖² / (N·V)),
   checked against the value Dem Bones itself reports; published: 0.0268 / 0.0156 / 0.0099.
   Times: Dem Bones' is that of its ``compute()`` (its ``rmse()`` and the data set-up run outside it); ours is
   printed as the child's whole ``learn_rig`` wall time split into learning and the error report (the exact
   vertex-to-surface statistics over every scan, ``report["timings_s"]["report"]``), and the time ratio
   compares the learning part with ``compute()``.
   Note: Dem Bones' bones are free rigid transforms per frame (6 DoF each, no skeleton), ours are parts of
   one kinematic tree (3 DoF per joint), so at equal counts Dem Bones has more freedom.

4. (only with ``--order tube``) the synthetic tube body of the solver tests (``tests/solver/learn_data.py``,
   509 vertices, 8 parts, hybrid-skin ground truth): 8 training scans, 4 held-out poses from another seed;
   training and held-out error, and joint centres vs the true joints, as in section 1.  Small and quick:
   a check of the whole evaluation path with known truth.

If ``solver.learn.pipeline.learn_rig`` cannot be imported or fails, every "ours" row prints FAILED with the reason
and the benchmark exits with status 1 after printing everything else; no number is ever invented.

Usage: ./run bench learn [--quick] [--no-dembones] [--order SECTIONS] [--out FILE]
       ~/.cache/articula/venv-bpy52/bin/python bench/bench_learn.py [--quick]
--quick: one MakeHuman case per rig (cmu_mb female,heavy hybrid; game_engine male,thin lbs), Bone_Anim at 5
and 10 bones, the cylinder only.  Results: bench/results/learn.txt (learn-quick.txt with --quick).
"""
import argparse
import datetime
import glob
import io
import json
import os
import platform
import re
import resource
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))   # bench_cli loads us by path
import _common  # noqa: E402  (makes ``import articula`` work)

import numpy as np  # noqa: E402

HERE = os.path.dirname(os.path.realpath(__file__))
REPO = os.path.dirname(HERE)
SHARED = os.path.join(os.path.dirname(REPO), "shared", "data")
ARTICULA_HOME = os.environ.get("ARTICULA_HOME", os.path.expanduser("~/.cache/articula"))
DEMBONES_PIN = "py-dem-bones==0.13.1"
DEMBONES_PUBLISHED = {5: 0.0268, 10: 0.0156, 20: 0.0099}
TRAIN_POSES, TEST_POSES = 30, 10


# ------------------------------------------------------------------------------------------ output

class Tee(io.TextIOBase):
    """Writes to the real stdout and, line by line, to the results file (partial results survive a
    stopped run)."""

    def __init__(self, out, path):
        os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
        self.out, self.file = out, open(path, "w")

    def write(self, s):
        self.out.write(s)
        self.file.write(s)
        return len(s)

    def flush(self):
        self.out.flush()
        self.file.flush()

    def close(self):
        self.file.close()


def line(text=""):
    print(text, flush=True)


def stats_text(s, unit="mm"):
    keys = ("mean", "std", "median", "mad", "iqr", "max")
    return "  ".join(f"{k} {s[k]:.3f}" for k in keys) + f" {unit}"


def machine():
    cpu = platform.processor() or "?"
    try:
        with open("/proc/cpuinfo") as f:
            cpu = next((ln.split(":", 1)[1].strip() for ln in f if ln.startswith("model name")), cpu)
    except OSError:
        pass
    return (f"{cpu}, {os.cpu_count()} cores (shared with other jobs), {platform.system()} {platform.release()}, "
            f"Python {platform.python_version()}, numpy {np.__version__}")


# ------------------------------------------------------------------------------------------ learner

def learner_status():
    """``(True, "")`` when ``solver.learn.pipeline.learn_rig`` imports, else ``(False, reason)``."""
    try:
        from articula.solver.learn.pipeline import learn_rig  # noqa: F401
        return True, ""
    except Exception as e:                                               # noqa: BLE001 (reported)
        return False, f"{type(e).__name__}: {e}"


def peak_rss_kb():
    """Peak resident memory of this process in kB: ``VmHWM`` of /proc/self/status (reset by exec, unlike
    ``ru_maxrss``, which a child inherits from the parent's high-water mark at fork), else ``ru_maxrss``."""
    try:
        with open("/proc/self/status") as f:
            for ln in f:
                if ln.startswith("VmHWM:"):
                    return float(ln.split()[1])
    except OSError:
        pass
    return float(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)


def _child_learn(src, dst):
    """In a fresh process: load scans, run learn_rig, save the bundle and the measurements."""
    from articula.solver.formats.bundle import save_bundle
    from articula.solver.learn.pipeline import learn_rig
    data = np.load(src)
    parts, rounds = int(data["parts"]), int(data["rounds"])
    options = json.loads(str(data["options"]))
    if rounds > 0:
        options["max_iterations"] = rounds
    base = peak_rss_kb()
    t0, c0 = time.perf_counter(), _common.cpu_seconds()
    result = learn_rig(np.asarray(data["scans"]), np.asarray(data["faces"]), parts=parts if parts > 0 else None,
                       seed=0, **options)
    wall, cpu = time.perf_counter() - t0, _common.cpu_seconds() - c0
    peak = peak_rss_kb()
    try:
        report = json.loads(json.dumps(getattr(result, "report", {}), default=str))
    except (TypeError, ValueError):
        report = {}
    save_bundle(dst, result.model, result.poses,
                {"wall_s": wall, "cpu_s": cpu, "rss_base_kb": base, "rss_peak_kb": peak, "report": report})


# learn_rig's default α, and a small α (RMSE measures the data term only); True: from every scan, not key scans
BONE_ANIM_RUNS = ((100.0, False), (1.0, False), (1.0, True))
LEARN_TIMEOUT = [None]        # seconds per learn_rig run (--learn-timeout)
LEARN_ROUNDS = [0]            # learn_rig max_iterations (--learn-iterations; 0 = its default)


def run_learner(scans, faces, parts, tmp, options=None):
    """learn_rig in a child process (``options``: further keyword arguments of learn_rig, JSON-able).
    Returns ``(model, poses, measurements)``; raises RuntimeError with the child's last error line if it
    fails or does not finish within ``LEARN_TIMEOUT``."""
    from articula.solver.formats.bundle import load_bundle
    src, dst = os.path.join(tmp, "learn_in.npz"), os.path.join(tmp, "learn_out.npz")
    if os.path.exists(dst):
        os.remove(dst)
    np.savez(src, scans=np.asarray(scans, dtype=np.float64), faces=np.asarray(faces, dtype=np.int32),
             parts=int(parts or 0), rounds=int(LEARN_ROUNDS[0]), options=json.dumps(options or {}))
    try:
        proc = subprocess.run([sys.executable, os.path.join(HERE, "bench_learn.py"), "--child-learn", src, dst],
                              capture_output=True, text=True, timeout=LEARN_TIMEOUT[0])
    except subprocess.TimeoutExpired:
        raise RuntimeError(f"learn_rig did not finish within {LEARN_TIMEOUT[0]:.0f} s (--learn-timeout); "
                           f"no numbers") from None
    if proc.returncode != 0 or not os.path.exists(dst):
        last = (proc.stderr.strip().splitlines() or ["(no message)"])[-1]
        raise RuntimeError(f"learn_rig failed in the child process: {last}")
    b = load_bundle(dst)
    return b.model, b.poses, b.provenance


def learn_detail(meas, num_scans):
    """``learned from K of M scans (the others' poses fitted), CPU c s on n threads`` from a child's
    measurements (its learn_rig report)."""
    rep = meas.get("report", {})
    keys = len(rep.get("key_scans", [])) or num_scans
    fitted = "" if keys >= num_scans else " (the others' poses fitted)"
    return (f"learned from {keys} of {num_scans} scans{fitted}, {meas['cpu_s']:.1f} s CPU on "
            f"{rep.get('workers', '?')} threads (incl. forked helpers)")


def learning_seconds(meas):
    """Wall time (s) of a child's learn_rig without its error report (``timings_s["report"]``: the exact
    vertex-to-surface statistics over all scans, which Dem Bones' timed ``compute()`` has no counterpart
    of; its ``rmse()`` is called outside the timed part too)."""
    return meas["wall_s"] - meas.get("report", {}).get("timings_s", {}).get("report", 0.0)


def wall_split(meas):
    """``W s wall (L s learning + R s error report)``."""
    learn = learning_seconds(meas)
    return f"{meas['wall_s']:.1f} s wall ({learn:.1f} s learning + {meas['wall_s'] - learn:.1f} s error report)"


def versus(db, rmse, meas):
    """``; vs Dem Bones: RMSE r x, time t x (learning / its compute())`` or '' without a Dem Bones result."""
    if db is None:
        return ""
    return (f"; vs Dem Bones: RMSE {rmse / db[0]:.2f}x, time {learning_seconds(meas) / db[1]:.2f}x "
            f"(learning / its compute())")


def learn_or_fail(status, label, prefix, scans, faces, parts, tmp, options=None):
    """:func:`run_learner`, or print ``<prefix>: FAILED - <reason>`` (no numbers) and add ``label`` to the
    failures.  status: ``(have_learner, why, failures)``.  Returns ``(model, poses, measurements)`` or None."""
    have_learner, why, failures = status
    try:
        if not have_learner:
            raise RuntimeError(f"solver.learn.pipeline.learn_rig is not available ({why}); no numbers")
        got = run_learner(scans, faces, parts, tmp, options)
    except RuntimeError as e:
        line(f"{prefix}: FAILED - {e}")
        failures.append(label)
        return None
    line(f"{prefix} objective log: {objective_log_text(got[2])}")
    return got


def objective_log_text(meas):
    """The learner's objective log (warm start, then the rounds' steps) at ten significant digits: the
    number that a change meant to keep behaviour (a refactoring) must leave identical."""
    rep = meas.get("report", {})
    steps = list(rep.get("warm_start_log", [])) + list(rep.get("objective_log", []))
    return " ".join(f"{name}={float(e):.10g}" for name, e in steps) or "(none in the report)"


# ------------------------------------------------------------------------------------------ Dem Bones

def _find_python(version):
    roots = []
    try:
        roots.append(subprocess.run(["pyenv", "root"], capture_output=True, text=True).stdout.strip())
    except OSError:
        pass
    roots.append(os.path.expanduser("~/.pyenv"))
    for root in roots:
        for cand in sorted(glob.glob(os.path.join(root, "versions", f"{version}*", "bin", f"python{version}"))):
            return cand
    for d in os.environ.get("PATH", "").split(os.pathsep):
        cand = os.path.join(d, f"python{version}")
        if os.access(cand, os.X_OK):
            return cand
    return None


def dembones_python():
    """The interpreter of ``$ARTICULA_HOME/venv-dembones`` (created with Python 3.11 or 3.13 and
    ``py-dem-bones`` installed from PyPI on first use).  Raises RuntimeError naming what is missing."""
    venv = os.path.join(ARTICULA_HOME, "venv-dembones")
    py = os.path.join(venv, "bin", "python")
    check = [py, "-c", "import py_dem_bones, numpy"]
    if os.path.exists(py) and subprocess.run(check, capture_output=True).returncode == 0:
        return py
    base = _find_python("3.11") or _find_python("3.13")
    if base is None:
        raise RuntimeError("no Python 3.11 or 3.13 to create venv-dembones (py-dem-bones has wheels for them)")
    line(f"(setting up {venv}: {DEMBONES_PIN} from PyPI)")
    subprocess.run([base, "-m", "venv", venv], check=True)
    proc = subprocess.run([py, "-m", "pip", "install", "-q", "--disable-pip-version-check", DEMBONES_PIN, "numpy"],
                          capture_output=True, text=True)
    if proc.returncode != 0 or subprocess.run(check, capture_output=True).returncode != 0:
        raise RuntimeError(f"installing {DEMBONES_PIN} failed: {(proc.stderr.strip().splitlines() or ['?'])[-1]}")
    return py


def run_dembones(py, rest, frames, faces, bones, tmp):
    """Dem Bones in its own venv.  Returns the runner's output (see dembones_runner.py) as a dict."""
    src, dst = os.path.join(tmp, "db_in.npz"), os.path.join(tmp, "db_out.npz")
    sizes = np.array([len(f) for f in faces], dtype=np.int64)
    corners = np.concatenate([np.asarray(f, dtype=np.int64) for f in faces])
    np.savez(src, rest=rest, frames=frames, face_sizes=sizes, corners=corners, bones=int(bones))
    # OpenMP threads that spin while waiting make Dem Bones 10x slower on a shared 2-core machine
    env = dict(os.environ, OMP_WAIT_POLICY=os.environ.get("OMP_WAIT_POLICY", "PASSIVE"))
    proc = subprocess.run([py, os.path.join(HERE, "dembones_runner.py"), src, dst], capture_output=True, text=True,
                          env=env)
    if proc.returncode != 0:
        raise RuntimeError(f"Dem Bones failed: {(proc.stderr.strip().splitlines() or ['?'])[-1]}")
    with np.load(dst) as out:
        return {k: out[k] for k in out.files}


def rmse_and_seconds(out):
    """``(RMSE, seconds of compute())`` of a :func:`run_dembones` result, for :func:`versus`."""
    return float(out["rmse"]), float(out["seconds"])


# ------------------------------------------------------------------------------------------ data

def read_obj(path):
    """``(vertices (V,3), triangles (T,3), polygons list)`` of an OBJ file."""
    from articula.solver.formats.obj import read_obj as read
    mesh = read(path)
    return mesh.vertices, mesh.triangles(), np.split(mesh.corner_verts, mesh.face_starts[1:])


def bone_anim():
    """Dem Bones' example: rest (754, 3), frames (400, 754, 3), polygons (quads), triangles."""
    d = os.path.join(SHARED, "dem_bones")
    frames = np.load(os.path.join(d, "Bone_Anim_positions_400x754x3.npy")).astype(np.float64)
    rest, tris, polys = read_obj(os.path.join(d, "Bone_Geom_rest.obj"))
    return rest, frames, polys, tris


def skinning_gt(name):
    """The skinning_gt rig ``name``: rest (V,3), triangles, joints (J,3), bones (B,2), weights (V,B), posed
    scans (N,V,3) of poses-1 then poses-2 in natural order, and the exact rig's reproduction (N,V,3)."""
    from articula.solver.formats import libigl as igl_formats
    d = os.path.join(SHARED, "skinning_gt", f"{name}-all")
    rest, tris, _ = read_obj(os.path.join(d, f"{name}.obj"))
    joints, bones = igl_formats.read_tgf(os.path.join(d, f"{name}.tgf"))
    W = igl_formats.read_dmat(os.path.join(d, f"{name}.DMAT"))

    def key(p):
        return (os.path.dirname(p), int(re.findall(r"(\d+)\.obj$", p)[0]))

    scans, exact, As, ts = [], [], [], []
    for obj in sorted(glob.glob(os.path.join(d, "poses-*", "*.obj")), key=key):
        A, t = igl_formats.read_tmat(obj[:-4] + ".Tmat", num_bones=len(bones))
        exact.append(np.einsum("vb,bvi->vi", W, np.einsum("bij,vj->bvi", A, rest) + t[:, None]))
        scans.append(read_obj(obj)[0])
        As.append(A)
        ts.append(t)
    g = dict(rest=rest, faces=tris, joints=joints, bones=bones, weights=W, scans=np.stack(scans),
             exact=np.stack(exact), A=np.stack(As), t=np.stack(ts), dropped=0)
    return _largest_component(g)


def _largest_component(g):
    """Keep the largest connected part of the mesh (learn_rig needs one connected mesh; the wolf's eyes are
    separate islands).  ``dropped`` = the number of vertices removed."""
    from articula.solver.geometry.mesh_graph import components
    _, labels = components(g["faces"], len(g["rest"]))
    if labels.max() == 0:
        return g
    keep = labels == np.argmax(np.bincount(labels))
    new = -np.ones(len(keep), dtype=np.int64)
    new[keep] = np.arange(keep.sum())
    faces = g["faces"][keep[g["faces"]].all(axis=1)]
    out = dict(g, rest=g["rest"][keep], faces=new[faces].astype(np.int32), weights=g["weights"][keep],
               scans=g["scans"][:, keep], exact=g["exact"][:, keep], dropped=int((~keep).sum()))
    return out


def part_joints(g):
    """Posed joints between the parts of a bone graph ``(N, B − 1, 3)``: a joint shared by d bones separates
    d − 1 pairs of parts in any spanning tree of the parts, so it is listed d − 1 times; in frame m it is
    moved by the transform of a bone touching it (all of them agree at a joint of a rigid-bone rig)."""
    joints, bones = g["joints"], g["bones"]
    deg = np.bincount(bones.ravel(), minlength=len(joints))
    idx = np.repeat(np.arange(len(joints)), np.maximum(deg - 1, 0))
    touching = np.array([np.flatnonzero((bones == j).any(axis=1))[0] for j in idx])
    return np.einsum("nkij,kj->nki", g["A"][:, touching], joints[idx]) + g["t"][:, touching]


# ------------------------------------------------------------------------------------------ evaluation

def surface_stats(scans, model, poses):
    """Scan-vertex -> posed-model-surface statistics (mm, for data in metres) and Dem Bones' RMSE (m)."""
    from articula.solver.fit import metrics
    from articula.solver.rig import skinning
    posed = skinning.hybrid_skin(model, poses)
    d = metrics.scan_to_model_distances(scans, posed, model.faces)
    return metrics.statistics_mm(d), metrics.dem_bones_rmse(posed, scans)


def held_out(model, scans):
    from articula.solver.fit import pose_fit
    t0 = time.perf_counter()
    fit = pose_fit.fit_poses(model, scans, max_iterations=30, tol=1e-10)
    seconds = time.perf_counter() - t0
    stats, _ = surface_stats(scans, model, fit.poses)
    return stats, fit, seconds


def posed_joints(model, poses):
    """Learned joint centres (non-root bones) in every frame ``(N, B − 1, 3)``.  The learned rest pose is one
    of the scans, so joints are compared posed, frame by frame, not at rest."""
    from articula.solver.fit import metrics
    return metrics.posed_joints(model.skeleton, poses)[:, 1:]


def joint_errors(learned, reference):
    """Hungarian matching of joint trajectories ``(N, J, 3)``; mean distance over the frames per pair."""
    from articula.solver.fit import metrics
    return metrics.match_joints(learned, reference).distances


# ------------------------------------------------------------------------------------------ sections

def makehuman_cases(quick):
    if quick:
        return [("cmu_mb", "female,heavy", "hybrid"), ("game_engine", "male,thin", "lbs")]
    return [(r, s, k) for r in ("cmu_mb", "game_engine") for s in ("female,heavy", "male,thin")
            for k in ("lbs", "hybrid")]


def section_makehuman(args, tmp, have_learner, why, failures, ours):
    from articula.sample_scenes.registered import posed_sequence
    from articula.sample_scenes.subjects import make_subject
    line("== 1. MakeHuman sequences: learned model vs the generating rig")
    first = None
    for rig, shape, skin in makehuman_cases(args.quick)[args.mh_skip:][:args.mh_cases or None]:
        t0 = time.perf_counter()
        train, faces, gt = posed_sequence(rig, shape, TRAIN_POSES, "rom", skin, seed=0)
        test, _, _ = posed_sequence(rig, shape, TEST_POSES, "rom", skin, seed=1)
        gen = time.perf_counter() - t0
        if first is None:
            first = (train, faces, f"{rig} / {shape} / {skin}")
        B = len(gt["bone_names"])
        line(f"-- {rig} / {shape} / {skin} skin: {TRAIN_POSES} training + {TEST_POSES} held-out poses, "
             f"{train.shape[1]} vertices, generating rig {B} bones  (data {gen:.1f} s)")
        if not args.no_reference:
            exact = make_subject(rig, shape).hybrid_model()
            stats, fit, sec = held_out(exact, test)
            what = "exact skin: expect 0" if skin == "hybrid" else "hybrid skin of the LBS rig, exact joints"
            line(f"   reference: generating rig's hybrid model, held-out poses by pose_fit ({what}): "
                 f"{stats_text(stats)}; {sec / TEST_POSES:.2f} s/frame, {fit.iterations.mean():.1f} LM iterations, "
                 f"{int(fit.converged.sum())}/{TEST_POSES} converged")
        got = learn_or_fail((have_learner, why, failures), f"makehuman {rig}/{shape}/{skin}", "   ours",
                            train, faces, args.parts, tmp)
        if got is None:
            continue
        model, poses, meas = got
        k = model.skeleton.num_bones
        tr, tr_rmse = surface_stats(train, model, poses)
        ours.setdefault("makehuman", (k, tr_rmse, meas))
        ho, hfit, hsec = held_out(model, test)
        ref_heads = gt["posed_heads"][:, 1:]
        je = joint_errors(posed_joints(model, poses), ref_heads) * 1000
        how = "chosen by learn_rig" if not args.parts else "given with --parts"
        line(f"   ours: {k} parts ({how}), {wall_split(meas)}, {learn_detail(meas, len(train))}, "
             f"peak RSS {meas['rss_peak_kb'] / 1024:.0f} MB (baseline after imports {meas['rss_base_kb'] / 1024:.0f} MB)")
        line(f"   ours training error (scan vertex -> learned surface): {stats_text(tr)}")
        line(f"   ours held-out error ({TEST_POSES} poses fitted by pose_fit, model fixed): {stats_text(ho)}; "
             f"{hsec / TEST_POSES:.2f} s/frame, {int(hfit.converged.sum())}/{TEST_POSES} converged")
        line(f"   ours joint centres vs generating rig, posed in every training scan ({len(je)} learned joints "
             f"matched among {ref_heads.shape[1]}; distance averaged over the scans): "
             f"mean {je.mean():.1f}  median {np.median(je):.1f}  max {je.max():.1f} mm")
    return first


def section_skinning_gt(args, tmp, have_learner, why, failures, db_py):
    line("== 2. skinning_gt (exact rigs, libigl formats; lengths in the files' units)")
    for name in args.gt or (("cylinder",) if args.quick else ("cylinder", "wolf")):
        d = os.path.join(SHARED, "skinning_gt", f"{name}-all")
        if not os.path.isdir(d):
            line(f"-- {name}: SKIPPED ({d} not present)")
            continue
        g = skinning_gt(name)
        N, V = g["scans"].shape[:2]
        B = len(g["bones"])
        diag = float(np.linalg.norm(g["rest"].max(0) - g["rest"].min(0)))
        ref_joints = part_joints(g)
        err = np.abs(g["exact"] - g["scans"]).max()
        islands = (f" (largest connected part: {g['dropped']} vertices of separate islands dropped, as "
                   f"learn_rig needs one connected mesh; Dem Bones gets the same)" if g["dropped"] else "")
        line(f"-- {name}: {N} posed meshes x {V} vertices{islands}, {B} bones, {len(g['joints'])} joints, "
             f"rest bounding-box diagonal {diag:.3f}")
        line(f"   exact rig (.DMAT weights, .Tmat transforms) reproduces the meshes to {err:.2e} "
             f"({err / diag:.1e} of the diagonal; the files are rounded)")
        db = None
        if db_py is not None:
            try:
                out = run_dembones(db_py, g["rest"], g["scans"], g["faces"], B, tmp)
                db = rmse_and_seconds(out)
                line(f"   Dem Bones ({int(out['bones'])} bones, given the rig's rest mesh): RMSE {float(out['rmse']):.4f} "
                     f"({float(out['rmse']) / diag:.2e} of diag), {float(out['seconds']):.2f} s")
            except RuntimeError as e:
                line(f"   Dem Bones: FAILED - {e}")
        got = learn_or_fail((have_learner, why, failures), f"skinning_gt {name}", "   ours", g["scans"], g["faces"],
                            B, tmp)
        if got is None:
            continue
        model, poses, meas = got
        stats, rmse = surface_stats(g["scans"], model, poses)
        je = joint_errors(posed_joints(model, poses), ref_joints)
        mean, worst = stats["mean"] / 1000, stats["max"] / 1000                  # back to file units
        line(f"   ours ({model.skeleton.num_bones} parts, {wall_split(meas)}): scan -> learned surface mean "
             f"{mean:.4f} max {worst:.4f} ({mean / diag:.2e} of diag); RMSE (Dem Bones' definition) {rmse:.4f}"
             f"{versus(db, rmse, meas)}")
        line(f"   ours joint centres vs the rig's joints, posed in every scan ({len(je)} matched among "
             f"{ref_joints.shape[1]}; distance averaged over the scans): mean "
             f"{je.mean():.4f} ({je.mean() / diag:.2e} of diag), max {je.max():.4f}")


def section_dembones(args, tmp, have_learner, why, failures, db_py, first_mh, ours):
    from articula.solver.fit import metrics
    line("== 3. Dem Bones (py-dem-bones 0.13.1, default parameters, own venv) vs learn_rig")
    line("   RMSE = sqrt(sum over frames and vertices of |reconstruction - target|^2 / (frames * vertices)), "
         "as DemBones::rmse()")
    if not os.path.isdir(os.path.join(SHARED, "dem_bones")):
        line("   SKIPPED: ../shared/data/dem_bones not present")
        return
    rest, frames, polys, tris = bone_anim()
    diag = float(np.linalg.norm(rest.max(0) - rest.min(0)))
    order = float(np.abs(frames[0] - rest).max())
    line(f"-- Bone_Anim: {frames.shape[0]} frames x {frames.shape[1]} vertices; rest bounding-box diagonal "
         f"{diag:.3f} (published 4.418); frame 0 equals the rest mesh vertex by vertex to {order:.1e} (same order)")
    counts = [c for c in (args.bone_counts or ((5, 10) if args.quick else (5, 10, 20))) if c > 0]
    for bones in counts:
        pub = DEMBONES_PUBLISHED.get(bones, "-")
        db = None
        if db_py is None:
            line(f"   {bones:2d} bones  Dem Bones: FAILED - no venv-dembones")
        else:
            try:
                out = run_dembones(db_py, rest, frames, polys, bones, tmp)
                mine = metrics.dem_bones_rmse(out["reconstruction"], frames)
                db = rmse_and_seconds(out)
                line(f"   {bones:2d} bones  Dem Bones RMSE {float(out['rmse']):.4f} (published {pub}; recomputed here "
                     f"{mine:.4f}), {int(out['bones'])} bones used, {float(out['seconds']):.2f} s, "
                     f"peak RSS {float(out['rss_kb']) / 1024:.0f} MB")
            except RuntimeError as e:
                line(f"   {bones:2d} bones  Dem Bones: FAILED - {e}")
        for alpha, every_scan in BONE_ANIM_RUNS:
            what = f"ours, alpha {alpha:g}" + (" (default)" if alpha == 100 else ", no joint prior (data-fit setting)")
            options = {"alpha": alpha} if alpha == 100 else {"alpha": alpha, "joint_prior": 0.0}
            if every_scan:
                what += ", learned from every scan"
                options["key_scans"] = None
            label = f"dem_bones {bones} alpha {alpha:g}" + (" every scan" if every_scan else "")
            got = learn_or_fail((have_learner, why, failures), label,
                                f"   {bones:2d} parts  {what}", frames, tris, bones, tmp, options)
            if got is not None:
                model, poses, meas = got
                _, rmse = surface_stats(frames, model, poses)
                line(f"   {bones:2d} parts  {what}: RMSE {rmse:.4f}, {model.skeleton.num_bones} parts, "
                     f"{wall_split(meas)}, {learn_detail(meas, len(frames))}, "
                     f"peak RSS {meas['rss_peak_kb'] / 1024:.0f} MB{versus(db, rmse, meas)}")
    if first_mh is None:                                     # section 1 not run (yet): its first sequence
        from articula.sample_scenes.registered import posed_sequence
        rig, shape, skin = makehuman_cases(args.quick)[0]
        train, faces, _ = posed_sequence(rig, shape, TRAIN_POSES, "rom", skin, seed=0)
        first_mh = (train, faces, f"{rig} / {shape} / {skin}")
    train, faces, label = first_mh
    mine = ours.get("makehuman")
    k = mine[0] if mine else (args.parts or 19)
    note = ("our part count" if mine else "--parts" if args.parts
            else "no learned part count: 19 parts, the spec's J + 1")
    line(f"-- MakeHuman {label}: {train.shape[0]} frames x {train.shape[1]} vertices, {k} bones ({note}); "
         f"Dem Bones gets the first scan as its rest mesh, as learn_rig sees only scans")
    out = None
    if db_py is not None:
        try:
            out = run_dembones(db_py, train[0], train, faces, k, tmp)
            line(f"   Dem Bones RMSE {float(out['rmse']) * 1000:.2f} mm, {int(out['bones'])} bones used, "
                 f"{float(out['seconds']):.1f} s, peak RSS {float(out['rss_kb']) / 1024:.0f} MB")
        except RuntimeError as e:
            line(f"   Dem Bones: FAILED - {e}")
    if mine:
        db = None if out is None else rmse_and_seconds(out)
        line(f"   ours (section 1, first case) RMSE {mine[1] * 1000:.2f} mm, {wall_split(mine[2])}"
             f"{versus(db, mine[1], mine[2])}")
    else:
        line(f"   ours: FAILED - no learned model for this sequence ({why or 'see section 1'}); no numbers")
        failures.append("dem_bones makehuman")


def section_tube(args, tmp, have_learner, why, failures):
    sys.path.insert(0, os.path.join(REPO, "tests", "solver"))
    from learn_data import hybrid_truth
    from articula.solver.fit import metrics
    line("== 4. tube body (synthetic, hybrid-skin ground truth; tests/solver/learn_data.py)")
    truth, true_poses, train = hybrid_truth(8, seed=0)
    test = hybrid_truth(5, seed=1)[2][1:]                  # scan 0 of every sequence is the rest pose
    k = truth.skeleton.num_bones
    line(f"-- {len(train)} training + {len(test)} held-out scans x {train.shape[1]} vertices, {k} true parts")
    if not args.no_reference:
        stats, fit, sec = held_out(truth, test)
        line(f"   reference: true model, held-out poses by pose_fit (expect 0): {stats_text(stats)}; "
             f"{int(fit.converged.sum())}/{len(test)} converged")
    got = learn_or_fail((have_learner, why, failures), "tube", "   ours", train, truth.faces, k, tmp)
    if got is None:
        return
    model, poses, meas = got
    tr, _ = surface_stats(train, model, poses)
    ho, hfit, _ = held_out(model, test)
    ref = metrics.posed_joints(truth.skeleton, true_poses)[:, 1:]
    je = joint_errors(posed_joints(model, poses), ref) * 1000
    line(f"   ours: {model.skeleton.num_bones} parts, {meas['wall_s']:.1f} s wall, {meas['cpu_s']:.1f} s CPU, "
         f"peak RSS {meas['rss_peak_kb'] / 1024:.0f} MB")
    line(f"   ours training error: {stats_text(tr)}")
    line(f"   ours held-out error ({len(test)} poses fitted by pose_fit): {stats_text(ho)}; "
         f"{int(hfit.converged.sum())}/{len(test)} converged")
    line(f"   ours joint centres vs the true joints ({len(je)} matched among {ref.shape[1]}; averaged over the "
         f"scans): mean {je.mean():.1f}  median {np.median(je):.1f}  max {je.max():.1f} mm")


# ------------------------------------------------------------------------------------------ main

def main(argv=None):
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["--child-learn"]:
        _child_learn(argv[1], argv[2])
        return 0
    p = argparse.ArgumentParser(prog="bench learn")
    p.add_argument("--quick", action="store_true", help="a subset (module docstring)")
    p.add_argument("--no-dembones", action="store_true", help="skip the Dem Bones runs")
    p.add_argument("--out", default=None, help="results file (default bench/results/learn[-quick].txt)")
    p.add_argument("--parts", type=int, default=0, help="parts for the MakeHuman runs (0: learn_rig chooses)")
    p.add_argument("--learn-timeout", type=float, default=None, help="seconds per learn_rig run (default none)")
    p.add_argument("--learn-iterations", type=int, default=0,
                   help="learn_rig max_iterations (outer rounds; 0: the learner's default)")
    p.add_argument("--bone-counts", type=lambda t: [int(x) for x in t.split(",")], default=None,
                   help="bone/part counts on Dem Bones' Bone_Anim (default 5,10,20; --quick 5,10)")
    p.add_argument("--mh-cases", type=int, default=0, help="only the first N MakeHuman cases (0: all)")
    p.add_argument("--mh-skip", type=int, default=0, help="skip the first N MakeHuman cases")
    p.add_argument("--no-reference", action="store_true", help="skip the exact-model pose_fit reference rows")
    p.add_argument("--gt", type=lambda t: t.split(","), default=None,
                   help="skinning_gt rigs (default cylinder,wolf; --quick cylinder)")
    p.add_argument("--order", default="makehuman,skinning_gt,dembones",
                   help="sections to run, in this order (comma-separated; also: tube, the synthetic tube "
                        "body with known truth, not in the default)")
    args = p.parse_args(argv)
    LEARN_TIMEOUT[0] = args.learn_timeout
    LEARN_ROUNDS[0] = args.learn_iterations
    order = [x.strip() for x in args.order.split(",") if x.strip()]
    unknown = set(order) - {"makehuman", "skinning_gt", "dembones", "tube"}
    if unknown:
        p.error(f"--order: unknown sections {sorted(unknown)}")
    out_path = args.out or os.path.join(HERE, "results", "learn-quick.txt" if args.quick else "learn.txt")
    tee = Tee(sys.stdout, out_path)
    real, sys.stdout = sys.stdout, tee
    failures = []
    t_start = time.perf_counter()
    try:
        line(f"command: ./run bench learn {' '.join(argv)}".rstrip())
        line(f"date: {datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC")
        line(f"machine: {machine()}")
        rev = subprocess.run(["git", "-C", REPO, "log", "-1", "--format=%h %cd", "--date=format:%H:%M"],
                             capture_output=True, text=True).stdout.strip()
        line(f"code: commit {rev or '?'} (uncommitted changes, if any, included)")
        have, why = learner_status()
        line(f"learner: {'solver.learn.pipeline.learn_rig' if have else 'MISSING (' + why + ')'}")
        db_py = None
        if not args.no_dembones:
            try:
                db_py = dembones_python()
                line(f"Dem Bones: {DEMBONES_PIN} in {os.path.dirname(os.path.dirname(db_py))}")
            except (RuntimeError, subprocess.CalledProcessError) as e:
                line(f"Dem Bones: FAILED to set up - {e}")
        ours, first = {}, None
        if args.parts:
            line(f"MakeHuman part count: {args.parts} (--parts)")
        if args.learn_iterations:
            line(f"learn_rig outer rounds: at most {args.learn_iterations} (--learn-iterations)")
        if args.learn_timeout:
            line(f"learn_rig time limit: {args.learn_timeout:.0f} s per run (--learn-timeout)")
        with tempfile.TemporaryDirectory(prefix="articula_bench_learn_") as tmp:
            for section in order:
                if section == "makehuman":
                    first = section_makehuman(args, tmp, have, why, failures, ours)
                elif section == "skinning_gt":
                    section_skinning_gt(args, tmp, have, why, failures, db_py)
                elif section == "tube":
                    section_tube(args, tmp, have, why, failures)
                elif not args.no_dembones:
                    section_dembones(args, tmp, have, why, failures, db_py, first, ours)
        line(f"total bench time {time.perf_counter() - t_start:.0f} s; peak RSS of the bench process "
             f"{resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB")
        if failures:
            line(f"FAILED rows ({len(failures)}): {', '.join(failures)}")
    finally:
        sys.stdout = real
        tee.close()
    print(f"(results written to {os.path.relpath(out_path, REPO)})")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
