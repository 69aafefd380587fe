"""numba threads: how many a solve uses by default, and when a forked process must use one.

numba runs its parallel kernels on a *threading layer* (``numba.threading_layer()``): GNU
OpenMP (``"omp"``) when libgomp loads, which it does from numba's PyPI wheels on Linux, else
``"workqueue"`` (or ``"tbb"`` when TBB is installed). libgomp does not survive a fork: a child
forked from a process that has run a parallel region is killed ("Terminating: fork() called from
a process already using GNU OpenMP, this is unsafe.") the moment it enters one, even after
``numba.set_num_threads(1)``; the serial kernels are safe there. Measured on numba 0.68 with a
``concurrent.futures.ProcessPoolExecutor`` forked after the parent ran a ``prange`` kernel on 2
threads: ``omp`` children die on their first parallel call; ``workqueue`` children run it on 2
threads; spawn and forkserver children are fresh processes and run it under any layer.

So every solver asks :func:`resolve_threads`:

* by default a solve uses the cores this process may run on (``os.sched_getaffinity``), capped
  at numba's ``NUMBA_NUM_THREADS``;
* :func:`run_parallel` records the pid and the layer of the first parallel call; in a fork of
  that process (another pid) under ``omp``, every solve runs its serial kernels instead (one
  thread, ``stats["threads"] == 1``), so parameter sweeps can fork workers after the main
  process used its threads;
* :func:`thread_limit` caps every solve of a whole job (``wncs-lp reproduce --threads N``),
  explicit counts included, through the environment variable :data:`LIMIT_ENV`, so worker
  processes (forked or spawned) inherit the cap.
"""
from __future__ import annotations

import os
import types
from contextlib import contextmanager
from typing import Any, Callable, Iterator

__all__ = ["usable_cores", "resolve_threads", "run_parallel", "run_twins", "fork_unsafe", "twins", "thread_limit",
           "threads_limit", "FORK_UNSAFE_LAYERS", "PARALLEL_MIN_STATES", "LIMIT_ENV"]

#: Below this many states a solve uses one thread unless ``threads`` says otherwise: a parallel
#: region costs 5-25 ms on a loaded 2-core machine (both threads must be scheduled), more than a
#: whole sweep of a small model (processes 1, 2 at cap 30, 110k states: 1.3 ms on one thread,
#: 14 ms on two under load 11; processes 1-3 at cap 16, 596k states: 22 ms against 45 ms).
PARALLEL_MIN_STATES = 1_000_000

#: Threading layers that a forked child cannot enter once its parent has.
FORK_UNSAFE_LAYERS = ("omp",)

#: The environment variable holding the most threads any solve may use (:func:`thread_limit`).
LIMIT_ENV = "WNCS_LP_THREADS"

#: (pid, threading layer) of the first parallel kernel call of this process tree, or None.
_FIRST_PARALLEL: tuple[int, str] | None = None


def usable_cores() -> int:
    """The cores this process may run on (its CPU affinity), at least 1."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # pragma: no cover - no affinity on this platform
        return max(1, os.cpu_count() or 1)


def fork_unsafe() -> bool:
    """Whether this process is a fork of one that ran a parallel kernel on a fork-unsafe layer."""
    return (_FIRST_PARALLEL is not None and _FIRST_PARALLEL[0] != os.getpid()
            and _FIRST_PARALLEL[1] in FORK_UNSAFE_LAYERS)


def threads_limit() -> int | None:
    """The cap :func:`thread_limit` set (the environment variable :data:`LIMIT_ENV`), or None."""
    text = os.environ.get(LIMIT_ENV, "").strip()
    try:
        n = int(text)
    except ValueError:
        return None
    return n if n >= 1 else None


@contextmanager
def thread_limit(threads: int | None) -> Iterator[None]:
    """Within the block, no solve uses more than ``threads`` threads (None: no cap), in this
    process and in the worker processes it starts (they inherit the environment)."""
    if threads is None:
        yield
        return
    if not (isinstance(threads, int) and not isinstance(threads, bool) and threads >= 1):
        from ..errors import SolverError

        raise SolverError(f"threads must be a whole number >= 1, got {threads!r}")
    old = os.environ.get(LIMIT_ENV)
    os.environ[LIMIT_ENV] = str(threads)
    try:
        yield
    finally:
        if old is None:
            os.environ.pop(LIMIT_ENV, None)
        else:
            os.environ[LIMIT_ENV] = old


def resolve_threads(threads: int | None, n_states: int | None = None) -> int:
    """The threads of a solve over ``n_states`` states: ``threads`` when given, else
    :func:`usable_cores` (one below :data:`PARALLEL_MIN_STATES` states); capped at numba's
    ``NUMBA_NUM_THREADS`` and at :func:`thread_limit`'s cap; 1 in a fork of a process that used
    GNU OpenMP (module docstring)."""
    if fork_unsafe():
        return 1
    import numba

    if threads is None:
        small = n_states is not None and n_states < PARALLEL_MIN_STATES
        threads = 1 if small else usable_cores()
    cap = threads_limit()
    if cap is not None:
        threads = min(int(threads), cap)
    return max(1, min(int(threads), int(numba.config.NUMBA_NUM_THREADS)))


def run_parallel(fn: Callable[..., Any], threads: int, *args: Any, chunksize: int | None = None) -> Any:
    """Call a parallel (``prange``) kernel on ``threads`` threads (numba's count restored after),
    and remember that this process has entered the threading layer."""
    global _FIRST_PARALLEL
    import numba

    old = numba.get_num_threads()
    if old != threads:
        numba.set_num_threads(threads)
    try:
        if chunksize is None:
            out = fn(*args)
        else:
            with numba.parallel_chunksize(chunksize):
                out = fn(*args)
    finally:
        if old != threads:
            numba.set_num_threads(old)
    if _FIRST_PARALLEL is None or _FIRST_PARALLEL[0] != os.getpid():
        try:
            layer = str(numba.threading_layer())
        except ValueError:  # pragma: no cover - no parallel region ran after all
            layer = "unknown"
        _FIRST_PARALLEL = (os.getpid(), layer)
    return out


def run_twins(parallel: Callable[..., Any], serial: Callable[..., Any], threads: int, *args: Any,
              chunksize: int | None = None) -> Any:
    """Call a :func:`twins` pair: ``serial(*args)`` on one thread, else ``parallel`` through
    :func:`run_parallel` on ``threads``."""
    if threads > 1:
        return run_parallel(parallel, threads, *args, chunksize=chunksize)
    return serial(*args)


def twins(body: Callable[..., Any], name: str, **flags: Any) -> tuple[Any, Any]:
    """``body`` compiled twice with numba: ``name`` on numba's threads (``parallel=True``: its
    ``prange`` loops split between them) and ``name + "_serial"`` on one (``prange`` is then
    ``range``). Each is a copy of ``body`` under its own name, because numba's on-disk cache
    names its files by the function's qualified name, not by the compile flags."""
    from numba import njit

    out = []
    for suffix, parallel in (("", True), ("_serial", False)):
        fn = types.FunctionType(body.__code__, body.__globals__, name + suffix, body.__defaults__, body.__closure__)
        fn.__qualname__ = name + suffix
        fn.__doc__ = body.__doc__
        out.append(njit(cache=True, nogil=True, parallel=parallel, **flags)(fn))
    return out[0], out[1]
