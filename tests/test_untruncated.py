"""The untruncated optimum: the interval [certified truncated optimum, uncapped simulation's upper
confidence limit] against a closed form, and the coupling it rests on (docs/model.md)."""
from __future__ import annotations

import re

import numpy as np
import pytest

from wncs_lp import load_scenario, scenario_path
from wncs_lp.models.system import System
from wncs_lp.workflow import make_policy
from wncs_lp.scenario import scenario_from_dict
from wncs_lp.simulate import simulate
from wncs_lp.workflow import run_scenario
from wncs_lp.untruncated import simulate_uncapped, untruncated_interval


def one_process(a: float, r: float, p: float, cap: int):
    """One scalar process (A = a, R = r) on one U = D = 0, T = 1 server whose update succeeds w.p. p
    (the downlink never fails): the AoI is 1 + a geometric variable."""
    return scenario_from_dict({
        "model": {"kind": "wncs", "allow_idle": False, "distinct": True, "tau_cap": cap},
        "channel": {"success_probability": p},
        "process": [{"name": "x", "A": [[a]], "R": [[r]]}],
        "server": [{"name": "s", "uplink_delay": 0, "downlink_delay": 0, "processing_time": [1], "p_down": 1.0}],
    }, source="closed form")


@pytest.mark.parametrize("a, r, p, cap", [(1.3, 1.0, 0.8, 4), (1.1, 2.0, 0.7, 6)])
def test_the_interval_holds_the_closed_form(a, r, p, cap):
    # P(tau = n) = p (1 - p)^(n - 1), q(n) = r (a^(2n) - 1) / (a^2 - 1): E q = r / (1 - (1 - p) a^2)
    true = r / (1 - (1 - p) * a * a)
    run = run_scenario(one_process(a, r, p, cap), "pi", need_mdp=True)
    # a one-sided 99.9% limit: the statement fails for one seed in a thousand, whatever the stream
    iv = untruncated_interval(run.solution.gain_lower, run.solution, run.mdp, slots=8_000, reps=8, seed=0,
                              confidence=0.999)
    assert iv.lower < true < iv.upper
    assert true - iv.lower > 1e-3 * true  # the cap matters here: the lower end is not the answer
    assert max(iv.max_tau) > cap  # the run went past the cap
    assert "<= g*_inf <=" in iv.message()


@pytest.fixture(scope="module")
def p12():
    sc = load_scenario(scenario_path("paper_p12.toml")).with_overrides({"tau_cap": 8})
    return sc, run_scenario(sc, "pi", need_mdp=True)


def test_coupling_capped_aoi_never_exceeds_the_true_one(p12):
    # same seed: same channel outcomes and, the policy seeing min(tau, cap), the same actions, so
    # every replication's untruncated average is at least its truncated one
    sc, run = p12
    capped = simulate(run.solution, run.mdp, slots=3_000, reps=6, seed=5, burn_in=100, progress=False)
    free, max_tau = simulate_uncapped(run.solution, run.mdp, slots=3_000, reps=6, seed=5, burn_in=100)
    assert np.all(np.array(free.rep_means) >= np.array(capped.rep_means))
    assert np.all(np.array(free.process_means) >= np.array(capped.process_means))
    assert max(max_tau) > 8
    assert free.mean > run.solution.gain_lower


def test_a_policy_with_memory_runs_uncapped(p12):
    sc, run = p12
    system = System.from_scenario(sc)
    rr = make_policy("round_robin", system)
    capped = simulate(rr, slots=2_000, reps=4, seed=1, burn_in=100, progress=False)
    free, _ = simulate_uncapped(rr, slots=2_000, reps=4, seed=1, burn_in=100)
    assert np.all(np.array(free.rep_means) >= np.array(capped.rep_means))


def test_no_policy_no_upper_end():
    iv = untruncated_interval(10.0)
    assert iv.upper == float("inf") and "no upper end" in iv.message()


def test_solve_states_the_interval_and_the_time_at_the_cap_on_both_routes(capsys):
    import json

    from wncs_lp.cli import main

    path = str(scenario_path("paper_p12"))
    assert main(["solve", path, "--set", "tau_cap=8", "--method", "vi", "--untruncated", "--slots", "400",
                 "--reps", "3", "--json"]) == 0
    vi = json.loads(capsys.readouterr().out)
    assert main(["solve", path, "--set", "tau_cap=8", "--method", "matrix-free", "--json"]) == 0
    mf = json.loads(capsys.readouterr().out)
    iv = vi["untruncated"]
    assert iv["lower"] == vi["gain_lower"] and vi["gain"] < iv["upper"] < float("inf")
    # no upper end without --untruncated (JSON null)
    assert mf["untruncated"]["lower"] == mf["gain_lower"] and mf["untruncated"]["upper"] is None
    # the matrix-free route's certified bracket holds the stationary law's mass at the cap
    cap = mf["cap_mass"]
    assert cap["total_lower"] - 1e-9 <= vi["cap_mass"]["total"] <= cap["total_upper"] + 1e-9
    total = sum(vi["cap_mass"]["per_process"])  # E #(processes at their cap)
    assert cap["expected_at_cap_lower"] - 1e-6 <= total <= cap["expected_at_cap_upper"] + 1e-6


def test_a_policy_that_starves_a_process_past_the_cap_is_unbounded():
    # at cap 4 the lab's optimal policy leaves sensor 3 alone once its AoI sits at the cap (it costs
    # nothing more there): without the cap its AoI grows without end; round robin serves everyone
    sc = load_scenario(scenario_path("lab_5sensors"), ["tau_cap=4"])
    run = run_scenario(sc, "vi", need_mdp=True)
    system = System.from_scenario(sc)
    iv = untruncated_interval(run.solution.gain_lower, [make_policy("optimal", system, run.mdp, solution=run.solution),
                                                        make_policy("round_robin", system)],
                              slots=1_500, reps=4, seed=0)
    starved, rr = iv.candidates
    assert starved.upper == float("inf") and "sensor-3" in starved.note
    assert np.isfinite(rr.upper) and iv.policy == "round_robin" and iv.upper == rr.upper
    assert "unbounded without the cap: optimal" in iv.message()


def test_bound_states_the_interval_with_its_bound_below(capsys):
    import json

    from wncs_lp.cli import main

    path = str(scenario_path("paper_p12"))
    assert main(["bound", path, "--set", "tau_cap=8", "--relaxation", "1", "--policy", "--compare", "greedy",
                 "--untruncated", "--slots", "300", "--reps", "3", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    iv = out["untruncated"]
    assert iv["lower"] == out["bound"]["lower_bound"] and iv["lower"] < iv["upper"]
    assert [c["policy"] for c in iv["candidates"]][1:] == ["greedy"]


def test_no_upper_end_where_a_run_without_the_cap_would_under_report():
    """Random arrivals: one process sent every slot on a U = D = 0, T = 1 server with p = 1 has AoI
    1 + A, A geometric(lambda) (docs/model.md's closed form), so g_inf = 1 / lambda = 10 for the
    AoI cost, while the capped system lumps the sensor's age at the cap (g*(3) = 2.71): a run
    without the cap on its configurations would state g*_inf <= 2.72. A cost table stops at its
    last value. Both: the certified lower end only, and the reason names the field."""
    from wncs_lp.errors import ModelError

    def one(**proc):
        return scenario_from_dict({"model": {"kind": "wncs", "tau_cap": 3}, "process": [{"A": [[1.0]], **proc}],
                                   "server": [{"uplink_delay": 0, "downlink_delay": 0, "processing_time": [1],
                                               "p_up": 1.0, "p_down": 1.0}]})

    for sc, field in ((one(cost="aoi", arrival_probability=0.1), "process[1].arrival_probability"),
                      (one(cost=[1, 2, 3, 4]), "process[1].cost")):
        run = run_scenario(sc, "pi", need_mdp=True)
        iv = untruncated_interval(run.solution.gain_lower, run.solution, run.mdp, slots=2_000, reps=4)
        assert iv.lower == run.solution.gain_lower and not iv.upper < 10.0 and field in iv.message()
        with pytest.raises(ModelError, match=re.escape(field)):
            simulate_uncapped(run.solution, run.mdp, slots=100, reps=2)
    assert untruncated_interval(1.0).note == ""


def test_the_growing_cost_stops_at_its_ceiling_without_recomputing_each_step(monkeypatch):
    """A starving process's AoI climbs by one a slot past where doubling its cost table overflows:
    the table grows once to the longest length below MAX_COST (q(n) = (a^(2n) - 1) / (a^2 - 1) in
    closed form here), later AoIs below it are read, and the first past it raises UnboundedCost --
    in a number of table builds logarithmic in the AoI, not one a slot."""
    import math

    from wncs_lp import untruncated
    from wncs_lp.mdp import MAX_COST

    a = 1.3
    proc = one_process(a, 1.0, 0.5, 4).processes[0]
    closed = lambda n: (a ** (2 * n) - 1) / (a * a - 1)  # noqa: E731
    ceiling = max(n for n in range(1, 1000) if closed(n) <= MAX_COST)
    assert math.isfinite(closed(ceiling))
    builds = []
    real = untruncated.process_cost
    monkeypatch.setattr(untruncated, "process_cost", lambda *x, **k: builds.append(x[1]) or real(*x, **k))
    q = untruncated._GrowingCost(proc, 4, "test")
    for n in range(1, ceiling + 1):
        assert q[np.array([n - 1])][0] == pytest.approx(closed(n), rel=1e-12)
    assert q.ceiling == ceiling and len(q) == ceiling
    with pytest.raises(untruncated.UnboundedCost, match=f"reached {ceiling + 1}"):
        q[np.array([ceiling])]
    assert len(builds) <= 3 * math.ceil(math.log2(ceiling)) + 2
