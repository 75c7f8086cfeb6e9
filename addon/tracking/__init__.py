"""The Blender pieces both trackers share (issue 33: ``addon/track`` and ``addon/track_depth`` never import
each other): :mod:`.inputs` (the model to track with, a frame range as text, the tracked-action markers)
and :mod:`.result` (the rig that plays the motion, the action with its residual curves and report, the
output-path check)."""
