"""Blender half of gaze control: the chest/neck/head chain and gaze line of a rig, the shot's correction
as its own NLA layer, and the panel state."""
