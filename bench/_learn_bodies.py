"""Section 0 of ``bench_learn.py`` (``--order issue19``): learned rigs that an animator can use on any body
(issue 19).  Per case, ``learn_rig`` with its DEFAULT options (the part count chosen from the motion; the
child process of :func:`_learn_runs.run_learner`), then Dem Bones (``dembones_runner.py``, its default
parameters, the first scan as its rest mesh, as learn_rig sees only scans) with as many bones as ours chose,
one after the other in the same run.  Printed per case:

* RMSE ratio, ours / Dem Bones, RMSE as Dem Bones defines it (``DemBones::rmse``; ours: the learned model
  posed with its learned pose of every scan, ``_learn_metrics.dem_bones_rmse``);
* wall-time ratio of the command: the child's whole ``learn_rig`` call (learning and its error report; the
  CLI's reading of files and writing of the bundle are outside it) over Dem Bones' ``compute()``;
* worst joint distance from the surface: every learned joint (bone heads but the root's, which is the root
  part's mean vertex, not a rotation centre) against the learned rest mesh, 0 inside it (generalized winding
  number, ``solver.geometry.inside.distance_outside``), as a fraction of the rest mesh's bounding-box
  diagonal;
* mirror pairs (``report["mirror_pairs"]``) and, for the quadrupeds, whether the leg pairs are found: a
  learned part lies on a leg of the generating rig when most of the vertices anchored to it have their
  largest ground-truth weight on a bone of that leg; the front (hind) legs are paired when some mirror pair
  joins a part on the left and a part on the right front (hind) leg;
* parts without vertices: bones with no vertex anchored to them (``model.anchor``, the hard part label) and
  no swing or twist weight above 1e-3;
* MakeHuman only: how many of the 14 major joints of the generating rig (shoulder, elbow, wrist, hip, knee,
  ankle .L/.R, neck, head; ``sample_scenes.bone_roles.major_joints``) have a learned joint within 2 cm, the
  distance being that of the nearest learned joint, both posed in every training scan, averaged over the
  scans (the major joints are over 10 cm apart at rest, so one learned joint cannot serve two).

Cases: MakeHuman ``cmu_mb`` subjects of three shapes (female,heavy / male,thin / average), linear-blend
skin, 30 random range-of-motion poses (every bone moves within its limits) followed by 20 frames of the walk
cycle (50 scans x 13,380 vertices); the wolf of ``skinning_gt/wolf-all`` (27 poses x 5,075 vertices, the
whole mesh with its eye islands); the fox ``sequences/fox_lbs_sequence.npz`` (191 frames x 1,250 vertices,
as stored: its UV seams split the mesh into 57 islands).  Targets: RMSE <= 1.0x Dem Bones; every joint
within 0.05 of the diagonal from the surface; the quadrupeds' front and hind leg pairs found; wall time
<= 2x Dem Bones at 5,000 vertices or more; all 14 major joints within 2 cm (MakeHuman).
Lengths: mm for MakeHuman (metres in the data), the files' units for the quadrupeds.
"""
import os
import re
import time

import numpy as np

from _learn_runs import SHARED, learn_or_fail, line, posed_joints, run_dembones, skinning_gt

MH_RIG, MH_SKIN, MH_ROM, MH_WALK = "cmu_mb", "lbs", 30, 20
MH_SHAPES = {"mh/female-heavy": "female,heavy", "mh/male-thin": "male,thin", "mh/average": "average"}
CASES = tuple(MH_SHAPES) + ("wolf", "fox")
QUICK_CASES = ("mh/female-heavy", "fox")
RMSE_TARGET = 1.0            # ours / Dem Bones
SURFACE_TARGET = 0.05        # worst joint distance outside the rest mesh / bounding-box diagonal
TIME_TARGET = 2.0            # ours / Dem Bones ...
TIME_MIN_VERTICES = 5000     # ... at this many vertices or more
MAJOR_TARGET_M = 0.02        # every major joint of the generating rig has a learned joint this close
EMPTY_WEIGHT = 1e-3          # a part with no anchored vertex and no weight above this is empty


# ------------------------------------------------------------------------------------------ data

def makehuman_case(shape):
    """Range-of-motion poses then walk frames of one subject, with the 14 major joints posed in every scan."""
    from articula.sample_scenes.registered import posed_sequence
    rom, faces, g1 = posed_sequence(MH_RIG, shape, MH_ROM, "rom", MH_SKIN, seed=0)
    walk, _, g2 = posed_sequence(MH_RIG, shape, MH_WALK, "walk", MH_SKIN, seed=0)
    bones = g1["major_joint_bones"]
    major = np.concatenate([g1["posed_heads"][:, bones], g2["posed_heads"][:, bones]])
    return dict(scans=np.concatenate([rom, walk]), faces=faces, major=major,
                major_labels=[str(x) for x in g1["major_joint_labels"]],
                legs=None, unit=1000.0, unit_name="mm",
                what=f"{MH_RIG} / {shape} / {MH_SKIN} skin: {MH_ROM} range-of-motion poses + {MH_WALK} walk frames")


def _chain_legs(joints, bones):
    """Leg of every bone of a .tgf skeleton (``None`` off the legs): a bone is lateral when its end joint is
    off the midline x = 0 (beyond a quarter of the widest joint's |x|); a leg is a chain of lateral bones
    grouped by the midline joint it starts from and its side; of the two such joints the one at larger z is
    the front girdle (the wolf faces +z)."""
    off = np.abs(joints[:, 0]) > 0.25 * np.abs(joints[:, 0]).max()
    parent_bone = {int(b): i for i, (_, b) in enumerate(bones)}
    start = []
    for a, b in bones:
        while off[a] and a in parent_bone:
            a = int(bones[parent_bone[a]][0])
        start.append(int(a) if off[b] else None)
    girdles = sorted({s for s in start if s is not None}, key=lambda j: -joints[j, 2])
    names = dict(zip(girdles, ("front", "hind")))
    return [None if s is None or s not in names else f"{names[s]} {'L' if joints[b, 0] > 0 else 'R'}"
            for s, (_, b) in zip(start, bones)]


def wolf_case():
    g = skinning_gt("wolf", whole=True)
    bone_legs = _chain_legs(g["joints"], g["bones"])
    return dict(scans=g["scans"], faces=g["faces"], major=None, legs=_vertex_legs(g["weights"], bone_legs),
                unit=1.0, unit_name="file units",
                what=f"skinning_gt/wolf-all: {len(g['scans'])} poses, {len(g['bones'])} bones, the whole mesh")


def fox_case():
    d = np.load(os.path.join(SHARED, "sequences", "fox_lbs_sequence.npz"))
    legs = []
    for name in d["joint_names"]:
        m = re.match(r"(Front|Back)_Leg_.*_([LR])$", str(name))
        legs.append(None if m is None else f"{'front' if m[1] == 'Front' else 'hind'} {m[2]}")
    return dict(scans=np.asarray(d["frames"], dtype=np.float64), faces=np.asarray(d["faces"], dtype=np.int32),
                major=None, legs=_vertex_legs(d["weights"], legs), unit=1.0, unit_name="file units",
                what=f"sequences/fox_lbs_sequence.npz: {len(d['frames'])} frames of its clips, "
                     f"{len(d['joint_names'])} joints")


def _vertex_legs(weights, bone_legs):
    """Leg name (or None) of every vertex: that of its largest ground-truth weight's bone."""
    return np.array([bone_legs[b] for b in np.argmax(np.asarray(weights), axis=1)], dtype=object)


def load_case(name):
    if name in MH_SHAPES:
        return makehuman_case(MH_SHAPES[name])
    if name == "wolf":
        if not os.path.isdir(os.path.join(SHARED, "skinning_gt", "wolf-all")):
            raise RuntimeError("../shared/data/skinning_gt/wolf-all not present")
        return wolf_case()
    if not os.path.exists(os.path.join(SHARED, "sequences", "fox_lbs_sequence.npz")):
        raise RuntimeError("../shared/data/sequences/fox_lbs_sequence.npz not present")
    return fox_case()


def _islands(faces, num_vertices):
    """``n islands (largest sizes ...)``."""
    from articula.solver.geometry.mesh_graph import components
    _, labels = components(faces, num_vertices)
    sizes = np.sort(np.bincount(labels))[::-1]
    return f"{len(sizes)} island{'s' if len(sizes) > 1 else ''}" + (
        f" (largest {', '.join(map(str, sizes[:4]))}{', ...' if len(sizes) > 4 else ''} vertices)"
        if len(sizes) > 1 else "")


def mesh_note(scans, faces):
    """The mesh's islands; for vertices that coincide in every scan (split at UV seams), the islands after
    welding them (information only: both tools get the mesh as stored)."""
    V = scans.shape[1]
    _, weld = np.unique(np.round(scans.transpose(1, 0, 2).reshape(V, -1), 6), axis=0, return_inverse=True)
    distinct = int(weld.max()) + 1
    text = _islands(faces, V)
    if distinct < V:
        text += f"; {distinct} distinct vertex trajectories, welded {_islands(weld.ravel()[faces], distinct)}"
    return text


# ------------------------------------------------------------------------------------------ measures

def our_rmse(scans, model, poses):
    import _learn_metrics as metrics
    from articula.solver.rig import skinning
    return metrics.dem_bones_rmse(skinning.hybrid_skin(model, poses), scans)


def joints_outside(model):
    """``(distance (B-1,), diagonal)``: every non-root joint's distance outside the learned rest mesh."""
    from articula.solver.geometry.inside import distance_outside
    rest = model.rest_vertices
    diag = float(np.linalg.norm(rest.max(0) - rest.min(0)))
    return distance_outside(model.skeleton.heads[1:], rest, model.faces), diag


def empty_parts(model):
    """Bones with no anchored vertex and no swing/twist weight above EMPTY_WEIGHT (their names)."""
    B = model.skeleton.num_bones
    count = np.bincount(model.anchor, minlength=B)
    heavy = np.maximum(model.swing_weights.max(axis=0), model.twist_weights.max(axis=0)) > EMPTY_WEIGHT
    return [model.skeleton.names[b] for b in range(B) if count[b] == 0 and not heavy[b]]


def leg_pairs(model, pairs, vertex_legs):
    """``{girdle: (paired, parts on its legs, parts on its legs in a left/right pair)}`` for front and hind."""
    names = list(model.skeleton.names)
    part_leg = []
    for b in range(model.skeleton.num_bones):
        legs = vertex_legs[model.anchor == b]
        legs = [x for x in legs if x is not None]
        top = max(set(legs), key=legs.count) if legs else None
        part_leg.append(top if top is not None and legs.count(top) > 0.5 * np.sum(model.anchor == b) else None)
    out = {}
    for girdle in ("front", "hind"):
        on = {b for b, leg in enumerate(part_leg) if leg and leg.startswith(girdle)}
        crossed = set()
        for left, right in pairs:
            a, b = names.index(left), names.index(right)
            if a in on and b in on and part_leg[a] != part_leg[b]:
                crossed |= {a, b}
        out[girdle] = (bool(crossed), len(on), len(crossed))
    return out


def major_joint_distances(model, poses, major):
    """Distance (m) of each major joint ``major (N, 14, 3)`` to its nearest learned joint, both posed in every
    scan, averaged over the scans."""
    learned = posed_joints(model, poses)                                           # (N, B-1, 3)
    d = np.linalg.norm(learned[:, :, None] - major[:, None], axis=-1).mean(axis=0)  # (B-1, 14)
    return d.min(axis=0)


# ------------------------------------------------------------------------------------------ runs

def run_case(name, status, db_py, tmp):
    """One case: data, ours (defaults), Dem Bones at our bone count.  Returns the row (``None`` for what
    has no number) after printing the case's detail lines."""
    row = dict(case=name, failed=None)
    try:
        t0 = time.perf_counter()
        case = load_case(name)
    except (RuntimeError, OSError) as e:
        line(f"-- {name}: FAILED - {e}")
        return dict(row, failed=str(e))
    scans, faces, u = case["scans"], case["faces"], case["unit"]
    N, V = scans.shape[:2]
    row.update(vertices=V, scans=N, quadruped=case["legs"] is not None, human=case["major"] is not None)
    line(f"-- {name}: {case['what']}; {N} scans x {V} vertices, {len(faces)} triangles, "
         f"{mesh_note(scans, faces)} (data {time.perf_counter() - t0:.1f} s)")
    got = learn_or_fail(status, f"issue19 {name}", "   ours", scans, faces, 0, tmp)
    if got is None:
        return dict(row, failed="learn_rig failed (above)")
    model, poses, meas = got
    rep = meas.get("report", {})
    k = model.skeleton.num_bones
    pairs = [tuple(p) for p in rep.get("mirror_pairs", [])]
    out, diag = joints_outside(model)
    worst = int(np.argmax(out))
    row.update(parts=k, rmse=our_rmse(scans, model, poses), wall=meas["wall_s"], cpu=meas["cpu_s"],
               pairs=len(pairs), empty=empty_parts(model), outside=float(out[worst] / diag))
    line(f"   ours: {k} parts (chosen by learn_rig; report parts {rep.get('parts', '?')}), converged "
         f"{rep.get('converged', '?')} after {rep.get('iterations', '?')} rounds, {meas['wall_s']:.1f} s wall "
         f"({meas['wall_s'] - rep.get('timings_s', {}).get('report', 0.0):.1f} s learning + "
         f"{rep.get('timings_s', {}).get('report', 0.0):.1f} s error report), {meas['cpu_s']:.1f} s CPU, "
         f"RMSE {row['rmse'] * u:.4g} {case['unit_name']}")
    where = (f"{int(np.sum(out > 0))} of {k - 1} outside the rest mesh, the worst ({model.skeleton.names[worst + 1]}) "
             f"{out[worst] * u:.4g} {case['unit_name']} = {row['outside']:.4f} of the diagonal {diag * u:.4g}"
             if out[worst] > 0 else f"all {k - 1} inside the rest mesh")
    line(f"   ours joints (non-root bone heads): {where}; parts without vertices: {len(row['empty'])}"
         f"{' (' + ', '.join(row['empty']) + ')' if row['empty'] else ''}")
    line(f"   ours mirror pairs ({len(pairs)}): {', '.join(f'{a}/{b}' for a, b in pairs) or 'none'}")
    if case["legs"] is not None:
        row["legs"] = leg_pairs(model, pairs, case["legs"])
        line("   ours leg pairs: " + "; ".join(
            f"{g} legs {'paired' if ok else 'NOT paired'} ({c} of {n} parts on them in a left/right pair)"
            for g, (ok, n, c) in row["legs"].items()))
    if case["major"] is not None:
        d = major_joint_distances(model, poses, case["major"])
        row["major"] = (int(np.sum(d <= MAJOR_TARGET_M)), len(d))
        miss = [f"{lab} {x * 100:.1f} cm" for lab, x in zip(case["major_labels"], d) if x > MAJOR_TARGET_M]
        line(f"   ours major joints with a learned joint within {MAJOR_TARGET_M * 100:.0f} cm: {row['major'][0]} of "
             f"{len(d)} (median nearest {np.median(d) * 100:.1f} cm); missed: {', '.join(miss) or 'none'}")
    if not _dem_bones(row, db_py, scans, faces, k, tmp, u, case["unit_name"]):
        status[2].append(f"issue19 {name} Dem Bones")
    return row


def _dem_bones(row, db_py, scans, faces, k, tmp, u, unit_name):
    """Dem Bones at ``k`` bones on the same scans (first scan as rest): its RMSE and compute() seconds into
    ``row``.  Returns False (after printing FAILED and the reason) when there are none."""
    if db_py is None:
        line("   Dem Bones: FAILED - no venv-dembones (set-up failed or --no-dembones)")
        return False
    try:
        out = run_dembones(db_py, scans[0], scans, faces, k, tmp)
    except RuntimeError as e:
        line(f"   Dem Bones: FAILED - {e}")
        return False
    row.update(db_rmse=float(out["rmse"]), db_seconds=float(out["seconds"]), db_bones=int(out["bones"]))
    cpu = float(out["cpu_seconds"]) if "cpu_seconds" in out else float("nan")
    line(f"   Dem Bones ({k} bones asked, {row['db_bones']} used): RMSE {row['db_rmse'] * u:.4g} {unit_name}, "
         f"compute() {row['db_seconds']:.1f} s wall, {cpu:.1f} s CPU; ours / Dem Bones: RMSE "
         f"{row['rmse'] / row['db_rmse']:.2f}x, wall time {row['wall'] / row['db_seconds']:.2f}x (CPU time "
         f"{row['cpu'] / cpu:.2f}x, less sensitive to the other jobs on a shared host)")
    return True


def _cell(row, key, fmt):
    value = row.get(key)
    return "FAILED" if value is None else fmt(value)


def print_table(rows):
    line("   case            vertices x scans  parts  DB bones  RMSE ours/DB  wall ours/DB       worst joint out  "
         "mirror pairs  legs (front, hind)  empty parts  major joints <= 2 cm")
    for r in rows:
        legs = r.get("legs")
        leg_text = "-" if not r.get("quadruped") else "FAILED" if legs is None else ", ".join(
            "yes" if legs[g][0] else "no" for g in ("front", "hind"))
        ratio = (f"{r['rmse'] / r['db_rmse']:.2f}x" if r.get("db_rmse") else "FAILED")
        wall = (f"{r['wall']:.0f}/{r['db_seconds']:.0f} s {r['wall'] / r['db_seconds']:.2f}x"
                if r.get("db_seconds") else f"{r['wall']:.0f} s / FAILED" if r.get("wall") else "FAILED")
        major = "-" if not r.get("human") else _cell(r, "major", lambda m: f"{m[0]}/{m[1]}")
        size = f"{r['vertices']} x {r['scans']}" if "vertices" in r else "FAILED"
        line(f"   {r['case']:<15} {size:<17} {_cell(r, 'parts', str):>5}  {_cell(r, 'db_bones', str):>8}  "
             f"{ratio:>12}  {wall:<17} {_cell(r, 'outside', lambda x: f'{x:.4f} diag'):>15}  "
             f"{_cell(r, 'pairs', str):>12}  {leg_text:<18}  {_cell(r, 'empty', lambda e: str(len(e))):>11}  {major}")


def _verdict(rows, applies, met):
    """``MET`` / ``MISSED`` / ``FAILED`` (some case without numbers) over the rows ``applies`` selects, with
    the cases of each outcome; ``met(row)`` is None when the row has no number."""
    judged = [(r["case"], met(r)) for r in rows if applies(r)]
    if not judged:
        return "not measured (no case)"
    groups = [(word, [c for c, ok in judged if ok is value]) for word, value in
              (("met", True), ("missed", False), ("no numbers", None))]
    word = "MISSED" if groups[1][1] else "FAILED" if groups[2][1] else "MET"
    return word + " - " + "; ".join(f"{w}: {', '.join(cases)}" for w, cases in groups if cases)


def print_targets(rows):
    def ratio(r, a, b):
        return None if r.get(a) is None or not r.get(b) else r[a] / r[b]

    def rmse_met(r):
        x = ratio(r, "rmse", "db_rmse")
        return None if x is None else x <= RMSE_TARGET

    def time_met(r):
        x = ratio(r, "wall", "db_seconds")
        return None if x is None else x <= TIME_TARGET

    targets = [
        (f"RMSE <= {RMSE_TARGET:g}x Dem Bones (MakeHuman and quadrupeds)", lambda r: True, rmse_met),
        (f"every joint within {SURFACE_TARGET:g} of the diagonal from the surface", lambda r: True,
         lambda r: None if r.get("outside") is None else r["outside"] <= SURFACE_TARGET),
        ("quadrupeds: front and hind leg pairs found", lambda r: r.get("quadruped", r["case"] in ("wolf", "fox")),
         lambda r: None if r.get("legs") is None else all(ok for ok, _, _ in r["legs"].values())),
        (f"wall time <= {TIME_TARGET:g}x Dem Bones at {TIME_MIN_VERTICES}+ vertices",
         lambda r: r.get("vertices", 0) >= TIME_MIN_VERTICES or (r["case"] in MH_SHAPES and "vertices" not in r),
         time_met),
        (f"all major joints within {MAJOR_TARGET_M * 100:.0f} cm (MakeHuman)", lambda r: r["case"] in MH_SHAPES,
         lambda r: None if r.get("major") is None else r["major"][0] == r["major"][1]),
    ]
    line("   targets:")
    for text, applies, met in targets:
        line(f"   * {text}: {_verdict(rows, applies, met)}")


def section_issue19(args, tmp, have_learner, why, failures, db_py):
    line("== 0. Issue 19: learned rigs on any body, default options, Dem Bones at our part count (same run)")
    line("   ratios: ours / Dem Bones; wall time: our whole learn_rig call (with its report) / Dem Bones' compute(); "
         "worst joint out: distance outside the learned rest mesh / its bounding-box diagonal (0 inside)")
    if args.learn_iterations:
        line(f"   NOTE: --learn-iterations {args.learn_iterations} given: learn_rig is not at its defaults")
    names = args.cases or (QUICK_CASES if args.quick else CASES)
    rows = [run_case(name, (have_learner, why, failures), db_py, tmp) for name in names]
    for r in rows:
        if r["failed"] and not any(f.endswith(r["case"]) for f in failures):
            failures.append(f"issue19 {r['case']}")
    line("-- issue 19 table")
    print_table(rows)
    print_targets(rows)
    return rows
