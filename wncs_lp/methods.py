"""The method registry: every solve method in one table (like cvxpy's solver map).

One row per method: its name, its criterion (average cost, or average cost under constraints),
its representation (what it takes: a stored MDP, or the scenario's AoI box without a matrix), the
keywords it fixes, the warm start it takes from a previous solution, what the size guard counts
for it (its memory model), the method it falls back to when the guard refuses the stored matrix,
and its help text. This module is the vocabulary alone: it imports nothing numeric, so the
command line builds its parser from it without loading numpy. The function that runs each row is
registered beside the dispatcher that calls it, imported normally (an :class:`Entry`:
:data:`wncs_lp.solvers.registry.AVERAGE` for :func:`~wncs_lp.solvers.registry.run_average`,
:data:`wncs_lp.constrained.registry.CONSTRAINED_ENTRIES` for
:func:`~wncs_lp.constrained.registry.run_constrained`,
:data:`wncs_lp.solvers.discounted.DISCOUNTED_ENTRIES` for
:func:`~wncs_lp.solvers.discounted.run_discounted`: the steps of :func:`wncs_lp.solve`), and
:func:`method` is the one validator of a method name (:func:`discounted_method` reads a name for
the discounted criterion). Every command (``solve``, ``evaluate``, ``simulate``, ``sweep``,
``verify``, ``map``, ``capstudy``, ``tradeoff``) and every library entry
point that takes a ``method`` (:func:`wncs_lp.solve` and its steps,
:func:`wncs_lp.workflow.make_policy`, :func:`wncs_lp.workflow.policy_for`,
:func:`wncs_lp.studies.run_sweep`, :func:`wncs_lp.studies.cap_study`,
:func:`wncs_lp.studies.tradeoff`) reads its vocabulary and default (``"auto"``) from here:

=================  ==========================================================================
``auto``           the LP on small models (at most 6,000 pairs), certified value iteration
                   above; both run and are compared when both are cheap (at most 30,000
                   pairs). ``stats["auto_choice"]`` says whose answer it is. On a scenario
                   whose stored matrix would not fit in memory: ``matrix-free``.
``lp``             the occupation-measure LP on Clarabel (direct), its policy polished and
                   exactly evaluated.
``lp-highs``       the same LP on HiGHS (simplex or interior point + crossover, by the LP's
                   shape).
``lp-cvxpy``       the same LP built with cvxpy.
``vi``             certified value iteration (Gauss-Seidel modified policy iteration on the
                   numba kernel, Jacobi relative value iteration without numba).
``rvi``            relative value iteration with the aperiodicity transform.
``pi``             Howard policy iteration with exact (sparse) evaluation.
``matrix-free``    certified value iteration over the AoI box without a stored matrix (a
                   scenario, or an MDP built from one).
=================  ==========================================================================

Every method returns the same certificate ``gain_lower <= g* <= gain_upper`` and takes ``tol``
(the accuracy asked for) and ``progress``; a keyword a method does not take is one
:class:`~wncs_lp.errors.SolverError` naming those it does (:meth:`Method.check_keywords`).

A scenario with ``[[constraint]]`` tables is solved by the methods of :data:`CONSTRAINED`
(``auto``, ``lp``, ``lp-highs``, ``lp-cvxpy``, ``lagrangian``): the same names where they mean
the same LP, one table of their own because their functions take the constraints too. The
discounted criterion has its table too, :data:`DISCOUNTED` (``pi``, ``vi``, ``lp``).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

__all__ = [
    "Method", "TABLE", "CONSTRAINED", "METHODS", "SCENARIO_METHODS", "CONSTRAINED_METHODS", "DEFAULT_METHOD",
    "LP_METHODS", "METHOD_HELP", "STORED", "STORED_LP", "BOX", "BIAS", "POLICY", "BASIS", "MDP_INPUT",
    "SCENARIO_INPUT", "AVERAGE", "CONSTRAINED_CRITERION", "DISCOUNTED_CRITERION", "DISCOUNTED", "DISCOUNTED_METHODS",
    "TABLES", "CRITERIA", "DISCOUNTED_FOR", "Entry", "method", "check_method", "check_criterion", "discounted_method",
    "memory_of",
    "exact_method", "EXACT_METHOD_MAX_STATES",
]

# ------------------------------------------------------------------ what the size guard counts
#: The stored transition matrix: the build's peak and the iteration's value vectors.
STORED = "stored"
#: The stored matrix and an interior-point LP's KKT factorisation.
STORED_LP = "stored+lp"
#: No matrix: one float64 value, one policy byte and one mask byte per state of the AoI box.
BOX = "box"

# ------------------------------------------------------------------ warm starts
#: ``h0`` = the previous solution's bias (value iteration, auto).
BIAS = "bias"
#: ``policy0`` = the previous solution's policy (policy iteration).
POLICY = "policy"
#: The previous LP's basis (a constrained LP kept in one HiGHS model, re-solved by dual simplex).
BASIS = "basis"

# ------------------------------------------------------------------ what a method takes
MDP_INPUT = "mdp"
SCENARIO_INPUT = "scenario"

# ------------------------------------------------------------------ criteria
#: The long-run average cost.
AVERAGE = "average"
#: The long-run average cost under bounds on other long-run averages (``[[constraint]]`` tables).
CONSTRAINED_CRITERION = "constrained"
#: The expected discounted cost with a discount factor beta in [0, 1).
DISCOUNTED_CRITERION = "discounted"


@dataclass(frozen=True)
class Method:
    """One solve method.

    Attributes
    ----------
    name : str
        As ``--method`` and ``method=`` spell it.
    help : str
        One line for ``--help``.
    takes : {"mdp", "scenario"}
        Its representation: a scenario method runs on the scenario's AoI box without building the
        MDP; on an MDP built from a scenario it runs its entry's ``on_mdp`` function.
    preset : tuple of (str, object)
        Keywords the name fixes (``lp-highs``: ``backend="highs"``).
    warm_start : {None, "bias", "policy", "basis"}
        What it takes from a previous solution on the same state space.
    memory : {"stored", "stored+lp", "box"}
        What the size guard counts (:func:`wncs_lp.models.guard.check_size`).
    fallback : str or None
        The method a scenario is solved by when the guard refuses this one's stored matrix.
    criterion : {"average", "constrained", "discounted"}
    hint : str
        How the size guard's message names the method when it suggests it as a cheaper route
        (empty: never suggested).
    """

    name: str
    help: str
    takes: str = MDP_INPUT
    preset: tuple[tuple[str, Any], ...] = ()
    warm_start: str | None = None
    memory: str = STORED
    fallback: str | None = None
    criterion: str = AVERAGE
    hint: str = ""

    @property
    def constrained(self) -> bool:
        return self.criterion == CONSTRAINED_CRITERION


@dataclass(frozen=True)
class Entry:
    """A registry row with the functions that run it (imported normally by the dispatcher's room).

    Attributes
    ----------
    row : Method
    run : callable or None
        ``run(mdp, **preset, **kw)`` (an MDP method), ``run(scenario_or_system, **kw)`` (a scenario
        method) or ``run(mdp, constraints, **preset, **kw)`` (a constrained one). None for a
        constrained ``auto``, which runs the method ``choose`` names.
    on_mdp : callable, optional
        A scenario method's function on an MDP built from a scenario.
    choose : callable, optional
        ``choose(mdp, constraints) -> method name`` (a constrained ``auto``).
    """

    row: Method
    run: Callable[..., Any] | None
    on_mdp: Callable[..., Any] | None = None
    choose: Callable[..., Any] | None = None

    def function(self, on_mdp: bool = False) -> Callable[..., Any]:
        """The function that runs the method (``on_mdp``: a scenario method's MDP form)."""
        return self.on_mdp if on_mdp and self.on_mdp is not None else self.run

    def keywords(self, on_mdp: bool = False) -> tuple[str, ...] | None:
        """The keywords the method takes (None: any, its function takes ``**kw``)."""
        import inspect

        params = inspect.signature(self.function(on_mdp)).parameters.values()
        if any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params):
            return None
        fixed = {k for k, _ in self.row.preset}
        return tuple(p.name for p in params if p.kind is inspect.Parameter.KEYWORD_ONLY and p.name not in fixed)

    def takes_keyword(self, name: str, on_mdp: bool = False) -> bool:
        taken = self.keywords(on_mdp)
        return taken is None or name in taken

    def check_keywords(self, kw: dict[str, Any], on_mdp: bool = False) -> None:
        """One clear :class:`~wncs_lp.errors.SolverError` for a keyword the method does not take."""
        taken = self.keywords(on_mdp) if kw else None
        bad = [k for k in kw if taken is not None and k not in taken]
        if bad:
            from .errors import SolverError

            raise SolverError(f"method {self.row.name!r} takes no keyword {bad[0]!r}; it takes {', '.join(taken)}")

    def call(self, subject: Any, *args: Any, on_mdp: bool = False, **kw: Any) -> Any:
        """Run the method on ``subject`` (after the keyword check)."""
        self.check_keywords(kw, on_mdp)
        return self.function(on_mdp)(subject, *args, **dict(self.row.preset), **kw)


#: The methods of an unconstrained solve, in the order the help lists them.
TABLE: dict[str, Method] = {m.name: m for m in (
    Method("auto",
           "default: the LP on small models, certified value iteration above, cross-checked when both are cheap; "
           "it says which it chose", warm_start=BIAS, fallback="matrix-free"),
    Method("lp", "occupation-measure LP on Clarabel", preset=(("backend", "clarabel"),), memory=STORED_LP),
    Method("lp-highs", "the same LP on HiGHS", preset=(("backend", "highs"),), memory=STORED_LP),
    Method("lp-cvxpy", "the same LP through cvxpy", preset=(("backend", "cvxpy"),), memory=STORED_LP),
    Method("vi", "certified value iteration", warm_start=BIAS),
    Method("rvi", "relative value iteration", warm_start=BIAS,
           hint="value iteration"),
    Method("pi", "policy iteration", warm_start=POLICY),
    Method("matrix-free", "certified value iteration without building the MDP", takes=SCENARIO_INPUT, memory=BOX,
           hint="the matrix-free solver"),
)}

#: The methods of a constrained solve (a scenario with ``[[constraint]]`` tables).
CONSTRAINED: dict[str, Method] = {m.name: m for m in (
    Method("auto", "the LP on HiGHS up to its size or with several bounds, the Lagrangian route beyond",
           criterion=CONSTRAINED_CRITERION),
    Method("lp", "the occupation-measure LP on Clarabel, then a crossover", preset=(("backend", "clarabel"),),
           memory=STORED_LP, warm_start=BASIS, criterion=CONSTRAINED_CRITERION),
    Method("lp-highs", "the same LP on HiGHS", memory=STORED_LP, warm_start=BASIS, criterion=CONSTRAINED_CRITERION),
    Method("lp-cvxpy", "the same LP through cvxpy", preset=(("backend", "cvxpy"),), memory=STORED_LP,
           criterion=CONSTRAINED_CRITERION),
    Method("lagrangian", "one bound: multiplier search with certified value iteration", criterion=CONSTRAINED_CRITERION,
           hint="the Lagrangian route"),
)}

#: The methods of the discounted criterion (``wncs_lp.solve(..., discount=beta)``).
DISCOUNTED: dict[str, Method] = {m.name: m for m in (
    Method("pi", "policy iteration with exact evaluation", criterion=DISCOUNTED_CRITERION),
    Method("vi", "value iteration, certified by MacQueen's bounds", criterion=DISCOUNTED_CRITERION),
    Method("lp", "the discounted LP on HiGHS", criterion=DISCOUNTED_CRITERION),
)}

#: The tables by criterion.
TABLES: dict[str, dict[str, Method]] = {AVERAGE: TABLE, CONSTRAINED_CRITERION: CONSTRAINED,
                                        DISCOUNTED_CRITERION: DISCOUNTED}

#: The criteria :func:`wncs_lp.solve` takes (``criterion=``), in the order the docs list them.
CRITERIA = (AVERAGE, DISCOUNTED_CRITERION, CONSTRAINED_CRITERION)

#: The discounted method each name of the average-cost vocabulary runs (``wncs-lp solve --discount``,
#: ``wncs_lp.solve(..., criterion="discounted")``): ``auto`` is policy iteration, value iteration
#: either kind of value iteration, every LP the discounted LP on HiGHS.
DISCOUNTED_FOR = {"auto": "pi", "pi": "pi", "vi": "vi", "rvi": "vi", "lp": "lp", "lp-highs": "lp", "lp-cvxpy": "lp"}

#: The methods every command and library function that solves an MDP takes, in help order.
METHODS = tuple(name for name, m in TABLE.items() if m.takes == MDP_INPUT)
#: The methods of a command that takes a scenario: :data:`METHODS` and the matrix-free solver.
SCENARIO_METHODS = tuple(TABLE)
#: The methods of a constrained solve.
CONSTRAINED_METHODS = tuple(CONSTRAINED)
#: The methods of a discounted solve.
DISCOUNTED_METHODS = tuple(DISCOUNTED)
#: The default of every command and library function that solves.
DEFAULT_METHOD = "auto"
#: The methods that solve an interior-point LP (the size guard counts the LP's memory for them).
LP_METHODS = tuple(name for name, m in TABLE.items() if m.memory == STORED_LP)

#: One help text for ``--method``, shared by every command.
METHOD_HELP = "solver: " + ", ".join(f"{m.name} ({m.help})" for m in TABLE.values() if m.takes == MDP_INPUT)


def method(name: str, constrained: bool = False, allowed: tuple[str, ...] | None = None,
           problem: str | None = None, criterion: str | None = None) -> Method:
    """The registry row of ``name`` (of :data:`CONSTRAINED` with ``constrained``, of the table of
    ``criterion`` when given): the one validator of a method name.

    Parameters
    ----------
    name : str
    constrained : bool
        Look ``name`` up among the constrained methods.
    criterion : {"average", "constrained", "discounted"}, optional
        The table to look ``name`` up in (default: by ``constrained``).
    allowed : tuple of str, optional
        The names the caller takes (default: the whole table).
    problem : str, optional
        What the caller solves (``"an unconstrained scenario"``): the message then says that
        ``name`` does not solve it.

    Raises
    ------
    SolverError
        ``name`` is not allowed; the message lists the names that are.
    """
    criterion = criterion or (CONSTRAINED_CRITERION if constrained else AVERAGE)
    table = TABLES[criterion]
    names = tuple(table) if allowed is None else allowed
    if isinstance(name, str) and name in names and name in table:
        return table[name]
    from .errors import SolverError

    if problem is not None:
        raise SolverError(f"method {name!r} does not solve {problem}; expected one of {', '.join(names)}")
    if criterion == DISCOUNTED_CRITERION:
        raise SolverError(f"unknown discounted method {name!r}; expected one of {', '.join(names)}")
    what = "constrained method" if criterion == CONSTRAINED_CRITERION else "method"
    raise SolverError(f"unknown {what} {name!r}; expected one of {', '.join(map(repr, names))}")


def check_criterion(criterion: str) -> str:
    """``criterion`` if it is one of :data:`CRITERIA`, else one :class:`~wncs_lp.errors.SolverError` listing them."""
    if isinstance(criterion, str) and criterion in CRITERIA:
        return criterion
    from .errors import SolverError

    raise SolverError(f"unknown criterion {criterion!r}; expected one of {', '.join(map(repr, CRITERIA))}")


def discounted_method(name: str) -> Method:
    """The row of :data:`DISCOUNTED` that ``name`` runs: a discounted method's own name, or a name of
    the average-cost vocabulary read through :data:`DISCOUNTED_FOR`.

    Raises
    ------
    SolverError
        ``name`` is neither; the message lists the discounted methods and the names that run them.
    """
    found = DISCOUNTED_FOR.get(name) if isinstance(name, str) else None
    if found is None and isinstance(name, str) and name in DISCOUNTED:
        found = name
    if found is not None:
        return DISCOUNTED[found]
    from .errors import SolverError

    raise SolverError(f"the discounted criterion solves with {', '.join(sorted(DISCOUNTED))} (method "
                      f"{', '.join(DISCOUNTED_FOR)}); got method {name!r}")


def check_method(name: str, allowed: tuple[str, ...] = METHODS) -> str:
    """``name`` if it is one of ``allowed`` (:func:`method`'s check), else its :class:`~wncs_lp.errors.SolverError`."""
    return method(name, allowed=allowed).name


def memory_of(name: str | None, constrained: bool = False) -> str:
    """The memory model the size guard counts for ``name`` (:data:`STORED` for None or an unknown name)."""
    table = CONSTRAINED if constrained else TABLE
    row = table.get(name) if name is not None else None
    return row.memory if row is not None else STORED


#: The reproduction solves by policy iteration up to this many states, by relative value
#: iteration above (:func:`exact_method`).
EXACT_METHOD_MAX_STATES = 60_000


def exact_method(n_states: int) -> str:
    """The reproduction's method: policy iteration (its gain exact to round-off, its policy a
    vertex the structural checks read) up to :data:`EXACT_METHOD_MAX_STATES` states, relative
    value iteration above (where a sparse factorisation per iteration no longer pays)."""
    return "pi" if n_states <= EXACT_METHOD_MAX_STATES else "rvi"
