"""The Blender half of depth-recording import: planning an import from the operator's inputs
(``plan``) and the images only Blender reads (``images``: EXR depth, colour frames).  The point-cloud
object it creates lives with the other sequence objects in ``addon/sequences/points.py``.
"""
