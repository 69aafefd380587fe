"""A policy stored as one small integer per state of a matrix-free layout (2.5e8 states fit)."""
from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import PolicyError
from ..models.system import System
from ..solvers.matrix_free.layout import check_local_actions
from .base import Policy

__all__ = ["MatrixFreePolicy"]


class MatrixFreePolicy(Policy):
    """A deterministic policy stored as one local action index (uint8) per layout state.

    ``act`` looks the states up in the layout, which contains every reachable state, so the
    simulator, :func:`wncs_lp.evaluate.evaluate` (through ``on_mdp``) and
    :func:`matrix_free_evaluate` all accept it.
    """

    def __init__(self, system: System, layout: Any, table: np.ndarray, name: str = "optimal",
                 solution: Any = None):
        super().__init__(system)
        # one local action per layout state, each within its configuration's actions (the kernels
        # and act() index the action tables by it)
        self.table = check_local_actions(table, layout, system.n_actions, f"policy {name!r}")
        self.layout = layout
        self.name = name
        self.solution = solution

    def act(self, tau, config_ids, rng=None):
        tau, c = self._check_inputs(tau, config_ids)
        idx = self.layout.index(tau, c)
        if np.any(idx < 0):
            r = int(np.flatnonzero(idx < 0)[0])
            raise PolicyError(f"state tau={tau[r].tolist()}, configuration {int(c[r])} is outside the policy's layout")
        return self.table[idx].astype(np.int64)

    @classmethod
    def from_solution(cls, solution: Any, name: str = "optimal") -> "MatrixFreePolicy":
        """The policy of a :class:`~wncs_lp.solvers.matrix_free.MatrixFreeSolution` (its ``local_actions``)."""
        return cls(solution.system, solution.layout, solution.local_actions, name=name, solution=solution)
