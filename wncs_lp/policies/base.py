"""The policy interface: one ``act`` over (tau, configuration) arrays, one ``on_mdp``.

See :mod:`wncs_lp.policies` for the two uses of a policy.
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any

import numpy as np

from ..errors import PolicyError
from ..mdp import MDP
from ..models.system import System

__all__ = ["Policy", "as_rng"]


def as_rng(rng: np.random.Generator | int | None) -> np.random.Generator:
    """A ``numpy.random.Generator`` from a generator, a seed or None."""
    return rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)


class Policy(ABC):
    """A stationary scheduling policy over the states (tau, C) of a :class:`System`.

    Subclasses implement :meth:`act`; :meth:`on_mdp` derives the enumerated form from it
    (randomised policies override it).

    Attributes
    ----------
    name : str
        Short name (``"greedy"``, ``"static[remote,edge]"``, ...).
    system : System
    randomised : bool
        Whether :meth:`act` draws random numbers.
    """

    name: str = "policy"
    randomised: bool = False

    def __init__(self, system: System):
        self.system = system

    @abstractmethod
    def act(self, tau: np.ndarray, config_ids: np.ndarray, rng: np.random.Generator | None = None) -> np.ndarray:
        """Local action indices for R states.

        Parameters
        ----------
        tau : (R, N) int array
            AoI values, 1 <= tau[r, k] <= tau_hat_k.
        config_ids : (R,) int array
            Configuration ids of the automaton.
        rng : numpy.random.Generator, optional
            Used by randomised policies only.

        Returns
        -------
        (R,) int64 array
            ``j[r]`` indexes ``system.automaton.actions[config_ids[r]]``.
        """

    def on_mdp(self, mdp: MDP) -> np.ndarray:
        """The policy on an enumerated MDP of the same scenario: (n,) pair indices.

        Raises
        ------
        PolicyError
            The MDP was not built from this policy's scenario.
        """
        self.system.check_mdp(mdp)
        st = mdp.states
        j = np.asarray(self.act(np.asarray(st.tau, dtype=np.int64), np.asarray(st.config, dtype=np.int64),
                                np.random.default_rng(0)), dtype=np.int64)
        if np.any(j < 0) or np.any(j >= np.diff(mdp.pair_ptr)):
            raise PolicyError(f"policy {self.name}: a local action index is out of range")
        return mdp.pair_ptr[:-1] + j

    def describe(self) -> dict[str, Any]:
        """JSON-ready description."""
        return {"policy": self.name, "randomised": self.randomised}

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.name!r})"

    # helpers ------------------------------------------------------------------
    @staticmethod
    def _check_inputs(tau: np.ndarray, config_ids: np.ndarray) -> tuple:
        tau = np.asarray(tau, dtype=np.int64)
        c = np.asarray(config_ids, dtype=np.int64)
        if tau.ndim != 2 or c.shape != (tau.shape[0],):
            raise PolicyError(f"act expects tau of shape (R, N) and config_ids of shape (R,), got {tau.shape}, {c.shape}")
        return tau, c
