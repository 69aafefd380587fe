r"""The policy of a bound: greedy on the relaxation's separable value function.

With the value tables :math:`h_k` of a relaxation (:class:`~wncs_lp.bounds.ValueTables`),

.. math:: \pi(\tau, C) = \arg\min_a \sum_o P(o \mid C, a) \sum_k h_k(\tau'_k, \mathrm{column}_k(C'_o)),

the paper's Section III rule (:class:`~wncs_lp.policies.suboptimal.SuboptimalPolicy`) with the
relaxation's tables instead of the random base policy's. For the private-servers relaxation
:math:`h_k` is process k's bias at the multipliers, read on k's projection of C; the price term
:math:`\sum_m \lambda_m \sum_k \text{claim}_m` of the relaxation is left out (it is the
constant :math:`\sum_m \lambda_m` whenever the claims sum to 1). Nothing of the size of the tau
box is formed: it works with :func:`wncs_lp.evaluate`, the matrix-free evaluation,
:func:`wncs_lp.simulate` and the maps like any :class:`~wncs_lp.policies.Policy`.
"""
from __future__ import annotations

import time
from typing import Any

import numpy as np

from ..errors import PolicyError
from ..models.system import System
from ..policies.suboptimal import SeparableGreedyPolicy
from .result import BoundResult

__all__ = ["BoundPolicy", "bound_policy"]


class BoundPolicy(SeparableGreedyPolicy):
    """The greedy policy on the value tables of a :class:`BoundResult`.

    Parameters
    ----------
    result : BoundResult
    system : System
        The system the bound was computed on (its configurations are the ones
        ``result.tables.column`` indexes).

    Attributes
    ----------
    result : BoundResult
    build_seconds : float
    """

    name = "bound"

    def __init__(self, result: BoundResult, system: System):
        t0 = time.perf_counter()
        cols = result.tables.column
        if len(cols) != system.n_processes or any(np.shape(c) != (system.n_configs,) for c in cols):
            raise PolicyError(f"the {result.relaxation} bound's tables belong to another system "
                              f"({len(cols)} processes, column maps of shape "
                              f"{sorted({np.shape(c) for c in cols})}; this system has {system.n_processes} "
                              f"processes and {system.n_configs} configurations)")
        super().__init__(system, result.tables.h, cols)
        self.result = result
        self.name = f"bound[{result.relaxation}]"
        self.build_seconds = time.perf_counter() - t0

    def describe(self) -> dict[str, Any]:
        return {**super().describe(), "relaxation": self.result.relaxation,
                "lower_bound": self.result.lower_bound, "build_seconds": self.build_seconds}


def bound_policy(result: BoundResult, system: System) -> BoundPolicy:
    """The greedy policy of a bound on its system (:class:`BoundPolicy`)."""
    return BoundPolicy(result, system)
