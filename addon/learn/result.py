"""The learned rig in the scene and on disk: :func:`build` (main thread, inside ``scene_guard``) builds the
exact swing/twist rig from an in-memory bundle, bakes the poses on the scan-sequence object's frames (scan
k on frame ``frame_start + k``, so scrubbing replays the scans with the learned rig), adds the heat map and
stores the report on the armature; :func:`save` writes the bundle.  The rig gets the scans' object matrix
(``LearnInput.matrix``): the bundle is in the scans' coordinates, the rig stands where the scans stand."""
import json
import os

from mathutils import Matrix

from ...solver.errors import ArticulaInputError
from ...solver.formats.bundle import Bundle, save_bundle
from ...solver.learn.options import LearnOptions
from ..rig import builder as rig_builder
from ..rig import bundle_io as rig_io
from .heat_map import add_heat_map
from .inputs import input_from_object
from .report import REPORT_PROPERTY, report_json
from .solve import learn


def build(context, outcome, name: str = ""):
    """Build the learned rig of :class:`addon.learn.solve.LearnOutcome` ``outcome``, bake one key per
    scan on the scans' frames and add the heat map.  Returns ``(rig, action)``.  Call inside
    ``scene_guard``."""
    inp = outcome.input
    bundle = Bundle(outcome.model, outcome.poses, {"source": "learn_rig", "scans": inp.source})
    rig_builder.check_model(bundle.model, bundle.poses)
    rig, action = rig_io.build_bundle(context, bundle, name or f"{inp.name} Rig", True, inp.frame_start)
    rig.armature.matrix_world = Matrix(inp.matrix.tolist())     # the mesh and twist armature are its children
    add_heat_map(rig.mesh.data, outcome.vertex_error_mm)
    rig.armature[REPORT_PROPERTY] = json.dumps(report_json(outcome))
    return rig, action


def check_output_path(path: str) -> None:
    """Refuse an output file whose folder does not exist (before the run, not after it)."""
    if path:
        folder = os.path.dirname(os.path.abspath(path))
        if not os.path.isdir(folder):
            raise ArticulaInputError(f"{path}: folder {folder!r} does not exist")


def save(path: str, outcome) -> None:
    """Write the learned model and its per-scan poses (input coordinates and vertex order, one pose per
    scan in scan order) to a bundle; the report goes into the provenance."""
    check_output_path(path)
    try:
        save_bundle(path, outcome.model, outcome.poses,
                    {"source": "learn_rig", "scans": outcome.input.source, "report": report_json(outcome)})
    except OSError as exc:
        raise ArticulaInputError(f"{path}: cannot write the bundle ({exc.strerror or exc})") from None


def learn_from_object(context, ob, options: LearnOptions = None, name: str = "", progress=None):
    """Learn a rig from scan-sequence object ``ob`` and build it, synchronously (for the demo and
    scripts).  Returns ``(rig, action, outcome)``; on failure the scene is left as it was."""
    from ..jobs import scene_guard
    outcome = learn(input_from_object(ob), options or LearnOptions(), progress)
    with scene_guard():
        rig, action = build(context, outcome, name)
    return rig, action, outcome
