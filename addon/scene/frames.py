"""The scene's frame range as imports and baked actions change it."""


def include_frames(scene, first: int, last: int, new_objects=()) -> None:
    """Make the scene's frame range cover ``first..last`` (an imported sequence): set outright in a scene
    holding nothing but ``new_objects`` (what the import just made), else only widened, so the range a
    user set (or another sequence needs) is never shortened."""
    last = max(first, last)
    own = {ob.as_pointer() for ob in new_objects}
    if all(ob.as_pointer() in own for ob in scene.objects):
        scene.frame_start, scene.frame_end = first, last
    else:
        scene.frame_start, scene.frame_end = min(scene.frame_start, first), max(scene.frame_end, last)
