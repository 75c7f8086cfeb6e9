"""Retargeting motion onto other characters: bone roles and the presets that name them, the source to
target mapping, armature maths, the per-segment direction solve with twist (:mod:`.solve`), root motion
scaled by the leg ratio, planted feet, and the shared-topology fit (:mod:`.topology`).  No bpy: the
Blender half is ``addon/retarget``.
"""
