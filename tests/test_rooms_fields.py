"""Every room honours each of a researcher's own fields -- per-link probabilities, cost families,
random arrivals -- or refuses it by name (issue 35's table of rooms x fields).

For each field one small system uses it (``tests/reference/own_systems.py``'s ``small_scenario``); each room runs on that system and its result is
checked against an independent quantity of the *same* system (the exact optimum and exact
evaluations of the MDP, itself checked against a reference builder in
``tests/models/test_own_systems.py``), and, where the room computes a number, against the same
room on the system without the field: a room that silently ignored the field would give the
number of the system without it.
"""
from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import pytest

import reference.own_systems as ref
import wncs_lp
from wncs_lp import io as export, policy_grids as maps
from wncs_lp.bounds import bound_policy, lower_bound
from wncs_lp.errors import WncsError
from wncs_lp.evaluate import evaluate
from wncs_lp.mdp import MDP
from wncs_lp.models.system import System
from wncs_lp.policies import GreedyPolicy, RandomPolicy, StaticPolicy, SuboptimalPolicy
from wncs_lp.policies.baselines import MaxAgePolicy, MaxWeightPolicy, RoundRobinPolicy
from wncs_lp.simulate import simulate

ROOMS = ["exact", "matrix-free", "relaxation 1", "relaxation 2", "relaxation 3", "suboptimal", "static", "greedy",
         "max_age", "max_weight", "round_robin", "bound policy", "simulator", "maps", "environment", "exports"]
#: (room, field) -> why the room refuses the field (None: honoured). Every room honours every field.
REFUSED: dict[tuple[str, str], str] = {}


class Case:
    """One system: scenario, MDP, System, exact optimum."""

    def __init__(self, field: str):
        self.scenario = ref.small_scenario(field)
        self.mdp = wncs_lp.build(self.scenario)
        self.system = System.from_scenario(self.scenario)
        self.optimum = wncs_lp.solve(self.mdp, "lp")
        self._memo: dict = {}

    def once(self, key, fn):
        if key not in self._memo:
            self._memo[key] = fn()
        return self._memo[key]

    def gain_of(self, policy) -> float:
        return float(evaluate(self.mdp, policy.on_mdp(self.mdp)).gain)


@pytest.fixture(scope="module")
def cases():
    return {field: Case(field) for field in ref.FIELDS}


def _bound(case: Case, rel: int) -> float:
    return case.once(("bound", rel), lambda: lower_bound(case.scenario, rel).lower_bound)


def _policy(case: Case, room: str):
    if room == "suboptimal":
        return case.once(room, lambda: SuboptimalPolicy(case.system))
    if room == "static":
        return StaticPolicy(case.system, (0, 1))
    if room == "greedy":
        return GreedyPolicy(case.system)
    if room == "max_age":
        return MaxAgePolicy(case.system)
    if room == "max_weight":
        return MaxWeightPolicy(case.system)
    return case.once(room, lambda: bound_policy(lower_bound(case.scenario, 1), case.system))


def _room_value(case: Case, room: str) -> float:
    """The number the room computes on the case's system (checked against the exact ones), once."""
    return case.once(("value", room), lambda: _compute(case, room))


def _compute(case: Case, room: str) -> float:
    g = case.optimum
    if room == "exact":
        states, model = ref.build(case.scenario)
        s, a, c, P, n = ref.to_arrays(states, model)
        g_ref = wncs_lp.solve(MDP.from_arrays(s, a, c, P, n), "pi").gain
        assert g.status == "optimal" and g.gain == pytest.approx(g_ref, rel=1e-10)
        return g.gain
    if room == "matrix-free":
        sol = wncs_lp.solve(case.scenario, "matrix-free")
        assert sol.status == "optimal" and sol.gain == pytest.approx(g.gain, rel=1e-9)
        return sol.gain
    if room.startswith("relaxation"):
        b = _bound(case, int(room[-1]))
        assert 0.9 * g.gain < b <= g.gain_upper * (1 + 1e-12)
        return b
    if room == "round_robin":  # a policy with memory: its exact per-process chains
        gain = RoundRobinPolicy(case.system).separable_evaluation().gain
        assert gain >= g.gain_lower * (1 - 1e-12)
        return gain
    if room in ("suboptimal", "static", "greedy", "max_age", "max_weight", "bound policy"):
        pol = _policy(case, room)
        gain = case.gain_of(pol)
        assert gain >= g.gain_lower * (1 - 1e-12)
        if room == "suboptimal":  # Lemma 2: the base policy's gain from the per-process chains
            assert pol.base_gain == pytest.approx(case.gain_of(RandomPolicy(case.system)), rel=1e-9)
        return gain
    if room == "simulator":
        sim = simulate(StaticPolicy(case.system, (0, 1)), slots=6_000, reps=6, seed=3, burn_in=200)
        exact = case.gain_of(StaticPolicy(case.system, (0, 1)))
        assert abs(sim.mean - exact) <= 4.5 * sim.stderr
        return exact
    if room == "maps":
        actions, states, _ = maps.policy_grid(case.mdp, g, "idle", axes=(1, 2))
        ok = states >= 0
        np.testing.assert_array_equal(actions[ok], case.mdp.a_indices[g.policy[states[ok]]])
        # the title's p: the one success probability of every link, none when the links differ
        per_link = case.scenario.source == "<links>"
        assert maps.map_names(case.mdp, case.scenario)["p"] == (None if per_link else 0.9)
        return float(actions[ok].sum())
    if room == "environment":  # a rollout of the static policy: its long-run cost, within 6%
        from wncs_lp.env import WncsEnv

        env, pol = WncsEnv(case.scenario), StaticPolicy(case.system, (0, 1))
        obs, _ = env.reset(seed=5)
        total, steps = 0.0, 5_000
        for _ in range(steps):
            j = int(pol.act(obs["tau"][None, :], np.array([obs["config"]]))[0])
            obs, reward, *_ = env.step(j)
            total -= reward
        exact = case.gain_of(pol)
        assert total / steps == pytest.approx(exact, rel=0.06)
        return exact
    if room == "exports":
        folder = Path(tempfile.mkdtemp(prefix="wncs_rooms_"))
        export.save_npz(case.mdp, folder / "m.npz", scenario=case.scenario)
        back = export.load_npz(folder / "m.npz")
        export.save_drn(case.mdp, folder / "m.drn", scenario=case.scenario)
        assert f"@nr_states\n{case.mdp.n_states}" in (folder / "m.drn").read_text()
        return wncs_lp.solve(back, "lp").gain
    raise AssertionError(room)


@pytest.mark.parametrize("field", ["links", "costs", "arrivals"])
@pytest.mark.parametrize("room", ROOMS)
def test_room_honours_or_refuses_field(cases, room, field):
    case = cases[field]
    why = REFUSED.get((room, field))
    if why is not None:
        with pytest.raises(WncsError, match=why):
            _room_value(case, room)
        return
    value = _room_value(case, room)
    plain = _room_value(cases["none"], room)
    if room != "maps":  # a map may coincide; the others are numbers of another system
        assert abs(value - plain) > 1e-6 * abs(plain), f"{room} gives the same number with and without {field}"
