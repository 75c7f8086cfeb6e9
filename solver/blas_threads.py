"""The thread count of the OpenBLAS libraries loaded into this process, changed for a block of code.

numpy's and scipy's wheels each bundle an OpenBLAS (``numpy.libs/libscipy_openblas64_-*.so``,
``scipy.libs/libscipy_openblas-*.so``, older numpy ``libopenblas64_p-*.so``) whose worker threads, one per
core, spin for a while after every call.  That is harmless while one thread of ours runs, but when the
weight BCD runs its two halves in two processes (:mod:`solver.weights_bcd`, :class:`parallel.ForkedCall`)
each process's BLAS threads compete with the other's work: measured on a captured MakeHuman game_engine
weight step (13,380 vertices × 30 scans, 2-core machine, one session), the two halves took 1.35 / 1.6 s
side by side against 0.79 / 0.90 s one after the other; with one BLAS thread per process 0.72 / 0.79 s.

:func:`limited` sets every loaded OpenBLAS to ``n`` threads in the block and restores the previous counts
after it.  The libraries are found in ``/proc/self/maps`` (Linux; elsewhere nothing is changed) and
driven through their exported ``*openblas_set_num_threads*`` / ``*openblas_get_num_threads*`` functions
(plain, ``64_``-suffixed and ``scipy_``-prefixed names).  Libraries without them are left alone.
"""
import ctypes
import re
import sys
import threading
from contextlib import contextmanager

_PREFIXES = ("openblas", "scipy_openblas")
_SUFFIXES = ("", "64_")
_LOCK = threading.Lock()
_FOUND = {}


def loaded_libraries():
    """Paths of the OpenBLAS shared libraries mapped into this process (Linux; ``[]`` elsewhere)."""
    if not sys.platform.startswith("linux"):
        return []
    try:
        with open("/proc/self/maps", encoding="utf-8", errors="replace") as f:
            maps = f.read()
    except OSError:
        return []
    return sorted(set(re.findall(r"(/\S*openblas\S*\.so[\w.]*)", maps)))


def _controls(path):
    """``(get, set)`` ctypes functions of the library at ``path``, or None if it exports neither name."""
    if path not in _FOUND:
        found = None
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            lib = None
        for prefix in _PREFIXES if lib is not None else ():
            for suffix in _SUFFIXES:
                get = getattr(lib, f"{prefix}_get_num_threads{suffix}", None)
                put = getattr(lib, f"{prefix}_set_num_threads{suffix}", None)
                if get is not None and put is not None:
                    get.restype, get.argtypes = ctypes.c_int, []
                    put.restype, put.argtypes = None, [ctypes.c_int]
                    found = (get, put)
                    break
            if found:
                break
        _FOUND[path] = found
    return _FOUND[path]


def thread_counts():
    """``{path: threads}`` of the loaded OpenBLAS libraries that can be controlled."""
    with _LOCK:
        return {p: c[0]() for p in loaded_libraries() if (c := _controls(p)) is not None}


@contextmanager
def limited(n=1):
    """Every controllable OpenBLAS runs on at most ``n`` (≥ 1) threads in the block; the previous counts
    are restored after it (also on an exception)."""
    n = max(1, int(n))
    with _LOCK:
        controls = [c for p in loaded_libraries() if (c := _controls(p)) is not None]
        saved = [get() for get, _ in controls]
        for (_, put), old in zip(controls, saved):
            if old > n:
                put(n)
    try:
        yield
    finally:
        with _LOCK:
            for (_, put), old in zip(controls, saved):
                if old > n:
                    put(old)
