"""Articula's batch entry point.

    blender -b [file.blend] -P <repo>/batch.py -- <command> [args...]
    python batch.py [--open file.blend] <command> [args...]      (Blender as the bpy module; ./run uses this)

Enables the add-on (an installed ``bl_ext.*.articula`` if there is one, else this checkout through a
local extension repository) and runs ``addon.cli.common.main``.  Exit code 0 on success, non-zero with a
message on failure.  ``<command> --help`` lists a command's options; ``help`` lists the commands.
"""
import importlib
import os
import sys
import tempfile

REPO = os.path.dirname(os.path.abspath(__file__))
DEV_REPO_MODULE = "articula_dev"


def _argv():
    argv = sys.argv
    if "--" in argv:                       # blender -b -P batch.py -- cmd ...
        return argv[argv.index("--") + 1:]
    return argv[1:]                         # python batch.py cmd ...


def dev_package_root() -> str:
    """A folder that contains ``articula`` -> this checkout (Blender requires dir name == manifest id).
    Used as the local extension repository here and, on ``sys.path``, by tests and benchmarks so
    ``import articula`` works with plain Python."""
    root = os.path.join(REPO, ".pkgroot")
    link = os.path.join(root, "articula")
    if not os.path.exists(link):
        os.makedirs(root, exist_ok=True)
        try:
            os.symlink("..", link)
        except FileExistsError:
            pass
    return root


def enable_addon(bpy) -> str:
    """Enable Articula and return its module name."""
    for name in list(bpy.context.preferences.addons.keys()):
        if name.startswith("bl_ext.") and name.endswith(".articula"):
            return name
    for repo in bpy.context.preferences.extensions.repos:
        if os.path.isfile(os.path.join(repo.directory, "articula", "blender_manifest.toml")) \
                and repo.module != DEV_REPO_MODULE:
            module = f"bl_ext.{repo.module}.articula"
            break
    else:
        repos = bpy.context.preferences.extensions.repos
        if DEV_REPO_MODULE not in [r.module for r in repos]:
            repos.new(name=DEV_REPO_MODULE, module=DEV_REPO_MODULE,
                      custom_directory=dev_package_root(), source='USER')
        module = f"bl_ext.{DEV_REPO_MODULE}.articula"
    bpy.ops.preferences.addon_enable(module=module)
    if module not in bpy.context.preferences.addons:
        raise SystemExit(f"articula: could not enable the add-on {module}")
    return module


def main() -> int:
    argv = _argv()
    open_file = None
    if argv[:1] == ["--open"] and len(argv) >= 2:
        open_file, argv = argv[1], argv[2:]
    if "bpy" not in sys.modules:           # the bpy module, not the Blender executable
        os.environ.setdefault("BLENDER_USER_RESOURCES",
                              os.path.join(os.environ.get("ARTICULA_HOME", tempfile.gettempdir()),
                                           "blender-user"))
    import bpy
    if open_file:
        bpy.ops.wm.open_mainfile(filepath=os.path.abspath(open_file))
    module = enable_addon(bpy)
    cli = importlib.import_module(module + ".addon.cli.main")
    return cli.main(argv)


if __name__ == "__main__":
    as_module = "bpy" not in sys.modules
    code = main()
    sys.stdout.flush()
    sys.stderr.flush()
    if as_module:       # the bpy 4.2 module segfaults in its exit handlers after a glTF export: skip them
        os._exit(code)
    sys.exit(code)
