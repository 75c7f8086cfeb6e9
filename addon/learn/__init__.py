"""The Blender half of rig learning: where the scans come from, the solver run with progress, and the rig
it becomes in the scene.

Pipeline (what ``articula.learn_rig``, the ``learn-rig`` batch command and the demo call):

1. :mod:`.inputs`: ``input_from_object`` (a registered scan-sequence object; main thread, reads its frame
   cache) or ``input_from_files`` (OBJ/PLY/STL/OFF files or a folder; no bpy), checked by ``check_scans``
   (at least 3 scans, finite coordinates, triangles); ``skeleton_from_armature`` for an initial skeleton;
2. :mod:`.solve`: ``learn`` (no bpy: runs in the worker thread) calls ``solver.learn.pipeline.learn_rig``
   with a ``solver.learn.options.LearnOptions``;
3. :mod:`.result`: ``build`` (main thread, inside ``scene_guard``) builds the rig, bakes one pose per scan
   on the scans' frames, adds the heat map (:mod:`.heat_map`) and stores the report (:mod:`.report`) on
   the armature; ``save`` writes the bundle (input coordinates and vertex order unchanged, one pose per
   scan in scan order, the report in its provenance); ``learn_from_object`` runs 1-3 synchronously (for
   the demo and scripts).
"""
