"""solver.parallel and the solver pieces that use it: two threads give the serial results (to rounding)."""
import os
import sys
import threading
import time

import numpy as np
import pytest

from articula.solver import parallel
from articula.solver.learn.joints_poses import normal_equation_blocks
from articula.solver.geometry.mesh_graph import uniform_laplacian
from articula.solver.learn.pipeline import learn_rig
from articula.solver.rig.model import Poses
from articula.solver.fit.pose_fit import fit_poses
from articula.solver.learn.objective import RigObjective
from articula.solver.rig.skinning import hybrid_skin
from articula.solver.geometry.surface_distance import distance_to_surface, per_vertex_scan_distances
from articula.solver.learn.weights.optimise import optimise_weights

from articula.sample_scenes.tube_scans import hybrid_truth


def test_map_keeps_order_runs_on_threads_and_never_nests():
    seen = set()

    def square(x):
        seen.add(threading.current_thread().name)
        inner = parallel.map_pieces(lambda y: (y, threading.current_thread().name), range(3))
        assert {name for _, name in inner} == {threading.current_thread().name}     # serial inside a worker
        return x * x

    assert parallel.workers() == 1
    assert parallel.map_pieces(square, range(7)) == [x * x for x in range(7)]
    assert seen == {threading.current_thread().name}                    # outside `using`: serial
    with parallel.using(2) as n:
        assert n == 2 and parallel.workers() == 2
        seen.clear()
        assert parallel.map_pieces(square, range(7)) == [x * x for x in range(7)]
        assert all(name.startswith("articula-solver") for name in seen)
    assert parallel.workers() == 1
    assert parallel.resolve(None) >= 1 and parallel.resolve(0) == parallel.resolve(None)


def test_map_propagates_exceptions_and_restores_the_setting():
    def boom(x):
        if x == 3:
            raise ValueError("piece 3")
        return x
    with pytest.raises(ValueError, match="piece 3"):
        with parallel.using(2):
            parallel.map_pieces(boom, range(6))
    assert parallel.workers() == 1


def test_split_covers_the_range_in_order():
    with parallel.using(2):
        pieces = parallel.split(11)
        assert len(pieces) == 2 and np.array_equal(np.concatenate(pieces), np.arange(11))
        assert len(parallel.split(11, min_size=6)) == 1
    assert len(parallel.split(11)) == 1


@pytest.fixture(scope="module")
def sequence():
    model, poses, scans = hybrid_truth(120, seed=3)        # 120 x 509 vertex-frames: above every threshold
    noisy = scans + np.random.default_rng(0).normal(scale=2e-3, size=scans.shape)
    return model, poses, noisy


def _twice(fn):
    serial = fn()
    with parallel.using(2):
        threaded = fn()
    return serial, threaded


def test_skin_blocks_fits_and_distances_equal_serial(sequence):
    model, poses, scans = sequence
    a, b = _twice(lambda: hybrid_skin(model, poses))
    assert np.abs(a - b).max() < 1e-14
    objective = RigObjective(scans, uniform_laplacian(model.faces, model.num_vertices), 100.0)
    a, b = _twice(lambda: normal_equation_blocks(model, poses, objective))
    for x, y in zip(a, b):
        assert np.allclose(x, y, rtol=1e-11, atol=1e-12 * np.abs(x).max())
    a, b = _twice(lambda: fit_poses(model, scans, max_iterations=3))
    assert np.abs(a.poses.rotations - b.poses.rotations).max() < 1e-10
    assert np.allclose(a.energy, b.energy, rtol=1e-10)
    a, b = _twice(lambda: per_vertex_scan_distances(scans, hybrid_skin(model, poses), model.faces))
    assert np.array_equal(a, b)
    posed = hybrid_skin(model, poses)
    assert np.allclose(a[7], distance_to_surface(scans[7], posed[7], model.faces), rtol=0, atol=1e-12)


def test_weights_and_whole_learning_equal_serial(sequence, monkeypatch):
    from articula.solver.learn.weights import evaluation as weights_bcd
    monkeypatch.setattr(weights_bcd, "PARALLEL_MIN_WORK", 2000)       # split every colour class as well
    model, poses, scans = sequence
    objective = RigObjective(scans, uniform_laplacian(model.faces, model.num_vertices), 100.0)
    start = Poses(poses.rotations.copy(), poses.translations.copy(), poses.scales.copy())
    a, b = _twice(lambda: optimise_weights(model, start, objective, max_sweeps=2))
    assert np.allclose(a[1], b[1], rtol=1e-12)
    assert np.abs(a[0].swing_weights - b[0].swing_weights).max() < 1e-6
    kw = dict(parts=8, max_iterations=1, bcd_sweeps=1, gn_iterations=2, bcd_steps=(0.2,), key_scans=12)
    one = learn_rig(scans[:40], model.faces, workers=1, **kw)
    two = learn_rig(scans[:40], model.faces, workers=2, **kw)
    assert one.report["workers"] == 1 and two.report["workers"] == 2
    assert np.allclose([e for _, e in one.report["objective_log"]], [e for _, e in two.report["objective_log"]],
                       rtol=1e-9)
    assert np.abs(one.model.rest_vertices - two.model.rest_vertices).max() < 1e-8


def test_shutdown_stops_the_pool_and_a_new_one_starts_on_demand():
    with parallel.using(2):
        workers = parallel.map_pieces(lambda _: threading.current_thread(), range(8))
        assert all(t.name.startswith("articula-solver") for t in workers)
        parallel.shutdown()
        assert not any(t.is_alive() for t in workers)        # (another copy of the module has its own pool)
        assert parallel.map_pieces(abs, [-1, -2]) == [1, 2]
    parallel.shutdown()


def test_shutdown_stops_the_reader_thread_too():
    """The thread reading a recording's next capture ahead is stopped with the pool (the add-on's
    unregister calls :func:`parallel.shutdown`), and a later read starts a new one."""
    first = parallel.reader().submit(threading.current_thread).result()
    assert first.name.startswith("articula-reader") and first.is_alive()
    parallel.shutdown()
    assert not first.is_alive()
    again = parallel.reader().submit(threading.current_thread).result()
    assert again is not first and again.is_alive()
    parallel.shutdown()


linux_only = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="ForkedCall forks on Linux only")


@linux_only
def test_forked_call_runs_in_a_child_and_returns_its_value():
    with parallel.using(2):
        assert parallel.can_fork()
        big = np.arange(300_000.0)                         # larger than a pipe's buffer
        with parallel.ForkedCall(lambda: (os.getpid(), big * 2, parallel.workers(), parallel.can_fork())) as job:
            here = big.sum()                                 # the caller works on meanwhile
            pid, doubled, inner_workers, inner_fork = job.result()
        assert pid != os.getpid() and np.array_equal(doubled, big * 2) and here == big.sum()
        assert inner_workers == 1 and not inner_fork         # the child runs serially, never forks again
        with parallel.allow_fork(False):
            assert not parallel.can_fork()
            with parallel.ForkedCall(lambda: os.getpid()) as job:
                assert job.result() == os.getpid()           # no fork: computed by the caller
    assert not parallel.can_fork()                            # one worker: never forks


@linux_only
def test_forked_call_reports_failures_and_reaps_an_abandoned_child():
    def boom():
        raise ValueError("in the child")
    with parallel.using(2):
        with parallel.ForkedCall(boom) as job:
            with pytest.raises(parallel.ForkFailed, match="ValueError: in the child"):
                job.result()
        with parallel.ForkedCall(lambda: os._exit(3)) as job:
            with pytest.raises(parallel.ForkFailed, match="no result"):
                job.result()
        with parallel.ForkedCall(lambda: time.sleep(60)) as job:
            pid = job.pid
        assert job.pid is None
        with pytest.raises(ChildProcessError):
            os.waitpid(pid, os.WNOHANG)                      # killed and reaped when the block was left


@linux_only
def test_fork_map_keeps_the_order_and_computes_the_second_half_in_a_child():
    with parallel.using(2):
        got = parallel.fork_map(lambda x: (x * x, os.getpid()), range(7))
    assert [v for v, _ in got] == [x * x for x in range(7)]
    assert {pid for _, pid in got[:3]} == {os.getpid()} and os.getpid() not in {pid for _, pid in got[3:]}
    assert parallel.fork_map(lambda x: os.getpid(), range(3)) == [os.getpid()] * 3    # one worker: here


@linux_only
def test_single_blas_thread_restores_the_thread_count_of_numpys_and_scipys_openblas():
    """Both wheels bundle their own OpenBLAS here (scipy's is the one SuperLU uses): both go to one
    thread inside the block and back afterwards."""
    threads = parallel._openblas_threads()
    assert len(threads) == 2, threads
    for _, put in threads:
        put(2)
    with parallel.single_blas_thread():
        assert [get() for get, _ in threads] == [1, 1]
        with parallel.single_blas_thread():
            assert [get() for get, _ in threads] == [1, 1]
        assert [get() for get, _ in threads] == [1, 1]
    assert [get() for get, _ in threads] == [2, 2]
    with pytest.raises(ValueError):
        with parallel.single_blas_thread():
            raise ValueError
    assert [get() for get, _ in threads] == [2, 2]


def test_map_in_order_uses_its_own_thread_count_and_reports_in_order():
    threads, reports, main = set(), [], threading.current_thread().name

    def slow_square(x):
        threads.add(threading.current_thread().name)
        time.sleep(0.02 * (x % 3 == 0))            # results finish out of order
        return x * x

    def report(i, result):
        assert threading.current_thread().name == main
        reports.append((i, result))

    assert parallel.workers() == 1                 # `using` is not consulted
    assert parallel.map_in_order(slow_square, range(9), 3, report) == [x * x for x in range(9)]
    assert reports == [(i, i * i) for i in range(9)]
    assert 1 < len(threads) <= 3 and all(name.startswith("articula-solver") for name in threads)
    threads.clear()
    assert parallel.map_in_order(slow_square, range(4), 1) == [0, 1, 4, 9] and threads == {main}
    threads.clear()
    assert parallel.map_in_order(slow_square, [5], 4) == [25] and threads == {main}   # one piece: no pool


def test_map_in_order_stops_on_errors_without_leaving_threads_behind():
    started, finished = [], []

    def work(x):
        started.append(x)
        time.sleep(0.01)
        if x == 2:
            raise ValueError("piece 2")
        finished.append(x)
        return x

    with pytest.raises(ValueError, match="piece 2"):
        parallel.map_in_order(work, range(40), 2)
    done = len(finished)
    time.sleep(0.05)
    assert len(finished) == done and len(started) < 40     # pieces not started were cancelled, none runs on

    def stop(i, result):
        if i == 3:
            raise KeyboardInterrupt
    started.clear()
    with pytest.raises(KeyboardInterrupt):
        parallel.map_in_order(work, range(3, 40), 2, stop)
    assert len(started) < 37
    inner = parallel.map_in_order(lambda x: parallel.map_in_order(lambda y: threading.current_thread().name,
                                                                    range(3), 3), range(2), 2)
    assert all(len(set(names)) == 1 for names in inner)    # serial inside a worker: no nested pools
