"""``bench NAME [args]``: run ``bench/bench_NAME.py`` of a source checkout (benchmarks are not
shipped in the extension zip).  ``bench list`` lists them, each with
the first line of its docstring."""
import argparse
import ast
import importlib.util
import os
import sys

from ...solver.errors import ArticulaInputError

_BENCH_DIR = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))), "bench")


def _available():
    if not os.path.isdir(_BENCH_DIR):
        return []
    return sorted(f[6:-3] for f in os.listdir(_BENCH_DIR) if f.startswith("bench_") and f.endswith(".py"))


def description(path: str) -> str:
    """A benchmark's one-line description: the first line of its module docstring ("" without one).  Read
    from the source, so listing needs none of the benchmarks' imports."""
    with open(path, encoding="utf-8") as f:
        doc = ast.get_docstring(ast.parse(f.read(), path)) or ""
    return doc.splitlines()[0].strip() if doc else ""


def run(args) -> int:
    names = _available()
    if args.name == "list":
        width = max((len(n) for n in names), default=0)
        for name in names:
            print(f"{name:<{width}}  {description(os.path.join(_BENCH_DIR, f'bench_{name}.py'))}")
        return 0
    if args.name not in names:
        raise ArticulaInputError(f"no benchmark {args.name!r}; available: {', '.join(names) or 'none'}"
                                 " (benchmarks run from a source checkout)")
    path = os.path.join(_BENCH_DIR, f"bench_{args.name}.py")
    if _BENCH_DIR not in sys.path:          # a benchmark imports its helpers (_common, _*.py) by name
        sys.path.insert(0, _BENCH_DIR)
    spec = importlib.util.spec_from_file_location(f"articula_bench_{args.name}", path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod
    spec.loader.exec_module(mod)
    print(f"# ./run bench {args.name} {' '.join(args.rest)}".rstrip())
    return int(mod.main(args.rest) or 0)


def add_commands(sub):
    p = sub.add_parser("bench", help="run a benchmark (bench list: the available ones)")
    p.add_argument("name")
    p.add_argument("rest", nargs=argparse.REMAINDER, help="arguments for the benchmark (options included)")
    p.set_defaults(func=run)
