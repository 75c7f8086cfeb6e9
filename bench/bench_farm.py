"""Farm batch on Flamenco: a local Manager and two Workers track a 300-frame recording vs one process.

Farm batch on Flamenco (issue 22): a Manager and two Workers on this machine (tools/flamenco_local.py),
a 300-frame depth recording (``sample_scenes.depth_bench`` subject 0, 320x240, Kinect v1 noise) tracked
by ``./run farm track`` against one ``./run track`` process in the same run.

Scenarios (``--only``):
* ``main``: wall time of the farm (2 Workers, ``--chunk 150``, overlaps of ``--overlaps``) and of one
  process; the largest vertex distance between the farm's and the one process's posed model per frame
  (bar: within 0.5 mm); Manager CPU seconds per task; shared-storage bytes per frame (depth PNGs read,
  chunk bundles written and read, the merged bundle).
* ``overhead``: the fixed cost of one task (``./run track --frames 0:2``: Blender start, model, recording
  set-up), for the chunk-size plan of docs/farm.md.
* ``scans``: the capture tracker on 24 unregistered 4-camera scans of a turning subject, chunks of 13
  with the default overlap (10), with the repair off (``--agree 0``) and on (the default): the largest
  vertex difference at the cut (and of the pass-1 poses), to the one process (target 0.5 mm), and each
  run's mean error of the 14 major joints against the ground truth.
* ``bad``: Manager unreachable; job type not installed; a Worker killed while it tracks a chunk; a job
  cancelled while it runs.  Nothing may be written at the output path by a failed or cancelled job.

Usage: ./run bench farm [--only main,overhead,bad,scans] [--frames 300] [--overlaps 40,60]
"""
import argparse
import os
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))   # bench_cli loads us by path
import _common  # noqa: E402,F401  (makes ``import articula`` work)

import numpy as np  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.realpath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "tools"))
import flamenco_local  # noqa: E402

RUN = os.path.join(ROOT, "run")
SCAN_CHUNK = 13         # capture chunks 0:13 and 3:24 with the default overlap (10 frames)


def _recording(frames):
    from articula.sample_scenes.depth_bench import bench_recording
    root = os.path.join(flamenco_local.home(), "bench_depth", f"s0_320x240_{frames}")
    return bench_recording(root, 0, (320, 240), frames)


def _vertices(path):
    from articula.solver.formats.bundle import load_bundle
    from articula.solver.rig.skinning import hybrid_skin
    b = load_bundle(path)
    return hybrid_skin(b.model, b.poses)


def _timed(cmd, timeout=1800):
    t0 = time.perf_counter()
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    return r, time.perf_counter() - t0


def _cpu_seconds(pid) -> float:
    with open(f"/proc/{pid}/stat") as fh:
        fields = fh.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _job_types():
    from articula.addon.farm import job_types
    return job_types.FOLDER


def main_scenario(rec, overlaps, folder):
    one = os.path.join(folder, "one.npz")
    r, one_wall = _timed([RUN, "track", "--model", rec["model_path"], "--depth", rec["out_dir"], "--out", one])
    assert r.returncode == 0, r.stderr
    print(f"one process: {len(rec['depth_paths'])} frames in {one_wall:.1f} s", flush=True)
    ref = _vertices(one)
    png = sum(os.path.getsize(p) for p in rec["depth_paths"]) / len(rec["depth_paths"])
    for overlap in overlaps:
        with flamenco_local.LocalFarm(os.path.join(folder, f"farm{overlap}"), _job_types(), RUN) as farm:
            out = os.path.join(folder, f"farm{overlap}", "shared", "tracked.npz")
            cpu0 = _cpu_seconds(farm.manager.pid)
            r, wall = _timed([RUN, "farm", "track", "--manager", farm.url, "--model", rec["model_path"], "--depth",
                              rec["out_dir"], "--out", out, "--chunk", "150", "--overlap", str(overlap), "--poll", "1"])
            assert r.returncode == 0, r.stdout + r.stderr
            cpu = _cpu_seconds(farm.manager.pid) - cpu0
        d = np.linalg.norm(_vertices(out) - ref, axis=2).max(axis=1) * 1000
        n = len(rec["depth_paths"])
        chunk_bytes = sum(os.path.getsize(os.path.join(out + ".farm", f)) for f in os.listdir(out + ".farm")
                          if f.endswith(".npz"))
        tracked = n + overlap                              # frames tracked over both chunks
        print(f"farm, 2 Workers, chunks of 150, overlap {overlap}: {wall:.1f} s vs one process {one_wall:.1f} s "
              f"(farm/one {wall / one_wall:.2f}); frames tracked {tracked} ({100 * overlap / n:.0f} % extra); "
              f"largest vertex difference to the one process {d.max():.3f} mm (frame {int(d.argmax())}; "
              f"{int((d > 0.5).sum())} frames over 0.5 mm); Manager CPU {cpu:.2f} s for 3 tasks; storage per frame: "
              f"{png / 1024:.0f} KiB depth PNG read x {tracked / n:.2f}, chunk bundles {chunk_bytes / n / 1024:.1f} KiB "
              f"written + read, merged {os.path.getsize(out) / n / 1024:.1f} KiB", flush=True)


def overhead_scenario(rec, folder):
    out = os.path.join(folder, "two.npz")
    r, wall = _timed([RUN, "track", "--model", rec["model_path"], "--depth", rec["out_dir"], "--frames", "0:2",
                      "--out", out])
    assert r.returncode == 0, r.stderr
    print(f"fixed cost of one task (./run track --frames 0:2): {wall:.1f} s", flush=True)


def _scans(folder):
    """24 unregistered scans (cached) and the subject's model bundle."""
    root = os.path.join(flamenco_local.home(), "bench_farm", "scans24")
    if not os.path.isfile(os.path.join(root, "ground_truth.npz")):
        subprocess.run([RUN, "samples", "unregistered", "--poses", "24", "--motion", "turn", "--out", root],
                       check=True, capture_output=True)
    model = os.path.join(folder, "subject.npz")
    subprocess.run([RUN, "samples", "subject", "--out", model], check=True, capture_output=True)
    return root, model


def _joint_error(path, gt):
    """Mean distance (mm) per frame of the 14 major joints to the ground truth."""
    from articula.solver.formats.bundle import load_bundle
    from articula.solver.rig.kinematics import forward_kinematics
    b = load_bundle(path)
    Rm, tm = forward_kinematics(b.model.skeleton, b.poses)
    heads = np.einsum("nbij,bj->nbi", Rm, b.model.skeleton.heads) + tm
    names = [str(n) for n in gt["bone_names"]]
    bones = [int(k) for k in gt["major_joint_bones"]]
    ours = [b.model.skeleton.names.index(names[k]) for k in bones]
    return 1000 * np.linalg.norm(heads[:, ours] - gt["posed_heads"][:, bones], axis=2).mean(axis=1)


def scans_scenario(folder):
    root, model = _scans(folder)
    one = os.path.join(folder, "scans_one.npz")
    r, one_wall = _timed([RUN, "track", "--model", model, "--scans", root, "--out", one], timeout=3600)
    assert r.returncode == 0, r.stderr
    gt = np.load(os.path.join(root, "ground_truth.npz"))
    ref, err = _vertices(one), _joint_error(one, gt)
    print(f"captures, one process: 24 frames in {one_wall:.0f} s; joint error {err.min():.0f}-{err.max():.0f} mm "
          f"(mean {err.mean():.1f})", flush=True)
    for agree in ("0", "default"):
        with flamenco_local.LocalFarm(os.path.join(folder, f"scans{agree}"), _job_types(), RUN) as farm:
            out = os.path.join(folder, f"scans{agree}", "shared", "tracked.npz")
            check = [] if agree == "default" else ["--agree", agree]
            r, wall = _timed([RUN, "farm", "track", "--manager", farm.url, "--model", model, "--scans", root,
                              "--out", out, "--chunk", str(SCAN_CHUNK), "--overlap", "10", *check, "--poll", "2"],
                             timeout=3600)
        assert r.returncode == 0, r.stdout + r.stderr
        from articula.solver.formats.bundle import load_bundle
        cut = load_bundle(out).provenance["report"]["merge"]["cuts"][0]
        d = np.linalg.norm(_vertices(out) - ref, axis=2).max(axis=1) * 1000
        e = _joint_error(out, gt)
        repairs = [part for line in r.stdout.splitlines() for part in line.split("; ") if "tracked again" in part]
        pass1 = f" ({cut['pass1_mm']:.2f} mm in pass 1)" if "pass1_mm" in cut else ""
        repaired = "repaired: " + repairs[0] if repairs else "no repair"
        f = cut["frame"]
        print(f"captures, farm --agree {agree}: {wall:.0f} s; {repaired}; cut frame {f}: "
              f"{cut['max_vertex_mm']:.1f} mm between the chunks{pass1}; to the one process "
              f"{d.min():.3g}-{d.max():.3g} mm (target <= 0.5 mm: {d.max() / 0.5:.2f}x); joint error "
              f"{e.min():.0f}-{e.max():.0f} mm (mean {e.mean():.1f}; frames {f}+: {e[f:].mean():.1f} "
              f"vs one process {err[f:].mean():.1f})", flush=True)


def bad_scenario(rec, folder):
    from articula.solver.farm.flamenco import Manager
    out = os.path.join(folder, "bad.npz")
    r, wall = _timed([RUN, "farm", "track", "--manager", "http://127.0.0.1:9", "--model", rec["model_path"],
                      "--depth", rec["out_dir"], "--out", out])
    print(f"Manager unreachable: exit {r.returncode} after {wall:.1f} s: {r.stderr.strip()}; "
          f"output written: {os.path.exists(out)}", flush=True)
    empty = os.path.join(folder, "empty_scripts")
    os.makedirs(empty, exist_ok=True)
    with flamenco_local.LocalFarm(os.path.join(folder, "bare"), empty, RUN, workers=0) as bare:
        r, _ = _timed([RUN, "farm", "track", "--manager", bare.url, "--model", rec["model_path"], "--depth",
                       rec["out_dir"], "--out", out])
        print(f"job type not installed: exit {r.returncode}: {r.stderr.strip()}", flush=True)
    with flamenco_local.LocalFarm(os.path.join(folder, "dying"), _job_types(), RUN) as farm:
        proc = subprocess.Popen([RUN, "farm", "track", "--manager", farm.url, "--model", rec["model_path"],
                                 "--depth", rec["out_dir"], "--out", out, "--chunk", "150", "--overlap", "40",
                                 "--poll", "1"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        t0 = time.perf_counter()
        _wait_active(Manager(farm.url))
        farm.kill_worker(0)
        text, _ = proc.communicate(timeout=1800)
        print(f"a Worker killed while tracking a chunk: exit {proc.returncode} after {time.perf_counter() - t0:.1f} s; "
              f"output written: {os.path.exists(out)}; last lines: {' | '.join(text.strip().splitlines()[-3:])}",
              flush=True)
    cancelled = os.path.join(folder, "cancelled.npz")
    with flamenco_local.LocalFarm(os.path.join(folder, "cancel"), _job_types(), RUN) as farm:
        proc = subprocess.Popen([RUN, "farm", "track", "--manager", farm.url, "--model", rec["model_path"],
                                 "--depth", rec["out_dir"], "--out", cancelled, "--chunk", "150", "--poll", "1"],
                                stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        manager = Manager(farm.url)
        job = _wait_active(manager)
        manager.cancel(job)
        text, _ = proc.communicate(timeout=600)
        print(f"job cancelled on the Manager while tracking: exit {proc.returncode}; "
              f"output written: {os.path.exists(cancelled)}; {text.strip().splitlines()[-1]}", flush=True)


def _wait_active(manager, timeout=120):
    """Id of the first job with an active task (polls the Manager)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        for job in _jobs(manager):
            if any(t["status"] == "active" for t in manager.tasks(job)):
                return job
        time.sleep(0.5)
    raise RuntimeError("no task became active")


def _jobs(manager):
    return [j["id"] for j in manager.request("GET", "/api/v3/jobs").get("jobs", [])]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="bench farm")
    ap.add_argument("--only", default="main,overhead,bad,scans")
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--overlaps", default="40,60")
    args = ap.parse_args(argv)
    reason = flamenco_local.availability()
    if reason:
        print(f"bench farm cannot run: {reason}")
        return 1
    only = set(args.only.split(","))
    rec = _recording(args.frames)
    folder = tempfile.mkdtemp(prefix="bench_farm_")
    if "main" in only:
        main_scenario(rec, [int(x) for x in args.overlaps.split(",")], folder)
    if "overhead" in only:
        overhead_scenario(rec, folder)
    if "bad" in only:
        bad_scenario(rec, folder)
    if "scans" in only:
        scans_scenario(folder)
    print(f"outputs in {folder}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
