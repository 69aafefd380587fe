"""The one public :func:`solve`, and the one route from a scenario to a solution: size guard ->
build -> solve.

:func:`solve` (``wncs_lp.solve``) takes an MDP, a scenario, its file or a shipped scenario's name,
a ``method`` and a criterion, and runs one step for what it was given, each imported here and
each dispatching through its registry of functions:

* a scenario (any criterion): :func:`run_scenario` below, which ends in one of the three;
* an MDP, average cost: :func:`~wncs_lp.solvers.registry.run_average`;
* an MDP under constraints: :func:`~wncs_lp.constrained.registry.run_constrained`;
* an MDP, discounted: :func:`~wncs_lp.solvers.discounted.run_discounted`.

Every command and library function that solves a scenario goes through :func:`run_scenario`
(``wncs-lp solve``, ``--discount`` included, ``map``, ``verify``, ``evaluate`` / ``simulate`` /
``sweep`` through the policy factory, ``capstudy``, :func:`solve` on a scenario, the
reproduction). It

1. reads the method's row in the registry (:data:`wncs_lp.methods.TABLE`,
   :data:`~wncs_lp.methods.CONSTRAINED` when the scenario's ``[[constraint]]`` tables are solved,
   :data:`~wncs_lp.methods.DISCOUNTED` for a discount factor);
2. runs a scenario method (``matrix-free``) on the scenario, without building anything (its
   function registered in :data:`wncs_lp.solvers.registry.AVERAGE`);
3. otherwise builds the MDP after the size guard, counting the memory the method needs (its
   memory model: the stored matrix, plus an interior-point LP for the LP methods);
4. when the guard refuses the stored matrix and the method names a fallback (``auto``: the
   matrix-free solver), solves by the fallback instead and says why; a refusal stands for a
   method without one, for a constrained or discounted solve, and when the caller needs the MDP;
5. solves the MDP with the method's step (above; its warm start and ``threads`` passed when it
   takes them).

It returns a :class:`~wncs_lp.solvers.route.ScenarioSolve`: the solution with what was built and why.
It lives on the workflow floor because it calls both the solvers and the constrained solvers,
which build on the solvers.
"""
from __future__ import annotations

import time
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Iterable

from .. import moved
from ..constrained.registry import run_constrained
from ..errors import SolverError
from ..mdp import MDP
from ..methods import (AVERAGE as AVERAGE_COST, CONSTRAINED_CRITERION, DEFAULT_METHOD, DISCOUNTED_CRITERION,
                       SCENARIO_INPUT, TABLE, Entry, Method, check_criterion, discounted_method)
from ..progress import Progress, as_progress
from ..solvers.discounted import check_discount, run_discounted
from ..solvers.registry import AVERAGE, run_average
from ..solvers.route import ScenarioSolve, WarmStart, as_scenario, build_scenario, scenario_row

if TYPE_CHECKING:  # pragma: no cover
    from ..constrained.result import ConstrainedSolution
    from ..scenario import Scenario
    from ..solvers.discounted import DiscountedSolution
    from ..solvers.matrix_free.result import MatrixFreeSolution
    from ..solvers.result import Solution

__all__ = ["solve", "run_scenario"]


def solve(problem: MDP | Scenario | str | Path, method: str = DEFAULT_METHOD, *, criterion: str | None = None,
          discount: float | None = None, constraints: Iterable[Any] | None = None,
          **kwargs: Any) -> Solution | MatrixFreeSolution | ConstrainedSolution | DiscountedSolution:
    """Solve an MDP or a scenario: the average cost (default), under constraints, or discounted.

    Parameters
    ----------
    problem : MDP, Scenario, path or str
        An MDP (``wncs_lp.build(scenario)``), or a scenario, its TOML file or a shipped
        scenario's name (``"paper_p12"``), solved by the one route of the command line
        (:func:`run_scenario`: size guard, build, solve; ``auto`` solves without a stored
        matrix when that matrix would not fit).
    method : str
        A name of the criterion's table in :mod:`wncs_lp.methods`, default ``"auto"``. Average
        cost: ``auto`` (the LP on small models, certified value iteration above, cross-checked
        when both are cheap; ``stats["auto_choice"]`` says which), ``lp``, ``lp-highs``,
        ``lp-cvxpy``, ``vi``, ``rvi``, ``pi``, ``matrix-free``. Constrained: ``auto``, ``lp``,
        ``lp-highs``, ``lp-cvxpy``, ``lagrangian``. Discounted: ``pi``, ``vi``, ``lp``, or a name
        of the average-cost table read as :data:`wncs_lp.methods.DISCOUNTED_FOR` says (``auto``
        is policy iteration).
    criterion : {"average", "constrained", "discounted"}, optional
        By default from the arguments: ``"discounted"`` with ``discount``, ``"constrained"``
        with ``constraints`` or on a scenario with ``[[constraint]]`` tables (as ``wncs-lp
        solve`` does), else ``"average"``. ``"average"`` on a scenario with such tables solves
        it without them (``--ignore-constraints``).
    discount : float, optional
        The discount factor beta in [0, 1) of the discounted criterion (certified by MacQueen's
        bounds: :mod:`wncs_lp.solvers.discounted`).
    constraints : iterable of ConstraintSpec or LinearConstraint, optional
        The bounds of the constrained criterion (a scenario's own ``[[constraint]]`` tables by
        default; given here, they replace them).
    **kwargs
        The method's keywords (and, for a scenario, the route's: ``force``, ``threads``,
        ``progress``; see :func:`run_scenario`). Every average-cost method takes ``tol`` (the
        accuracy asked for: the relative certificate width; for ``lp``/``lp-cvxpy`` the solver's
        tolerance, the certificate being checked at ``cert_rtol``) and ``progress``; see the
        method's function for the rest. A keyword the method does not take raises a
        :class:`SolverError` naming the ones it does.

    Returns
    -------
    Solution, MatrixFreeSolution, ConstrainedSolution or DiscountedSolution
        A :class:`~wncs_lp.solvers.result.Solution` has ``sigma`` (the action per state) and
        ``chain(mdp)`` (the induced Markov chain); a scenario solved without a stored matrix gives
        a ``MatrixFreeSolution``, a constrained solve a ``ConstrainedSolution``, a discounted one
        a ``DiscountedSolution``. Each carries its certificate.

    Raises
    ------
    SolverError
        ``problem`` is none of the above (the message names its type), an unknown criterion,
        method or keyword, a criterion without its argument (``discount``, ``constraints`` on an
        MDP), or a solver failure.
    """
    if not isinstance(problem, MDP):
        return run_scenario(problem, method, criterion=criterion, discount=discount, constraints=constraints,
                            **kwargs).solution
    criterion = _criterion(criterion, discount, constraints, bool(constraints))
    if criterion == DISCOUNTED_CRITERION:
        return run_discounted(problem, discount, discounted_method(method).name, **kwargs)
    if criterion == CONSTRAINED_CRITERION:
        if constraints is None:
            raise SolverError("criterion 'constrained' on an MDP needs its bounds: constraints=[...] "
                              "(a scenario's [[constraint]] tables are read from the scenario)")
        return run_constrained(problem, constraints, method, **kwargs)
    return run_average(problem, method, **kwargs)


def _criterion(criterion: str | None, discount: float | None, constraints: Any, has_tables: bool) -> str:
    """The criterion asked for, explicitly or by its argument (:func:`solve`'s ``criterion``)."""
    if criterion is not None:
        criterion = check_criterion(criterion)
    if discount is not None and criterion not in (None, DISCOUNTED_CRITERION):
        raise SolverError(f"discount={discount!r} is the discounted criterion's; criterion {criterion!r} takes none")
    if discount is None and criterion == DISCOUNTED_CRITERION:
        raise SolverError("criterion 'discounted' needs its discount factor: discount=beta in [0, 1)")
    if constraints is not None and criterion not in (None, CONSTRAINED_CRITERION):
        raise SolverError(f"constraints= are the constrained criterion's; criterion {criterion!r} takes none")
    if criterion is not None:
        return criterion
    if discount is not None:
        return DISCOUNTED_CRITERION
    return CONSTRAINED_CRITERION if constraints is not None or has_tables else AVERAGE_COST


def run_scenario(
    scenario: Any,
    method: str = DEFAULT_METHOD,
    *,
    criterion: str | None = None,
    discount: float | None = None,
    constraints: Iterable[Any] | None = None,
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
        constrained solve, of :data:`~wncs_lp.methods.DISCOUNTED` or
        :data:`~wncs_lp.methods.DISCOUNTED_FOR` for a discounted one); default ``"auto"``.
    criterion, discount, constraints
        As :func:`solve` takes them. A discounted solve of a scenario with ``[[constraint]]``
        tables is refused unless ``constrained=False`` says to solve it without them.
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
    tables = bool(scenario.constraints) if constrained is None else bool(constrained)
    criterion = _criterion(criterion, discount, constraints, tables)
    prog = as_progress(progress)
    if criterion == DISCOUNTED_CRITERION:
        if tables and constrained is not False:
            raise SolverError(f"{scenario.source}: the discounted criterion solves the unconstrained problem, and this "
                              "scenario has [[constraint]] tables; solve it without them with constrained=False "
                              "(--ignore-constraints)")
        return _discounted(scenario, method, discount, t0, force, prog, mdp, check, kw)
    constrained = criterion == CONSTRAINED_CRITERION
    row = scenario_row(method, constrained)
    if row.takes == SCENARIO_INPUT and mdp is None and not need_mdp:
        return _without_matrix(scenario, AVERAGE[row.name], row.name, "asked for", t0, force, threads, prog, kw)
    build_seconds = 0.0
    if mdp is None:
        mdp, build_seconds, fallen = _build(scenario, row, constrained, need_mdp, t0, force, threads, prog, kw)
        if fallen is not None:
            return fallen
    if check is not None:
        check(mdp)
    if constrained:
        bounds = list(scenario.constraints if constraints is None else constraints)
        prog.phase(f"solving the constrained problem ({len(bounds)} bound(s)) with method {method}")
        sol = run_constrained(mdp, bounds, method, **kw)
        return ScenarioSolve(sol, mdp, sol.method, method, constrained=True, build_seconds=build_seconds,
                             seconds=time.perf_counter() - t0)
    return _average(mdp, row, warm, threads, prog, kw, t0, build_seconds)


def _build(scenario: Any, row: Method, constrained: bool, need_mdp: bool, t0: float, force: bool,
           threads: int | None, prog: Progress, kw: dict[str, Any]) -> tuple[MDP | None, float, ScenarioSolve | None]:
    """The MDP after the size guard and its build seconds; or, when the guard refuses the stored
    matrix and the method names a fallback the caller takes, the fallback's solve instead."""
    from ..models.guard import SizeLimitError

    offer = tuple(TABLE.values()) if not (constrained or need_mdp) else None  # the caller takes matrix-free
    try:
        mdp, seconds = build_scenario(scenario, row.name, constrained=constrained, force=force, progress=prog,
                                      offer=offer)
        return mdp, seconds, None
    except SizeLimitError as refused:
        if row.fallback is None or constrained or need_mdp:
            raise
        why = f"{row.name}: the stored matrix would not fit in memory"
        try:
            return None, 0.0, _without_matrix(scenario, AVERAGE[row.fallback], row.name, why, t0, force, threads,
                                              prog, kw)
        except SolverError:  # not a model the fallback takes: the guard's refusal stands
            raise refused from None


def _average(mdp: MDP, row: Method, warm: WarmStart | None, threads: int | None, prog: Progress,
             kw: dict[str, Any], t0: float, build_seconds: float) -> ScenarioSolve:
    """The average-cost step on the built MDP, with the warm start and the threads its method takes."""
    extra = warm.keywords(mdp, row) if warm is not None else {}
    if threads is not None and AVERAGE[row.name].takes_keyword("threads", on_mdp=True):
        extra["threads"] = threads
    prog.phase(f"solving with method {row.name}")
    sol = run_average(mdp, row.name, progress=prog, **extra, **kw)
    return ScenarioSolve(sol, mdp, row.name, row.name, build_seconds=build_seconds, seconds=time.perf_counter() - t0,
                         warm_start=bool(set(extra) - {"threads"}))


def _discounted(scenario: Any, method: str, discount: float, t0: float, force: bool, prog: Progress,
                mdp: MDP | None, check: Callable[[MDP], Any] | None, kw: dict[str, Any]) -> ScenarioSolve:
    """The discounted criterion on a scenario: its method and discount factor checked, then the
    stored matrix built after the size guard and solved (no fallback: every discounted method
    needs the matrix)."""
    row = discounted_method(method)
    beta = check_discount(discount)
    build_seconds = 0.0
    if mdp is None:
        mdp, build_seconds = build_scenario(scenario, force=force, progress=prog)
    if check is not None:
        check(mdp)
    prog.phase(f"solving the discounted problem (beta = {beta:g}) with method {row.name}")
    sol = run_discounted(mdp, beta, row.name, **kw)
    return ScenarioSolve(sol, mdp, row.name, method, build_seconds=build_seconds, seconds=time.perf_counter() - t0)


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


#: Names that moved or were replaced: found here for one release, with a warning (:mod:`wncs_lp.moved`).
__getattr__ = moved.old_names(__name__)
