"""The Blender half of tracking a depth recording (``solver.track_depth``), reached through the same
``articula.track`` operator and ``track`` batch command as scan tracking.

Pipeline:

1. :mod:`.inputs`: whether the depth tracker runs (``uses_depth_tracker``: a point-cloud object imported
   from a depth recording), the model (``find_model``: a selected Articula rig, a bundle file, or none:
   the built-in template body) and the recording (``recording_from_object``: an imported depth object,
   tracked in the rig's object space or the world; ``recording_from_folder``: depth PNG frames as
   written, for the batch command);
2. :mod:`.solve`: ``track`` (no bpy: the job's worker thread) calls
   ``solver.track_depth.pipeline.track_recording``;
3. :mod:`.result`: ``build`` (main thread, inside ``scene_guard``) bakes the poses as an action on the rig
   (or on a rig built from the tracked model: the adapted template, a bundle's model) standing so that it
   plays over the point cloud, with the per-frame residual curve and the report (:mod:`.report`);
   ``look_through`` makes the recording's camera the scene camera; ``save`` writes the tracked bundle.
"""
