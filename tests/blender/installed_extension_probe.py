"""Install an extension zip into a fresh Blender and report what works, as JSON.

    BLENDER_USER_RESOURCES=<empty dir> python -I installed_extension_probe.py <zip> <out.json>

Run in a subprocess by ``test_package.py``: the pytest process already has the development copy of the
add-on enabled, so the real install has to happen in a Blender of its own.
"""
import importlib
import json
import sys
import traceback

ZIP, OUT = sys.argv[1:3]
MODULE = "bl_ext.user_default.articula"
BAD_INPUT = "/nonexistent/articula-package-test/input"

import bpy  # noqa: E402  (after reading the arguments, so a usage error needs no Blender)

result = {"blender": bpy.app.version_string, "python": "%d.%d" % sys.version_info[:2]}
try:
    ret = bpy.ops.extensions.package_install_files(filepath=ZIP, repo="user_default", enable_on_install=True)
    # package_install_files returns FINISHED even when the install failed: everything below checks for real.
    result["install_result"] = sorted(ret)
    result["enabled"] = MODULE in bpy.context.preferences.addons
    mod = sys.modules.get(MODULE)
    result["module_file"] = getattr(mod, "__file__", None)

    registration = importlib.import_module(MODULE + ".addon.registration")
    classes = [cls for module in registration.MODULES for cls in getattr(module, "classes", ())]
    # Operators, panels and menus are also reachable as bpy.types.<name>; property groups and preferences not.
    result["classes"] = {cls.__name__: bool(getattr(cls, "is_registered", False)) and (
        getattr(bpy.types, cls.__name__, None) is cls
        or not issubclass(cls, (bpy.types.Operator, bpy.types.Panel, bpy.types.Menu))) for cls in classes}
    result["panel_main"] = hasattr(bpy.types, "ARTICULA_PT_main")

    operators = importlib.import_module(MODULE + ".operators")
    result["features"] = [module.__name__.rpartition(".")[2] for module in operators.FEATURES]
    result["operator_idnames"] = sorted(cls.bl_idname for cls in operators.classes)
    result["bpy_ops_articula"] = sorted("articula." + name for name in dir(bpy.ops.articula))

    # Call every operator that takes inputs by name with input that cannot exist: it has to run its code
    # from the installed copy and cancel with a report (a RuntimeError "Error: ..." when called from Python),
    # or finish; a Python traceback means the installed extension is broken.
    calls = {}
    for idname in result["operator_idnames"]:
        op = getattr(bpy.ops.articula, idname.split(".", 1)[1])
        bpy.ops.wm.read_homefile(use_empty=True)
        inputs = {p.identifier: BAD_INPUT for p in op.get_rna_type().properties
                  if p.type == 'STRING' and not p.is_readonly and p.identifier != "rna_type"}
        if not inputs:
            calls[idname] = {"outcome": "not called", "detail": "takes no inputs by name"}
        elif not op.poll():
            calls[idname] = {"outcome": "poll false", "detail": "cannot run in an empty scene"}
        else:
            try:
                calls[idname] = {"outcome": "returned", "detail": sorted(op('EXEC_DEFAULT', **inputs))}
            except RuntimeError as exc:
                calls[idname] = {"outcome": "report", "detail": str(exc)}
    result["calls"] = calls
except Exception:
    result["exception"] = traceback.format_exc()

with open(OUT, "w", encoding="utf-8") as fh:
    json.dump(result, fh, indent=1)
