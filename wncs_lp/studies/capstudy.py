r"""The cap study: solve at increasing AoI caps until the truncation no longer matters.

Why it is meaningful. The cap :math:`C` stops the AoI (and its cost) from growing. While every
loop length :math:`U_m + T_{m,k} + D_m` fits under :math:`C`, the cap-:math:`C` model is a
lumping of the cap-:math:`C'` model (:math:`C < C'`: merge the AoI values :math:`\ge C`) whose
costs are lower (:math:`q_k` is increasing and :math:`q_k(\min(\tau, C)) \le q_k(\tau)`), so

.. math:: g^*(C) \le g^*(C') \qquad (C < C'),

a non-decreasing sequence of lower bounds on the untruncated optimum (tested in
``tests/test_truncation.py``). Each row reports the gain with its certificate, the mass the
optimal policy spends at the cap (:mod:`wncs_lp.truncation`) and the change from the previous
cap; the study stops at the first cap where both the mass and the relative change fall below
the tolerances (or at the last cap given). Beside each gain, the policy optimal at the first cap
is evaluated at that cap (:class:`~wncs_lp.policies.ClippedPolicy`): what the small model's
answer is worth in the larger one.

Every cap takes the one route, so the study passes to the matrix-free solver where the stored
matrix would not fit (``auto``), as ``wncs-lp solve`` does: the mass at the cap is then the
certified upper end of :class:`~wncs_lp.truncation.CapCount` (the study stops only when even that
is below the tolerance), and the first cap's policy is evaluated by the certified matrix-free
evaluation.

The caps are walked in order by the studies' grid runner (:func:`~wncs_lp.studies.runner.run_grid`,
each cap handing the first cap's policy and its gain to the next), every solve through the one
route (:func:`wncs_lp.workflow.route.run_scenario`).
"""
from __future__ import annotations

import time
from dataclasses import asdict, dataclass
from functools import partial
from typing import Any, Callable, Sequence

from ..arguments import real, shown, whole
from ..errors import ArgumentError, WncsError
from ..methods import DEFAULT_METHOD
from ..scenario import Scenario
from .runner import run_grid

__all__ = ["CapRow", "CapStudy", "cap_study"]


@dataclass(frozen=True)
class CapRow:
    """One cap of a study.

    Attributes
    ----------
    cap : int
    states, pairs : int
    gain, gain_lower, gain_upper : float
        The optimal gain at this cap and its certificate.
    cap_mass : float
        Share of the optimal policy's long-run time with some AoI at the cap.
    rel_change : float
        (gain - previous gain) / gain (NaN on the first row).
    first_policy_gain : float
        The exact gain, at this cap, of the policy optimal at the study's first cap (NaN when a
        state of this cap has no counterpart there).
    seconds : float
    method : str
        The method that ran (``matrix-free`` where the stored matrix would not fit: then
        ``pairs`` is 0, ``states`` counts the matrix-free layout, ``cap_mass`` is the certified
        upper end of the mass (:class:`~wncs_lp.truncation.CapCount`) and ``first_policy_gain``
        the midpoint of a certified matrix-free evaluation).
    status : str
        The status of this cap's solve (:mod:`wncs_lp.status`): ``"optimal"`` only where its
        certificate closed; the study converges only on certified rows.
    """

    cap: int
    states: int
    pairs: int
    gain: float
    gain_lower: float
    gain_upper: float
    cap_mass: float
    rel_change: float
    first_policy_gain: float
    seconds: float
    method: str = ""
    status: str = "optimal"

    @property
    def certified(self) -> bool:
        """This cap's solve is certified (status ``optimal``)."""
        return self.status == "optimal"


@dataclass(frozen=True)
class CapStudy:
    """The rows of a cap study and whether it converged.

    Attributes
    ----------
    rows : tuple of CapRow
    converged : bool
        The last row meets both tolerances, and its solve and the previous cap's are certified
        (a gain change between uncertified gains proves nothing).
    mass_tol, gain_rtol : float
    """

    rows: tuple[CapRow, ...]
    converged: bool
    mass_tol: float
    gain_rtol: float

    def table(self) -> list[dict[str, Any]]:
        return [asdict(r) for r in self.rows]

    def __repr__(self) -> str:
        last = self.rows[-1] if self.rows else None
        tail = f", last cap {last.cap}: gain {last.gain:.10g}, mass at cap {last.cap_mass:.2%}" if last else ""
        return f"CapStudy({len(self.rows)} caps, converged={self.converged}{tail})"


def _cap_row(scenario: Scenario, opts: dict[str, Any], cap: int, carry: dict[str, Any] | None,
             emit: Callable[[CapRow], None] | None = None) -> tuple[list[CapRow], dict[str, Any]]:
    """Solve at one cap (a task of :func:`~wncs_lp.studies.runner.run_grid`, walked in order),
    through the one route: the enumerated MDP where it fits, else (``auto``) the matrix-free
    solver. The carry holds the first cap's optimal policy and the previous gain."""
    from ..models.system import System
    from ..workflow import run_scenario

    t0 = time.perf_counter()
    sc = scenario.with_overrides({"tau_cap": cap})
    run = run_scenario(sc, opts["method"], constrained=False, force=opts["force"], threads=opts["threads"])
    sol = run.solution
    system = System.from_scenario(sc) if run.built else sol.system
    mass, states, pairs, policy = (_enumerated(run, system) if run.built else _matrix_free(sol, system, opts))
    if carry is None:
        carry = {"first": policy, "prev": None}
        fp = float(sol.gain)
    else:
        fp = _first_policy_gain(carry["first"], run, system, opts)
    prev = carry["prev"]
    change = float("nan") if prev is None else (sol.gain - prev) / abs(sol.gain)
    row = CapRow(cap, states, pairs, float(sol.gain), float(sol.gain_lower), float(sol.gain_upper), float(mass),
                 float(change), float(fp), time.perf_counter() - t0, run.method, str(sol.status))
    if emit is not None:
        emit(row)
    return [row], {**carry, "prev": float(sol.gain)}


def _enumerated(run: Any, system: Any) -> tuple[float, int, int, Any]:
    """(mass at the cap, states, pairs, the optimal policy) of a solve on the enumerated MDP."""
    from ..policies import OptimalPolicy
    from ..truncation import policy_cap_mass

    mdp, sol = run.mdp, run.solution
    return (policy_cap_mass(mdp, sol.policy).total, mdp.n_states, mdp.n_pairs, OptimalPolicy(mdp, sol, system, outside="first"))


def _matrix_free(sol: Any, system: Any, opts: dict[str, Any]) -> tuple[float, int, int, Any]:
    """The same of a matrix-free solve: the mass is the certified upper end of :class:`CapCount`."""
    from ..policies import MatrixFreePolicy
    from ..solvers.matrix_free import matrix_free_cap_mass
    from ..truncation import CAP_COUNT_ATOL, CapCount

    count = CapCount.of(matrix_free_cap_mass(system, sol, atol=CAP_COUNT_ATOL, threads=opts["threads"]), system)
    return count.total, int(sol.stats.get("n_states", sol.bias.size)), 0, MatrixFreePolicy.from_solution(sol)


def _first_policy_gain(first: Any, run: Any, system: Any, opts: dict[str, Any]) -> float:
    """The exact gain at this cap of the first cap's optimal policy, fed the clipped AoI (NaN when a
    state has no counterpart there)."""
    from ..evaluate import evaluate
    from ..policies import ClippedPolicy

    try:
        clipped = ClippedPolicy(first, system)
        if run.built:
            return float(evaluate(run.mdp, clipped).gain)
        from ..solvers.matrix_free import matrix_free_evaluate

        return float(matrix_free_evaluate(system, clipped, threads=opts["threads"]).gain)
    except WncsError:
        return float("nan")


def cap_study(
    scenario: Scenario,
    caps: Sequence[int],
    *,
    mass_tol: float = 0.01,
    gain_rtol: float = 1e-3,
    method: str = DEFAULT_METHOD,
    force: bool = False,
    threads: int | None = None,
    on_row: Callable[[CapRow], None] | None = None,
) -> CapStudy:
    """Solve the scenario at each cap in ``caps`` (increasing) until the truncation stops mattering.

    Parameters
    ----------
    scenario : Scenario
        Every process's cap is overridden by each value of ``caps``.
    caps : sequence of int
        Increasing caps; each must be at least the longest loop length of the scenario (below
        it the lower-bound property does not hold and the study refuses).
    mass_tol, gain_rtol : float
        Stop at the first cap whose mass at the cap is at most ``mass_tol`` and whose relative
        change from the previous cap is at most ``gain_rtol``.
    method : str
        Solver method (:data:`wncs_lp.methods.METHODS`), through the one route
        (:func:`wncs_lp.workflow.route.run_scenario`).
    force : bool
        Build past the size guard.
    threads : int, optional
        Kernel threads of the solver (default: the solver's).
    on_row : callable, optional
        Called with each row as soon as it is computed (progress, incremental output).
    """
    from ..methods import check_method

    mass_tol = real(mass_tol, "mass_tol", lo=0.0, hi=1.0)
    gain_rtol = real(gain_rtol, "gain_rtol", lo=0.0)
    if isinstance(caps, (str, bytes)) or not hasattr(caps, "__iter__"):
        raise ArgumentError("caps", f"expected a sequence of whole numbers, got {shown(caps)}")
    caps = [whole(c, "caps", lo=1) for c in caps]
    if not caps or any(b <= a for a, b in zip(caps, caps[1:])):
        raise WncsError(f"cap study: expected increasing caps, got {caps}")
    longest = max(max(s.loop) for s in scenario.servers)
    if caps[0] < longest:
        raise WncsError(f"cap study: the first cap {caps[0]} is below the longest loop length {longest} "
                        "(U + T + D); g*(C) is a lower bound on larger caps only from there on")
    check_method(method)
    rows: list[CapRow] = []

    def record(row: CapRow) -> None:
        rows.append(row)
        if on_row is not None:
            on_row(row)

    def converged(results: list[CapRow], carry: Any) -> bool:
        r = results[-1]
        return (len(rows) > 1 and r.cap_mass <= mass_tol and abs(r.rel_change) <= gain_rtol
                and r.certified and rows[-2].certified)

    opts = {"method": method, "force": force, "threads": threads}
    run_grid(caps, partial(_cap_row, scenario, opts), record, stop=converged)
    return CapStudy(tuple(rows), bool(rows) and converged(rows[-1:], None), mass_tol, gain_rtol)
