"""The steps of the scenario route that need no solver: the size guard and the build
(:func:`build_scenario`), a scenario read from a file or a name (:func:`as_scenario`), the row of
a method for a scenario (:func:`scenario_row`), and what a solve hands on (:class:`ScenarioSolve`,
:class:`WarmStart`).

The route itself, :func:`wncs_lp.workflow.route.run_scenario` (size guard -> build -> solve, and
``auto``'s fallback to the matrix-free solver), lives on the workflow floor above the solvers and
the constrained solvers, which it calls.
"""
from __future__ import annotations

import hashlib
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .. import methods, moved
from ..errors import SolverError
from ..mdp import MDP
from ..methods import BIAS, CONSTRAINED, POLICY, SCENARIO_INPUT, STORED_LP, TABLE, Method
from ..progress import Progress, as_progress

__all__ = ["ScenarioSolve", "WarmStart", "build_scenario", "as_scenario", "scenario_row", "space_key"]


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
    solution : Solution, MatrixFreeSolution, ConstrainedSolution or DiscountedSolution
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
        value = (f"gain {self.gain:.10g}" if hasattr(self.solution, "gain")
                 else f"discounted, beta {self.solution.beta:g}")
        return (f"ScenarioSolve({via} ({self.route}), {size}, status {self.solution.status!r}, {value}, "
                f"build {self.build_seconds:.2f} s, total {self.seconds:.2f} s)")


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


def scenario_row(method: str, constrained: bool) -> Method:
    """The registry row of ``method`` for a scenario solved with (``constrained``) or without its
    ``[[constraint]]`` tables (:func:`wncs_lp.methods.method`: the one validator)."""
    what = "a scenario with [[constraint]] tables" if constrained else "an unconstrained scenario"
    return methods.method(method, constrained=constrained, problem=what)


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
    row = scenario_row(method, constrained) if method is not None else None
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


#: Names that moved or were replaced: found here for one release, with a warning (:mod:`wncs_lp.moved`).
__getattr__ = moved.old_names(__name__)
