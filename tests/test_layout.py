"""The source tree keeps the shape docs/DEVELOPING.md describes: small modules and functions, no import
cycles, product code that does not depend on sample-data generators or benchmarks, and docstrings that
cite the project's own docs rather than files outside the checkout."""
import ast
import os
import re

import pytest

from .conftest import REPO

PRODUCT = ("solver", "addon", "operators")
MAX_MODULE_LINES = 700
MAX_FUNCTION_LINES = 100
# Batch commands and the demo may build sample data; nothing else in the product may.
MAY_IMPORT_SAMPLES = {"addon/cli/main.py", "addon/cli/demo.py"}


def _sources(*tops):
    for top in tops:
        for folder, _, names in os.walk(os.path.join(REPO, top)):
            for name in sorted(names):
                if name.endswith(".py"):
                    path = os.path.join(folder, name)
                    yield os.path.relpath(path, REPO).replace(os.sep, "/"), path


def _module_name(rel):
    mod = rel[:-3].replace("/", ".")
    return mod[:-len(".__init__")] if mod.endswith(".__init__") else mod


def _imports(rel, tree):
    """Absolute (extension-relative) names of the modules ``rel`` imports at module level or inside
    functions, resolving relative imports; ``from package import module`` yields the module."""
    package = _module_name(rel) if rel.endswith("__init__.py") else _module_name(rel).rpartition(".")[0]
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.level:
            base = package.split(".") if package else []
            base = base[:len(base) - (node.level - 1)] if node.level > 1 else base
            target = ".".join(base + ([node.module] if node.module else []))
            yield target
            for alias in node.names:
                yield f"{target}.{alias.name}" if target else alias.name
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.startswith("articula."):
                    yield alias.name[len("articula."):]
        elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith("articula."):
            yield node.module[len("articula."):]


def _trees(*tops):
    return {rel: ast.parse(open(path, encoding="utf-8").read(), rel) for rel, path in _sources(*tops)}


def test_modules_and_functions_are_short():
    long_modules, long_functions = [], []
    for rel, path in _sources(*PRODUCT):
        text = open(path, encoding="utf-8").read()
        if text.count("\n") > MAX_MODULE_LINES:
            long_modules.append(f"{rel}: {text.count(chr(10))} lines")
        for node in ast.walk(ast.parse(text, rel)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                first = node.body[0]
                if (isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant)
                        and isinstance(first.value.value, str) and len(node.body) > 1):
                    first = node.body[1]                      # the body starts after the docstring
                lines = node.end_lineno - first.lineno + 1
                if lines > MAX_FUNCTION_LINES:
                    long_functions.append(f"{rel}:{node.lineno} {node.name}: {lines} lines")
    assert not long_modules, f"modules over {MAX_MODULE_LINES} lines: {long_modules}"
    assert not long_functions, f"function bodies over {MAX_FUNCTION_LINES} lines: {long_functions}"


def test_no_import_cycles():
    trees = _trees(*PRODUCT, "sample_scenes")
    modules = {_module_name(rel): rel for rel in trees}
    graph = {}
    for rel, tree in trees.items():
        deps = {name for name in _imports(rel, tree) if name in modules}
        graph[_module_name(rel)] = deps - {_module_name(rel)}
    # A package's __init__ is imported by each of its modules; cycles through an __init__ that only holds
    # a docstring are not cycles, so __init__ modules without imports have no edges (they have none).
    state, stack, cycles = {}, [], []

    def visit(node):
        state[node] = 1
        stack.append(node)
        for dep in sorted(graph[node]):
            if state.get(dep) == 1:
                cycles.append(stack[stack.index(dep):] + [dep])
            elif dep not in state:
                visit(dep)
        stack.pop()
        state[node] = 2

    for node in sorted(graph):
        if node not in state:
            visit(node)
    assert not cycles, "import cycles: " + "; ".join(" -> ".join(c) for c in cycles)


def test_product_code_does_not_import_samples_or_benchmarks():
    bad = []
    for rel, tree in _trees(*PRODUCT).items():
        for name in _imports(rel, tree):
            top = name.split(".")[0]
            if top == "bench" or (top == "sample_scenes" and rel not in MAY_IMPORT_SAMPLES):
                bad.append(f"{rel} imports {name}")
    assert not bad, bad


def test_solver_never_imports_blender():
    bad = [f"{rel} imports {name}" for rel, tree in _trees("solver").items() for name in _imports(rel, tree)
           if name.split(".")[0] in ("addon", "operators")]
    for rel, path in _sources("solver"):
        if re.search(r"^\s*(import|from)\s+(bpy|mathutils|bmesh)\b", open(path, encoding="utf-8").read(), re.M):
            bad.append(f"{rel} imports Blender")
    assert not bad, bad


# The scan tracker and the depth tracker share only the tracking core (solver/tracking, addon/tracking) and
# the shared packages: neither's packages import the other's (issue 33).
TRACKERS = (("solver.track", "addon.track"), ("solver.track_depth", "addon.track_depth"))
# Imports still to move, each with who moves it; the test fails when one is gone, so the list shrinks.
PENDING_TRACKER_IMPORTS = set()


def _within(name, package):
    return name == package or name.startswith(package + ".")


def test_the_two_trackers_never_import_each_other():
    bad, pending = [], set()
    for rel, tree in _trees("solver/track", "solver/track_depth", "addon/track", "addon/track_depth").items():
        own = next(k for k, packages in enumerate(TRACKERS) if any(_within(_module_name(rel), p) for p in packages))
        for name in sorted(set(_imports(rel, tree))):
            other = next((p for p in TRACKERS[1 - own] if _within(name, p)), None)
            if other is None:
                continue
            key = next(((r, m) for r, m in PENDING_TRACKER_IMPORTS if r == rel and _within(name, m)), None)
            if key:
                pending.add(key)
            else:
                bad.append(f"{rel} imports {name}")
    assert not bad, "the trackers import each other (move the shared piece to solver/tracking or addon/tracking): " \
        + "; ".join(bad)
    assert pending == PENDING_TRACKER_IMPORTS, \
        f"no longer imported, remove from PENDING_TRACKER_IMPORTS: {PENDING_TRACKER_IMPORTS - pending}"


@pytest.mark.parametrize("top", PRODUCT + ("sample_scenes",))
def test_docstrings_cite_the_project_not_outside_files(top):
    """The project reads on its own: no ``../shared`` paths in the code (cite the dissertation's chapter
    and equation, or docs/)."""
    bad = [rel for rel, path in _sources(top) if "../shared" in open(path, encoding="utf-8").read()]
    assert not bad, f"these files cite ../shared: {bad}"


# ------------------------------------------------------------------------------------------- benchmarks

BENCH = os.path.join(REPO, "bench")
# The extension's two entry points: register() (Blender) and the batch commands (batch.py).
ENTRY_POINTS = ("addon.registration", "addon.cli.main")
# Product modules that only tests or benches import, kept for a stated reason (empty is the goal).
USED_OUTSIDE_THE_PRODUCT_ONLY = {}


def _bench_trees():
    return {name: ast.parse(open(os.path.join(BENCH, name), encoding="utf-8").read(), name)
            for name in sorted(os.listdir(BENCH)) if name.endswith(".py")}


def _bench_imports(tree):
    """Top-level module names a bench file imports (``import x.y`` -> ``x``), anywhere in the file."""
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            yield from (alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            yield node.module.split(".")[0]


def test_no_bench_imports_tests():
    """Benchmarks stand on their own: shared helpers live in bench/ (or sample_scenes/), never in tests/."""
    bad = []
    for name, tree in _bench_trees().items():
        if "tests" in set(_bench_imports(tree)):
            bad.append(f"{name} imports tests")
        text = open(os.path.join(BENCH, name), encoding="utf-8").read()
        if re.search(r"sys\.path\.\w+\([^)]*[\"']tests[\"']", text):
            bad.append(f"{name} puts tests/ on sys.path")
    assert not bad, bad


def test_every_bench_has_a_one_line_description():
    """``./run bench list`` shows the first line of each bench_*.py's docstring: it must be there, short,
    and a line of its own (followed by a blank line or the end of the docstring)."""
    bad = []
    for name, tree in _bench_trees().items():
        if not name.startswith("bench_"):
            continue
        lines = (ast.get_docstring(tree) or "").splitlines()
        if not lines or not lines[0].strip() or len(lines[0]) > 100 or (len(lines) > 1 and lines[1].strip()):
            bad.append(f"{name}: {lines[:2]}")
    assert not bad, f"bench files without a one-line description: {bad}"


def test_no_import_cycles_between_benches():
    trees = _bench_trees()
    local = {name[:-3] for name in trees}
    graph = {name[:-3]: set(_bench_imports(tree)) & local - {name[:-3]} for name, tree in trees.items()}
    cycles, seen, stack = [], set(), []

    def visit(node):
        stack.append(node)
        for dep in sorted(graph[node]):
            if dep in stack:
                cycles.append(tuple(stack[stack.index(dep):] + [dep]))
            elif dep not in seen:
                visit(dep)
        stack.pop()
        seen.add(node)

    for node in sorted(graph):
        if node not in seen:
            visit(node)
    assert not cycles, f"import cycles between benches: {sorted(set(cycles))}"


def test_every_product_module_is_used_by_the_product():
    """A module of solver/, addon/ or operators/ is reachable from the extension's entry points; code only
    tests or benches use lives beside them (tests/ helpers, bench/ helpers, sample_scenes/)."""
    trees = _trees(*PRODUCT)
    modules = {_module_name(rel) for rel in trees}
    graph = {_module_name(rel): {n for n in _imports(rel, tree) if n in modules} for rel, tree in trees.items()}
    reached, todo = set(), list(ENTRY_POINTS)
    while todo:
        mod = todo.pop()
        if mod in reached or mod not in graph:
            continue
        reached.add(mod)
        todo.extend(graph[mod])
        parts = mod.split(".")
        todo.extend(".".join(parts[:k]) for k in range(1, len(parts)))     # a module imports its packages
    unused = sorted(modules - reached - set(USED_OUTSIDE_THE_PRODUCT_ONLY))
    assert not unused, f"product modules the product never imports (move them beside their users): {unused}"


def _docstrings(tree):
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            doc = ast.get_docstring(node)
            if doc:
                yield doc


@pytest.mark.parametrize("top", PRODUCT + ("sample_scenes", "tests", "bench", "tools"))
def test_docstrings_cite_documents_that_exist(top):
    """A Markdown file a docstring names (``docs/RIG.md``, ``README.md``) is in the checkout: citing a
    document that is not there sends the reader nowhere."""
    bad = []
    for rel, path in _sources(top):
        text = "\n".join(_docstrings(ast.parse(open(path, encoding="utf-8").read(), rel)))
        for cited in sorted(set(re.findall(r"(?<![\w/.-])((?:[\w-]+/)*[\w-]+\.md)\b", text))):
            where = [cited] if "/" in cited else [cited, os.path.join("docs", cited)]
            if not any(os.path.isfile(os.path.join(REPO, w)) for w in where):
                bad.append(f"{rel} cites {cited}")
    assert not bad, bad


def test_cited_bench_lines_exist():
    """Every ``./run bench NAME`` in the README and docs/ names a benchmark that exists (bench/bench_NAME.py):
    a number's reproduction line must run."""
    bad = []
    docs = [os.path.join(REPO, "README.md")] + [os.path.join(REPO, "docs", n) for n in sorted(os.listdir(
        os.path.join(REPO, "docs"))) if n.endswith(".md")]
    for path in docs:
        for name in set(re.findall(r"\./run bench ([a-z_0-9]+)", open(path, encoding="utf-8").read())):
            if name != "list" and not os.path.isfile(os.path.join(BENCH, f"bench_{name}.py")):
                bad.append(f"{os.path.relpath(path, REPO)}: ./run bench {name}")
    assert not bad, bad
