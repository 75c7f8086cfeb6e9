"""Helpers of ``bench_learn.py`` and its sections (``_learn_*.py``): output (a results file beside stdout),
``learn_rig`` in a child process with its time and memory, Dem Bones in its own virtual environment
(``dembones_runner.py``), the data sets (Dem Bones' Bone_Anim, the libigl skinning_gt rigs) and the error
measures.  Units: those of the data (metres for MakeHuman), times in seconds."""
import glob
import io
import json
import os
import platform
import re
import resource
import subprocess
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _common  # noqa: E402  (makes ``import articula`` work)

import numpy as np  # noqa: E402

HERE = os.path.dirname(os.path.realpath(__file__))
REPO = os.path.dirname(HERE)
SHARED = os.path.join(os.path.dirname(REPO), "shared", "data")
ARTICULA_HOME = os.environ.get("ARTICULA_HOME", os.path.expanduser("~/.cache/articula"))
DEMBONES_PIN = "py-dem-bones==0.13.1"


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


def child_learn(src, dst):
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


def skinning_gt(name, whole=False):
    """The skinning_gt rig ``name``: rest (V,3), triangles, joints (J,3), bones (B,2), weights (V,B), posed
    scans (N,V,3) of poses-1 then poses-2 in natural order, and the exact rig's reproduction (N,V,3); only the
    largest connected part of the mesh unless ``whole``."""
    import _libigl as igl_formats
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
    return g if whole else _largest_component(g)


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
    import _learn_metrics as metrics
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
    import _learn_metrics as metrics
    return metrics.posed_joints(model.skeleton, poses)[:, 1:]


def joint_errors(learned, reference):
    """Hungarian matching of joint trajectories ``(N, J, 3)``; mean distance over the frames per pair."""
    import _learn_metrics as metrics
    return metrics.match_joints(learned, reference).distances
