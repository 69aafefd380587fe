"""Steps computed in worker processes (Context.prefetch) give the numbers computed in the main process."""
from __future__ import annotations

import numpy as np

from wncs_lp.reproduce.cache import code_version
from wncs_lp.reproduce.context import PROFILES, Context, Step, _run_step

SIM = ("optimal", 400, 2, 7, 40)


def _numbers(ctx: Context, scenarios) -> list:
    out = []
    for sc in scenarios:
        solved = ctx.solve(sc)
        search = ctx.static_search(sc)
        out.append((solved.gain, solved.gain_lower, solved.gain_upper, solved.policy.tolist(),
                    solved.stationary.tolist(), ctx.evaluate(sc, "greedy")["gain"],
                    [e["gain"] for e in search["all"]], ctx.simulate(sc, *SIM)))
    return out


def test_worker_steps_equal_the_main_process_steps(tmp_path):
    prof = PROFILES["quick"]
    main = Context(tmp_path / "main", prof)
    main.workers = 1
    pooled = Context(tmp_path / "pooled", prof)
    scenarios = [pooled.scenario("paper_p12.toml", ["tau_cap=7", f"p={p}"]) for p in (0.8, 0.9, 1.0)]
    try:
        pooled.prefetch([Step(sc, ("greedy",), True, (SIM,)) for sc in scenarios])
        computed_there = pooled.cache.misses
        got = _numbers(pooled, scenarios)
    finally:
        pooled.close()
    assert computed_there == 0 and pooled.cache.misses == 0 and pooled.cache.hits > 0  # all from the workers
    want = _numbers(main, scenarios)
    assert main.cache.misses > 0  # computed here
    assert got == want  # bitwise: the same code on the same instances
    assert all(np.isfinite(g[0]) for g in got)


def test_nothing_is_sent_to_workers_when_every_result_is_cached(tmp_path):
    prof = PROFILES["quick"]
    ctx = Context(tmp_path, prof)
    ctx.workers = 1
    scenarios = [ctx.scenario("paper_p12.toml", ["tau_cap=7", f"p={p}"]) for p in (0.8, 0.9)]
    steps = [Step(sc, ("greedy",), True) for sc in scenarios]
    assert not any(ctx._cached(s) for s in steps)
    _numbers_cached = [(ctx.solve(sc), ctx.static_search(sc), ctx.evaluate(sc, "greedy")) for sc in scenarios]
    assert _numbers_cached and all(ctx._cached(s) for s in steps)
    ctx.workers = 2
    ctx.prefetch(steps)
    assert ctx._pool is None  # no worker started


def test_a_worker_on_other_source_computes_nothing(tmp_path):
    prof = PROFILES["quick"]
    ctx = Context(tmp_path, prof)
    step = Step(ctx.scenario("paper_p12.toml", ["tau_cap=7"]), ("greedy",))
    assert _run_step(tmp_path, prof, step, "edited since the run started") is False
    assert not list((tmp_path / "cache").glob("*.json"))  # nothing stored under keys the parent would not read
    assert _run_step(tmp_path, prof, step, code_version()) is True
    assert ctx._cached(step)


def _record_pid(ctx: Context, tag: str):
    """A cached step that records which process computed it (for prefetch_calls)."""
    import os

    return ctx.cache.get_or_compute("pid", {"tag": tag}, lambda: ({"pid": os.getpid()}, None))[0]["pid"]


def test_prefetch_calls_compute_the_steps_in_workers(tmp_path):
    import os

    ctx = Context(tmp_path, PROFILES["quick"])
    try:
        ctx.prefetch_calls(_record_pid, [("a",), ("b",)])
    finally:
        ctx.close()
    pids = [_record_pid(ctx, t) for t in ("a", "b")]  # read from the cache
    assert ctx.cache.misses == 0 and os.getpid() not in pids
    ctx.prefetch_calls(_record_pid, [("c",)])  # a single call is not worth a worker: left to the caller
    assert ctx._pool is None and _record_pid(ctx, "c") == os.getpid()
