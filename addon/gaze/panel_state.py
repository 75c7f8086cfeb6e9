"""The Gaze panel's state, saved with the .blend (``Scene.articula_gaze``): target, shot and the shot
settings that ``articula.gaze`` shares with it (:class:`ShotSettings`), passed to the operator when it
runs from the panel."""
import bpy


class ShotSettings:
    """Properties of a gaze shot common to the panel's state and the operator (a mixin: Blender collects
    the annotations of both classes' bases)."""
    fade_frames: bpy.props.IntProperty(name="Fade", default=10, min=0, description="Frames of fade in and of fade out")
    shares: bpy.props.FloatVectorProperty(name="Split", size=3, default=(0.1, 0.4, 0.5), min=0.0, soft_max=1.0,
                                          description="Shares of the turn for chest, neck and head (normalised: "
                                                      "3, 3, 4 is 30/30/40 %)")
    chest: bpy.props.StringProperty(name="Chest Bone", description="Chest bone ('' = found by role)")
    neck: bpy.props.StringProperty(name="Neck Bone", description="Neck bone ('' = found by role)")
    head: bpy.props.StringProperty(name="Head Bone", description="Head bone ('' = found by role)")
    facing: bpy.props.EnumProperty(
        name="Facing", default='AUTO', description="Where the face points in the armature's rest pose",
        items=(('AUTO', "Automatic", "Annotated eyes on Articula MakeHuman-topology rigs, else the rest pose's facing"),
               ('-Y', "-Y", "The face points along -Y of the armature's rest (Blender's front)"),
               ('+Y', "+Y", "The face points along +Y of the armature's rest"),
               ('-X', "-X", "The face points along -X of the armature's rest"),
               ('+X', "+X", "The face points along +X of the armature's rest")))


SHOT_SETTINGS = tuple(ShotSettings.__annotations__)


class ArticulaGazeState(ShotSettings, bpy.types.PropertyGroup):
    target: bpy.props.PointerProperty(name="Target", type=bpy.types.Object,
                                      description="Object to look at (may move)")
    frame_start: bpy.props.IntProperty(name="First Frame", default=1, description="First frame of the shot")
    frame_end: bpy.props.IntProperty(name="Last Frame", default=250, description="Last frame of the shot")


classes = (ArticulaGazeState,)


def register_extra():
    bpy.types.Scene.articula_gaze = bpy.props.PointerProperty(type=ArticulaGazeState)


def unregister_extra():
    del bpy.types.Scene.articula_gaze
