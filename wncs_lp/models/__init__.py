"""Models: scenario -> :class:`~wncs_lp.models.base.Model` -> :class:`~wncs_lp.mdp.MDP`.

One module per model kind (:mod:`.wncs`, :mod:`.preemption`), each a :class:`Model` subclass
that owns everything the toolkit knows of that kind; the rest is shared:

* :mod:`.automaton` -- the configuration automaton and its exploration;
* :mod:`.statespace` -- the decoded (tau, configuration) view of a state space;
* :mod:`.assemble` -- the vectorised assembly of the MDP over the AoI box;
* :mod:`.cost` -- the AoI-to-MSE cost tables;
* :mod:`.system` -- the automaton and costs without the box (policies, simulation);
* :mod:`.guard` -- size and memory estimates before a build.

Only this package looks at ``scenario.model.kind``: :func:`model_for` is the one dispatch.
"""
from __future__ import annotations

from ..errors import ModelError
from ..mdp import MDP
from ..scenario import Scenario
from .base import Model
from .preemption import PreemptionModel
from .wncs import WncsModel

__all__ = ["MODELS", "Model", "build", "model_for", "model_type"]

#: The model classes by ``kind``.
MODELS: dict[str, type[Model]] = {WncsModel.kind: WncsModel, PreemptionModel.kind: PreemptionModel}


def model_for(scenario: Scenario) -> Model:
    """The :class:`Model` of a scenario (dispatching on ``scenario.model.kind``)."""
    if not isinstance(scenario, Scenario):
        hint = (" (an MDP is already built: solve it)" if isinstance(scenario, MDP) else
                " (load it first: wncs_lp.load_scenario(path) or wncs_lp.scenario_from_dict(raw))")
        raise ModelError(f"expected a Scenario, got {type(scenario).__name__}{hint}")
    cls = MODELS.get(scenario.model.kind)
    if cls is None:
        raise ModelError(f"{scenario.source}: no model of kind {scenario.model.kind!r}; expected one of {', '.join(MODELS)}")
    return cls(scenario)


def model_type(mdp: MDP) -> type[Model]:
    """The model class of a built MDP.

    The model the state space was built from; for an MDP without one (e.g. read back from a
    file) the ``kind`` of its metadata, else the shape of its configurations (Section II when
    nothing tells).
    """
    states = getattr(mdp, "states", None)
    model = getattr(states, "model", None)
    if model is not None:
        return type(model)
    kind = mdp.meta.get("kind") if isinstance(mdp.meta, dict) else None
    if kind in MODELS:
        return MODELS[kind]
    configs = getattr(states, "configs", None) or [None]
    if getattr(configs[0], "_fields", ()) == ("b", "job", "stack", "down"):
        return PreemptionModel
    return WncsModel


def build(scenario: Scenario, model: Model | None = None, *, force: bool = False, need_lp: bool = False) -> MDP:
    """Build the MDP of a scenario, after the size guard.

    Parameters
    ----------
    scenario : Scenario
    model : Model, optional
        A :class:`Model` of the scenario whose explored automaton to reuse.
    force : bool
        Build even when the size guard estimates more memory than half of what is available
        now (:func:`wncs_lp.models.guard.check_size`); the estimate itself is cheap (the
        automaton times per-axis AoI sets, no state enumerated).
    need_lp : bool
        Count the memory of an interior-point LP solve too (for ``method="lp"``/``"lp-cvxpy"``).

    Warns
    -----
    ScenarioWarning
        A degenerate scenario (:meth:`~wncs_lp.scenario.Scenario.degenerate_warnings`).

    Raises
    ------
    SizeLimitError
        (a :class:`~wncs_lp.errors.WncsError`) the estimate exceeds the limit: the message gives
        the estimated states, pairs, nonzeros and memory, the limit, and cheaper routes;
        ``exc.estimate`` holds the :class:`~wncs_lp.models.guard.SizeEstimate`.
    """
    import warnings

    from ..errors import ScenarioWarning
    from .guard import check_size

    model = model if model is not None else model_for(scenario)  # refuses anything but a Scenario
    for text in scenario.degenerate_warnings():
        warnings.warn(text, ScenarioWarning, stacklevel=2)
    check_size(scenario, force=force, need_lp=need_lp, model=model)
    return model.build()
