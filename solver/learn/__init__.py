"""Rig learning from registered scans (dissertation (model-adaptive mocap) chapter 3): key scans,
segmentation by motion, mirror symmetry, skeleton, joints and poses, swing/twist weights, rest shape, the
pipeline that alternates them (``pipeline.learn_rig``), its settings (``options.LearnOptions``) and its
report (``report.make_report``).
"""
