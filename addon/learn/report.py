"""The learning report on the Blender side: the solver's report with the run's input and options as JSON
(stored on the armature as ``articula_learn_report`` and in a saved bundle's provenance) and its error
summary."""
import numpy as np

REPORT_PROPERTY = "articula_learn_report"       # armature ID property: the solver's report (JSON)
REPORTED_OPTIONS = ("parts", "alpha", "symmetry", "max_iterations", "seed", "key_scans", "workers", "joint_prior",
                    "memory_limit_gb", "key_scan_budget", "name_roles")


def jsonable(x):
    """``x`` with numpy arrays and scalars, tuples and non-string keys turned into JSON types."""
    if isinstance(x, dict):
        return {str(k): jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return jsonable(x.tolist())
    if isinstance(x, np.generic):
        return x.item()
    return x


def report_json(outcome) -> dict:
    """The solver's report of a :class:`addon.learn.solve.LearnOutcome` with the run's input and options
    (JSON-serialisable)."""
    opts, inp = outcome.options, outcome.input
    options = {name: getattr(opts, name) for name in REPORTED_OPTIONS}
    options["initial_skeleton"] = opts.initial_skeleton is not None
    return jsonable({**outcome.report,
                     "input": {"source": inp.source, "scans": int(len(inp.scans)), "vertices": int(inp.scans.shape[1]),
                               "faces": int(len(inp.faces))},
                     "options": options})


def error_summary(report: dict) -> dict:
    """The error statistics in mm from the solver's report (keys mean, median, max, ...)."""
    for key in ("surface_error_mm", "error_mm"):
        if isinstance(report.get(key), dict):
            return report[key]
    return {k: report[k] for k in ("mean", "std", "median", "mad", "iqr", "max") if k in report}


def summary_text(outcome) -> str:
    """One line of the outcome's error statistics (mm): mean, median, max; the parts (:func:`parts_text`),
    the islands carried rigidly (:func:`islands_text`) and fewer key scans learned from to fit the memory budget, if any."""
    s = error_summary(outcome.report)
    parts = [f"{k} {s[k]:.2f}" for k in ("mean", "median", "max") if k in s]
    text = "error (mm) " + ", ".join(parts) if parts else "no error statistics"
    notes = [parts_text(outcome.report), islands_text(outcome.report),
             (outcome.report.get("memory") or {}).get("note", ""), outcome.report.get("key_scans_note", "")]
    return "; ".join([text] + [n for n in notes if n])


def parts_text(report: dict) -> str:
    """How the rig's parts came about ("" if the report says nothing), e.g. "22 parts (14 from the error
    curve + 8 segments moving on their own), 5 left/right pairs, 2 empty end bones removed, 310 seam
    vertices welded"."""
    out = []
    count = report.get("part_count") or {}
    if "parts" in report:
        how = (f" ({count['curve_parts']} from the error curve + {len(count['splits'])} segments moving on their "
               f"own)" if count.get("splits") else "")
        out.append(f"{report['parts']} parts{how}")
    if report.get("mirror_pairs"):
        out.append(f"{len(report['mirror_pairs'])} left/right pairs")
    if (report.get("bone_names") or {}).get("scheme") == "roles":
        out.append(f"humanoid: {report['bone_names']['roles']} bones named by role")
    removed = report.get("empty_parts_removed") or []
    if removed:
        out.append(f"{len(removed)} empty end bone{'s' if len(removed) != 1 else ''} removed")
    if report.get("welded_vertices"):
        out.append(f"{report['welded_vertices']} seam vertices welded")
    return ", ".join(out)


def islands_text(report: dict) -> str:
    """What the report says about separate mesh islands carried rigidly ("" if none), e.g.
    "2 separate islands (130 vertices) carried rigidly by bones head, torso"."""
    info = report.get("islands") or {}
    if not info.get("count"):
        return ""
    bones = sorted({row["bone"] for row in info.get("islands", [])})
    n = info["count"]
    return (f"{n} separate island{'s' if n != 1 else ''} ({info['vertices']} vertices) carried rigidly by "
            f"bone{'s' if len(bones) != 1 else ''} {', '.join(bones)}")
