"""Gaze control: turning a character's gaze line towards a target, shared by chest, neck, head and
eyes with sigmoid fades.  Empty until the gaze issue lands.
"""
