"""Tracking a person's model through unregistered captures (scans or point clouds whose vertices do not
correspond from frame to frame): reading and cleaning the captures, the first frame, per-frame
articulated registration with correspondences, visibility and robust weights, the pose prior, temporal
windows, model adaptation, and joining tracked chunks (:mod:`.merge`).  Depth-camera recordings are
tracked by ``solver.track_depth``.
"""
