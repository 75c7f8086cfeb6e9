"""Blender side of farm batch on Flamenco (docs/farm.md): the job-type scripts the Manager runs, the
inputs of a farm tracking job, and the panel's state."""
