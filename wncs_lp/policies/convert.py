"""Any documented form of a policy as a :class:`~wncs_lp.policies.Policy`: what the simulator
takes (a policy, a solution, pair indices, pair probabilities or an action per state)."""
from __future__ import annotations

from typing import Any

import numpy as np

from .. import moved
from ..errors import PolicyError
from ..mdp import MDP
from ..models.system import System
from ..policy_forms import policy_array
from .base import Policy, TablePolicy, system_of
from .matrix_free import MatrixFreePolicy
from .mixed import MixedPolicy

__all__ = ["as_policy"]


def as_policy(policy: Any = None, mdp: MDP | None = None, *, sigma: Any = None, system: System | None = None,
              name: str | None = None) -> Policy:
    """A :class:`Policy` from any documented form of one (what the simulator takes).

    Parameters
    ----------
    policy : Policy, Solution, MatrixFreeSolution or array, optional
        A policy (returned as it is); a solution (its policy: a ``Solution`` or
        ``ConstrainedSolution`` needs ``mdp``, a ``MatrixFreeSolution`` does not); or, with
        ``mdp``, (n,) int pair indices or (L,) float pair probabilities.
    mdp : MDP, optional
        The enumerated MDP an array or a solution lives on (built from the scenario).
    sigma : (n,) int array, optional
        An action per state of ``mdp`` instead (a row of ``mdp.action_table``, :attr:`Solution.sigma`).
    system : System, optional
        Default: the MDP's (:func:`system_of`).
    name : str, optional

    Raises
    ------
    PolicyError
        Nothing given, both ``policy`` and ``sigma``, an array or solution without its MDP, or a
        malformed array (the message says what was expected).
    """
    if isinstance(policy, Policy) and sigma is None:
        return policy
    if policy is None and sigma is None:
        raise PolicyError("no policy given: pass a Policy, a solution, pair indices (policy=) or an action per "
                          "state (sigma=) with the MDP (mdp=)")
    if sigma is None and hasattr(policy, "local_actions") and hasattr(policy, "layout"):  # a MatrixFreeSolution
        return MatrixFreePolicy.from_solution(policy, name=name or "optimal")
    if mdp is None:
        what = "an action per state (sigma)" if sigma is not None else (
            f"a {type(policy).__name__}" if not isinstance(policy, (np.ndarray, list, tuple)) else "an array")
        raise PolicyError(f"a policy given as {what} needs the MDP it lives on: pass mdp= (e.g. "
                          "simulate(sol.policy, mdp) or simulate(mdp=mdp, sigma=sigma)), or wrap it first "
                          "(Policy.from_sigma(mdp, sigma), Policy.from_function(system, f))")
    system = system if system is not None else system_of(mdp)
    arr = policy_array(mdp, policy, sigma)
    if np.issubdtype(arr.dtype, np.floating):
        return MixedPolicy(system, mdp, arr, name=name)
    if name is None:
        name = "sigma" if sigma is not None else ("optimal" if hasattr(policy, "gain_lower") else "pairs")
    return TablePolicy(system, mdp, arr, name=name)


#: Names that moved or were replaced: found here for one release, with a warning (:mod:`wncs_lp.moved`).
__getattr__ = moved.old_names(__name__)
