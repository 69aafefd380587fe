"""The model protocol: everything the toolkit knows about one kind of model, in one class.

A model kind (``kind = "wncs"`` or ``"preemption"`` in a scenario file) is one subclass of
:class:`Model`, in one file of this package. Outside :mod:`wncs_lp.models` no module tests a
model kind or reads a configuration tuple by position: policies, verifiers, maps and the
reproduction ask the model instead, through the methods below.

Two kinds of knowledge live here:

* what needs the scenario (the automaton, server acceptance, the busy table, the greedy rule,
  building the MDP): instance methods of ``Model(scenario)``;
* what only reads a configuration or an action label (idle?, the job in service, readable
  names): class methods, so that a model-free MDP (e.g. one read back from a file) can still be
  described through :func:`wncs_lp.models.model_type`.

Class attributes declare which structural checks and policies apply, so a verifier or a
policy asks ``model.has_static_policy`` rather than which model it is.
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from functools import cached_property
from typing import Any, ClassVar, Hashable, Sequence

import numpy as np

from ..errors import ModelError
from ..mdp import MDP
from ..scenario import Scenario
from .assemble import build_aoi_mdp
from .automaton import AutomatonBounds, ConfigAutomaton, ExplorationLimitError, LazyAutomaton, approx_count
from .cost import cost_tables

__all__ = ["Model"]


class Model(ABC):
    """One model kind of the toolkit, bound to a scenario.

    Parameters
    ----------
    scenario : Scenario

    Class attributes
    ----------------
    kind : str
        The scenario's ``model.kind``.
    checks : tuple of str
        The structural checks that apply (names of :mod:`wncs_lp.verify` checks).
    threshold_form : {"rays", "intervals"}
        How the threshold check reads this model: Theorem 2's rays in the idle configuration
        (``"rays"``) or the switching-curve interval property in every configuration with a
        choice (``"intervals"``).
    threshold_configs : {"idle", "all"}
        The threshold check's default configurations.
    has_static_policy : bool
        Whether a static process -> server assignment is a policy of this model.
    """

    kind: ClassVar[str] = ""
    checks: ClassVar[tuple[str, ...]] = ("monotonicity", "threshold")
    threshold_form: ClassVar[str] = "rays"
    threshold_configs: ClassVar[str] = "idle"
    has_static_policy: ClassVar[bool] = False

    def __init__(self, scenario: Scenario):
        self.scenario = scenario

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.scenario.source!r})"

    # ------------------------------------------------------------------ the automaton
    @cached_property
    def automaton(self) -> ConfigAutomaton:
        """The configurations reachable from the initial ones (explored once, then cached).

        Raises
        ------
        ExplorationLimitError
            The automaton is larger than the exploration budget
            (:func:`~wncs_lp.models.automaton.exploration_limit`); the message names the scenario
            and the upper bound of :meth:`automaton_bounds`.
        """
        try:
            return self.explore()
        except ExplorationLimitError as exc:
            bound = self.automaton_bounds().configs
            told = (f"; its upper bound from the delays, processing times and number of processes is "
                    f"{approx_count(bound)} configurations" if bound else "")
            raise ExplorationLimitError(
                f"{self.scenario.source}: {exc}{told}. Every configuration carries at least one state, so the MDP "
                f"would not fit either: shorter delays, fewer processes or servers make it smaller; force=True "
                f"(--force) explores it anyway", exc.explored, exc.edges, exc.places) from None

    def automaton_bounds(self) -> AutomatonBounds:
        """Bounds on the automaton from the scenario alone, before exploring it (the size guard's
        first look); the default knows nothing beyond one initial configuration."""
        return AutomatonBounds()

    @abstractmethod
    def explore(self) -> ConfigAutomaton:
        """Explore the configuration automaton (see :func:`~wncs_lp.models.automaton.explore_configs`)."""

    def lazy_automaton(self) -> LazyAutomaton:
        """The automaton unexplored, to be expanded configuration by configuration as they are met
        (:class:`~wncs_lp.models.automaton.LazyAutomaton`; :meth:`System.lazy`)."""
        raise ModelError(f"{self.scenario.source}: a {self.kind!r} model has no lazily explored automaton")

    @abstractmethod
    def initial_config(self) -> Hashable:
        """The configuration a simulation starts in (every server idle, pipelines empty)."""

    def build(self) -> MDP:
        """The MDP over the reachable (tau, configuration) states of :attr:`automaton`."""
        sc = self.scenario
        return build_aoi_mdp(
            self.automaton,
            sc.tau_caps,
            cost_tables(sc),
            describe_config=self.describe,
            name=f"{self.kind}:{sc.source}",
            meta=self.meta(),
            model=self,
        )

    def meta(self) -> dict[str, Any]:
        """The MDP's metadata (``kind``, ``source``, ``fingerprint``...)."""
        return {"kind": self.kind, "source": self.scenario.source, "fingerprint": self.scenario.fingerprint()}

    # ------------------------------------------------------------------ per configuration
    @abstractmethod
    def accepts(self, config: Hashable) -> tuple[bool, ...]:
        """Per server: whether a new update may be started on / sent to it in ``config``."""

    @abstractmethod
    def busy(self, config: Hashable, labels: np.ndarray) -> np.ndarray:
        """(A, M): probability that server m performs a service step under each action label.

        ``labels`` is the (A, M) array of the configuration's action labels (padding rows -1
        give 0).
        """

    @abstractmethod
    def greedy_label(self, config: Hashable, order: Sequence[int]) -> tuple[int, ...]:
        """The greedy baseline's action label in ``config`` for processes ranked by ``order``
        (0-based, largest current cost first)."""

    def cheaper_routes(self) -> list[str]:
        """Routes that need no enumeration of the state space (for the size guard's message)."""
        return []

    # ------------------------------------------------------------------ private servers
    #: Why this kind has no private-servers relaxation (:mod:`wncs_lp.bounds.private`), in words.
    private_servers_refusal: ClassVar[str] = "its processes do not decompose into private copies of the servers"

    def private_scenario(self, k: int) -> Scenario:
        """Process ``k`` (0-based) alone with its own copy of every server, idling allowed: the
        private system of the private-servers relaxation (the group of ``k`` alone, see
        :meth:`group_scenario`, which raises for a kind without the relaxation)."""
        return self.group_scenario((k,))

    def group_scenario(self, group: Sequence[int]) -> Scenario:
        """The processes of ``group`` (0-based, increasing) alone with their own copy of every
        server, idling allowed: the private system of a group in the grouped private-servers
        relaxation (:mod:`wncs_lp.bounds.grouped`); process ``group[i]`` is its process i + 1.

        Raises
        ------
        ModelError
            The kind has no such relaxation (:attr:`private_servers_refusal` says why).
        """
        raise ModelError(f"{self.scenario.source}: no private-servers bound for a {self.kind!r} model: "
                         f"{self.private_servers_refusal}")

    def project(self, config: Hashable, k: int) -> Hashable:
        """Process ``k``'s own jobs of a joint configuration, as a configuration of
        :meth:`private_scenario` (``k``): the projection on the group of ``k`` alone."""
        return self.project_group(config, (k,))

    def project_group(self, config: Hashable, group: Sequence[int]) -> Hashable:
        """The jobs of the processes of ``group`` in a joint configuration, as a configuration of
        :meth:`group_scenario` (``group``)."""
        raise ModelError(f"{self.scenario.source}: a {self.kind!r} configuration has no per-process projection")

    def project_labels(self, labels: np.ndarray, k: int) -> np.ndarray:
        """The action labels (an (..., M) int array) as seen by process ``k`` alone: what it sends
        where, as labels of :meth:`private_scenario` (``k``)."""
        raise ModelError(f"{self.scenario.source}: a {self.kind!r} action has no per-process projection")

    def project_group_labels(self, labels: np.ndarray, group: Sequence[int]) -> np.ndarray:
        """The action labels (an (..., M) int array) as seen by the processes of ``group`` alone:
        labels of :meth:`group_scenario` (``group``)."""
        raise ModelError(f"{self.scenario.source}: a {self.kind!r} action has no per-group projection")

    def claims(self, config: Hashable, labels: np.ndarray) -> np.ndarray:
        """(A, M, N) 0/1 array: whether process k holds server m's resource under each action
        label of ``config`` (the capacity of the private-servers relaxation)."""
        raise ModelError(f"{self.scenario.source}: a {self.kind!r} model defines no server claims")

    # ------------------------------------------------------------------ reading configurations
    @abstractmethod
    def describe(self, config: Hashable) -> str:
        """A readable one-line description of a configuration."""

    @classmethod
    @abstractmethod
    def is_idle(cls, config: Any) -> bool:
        """Every server idle and every pipeline empty (False for anything not a configuration)."""

    @classmethod
    def job_in_service(cls, config: Any) -> tuple[int, int] | None:
        """``(process, remaining slots)`` of the job in service of a single-server model, else None."""
        return None

    @classmethod
    def arrived(cls, config: Any) -> tuple[int, ...]:
        """Per process (1 = an update arrived and may be started now); empty when not applicable."""
        return ()

    @classmethod
    def complete_partial(cls, text: str, descriptions: Sequence[str], idle_description: str | None) -> str | None:
        """A full description from a partial one (e.g. servers not named are idle), or None."""
        return None

    # ------------------------------------------------------------------ names
    @classmethod
    @abstractmethod
    def action_name(cls, label: tuple[int, ...], config: Any, names: dict) -> str:
        """A readable name of an action label (``config`` may be None: then a generic name)."""

    @classmethod
    @abstractmethod
    def short_action(cls, label: tuple[int, ...], names: dict) -> str:
        """A short legend entry of an action label."""

    @classmethod
    def default_servers(cls, configs: Sequence[Any]) -> list[str] | None:
        """Server names when the scenario is unknown (None: the model has no server list)."""
        return None
