"""Blender-side building blocks of Articula (bpy allowed): registration, preferences, panels,
scene <-> array conversion, the rig builder, action baking and the Blender half of the importers."""


def package_name() -> str:
    """Name of the extension package as Blender knows it (e.g. ``bl_ext.user_default.articula``)."""
    return __package__.rpartition(".")[0]
