"""Blender half of retargeting: driving other characters and scans with an Articula rig."""
