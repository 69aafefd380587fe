r"""The long-run averages a constraint can bound, as per-pair vectors of an AoI MDP.

In the occupation measure :math:`x(s, a)` of a stationary policy every long-run average per
slot is linear: :math:`\bar d = \sum_l d_l x_l` for the per-pair value :math:`d_l = d(s_l, a_l)`.
This module gives :math:`d` for each quantity of a ``[[constraint]]`` table
(:data:`wncs_lp.scenario.QUANTITIES`):

==================  ==================================================================
``cost``            :math:`c(s) = \sum_k q_k(\tau_k)`: the MDP's own cost vector
``process_cost``    :math:`q_k(\tau_k)` of one process (its weight included)
``aoi``             :math:`\tau_k` of one process (the capped value in the state)
``send_rate``       :math:`[a_m \ne 0]` for server m, or :math:`[a_m = k]` with a process
                    filter: an update is *sent* (its uplink energy spent) even if the
                    link then loses it. Preemption model: :math:`[a \ne 0]`, a fresh job
                    is started on the one server.
==================  ==================================================================
"""
from __future__ import annotations

import numpy as np

from ..errors import ModelError
from ..mdp import MDP
from ..scenario import QUANTITIES, ConstraintSpec
from .cost import cost_tables

__all__ = ["pair_values", "QUANTITIES"]


def pair_values(mdp: MDP, spec: ConstraintSpec) -> np.ndarray:
    """The per-pair value :math:`d_l` whose occupation-weighted sum is the bounded average.

    Parameters
    ----------
    mdp : MDP
        Built by :func:`wncs_lp.models.build` (its ``states`` decode tau and its
        ``action_table`` the servers' actions).
    spec : ConstraintSpec
        A validated ``[[constraint]]`` table of the MDP's scenario.

    Returns
    -------
    (L,) float array

    Raises
    ------
    ModelError
        The MDP has no decoded states or actions, or the spec names a process or server the
        MDP does not have.
    """
    if spec.quantity not in QUANTITIES:
        raise ModelError(f"unknown quantity {spec.quantity!r}: expected one of {list(QUANTITIES)}")
    if spec.quantity == "cost":
        return np.asarray(mdp.cost, dtype=float).copy()
    st = mdp.states
    if spec.quantity in ("process_cost", "aoi"):
        if st is None or not hasattr(st, "tau"):
            raise ModelError(f"quantity {spec.quantity} needs an MDP with decoded AoI states (build it with wncs_lp.build)")
        tau = np.asarray(st.tau, dtype=np.int64)
        k = spec.process
        if k is None or not 0 <= k < tau.shape[1]:
            raise ModelError(f"quantity {spec.quantity} needs a process in 1..{tau.shape[1]}, got {k}")
        tk = tau[mdp.s_indices, k]
        if spec.quantity == "aoi":
            return tk.astype(float)
        model = getattr(st, "model", None)
        if model is None:
            raise ModelError("quantity process_cost needs the MDP's scenario (an MDP built by wncs_lp.build)")
        return np.asarray(cost_tables(model.scenario)[k], dtype=float)[tk - 1]
    table = mdp.action_table
    if table is None:
        raise ModelError("quantity send_rate needs the MDP's decoded actions (action_table)")
    table = np.atleast_2d(np.asarray(table, dtype=np.int64))
    m = spec.server
    if m is None or not 0 <= m < table.shape[1]:
        raise ModelError(f"quantity send_rate needs a server in 1..{table.shape[1]}, got {m}")
    a = table[mdp.a_indices, m]
    sent = a != 0 if spec.process is None else a == spec.process + 1
    return sent.astype(float)
