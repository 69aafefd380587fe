"""Policies of one's own and the documented policy forms: ``Policy.from_function``, ``sigma`` vs
pair indices (``sigma_to_pairs`` / ``pairs_to_sigma``), and every form taken by ``evaluate``,
``simulate`` and ``evaluate_policy``."""
from __future__ import annotations

import numpy as np
import pytest

from wncs_lp import MDP, scenario_path
from wncs_lp.errors import PolicyError
from wncs_lp.evaluate import evaluate
from wncs_lp.models import build
from wncs_lp.policies import (Configuration, Policy, StaticPolicy, System, as_policy, default_assignment,
                              pairs_to_sigma, sigma_to_pairs)
from wncs_lp.scenario import load_scenario
from wncs_lp.simulate import simulate
from wncs_lp import solve
from wncs_lp.solvers.dp import evaluate_policy


@pytest.fixture(scope="module")
def p12():
    sc = load_scenario(scenario_path("paper_p12"), ["tau_cap=7"])
    mdp = build(sc)
    return sc, System.from_scenario(sc), mdp, solve(mdp, "pi")


def uneven_mdp() -> MDP:
    """Three states; state 1 has only action 2 and state 2 only actions 1 and 2, so its pair
    indices and its actions differ (pairs 0,1 | 2 | 3,4)."""
    s = [0, 0, 1, 2, 2]
    a = [0, 1, 2, 1, 2]
    c = [1.0, 2.0, 0.5, 3.0, 1.0]
    P = [[0, 1, 0], [0, 0, 1], [1, 0, 0], [0, 1, 0], [1, 0, 0]]
    return MDP.from_arrays(s, a, c, np.array(P, dtype=float), 3)


# ----------------------------------------------------------------------------- the converters
def test_sigma_and_pairs_by_hand():
    mdp = uneven_mdp()
    # by hand: state 0 takes action 1 (pair 1), state 1 action 2 (pair 2), state 2 action 1 (pair 3)
    np.testing.assert_array_equal(sigma_to_pairs(mdp, np.array([1, 2, 1])), [1, 2, 3])
    np.testing.assert_array_equal(pairs_to_sigma(mdp, np.array([0, 2, 4])), [0, 2, 2])
    with pytest.raises(PolicyError, match=r"sigma\[1\] = 0 is not an action of state 1; its actions .* are 2"):
        sigma_to_pairs(mdp, np.array([0, 0, 1]))
    with pytest.raises(PolicyError, match=r"shape \(3,\)"):
        sigma_to_pairs(mdp, np.array([0, 2]))
    with pytest.raises(PolicyError, match="integer array"):
        sigma_to_pairs(mdp, np.array([0.0, 2.0, 1.0]))
    with pytest.raises(PolicyError, match=r"policy\[1\] = 0 is a pair of state 0; expected a pair index of state 1"):
        pairs_to_sigma(mdp, np.array([0, 0, 3]))
    with pytest.raises(PolicyError, match="out of range"):
        pairs_to_sigma(mdp, np.array([0, 2, 7]))


def test_the_converters_invert_each_other(p12):
    _, _, mdp, sol = p12
    np.testing.assert_array_equal(pairs_to_sigma(mdp, sol.policy), sol.sigma)
    np.testing.assert_array_equal(sigma_to_pairs(mdp, sol.sigma), sol.policy)
    # the action of each state read straight off the MDP's pairs
    np.testing.assert_array_equal(mdp.a_indices[sol.policy], sol.sigma)


def test_sigma_passed_as_pairs_says_so(p12):
    _, _, mdp, sol = p12
    with pytest.raises(PolicyError, match="pass it as sigma="):
        evaluate(mdp, sol.sigma)


# ----------------------------------------------------------------------------- every form, one answer
def test_every_form_evaluates_to_the_solution_gain(p12):
    _, system, mdp, sol = p12
    forms = [evaluate(mdp, sol).gain, evaluate(mdp, sol.policy).gain, evaluate(mdp, sigma=sol.sigma).gain,
             evaluate(mdp, Policy.from_sigma(mdp, sol.sigma)).gain, evaluate(mdp, sol.policy, system).gain,
             evaluate_policy(mdp, sigma=sol.sigma).gain, evaluate_policy(mdp, sol).gain]
    # the certificate of the solve is the independent reference
    for g in forms:
        assert sol.gain_lower - 1e-9 * sol.gain <= g <= sol.gain_upper + 1e-9 * sol.gain


def test_simulate_takes_arrays_with_their_mdp(p12):
    _, _, mdp, sol = p12
    runs = [simulate(sol.policy, mdp, slots=3000, reps=8, seed=5, burn_in=300, progress=False),
            simulate(mdp=mdp, sigma=sol.sigma, slots=3000, reps=8, seed=5, burn_in=300, progress=False),
            simulate(sol, mdp, slots=3000, reps=8, seed=5, burn_in=300, progress=False)]
    # one policy, one seed: the same sample path whatever the form
    assert runs[0].mean == runs[1].mean == runs[2].mean
    # Monte Carlo against the exact gain: within 4 standard errors
    assert abs(runs[0].mean - sol.gain) <= 4 * runs[0].stderr


def test_an_array_without_its_mdp_is_one_clear_error(p12):
    _, _, mdp, sol = p12
    with pytest.raises(PolicyError, match="needs the MDP it lives on"):
        simulate(np.asarray(sol.policy), slots=10, reps=2, progress=False)
    with pytest.raises(PolicyError, match="needs the MDP it lives on"):
        as_policy(sigma=sol.sigma)
    with pytest.raises(PolicyError, match="exactly one way"):
        evaluate(mdp, sol.policy, sigma=sol.sigma)
    with pytest.raises(PolicyError, match=rf"\({mdp.n_pairs},\) pair probabilities"):
        evaluate(mdp, np.ones(5) / 5)


# ----------------------------------------------------------------------------- from a function
def static_rule(system: System, assignment):
    """The static policy as docs/policies.md states it, written against the Configuration view:
    an accepting server gets its assigned process of largest current cost (ties: lower index);
    a server with none assigned that may not idle gets the largest-cost process not yet sent."""
    sc = system.scenario
    N = sc.n_processes

    def f(tau, conf: Configuration):
        cost = [system.q[k][tau[k] - 1] for k in range(N)]
        order = sorted(range(N), key=lambda k: (-cost[k], k))
        idle_ok = sc.model.allow_idle or sum(conf.accepts) > N
        label, sent = [0] * len(conf.accepts), set()
        for m, ok in enumerate(conf.accepts):
            k = next((k for k in order if ok and assignment[k] == m), None)
            if k is not None:
                label[m] = k + 1
                sent.add(k)
        for m, ok in enumerate(conf.accepts):
            if ok and label[m] == 0 and not idle_ok:
                k = next((k for k in order if k not in sent), None)
                if k is not None:
                    label[m] = k + 1
                    sent.add(k)
        return tuple(label)

    return f


def test_a_function_policy_is_the_static_policy(p12):
    sc, system, mdp, _ = p12
    assignment = default_assignment(sc)
    own = Policy.from_function(system, static_rule(system, assignment), name="my static")
    ref = StaticPolicy(system, assignment)
    np.testing.assert_array_equal(own.on_mdp(mdp), ref.on_mdp(mdp))
    assert evaluate(mdp, own).gain == pytest.approx(evaluate(mdp, ref).gain, rel=1e-12)
    assert evaluate(mdp, own).policy == "my static"


def test_the_function_is_called_once_per_state(p12):
    _, system, mdp, _ = p12
    calls = []

    def first_action(tau, conf):
        calls.append((tau, conf.id))
        return conf.actions[0]

    pol = Policy.from_function(mdp, first_action)  # the MDP's system
    pairs = pol.on_mdp(mdp)
    np.testing.assert_array_equal(pairs, mdp.pair_ptr[:-1])  # the first action of every state
    assert len(calls) == mdp.n_states == len(set(calls))
    simulate(pol, slots=500, reps=4, seed=1, burn_in=10, progress=False)
    assert len(calls) == mdp.n_states  # every state a run visits is a state of the MDP: no new call


def test_the_function_sees_the_model_readable_configuration(p12):
    _, system, mdp, _ = p12
    seen = {}

    def record(tau, conf):
        seen[conf.id] = conf
        return conf.actions[-1]

    Policy.from_function(system, record).on_mdp(mdp)
    assert len(seen) == system.n_configs
    for c, conf in seen.items():
        raw = system.automaton.configs[c]
        assert conf.description == system.model.describe(raw) == str(conf)
        assert conf.idle == system.model.is_idle(raw)
        assert conf.accepts == tuple(bool(x) for x in system.accepts[c])
        assert conf.servers == tuple(s.name for s in system.scenario.servers)
    idle = [conf for conf in seen.values() if conf.idle]
    assert idle and all(all(conf.accepts) for conf in idle)  # an idle configuration accepts everywhere


def test_an_unknown_label_names_the_state_and_the_allowed_labels(p12):
    _, system, mdp, _ = p12
    pol = Policy.from_function(system, lambda tau, conf: (9, 9))
    with pytest.raises(PolicyError, match=r"returned \(9, 9\) in state tau=\(\d+, \d+\), configuration \d+ \[.*\]; "
                                          r"the action labels allowed there are \("):
        pol.on_mdp(mdp)
    with pytest.raises(PolicyError, match="returned 'remote'"):
        Policy.from_function(system, lambda tau, conf: "remote").on_mdp(mdp)
    with pytest.raises(PolicyError, match="needs a function"):
        Policy.from_function(system, 3)


# ----------------------------------------------------------------------------- a saved policy
def test_a_saved_policy_reads_back_in_its_form(p12, tmp_path):
    from wncs_lp.io import ExportError, save_policy_npz
    from wncs_lp.policies import MixedPolicy, TablePolicy
    from wncs_lp.io import policy_from_file

    sc, _, mdp, sol = p12
    det = policy_from_file(save_policy_npz(tmp_path / "det.npz", mdp, sol.policy, scenario=sc), mdp)
    assert isinstance(det, TablePolicy) and det.name == "det"
    np.testing.assert_array_equal(det.on_mdp(mdp), sol.policy)
    # a half-half mix of the optimal and the first action of every state: its exact gain is that of
    # the same probabilities evaluated directly
    probs = np.zeros(mdp.n_pairs)
    probs[sol.policy] += 0.5
    probs[mdp.pair_ptr[:-1]] += 0.5
    mixed = policy_from_file(save_policy_npz(tmp_path / "mix.npz", mdp, probs, scenario=sc), mdp)
    assert isinstance(mixed, MixedPolicy)
    assert evaluate(mdp, mixed).gain == pytest.approx(evaluate(mdp, probs, System.from_scenario(sc)).gain, rel=1e-12)
    other = build(load_scenario(scenario_path("paper_p12"), ["tau_cap=8"]))
    with pytest.raises(ExportError, match="are not those of"):
        policy_from_file(tmp_path / "det.npz", other)


def test_a_function_policy_on_the_preemption_model():
    # the preemption model's labels have one entry; the last allowed label of every state is its
    # last pair (the labels are listed in the MDP's action order)
    sc = load_scenario(scenario_path("paper_preemption_p12"), ["tau_cap=7"])
    mdp = build(sc)
    pol = Policy.from_function(sc, lambda tau, conf: conf.actions[-1])
    np.testing.assert_array_equal(pol.on_mdp(mdp), mdp.pair_ptr[1:] - 1)
    one = Policy.from_function(sc, lambda tau, conf: conf.actions[0][0])  # a bare int is a one-entry label
    np.testing.assert_array_equal(one.on_mdp(mdp), mdp.pair_ptr[:-1])


def test_a_matrix_free_solution_is_a_policy_too(p12):
    import wncs_lp

    sc, _, mdp, sol = p12
    mf = wncs_lp.solve(sc, "matrix-free")
    ev = evaluate(mdp, mf)
    # the exact gain of the matrix-free policy on the enumerated MDP lies in both certificates
    assert ev.policy == "matrix-free" and within(mf, ev.gain) and within(sol, ev.gain)
    run = simulate(mf, slots=3000, reps=8, seed=2, burn_in=300, progress=False)
    assert abs(run.mean - ev.gain) <= 4 * run.stderr


def within(sol, g: float) -> bool:
    return sol.gain_lower - 1e-9 * sol.gain <= g <= sol.gain_upper + 1e-9 * sol.gain
