"""``articula.import_scans``: a sequence of scans -> a scan-sequence object that plays back per frame.

Sources (first match wins):
* ``files`` (names in ``directory``) or ``filepath``: OBJ/PLY/STL/OFF files, one frame each, or a
  folder of them (``directory``/``filepath`` naming a folder, no files selected), naturally sorted;
  one Alembic ``.abc``; or one MDD/PC2 point cache whose faces come from ``base_mesh`` (a mesh file)
  or ``source_object`` (else the active mesh object);
* ``source_object`` alone: a mesh object's shape keys (one frame per key, basis first) or its
  animation over ``source_frame_start..source_frame_end`` (0, 0: the scene's range).
"""
import os

import bpy
from bpy_extras.io_utils import ImportHelper

from ..addon import scan_sequence, scan_sources
from ..addon.jobs import JobOperator
from ..solver.errors import ArticulaInputError
from ..solver.meshfiles import MESH_EXTENSIONS, read_mesh
from ..solver.pointcache import CACHE_EXTENSIONS, read_point_cache
from ..solver.scan_sequence import list_scan_files, natural_sorted, read_scan_files, sequence_from_cache


class ARTICULA_OT_import_scans(JobOperator, bpy.types.Operator, ImportHelper):
    """Import a sequence of scans (mesh files, a folder, Alembic, MDD/PC2, or a mesh object's shape keys
    or animation) as a scan-sequence object that plays back frame by frame"""
    bl_idname = "articula.import_scans"
    bl_label = "Import Scans"
    bl_options = {'REGISTER', 'UNDO'}
    job_label = "Import scans"

    filename_ext = ""
    filter_glob: bpy.props.StringProperty(default="*.obj;*.ply;*.stl;*.off;*.abc;*.mdd;*.pc2",
                                          options={'HIDDEN'})
    directory: bpy.props.StringProperty(subtype='DIR_PATH', options={'HIDDEN', 'SKIP_SAVE'})
    files: bpy.props.CollectionProperty(type=bpy.types.OperatorFileListElement,
                                        options={'HIDDEN', 'SKIP_SAVE'})
    source_object: bpy.props.StringProperty(
        name="Source Object", options={'SKIP_SAVE'},
        description="Mesh object to take frames from (shape keys or animation), or the base mesh of a point cache")
    base_mesh: bpy.props.StringProperty(
        name="Base Mesh", subtype='FILE_PATH', options={'SKIP_SAVE'},
        description="Mesh file giving the faces of an MDD/PC2 point cache")
    name: bpy.props.StringProperty(name="Name", options={'SKIP_SAVE'},
                                   description="Name of the new object (empty: after the folder or file)")
    frame_start: bpy.props.IntProperty(name="First Frame", default=1,
                                       description="Scene frame that shows the first scan")
    require_registered: bpy.props.BoolProperty(
        name="Require Registered", default=False,
        description="Fail unless every frame has the same vertices and faces (needed to learn a rig)")
    object_frames: bpy.props.EnumProperty(
        name="Object Frames", default='AUTO',
        items=(('AUTO', "Auto", "Animation if the object is animated, else its shape keys"),
               ('SHAPE_KEYS', "Shape Keys", "One frame per shape key"),
               ('ANIMATION', "Animation", "The evaluated mesh at every frame of the range")))
    source_frame_start: bpy.props.IntProperty(name="Source Start", default=0,
                                              description="First frame of an animated source (0: scene start)")
    source_frame_end: bpy.props.IntProperty(name="Source End", default=0,
                                            description="Last frame of an animated source (0: scene end)")

    def _has_file_input(self):
        return bool(self.filepath or self.directory or any(f.name for f in self.files))

    def invoke(self, context, event):
        if self._has_file_input() or self.source_object:
            return JobOperator.invoke(self, context, event)
        self._browsing = True
        context.window_manager.fileselect_add(self)
        return {'RUNNING_MODAL'}

    def execute(self, context):
        if getattr(self, "_browsing", False) and not bpy.app.background:
            # Confirmed in the file browser: run as a modal job (progress + Esc) with the chosen input.
            self._browsing = False
            props = {p.identifier: getattr(self.properties, p.identifier)
                     for p in self.properties.bl_rna.properties if p.identifier not in ("rna_type", "files")}
            props["files"] = [{"name": f.name} for f in self.files]
            bpy.ops.articula.import_scans('INVOKE_DEFAULT', **props)
            return {'CANCELLED'}   # the job pushes its own undo step
        return JobOperator.execute(self, context)

    # -- job parts -----------------------------------------------------------------------------------
    def _paths(self):
        """(kind, paths): kind 'MESHES', 'ALEMBIC', 'CACHE' or None (no file input)."""
        directory = bpy.path.abspath(self.directory) if self.directory else ""
        names = [f.name for f in self.files if f.name]
        if names:
            paths = [os.path.join(directory, n) for n in natural_sorted(names)]
        elif self.filepath and not os.path.isdir(bpy.path.abspath(self.filepath)):
            paths = [bpy.path.abspath(self.filepath)]
            if not os.path.exists(paths[0]):
                raise ArticulaInputError(f"{paths[0]}: file or folder not found")
        elif self.filepath or directory:
            return 'MESHES', list_scan_files(bpy.path.abspath(self.filepath) or directory)
        else:
            return None, []
        exts = {os.path.splitext(p)[1].lower() for p in paths}
        if exts <= set(MESH_EXTENSIONS):
            if len(exts) > 1:
                raise ArticulaInputError(f"mixed file types ({', '.join(sorted(exts))}); pick one format")
            return 'MESHES', paths
        if len(paths) == 1 and exts == {".abc"}:
            return 'ALEMBIC', paths
        if len(paths) == 1 and exts <= set(CACHE_EXTENSIONS):
            return 'CACHE', paths
        raise ArticulaInputError(f"cannot import {', '.join(os.path.basename(p) for p in paths[:3])}: pick mesh "
                                 f"files ({', '.join(MESH_EXTENSIONS)}), a folder of them, one .abc, or one "
                                 f".mdd/.pc2 with a base mesh")

    def prepare(self, context):
        kind, paths = self._paths()
        required = self.require_registered
        if kind is None and not self.source_object:
            raise ArticulaInputError("nothing to import: give files, a folder, or a source object")
        if kind == 'MESHES':
            name = self.name or _folder_name(paths)
            source = os.path.dirname(paths[0]) if len(paths) > 1 else paths[0]

            def read(progress):
                return read_scan_files(paths, progress, required)
        elif kind == 'CACHE':
            cache = paths[0]
            name = self.name or os.path.splitext(os.path.basename(cache))[0]
            source = cache
            base_file = bpy.path.abspath(self.base_mesh) if self.base_mesh else ""
            base_polys = None
            if not base_file:
                base_ob = (scan_sources.source_mesh_object(self.source_object) if self.source_object
                           else context.active_object)
                if base_ob is None or base_ob.type != 'MESH':
                    raise ArticulaInputError(f"{os.path.basename(cache)}: a point cache has no faces; give a "
                                             f"base mesh file or select the mesh it belongs to")
                base_polys = (scan_sequence.read_polymesh(base_ob.data), base_ob.name)

            def read(progress):
                progress(0.1, f"reading {os.path.basename(cache)}")
                frames = read_point_cache(cache)
                base, base_name = base_polys or (read_mesh(base_file), os.path.basename(base_file))
                return sequence_from_cache(frames, base, os.path.basename(cache), base_name)
        elif kind == 'ALEMBIC':
            seq = scan_sources.sample_alembic(context, paths[0], required)
            name = self.name or os.path.splitext(os.path.basename(paths[0]))[0]
            source = paths[0]

            def read(progress):
                return seq
        else:
            ob = scan_sources.source_mesh_object(self.source_object)
            mode = self.object_frames
            if mode == 'AUTO':
                mode = 'ANIMATION' if scan_sources.object_has_animation(ob) else 'SHAPE_KEYS'
            if mode == 'SHAPE_KEYS':
                seq = scan_sources.sample_shape_keys(ob)
            else:
                first = self.source_frame_start or context.scene.frame_start
                last = self.source_frame_end or context.scene.frame_end
                seq = scan_sources.sample_animation(context, ob, first, last, required)
            name = self.name or f"{ob.name}_scans"
            source = f"object {ob.name} ({'shape keys' if mode == 'SHAPE_KEYS' else 'animation'})"

            def read(progress):
                return seq

        # The cache path is chosen here (bpy); the worker (no bpy) writes the file.
        cache_paths = {True: scan_sequence.new_cache_path(name, True),
                       False: scan_sequence.new_cache_path(name, False)}

        def work(progress):
            seq = read(progress)
            progress(0.95, "writing frame cache")
            path = cache_paths[seq.registered]
            scan_sequence.write_cache(path, seq)
            return seq, path, name, source

        return work

    def finish(self, context, result):
        seq, path, name, source = result
        try:
            ob = scan_sequence.create_object(context, name, seq, path, self.frame_start, source)
        except BaseException:
            _remove(path)
            raise
        note = "registered" if seq.registered else f"unregistered ({seq.why_unregistered})"
        self.report({'INFO'}, f"{ob.name}: {len(seq)} frames of {len(seq.topology.vertices)} vertices, {note}")


def _folder_name(paths) -> str:
    if len(paths) == 1:
        return os.path.splitext(os.path.basename(paths[0]))[0]
    return os.path.basename(os.path.dirname(os.path.abspath(paths[0]))) or "scans"


def _remove(path):
    try:
        os.remove(path)
    except OSError:
        pass


classes = (ARTICULA_OT_import_scans,)
