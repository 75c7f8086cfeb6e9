"""Shared by the benchmarks: makes ``import articula`` work (the checkout as a package) and
formats result lines."""
import os
import sys

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
_ROOT = os.path.join(REPO, ".pkgroot")
if not os.path.exists(os.path.join(_ROOT, "articula")):
    os.makedirs(_ROOT, exist_ok=True)
    os.symlink("..", os.path.join(_ROOT, "articula"))
if _ROOT not in sys.path:
    sys.path.insert(0, _ROOT)


def report(name: str, value, unit: str = "", note: str = "") -> None:
    """Print one result line: ``name: value unit  (note)``."""
    text = f"{value:.4g}" if isinstance(value, float) else str(value)
    print(f"{name}: {text} {unit}".rstrip() + (f"  ({note})" if note else ""), flush=True)
