"""The Blender half of depth-recording import: planning an import from the operator's inputs.
"""
