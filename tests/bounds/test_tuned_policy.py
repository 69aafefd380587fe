"""Tables tuned for a policy (``wncs_lp.bounds.tuned``): a bound's tables reweighted per class of
processes by a seeded simulation, checked against the exact evaluation of the policies on the
enumerated MDP and against the LP's optimum."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from wncs_lp import scenario_path, solve
from wncs_lp.bounds import policy_gaps, private_bound
from wncs_lp.bounds.policy import BoundPolicy, GroupBoundPolicy, bound_policy
from wncs_lp.bounds.result import GroupTables, ValueTables
from wncs_lp.bounds.tuned import TUNE_SEED_OFFSET, reweighted, table_classes, tune_tables, tuned_policy, tuning_proxy
from wncs_lp.errors import PolicyError
from wncs_lp.evaluate import evaluate
from wncs_lp.models import build
from wncs_lp.models.system import System
from wncs_lp.policies import parse_policy_names
from wncs_lp.scenario import load_scenario
from wncs_lp.simulate import simulate

pytestmark = pytest.mark.filterwarnings("ignore::wncs_lp.errors.ScenarioWarning")

#: A short tuning (the package's default simulates 8 x 2,500 slots a candidate, up to 40 candidates).
SHORT = {"slots": 1_500, "reps": 6, "burn_in": 200, "max_evaluations": 9}


@pytest.fixture(scope="module")
def p123():
    """Processes 1-3 at cap 10 (83,478 states): relaxation 1's bound, whose greedy policy is 6.5% above
    the optimum there, the optimum by the LP and the tuned greedy policy (tuning seed 2)."""
    sc = load_scenario(scenario_path("paper_p123"), ["tau_cap=10"])
    system = System.from_scenario(sc)
    mdp = build(sc)
    bound = private_bound(system)
    tuned = tune_tables(bound, system, "greedy", seed=2, **SHORT)
    return system, mdp, solve(mdp).gain, bound, tuned


def test_the_tuned_greedy_policy_beats_the_untuned_one_by_exact_evaluation(p123):
    system, mdp, g_star, bound, tuned = p123
    plain = evaluate(mdp, bound_policy(bound, system)).gain
    mine = evaluate(mdp, tuned_policy(tuned, system)).gain
    assert plain > 1.05 * g_star  # the premise: relaxation 1's greedy policy is poor here
    assert g_star - 1e-6 <= mine < plain - 0.04 * g_star  # tuning recovers most of it (exact: optimal to 1e-8)
    assert not np.allclose(tuned.weights, 1.0) and tuned.tuned_mean < tuned.base_mean
    # the weights normalised to a mean of 1 over the processes (one process a class here)
    assert np.mean(tuned.weights[tuned.classes]) == pytest.approx(1.0, rel=1e-12)


def test_the_gap_report_tunes_on_its_own_seed_and_evaluates_on_another(p123):
    system, mdp, _, bound, tuned = p123
    report = policy_gaps(bound, system, ["tuned"], exact=False, slots=3_000, reps=6, seed=0, burn_in=200, tune=SHORT)
    row = report.rows[0]
    info = row.detail["tuning"]
    assert info["tuning_seed"] == 0 + TUNE_SEED_OFFSET != row.detail["seed"] == 0
    # reproducible: the report's tuning (seed 2) and the fixture's by hand on the same seed and
    # settings give the same weights to the last bit
    assert info["weights"] == [float(w) for w in tuned.weights] and info["slots"] == SHORT["slots"]
    # the Monte Carlo gain of the tuned policy against its exact evaluation
    exact = evaluate(mdp, tuned_policy(tuned, system)).gain
    assert abs(row.gain - exact) <= 5 * row.detail["stderr"] + 1e-6 * exact
    assert row.gap == pytest.approx((row.gain_upper - bound.lower_bound) / bound.lower_bound, rel=1e-12)


def test_reweighted_tables_are_the_blocks_scaled_and_no_bound(p123):
    system, _, _, bound, _ = p123
    w = np.array([0.5, 2.0, 1.5])
    r = reweighted(bound, w, np.arange(3))
    for k in range(3):
        np.testing.assert_array_equal(r.tables.h[k], w[k] * np.asarray(bound.tables.h[k]))
    assert np.isnan(r.lower_bound) and "nothing" in r.certified_by and r.alternatives == ()
    # a common scale changes no greedy decision (the argmin of a positive multiple)
    rng = np.random.default_rng(5)
    c = rng.integers(0, system.n_configs, 400)
    tau = rng.integers(1, 11, (400, 3))
    same = reweighted(bound, np.full(3, 3.0), np.arange(3))
    np.testing.assert_array_equal(bound_policy(same, system).act(tau, c), bound_policy(bound, system).act(tau, c))
    with pytest.raises(PolicyError, match="positive"):
        reweighted(bound, np.array([1.0, -1.0, 1.0]), np.arange(3))
    with pytest.raises(PolicyError, match="target"):
        tune_tables(bound, system, "index")


def test_classes_follow_the_interchangeable_copies():
    sc = load_scenario(scenario_path("bounds_p1234_twice"), ["tau_cap=3"])
    system = System.from_scenario(sc)
    z = np.zeros((1, 3))
    col = np.zeros(system.n_configs, np.int64)
    per_process = ValueTables(h=(z,) * 8, column=(col,) * 8)
    np.testing.assert_array_equal(table_classes(per_process, system), [0, 1, 2, 3, 0, 1, 2, 3])
    pairs = GroupTables(groups=((0, 4), (1, 5), (2, 6), (3, 7)), h=(z,) * 4, column=(col,) * 4)
    np.testing.assert_array_equal(table_classes(pairs, system), [0, 1, 2, 3])
    mixed = GroupTables(groups=((0, 1), (2, 3), (4, 5), (6, 7)), h=(z,) * 4, column=(col,) * 4)
    np.testing.assert_array_equal(table_classes(mixed, system), [0, 1, 0, 1])


def test_tuning_on_joint_tables_scales_the_built_expectations_exactly(p123):
    """Tables over the joint configuration (relaxations 2 and 4) are tuned by scaling the greedy
    policy's precomputed expectations instead of computing them again: here (no two actions tie to
    rounding) the tuning's mean at the weights it returns is the mean of the tuned policy built from
    scratch, on the same seed, to the last bit. Relaxation 1's tables read on the joint
    configurations stand in for such tables (as one table per process, and as two groups)."""
    system, mdp, g_star, bound, _ = p123
    n = system.n_configs
    joint = tuple(np.asarray(h)[np.asarray(col)] for h, col in zip(bound.tables.h, bound.tables.column))
    per_process = replace(bound, relaxation="joint-configuration",
                          tables=ValueTables(h=joint, column=(np.arange(n),) * 3))
    grouped = replace(bound, relaxation="joint-pairs", tables=GroupTables(
        groups=((0, 1), (2,)), h=(joint[0][:, :, None] + joint[1][:, None, :], joint[2]), column=(np.arange(n),) * 2))
    for res, kind in ((per_process, BoundPolicy), (grouped, GroupBoundPolicy)):
        tuned = tune_tables(res, system, "greedy", seed=2, **SHORT)
        fresh = tuned_policy(tuned, system)
        assert isinstance(fresh, kind) and not np.allclose(tuned.weights, 1.0)
        again = simulate(fresh, slots=SHORT["slots"], reps=SHORT["reps"], seed=2, burn_in=SHORT["burn_in"],
                         control=res.tables.value, progress=False)
        assert again.mean == tuned.tuned_mean
        assert g_star - 1e-6 <= evaluate(mdp, fresh).gain < 1.01 * g_star


def test_the_lookahead_and_the_rollout_are_tuned_for_themselves(p123):
    system, mdp, g_star, bound, _ = p123
    assert parse_policy_names("tuned,tuned_lookahead,tuned_rollout") == ["tuned", "tuned_lookahead", "tuned_rollout"]
    quick = {"slots": 500, "reps": 4, "burn_in": 100, "max_evaluations": 3}
    report = policy_gaps(bound, system, ["tuned_lookahead", "tuned_rollout"], exact=True, tune=quick)
    for row, target in zip(report.rows, ("lookahead", "rollout")):
        assert row.policy == f"tuned-{target}[private-servers]" and row.detail["tuning"]["target"] == target
        assert row.how == "exact" and g_star - 1e-6 <= row.gain <= row.gain_upper < 1.001 * g_star


def test_a_move_must_beat_its_paired_noise_when_asked(p123):
    """``accept_se``: a move kept only when its paired mean difference is below minus that many of its
    standard errors. The fixture's search (accept_se 0) keeps moves on this instance, whose greedy
    policy is 6.5% off; the history's kept means fall, and no finite sample beats an infinite bar."""
    system, _, _, bound, tuned = p123
    means = [m for _, m in tuned.history]
    assert len(means) > 1 and all(b < a for a, b in zip(means, means[1:]))
    stuck = tune_tables(bound, system, "greedy", seed=2, accept_se=1e9, **SHORT)
    assert np.array_equal(stuck.weights, np.ones_like(stuck.weights)) and len(stuck.history) == 1
    assert stuck.base_mean == tuned.base_mean  # the same start on the same seed
    with pytest.raises(PolicyError, match="accept_se"):
        tune_tables(bound, system, "greedy", accept_se=-1.0)


def test_weights_tuned_on_a_cheaper_proxy_serve_the_dearer_policy(p123):
    """``proxy``: the search simulates another policy than the one the weights are for. The
    lookahead with one candidate is the greedy policy itself, so tuning the lookahead on it retraces
    the greedy tuning's search to the last bit; the lookahead then built on those weights (all its
    candidates) is evaluated exactly against the LP's optimum."""
    system, mdp, g_star, bound, tuned = p123
    quick = {"slots": 600, "reps": 4, "burn_in": 100, "max_evaluations": 5}
    greedy = tune_tables(bound, system, "greedy", seed=2, **quick)
    via_k1 = tune_tables(bound, system, "lookahead", seed=2, proxy=1, **quick)
    assert via_k1.target == "lookahead" and via_k1.settings["proxy"] == "lookahead-k1"
    assert not np.allclose(greedy.weights, 1.0)
    np.testing.assert_array_equal(via_k1.weights, greedy.weights)
    assert via_k1.base_mean == greedy.base_mean and via_k1.tuned_mean == greedy.tuned_mean
    pol = tuned_policy(via_k1, system)
    assert pol.name == "tuned-lookahead[private-servers]" and pol.candidates is None  # every action here
    assert g_star - 1e-6 <= evaluate(mdp, pol).gain < 1.001 * g_star
    # "auto" where the lookahead by name takes every action: the target itself; "greedy": the greedy
    assert tuning_proxy(system, "lookahead") == ("lookahead", None) and tuned.settings["proxy"] == "greedy"
    assert tuning_proxy(system, "rollout", "greedy") == ("greedy", None)
    assert tuning_proxy(system, "rollout", 2) == ("rollout", 2)
    with pytest.raises(PolicyError, match="proxy"):
        tuning_proxy(system, "lookahead", 0)
    with pytest.raises(PolicyError, match="target"):
        tuning_proxy(system, "index", "greedy")
