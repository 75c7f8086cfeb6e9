"""Batch commands: ``./run <command> ...`` and ``blender -b -P batch.py -- <command> ...``.
"""
