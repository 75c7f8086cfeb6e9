"""Gaze shots: the turn that points a character's gaze line at a target, shared by chest, neck, head and
eyes (:mod:`.aim`), and the fades that blend it in and out over a shot (:mod:`.fade`); ``data/`` holds
the gaze line's annotation on the MakeHuman body.  No bpy: the Blender half is ``addon/gaze``.
"""
