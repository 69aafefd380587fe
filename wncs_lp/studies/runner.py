"""The one grid runner of the studies: every point computed once, in order or in parallel.

:func:`run_grid` walks a study's points. In order (one worker, or a single point) each point
receives what the previous one handed on (``carry``: a warm start, the first cap's policy) and
may end the walk (``stop``: a cap study that has converged); its results are recorded one by one
as they are made, so an interrupted run keeps every finished row. In parallel (a process pool, a
Dask cluster: :mod:`wncs_lp.studies.executors`) the points are independent tasks and their
results are recorded as each task ends.
"""
from __future__ import annotations

from concurrent.futures import as_completed
from typing import Any, Callable, Sequence

from .executors import parallel

__all__ = ["run_grid"]


def run_grid(
    tasks: Sequence[Any],
    compute: Callable[..., tuple[list[Any], Any]],
    record: Callable[[Any], None],
    *,
    executor: Any = None,
    max_workers: int = 1,
    stop: Callable[[list[Any], Any], bool] | None = None,
) -> None:
    """Compute every task and record its results.

    Parameters
    ----------
    tasks : sequence
        One item per point (picklable when run in parallel).
    compute : callable
        ``compute(task, carry, emit) -> (results, carry)``, a module-level function (or a
        :func:`functools.partial` of one) so worker processes can run it. In order, ``emit`` is
        ``record`` (call it for each result as soon as it is made) and ``carry`` what the
        previous task returned (None for the first); in parallel both are None.
    record : callable
        Receives each result in this process (it writes the study's files).
    executor, max_workers
        Where the tasks run (:func:`wncs_lp.studies.executors.parallel`).
    stop : callable, optional
        ``stop(results, carry) -> bool`` after each task in order: True ends the walk.
    """
    with parallel(executor, max_workers, len(tasks)) as pool:
        if pool is None:
            carry = None
            for task in tasks:
                results, carry = compute(task, carry, record)
                if stop is not None and stop(results, carry):
                    return
            return
        futures = [pool.submit(compute, task, None, None) for task in tasks]
        try:
            for fut in as_completed(futures):
                results, _ = fut.result()
                for r in results:
                    record(r)
        finally:
            for fut in futures:
                fut.cancel()
