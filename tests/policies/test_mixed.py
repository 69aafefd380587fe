"""Randomised policies as first-class policies: MixedPolicy evaluates exactly, simulates (seeded),
exports and draws on policy maps."""
from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

import wncs_lp  # noqa: E402
from wncs_lp.chain import PolicyChain  # noqa: E402
from wncs_lp import solve  # noqa: E402
from wncs_lp.errors import ModelError, PolicyError  # noqa: E402
from wncs_lp.evaluate import evaluate  # noqa: E402
from wncs_lp.io import ExportError, load_npz, load_policy_npz, save_npz, save_policy_npz  # noqa: E402
from wncs_lp.policy_grids import mixed_states, policy_grid, policy_pairs, recurrent_mask, slice_grid  # noqa: E402
from wncs_lp.models import build  # noqa: E402
from wncs_lp.policies import MixedPolicy, OptimalPolicy, RandomPolicy, System  # noqa: E402
from wncs_lp.scenario import ConstraintSpec  # noqa: E402
from wncs_lp.simulate import simulate  # noqa: E402
from wncs_lp.viz import plot_policy_map, plot_policy_slice  # noqa: E402
from wncs_lp.viz.maps import MIX_GID, MIX_OFFSET  # noqa: E402

SETS = ["model.allow_idle=true", "tau_cap=6"]


def p12(sets=SETS):
    return wncs_lp.load_scenario(wncs_lp.scenario_path("paper_p12.toml"), sets)


@pytest.fixture(scope="module")
def setup():
    sc = p12()
    mdp = build(sc)
    system = System.from_scenario(sc)
    sol = solve(mdp, "lp", constraints=[ConstraintSpec("send_rate", server=0, max=0.2, label="x")])
    return sc, mdp, system, sol


def half_half(mdp) -> np.ndarray:
    """50/50 between the first two actions of every state that has two or more."""
    k = np.diff(mdp.pair_ptr)
    probs = np.zeros(mdp.n_pairs)
    probs[mdp.pair_ptr[:-1]] = 1.0
    two = np.flatnonzero(k >= 2)
    probs[mdp.pair_ptr[two]] = 0.5
    probs[mdp.pair_ptr[two] + 1] = 0.5
    return probs


def pure(mdp, j: int) -> np.ndarray:
    """Deterministic: local action min(j, last) in every state."""
    return (mdp.pair_ptr[:-1] + np.minimum(j, np.diff(mdp.pair_ptr) - 1)).astype(np.int64)


def gids(ax) -> list:
    return [ln for ln in ax.get_lines() if ln.get_gid() == MIX_GID]


def star_cells(line) -> set:
    """The (tau_i, tau_j) cells the stars of a grid map sit on."""
    return {(round(x - MIX_OFFSET, 6), round(y - MIX_OFFSET, 6)) for x, y in zip(line.get_xdata(), line.get_ydata())}


def legend_texts(ax) -> list[str]:
    return [t.get_text() for t in ax.get_legend().get_texts()]


# ============================================================================ (a) exact = Monte Carlo
def test_constrained_policy_exact_evaluation_agrees_with_monte_carlo(setup):
    sc, mdp, system, sol = setup
    assert sol.ok and sol.n_randomized == 1
    mp = MixedPolicy.from_solution(system, mdp, sol)
    assert mp.randomised and mp.name == "mixed[lp]"
    np.testing.assert_array_equal(mp.randomised_states, sol.randomized_states)
    ev = evaluate(mdp, mp)
    assert ev.randomised and ev.recurrent_classes == 1
    assert ev.gain == pytest.approx(sol.gain, rel=1e-9)
    r = simulate(mp, slots=20_000, reps=20, seed=3, burn_in=500)
    assert abs(r.mean - ev.gain) < 4 * r.stderr, (r.mean, r.stderr, ev.gain)
    # the test has power: making the one randomised state deterministic moves the gain by >> 4 se
    s = int(sol.randomized_states[0])
    for l in mdp.pairs_of(s):
        if sol.policy[l] > 0:
            p = sol.policy.copy()
            p[list(mdp.pairs_of(s))] = 0.0
            p[l] = 1.0
            assert abs(evaluate(mdp, p, system=system).gain - ev.gain) > 8 * r.stderr


def test_heavily_randomised_policy_exact_evaluation_agrees_with_monte_carlo(setup):
    sc, mdp, system, _ = setup
    hp = MixedPolicy(system, mdp, half_half(mdp), name="half")
    assert hp.n_randomised == int((np.diff(mdp.pair_ptr) >= 2).sum()) > 100
    ev = evaluate(mdp, hp)
    r = simulate(hp, slots=20_000, reps=20, seed=11, burn_in=500)
    assert abs(r.mean - ev.gain) < 4 * r.stderr, (r.mean, r.stderr, ev.gain)
    # and the randomisation matters: either pure policy is far from the mix
    for j in (0, 1):
        g = evaluate(mdp, pure(mdp, j), system=system).gain
        assert abs(g - ev.gain) > 20 * r.stderr
    # exact evaluation through on_mdp equals evaluation of the bare array
    assert evaluate(mdp, half_half(mdp), system=system).gain == ev.gain


def test_uniform_mix_is_the_random_policy(setup):
    _, mdp, system, _ = setup
    k = np.diff(mdp.pair_ptr)
    mp = MixedPolicy(system, mdp, np.repeat(1.0 / k, k))
    np.testing.assert_allclose(mp.on_mdp(mdp), RandomPolicy(system).on_mdp(mdp), rtol=0, atol=1e-15)
    assert evaluate(mdp, mp).gain == pytest.approx(evaluate(mdp, RandomPolicy(system)).gain, rel=1e-12)


def test_act_draws_the_state_mix(setup):
    _, mdp, system, sol = setup
    mp = MixedPolicy.from_solution(system, mdp, sol)
    s = int(sol.randomized_states[0])
    R = 200_000
    tau = np.tile(mdp.states.tau[s], (R, 1))
    c = np.full(R, int(mdp.states.config[s]))
    j = mp.act(tau, c, np.random.default_rng(0))
    p = sol.policy[mdp.pair_ptr[s]:mdp.pair_ptr[s + 1]]
    freq = np.bincount(j, minlength=p.size) / R
    assert np.all(freq[p == 0] == 0)
    assert np.all(np.abs(freq - p) < 4 * np.sqrt(p * (1 - p) / R) + 1e-12)
    np.testing.assert_allclose(mp.probabilities(tau[:1], c[:1])[0, :p.size], p)
    # deterministic states always give their one action
    other = np.setdiff1d(np.arange(mdp.n_states), mp.randomised_states)
    jj = mp.act(mdp.states.tau[other], mdp.states.config[other], np.random.default_rng(1))
    assert np.all(sol.policy[mdp.pair_ptr[other] + jj] == 1.0)


def test_mixes_and_describe(setup):
    _, mdp, system, sol = setup
    mp = MixedPolicy.from_solution(system, mdp, sol)
    (m,) = mp.mixes()
    s = int(sol.randomized_states[0])
    assert m["state"] == s and m["label"] == mdp.state_label(s) and m["tau"] == [6, 6]
    assert m["mix"] == sol.mixes(mdp)[0]["mix"] and sum(m["mix"].values()) == pytest.approx(1.0)
    d = mp.describe()
    assert d["randomised"] is True and d["randomised_states"] == 1


# ============================================================================ (b) seeds
def test_same_seed_same_simulation_different_seed_differs(setup):
    _, mdp, system, _ = setup
    hp = MixedPolicy(system, mdp, half_half(mdp))
    a = simulate(hp, slots=2_000, reps=4, seed=5, burn_in=100)
    b = simulate(hp, slots=2_000, reps=4, seed=5, burn_in=100)
    c = simulate(hp, slots=2_000, reps=4, seed=6, burn_in=100)
    assert a.rep_means == b.rep_means and a.utilisation == b.utilisation
    assert a.rep_means != c.rep_means
    # act itself is reproducible from a seed
    st = mdp.states
    j1 = hp.act(st.tau, st.config, np.random.default_rng(9))
    j2 = hp.act(st.tau, st.config, np.random.default_rng(9))
    j3 = hp.act(st.tau, st.config, np.random.default_rng(10))
    np.testing.assert_array_equal(j1, j2)
    assert np.any(j1 != j3)


def test_one_hot_of_a_deterministic_solution_simulates_like_the_optimal_policy(setup):
    sc, mdp, system, _ = setup
    det = solve(mdp, "pi")
    mp = MixedPolicy.from_solution(system, mdp, det)
    probs = mp.on_mdp(mdp)
    assert probs.dtype == np.float64 and np.all(probs[det.policy] == 1.0) and probs.sum() == mdp.n_states
    assert mp.n_randomised == 0
    assert evaluate(mdp, mp).gain == pytest.approx(det.gain, rel=1e-9)
    # the policy's draws come from its own stream: the channel uniforms are common random numbers
    a = simulate(mp, slots=1_000, reps=3, seed=2, burn_in=0)
    b = simulate(OptimalPolicy(mdp, det, system), slots=1_000, reps=3, seed=2, burn_in=0)
    assert a.rep_means == b.rep_means


# ============================================================================ (c) export
def test_policy_export_round_trip(setup, tmp_path):
    sc, mdp, system, sol = setup
    mp = MixedPolicy.from_solution(system, mdp, sol)
    path = save_policy_npz(tmp_path / "pol", mdp, mp, scenario=sc, meta={"bound": 0.2})
    assert path.suffix == ".npz" and sorted(p.name for p in tmp_path.iterdir()) == ["pol.npz"]  # no temp file left
    back = load_policy_npz(path, mdp)
    np.testing.assert_array_equal(back, sol.policy)
    with np.load(path, allow_pickle=False) as z:
        assert str(z["format"]) == "wncs_lp.policy-npz" and str(z["name"]) == "mixed[lp]"
        np.testing.assert_array_equal(z["randomized_states"], sol.randomized_states)
    assert evaluate(mdp, MixedPolicy(system, mdp, back)).gain == pytest.approx(sol.gain, rel=1e-12)
    # arrays, solutions and deterministic policies too; the MDP file carries an optional policy
    np.testing.assert_array_equal(load_policy_npz(save_policy_npz(tmp_path / "a.npz", mdp, sol.policy)), sol.policy)
    det = solve(mdp, "pi")
    onehot = load_policy_npz(save_policy_npz(tmp_path / "d.npz", mdp, det), mdp)
    assert np.all(onehot[det.policy] == 1.0) and onehot.sum() == mdp.n_states
    mpath = save_npz(mdp, tmp_path / "m.npz", scenario=sc, policy=sol)
    np.testing.assert_array_equal(load_policy_npz(mpath, mdp), sol.policy)
    assert load_npz(mpath).n_pairs == mdp.n_pairs
    with pytest.raises(ExportError, match="holds no policy"):
        load_policy_npz(save_npz(mdp, tmp_path / "plain.npz", scenario=sc))
    # another MDP: refused
    other = build(p12(["model.allow_idle=true", "tau_cap=5"]))
    with pytest.raises(ExportError, match="not those of"):
        load_policy_npz(path, other)
    # bad probabilities are refused on save, naming the state
    bad = sol.policy.copy()
    bad[0] = -0.5
    with pytest.raises(ExportError, match="state 0"):
        save_policy_npz(tmp_path / "bad.npz", mdp, bad)
    assert not (tmp_path / "bad.npz").exists()


# ============================================================================ (d) maps
def test_map_marks_exactly_the_randomised_states(setup):
    sc, mdp, system, sol = setup
    s = int(sol.randomized_states[0])
    cfg = int(mdp.states.config[s])
    for pol in (sol, MixedPolicy.from_solution(system, mdp, sol), sol.policy):
        ax = plot_policy_map(mdp, pol, cfg, scenario=sc)
        (line,) = gids(ax)
        assert star_cells(line) == {tuple(float(t) for t in mdp.states.tau[s])}
        assert ax.get_legend().get_title().get_text() == "most likely action"
        mix = [t for t in legend_texts(ax) if t.startswith("mixes at (6, 6): ")]
        assert len(mix) == 1 and "0.71" in mix[0] and "0.29" in mix[0]
        plt.close(ax.figure)
    # the map shows the most likely action of each state
    A, S, _ = policy_grid(mdp, sol, cfg)
    best = policy_pairs(mdp, sol)
    for x, y in zip(*np.nonzero(S >= 0)):
        st = int(S[x, y])
        pairs = np.arange(mdp.pair_ptr[st], mdp.pair_ptr[st + 1])
        assert A[x, y] == mdp.a_indices[pairs[np.argmax(sol.policy[pairs])]] == mdp.a_indices[best[st]]
    # in another configuration: no star, and the legend says where the policy mixes
    ax = plot_policy_map(mdp, sol, "idle", scenario=sc)
    assert not gids(ax) and "randomised in 1 state(s), none on this map" in legend_texts(ax)
    plt.close(ax.figure)


def test_map_of_heavily_randomised_policy_and_shading(setup):
    sc, mdp, system, _ = setup
    probs = half_half(mdp)
    ax = plot_policy_map(mdp, probs, "idle", scenario=sc)
    A, S, _ = policy_grid(mdp, probs, "idle")
    want = {(x + 1.0, y + 1.0) for x, y in zip(*np.nonzero(S >= 0)) if np.diff(mdp.pair_ptr)[S[x, y]] >= 2}
    (line,) = gids(ax)
    assert star_cells(line) == want and len(want) > 1
    assert any(t.startswith(f"mixes at {len(want)} cells, e.g. ") and t.count("0.50") == 2 for t in legend_texts(ax))
    plt.close(ax.figure)
    # ties go to the first action; recurrence is that of the randomised chain
    np.testing.assert_array_equal(policy_pairs(mdp, probs), mdp.pair_ptr[:-1])
    np.testing.assert_array_equal(recurrent_mask(mdp, probs), PolicyChain(mdp, probs).recurrent)
    np.testing.assert_array_equal(mixed_states(mdp, probs), np.flatnonzero(np.diff(mdp.pair_ptr) >= 2))
    assert mixed_states(mdp, solve(mdp, "pi")).size == 0


def test_deterministic_map_has_no_star(setup):
    sc, mdp, _, _ = setup
    det = solve(mdp, "pi")
    ax = plot_policy_map(mdp, det, "idle", scenario=sc)
    assert not gids(ax) and ax.get_legend().get_title().get_text() == "action"
    assert not any("mixes" in t or "randomised" in t for t in legend_texts(ax))
    plt.close(ax.figure)


def test_slice_of_a_randomised_policy_marks_its_mixed_points():
    sc = wncs_lp.load_scenario(wncs_lp.scenario_path("paper_p123.toml"), ["tau_cap=4"])
    mdp = build(sc)
    probs = half_half(mdp)
    total = 7
    A, S, _ = slice_grid(mdp, probs, "idle", total)
    ax = plot_policy_slice(mdp, probs, "idle", total, scenario=sc)
    (line,) = gids(ax)
    n_mixed = int(np.isin(S[A >= 0], mixed_states(mdp, probs)).sum())
    assert len(line.get_xdata()) == n_mixed > 0
    plt.close(ax.figure)


# ============================================================================ (e) bad input
def test_bad_probabilities_give_one_clear_error_naming_the_state(setup):
    _, mdp, system, sol = setup
    s = int(sol.randomized_states[0])
    a, b = int(mdp.pair_ptr[s]), int(mdp.pair_ptr[s + 1])
    label = mdp.state_label(s)
    neg = sol.policy.copy()
    neg[a:b] = 0.0
    neg[a], neg[a + 1] = 1.5, -0.5
    with pytest.raises(PolicyError, match=rf"state {s} \(tau=\(6,6\).*-0\.5.*>= 0") as e:
        MixedPolicy(system, mdp, neg)
    assert label in str(e.value)
    sums = sol.policy.copy()
    sums[a:b] *= 0.9
    with pytest.raises(PolicyError, match=rf"probabilities of state {s} \(.*sum to 0\.9, expected 1") as e:
        MixedPolicy(system, mdp, sums)
    assert label in str(e.value)
    many = sol.policy * 0.5
    with pytest.raises(PolicyError, match=rf"state 0 .*and {mdp.n_states - 1} more state"):
        MixedPolicy(system, mdp, many)
    with pytest.raises(PolicyError, match=rf"shape \({mdp.n_pairs},\)"):
        MixedPolicy(system, mdp, sol.policy[:-1])
    with pytest.raises(PolicyError, match="nan"):
        nan = sol.policy.copy()
        nan[a] = np.nan
        MixedPolicy(system, mdp, nan)
    with pytest.raises(PolicyError, match="not one of its pairs"):
        MixedPolicy(system, mdp, np.zeros(mdp.n_states, dtype=np.int64) + 1)
    with pytest.raises(PolicyError, match="needs an object with a .policy"):
        MixedPolicy.from_solution(system, mdp, object())
    # the maps report the same problem as a ModelError
    with pytest.raises(ModelError, match=rf"state {s}"):
        policy_grid(mdp, sums, "idle")


def test_states_outside_the_mdp_and_other_mdps_are_refused(setup):
    _, mdp, system, sol = setup
    mp = MixedPolicy.from_solution(system, mdp, sol)
    with pytest.raises(PolicyError, match="outside the MDP's box"):
        mp.act(np.array([[7, 1]]), np.array([0]), np.random.default_rng(0))
    missing = np.flatnonzero(mdp.states.lookup < 0)
    if missing.size:  # a (tau, configuration) the MDP does not reach
        c, flat = np.unravel_index(missing[0], mdp.states.lookup.shape)
        tau = np.array(np.unravel_index(flat, mdp.states.caps)) + 1
        with pytest.raises(PolicyError, match="is not in the MDP"):
            mp.act(tau[None, :], np.array([c]), np.random.default_rng(0))
    # the same scenario rebuilt is fine; another cap is not
    np.testing.assert_array_equal(mp.on_mdp(build(p12())), sol.policy)
    other_sc = p12(["model.allow_idle=true", "tau_cap=5"])
    with pytest.raises(PolicyError):
        mp.on_mdp(build(other_sc))
    with pytest.raises(PolicyError):
        MixedPolicy(System.from_scenario(other_sc), mdp, sol.policy)
