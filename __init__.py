"""Articula: rigs, swing/twist skins and motion from registered scans and depth recordings.

Extension entry point.  Only ``register``/``unregister`` live here; they delegate to ``addon``.
Importing this package does not import bpy, so ``articula.solver`` stays usable from plain Python.
"""


def register():
    from .addon import registration
    registration.register()


def unregister():
    from .addon import registration
    registration.unregister()
