"""Build the Articula extension zips, one per platform, with scipy bundled as wheels.

    ./run package [--platforms linux-x64,windows-x64,macos-arm64,macos-x64] [--out dist]

Steps:
1. Wheels: for every platform and for both Python versions Blender uses (3.11 for 4.2-5.0, 3.13 for 5.1+),
   ``pip download --no-deps --only-binary=:all:`` with an explicit target (``--python-version``, ``--platform``,
   ``--implementation cp``, ``--abi``).  Downloads are cached in ``$ARTICULA_HOME/wheels`` (one folder per
   request, so a second run needs no network).  numpy is never bundled: Blender ships its own.
2. Staging: a copy of the files git tracks in the checkout (``git ls-files``: sample data, models and reports a
   user wrote into the checkout never reach a zip; outside a git checkout this is an error) whose
   ``blender_manifest.toml`` gets ``platforms`` and ``wheels`` filled in (the committed manifest keeps
   ``wheels = []`` for development and is never modified).  An untracked ``.py`` file in the extension's
   packages is an error (a new module left out would break the installed add-on); other untracked files there
   are named in the log.
3. Build with Blender's own builder (``bl_pkg/cli/blender_ext.py`` shipped in the bpy wheel, run as a plain
   script, with Blender's list of valid tags), ``--split-platforms`` -> ``articula-<version>-<platform>.zip``.
4. Check every zip (only the extension's own files plus its platform's wheels; the generated manifest block
   lists exactly those wheels), validate it with the ``validate`` command of every Blender found and compile its
   Python files with each one's Python.  The Blenders found must include the oldest supported one
   (``blender_version_min``), so a manifest key or a syntax 4.2 / Python 3.11 does not know fails here.

Wheel choices (scipy 1.17.1, checked on PyPI): linux-x64 ``manylinux_2_27_x86_64.manylinux_2_28_x86_64``
(scipy 1.17 has no manylinux2014 wheel; Blender itself needs glibc 2.28), windows-x64 ``win_amd64``,
macos-arm64 ``macosx_12_0_arm64`` and macos-x64 ``macosx_10_14_x86_64`` (the OpenBLAS builds; the ``macosx_14_0``
Accelerate builds would exclude macOS 11-13).  Known gap: scipy 1.17.1 has no arm64 wheel for macOS 11, which
Blender 4.2 still supports on Apple silicon, so the extension needs macOS 12 there.  A platform without a wheel
for a pinned version is an error naming the platform, the Python version and the package: the solver is tested
against these pins, so there is no silent fall-back to another scipy.
"""
from __future__ import annotations

import argparse
import dataclasses
import glob
import importlib.util
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
import tomllib
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
ARTICULA_HOME = Path(os.environ.get("ARTICULA_HOME") or Path.home() / ".cache" / "articula")
MANIFEST = "blender_manifest.toml"


@dataclasses.dataclass(frozen=True)
class Requirement:
    name: str
    version: str


# numpy is deliberately absent: Blender ships it and a second copy would shadow or clash with Blender's.
# Only what product code imports is bundled (docs/libraries.md: trimesh is used by tests and benchmarks only).
REQUIREMENTS = (
    Requirement("scipy", "1.17.1"),
)
# Python of Blender 4.2 LTS .. 5.0 and of 5.1 .. 5.2 LTS.
PYTHON_VERSIONS = ("3.11", "3.13")
# Blender platform -> the pip ``--platform`` tag to ask for (pip also accepts older compatible tags).
PLATFORMS = {
    "linux-x64": "manylinux_2_28_x86_64",
    "windows-x64": "win_amd64",
    "macos-arm64": "macosx_12_0_arm64",
    "macos-x64": "macosx_10_14_x86_64",
}
# What an installed extension needs: the entry module, the manifest, its Python packages and the wheels.
# Anything else in a zip (tests, tools, docs, dot-files ...) means ``[build] paths_exclude_pattern`` missed it.
EXTENSION_FILES = {"__init__.py", MANIFEST, "batch.py",  # batch.py: blender -b -P <installed>/batch.py
                   "articula-batch", "articula-batch.cmd"}  # its wrappers (Flamenco's {articula}, docs/farm.md)
EXTENSION_PACKAGES = {"addon", "operators", "solver", "sample_scenes"}
WHEEL_DIR = "wheels"
# Never copied into the staging tree (VCS data, the symlink farm used by tests, build outputs).
STAGING_SKIP_TOP = {".git", ".pkgroot", "dist", "out", WHEEL_DIR}


class PackageError(Exception):
    """A packaging failure with a message meant for the person running the tool."""


# --------------------------------------------------------------------------------------------------
# Blender's builder


@dataclasses.dataclass(frozen=True)
class BlenderTools:
    version: tuple[int, int]
    builder: Path   # bl_pkg/cli/blender_ext.py
    tags: Path      # _bpy_internal/extensions/tags.py, what ``blender --command extension`` validates tags with
    python: Path    # interpreter to run the builder with (the bpy venv's own)

    @property
    def label(self) -> str:
        return "Blender %d.%d" % self.version


def _python_of(path: Path) -> Path:
    """The interpreter of the virtual environment that contains ``path`` (else the running one)."""
    for parent in path.parents:
        if (parent / "pyvenv.cfg").is_file():
            for exe in (parent / "bin" / "python", parent / "Scripts" / "python.exe"):
                if exe.exists():
                    return exe
    return Path(sys.executable)


def _tools_in(bpy_dir: Path) -> list[BlenderTools]:
    found = []
    for builder in glob.glob(str(bpy_dir / "[0-9]*.[0-9]*" / "scripts" / "addons_core" / "bl_pkg" / "cli"
                                 / "blender_ext.py")):
        builder = Path(builder)
        scripts = builder.parents[3]
        major, minor = scripts.parent.name.split(".")
        tags = scripts / "modules" / "_bpy_internal" / "extensions" / "tags.py"
        if tags.is_file():
            found.append(BlenderTools((int(major), int(minor)), builder, tags, _python_of(builder)))
    return found


def find_blenders() -> list[BlenderTools]:
    """Every bpy install we can see: this interpreter's and those of the ``./run`` venvs. Newest first."""
    dirs = set()
    spec = importlib.util.find_spec("bpy")  # locates bpy without importing it
    if spec and spec.submodule_search_locations:
        dirs.update(Path(p).resolve() for p in spec.submodule_search_locations)
    dirs.update(Path(p).resolve() for p in glob.glob(str(ARTICULA_HOME / "venv-*" / "lib" / "python3.*"
                                                          / "site-packages" / "bpy")))
    by_version = {}
    for d in sorted(dirs):
        for tools in _tools_in(d):
            by_version.setdefault(tools.version, tools)
    return [by_version[v] for v in sorted(by_version, reverse=True)]


def run_builder(tools: BlenderTools, *args: str) -> str:
    cmd = [str(tools.python), str(tools.builder), *args, "--valid-tags", str(tools.tags)]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    out = (proc.stdout + proc.stderr).strip()
    if proc.returncode != 0 or "ERROR" in out:
        raise PackageError(f"{tools.label} builder failed: {' '.join(cmd)}\n{out}")
    return out


# --------------------------------------------------------------------------------------------------
# Wheels

# {name}-{version}(-{build})?-{python tag}-{abi tag}-{platform tag}.whl
_WHEEL_RE = re.compile(
    r"^(?P<name>[^-]+)-(?P<version>[^-]+)(-\d[^-]*)?-(?P<py>[^-]+)-(?P<abi>[^-]+)-(?P<plat>[^-]+)\.whl$")


def parse_wheel(filename: str) -> dict:
    m = _WHEEL_RE.match(filename)
    if not m:
        raise PackageError(f"not a wheel file name: {filename}")
    return m.groupdict()


def _normal(name: str) -> str:
    return re.sub(r"[-_.]+", "_", name).lower()


def fetch_wheel(req: Requirement, python: str, platform: str, cache: Path) -> Path:
    """The cached wheel of ``req`` for CPython ``python`` on Blender ``platform``; downloads it if missing."""
    cp = "cp" + python.replace(".", "")
    pip_platform = PLATFORMS[platform]
    folder = cache / f"{req.name}-{req.version}" / f"{cp}-{pip_platform}"
    cached = sorted(folder.glob("*.whl"))
    if len(cached) == 1:
        return cached[0]
    if len(cached) > 1:
        raise PackageError(f"the wheel cache folder {folder} holds {len(cached)} wheels instead of one; delete it")

    cache.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=".download-", dir=cache))
    try:
        cmd = [sys.executable, "-m", "pip", "download", "--no-deps", "--only-binary=:all:",
               "--disable-pip-version-check", "--quiet",
               "--python-version", python, "--implementation", "cp", "--abi", cp, "--platform", pip_platform,
               "--dest", str(tmp), f"{req.name}=={req.version}"]
        proc = subprocess.run(cmd, capture_output=True, text=True)
        got = sorted(tmp.glob("*.whl"))
        if proc.returncode != 0 or len(got) != 1:
            detail = "\n    ".join((proc.stderr or proc.stdout).strip().splitlines()[-3:])
            raise PackageError(
                f"no {req.name}=={req.version} wheel for platform {platform} and Python {python} "
                f"(pip --platform {pip_platform} --abi {cp}).\n    {detail}\n"
                f"Leave the platform out (--platforms) or change the pin in tools/package.py.")
        tags = parse_wheel(got[0].name)
        ok = tags["py"] == cp and tags["abi"] == cp
        if _normal(tags["name"]) != _normal(req.name) or tags["version"] != req.version or not ok:
            raise PackageError(f"pip returned an unexpected wheel for {req.name}=={req.version}, {cp}, "
                               f"{pip_platform}: {got[0].name}")
        folder.parent.mkdir(parents=True, exist_ok=True)
        try:
            os.rename(tmp, folder)
        except OSError as exc:  # a concurrent run filled the cache first: use theirs
            if len(sorted(folder.glob("*.whl"))) != 1:
                raise PackageError(f"could not store {got[0].name} in the wheel cache {folder}: {exc}")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return sorted(folder.glob("*.whl"))[0]


def fetch_wheels(platforms: list[str], cache: Path) -> dict[str, list[Path]]:
    """Blender platform -> its wheels (one per requirement and Python version)."""
    return {platform: [fetch_wheel(req, python, platform, cache) for req in REQUIREMENTS for python in PYTHON_VERSIONS]
            for platform in platforms}


# --------------------------------------------------------------------------------------------------
# Staging and the manifest


def manifest_with(text: str, platforms: list[str], wheels: list[str]) -> str:
    """``text`` (a manifest) with its top-level ``platforms`` and ``wheels`` set; everything else unchanged."""
    values = {"platforms": platforms, "wheels": wheels}
    lines = text.splitlines()
    first_table = next((i for i, line in enumerate(lines) if line.lstrip().startswith("[")), len(lines))
    while first_table > 0 and not lines[first_table - 1].strip():
        first_table -= 1  # new keys go after the last top-level line, not after the blank lines
    for key, value in values.items():
        new = f"{key} = [{', '.join(_toml_str(v) for v in value)}]"
        pattern = re.compile(rf"^\s*{key}\s*=")
        idx = [i for i in range(first_table) if pattern.match(lines[i])]
        if idx:
            try:
                tomllib.loads(lines[idx[0]])
            except tomllib.TOMLDecodeError:  # a multi-line value: refuse rather than guess
                raise PackageError(f"{MANIFEST}: write '{key} = [...]' on one line so it can be filled in")
            lines[idx[0]] = new
        else:
            lines.insert(first_table, new)
            first_table += 1
    result = "\n".join(lines) + "\n"
    old, new_data = tomllib.loads(text), tomllib.loads(result)
    if {k: new_data.pop(k) for k in values} != values or {k: v for k, v in old.items() if k not in values} != new_data:
        raise PackageError(f"internal error: filling in {MANIFEST} changed more than platforms/wheels")
    return result


def _toml_str(s: str) -> str:
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"') + '"'


def _git_files(source: Path, *args: str) -> list[str]:
    """``git ls-files -z ARGS`` run in ``source``: paths relative to it (POSIX); PackageError outside git."""
    try:
        proc = subprocess.run(["git", "-C", str(source), "ls-files", "-z", *args], capture_output=True)
    except FileNotFoundError:
        raise PackageError("git is not installed: ./run package builds from the files git tracks") from None
    if proc.returncode != 0:
        detail = proc.stderr.decode(errors="replace").strip().splitlines()
        raise PackageError(f"{source} is not a git checkout ({detail[-1] if detail else 'git ls-files failed'}): "
                           f"./run package builds from the files git tracks, so run it in a clone of the "
                           f"repository")
    return [p for p in proc.stdout.decode("utf-8", errors="surrogateescape").split("\0") if p]


def tracked_files(source: Path) -> list[str]:
    """The files git tracks in ``source`` that exist (relative POSIX paths, sorted): the only files a zip
    may take from the checkout.  Untracked and ignored files are never packaged."""
    return sorted(p for p in _git_files(source, "--cached") if os.path.lexists(source / p))


def untracked_extension_files(source: Path) -> list[str]:
    """Files in the extension's packages that git neither tracks nor ignores (left out of the zip)."""
    return sorted(_git_files(source, "--others", "--exclude-standard", "--", *sorted(EXTENSION_PACKAGES)))


def stage(source: Path, dest: Path, wheels: list[Path], platforms: list[str], skip_dirs=()) -> Path:
    """Copy the files git tracks in ``source`` (:func:`tracked_files`) to ``dest/<id>`` with the wheels in
    ``wheels/`` and the manifest filled in.

    ``skip_dirs``: more folders not to copy (the output folder when it lies inside the source tree)."""
    manifest = tomllib.loads((source / MANIFEST).read_text(encoding="utf-8"))
    pkg = dest / manifest["id"]
    skip_dirs = {Path(d).resolve() for d in skip_dirs}
    pkg.mkdir(parents=True)
    for rel in tracked_files(source):
        parts = rel.split("/")
        path = source / rel
        if parts[0] in STAGING_SKIP_TOP or "__pycache__" in parts or any(
                path.resolve().is_relative_to(d) for d in skip_dirs):
            continue
        target = pkg / rel
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(path, target, follow_symlinks=False)
    (pkg / WHEEL_DIR).mkdir(exist_ok=True)
    for wheel in wheels:
        target = pkg / WHEEL_DIR / wheel.name
        try:
            os.link(wheel, target)
        except OSError:
            shutil.copy2(wheel, target)
    text = (source / MANIFEST).read_text(encoding="utf-8")
    (pkg / MANIFEST).write_text(
        manifest_with(text, platforms, [f"./{WHEEL_DIR}/{w.name}" for w in wheels]), encoding="utf-8")
    return pkg


# --------------------------------------------------------------------------------------------------
# Checking the result


def check_zip(path: Path, platform: str, wheels: list[Path]) -> list[str]:
    """Raise unless the zip holds only the extension's files and exactly ``wheels``; return the wheel names."""
    with zipfile.ZipFile(path) as zf:
        names = [n for n in zf.namelist() if not n.endswith("/")]
        manifest = tomllib.loads(zf.read(MANIFEST).decode("utf-8"))
    problems = []
    for name in names:
        parts = name.split("/")
        if len(parts) == 1 and name not in EXTENSION_FILES:
            problems.append(name)
        elif len(parts) > 1 and parts[0] not in EXTENSION_PACKAGES | {WHEEL_DIR}:
            problems.append(name)
        elif any(p.startswith(".") or p == "__pycache__" for p in parts) or name.endswith(".pyc"):
            problems.append(name)
    if problems:
        shown = ", ".join(sorted(problems)[:10]) + (" ..." if len(problems) > 10 else "")
        raise PackageError(f"{path.name} holds files an installed extension does not need: {shown}\n"
                           f"Exclude them in {MANIFEST} [build] paths_exclude_pattern, or if they are a new "
                           f"package of the extension, add it to EXTENSION_PACKAGES in tools/package.py.")
    missing = sorted(EXTENSION_FILES - set(names)) + sorted(
        f"{p}/__init__.py" for p in EXTENSION_PACKAGES if f"{p}/__init__.py" not in names)
    if missing:
        raise PackageError(f"{path.name} lacks {', '.join(missing)}")

    expected = sorted(f"{WHEEL_DIR}/{w.name}" for w in wheels)
    in_zip = sorted(n for n in names if n.startswith(WHEEL_DIR + "/"))
    generated = manifest.get("build", {}).get("generated", {})
    listed = sorted(w.removeprefix("./") for w in generated.get("wheels", []))
    if in_zip != expected or listed != expected or generated.get("platforms") != [platform]:
        raise PackageError(f"{path.name}: Blender's builder kept wheels {in_zip} and listed {listed} for "
                           f"platforms {generated.get('platforms')}, expected {expected} for {platform}")
    if any(parse_wheel(Path(n).name)["name"].lower() == "numpy" for n in in_zip):
        raise PackageError(f"{path.name} bundles numpy; Blender ships its own")
    return [Path(n).name for n in in_zip]


_COMPILE_ALL = """
import sys, zipfile
bad = []
with zipfile.ZipFile(sys.argv[1]) as zf:
    for name in zf.namelist():
        if name.endswith(".py"):
            try:
                compile(zf.read(name), name, "exec", dont_inherit=True)
            except SyntaxError as exc:
                bad.append(f"{name}:{exc.lineno}: {exc.msg}")
print("\\n".join(bad))
sys.exit(1 if bad else 0)
"""


def check_compiles(path: Path, tools: BlenderTools) -> None:
    """Raise unless every Python file in the zip compiles with the Python of ``tools``' Blender."""
    proc = subprocess.run([str(tools.python), "-I", "-c", _COMPILE_ALL, str(path)], capture_output=True, text=True)
    if proc.returncode != 0:
        raise PackageError(f"{path.name}: Python files that {tools.label}'s Python ({tools.python}) cannot "
                           f"compile:\n{(proc.stdout + proc.stderr).strip()}")


def zip_name(manifest: dict, platform: str) -> str:
    """The builder's name for a split-platform zip."""
    return f"{manifest['id']}-{manifest['version']}-{platform.replace('-', '_')}.zip"


# --------------------------------------------------------------------------------------------------


def build(platforms: list[str], out: Path, cache: Path, source: Path = ROOT, log=print) -> list[Path]:
    """Download, stage, build, check and validate; return the zip paths (one per platform)."""
    manifest = tomllib.loads((source / MANIFEST).read_text(encoding="utf-8"))
    left_out = untracked_extension_files(source)          # before any download: outside git is an error
    modules = [f for f in left_out if f.endswith(".py")]
    if modules:
        raise PackageError(f"Python files in the extension's packages that git does not track would be missing "
                           f"from the zip (the installed add-on could not import them): {', '.join(modules[:10])}"
                           f"{' ...' if len(modules) > 10 else ''}. git add them, or move them out of the way.")
    blenders = find_blenders()
    if not blenders:
        raise PackageError("no bpy install found (neither this interpreter's nor $ARTICULA_HOME/venv-*); "
                           "run ./run setup")
    oldest = tuple(int(x) for x in manifest["blender_version_min"].split(".")[:2])
    if oldest not in {b.version for b in blenders}:
        raise PackageError(
            f"no Blender {oldest[0]}.{oldest[1]} builder found, but blender_version_min is "
            f"{manifest['blender_version_min']}: the zips must pass that Blender's validation too. "
            f"Found: {', '.join(b.label for b in blenders)}. Run ./run setup.")
    builder = blenders[0]

    t0 = time.perf_counter()
    wheels = fetch_wheels(platforms, cache)
    t1 = time.perf_counter()
    log(f"wheels: {sum(len(w) for w in wheels.values())} for {len(platforms)} platform(s) "
        f"from {cache} in {t1 - t0:.1f} s")

    out.mkdir(parents=True, exist_ok=True)
    all_wheels = list({w.name: w for p in platforms for w in wheels[p]}.values())
    if left_out:
        log(f"left out {len(left_out)} file(s) git does not track (git add them to ship them): "
            f"{', '.join(left_out[:10])}{' ...' if len(left_out) > 10 else ''}")
    with tempfile.TemporaryDirectory(prefix="articula-stage-") as tmp:
        pkg = stage(source, Path(tmp), all_wheels, platforms, skip_dirs=[out])
        run_builder(builder, "build", "--source-dir", str(pkg), "--output-dir", str(out), "--split-platforms")
    t2 = time.perf_counter()
    log(f"built with {builder.label}'s builder ({builder.builder}) in {t2 - t1:.1f} s")

    zips = []
    for platform in platforms:
        path = out / zip_name(manifest, platform)
        if not path.is_file():
            raise PackageError(f"the builder did not write {path}")
        try:
            names = check_zip(path, platform, wheels[platform])
            for tools in blenders:
                run_builder(tools, "validate", str(path))
                check_compiles(path, tools)
        except PackageError:
            path.unlink()                 # never leave a zip that failed its checks in the output folder
            raise
        log(f"{path}  {path.stat().st_size / 1e6:.1f} MB  wheels: {', '.join(names)}")
        zips.append(path)
    t3 = time.perf_counter()
    log(f"checked, validated and compiled with {', '.join(b.label for b in blenders)} in {t3 - t2:.1f} s; "
        f"total {t3 - t0:.1f} s")
    return zips


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="./run package", description=__doc__.split("\n\n")[0])
    parser.add_argument("--platforms", default=",".join(PLATFORMS),
                        help=f"comma-separated, from {', '.join(PLATFORMS)} (default: all)")
    parser.add_argument("--out", type=Path, default=ROOT / "dist", help="output folder (default: dist/)")
    parser.add_argument("--wheel-cache", type=Path, default=ARTICULA_HOME / "wheels",
                        help="downloaded wheels (default: $ARTICULA_HOME/wheels)")
    args = parser.parse_args(argv)
    platforms = [p.strip() for p in args.platforms.split(",") if p.strip()]
    unknown = [p for p in platforms if p not in PLATFORMS]
    if unknown or not platforms:
        parser.error(f"unknown platform(s) {', '.join(unknown) or '(none given)'}; known: {', '.join(PLATFORMS)}")
    try:
        build(list(dict.fromkeys(platforms)), args.out.resolve(), args.wheel_cache.resolve())
    except PackageError as exc:
        print(f"package: error: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
