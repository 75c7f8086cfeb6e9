"""The Blender half of tracking unregistered captures with a person's model.

Pipeline (what ``articula.track`` and the ``track`` batch command call):

1. :mod:`.inputs`: the model (``model_from_rig``: an Articula rig and the poses it was trained on;
   ``model_from_bundle``: a bundle file), the captures (``captures_from_object``: a scan-sequence or
   point-cloud object, mapped into the solve frame; ``captures_from_files``: files as written) and the
   frame range (``addon.tracking.inputs.parse_frames``);
2. :mod:`.solve`: ``track`` (no bpy: runs in the worker thread) calls
   ``solver.track.pipeline.track_sequence`` and measures each capture point's error;
3. :mod:`.result`: ``build`` (main thread, inside ``scene_guard``) bakes the poses as an action on the rig
   (or on a rig built from the adapted model) with the residual curves, stores the report
   (:mod:`.report`) and gives the captures their error colours (:mod:`.error_colors`); ``save`` writes
   the tracked bundle, whose provenance lets ``merge-tracks`` (``solver.track.merge``) join chunks.
"""
