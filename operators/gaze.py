"""``articula.gaze``: make a character look at a target over a shot, the turn shared by chest, neck and
head (and the eyes), faded in and out, as its own NLA layer on top of the existing animation."""
import bpy

from ..addon.gaze import shot
from ..addon.gaze.panel_state import ShotSettings
from ..addon.retarget.armatures import find_armature
from ..solver.errors import ArticulaInputError


class ARTICULA_OT_gaze(ShotSettings, bpy.types.Operator):
    """Turn the character's chest, neck, head and eyes so its face points at the target over a shot,
    faded in and out; the correction is an NLA strip on top of the animation (mute or delete it to undo)"""
    bl_idname = "articula.gaze"
    bl_label = "Look at Target"
    bl_options = {'REGISTER', 'UNDO'}

    armature: bpy.props.StringProperty(name="Armature", description="The character (default: the active armature)")
    target: bpy.props.StringProperty(name="Target", description="Object to look at (default: the panel's target)")
    frame_start: bpy.props.IntProperty(name="First Frame", default=-1, description="-1: the scene's first frame")
    frame_end: bpy.props.IntProperty(name="Last Frame", default=-1, description="-1: the scene's last frame")

    def execute(self, context):
        scene = context.scene
        try:
            arm = find_armature(self.armature or (context.active_object.name if context.active_object else ""),
                                "character")
            name = self.target or (scene.articula_gaze.target.name if scene.articula_gaze.target else "")
            target = bpy.data.objects.get(name) if name else None
            if name and target is None:
                raise ArticulaInputError(f"no target object {name!r} in the file")
            start = scene.frame_start if self.frame_start < 0 else self.frame_start
            end = scene.frame_end if self.frame_end < 0 else self.frame_end
            overrides = {"chest": self.chest, "neck": self.neck, "head": self.head}
            report = shot.apply_shot(context, arm, target, start, end, self.fade_frames, overrides, tuple(self.shares),
                                     "" if self.facing == 'AUTO' else self.facing)
        except ArticulaInputError as exc:
            self.report({'ERROR'}, str(exc))
            return {'CANCELLED'}
        self.report({'WARNING'} if report["limited"] else {'INFO'}, shot.summary(report))
        return {'FINISHED'}


classes = (ARTICULA_OT_gaze,)
