"""Rig learning from registered scans (dissertation on model-adaptive motion capture, chapter 3):
key scans, segmentation by motion, skeleton, joints and poses, swing/twist weights, rest shape, and the
pipeline that alternates them (``pipeline.learn_rig``).
"""
