"""The decoded view of an AoI-product state space: (tau, configuration) per state."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Hashable, Sequence

import numpy as np

from ..errors import ModelError

__all__ = ["StateSpace"]


@dataclass(frozen=True, eq=False)
class StateSpace:
    """The decoded view of an AoI-product state space.

    Attributes
    ----------
    tau : (n, N) int array
        The AoI of every process in every state (values 1..tau_hat_k).
    config : (n,) int array
        The configuration id of every state.
    configs : list
        The configuration objects (model-specific tuples), by id.
    caps : tuple[int, ...]
    describe_config : callable
        config object -> readable string.
    model : Model or None
        The :class:`~wncs_lp.models.base.Model` the space was built from (None for a space
        read back from a file).
    """

    tau: np.ndarray
    config: np.ndarray
    configs: list
    caps: tuple[int, ...]
    describe_config: Callable[[Any], str] = repr
    _lookup: np.ndarray | None = None  # (n_configs, box) -> state id or -1
    model: Any = None

    @property
    def n_states(self) -> int:
        return int(self.config.size)

    def label(self, s: int) -> str:
        t = ",".join(str(int(x)) for x in self.tau[s])
        return f"tau=({t}) | {self.describe_config(self.configs[int(self.config[s])])}"

    def find(self, tau: Sequence[int], config: Hashable | int) -> int:
        """The state id of (tau, config), or -1 when that state is not reachable."""
        c = config if isinstance(config, (int, np.integer)) else self.config_id(config)
        if c < 0:
            return -1
        tau = np.asarray(tau, dtype=np.int64)
        if tau.shape != (len(self.caps),) or np.any(tau < 1) or np.any(tau > np.asarray(self.caps)):
            return -1
        flat = int(np.ravel_multi_index(tuple(tau - 1), self.caps))
        return int(self._lookup[c, flat])

    def ids(self, tau: np.ndarray, config_ids: np.ndarray) -> np.ndarray:
        """State ids of R states given as an (R, N) AoI array and (R,) configuration ids (-1 = absent).

        The AoI values must lie in the box (not checked: this is the vectorised hot path).
        """
        flat = np.ravel_multi_index(tuple((np.asarray(tau, dtype=np.int64) - 1).T), self.caps)
        return self._lookup[np.asarray(config_ids, dtype=np.int64), flat]

    def config_id(self, config: Hashable) -> int:
        try:
            return self.configs.index(config)
        except ValueError:
            return -1

    def lookup_grid(self, config: Hashable | int) -> np.ndarray:
        """State ids of one configuration over the whole tau box (shape = caps; -1 = unreachable)."""
        c = config if isinstance(config, (int, np.integer)) else self.config_id(config)
        if c < 0:
            raise ModelError(f"configuration {config!r} is not reachable")
        return self._lookup[c].reshape(self.caps)

    @property
    def lookup(self) -> np.ndarray:
        """(n_configs, box) state id of each (configuration, flat tau index); -1 = unreachable."""
        return self._lookup
