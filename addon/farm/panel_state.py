"""The Farm panel's state, saved with the .blend (``Scene.articula_farm``): where the Flamenco Manager
is, the inputs of a chunked tracking job (as ``./run farm track`` takes them, docs/farm.md) and the
followed job's status, which ``articula.farm_submit`` writes at each poll."""
import bpy


class ArticulaFarmChunk(bpy.types.PropertyGroup):
    """One unit of the followed job: ``name`` is "chunk N" or "merge", ``status`` the Manager's task
    status ("queued", "active", "completed", "failed", ...)."""
    status: bpy.props.StringProperty(name="Status")


class ArticulaFarmState(bpy.types.PropertyGroup):
    manager_url: bpy.props.StringProperty(name="Manager", default="http://localhost:8080",
                                          description="The Flamenco Manager's address (http://HOST:PORT)")
    model: bpy.props.StringProperty(name="Model", subtype='FILE_PATH',
                                    description="The person's model bundle (.npz) on the farm's shared storage "
                                                "(empty, depth only: the built-in template body, adapted by a "
                                                "first task)")
    input_dir: bpy.props.StringProperty(name="Recording", subtype='DIR_PATH',
                                        description="Folder of the recording, on the farm's shared storage")
    kind: bpy.props.EnumProperty(
        name="Kind", default='DEPTH', description="What the recording folder holds",
        items=(('DEPTH', "Depth Frames", "16-bit PNG depth frames with intrinsics.json (or a camera preset)"),
               ('SCANS', "Scans", "Unregistered captures, one file per frame")))
    camera: bpy.props.StringProperty(name="Camera",
                                     description="Depth only: camera preset of a folder without intrinsics.json")
    out: bpy.props.StringProperty(name="Output", subtype='FILE_PATH',
                                  description="Tracked bundle to write (.npz) on the shared storage")
    blend: bpy.props.StringProperty(name="Blend", subtype='FILE_PATH',
                                    description="Optional: also bake the tracked rig and action into this .blend")
    chunk: bpy.props.IntProperty(name="Chunk", default=0, min=0,
                                 description="Frames per chunk (0: 300 for depth, 60 for scans)")
    overlap: bpy.props.IntProperty(name="Overlap", default=0, min=0,
                                   description="Frames a chunk tracks before its own to settle (0: 60 for depth, 10 for scans)")
    retries: bpy.props.IntProperty(name="Retries", default=2, min=0, max=20,
                                   description="How many times the failed chunks of a job are submitted again")
    job_id: bpy.props.StringProperty(name="Job", description="The followed job's id on the Manager")
    status_text: bpy.props.StringProperty(name="Status", description="The last status line of the job")
    progress: bpy.props.FloatProperty(name="Progress", default=0.0, min=0.0, max=1.0, subtype='FACTOR',
                                      description="Share of the job's tasks completed")
    chunks: bpy.props.CollectionProperty(type=ArticulaFarmChunk)


def show_status(state, status) -> None:
    """Write one poll's :class:`solver.farm.follow.Status` into ``state`` (job, line, fraction, one row
    per chunk and one for the merge when the job has it)."""
    state.job_id, state.status_text, state.progress = status.job_id, status.text, status.fraction
    rows = [(f"chunk {k + 1}", s) for k, s in enumerate(status.unit_status)]
    if status.finish_status != "none":
        rows.append(("merge", status.finish_status))
    if len(state.chunks) != len(rows):
        state.chunks.clear()
        for _ in rows:
            state.chunks.add()
    for item, (name, text) in zip(state.chunks, rows):
        item.name, item.status = name, text


classes = (ArticulaFarmChunk, ArticulaFarmState)


def register_extra():
    bpy.types.Scene.articula_farm = bpy.props.PointerProperty(type=ArticulaFarmState)


def unregister_extra():
    del bpy.types.Scene.articula_farm
