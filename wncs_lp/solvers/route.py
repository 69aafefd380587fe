"""The one route from a scenario to a solution: size guard -> build -> solve.

Every command and library function that solves a scenario goes through :func:`solve_scenario`
(``wncs-lp solve``, ``map``, ``verify``, ``evaluate`` / ``simulate`` / ``sweep`` through the policy
factory, ``capstudy``, :func:`wncs_lp.solve` on a scenario, the reproduction). It

1. reads the method's row in the registry (:data:`wncs_lp.methods.TABLE`, or
   :data:`~wncs_lp.methods.CONSTRAINED` when the scenario's ``[[constraint]]`` tables are solved);
2. runs a scenario method (``matrix-free``) on the scenario, without building anything;
3. otherwise builds the MDP after the size guard, counting the memory the method needs (its
   memory model: the stored matrix, plus an interior-point LP for the LP methods);
4. when the guard refuses the stored matrix and the method names a fallback (``auto``: the
   matrix-free solver), solves by the fallback instead and says why; a refusal stands for a
   method without one, for a constrained solve, and when the caller needs the MDP;
5. solves the MDP with the method (its warm start and ``threads`` passed when it takes them).

It returns a :class:`ScenarioSolve`: the solution with what was built and why.
"""
from __future__ import annotations

import hashlib
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

from ..errors import SolverError
from ..mdp import MDP
from ..methods import (BIAS, CONSTRAINED, DEFAULT_METHOD, POLICY, SCENARIO_INPUT, SOLVE, SOLVE_CONSTRAINED,
                       STORED_LP, TABLE, Method, resolve)
from ..progress import Progress, as_progress

__all__ = ["ScenarioSolve", "WarmStart", "solve_scenario", "build_scenario", "as_scenario", "space_key"]


def space_key(mdp: MDP) -> str:
    """A digest of an MDP's state numbering (configurations and the (C, tau) -> state lookup)."""
    h = hashlib.sha1(repr(list(mdp.states.configs)).encode())
    h.update(np.ascontiguousarray(mdp.states.lookup).tobytes())
    return h.hexdigest()


@dataclass(frozen=True, eq=False)
class WarmStart:
    """What a solve hands on to the next solve of a neighbouring scenario (a sweep's next value).

    Used only when the next MDP numbers its states the same way (``space``, ``n_pairs``), in the
    form the next method takes (its registry row's ``warm_start``: the bias as ``h0``, or the
    policy as ``policy0``).
    """

    space: str
    n_pairs: int
    bias: np.ndarray
    policy: np.ndarray

    @classmethod
    def of(cls, mdp: MDP, solution: Any) -> "WarmStart":
        return cls(space_key(mdp), int(mdp.n_pairs), np.asarray(solution.bias), np.asarray(solution.policy))

    def keywords(self, mdp: MDP, row: Method) -> dict[str, Any]:
        """The warm-start keyword of ``row`` on ``mdp`` (empty when the state spaces differ)."""
        if self.n_pairs != mdp.n_pairs or self.space != space_key(mdp):
            return {}
        if row.warm_start == BIAS:
            return {"h0": self.bias}
        if row.warm_start == POLICY:
            return {"policy0": self.policy}
        return {}


@dataclass(frozen=True, eq=False)
class ScenarioSolve:
    """A scenario's solution and how it was reached.

    Attributes
    ----------
    solution : Solution, MatrixFreeSolution or ConstrainedSolution
    mdp : MDP or None
        The MDP that was built (None on the matrix-free route: nothing was).
    method : str
        The method that ran (``matrix-free`` when ``auto`` fell back to it).
    requested : str
        The method asked for.
    route : str
        Why this method ran: ``"asked for"``, or the fallback's reason
        (``"auto: the stored matrix would not fit in memory"``).
    constrained : bool
        The scenario's ``[[constraint]]`` tables were solved.
    build_seconds, seconds : float
        The build alone, and the whole route (guard, build and solve).
    warm_start : bool
        The solve started from a previous solution (:class:`WarmStart`).
    """

    solution: Any
    mdp: MDP | None
    method: str
    requested: str
    route: str = "asked for"
    constrained: bool = False
    build_seconds: float = 0.0
    seconds: float = 0.0
    warm_start: bool = False

    @property
    def ok(self) -> bool:
        return bool(self.solution.ok)

    @property
    def gain(self) -> float:
        return float(self.solution.gain)

    @property
    def built(self) -> bool:
        """An MDP was built (False on the matrix-free route)."""
        return self.mdp is not None

    def warm(self) -> WarmStart | None:
        """The warm start this solve hands on (None without an MDP)."""
        return None if self.mdp is None else WarmStart.of(self.mdp, self.solution)

    def __repr__(self) -> str:
        size = f"{self.mdp.n_states:,} states" if self.mdp is not None else "no MDP built"
        via = self.method if self.method == self.requested else f"{self.requested} -> {self.method}"
        return (f"ScenarioSolve({via} ({self.route}), {size}, status {self.solution.status!r}, gain "
                f"{self.gain:.10g}, build {self.build_seconds:.2f} s, total {self.seconds:.2f} s)")


def as_scenario(scenario: Any) -> Any:
    """A :class:`~wncs_lp.scenario.Scenario` from itself, a scenario file or a shipped scenario's
    name (``"paper_p12"``); anything else is one :class:`SolverError` naming its type."""
    from ..scenario import Scenario, load_scenario

    if isinstance(scenario, Scenario):
        return scenario
    if isinstance(scenario, (str, Path)):
        path = Path(scenario)
        if not path.exists() and isinstance(scenario, str) and "/" not in scenario:
            from ..formulations import scenario_names, scenario_path

            if scenario in scenario_names() or f"{scenario}.toml" in scenario_names():
                path = scenario_path(scenario)
        return load_scenario(path)
    raise SolverError(f"expected an MDP, a Scenario, a scenario file or a shipped scenario's name; got "
                      f"{type(scenario).__name__}")


def _row(method: str, constrained: bool) -> Method:
    table = CONSTRAINED if constrained else TABLE
    if method not in table:
        what = "a scenario with [[constraint]] tables" if constrained else "an unconstrained scenario"
        raise SolverError(f"method {method!r} does not solve {what}; expected one of {', '.join(table)}")
    return table[method]


def build_scenario(scenario: Any, method: str | None = None, *, constrained: bool = False, force: bool = False,
                   progress: bool | Progress | None = None, offer: tuple[Method, ...] | None = None
                   ) -> tuple[MDP, float]:
    """The scenario's MDP after the size guard, counting the memory ``method`` needs (an
    interior-point LP's too for the LP methods; the stored matrix alone without a method);
    returns ``(mdp, build seconds)``.

    ``offer``: the methods a refusal may suggest instead (default: those of the table that
    solve a built MDP, the constrained ones for ``constrained``).

    Warns
    -----
    ScenarioWarning
        A degenerate scenario (as :func:`wncs_lp.build` does).

    Raises
    ------
    SizeLimitError
        The estimate exceeds the limit and ``force`` is False.
    """
    import warnings

    from ..errors import ScenarioWarning
    from ..models import guard

    for text in scenario.degenerate_warnings():
        warnings.warn(text, ScenarioWarning, stacklevel=3)

    prog = as_progress(progress)
    row = _row(method, constrained) if method is not None else None
    # the LP's memory on the backend the method names (Clarabel unless it says otherwise)
    need_lp = dict(row.preset).get("backend", "clarabel") if row is not None and row.memory == STORED_LP else False
    if offer is None:
        offer = tuple(m for m in (CONSTRAINED if constrained else TABLE).values() if m.takes != SCENARIO_INPUT)
    t0 = time.perf_counter()
    prog.phase(f"building the MDP of {scenario.source} (size guard first{', LP memory included' if need_lp else ''})")
    mdp = guard.build_checked(scenario, force=force, need_lp=need_lp, offer=offer)
    seconds = time.perf_counter() - t0
    prog.phase(f"built: {mdp.n_states:,} states, {mdp.n_pairs:,} state-action pairs, {mdp.P.nnz:,} transitions "
               f"in {seconds:.2f} s")
    return mdp, seconds


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
    row = _row(method, constrained)
    prog = as_progress(progress)
    if row.takes == SCENARIO_INPUT and mdp is None and not need_mdp:
        return _without_matrix(scenario, row, row.name, "asked for", t0, force, threads, prog, kw)
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
                return _without_matrix(scenario, TABLE[row.fallback], row.name, why, t0, force, threads, prog, kw)
            except SolverError:  # not a model the fallback takes: the guard's refusal stands
                raise refused from None
    if check is not None:
        check(mdp)
    if constrained:
        prog.phase(f"solving the constrained problem ({len(scenario.constraints)} bound(s)) with method {method}")
        sol = resolve(SOLVE_CONSTRAINED)(mdp, scenario.constraints, method, **kw)
        return ScenarioSolve(sol, mdp, sol.method, method, constrained=True, build_seconds=build_seconds,
                             seconds=time.perf_counter() - t0)
    extra = warm.keywords(mdp, row) if warm is not None else {}
    if threads is not None and row.takes_keyword("threads", on_mdp=True):
        extra["threads"] = threads
    prog.phase(f"solving with method {method}")
    sol = resolve(SOLVE)(mdp, method, progress=prog, **extra, **kw)
    return ScenarioSolve(sol, mdp, method, method, build_seconds=build_seconds, seconds=time.perf_counter() - t0,
                         warm_start=bool(set(extra) - {"threads"}))


def _without_matrix(scenario: Any, row: Method, requested: str, why: str, t0: float, force: bool,
                    threads: int | None, prog: Progress, kw: dict[str, Any]) -> ScenarioSolve:
    """A scenario method on the scenario itself: nothing is built."""
    extra = dict(kw)
    if threads is not None and row.takes_keyword("threads"):
        extra["threads"] = threads
    if force:
        extra["force"] = True
    prog.phase(f"solving without a stored matrix ({why})")
    sol = row.call(scenario, progress=bool(prog.enabled), **extra)
    return ScenarioSolve(sol, None, row.name, requested, route=why, seconds=time.perf_counter() - t0)
