"""The Gaze panel's state, saved with the .blend (``Scene.articula_gaze``): target, shot, fade, split and
bone overrides, used as the defaults of ``articula.gaze`` when it runs from the panel."""
import bpy


class ArticulaGazeState(bpy.types.PropertyGroup):
    target: bpy.props.PointerProperty(name="Target", type=bpy.types.Object,
                                      description="Object to look at (may move)")
    frame_start: bpy.props.IntProperty(name="First Frame", default=1, description="First frame of the shot")
    frame_end: bpy.props.IntProperty(name="Last Frame", default=250, description="Last frame of the shot")
    fade: bpy.props.IntProperty(name="Fade", default=10, min=0, description="Frames of fade in and of fade out")
    shares: bpy.props.FloatVectorProperty(name="Split", size=3, default=(0.1, 0.4, 0.5), min=0.0, max=1.0,
                                          description="Shares of the turn for chest, neck and head")
    chest: bpy.props.StringProperty(name="Chest Bone", description="Override the chest bone found by role")
    neck: bpy.props.StringProperty(name="Neck Bone", description="Override the neck bone found by role")
    head: bpy.props.StringProperty(name="Head Bone", description="Override the head bone found by role")
    facing: bpy.props.EnumProperty(
        name="Facing", default='AUTO', description="Where the face points in the armature's rest pose",
        items=(('AUTO', "Automatic", "Annotated eyes on Articula MakeHuman-topology rigs, else the rest facing"),
               ('-Y', "-Y", ""), ('+Y', "+Y", ""), ('-X', "-X", ""), ('+X', "+X", "")))


classes = (ArticulaGazeState,)


def register_extra():
    bpy.types.Scene.articula_gaze = bpy.props.PointerProperty(type=ArticulaGazeState)


def unregister_extra():
    del bpy.types.Scene.articula_gaze
