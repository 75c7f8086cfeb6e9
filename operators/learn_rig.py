"""``articula.learn_rig``: learn an Articula rig (armature, swing/twist skin, adapted rest mesh) from
registered scans, bake one pose per scan and show the per-vertex error as a heat map.

Input (first match wins): ``files`` in ``directory`` or the folder ``directory`` (mesh files read with
the solver's readers, coordinates as written; ``axis_forward``/``axis_up`` place the rig as
``articula.import_scans`` places those files); the scan-sequence object named ``source_object``; the
active object.  The rig gets the scans' object matrix; the bundle stays in the scans' coordinates.  The work is in :mod:`addon.learn`; the settings' defaults and bounds come from
:class:`solver.learn.options.LearnOptions`.
"""
import contextlib
import os
from dataclasses import replace

import bpy
import numpy as np

from ..addon import preferences
from ..addon.jobs import JobOperator
from ..addon.learn import inputs, result, solve
from ..addon.learn.report import summary_text
from .import_scans import axis_property
from ..solver.errors import ArticulaInputError
from ..solver.learn.options import LearnOptions, fields_by_name, name_setting, property_range


class ARTICULA_OT_learn_rig(JobOperator, bpy.types.Operator):
    """Learn a rig from registered scans: armature, swing/twist skin weights and adapted rest mesh, one
    baked pose per scan and a per-vertex error heat map"""
    bl_idname = "articula.learn_rig"
    bl_label = "Learn Rig from Scans"
    bl_options = {'REGISTER', 'UNDO'}
    job_label = "Learn rig"

    source_object: bpy.props.StringProperty(
        name="Scan Sequence", options={'SKIP_SAVE'},
        description="Registered scan-sequence object to learn from (empty: the active object)")
    directory: bpy.props.StringProperty(
        name="Folder", subtype='DIR_PATH', options={'SKIP_SAVE'},
        description="Folder of registered scans (OBJ/PLY/STL/OFF), used instead of a scan-sequence object")
    files: bpy.props.CollectionProperty(type=bpy.types.OperatorFileListElement, options={'HIDDEN', 'SKIP_SAVE'})
    axis_forward: axis_property("Forward")
    axis_up: axis_property("Up")
    name: bpy.props.StringProperty(name="Name", options={'SKIP_SAVE'},
                                   description="Name of the new rig (empty: after the scans)")
    parts: bpy.props.IntProperty(
        name="Parts", **property_range("parts"),
        description="Number of body parts (bones); 0 chooses it from the motion in the scans")
    alpha: bpy.props.FloatProperty(
        name="Shape Weight (alpha)", **property_range("alpha"),
        description="Weight of the local-shape (Laplacian) term against the absolute position error; "
                    "dimensionless. 100 (for metre-scale human scans) makes a 1 mm error of the local shape "
                    "cost as much as a 10 mm offset: higher keeps surface detail, lower fits positions")
    symmetry: bpy.props.BoolProperty(
        name="Symmetry", **property_range("symmetry"),
        description="Find the mirror plane, pair left/right parts (.L/.R names) and keep them symmetric")
    name_roles: bpy.props.BoolProperty(
        name="Role Names", **property_range("name_roles"),
        description="Name the bones of a recognised humanoid by their roles (hips, spine, chest, neck, head, "
                    "thigh.L, upper_arm.R, ...) so that retargeting maps them without a manual mapping; the "
                    "others keep part names")
    max_iterations: bpy.props.IntProperty(
        name="Max Iterations", **property_range("max_iterations"),
        description="Outer rounds of the alternating optimisation (joints and poses, weights, rest mesh), after two "
                    "warm-start rounds; "
                    "it stops earlier once the objective no longer decreases. 0: initialisation only")
    key_scans: bpy.props.IntProperty(
        name="Key Scans", **property_range("key_scans"),
        description="Learn the skeleton, weights and rest mesh from at most this many scans (the most "
                    "different poses) and fit the poses of the other scans with the learned rig: long "
                    "sequences learn in a fraction of the time. 0: learn from every scan")
    memory_limit_gb: bpy.props.FloatProperty(
        name="Memory Limit (GB)", **property_range("memory_limit_gb"),
        description="Memory the run may use, in GB. 0: 80% of the memory available when it starts. If the key "
                    "scans do not fit, it learns from fewer of them (and says so); it refuses only if 3 do not fit")
    joint_prior: bpy.props.FloatProperty(
        name="Joint Prior", **property_range("joint_prior"), precision=3,
        description="How strongly the joints stay near their first estimates where the motion hardly "
                    "determines them (e.g. along a knee's hinge axis), as a fraction of the data's own pull "
                    "on each joint. 0: no prior (with a small Shape Weight: the closest fit to the scans)")
    seed: bpy.props.IntProperty(name="Seed", **property_range("seed"),
                                description="Random seed of the segmentation (same seed, same result)")
    initial_armature: bpy.props.StringProperty(
        name="Initial Armature", options={'SKIP_SAVE'},
        description="Armature whose bones (world positions) become the initial skeleton instead of the "
                    "automatic one (empty: automatic)")
    output_bundle: bpy.props.StringProperty(
        name="Save Bundle", subtype='FILE_PATH', options={'SKIP_SAVE'},
        description="Also write the learned model and poses to this bundle (.npz); empty: do not write")

    def invoke(self, context, event):
        if not self._has_input():
            self._dialog = True
            return context.window_manager.invoke_props_dialog(self, width=360)
        return JobOperator.invoke(self, context, event)

    def execute(self, context):
        if getattr(self, "_dialog", False) and not bpy.app.background:
            # Confirmed in the options dialog: run as a modal job (progress + Esc) on the active object.
            self._dialog = False
            props = {p.identifier: getattr(self.properties, p.identifier)
                     for p in self.properties.bl_rna.properties if p.identifier not in ("rna_type", "files")}
            if context.active_object is not None and not props["source_object"]:
                props["source_object"] = context.active_object.name
            bpy.ops.articula.learn_rig('INVOKE_DEFAULT', **props)
            return {'CANCELLED'}   # the job pushes its own undo step
        return JobOperator.execute(self, context)

    def draw(self, context):
        col = self.layout.column()
        for prop in ("parts", "alpha", "joint_prior", "symmetry", "name_roles", "max_iterations", "key_scans",
                     "memory_limit_gb", "seed"):
            col.prop(self, prop)
        col.prop_search(self, "initial_armature", bpy.data, "objects")
        col.prop(self, "output_bundle")
        col.prop(self, "name")

    def _has_input(self):
        return bool(self.source_object or self.directory or any(f.name for f in self.files))

    # -- job parts -----------------------------------------------------------------------------------
    def setting_names(self) -> dict:
        """LearnOptions field -> what the user sees: the UI name of the property of the same identifier
        (e.g. parts -> "Parts"); workers come from the preferences' Threads."""
        names = {p.identifier: p.name for p in self.properties.bl_rna.properties if p.identifier in fields_by_name()}
        names["workers"] = "Threads (Articula preferences)"
        return names

    def prepare(self, context):
        """:meth:`_prepare` and its work, their messages naming the settings as the user sees them."""
        names = self.setting_names()
        with _named_settings(names):
            work = self._prepare(context)

        def named_work(progress):
            with _named_settings(names):
                return work(progress)
        return named_work

    def _prepare(self, context):
        options = LearnOptions(parts=self.parts, alpha=self.alpha, symmetry=self.symmetry,
                               max_iterations=self.max_iterations, seed=self.seed, key_scans=self.key_scans,
                               workers=preferences.threads(context), joint_prior=self.joint_prior,
                               memory_limit_gb=self.memory_limit_gb, name_roles=self.name_roles)
        options.validate()
        arm = bpy.data.objects.get(self.initial_armature) if self.initial_armature else None
        if self.initial_armature and arm is None:
            raise ArticulaInputError(f"initial armature: no object named {self.initial_armature!r}")
        out = bpy.path.abspath(self.output_bundle) if self.output_bundle else ""
        result.check_output_path(out)
        names = [f.name for f in self.files if f.name]
        if self.directory or names:
            paths = inputs.scan_paths(bpy.path.abspath(self.directory), names)
            matrix = inputs.files_matrix(paths, (self.axis_forward, self.axis_up))
            inputs.check_before_reading(paths, options)     # the first file's size, before reading all

            def read(progress):
                return inputs.input_from_files(paths, matrix=matrix)
        else:
            if self.source_object:
                ob = bpy.data.objects.get(self.source_object)
                if ob is None:
                    raise ArticulaInputError(f"no object named {self.source_object!r}")
            else:
                ob = context.active_object
            inp = inputs.input_from_object(ob)
            inputs.check_input_sizes(inp, options)
            matrix = inp.matrix

            def read(progress):
                return inp
        if arm is not None:      # placed over the scans as shown: into the scans' coordinates
            skeleton = inputs.skeleton_from_armature(arm, world_to_scans=np.linalg.inv(matrix))
            options = replace(options, initial_skeleton=skeleton)
        self._output = out

        def work(progress):
            progress(0.0, "reading scans")
            return solve.learn(read(progress), options, progress)
        return work

    def finish(self, context, outcome):
        rig, action = result.build(context, outcome, self.name)
        if self._output:
            result.save(self._output, outcome)
        for text in rig.warnings:
            self.report({'WARNING'}, text)
        saved = f"; saved {os.path.basename(self._output)}" if self._output else ""
        self.report({'INFO'}, f"Learned rig {rig.armature.name!r}: {outcome.model.skeleton.num_bones} bones, "
                              f"{len(outcome.poses)} poses on frames {outcome.input.frame_start}.."
                              f"{outcome.input.frame_start + len(outcome.poses) - 1}; "
                              f"{summary_text(outcome)}{saved}")


@contextlib.contextmanager
def _named_settings(names: dict):
    """Re-raise a settings error with the field replaced by ``names[field]`` (:func:`name_setting`)."""
    try:
        yield
    except ArticulaInputError as exc:
        raise ArticulaInputError(name_setting(str(exc), names)) from None


classes = (ARTICULA_OT_learn_rig,)
