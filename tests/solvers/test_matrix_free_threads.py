"""numba threads: the default is the usable cores (on large layouts), and worker processes forked
after the main process ran threaded kernels still solve (issue 28)."""
from __future__ import annotations

import multiprocessing
import os
from concurrent.futures import ProcessPoolExecutor

import pytest

numba = pytest.importorskip("numba")

import wncs_lp  # noqa: E402
from wncs_lp.solvers import threads as th  # noqa: E402
from wncs_lp.solvers.matrix_free import matrix_free_evaluate, matrix_free_value_iteration  # noqa: E402


def _scenario(cap: int = 7):
    return wncs_lp.load_scenario(wncs_lp.scenario_path("paper_p1234"), [f"tau_cap={cap}"])


def _solve_in_child(threads: int):
    """In a forked worker: both solvers asked for ``threads`` threads."""
    sc = _scenario()
    mf = matrix_free_value_iteration(sc, threads=threads)
    vi = wncs_lp.solve(wncs_lp.build(sc), "vi", threads=threads)
    return os.getpid(), mf.status, mf.gain, mf.stats["threads"], vi.gain, vi.stats["threads"]


def test_the_default_is_the_usable_cores(monkeypatch):
    cap = int(numba.config.NUMBA_NUM_THREADS)
    assert th.resolve_threads(None, 10 * th.PARALLEL_MIN_STATES) == min(len(os.sched_getaffinity(0)), cap)
    assert th.resolve_threads(None, 10) == 1  # below the size where a parallel region pays
    assert th.resolve_threads(3, 10) == min(3, cap)  # a count given is kept (capped)
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0})  # e.g. taskset -c 0
    assert th.resolve_threads(None, 10 * th.PARALLEL_MIN_STATES) == 1


@pytest.mark.slow
def test_workers_forked_after_threaded_kernels_still_solve():
    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.fail("this test needs numba to have 2 threads (NUMBA_NUM_THREADS >= 2)")
    sc = _scenario()
    parent = matrix_free_value_iteration(sc, threads=2)  # enters numba's threading layer here
    assert parent.status == "optimal" and parent.stats["threads"] == 2
    ev = matrix_free_evaluate(sc, parent, threads=2)
    assert ev.status == "optimal"
    layer = numba.threading_layer()
    # a GNU OpenMP child would be killed ("fork() called from a process already using GNU
    # OpenMP") the moment it entered a parallel region: BrokenProcessPool
    with ProcessPoolExecutor(2, mp_context=multiprocessing.get_context("fork")) as ex:
        results = list(ex.map(_solve_in_child, [2, 2]))
    slack = 1e-9 * parent.gain
    for pid, status, g_mf, th_mf, g_vi, th_vi in results:
        assert pid != os.getpid() and status == "optimal"
        assert parent.gain_lower - slack <= g_mf <= parent.gain_upper + slack
        assert parent.gain_lower - slack <= g_vi <= parent.gain_upper + slack
        if layer in th.FORK_UNSAFE_LAYERS:
            assert th_mf == th_vi == 1
    # and the parent itself still runs on its threads
    assert matrix_free_value_iteration(sc, threads=2).stats["threads"] == 2
