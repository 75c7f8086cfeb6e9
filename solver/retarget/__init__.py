"""Retargeting motion onto other characters: roles of unknown rigs from their shape (:mod:`.humanoid`; the
role vocabulary and the names of known rigs are :mod:`solver.roles`), the source to target mapping, armature maths, the per-segment direction solve with twist (:mod:`.solve`), root motion
scaled by the leg ratio, planted feet, and the shared-topology fit (:mod:`.topology`).  No bpy: the
Blender half is ``addon/retarget``.
"""
