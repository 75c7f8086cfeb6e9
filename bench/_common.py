"""Shared by the benchmarks: makes ``import articula`` work (the checkout as a package) and
formats result lines."""
import importlib.util
import os
import sys

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
_spec = importlib.util.spec_from_file_location("articula_batch", os.path.join(REPO, "batch.py"))
_batch = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(_batch)            # batch.py imports bpy only when run as a script
_ROOT = _batch.dev_package_root()
if _ROOT not in sys.path:
    sys.path.insert(0, _ROOT)


def report(name: str, value, unit: str = "", note: str = "") -> None:
    """Print one result line: ``name: value unit  (note)``."""
    text = f"{value:.4g}" if isinstance(value, float) else str(value)
    print(f"{name}: {text} {unit}".rstrip() + (f"  ({note})" if note else ""), flush=True)


def best_time(fn, repeats, clock=None):
    """(best time in seconds over ``repeats`` calls of ``fn``, the last call's result); ``clock`` defaults to
    ``time.perf_counter`` (wall), ``time.process_time`` measures CPU."""
    import time
    clock = clock or time.perf_counter
    best, out = float("inf"), None
    for _ in range(repeats):
        t0 = clock()
        out = fn()
        best = min(best, clock() - t0)
    return best, out


def cpu_seconds():
    """CPU time (s) of this process (all threads) plus that of its children that have been waited for
    (the solver's forked helper processes, :class:`solver.parallel.ForkedCall`)."""
    import resource
    import time
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + kids.ru_utime + kids.ru_stime


def addon_modules(bpy):
    """Enable the add-on in this bpy (as Blender enables an extension) and return ``name ->`` its module
    (e.g. ``"addon.scene.render"``), for the benchmarks and the docs' picture tools."""
    import importlib
    mod = _batch.enable_addon(bpy)
    return lambda name: importlib.import_module(f"{mod}.{name}")
