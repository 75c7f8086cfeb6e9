"""The extension registers its UI and preferences the way Blender loads extensions."""
import bpy

from .conftest import MODULE


def test_sidebar_tab_and_panels_registered():
    for name in ("ARTICULA_PT_main", "ARTICULA_PT_import", "ARTICULA_PT_rig", "ARTICULA_PT_animate"):
        panel = getattr(bpy.types, name)
        assert panel.bl_category == "Articula" and panel.bl_space_type == 'VIEW_3D'


def test_preferences_have_defaults():
    prefs = bpy.context.preferences.addons[MODULE].preferences
    assert prefs.threads == 0 and prefs.cache_dir == ""
    prefs.threads = 3
    from bl_ext.articula_test.articula.addon import preferences
    assert preferences.threads() == 3
    prefs.threads = 0
    assert preferences.threads() >= 1


def test_object_data_property_survives_save_and_reload(tmp_path):
    me = bpy.data.meshes.new("m")
    ob = bpy.data.objects.new("seq", me)
    bpy.context.scene.collection.objects.link(ob)
    ob.articula.kind = 'SCAN_SEQUENCE'
    ob.articula.frame_count = 7
    path = str(tmp_path / "t.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.wm.open_mainfile(filepath=path)
    ob = bpy.data.objects["seq"]
    assert ob.articula.kind == 'SCAN_SEQUENCE' and ob.articula.frame_count == 7
