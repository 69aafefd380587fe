"""Tests of the structural verifiers (wncs_lp/verify/): Theorems 1-3.

Each verifier passes a case that satisfies its property by construction and catches a
violation planted on purpose (a perturbed value function or policy, built with
dataclasses.replace on a real solution), with counts checked against brute-force loops.
"""
from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from wncs_lp import scenario_path
from wncs_lp.cli import main
from wncs_lp.errors import ModelError
from wncs_lp.mdp import MDP
from wncs_lp.models import build
from wncs_lp.models.wncs import idle_config
from wncs_lp.scenario import load_scenario
from wncs_lp import solve
from wncs_lp.solvers.certify import q_values
from wncs_lp.verify import (
    CheckReport,
    Tolerance,
    check_consistency,
    check_monotonicity,
    check_threshold,
    policy_context,
    verify_all,
)

P12 = scenario_path("paper_p12.toml")
PRE = scenario_path("paper_preemption_p12.toml")


@pytest.fixture(scope="module")
def p12():
    sc = load_scenario(P12, ["tau_cap=6"])
    mdp = build(sc)
    return sc, mdp, solve(mdp, "pi")


@pytest.fixture(scope="module")
def pre():
    sc = load_scenario(PRE, ["tau_cap=6"])
    mdp = build(sc)
    return sc, mdp, solve(mdp, "pi")


def pair_of(mdp: MDP, s: int, label: tuple) -> int:
    for l in mdp.pairs_of(s):
        if mdp.action_label(l) == tuple(label):
            return l
    raise AssertionError(f"action {label} infeasible in state {s}")


def monotone_bias(mdp: MDP) -> np.ndarray:
    """V = sum_k tau_k + 10 * configuration id: nondecreasing in each tau_k by construction."""
    return mdp.states.tau.sum(axis=1).astype(float) + 10.0 * mdp.states.config


def adjacent_pairs(mdp: MDP) -> list[tuple[int, int]]:
    sp = mdp.states
    out = []
    for s in range(mdp.n_states):
        for k in range(len(sp.caps)):
            tau = sp.tau[s].copy()
            tau[k] += 1
            t = sp.find(tau, int(sp.config[s]))
            if t >= 0:
                out.append((s, t))
    return out


# ============================================================================ Theorem 1
def test_monotonicity_constructed_passes(p12):
    _, mdp, sol = p12
    rep = check_monotonicity(mdp, dataclasses.replace(sol, bias=monotone_bias(mdp)))
    assert isinstance(rep, CheckReport)
    assert rep.holds and rep.violations == 0 and rep.worst is None and rep.examples == ()
    assert rep.checked == len(adjacent_pairs(mdp))
    assert rep.details["dominance"]["violating_states"] == 0


def test_monotonicity_planted_bump(p12):
    sc, mdp, sol = p12
    V = monotone_bias(mdp)
    c0 = idle_config(sc)
    s = mdp.states.find((3, 3), c0)
    assert s >= 0
    V[s] += 100.0
    rep = check_monotonicity(mdp, dataclasses.replace(sol, bias=V), examples=50)
    expected = [(a, b) for a, b in adjacent_pairs(mdp) if a == s]  # V(s) > V(s + e_k) for every k
    assert not rep.holds
    assert rep.violations == len(expected) == 2
    assert {tuple(e.states) for e in rep.examples} == set(expected)
    assert s in rep.worst.states and rep.worst.size == pytest.approx(100.0 - 1.0)
    assert rep.recurrent_violations + (rep.violations - rep.recurrent_violations) == rep.violations
    assert sum(rep.split.values()) == rep.violations
    # every reachable idle state above (3, 3) is dominated by the bump
    above = [t for t in np.flatnonzero(mdp.states.config == mdp.states.config[s])
             if np.all(mdp.states.tau[t] >= mdp.states.tau[s]) and t != s]
    assert rep.details["dominance"]["violating_states"] == len(above)
    j = rep.to_json()
    assert json.loads(json.dumps(j))["violations"] == 2
    assert j["worst"]["labels"][0].startswith("tau=(3,3)")


def test_monotonicity_tolerance_recorded_and_respected(p12):
    sc, mdp, sol = p12
    V = monotone_bias(mdp)
    s = mdp.states.find((3, 3), idle_config(sc))
    V[s] += 1.0 + 1e-3  # V(s) exceeds V(s + e_k) by 1e-3
    scale = V.max() - V.min()
    tight = check_monotonicity(mdp, dataclasses.replace(sol, bias=V), tolerance=Tolerance(0.0, 1e-9))
    loose = check_monotonicity(mdp, dataclasses.replace(sol, bias=V), tolerance=Tolerance(1e-2, 0.0))
    assert tight.violations == 2 and loose.violations == 0
    assert tight.tol == pytest.approx(1e-9 * scale) and tight.value_scale == pytest.approx(scale)
    assert loose.to_json()["atol"] == 1e-2


def test_monotonicity_real_solution_is_consistent(p12, pre):
    for _, mdp, sol in (p12, pre):
        rep = check_monotonicity(mdp, sol)
        assert rep.checked == len(adjacent_pairs(mdp))
        V = sol.bias
        brute = sum(1 for a, b in adjacent_pairs(mdp) if V[a] - V[b] > rep.tol)
        assert rep.violations == brute


# ============================================================================ Theorem 2
def threshold_policy(mdp: MDP, sol, sc, flip: tuple | None = None) -> np.ndarray:
    """(1,2) where tau_1 >= tau_2 else (2,1) in idle states: invariant along e_1 + e_2."""
    pol = sol.policy.copy()
    c0 = mdp.states.config_id(idle_config(sc))
    for s in np.flatnonzero(mdp.states.config == c0):
        t1, t2 = mdp.states.tau[s]
        a = (1, 2) if t1 >= t2 else (2, 1)
        if flip is not None and (t1, t2) == flip:
            a = (a[1], a[0])
        pol[s] = pair_of(mdp, s, a)
    return pol


def ray_cases(mdp: MDP, sc, pol: np.ndarray, q: np.ndarray, tol: float):
    """Brute force: (checked, violations, ties) of Theorem 2 in the idle configuration."""
    c0 = idle_config(sc)
    checked = viol = ties = 0
    for s in np.flatnonzero(mdp.states.config == mdp.states.config_id(c0)):
        a = mdp.action_label(pol[s])
        t = mdp.states.tau[s].copy()
        z = 1
        while True:
            t2 = t + z
            s2 = mdp.states.find(t2, c0)
            if np.any(t2 > np.asarray(mdp.states.caps)):
                break
            z += 1
            if s2 < 0:
                continue
            checked += 1
            if mdp.action_label(pol[s2]) != a:
                gap = abs(q[pair_of(mdp, s2, a)] - q[pol[s2]])
                if gap <= tol:
                    ties += 1
                else:
                    viol += 1
    return checked, viol, ties


def test_threshold_constructed_passes(p12):
    sc, mdp, sol = p12
    pol = threshold_policy(mdp, sol, sc)
    rep = check_threshold(mdp, dataclasses.replace(sol, policy=pol))
    ctx = policy_context(mdp, dataclasses.replace(sol, policy=pol))
    checked, viol, ties = ray_cases(mdp, sc, pol, ctx.q, ctx.tol)
    assert rep.holds and rep.violations == 0 and rep.ties == 0
    assert rep.checked == checked > 0
    assert rep.details["line_gaps"]["count"] == 0


def test_threshold_planted_flip(p12):
    sc, mdp, sol = p12
    pol = threshold_policy(mdp, sol, sc, flip=(4, 2))
    bad = dataclasses.replace(sol, policy=pol)
    rep = check_threshold(mdp, bad, examples=100)
    ctx = policy_context(mdp, bad)
    checked, viol, ties = ray_cases(mdp, sc, pol, ctx.q, ctx.tol)
    s_flip = mdp.states.find((4, 2), idle_config(sc))
    assert not rep.holds
    assert (rep.checked, rep.violations, rep.ties) == (checked, viol, ties)
    assert viol >= 1
    assert any(s_flip in e.states for e in rep.examples)
    # the region of (1, 2) has a gap on the diagonal through (4, 2)
    assert rep.details["line_gaps"]["count"] >= 1
    assert rep.details["lines"]["diagonal tau_1+tau_2"]["gaps"] >= 1
    # an enormous tolerance turns every disagreement into a tie
    lax = check_threshold(mdp, bad, tolerance=Tolerance(1e12, 0.0))
    assert lax.holds and lax.violations == 0 and lax.ties == viol + ties


def test_threshold_real_solution_matches_brute_force(p12):
    sc, mdp, sol = p12
    rep = check_threshold(mdp, sol)
    ctx = policy_context(mdp, sol)
    assert (rep.checked, rep.violations, rep.ties) == ray_cases(mdp, sc, sol.policy, ctx.q, ctx.tol)


# ============================================================================ Theorem 3
def enumerate_paths(mdp: MDP, sol, s: int, tol: float, q: np.ndarray) -> tuple[int, int]:
    """Plain DFS (no memo) over the tree of one start: (paths, violating paths)."""
    sp = mdp.states
    k = mdp.action_label(sol.policy[s])[0]

    def job(x):
        return sp.configs[sp.config[x]][1]

    def walk(x):
        j = mdp.action_label(sol.policy[x])[0]
        pair = int(sol.policy[x])
        if j != 0:
            p0 = pair_of(mdp, x, (0,))
            if abs(q[p0] - q[pair]) > tol:
                return 1, 1
            pair = p0
        if job(x)[1] == 1:
            return 1, 0
        row = mdp.P[pair]
        tot = [walk(int(y)) for y in row.indices]
        return sum(t[0] for t in tot), sum(t[1] for t in tot)

    row = mdp.P[int(sol.policy[s])]
    ys = [int(y) for y in row.indices]
    if job(ys[0]) is None or job(ys[0])[0] != k:
        return 1, 0
    tot = [walk(y) for y in ys]
    return sum(t[0] for t in tot), sum(t[1] for t in tot)


def test_consistency_counts_match_plain_enumeration(pre):
    _, mdp, sol = pre
    rep = check_consistency(mdp, sol, examples=10_000, starts="all")
    ctx = policy_context(mdp, sol)
    starts = [s for s in range(mdp.n_states) if mdp.action_label(sol.policy[s])[0] != 0]
    assert rep.checked == len(starts)
    totals = [enumerate_paths(mdp, sol, s, ctx.tol, ctx.q) for s in starts]
    assert rep.details["paths"] == sum(t[0] for t in totals)
    assert rep.details["violating_paths"] == sum(t[1] for t in totals)
    assert rep.violations == sum(1 for t in totals if t[1] > 0)
    assert rep.holds == (rep.violations == 0)


def test_consistency_non_preemptive_holds_by_construction():
    sc = load_scenario(PRE, ["tau_cap=6", "model.preemptive=false"])
    mdp = build(sc)
    sol = solve(mdp, "pi")
    rep = check_consistency(mdp, sol)
    starts = sum(1 for s in range(mdp.n_states) if mdp.action_label(sol.policy[s])[0] != 0)
    assert rep.holds and rep.violations == 0 and rep.checked == 0  # no job is started by preempting
    every = check_consistency(mdp, sol, starts="all")
    assert every.holds and every.checked == starts > 0
    assert rep.details["starts_by_type"]["preempting"] == 0
    assert rep.details["counterexample"] is None


def test_consistency_planted_preemption(pre):
    _, mdp, sol = pre
    sp = mdp.states
    base = check_consistency(mdp, sol, examples=100_000, starts="all")
    flagged = {e.states[0] for e in base.examples}
    q = q_values(mdp, sol.bias)
    tol = base.tol
    # a start on an idle server, not violating, whose next state serves the job with >= 2 slots
    # left and has the other process's update arrived, where preempting is strictly worse
    target = None
    for s in range(mdp.n_states):
        k = mdp.action_label(sol.policy[s])[0]
        if k == 0 or sp.configs[sp.config[s]][1] is not None or s in flagged:
            continue
        for y in mdp.P[int(sol.policy[s])].indices:
            b, job, _, _ = sp.configs[sp.config[y]]
            j = 3 - k
            if job is not None and job[0] == k and job[1] >= 2 and b[j - 1] and \
                    mdp.action_label(sol.policy[y]) == (0,):
                l = pair_of(mdp, int(y), (j,))
                if q[l] - q[sol.policy[y]] > 10 * tol:
                    target = (s, int(y), j, l)
                    break
        if target:
            break
    assert target is not None
    s, y, j, l = target
    pol = sol.policy.copy()
    pol[y] = l
    rep = check_consistency(mdp, dataclasses.replace(sol, policy=pol), examples=100_000, starts="all")
    assert not rep.holds and rep.violations > base.violations
    # the planted start is on an idle server: outside Theorem 3's own wording (jobs started by preempting)
    scoped = check_consistency(mdp, dataclasses.replace(sol, policy=pol), examples=100_000)
    assert s not in {e.states[0] for e in scoped.examples}
    assert all(e.info["start_type"] == "preempting" for e in scoped.examples)
    ex = next(e for e in rep.examples if e.states[0] == s)
    traj = ex.info["trajectory"]
    assert traj[0]["state"] == s and traj[-1]["state"] == y
    assert traj[-1]["action"] == [j] and "preempts" in traj[-1]["event"]
    assert ex.kind == "preempt" and 0 < ex.size <= 1
    assert rep.details["counterexample"] is not None


def test_consistency_breakdown_by_start_type(pre):
    _, mdp, sol = pre
    rep = check_consistency(mdp, sol, starts="all")
    by = rep.details["by_start_type"]
    kinds = ("idle_server", "preempting", "restarting_own")
    assert by["all"]["checked"] == rep.checked and by["all"]["violations"] == rep.violations
    assert sum(by[k]["checked"] for k in kinds) == rep.checked
    assert sum(by[k]["violations"] for k in kinds) == rep.violations
    assert sum(by[k]["recurrent_violations"] for k in kinds) == rep.recurrent_violations
    assert by["preempting_with_other_available"]["checked"] <= by["preempting"]["checked"]
    for k, v in by.items():
        if v["violations"]:
            assert v["counterexample"]["info"]["trajectory"][0]["state"] == v["counterexample"]["states"][0]
    # Theorem 3's own wording: the headline counts are the preempting starts', with preempting examples
    own = check_consistency(mdp, sol, examples=1_000)
    pre_ = by["preempting"]
    assert (own.checked, own.violations, own.recurrent_violations, own.at_cap_violations) == (
        pre_["checked"], pre_["violations"], pre_["recurrent_violations"], pre_["at_cap_violations"])
    assert own.split["recurrent_below_cap"] == pre_["recurrent_below_cap"]
    assert all(e.info["start_type"] == "preempting" for e in own.examples)
    assert own.unit == "preempting start states" and own.details["scope"] == "preempting"
    with pytest.raises(ModelError, match="starts must be"):
        check_consistency(mdp, sol, starts="some")


def test_recurrent_means_every_state_involved(p12):
    _, mdp, sol = p12
    V = monotone_bias(mdp)
    rec = policy_context(mdp, sol).recurrent
    up = {}
    for a, b in adjacent_pairs(mdp):
        up.setdefault(a, []).append(b)
    # a recurrent state with one recurrent and one transient upper neighbour, if any
    s = next((a for a, bs in up.items() if rec[a] and len({bool(rec[b]) for b in bs}) == 2),
             next(a for a, bs in up.items() if rec[a]))
    V[s] += 1000.0
    rep = check_monotonicity(mdp, dataclasses.replace(sol, bias=V), examples=100)
    assert rep.violations == len(up[s]) >= 1
    assert rep.recurrent_violations == sum(1 for b in up[s] if rec[b])
    assert rep.details["violations_with_some_recurrent_state"] == len(up[s])  # s itself is recurrent


def test_consistency_rejects_wncs(p12):
    _, mdp, sol = p12
    with pytest.raises(ModelError, match="preemption model only"):
        check_consistency(mdp, sol)


def test_structure_needs_state_space():
    P = np.array([[[1.0, 0.0], [0.0, 1.0]], [[0.0, 1.0], [1.0, 0.0]]])
    mdp = MDP.from_dense(P, np.array([[1.0, 2.0], [3.0, 0.5]]))
    sol = solve(mdp, "pi")
    with pytest.raises(ModelError, match="AoI state space"):
        check_monotonicity(mdp, sol)


def test_verify_all_by_kind(p12, pre):
    assert [r.name for r in verify_all(p12[1], p12[2])] == ["monotonicity", "threshold"]
    reps = verify_all(pre[1], pre[2])
    assert [r.name for r in reps] == ["monotonicity", "threshold", "consistency"]
    for r in reps:
        j = r.to_json()
        json.dumps(j)
        assert sum(j["split"].values()) == j["violations"] or r.name == "threshold"


# ============================================================================ CLI
def test_cli_verify_json(capsys):
    rc = main(["verify", str(PRE), "--set", "tau_cap=5", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert rc == 0
    names = [c["name"] for c in out["checks"]]
    assert names == ["monotonicity", "threshold", "consistency"]
    for c in out["checks"]:
        assert isinstance(c["holds"], bool)
        for key in ("checked", "violations", "recurrent_violations"):
            assert isinstance(c[key], int)


def test_cli_verify_table(capsys):
    rc = main(["verify", str(P12), "--set", "tau_cap=5", "--method", "rvi"])
    out = capsys.readouterr().out
    assert rc == 0
    assert "monotonicity" in out and "threshold" in out and ("HOLDS" in out or "FAILS" in out)
