"""Bone roles: the one vocabulary of humanoid bones (:mod:`.vocabulary`: the role tree, sides, mirror)
and the recogniser from a rig's bone names to roles (:mod:`.recognise`, over the rig presets of
:mod:`.presets`), used by retargeting, the pose priors, the start poses, learned rigs' names and gaze.
"""
from .recognise import Recognition, bone_keys, bone_roles, name_key, recognise, role_bones
from .vocabulary import (ARM, CENTRE, CORE, FINGERS, LEG, LEG_ROLES, NEXT, PARENT, ROLES, SIDES, is_finger,
                         mirror, ordered, side)

__all__ = ["ARM", "CENTRE", "CORE", "FINGERS", "LEG", "LEG_ROLES", "NEXT", "PARENT", "ROLES", "SIDES",
           "Recognition", "bone_keys", "bone_roles", "is_finger", "mirror", "name_key", "ordered", "recognise",
           "role_bones", "side"]
