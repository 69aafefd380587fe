"""The claim resource of relaxation 1 and the projections it is read through.

The identity that makes the bound valid: in every state-action pair of the joint system the
claims on server m of all processes, each read off that process's projection in its private
system, sum to 1 (no idling and N >= M) or to at most 1 (otherwise). And the claim itself against
an independent walk along the server's timeline (tests/bounds/bounds_reference.py).
"""
from __future__ import annotations

import numpy as np
import pytest
from bounds_reference import SHAPES, claims_brute, shape

from wncs_lp import scenario_path
from wncs_lp.errors import ModelError
from wncs_lp.models import build, model_for
from wncs_lp.scenario import load_scenario


def _pairs(mdp):
    """The distinct (configuration id, action label) of an enumerated MDP's pairs."""
    cfg = np.asarray(mdp.states.config)[mdp.s_indices]
    uniq = np.unique(np.stack([cfg, mdp.a_indices], axis=1), axis=0)
    return [(int(c), tuple(int(x) for x in mdp.action_table[a])) for c, a in uniq]


def _projected_sums(scenario):
    """(M,) sums over processes of the private claims, for every pair of the enumerated joint MDP."""
    mdp = build(scenario)
    model = model_for(scenario)
    configs = mdp.states.configs
    privates = [model_for(model.private_scenario(k)) for k in range(scenario.n_processes)]
    known = [{cfg: i for i, cfg in enumerate(p.automaton.configs)} for p in privates]
    sums = []
    for c, label in _pairs(mdp):
        total = np.zeros(scenario.n_servers)
        for k, priv in enumerate(privates):
            own = model.project(configs[c], k)
            assert own in known[k], f"projection of {configs[c]} on process {k + 1} not in its private system"
            own_label = model.project_labels(np.array([label]), k)
            assert tuple(own_label[0]) in priv.automaton.actions[known[k][own]], "projected action not feasible"
            total += priv.claims(own, own_label)[0, :, 0]
        sums.append(total)
    return np.array(sums)


@pytest.mark.parametrize("name", SHAPES)
def test_claims_of_the_projections_sum_to_one(name):
    sc = shape(name)
    sums = _projected_sums(sc)
    assert sums.shape[1] == sc.n_servers
    assert np.all(sums <= 1)
    if not sc.model.allow_idle and sc.n_processes >= sc.n_servers:
        assert np.all(sums == 1), f"{name}: a pair whose claims do not sum to 1"
    else:  # an accepting server left unused claims nothing
        assert np.any(sums == 0)


def test_claims_sum_to_one_on_the_paper_four_processes():
    sums = _projected_sums(load_scenario(scenario_path("paper_p1234"), ["tau_cap=4"]))
    assert sums.size and np.all(sums == 1)


@pytest.mark.parametrize("name", ["paper", "u2", "u3", "3x3", "three-servers"])
def test_claims_against_a_walk_along_the_server_timeline(name):
    sc = shape(name)
    model = model_for(sc)
    auto = model.automaton
    checked = 0
    for cfg, actions in zip(auto.configs, auto.actions):
        labels = np.array(actions, dtype=np.int64)
        got = model.claims(cfg, labels)  # (A, M, N)
        for j, a in enumerate(actions):
            np.testing.assert_array_equal(got[j], claims_brute(sc, cfg, a), err_msg=f"{cfg} {a}")
            checked += 1
    assert checked > 50


def test_private_scenario_is_the_process_alone_with_idling():
    sc = shape("u3")
    priv = model_for(sc).private_scenario(1)
    assert priv.n_processes == 1 and priv.model.allow_idle
    assert [s.processing_time for s in priv.servers] == [(1,), (2,)]
    assert [(s.uplink_delay, s.downlink_delay, s.p_up, s.p_down) for s in priv.servers] == \
        [(3, 0, (0.9,), (0.9,)), (0, 1, (0.9,), (0.9,))]
    np.testing.assert_array_equal(priv.processes[0].A, sc.processes[1].A)


def test_preemption_model_has_no_projection():
    sc = load_scenario(scenario_path("paper_preemption_p12"), ["tau_cap=7"])
    with pytest.raises(ModelError, match="preemption"):
        model_for(sc).private_scenario(0)
