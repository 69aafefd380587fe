"""Model builders: scenario -> :class:`~wncs_lp.mdp.MDP`. One module per model."""
from __future__ import annotations

from ..errors import ModelError
from ..mdp import MDP
from ..scenario import Scenario

__all__ = ["build"]


def build(scenario: Scenario) -> MDP:
    """Build the MDP of a scenario, dispatching on ``scenario.model.kind``."""
    kind = scenario.model.kind
    if kind == "wncs":
        from .wncs import build_wncs

        return build_wncs(scenario)
    if kind == "preemption":
        from .preemption import build_preemption

        return build_preemption(scenario)
    raise ModelError(f"{scenario.source}: no builder for model kind {kind!r}")
