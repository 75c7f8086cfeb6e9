"""The Blender half of rig learning: the learner's input from a scan-sequence object or files,
building the learned rig with its baked poses and error heat map, and saving the results.
"""
