"""Where a study's grid points run in parallel: worker processes, or a Dask cluster.

:func:`parallel` takes what the caller names and yields a :class:`concurrent.futures.Executor`
(or None: run in order, in this process):

================================  ==========================================================
``None`` / ``"process"``          worker processes of this machine
                                  (:class:`~concurrent.futures.ProcessPoolExecutor`) when
                                  ``max_workers > 1``, else in order
``"dask"``                        a Dask cluster of ``max_workers`` worker processes on this
                                  machine, started for the run and closed after it (no
                                  dashboard: it would take port 8787 from one already running)
``"tcp://HOST:PORT"`` (any        the Dask scheduler at that address (your cluster): a client
``scheme://``)                    is connected for the run and closed after it; the cluster
                                  stays
a ``dask.distributed.Client``     that client's cluster (left open)
a ``concurrent.futures.Executor`` that executor (left open)
================================  ==========================================================

With a cluster or an executor of your own the points always run there (``max_workers`` is the
cluster's business); with ``"process"`` or ``"dask"`` only when ``max_workers > 1``.
"""
from __future__ import annotations

import contextlib
from concurrent.futures import Executor, ProcessPoolExecutor
from typing import Any, Iterator

from ..errors import WncsError

__all__ = ["EXECUTORS", "parallel", "check_executor"]

#: The executors named by a string (besides a scheduler address).
EXECUTORS = ("process", "dask")
#: Seconds a scheduler address has to answer.
CONNECT_TIMEOUT = 30


def _is_client(obj: Any) -> bool:
    return callable(getattr(obj, "get_executor", None)) and hasattr(obj, "scheduler")


def _is_address(obj: Any) -> bool:
    return isinstance(obj, str) and "://" in obj


def check_executor(executor: Any) -> Any:
    """``executor`` if :func:`parallel` takes it, else one :class:`WncsError` saying what it takes."""
    if executor is None or executor in EXECUTORS or _is_address(executor) or _is_client(executor) \
            or isinstance(executor, Executor):
        return executor
    raise WncsError(f"unknown executor {executor!r}; expected one of 'process', 'dask', a Dask scheduler address "
                    "(tcp://HOST:PORT), a dask.distributed Client or a concurrent.futures Executor")


def _distributed():
    try:
        import distributed  # noqa: F401
    except ImportError:
        raise WncsError("a Dask executor needs dask.distributed: pip install 'wncs_lp[dask]'") from None
    return distributed


@contextlib.contextmanager
def _own_cluster(max_workers: int) -> Iterator[Executor]:
    """A local cluster for one run, closed client first, then cluster. Its scheduler's and workers'
    own log lines are silenced: on a loaded machine a worker's last heartbeat can meet the closing
    scheduler and log a ``CommClosedError`` traceback that says nothing about the run (a worker's
    real failure still reaches the run, as its task's exception)."""
    import logging

    distributed = _distributed()
    cluster = distributed.LocalCluster(n_workers=max_workers, threads_per_worker=1, processes=True,
                                       dashboard_address=None, silence_logs=logging.CRITICAL)
    client = distributed.Client(cluster)
    try:
        yield client.get_executor()
    finally:
        client.close()
        cluster.close()


@contextlib.contextmanager
def _scheduler(address: str) -> Iterator[Executor]:
    """A client of the cluster at ``address`` for one run (the cluster stays up)."""
    distributed = _distributed()
    try:
        client = distributed.Client(address, timeout=CONNECT_TIMEOUT)
    except (OSError, TimeoutError) as exc:
        raise WncsError(f"no Dask scheduler answers at {address}: {exc}") from None
    try:
        yield client.get_executor()
    finally:
        client.close()


@contextlib.contextmanager
def _processes(max_workers: int) -> Iterator[Executor]:
    pool = ProcessPoolExecutor(max_workers=max_workers)
    try:
        yield pool
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


@contextlib.contextmanager
def parallel(executor: Any, max_workers: int, tasks: int) -> Iterator[Executor | None]:
    """The executor the ``tasks`` run on (None: in order, in this process); see the module docstring."""
    check_executor(executor)
    if max_workers < 1:
        raise WncsError(f"max_workers must be >= 1, got {max_workers}")
    if tasks <= 1:
        yield None
    elif isinstance(executor, Executor):
        yield executor
    elif _is_client(executor):
        yield executor.get_executor()
    elif _is_address(executor):
        with _scheduler(executor) as ex:
            yield ex
    elif max_workers == 1:
        yield None
    elif executor == "dask":
        with _own_cluster(max_workers) as ex:
            yield ex
    else:
        with _processes(max_workers) as ex:
            yield ex
