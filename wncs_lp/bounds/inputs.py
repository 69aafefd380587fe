"""What enters the bounds: a :class:`~wncs_lp.models.system.System` checked, and every private
chain checked against it.

A bound is only as good as the system it reads. Relaxation 2 reads the System's automaton and
cost tables; relaxations 1 and 3 rebuild every process's (or group's) private system from the
scenario's fields. So a System edited by hand (``dataclasses.replace(system, q=...)``, an
automaton of one's own, a Model whose server step was patched) could be bounded as another
system without a word. Two checks stop that:

* :func:`bound_system` -- where a Scenario or System enters a bound: every field of the System
  checked (types, caps, the cost tables' shapes and values, the automaton's outcome
  probabilities); cost tables other than the scenario's are **honoured**: the System is rewritten
  with a scenario whose processes carry those tables (``cost = [...]``, weight 1), so the private
  chains read them too.
* :func:`check_private_chains` -- the validity condition of relaxations 1 and 3 itself: from
  every joint pair (C, a) the processes of a group must move exactly as in their private system
  under the projected action -- the distribution of (projected next configuration, the group's
  delivery ages) equal to the private pair's. Per-link probabilities, random arrivals and cost
  families pass it by construction; a System whose automaton does not come from its scenario's
  fields fails it, and the bound refuses it by name (relaxation 2 still honours it).
"""
from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from ..errors import ScenarioError, WncsError
from ..mdp import MAX_COST
from ..models import Model, model_for
from ..models.cost import cost_tables
from ..models.system import System
from ..scenario import Scenario

__all__ = ["bound_system", "check_private_chains"]

#: Largest difference of probabilities accepted between a joint pair's marginal on a group and
#: the group's private pair (sums of a few products of probabilities: round-off is ~1e-16).
PROJECTION_TOL = 1e-12


def _refuse(field: str, what: str) -> WncsError:
    return WncsError(f"{field}: {what}")


def bound_system(obj: Any) -> System:
    """The System a bound works on: a Scenario's, or a System checked field by field.

    Cost tables that differ from the scenario's (a System made with
    ``dataclasses.replace(system, q=...)``) are honoured: the result's scenario gives every
    process its table as ``cost = [...]`` (weight 1), so relaxations 1 and 3 read them as
    relaxation 2 does.

    Raises
    ------
    WncsError
        Not a Scenario or System, or a System field that does not fit (named: ``System.caps``,
        ``System.q[k]``, ``System.model``, ``System.automaton``, ``System.n_actions``), among them
        a cost table that is not a valid scenario cost table (negative, decreasing).
    """
    if isinstance(obj, Scenario):
        return System.from_scenario(obj)
    if not isinstance(obj, System):
        raise WncsError(f"expected a Scenario or a System, got {type(obj).__name__}")
    system = obj
    sc = system.scenario
    if not isinstance(sc, Scenario):
        raise _refuse("System.scenario", f"expected a Scenario, found {type(sc).__name__}")
    mine = getattr(system.model, "scenario", None)
    if not isinstance(system.model, Model) or system.model.kind != sc.model.kind or not (
            mine is sc or (isinstance(mine, Scenario) and mine.fingerprint() == sc.fingerprint())):
        raise _refuse("System.model", "expected the Model of the System's own scenario (models.model_for(scenario)); "
                                      "build the System with System.from_scenario")
    N = sc.n_processes
    caps = np.asarray(system.caps)
    if caps.shape != (N,) or tuple(int(c) for c in caps) != sc.tau_caps:
        raise _refuse("System.caps", f"expected the scenario's AoI caps {sc.tau_caps}, found {caps.tolist()}")
    q = system.q
    if not isinstance(q, (tuple, list)) or len(q) != N:
        raise _refuse("System.q", f"expected one cost table per process ({N}), found {type(q).__name__}"
                                  + (f" of {len(q)}" if isinstance(q, (tuple, list)) else ""))
    for k, table in enumerate(q):
        t = np.asarray(table)
        if t.shape != (sc.tau_caps[k],) or not np.issubdtype(t.dtype, np.number):
            raise _refuse(f"System.q[{k}]", f"expected q_{k + 1}(1..{sc.tau_caps[k]}), {sc.tau_caps[k]} numbers, "
                                            f"found shape {t.shape}")
        if not np.all(np.abs(t) <= MAX_COST):
            raise _refuse(f"System.q[{k}]", f"expected finite costs of magnitude at most {MAX_COST:g}")
    _check_automaton(system)
    mine = cost_tables(sc)
    if all(np.array_equal(np.asarray(a, float), b) for a, b in zip(q, mine)):
        return system
    return _with_costs(system)


def _check_automaton(system: System) -> None:
    if system.is_lazy:  # expanded on demand by its own model's step (checked above): no stored tables to audit
        return
    auto = system.automaton
    nC = len(auto.configs)
    if len(auto.actions) != nC or len(auto.outcomes) != nC:
        raise _refuse("System.automaton", f"{nC} configurations but {len(auto.actions)} action lists and "
                                          f"{len(auto.outcomes)} outcome lists")
    if np.asarray(system.n_actions).tolist() != [len(a) for a in auto.actions]:
        raise _refuse("System.n_actions", "does not count the automaton's actions of every configuration")
    flat = auto.flat(system.n_processes)
    prob = np.asarray(flat.out_prob, float)
    if prob.size and not (np.all(prob >= 0) and np.all(prob <= 1)):
        raise _refuse("System.automaton", "outcome probabilities outside [0, 1]")
    totals = np.add.reduceat(prob, flat.out_ptr[:-1]) if prob.size else np.zeros(0)
    bad = np.flatnonzero(np.abs(totals - 1.0) > 1e-9)
    if bad.size:
        a = int(bad[0])
        c = int(np.searchsorted(flat.act_ptr, a, side="right") - 1)
        raise _refuse("System.automaton", f"the outcome probabilities of configuration {c}, action "
                                          f"{auto.actions[c][a - int(flat.act_ptr[c])]} sum to {totals[a]:.17g}, not 1")
    if flat.deltas.size and flat.deltas.shape[1] != system.n_processes:
        raise _refuse("System.automaton", f"delivery vectors of {flat.deltas.shape[1]} entries for "
                                          f"{system.n_processes} processes")


def _with_costs(system: System) -> System:
    """The System with a scenario whose processes carry the System's cost tables (weight 1): the
    same automaton (costs do not change it), so nothing is explored again."""
    sc = system.scenario
    fields: dict[str, Any] = {}
    for k, table in enumerate(system.q):
        fields[f"process.{k + 1}.cost"] = [float(x) for x in np.asarray(table, float)]
        fields[f"process.{k + 1}.weight"] = 1.0
    try:
        new = sc.replace(**fields)
    except ScenarioError as exc:  # the tables of one's own, read as the scenario's cost tables
        k = exc.field.split("]")[0].split("[")[-1] if exc.field.startswith("process[") else "?"
        raise _refuse(f"System.q[{int(k) - 1 if k.isdigit() else k}]",
                      f"the bounds honour cost tables of one's own as the processes' cost field "
                      f"(docs/scenarios.md), which this one is not: {exc.expected}") from None
    model = model_for(new)
    if system.is_lazy:  # explored again on demand from the edited scenario (costs do not change the moves)
        return System.from_scenario(new, model, explore="lazy")
    model.__dict__["automaton"] = system.automaton  # Model.automaton is a cached property
    return System.from_automaton(new, system.automaton, model)


def _group_labels(model: Model, labels: np.ndarray, group: Sequence[int]) -> np.ndarray:
    """The joint action labels as the group's private system sees them (member i is i + 1)."""
    out = np.zeros(labels.shape, dtype=np.int64)
    for i, k in enumerate(group):
        out += (i + 1) * model.project_labels(labels, k)
    return out


def check_private_chains(system: System, groups: Sequence[Sequence[int]], chains: Sequence[Any],
                         columns: Sequence[np.ndarray], relaxation: str) -> None:
    """Refuse the bound unless every group moves in the joint system as in its private chain.

    Parameters
    ----------
    system : System
    groups : sequence of tuples of int
        The groups (0-based processes; one process each for relaxation 1).
    chains : sequence of PrivateChain
        ``chains[i]`` the private chain of ``groups[i]`` (possibly shared by identical groups).
    columns : sequence of int arrays
        ``columns[i][c]``: the private configuration id of group i's projection of joint
        configuration c.
    relaxation : str
        For the message.

    Raises
    ------
    WncsError
        A group whose private chain does not reproduce its joint transitions (the message names
        the process(es), a configuration and an action, and why that can happen).
    """
    if system.is_lazy:  # its own model's moves, expanded on demand: the private chains are built from the same model
        return
    fl = system.automaton.flat(system.n_processes)
    n_pairs = int(fl.act_ptr[-1])
    pair_c = np.repeat(np.arange(system.n_configs), np.diff(fl.act_ptr))
    pair_j = np.arange(n_pairs) - fl.act_ptr[pair_c]
    n_out = np.diff(fl.out_ptr)
    edge_pair = np.repeat(np.arange(n_pairs), n_out)
    joint_delta = np.asarray(fl.deltas, np.int64)[fl.out_delta]
    for group, chain, col in zip(groups, chains, columns):
        group = tuple(int(k) for k in group)
        pauto = chain.model.automaton
        pfl = pauto.flat(len(group))
        # the private pair of every joint pair
        labels = _group_labels(system.model, system.labels, group)[pair_c, pair_j]  # (pairs, M)
        col = np.asarray(col, np.int64)
        combos, inv = np.unique(np.column_stack([col[pair_c], labels]), axis=0, return_inverse=True)
        index = [{tuple(a): j for j, a in enumerate(acts)} for acts in pauto.actions]
        found = np.array([index[int(row[0])].get(tuple(int(x) for x in row[1:]), -1) for row in combos], np.int64)
        local = found[inv.ravel()]
        if np.any(local < 0):
            p = int(np.flatnonzero(local < 0)[0])
            raise _mismatch(system, group, relaxation, int(pair_c[p]), int(pair_j[p]),
                            "the projected action is not an action of the private system")
        ppair = pfl.act_ptr[col[pair_c]] + local
        # joint edges: (pair, private next configuration, the group's delivery ages), + prob
        pdelta = np.asarray(pfl.deltas, np.int64)[pfl.out_delta] if pfl.out_delta.size else np.zeros((0, len(group)))
        p_lo, p_n = pfl.out_ptr[ppair], np.diff(pfl.out_ptr)[ppair]
        p_edges = np.repeat(p_lo - np.r_[0, np.cumsum(p_n)[:-1]], p_n) + np.arange(int(p_n.sum()))
        rows = np.concatenate([joint_delta[:, list(group)], pdelta[p_edges]])
        _, did = np.unique(rows, axis=0, return_inverse=True)
        did = did.ravel()
        pairs = np.concatenate([edge_pair, np.repeat(np.arange(n_pairs), p_n)])
        nxt = np.concatenate([col[fl.out_nxt], pfl.out_nxt[p_edges]])
        w = np.concatenate([fl.out_prob, -pfl.out_prob[p_edges]])
        nd = int(did.max()) + 1 if did.size else 1
        nn = int(max(nxt.max(initial=0), 0)) + 1
        key = (pairs.astype(np.int64) * nn + nxt) * nd + did
        uniq, inv = np.unique(key, return_inverse=True)
        diff = np.bincount(inv.ravel(), weights=w, minlength=uniq.size)
        bad = np.flatnonzero(np.abs(diff) > PROJECTION_TOL)
        if bad.size:
            p = int(uniq[bad[0]] // (nd * nn))
            raise _mismatch(system, group, relaxation, int(pair_c[p]), int(pair_j[p]),
                            f"an outcome's probability differs by {abs(diff[bad[0]]):.3g} between the joint system "
                            f"and the private chain")


def _mismatch(system: System, group: tuple, relaxation: str, c: int, j: int, why: str) -> WncsError:
    who = (f"process {group[0] + 1}" if len(group) == 1 else
           "the group of processes " + ", ".join(str(k + 1) for k in group))
    cfg = system.automaton.configs[c]
    return WncsError(
        f"System.automaton: {relaxation} cannot honour this system: {who} does not move in it as in its private "
        f"system built from the scenario's fields ({why}; configuration #{c} '{system.model.describe(cfg)}', action "
        f"{system.automaton.actions[c][j]}). The System's automaton or its Model was changed by hand (an edited "
        f"automaton, a patched server step), so the private chains would bound another system; write the system's "
        f"per-link probabilities, costs and arrivals as scenario fields (docs/scenarios.md), or use relaxation 2, "
        f"which reads the System's own automaton")
