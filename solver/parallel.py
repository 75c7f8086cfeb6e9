"""Thread parallelism for the solver: independent pieces of work mapped over a small thread pool.

The pieces are chunks of scans (Gauss–Newton systems, skinning, surface distances), blocks of frames (pose
fits) and sets of vertices (weight candidates).  numpy releases the GIL inside its array loops, einsum and
BLAS, so two threads overlap most of the work even though the orchestration is Python.  Each piece is
computed exactly as it would be alone, so a result depends on the number of workers only through how the
work is split (rounding: products over differently shaped batches may differ in the last bit), never
on the scheduling.

Processes (:class:`ForkedCall`): work whose Python orchestration dominates (the weight BCD's colour
classes of a few hundred vertices) gains nothing from a second thread, so one independent half of it can
run in a forked child process (Linux only: fork without exec is unsafe with macOS frameworks and absent
on Windows) that sends its result back through a pipe; elsewhere, or if the child fails, the caller
computes that half itself.  The child sees a copy of the memory at the fork and runs serially.

``with using(n): ...`` sets the number of workers for solver calls made in the block (``None`` or 0 = one
per CPU core); outside any such block the solver runs on one thread.  Calls from inside a worker run
serially (no nested pools).  :func:`map_in_order` is for callers that choose their own thread count and
report progress as results arrive (the depth-recording import).
"""
import functools
import os
import pickle
import signal
import sys
import threading
import warnings
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager

import numpy as np

_STATE = {"workers": 1, "pool": None, "pool_size": 0, "reader": None}
_LOCK = threading.Lock()
_LOCAL = threading.local()


def resolve(workers):
    """Worker count for a requested ``workers`` (None or ≤ 0: one per CPU core), at least 1."""
    if workers is None or int(workers) <= 0:
        return max(1, os.cpu_count() or 1)
    return int(workers)


@contextmanager
def using(workers=None):
    """Solver calls in the block use ``resolve(workers)`` threads; the previous setting is restored."""
    n = resolve(workers)
    with _LOCK:
        saved = _STATE["workers"]
        _STATE["workers"] = n
    try:
        yield n
    finally:
        with _LOCK:
            _STATE["workers"] = saved


def workers():
    """The number of threads a :func:`map_pieces` call would use here (1 inside a worker)."""
    return 1 if getattr(_LOCAL, "inside", False) else _STATE["workers"]


def _pool(n):
    with _LOCK:
        if _STATE["pool"] is None or _STATE["pool_size"] < n:
            if _STATE["pool"] is not None:
                _STATE["pool"].shutdown(wait=False)
            _STATE["pool"] = ThreadPoolExecutor(n, thread_name_prefix="articula-solver",
                                                initializer=_mark_worker)
            _STATE["pool_size"] = n
        return _STATE["pool"]


def _mark_worker():
    _LOCAL.inside = True


def map_pieces(fn, pieces):
    """``[fn(p) for p in pieces]``, on :func:`workers` threads when there are several pieces."""
    pieces = list(pieces)
    n = min(workers(), len(pieces))
    if n <= 1:
        return [fn(p) for p in pieces]
    return list(_pool(n).map(fn, pieces))


def map_in_order(fn, pieces, workers, on_result=None):
    """``[fn(p) for p in pieces]`` on ``workers`` threads of a pool of its own (serially in the calling
    thread when ``workers`` <= 1, there is one piece, or the caller is itself a worker).  ``on_result(i,
    result)`` runs in the calling thread as each result is ready, in order: progress reports, which may
    raise to stop (e.g. ``Cancelled``).  When ``fn`` or ``on_result`` raises, the pieces not yet started
    are cancelled and the running ones finish before the exception propagates, so no thread outlives the
    call.  Unlike :func:`map_pieces` the thread count is the caller's, not :func:`using`'s."""
    pieces = list(pieces)
    n = min(int(workers), len(pieces)) if not getattr(_LOCAL, "inside", False) else 1
    results = []
    if n <= 1:
        for i, p in enumerate(pieces):
            results.append(fn(p))
            if on_result is not None:
                on_result(i, results[-1])
        return results
    with ThreadPoolExecutor(n, thread_name_prefix="articula-solver", initializer=_mark_worker) as pool:
        futures = [pool.submit(fn, p) for p in pieces]
        try:
            for i, fut in enumerate(futures):
                results.append(fut.result())
                if on_result is not None:
                    on_result(i, results[-1])
        except BaseException:
            for fut in futures:
                fut.cancel()
            raise
    return results


def shutdown():
    """Stop the pool's idle threads and the reader thread (a later :func:`map_pieces` or :func:`reader`
    starts new ones); e.g. when the add-on is disabled."""
    with _LOCK:
        pool, _STATE["pool"], _STATE["pool_size"] = _STATE["pool"], None, 0
        ahead, _STATE["reader"] = _STATE["reader"], None
    for executor in (pool, ahead):
        if executor is not None:
            executor.shutdown(wait=True)


def reader() -> ThreadPoolExecutor:
    """The one thread that reads input ahead beside the pool (a recording's next capture), started on
    first use and stopped by :func:`shutdown`."""
    with _LOCK:
        if _STATE["reader"] is None:
            _STATE["reader"] = ThreadPoolExecutor(1, thread_name_prefix="articula-reader")
        return _STATE["reader"]


def piece_size(count, largest):
    """Length of the consecutive pieces that cut ``count`` items into at least one piece per
    :func:`workers` thread, none longer than ``largest`` (≥ 1)."""
    return max(1, min(int(largest), -(-int(count) // workers())))


def split(count, min_size=1):
    """Index arrays that cut ``range(count)`` into :func:`workers` nearly equal consecutive pieces, each at
    least ``min_size`` long (fewer pieces if needed; one piece when serial)."""
    n = max(1, min(workers(), count // max(int(min_size), 1)))
    return np.array_split(np.arange(count), n)


_FORK = {"enabled": True, "child": False}


def can_fork():
    """Whether :class:`ForkedCall` runs its function in a child process here: Linux, two or more
    :func:`workers`, not inside a worker thread or a forked child, and not switched off
    (``ARTICULA_NO_FORK=1`` or :func:`allow_fork`)."""
    return (_FORK["enabled"] and not _FORK["child"] and sys.platform.startswith("linux")
            and hasattr(os, "fork") and workers() >= 2 and os.environ.get("ARTICULA_NO_FORK") != "1")


@contextmanager
def allow_fork(enabled):
    """:func:`can_fork` is False in the block if ``enabled`` is False (for comparing both paths)."""
    saved = _FORK["enabled"]
    _FORK["enabled"] = bool(enabled)
    try:
        yield
    finally:
        _FORK["enabled"] = saved


def fork_map(fn, pieces):
    """``[fn(p) for p in pieces]`` with the second half of the pieces computed in a forked child
    (:class:`ForkedCall`; fn's results must pickle) while this process computes the first half, each
    serially; :func:`map_pieces` where :func:`can_fork` is False or there is only one piece.  A failed
    child's half is computed here.  For pieces whose work holds the interpreter lock for much of the
    time (the Gauss–Newton systems of the joints-and-poses step); work that releases it (surface
    distances) gains as much on threads."""
    pieces = list(pieces)
    if len(pieces) < 2 or not can_fork():
        return map_pieces(fn, pieces)
    mine, theirs = pieces[: len(pieces) // 2], pieces[len(pieces) // 2:]

    def serial(part):
        return [fn(p) for p in part]

    with ForkedCall(lambda: serial(theirs)) as job:
        first = serial(mine)
        try:
            second = job.result()
        except ForkFailed:
            second = serial(theirs)
    return first + second


class ForkFailed(RuntimeError):
    """The forked child did not deliver a result (it raised, crashed or was killed)."""


class ForkedCall:
    """``fn()`` started in a forked child process (if :func:`can_fork`), to be collected by :meth:`result`
    while the caller works on: the child runs on one thread, pickles ``fn()``'s return value into a pipe
    and exits without running the parent's exit handlers.  Without fork, :meth:`result` calls ``fn()``
    itself.  Use as a context manager: leaving the block before :meth:`result` kills and reaps the child."""

    def __init__(self, fn):
        self.fn, self.pid, self.fd = fn, None, None
        if not can_fork():
            return
        r, w = os.pipe()
        with warnings.catch_warnings():        # the interpreter warns about forking with live threads;
            warnings.simplefilter("ignore", DeprecationWarning)  # the child only computes with numpy
            pid = os.fork()
        if pid == 0:                                                    # child
            os.close(r)
            _child_main(fn, w)
        os.close(w)
        self.pid, self.fd = pid, r

    def result(self):
        """``fn()``'s return value: from the child (raises :class:`ForkFailed` if it gave none), or computed
        here when no child was started."""
        if self.pid is None:
            return self.fn()
        chunks = []
        with os.fdopen(self.fd, "rb") as f:
            self.fd = None
            while True:
                b = f.read(1 << 20)
                if not b:
                    break
                chunks.append(b)
        _, status = os.waitpid(self.pid, 0)
        self.pid = None
        try:
            ok, value = pickle.loads(b"".join(chunks))
        except Exception:
            raise ForkFailed(f"the forked child gave no result (exit status {status})") from None
        if not ok:
            raise ForkFailed(f"the forked child failed: {value}")
        return value

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        if self.fd is not None:
            os.close(self.fd)
            self.fd = None
        if self.pid is not None:
            try:
                os.kill(self.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            os.waitpid(self.pid, 0)
            self.pid = None
        return False


def _child_main(fn, fd):
    """In the forked child: run ``fn()`` serially, write ``(ok, value or error text)`` to ``fd``, exit."""
    code = 0
    try:
        _FORK["child"] = True
        _STATE.update(workers=1, pool=None, pool_size=0)
        try:
            data = pickle.dumps((True, fn()), protocol=pickle.HIGHEST_PROTOCOL)
        except BaseException as e:                                     # noqa: BLE001 (reported to the parent)
            data = pickle.dumps((False, f"{type(e).__name__}: {e}"))
            code = 1
        view = memoryview(data)
        while len(view):
            view = view[os.write(fd, view):]
    except BaseException:                                              # noqa: BLE001
        code = 2
    finally:
        os._exit(code)


# -- numpy's BLAS threads ----------------------------------------------------------------------------

@functools.lru_cache(maxsize=None)
@functools.lru_cache(maxsize=None)
def _openblas_threads():
    """``[(get, set), ...]`` thread-count functions of the OpenBLAS libraries bundled with numpy (wheels:
    ``numpy.libs/``, macOS ``numpy/.dylibs/``) and with scipy (``scipy.libs/``, a second copy that SuperLU
    and scipy.linalg use: left multi-threaded, a 64-column sparse solve took 3.2 s instead of 0.13 s on
    the 2-core machine); empty for another BLAS."""
    import ctypes
    import glob
    import os
    roots = [os.path.dirname(np.__file__)]
    try:
        import scipy
        roots.append(os.path.dirname(scipy.__file__))
    except ImportError:
        pass
    found = []
    for root in roots:
        for path in glob.glob(os.path.join(root + ".libs", "*openblas*")) + \
                glob.glob(os.path.join(root, ".dylibs", "*openblas*")):
            try:
                lib = ctypes.CDLL(path)                              # already loaded: the same library
            except OSError:
                continue
            for name in ("scipy_openblas_get_num_threads64_", "scipy_openblas_get_num_threads",
                         "openblas_get_num_threads64_", "openblas_get_num_threads"):
                get, put = getattr(lib, name, None), getattr(lib, name.replace("_get_", "_set_"), None)
                if get is not None and put is not None:
                    get.restype, put.argtypes = ctypes.c_int, [ctypes.c_int]
                    found.append((get, put))
                    break
    return found


_BLAS_STATE = {"lock": threading.Lock(), "depth": 0, "saved": []}


@contextmanager
def single_blas_thread():
    """Run the block with numpy's OpenBLAS on one thread (the previous count is restored when the last
    active block ends; nesting and several Python threads are fine).

    For the Gauss–Newton solvers, which make hundreds of mid-size BLAS calls between other numpy work:
    with several threads, every call waits for the worker threads and the workers spin between calls,
    which costs far more CPU time than the products themselves.  Covers numpy's and scipy's bundled
    OpenBLAS; does nothing for another BLAS."""
    threads = _openblas_threads()
    if not threads:
        yield
        return
    state = _BLAS_STATE
    with state["lock"]:
        if state["depth"] == 0:
            state["saved"] = [get() for get, _ in threads]
            for _, put in threads:
                put(1)
        state["depth"] += 1
    try:
        yield
    finally:
        with state["lock"]:
            state["depth"] -= 1
            if state["depth"] == 0:
                for (_, put), saved in zip(threads, state["saved"]):
                    put(saved)
