"""The check shared by every command that writes animation onto a character (retarget, gaze, bake): the
armature must be local or a library override.  An object linked from another .blend without an override
is read-only for the user, and what a script writes to it is not saved, so it is refused before anything
changes, with what to do."""
import bpy

from ..solver.errors import ArticulaInputError


def overrides_of(ob) -> list:
    """The library overrides in this file whose reference is the linked object ``ob``."""
    return [o for o in bpy.data.objects if o.override_library is not None and o.override_library.reference == ob]


def check_editable(ob, what: str) -> None:
    """Refuse ``ob`` (``what``: "target", "character", ... for the message) when it is linked from a
    library: one line naming the library's file and how to make it editable (or its existing override)."""
    if ob.library is None:
        return
    where = bpy.path.basename(ob.library.filepath) or ob.library.name
    made = overrides_of(ob)
    if made:
        raise ArticulaInputError(f"{what} {ob.name!r} is linked from {where} and cannot be changed: use its library "
                                 f"override {made[0].name!r} (in this file) instead")
    raise ArticulaInputError(f"{what} {ob.name!r} is linked from {where} and cannot be changed: make a library "
                             "override (Object › Library Override › Make) and try again")
