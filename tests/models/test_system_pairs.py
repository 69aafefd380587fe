"""The System's pair-indexed tables against the explored automaton, and the lazily explored System
against the enumerated one: same actions, same outcomes, same simulations."""
from __future__ import annotations

import sys
from dataclasses import replace

import numpy as np
import pytest

from wncs_lp import scenario_path
from wncs_lp.errors import ModelError, PolicyError, SizeLimitError
from wncs_lp.models import system as system_module
from wncs_lp.models.system import System
from wncs_lp.workflow import make_policy
from wncs_lp.scenario import load_scenario, scenario_from_dict
from wncs_lp.simulate import simulate

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

pytestmark = pytest.mark.filterwarnings("ignore::wncs_lp.errors.ScenarioWarning")


@pytest.fixture(scope="module")
def fog():
    """The paper's processes 1, 3, 4 on three servers (bounds_p1234_fog's) at cap 4: the enumerated
    and the lazy system (1,434 configurations)."""
    raw = tomllib.loads(scenario_path("bounds_p1234_fog").read_text())
    raw["process"] = [raw["process"][i] for i in (0, 2, 3)]
    raw["model"]["tau_cap"] = 4
    sc = scenario_from_dict(raw, source="<fog, processes 1, 3, 4>")
    return sc, System.from_scenario(sc), System.from_scenario(sc, explore="lazy")


def _outcomes(system: System, c: int, j: int) -> dict:
    """{(next configuration object, delivery vector): probability} of local action j in c, from the pairs."""
    pt = system.pairs
    p = pt.first[c] + j
    real = pt.prob[p] > 0
    return {(system.automaton.configs[n], tuple(pt.deltas[d])): pr
            for n, d, pr in zip(pt.nxt[p][real], pt.delta[p][real], pt.prob[p][real])}


def test_pairs_are_the_automatons_edges(fog):
    _, full, _ = fog
    auto, pt = full.automaton, full.pairs
    assert pt.n_pairs == sum(len(a) for a in auto.actions) and np.array_equal(pt.count, full.n_actions)
    for c in range(0, full.n_configs, 7):
        for j, outs in enumerate(auto.outcomes[c]):
            p = pt.first[c] + j
            assert tuple(pt.labels[p]) == tuple(auto.actions[c][j])
            want = {(auto.configs[n], tuple(d)): pr for n, d, pr in outs}
            assert _outcomes(full, c, j) == pytest.approx(want, rel=0, abs=0)
            assert np.isinf(pt.cum[p, len(outs) - 1]) and np.all(np.diff(pt.cum[p, :len(outs) - 1]) > 0)
            np.testing.assert_array_equal(pt.busy[p], full.model.busy(auto.configs[c], pt.labels[p][None])[0])


def test_padded_outcome_tables_refuse_past_their_limit(monkeypatch):
    small = System.from_scenario(load_scenario(scenario_path("paper_p12"), ["tau_cap=3"]))
    monkeypatch.setattr(system_module, "OUTCOME_TABLES_MAX_BYTES", 1000)
    with pytest.raises(SizeLimitError, match="System.pairs"):
        small.outcome_tables


def test_the_lazy_system_expands_the_same_automaton(fog):
    _, full, lazy = fog
    assert lazy.is_lazy and not full.is_lazy and lazy.n_expanded == 1
    rng = np.random.default_rng(0)
    for _ in range(4):  # expand a frontier of what is known, four times
        known = np.flatnonzero(lazy.n_actions == 0)[:40]
        assert lazy.expand(np.r_[known, rng.integers(0, lazy.n_configs, 5)]) >= known.size
    done = np.flatnonzero(lazy.n_actions > 0)
    assert done.size > 100
    for c in done:
        f = full.automaton.index[lazy.automaton.configs[c]]
        assert lazy.automaton.actions[c] == full.automaton.actions[f]
        for j in range(lazy.n_actions[c]):
            assert _outcomes(lazy, c, j) == _outcomes(full, f, j)
        assert np.array_equal(lazy.accepts[c], full.accepts[f])


@pytest.mark.parametrize("name", ["greedy", "static", "relaxation"])
def test_a_simulation_on_the_lazy_system_is_the_enumerated_one(fog, name):
    """Same policy, same seed: the lazily explored system draws the same outcomes in the same order."""
    from wncs_lp.bounds import ValueTables, bound_policy, private_bound

    _, full, lazy = fog
    if name == "relaxation":  # the lazy bound's tables (its capacity an inequality) on both systems
        res = private_bound(lazy)
        a = bound_policy(replace(res, tables=ValueTables(res.tables.h, private_bound(full).tables.column)), full)
        b = bound_policy(res, lazy)
    else:
        a, b = make_policy(name, full), make_policy(name, lazy)
    x = simulate(a, slots=300, reps=4, seed=5, burn_in=20, progress=False)
    y = simulate(b, slots=300, reps=4, seed=5, burn_in=20, progress=False)
    assert x.rep_means == y.rep_means and x.utilisation == y.utilisation


def test_policies_that_need_the_whole_automaton_refuse_a_lazy_system(fog):
    lazy = fog[2]
    for name in ("suboptimal", "random"):
        with pytest.raises(PolicyError, match="whole configuration automaton.*greedy, static"):
            make_policy(name, lazy)


def test_auto_explores_lazily_what_is_too_large_to_enumerate():
    sc = load_scenario(scenario_path("bounds_fog12"))
    s = System.from_scenario(sc, explore="auto")  # 762,073 x 1,320 by the model's bounds: at once, unexplored
    assert s.is_lazy and s.n_expanded == 1 and s.max_actions == 12 * 11 * 10


def test_auto_explores_lazily_past_its_edge_budget(monkeypatch):
    sc = load_scenario(scenario_path("paper_p12"), ["tau_cap=4"])
    assert not System.from_scenario(sc, explore="auto").is_lazy
    monkeypatch.setattr(system_module, "AUTO_EDGES", 10)  # the exploration stops; the system is lazy instead
    s = System.from_scenario(sc, explore="auto")
    assert s.is_lazy and s.n_expanded == 1
    with pytest.raises(ModelError, match="explore must be"):
        System.from_scenario(sc, explore="some")
