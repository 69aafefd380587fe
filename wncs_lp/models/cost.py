"""The AoI-to-MSE cost tables q_k(tau) of ``model.md`` section 1.

q_k(tau) = w_k * trace( sum_{i=0}^{tau-1} A_k^i R_k (A_k^T)^i ),  tau = 1..tau_hat_k,

the trace of the paper's Q_k (eq. (5)): the estimation error covariance of process k when its
freshest information is tau slots old.
"""
from __future__ import annotations

import numpy as np

from ..scenario import ProcessSpec, Scenario

__all__ = ["mse_table", "cost_tables"]


def mse_table(A: np.ndarray, R: np.ndarray, tau_max: int, weight: float = 1.0) -> np.ndarray:
    """Return ``q`` with ``q[tau - 1] = weight * trace(sum_{i<tau} A^i R A^iT)`` for tau = 1..tau_max.

    Computed by the recursion S_tau = S_{tau-1} + A^{tau-1} R A^{tau-1 T}, carrying
    M_i = A^i R A^iT = A M_{i-1} A^T, so it costs tau_max small matrix products.

    Examples
    --------
    >>> mse_table(np.array([[1.02]]), np.array([[1.0]]), 2)
    array([1.    , 2.0404])
    """
    A = np.asarray(A, dtype=float)
    M = np.asarray(R, dtype=float).copy()
    out = np.empty(tau_max)
    acc = 0.0
    for t in range(tau_max):
        acc += float(np.trace(M))
        out[t] = weight * acc
        M = A @ M @ A.T
    return out


def process_cost(process: ProcessSpec, tau_max: int | None = None) -> np.ndarray:
    """q_k(1..tau_max) for one process (default: up to its own cap)."""
    return mse_table(process.A, process.R, tau_max or process.tau_cap, process.weight)


def cost_tables(scenario: Scenario) -> list[np.ndarray]:
    """q_k(1..tau_hat_k) for every process of a scenario, in order."""
    return [process_cost(pr) for pr in scenario.processes]
