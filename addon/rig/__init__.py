"""The Blender half of the rig: building the exact swing/twist rig from a model, reading a rig back,
baking and reading actions, bundle import/export, the linear-blend export rig, bone widgets.
"""
