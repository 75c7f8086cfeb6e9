"""Blender scene building blocks shared by every feature: mesh <-> array conversion and headless
rendering.
"""
