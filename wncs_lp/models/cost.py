"""The cost tables q_k(tau) of ``docs/model.md`` (section 1 and "Cost families").

The default family is the MSE,

q_k(tau) = w_k * trace( sum_{i=0}^{tau-1} A_k^i R_k (A_k^T)^i ),  tau = 1..tau_hat_k,

the trace of the paper's Q_k (eq. (5)): the estimation error covariance of process k when its
freshest information is tau slots old. It grows like rho(A_k)^(2 tau) for an unstable A_k, so a
large cap can overflow: a table whose entries pass :data:`wncs_lp.mdp.MAX_COST` (or are not
finite) is refused where it is computed, naming the process and the AoI. The other families of
a process's ``cost`` field: the AoI (w_k tau), a power of it (w_k tau^x) and an explicit table
(w_k c_tau), checked the same way.
"""
from __future__ import annotations

import numpy as np

from ..errors import ModelError
from ..mdp import MAX_COST
from ..scenario import CostSpec, ProcessSpec, Scenario

__all__ = ["mse_table", "cost_tables", "process_cost", "family_table"]


def mse_table(A: np.ndarray, R: np.ndarray, tau_max: int, weight: float = 1.0, *, what: str = "the cost") -> np.ndarray:
    """Return ``q`` with ``q[tau - 1] = weight * trace(sum_{i<tau} A^i R A^iT)`` for tau = 1..tau_max.

    Computed by the recursion S_tau = S_{tau-1} + A^{tau-1} R A^{tau-1 T}, carrying
    M_i = A^i R A^iT = A M_{i-1} A^T, so it costs tau_max small matrix products.

    Raises
    ------
    ModelError
        Some q(tau) is not finite or exceeds :data:`~wncs_lp.mdp.MAX_COST` in magnitude; the
        message names ``what`` and the first such AoI.

    Examples
    --------
    >>> mse_table(np.array([[1.02]]), np.array([[1.0]]), 2)
    array([1.    , 2.0404])
    """
    A = np.asarray(A, dtype=float)
    M = np.asarray(R, dtype=float).copy()
    out = np.empty(tau_max)
    acc = 0.0
    with np.errstate(over="ignore", invalid="ignore"):  # overflow is detected and named below
        for t in range(tau_max):
            acc += float(np.trace(M))
            out[t] = weight * acc
            if not abs(out[t]) <= MAX_COST:
                _overflow(what, t + 1, out[t], A)
            M = A @ M @ A.T
    return out


def _overflow(what: str, tau: int, value: float, A: np.ndarray) -> None:
    try:
        rho = float(np.max(np.abs(np.linalg.eigvals(A)))) if np.all(np.isfinite(A)) else float("inf")
    except np.linalg.LinAlgError:  # pragma: no cover - eigvals of a finite square matrix converges
        rho = float("nan")
    found = "overflows float64" if not np.isfinite(value) else f"is {value:.3g}, beyond {MAX_COST:g}"
    raise ModelError(
        f"{what}: the cost q(tau) = weight * trace(sum_(i<tau) A^i R A^iT) {found} at AoI tau = {tau} "
        f"(the largest cost the solvers take is {MAX_COST:g}: sums and squares of larger ones overflow; q grows "
        f"like rho(A)^(2 tau), rho(A) = {rho:.4g}): lower tau_cap below {tau}, or scale A, R or the weight down"
    )


def family_table(cost: CostSpec, tau_max: int, weight: float = 1.0, *, what: str = "the cost") -> np.ndarray:
    """``q`` with ``q[tau - 1] = weight * f(tau)`` for the families other than the MSE: f(tau) = tau
    (``"aoi"``), tau ** power (``"power"``), ``table[tau - 1]`` (``"table"``).

    Raises
    ------
    ModelError
        The family is the MSE (it needs A and R: :func:`mse_table`), the table is shorter than
        ``tau_max``, or some q(tau) is not finite or exceeds :data:`~wncs_lp.mdp.MAX_COST`.
    """
    tau = np.arange(1, tau_max + 1, dtype=float)
    with np.errstate(over="ignore", invalid="ignore"):
        if cost.family == "aoi":
            base = tau
        elif cost.family == "power":
            base = tau ** cost.power
        elif cost.family == "table":
            if len(cost.table) < tau_max:
                raise ModelError(f"{what}: the cost table has {len(cost.table)} values, fewer than the AoI cap {tau_max}")
            base = np.asarray(cost.table[:tau_max], dtype=float)
        else:
            raise ModelError(f"{what}: cost family {cost.family!r} has no table of its own here (the MSE needs A and R)")
        out = weight * base
    bad = np.flatnonzero(~(np.abs(out) <= MAX_COST))
    if bad.size:
        t = int(bad[0]) + 1
        found = "overflows float64" if not np.isfinite(out[t - 1]) else f"is {out[t - 1]:.3g}, beyond {MAX_COST:g}"
        lower = f"lower tau_cap below {t}, or " if t > 1 else ""
        raise ModelError(f"{what}: the cost q(tau) = weight * {cost} {found} at AoI tau = {t} (the largest cost the "
                         f"solvers take is {MAX_COST:g}): {lower}scale the cost or the weight down")
    return out


def process_cost(process: ProcessSpec, tau_max: int | None = None, source: str = "") -> np.ndarray:
    """q_k(1..tau_max) for one process (default: up to its own cap), in its cost family."""
    what = f"{source + ': ' if source else ''}process '{process.name}'"
    tau_max = tau_max or process.tau_cap
    if process.cost.family == "mse":
        return mse_table(process.A, process.R, tau_max, process.weight, what=what)
    return family_table(process.cost, tau_max, process.weight, what=what)


def cost_tables(scenario: Scenario) -> list[np.ndarray]:
    """q_k(1..tau_hat_k) for every process of a scenario, in order."""
    return [process_cost(pr, source=scenario.source) for pr in scenario.processes]
