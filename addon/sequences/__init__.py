"""Sequence objects that play recordings back frame by frame: scan sequences (meshes) and point-cloud
sequences (depth recordings), and the sources scans are imported from.
"""
