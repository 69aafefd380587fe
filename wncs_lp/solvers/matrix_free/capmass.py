"""How much a policy leans on the AoI cap, certified without a transition matrix: matrix-free
evaluations under the cost "processes at their cap" (:func:`cap_cost`)."""
from __future__ import annotations

from typing import Any

import numpy as np

from ...models.system import System
from ...scenario import Scenario
from .iterate import matrix_free_evaluate
from .result import MatrixFreeEvaluation, as_system

__all__ = ["cap_cost", "matrix_free_cap_mass", "matrix_free_cap_masses"]


def cap_cost(scenario_or_system: Scenario | System) -> np.ndarray:
    """The (N, max cap) cost table sum_k [tau_k = cap_k]: its average is the expected number of
    processes at their cap, E[#{k : tau_k = cap_k}] = sum_k m_k (:mod:`wncs_lp.truncation`)."""
    caps = np.asarray(as_system(scenario_or_system).caps, dtype=np.int64)
    c = np.zeros((caps.size, int(caps.max())))
    c[np.arange(caps.size), caps - 1] = 1.0
    return c


def _cap_defaults(kw: dict[str, Any]) -> None:
    """The defaults of an evaluation under the cap cost: relative ``tol`` 1e-8, and in-place
    sweeps from the start (``warm_start=False``). :func:`~.iterate.matrix_free_evaluate` warms up
    with Jacobi passes by default because a wide first bracket's midpoint, as the in-place
    sweeps' shift, would distort h; here the first bracket is [0, N], and what the sweeps must do
    first is carry the cost down from the caps, which the Jacobi passes (aperiodicity transform
    0.5) do at half the speed and at the price of a certificate each (the passes and CPU
    measured both ways are in docs/matrix-free.md)."""
    kw.setdefault("tol", 1e-8)
    kw.setdefault("warm_start", False)


def matrix_free_cap_mass(scenario_or_system: Scenario | System, policy: Any, *, atol: float = 1e-7,
                         **kw: Any) -> "MatrixFreeEvaluation":
    r"""How much a policy leans on the AoI cap, certified, without a transition matrix.

    The long-run average of :math:`\sum_k [\tau_k = \hat\tau_k]`, i.e. the expected number of
    processes at their cap :math:`\sum_k m_k`, by :func:`matrix_free_evaluate` with
    :func:`cap_cost`. It brackets the mass with *some* process at its cap (the quantity of
    :func:`wncs_lp.truncation.cap_mass`, which needs the stationary law):
    :math:`\frac1N \sum_k m_k \le m \le \sum_k m_k`, so the result is an upper bound on m.
    ``atol`` is the absolute width at which the bracket counts as closed (a share of time, so
    1e-7 is ample; the commands ask for :data:`wncs_lp.truncation.CAP_COUNT_ATOL`, what they
    print needs no more); ``tol`` (relative, default 1e-8 here) also closes it. ``warm_start``
    defaults to off here (:func:`_cap_defaults`).
    """
    _cap_defaults(kw)
    kw.setdefault("name", f"{getattr(policy, 'name', 'policy')}: processes at the cap")
    return matrix_free_evaluate(scenario_or_system, policy, cost=cap_cost(scenario_or_system), atol=atol, **kw)


def matrix_free_cap_masses(scenario_or_system: Scenario | System, policy: Any, *, atol: float = 1e-6,
                           **kw: Any) -> list["MatrixFreeEvaluation"]:
    r"""The time each process spends at its cap under a policy, certified: one evaluation per
    process k with the cost :math:`[\tau_k = \hat\tau_k]` (so N times the work of
    :func:`matrix_free_cap_mass`). Entry k brackets :math:`m_k`; the share of time with some
    process at its cap lies in :math:`[\max_k m_k, \min(1, \sum_k m_k)]`. ``atol`` is the
    absolute width at which each bracket counts as closed.
    """
    system = as_system(scenario_or_system)
    base = cap_cost(system)
    _cap_defaults(kw)
    out = []
    for k in range(base.shape[0]):
        cost = np.zeros_like(base)
        cost[k] = base[k]
        name = f"{getattr(policy, 'name', 'policy')}: process {k + 1} at its cap"
        out.append(matrix_free_evaluate(system, policy, cost=cost, atol=atol, name=name, **kw))
    return out
