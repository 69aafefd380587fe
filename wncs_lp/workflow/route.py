"""The one route from a scenario to a solution: size guard -> build -> solve.

Every command and library function that solves a scenario goes through :func:`solve_scenario`
(``wncs-lp solve``, ``map``, ``verify``, ``evaluate`` / ``simulate`` / ``sweep`` through the policy
factory, ``capstudy``, :func:`wncs_lp.solve` on a scenario, the reproduction). It

1. reads the method's row in the registry (:data:`wncs_lp.methods.TABLE`, or
   :data:`~wncs_lp.methods.CONSTRAINED` when the scenario's ``[[constraint]]`` tables are solved);
2. runs a scenario method (``matrix-free``) on the scenario, without building anything (its
   function registered in :data:`wncs_lp.solvers.registry.AVERAGE`);
3. otherwise builds the MDP after the size guard, counting the memory the method needs (its
   memory model: the stored matrix, plus an interior-point LP for the LP methods);
4. when the guard refuses the stored matrix and the method names a fallback (``auto``: the
   matrix-free solver), solves by the fallback instead and says why; a refusal stands for a
   method without one, for a constrained solve, and when the caller needs the MDP;
5. solves the MDP with the method (:func:`wncs_lp.solvers.solve`, or
   :func:`wncs_lp.constrained.solve_constrained`; its warm start and ``threads`` passed when it
   takes them).

It returns a :class:`~wncs_lp.solvers.route.ScenarioSolve`: the solution with what was built and why.
It lives on the workflow floor because it calls both the solvers and the constrained solvers,
which build on the solvers.
"""
from __future__ import annotations

import time
from typing import Any, Callable

from ..constrained import solve_constrained
from ..errors import SolverError
from ..mdp import MDP
from ..methods import DEFAULT_METHOD, SCENARIO_INPUT, TABLE, Entry
from ..progress import Progress, as_progress
from ..solvers import solve
from ..solvers.registry import AVERAGE
from ..solvers.route import ScenarioSolve, WarmStart, as_scenario, build_scenario, scenario_row

__all__ = ["solve_any", "solve_scenario"]


def solve_any(problem: Any, method: str = DEFAULT_METHOD, **kw: Any) -> Any:
    """What :func:`wncs_lp.solve` runs: an MDP by :func:`wncs_lp.solvers.solve`, a scenario (or its
    file, or a shipped scenario's name) by :func:`solve_scenario`, whose solution is returned."""
    if isinstance(problem, MDP):
        return solve(problem, method, **kw)
    return solve_scenario(problem, method, **kw).solution


def solve_scenario(
    scenario: Any,
    method: str = DEFAULT_METHOD,
    *,
    constrained: bool | None = None,
    force: bool = False,
    threads: int | None = None,
    progress: bool | Progress | None = None,
    mdp: MDP | None = None,
    need_mdp: bool = False,
    warm: WarmStart | None = None,
    check: Callable[[MDP], Any] | None = None,
    **kw: Any,
) -> ScenarioSolve:
    """Solve a scenario by name of method: size guard, build, solve (module docstring).

    Parameters
    ----------
    scenario : Scenario, path or str
        A scenario, its TOML file, or a shipped scenario's name (``"paper_p12"``).
    method : str
        A name of :data:`wncs_lp.methods.TABLE` (of :data:`~wncs_lp.methods.CONSTRAINED` for a
        constrained solve); default ``"auto"``.
    constrained : bool, optional
        Solve the scenario's ``[[constraint]]`` tables: by default when it has some; False
        solves the unconstrained problem (``--ignore-constraints``).
    force : bool
        Build (or sweep the box) even when the size guard refuses.
    threads : int, optional
        Kernel threads, for the methods that take them (default: the solver's).
    progress : bool or Progress
        The phases and the solver's progress on stderr.
    mdp : MDP, optional
        The scenario's MDP, already built (the guard and the build are skipped).
    need_mdp : bool
        The caller needs the MDP: a scenario method then runs on the built MDP, and a refusal
        of the guard is never answered by the matrix-free fallback.
    warm : WarmStart, optional
        A previous solution on the same state space to start from (:meth:`ScenarioSolve.warm`).
    check : callable, optional
        Called with the MDP before the solve (the caller's own arguments checked against it
        before the time is spent).
    **kw
        The method's own keywords (``tol``, ``max_iter``, ...); a keyword it does not take is
        one :class:`SolverError` naming those it does.

    Returns
    -------
    ScenarioSolve

    Raises
    ------
    SolverError
        An unknown method, or one that does not solve this kind of problem (the message lists
        those that do), a keyword it does not take, or a solver failure.
    SizeLimitError
        The guard refuses the stored matrix and the method has no fallback.
    """
    t0 = time.perf_counter()
    scenario = as_scenario(scenario)
    constrained = bool(scenario.constraints) if constrained is None else bool(constrained)
    row = scenario_row(method, constrained)
    prog = as_progress(progress)
    if row.takes == SCENARIO_INPUT and mdp is None and not need_mdp:
        return _without_matrix(scenario, AVERAGE[row.name], row.name, "asked for", t0, force, threads, prog, kw)
    build_seconds = 0.0
    if mdp is None:
        from ..models.guard import SizeLimitError

        offer = tuple(TABLE.values()) if not (constrained or need_mdp) else None  # the caller takes matrix-free
        try:
            mdp, build_seconds = build_scenario(scenario, method, constrained=constrained, force=force, progress=prog,
                                                offer=offer)
        except SizeLimitError as refused:
            if row.fallback is None or constrained or need_mdp:
                raise
            why = f"{row.name}: the stored matrix would not fit in memory"
            try:
                return _without_matrix(scenario, AVERAGE[row.fallback], row.name, why, t0, force, threads, prog, kw)
            except SolverError:  # not a model the fallback takes: the guard's refusal stands
                raise refused from None
    if check is not None:
        check(mdp)
    if constrained:
        prog.phase(f"solving the constrained problem ({len(scenario.constraints)} bound(s)) with method {method}")
        sol = solve_constrained(mdp, scenario.constraints, method, **kw)
        return ScenarioSolve(sol, mdp, sol.method, method, constrained=True, build_seconds=build_seconds,
                             seconds=time.perf_counter() - t0)
    extra = warm.keywords(mdp, row) if warm is not None else {}
    if threads is not None and AVERAGE[row.name].takes_keyword("threads", on_mdp=True):
        extra["threads"] = threads
    prog.phase(f"solving with method {method}")
    sol = solve(mdp, method, progress=prog, **extra, **kw)
    return ScenarioSolve(sol, mdp, method, method, build_seconds=build_seconds, seconds=time.perf_counter() - t0,
                         warm_start=bool(set(extra) - {"threads"}))


def _without_matrix(scenario: Any, found: Entry, requested: str, why: str, t0: float, force: bool,
                    threads: int | None, prog: Progress, kw: dict[str, Any]) -> ScenarioSolve:
    """A scenario method on the scenario itself: nothing is built."""
    extra = dict(kw)
    if threads is not None and found.takes_keyword("threads"):
        extra["threads"] = threads
    if force:
        extra["force"] = True
    prog.phase(f"solving without a stored matrix ({why})")
    sol = found.call(scenario, progress=bool(prog.enabled), **extra)
    return ScenarioSolve(sol, None, found.row.name, requested, route=why, seconds=time.perf_counter() - t0)
