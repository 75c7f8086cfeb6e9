"""The linux-x64 zip that ``./run package`` builds installs into a real Blender and works.

Builds with ``tools/package.py`` (wheels from the shared cache, so only the first run downloads), then installs
the zip with ``bpy.ops.extensions.package_install_files`` in a subprocess running this venv's Python and bpy, with
an empty ``BLENDER_USER_RESOURCES``, and checks what a user would rely on: the add-on is enabled from the
installed copy, every class the source registers is registered, the bundled wheels were extracted and import, and
the operators run.  Runs on bpy 5.2 (Python 3.13) and on bpy 4.2 (Python 3.11).
"""
import ast
import importlib.util
import json
import os
import subprocess
import sys
import time
import tomllib
import zipfile
from pathlib import Path

import bpy
import pytest

REPO = Path(__file__).resolve().parents[2]
PROBE = Path(__file__).with_name("installed_extension_probe.py")
PLATFORM = "linux-x64"
PY = "%d.%d" % sys.version_info[:2]


def _load_tool():
    spec = importlib.util.spec_from_file_location("articula_package_tool", REPO / "tools" / "package.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


tool = _load_tool()


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    out = tmp_path_factory.mktemp("dist")
    started = time.time()
    proc = subprocess.run([sys.executable, str(REPO / "tools" / "package.py"), "--platforms", PLATFORM,
                           "--out", str(out)], capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    manifest = tomllib.loads((REPO / "blender_manifest.toml").read_text(encoding="utf-8"))
    zip_path = out / tool.zip_name(manifest, PLATFORM)
    assert zip_path.is_file(), proc.stdout
    return {"zip": zip_path, "stdout": proc.stdout, "started": started, "seconds": time.time() - started}


@pytest.fixture(scope="module")
def installed(built, tmp_path_factory):
    user = tmp_path_factory.mktemp("blender_user")
    report = user / "probe.json"
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(user))
    proc = subprocess.run([sys.executable, "-I", str(PROBE), str(built["zip"]), str(report)], env=env,
                          cwd=str(user), capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0 and report.is_file(), proc.stdout + proc.stderr
    result = json.loads(report.read_text(encoding="utf-8"))
    assert "exception" not in result, result["exception"] + proc.stdout + proc.stderr
    result["user"] = user
    result["log"] = proc.stdout + proc.stderr
    return result


def _source_features():
    tree = ast.parse((REPO / "operators" / "__init__.py").read_text(encoding="utf-8"))
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(getattr(t, "id", None) == "FEATURES" for t in node.targets):
            return [elt.id for elt in node.value.elts]          # FEATURES = (module, module, ...)
    raise AssertionError("operators/__init__.py defines no FEATURES")


def test_zip_holds_the_extension_and_this_platforms_wheels_only(built):
    with zipfile.ZipFile(built["zip"]) as zf:
        names = [n for n in zf.namelist() if not n.endswith("/")]
        manifest = tomllib.loads(zf.read("blender_manifest.toml").decode("utf-8"))
        contents = {n: zf.read(n) for n in names if not n.startswith("wheels/")}
    tops = {n.split("/")[0] for n in names}
    assert tops <= {"__init__.py", "blender_manifest.toml", "batch.py", "articula-batch", "articula-batch.cmd", "wheels", "addon", "operators",
                    "solver", "sample_scenes"}, sorted(tops)
    assert {"__init__.py", "blender_manifest.toml", "batch.py", "addon", "operators", "solver", "wheels"} <= tops
    assert not [n for n in names if "__pycache__" in n or n.endswith(".pyc") or "/." in "/" + n]
    assert {"addon/farm/job_types/articula_track.js", "addon/farm/job_types/articula_subjects.js"} <= set(names)

    # Every file git tracks in the extension's packages is in the zip, unchanged (skipping files another
    # developer saved after the build started), and nothing git does not track is.
    tracked = set(tool.tracked_files(REPO))
    for rel in tracked:
        path = REPO / rel
        if rel.split("/")[0] in ("addon", "operators", "solver", "sample_scenes") and path.is_file() \
                and path.stat().st_mtime < built["started"]:
            assert contents.get(rel) == path.read_bytes(), f"{rel} missing or different in the zip"
    assert not set(contents) - tracked, sorted(set(contents) - tracked)

    wheels = sorted(n.split("/", 1)[1] for n in names if n.startswith("wheels/"))
    assert len(wheels) == 2, wheels
    assert [w for w in wheels if w.startswith("scipy-1.17.1-cp311-cp311-") and w.endswith("_x86_64.whl")
            and "manylinux" in w]
    assert [w for w in wheels if w.startswith("scipy-1.17.1-cp313-cp313-") and w.endswith("_x86_64.whl")
            and "manylinux" in w]
    assert not [w for w in wheels if w.lower().startswith("trimesh")]   # tests and benches only (docs/libraries.md)
    assert not [w for w in wheels if w.lower().startswith("numpy")]
    assert manifest["platforms"] == [PLATFORM]
    assert manifest["build"]["generated"] == {"platforms": [PLATFORM], "wheels": [f"./wheels/{w}" for w in wheels]}

    committed = tomllib.loads((REPO / "blender_manifest.toml").read_text(encoding="utf-8"))
    assert committed["wheels"] == [] and "platforms" not in committed, "the committed manifest was modified"
    print(f"\n{built['zip'].name}: {built['zip'].stat().st_size / 1e6:.1f} MB, built in {built['seconds']:.1f} s")


def test_validators_of_blender_42_and_this_blender_accept_the_zip(built):
    blenders = {b.version: b for b in tool.find_blenders()}
    this = tuple(bpy.app.version[:2])
    assert (4, 2) in blenders and this in blenders, sorted(blenders)
    for version in sorted({(4, 2), this}):
        out = tool.run_builder(blenders[version], "validate", str(built["zip"]))
        assert "Success" in out, out
    assert "validated and compiled with" in built["stdout"] and "Blender 4.2" in built["stdout"]


def test_install_enables_the_installed_copy(installed):
    assert installed["install_result"] == ["FINISHED"]
    assert installed["enabled"], installed["log"]
    module_file = Path(installed["module_file"]).resolve()
    assert module_file == (installed["user"] / "extensions" / "user_default" / "articula" / "__init__.py").resolve()
    assert installed["python"] == PY


def test_every_class_the_source_registers_is_registered(installed):
    assert installed["panel_main"]
    assert installed["classes"] and all(installed["classes"].values()), installed["classes"]
    assert installed["features"] == _source_features()
    assert installed["bpy_ops_articula"] == installed["operator_idnames"]
    for idname in installed["operator_idnames"]:
        assert idname.startswith("articula.") and installed["classes"]["ARTICULA_OT_" + idname[9:]]


def test_bundled_wheels_are_extracted_and_import(installed):
    site = installed["user"] / "extensions" / ".local" / "lib" / f"python{PY}" / "site-packages"
    assert (site / "scipy" / "__init__.py").is_file() and (site / "scipy-1.17.1.dist-info").is_dir()
    assert not (site / "numpy").exists() and not (site / "trimesh").exists()
    # This venv has scipy itself; import the extracted copy first, with this venv's numpy standing in for
    # Blender's, the way a real Blender would.
    code = (
        "import sys; sys.path.insert(0, sys.argv[1]); import json, numpy, scipy\n"
        "from scipy.spatial import cKDTree\n"
        "tree = cKDTree(numpy.eye(3)); d, i = tree.query([[0.9, 0.1, 0.0]])\n"
        "print(json.dumps({'scipy': [scipy.__version__, scipy.__file__], 'nearest': int(i[0])}))\n")
    proc = subprocess.run([sys.executable, "-I", "-c", code, str(site)], capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr
    got = json.loads(proc.stdout.strip().splitlines()[-1])
    assert got["scipy"][0] == "1.17.1" and Path(got["scipy"][1]).is_relative_to(site)
    assert got["nearest"] == 0


def test_operators_run_from_the_installed_copy(installed):
    calls = installed["calls"]
    assert calls, "the installed copy registers no operators"
    for idname, call in calls.items():
        assert "Traceback" not in str(call["detail"]), f"{idname} crashed: {call['detail']}"
        if call["outcome"] == "returned":
            assert call["detail"] in (["CANCELLED"], ["FINISHED"]), (idname, call)
        if call["outcome"] == "report":
            assert call["detail"].strip(), idname
    ran = [i for i, c in calls.items() if c["outcome"] in ("returned", "report")]
    assert ran, f"no operator could be run with bad input in an empty scene: {calls}"


def test_a_platform_without_a_wheel_is_a_clear_error(tmp_path, monkeypatch):
    monkeypatch.setenv("PIP_NO_INDEX", "1")  # nothing can be found: the same path as a missing wheel
    monkeypatch.delenv("PIP_FIND_LINKS", raising=False)
    req = tool.Requirement("scipy", "1.17.1")
    with pytest.raises(tool.PackageError) as err:
        tool.fetch_wheel(req, "3.13", "macos-x64", tmp_path)
    message = str(err.value)
    assert "scipy==1.17.1" in message and "macos-x64" in message and "Python 3.13" in message
    assert not list(tmp_path.rglob("*.whl")) and not [p for p in tmp_path.iterdir() if p.is_dir()]


def test_staged_manifest_changes_only_platforms_and_wheels():
    text = (REPO / "blender_manifest.toml").read_text(encoding="utf-8")
    staged = tomllib.loads(tool.manifest_with(text, ["linux-x64"], ["./wheels/a-1-py3-none-any.whl"]))
    original = tomllib.loads(text)
    assert staged.pop("platforms") == ["linux-x64"] and staged.pop("wheels") == ["./wheels/a-1-py3-none-any.whl"]
    original.pop("wheels", None)
    assert staged == original
    with pytest.raises(tool.PackageError, match="one line"):
        tool.manifest_with(text.replace("wheels = []", "wheels = [\n]"), ["linux-x64"], [])


def _git(folder, *args):
    subprocess.run(["git", "-C", str(folder), *args], check=True, capture_output=True)


def test_staging_copies_only_the_files_git_tracks(tmp_path, monkeypatch):
    """What a user's batch run leaves in the checkout (untracked data, a model, an ignored report) and a
    module not yet added to git stay out of the staged tree that the builder zips."""
    monkeypatch.setenv("GIT_CEILING_DIRECTORIES", str(tmp_path))
    src = tmp_path / "src"
    files = {"blender_manifest.toml": (REPO / "blender_manifest.toml").read_bytes(), "__init__.py": b"",
             "batch.py": b"", "addon/__init__.py": b"", "addon/rig.py": b"x = 1\n", ".gitignore": b"/out/\n",
             "docs/a.md": b"doc"}
    user_files = {"model.npz": b"PK", "data/scans/pose_0000.obj": b"v 0 0 0\n", "out/report.json": b"{}",
                  "addon/new_module.py": b"y = 2\n"}
    for rel, data in {**files, **user_files}.items():
        (src / rel).parent.mkdir(parents=True, exist_ok=True)
        (src / rel).write_bytes(data)
    _git(src, "init", "-q")
    _git(src, "add", *files)
    assert tool.tracked_files(src) == sorted(files)
    assert tool.untracked_extension_files(src) == ["addon/new_module.py"]
    pkg = tool.stage(src, tmp_path / "stage", [], ["linux-x64"])
    staged = sorted(p.relative_to(pkg).as_posix() for p in pkg.rglob("*") if p.is_file())
    assert staged == sorted(files)
    assert (pkg / "addon" / "rig.py").read_bytes() == b"x = 1\n"


def test_packaging_outside_a_git_checkout_is_a_clear_error(tmp_path, monkeypatch):
    monkeypatch.setenv("GIT_CEILING_DIRECTORIES", str(tmp_path))
    src = tmp_path / "unpacked"
    src.mkdir()
    (src / "blender_manifest.toml").write_bytes((REPO / "blender_manifest.toml").read_bytes())
    with pytest.raises(tool.PackageError, match=r"unpacked is not a git checkout .*files git tracks"):
        tool.build(["linux-x64"], tmp_path / "dist", tmp_path / "wheels", source=src)
    assert not (tmp_path / "dist").exists() and not (tmp_path / "wheels").exists()


def test_an_untracked_module_in_the_packages_is_refused_before_building(tmp_path, monkeypatch):
    monkeypatch.setenv("GIT_CEILING_DIRECTORIES", str(tmp_path))
    src = tmp_path / "src"
    (src / "solver").mkdir(parents=True)
    (src / "blender_manifest.toml").write_bytes((REPO / "blender_manifest.toml").read_bytes())
    (src / "solver" / "__init__.py").write_text("")
    (src / "solver" / "new_module.py").write_text("")
    (src / "solver" / "notes.txt").write_text("")
    _git(src, "init", "-q")
    _git(src, "add", "blender_manifest.toml", "solver/__init__.py")
    with pytest.raises(tool.PackageError, match=r"git does not track .*: solver/new_module.py\. git add them"):
        tool.build(["linux-x64"], tmp_path / "dist", tmp_path / "wheels", source=src)
    assert not (tmp_path / "dist").exists()
