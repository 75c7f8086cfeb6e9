"""Sequence objects that play recordings back frame by frame: scan sequences (meshes, ``scans``) and
point-cloud sequences (depth recordings, ``points``), their shared playback (``playback``: handlers,
frame index, cache paths), and the sources scans are imported from (``scan_sources``).
"""
