"""One verdict rule for structural checks (wncs_lp/verify/verdict.py), shared by `wncs-lp verify`
and the reproduction, and the switching-curve form of the threshold check (claim C9).

The rule is checked on hand-made counts; the switching-curve check on policies planted in one
configuration of a real preemption model (strict Q-values, so ties play no part), against a plain
re-implementation that walks every axis-parallel and diagonal line of the AoI box.
"""
from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from wncs_lp import scenario_path
from wncs_lp.cli import main
from wncs_lp.models import build
from wncs_lp.scenario import load_scenario
from wncs_lp import solve
from wncs_lp.verify import check_threshold, policy_context
from wncs_lp.verify.verdict import (DEPENDS, ERROR, FAILS, HOLDS, combine, structural_verdict, verdict_of)

PRE = scenario_path("paper_preemption_p12.toml")


# ============================================================================ the rule
def test_rule_on_hand_made_counts():
    assert structural_verdict(True, 0) == HOLDS
    assert structural_verdict(False, 0) == DEPENDS  # violations, none recurrent and below the cap
    assert structural_verdict(False, 3) == FAILS
    assert verdict_of({"holds": False, "split": {"recurrent_below_cap": 0, "transient_at_cap": 5}}) == DEPENDS
    assert verdict_of({"holds": False, "split": {"recurrent_below_cap": 1}}) == FAILS
    assert verdict_of({"holds": True, "split": {}}) == HOLDS


def test_combining_instances():
    assert combine([HOLDS, HOLDS]) == HOLDS
    assert combine([HOLDS, DEPENDS]) == DEPENDS
    assert combine([DEPENDS, FAILS, HOLDS]) == FAILS  # one counterexample decides
    assert combine([]) == ERROR and combine([HOLDS, ERROR]) == ERROR


@pytest.fixture(scope="module")
def pre8():
    sc = load_scenario(PRE, ["tau_cap=8"])
    mdp = build(sc)
    return sc, mdp, solve(mdp, "pi")


def test_check_report_verdict_follows_the_rule(pre8):
    _, mdp, sol = pre8
    from wncs_lp.verify import check_consistency

    rep = check_consistency(mdp, sol, starts="all")
    assert rep.violations > 0
    for split, want in (({"recurrent_below_cap": 0, "transient_at_cap": 1}, DEPENDS),
                        ({"recurrent_below_cap": 2}, FAILS)):
        r = dataclasses.replace(rep, holds=False, split=split)
        assert r.verdict == want == r.to_json()["verdict"] == verdict_of(r.to_json())
    assert dataclasses.replace(rep, holds=True).verdict == HOLDS


# ============================================================================ the command line
def test_verify_exits_1_on_fails_and_0_on_depends(monkeypatch, capsys, pre8):
    import wncs_lp.verify as verify

    real = verify.verify_all

    def planted(mdp, sol, **kw):
        reps = real(mdp, sol, **kw)
        return [dataclasses.replace(reps[0], holds=False, violations=1, recurrent_violations=1,
                                    split={"recurrent_below_cap": 1, "recurrent_at_cap": 0,
                                           "transient_below_cap": 0, "transient_at_cap": 0})] + reps[1:]

    monkeypatch.setattr(verify, "verify_all", planted)
    rc = main(["verify", str(PRE), "--set", "tau_cap=6", "--json"])
    cap = capsys.readouterr()
    out = json.loads(cap.out)
    assert rc == 1 and out["checks"][0]["verdict"] == FAILS and out["verdict"] == FAILS
    assert "monotonicity FAILS" in cap.err
    monkeypatch.setattr(verify, "verify_all", real)
    rc = main(["verify", str(PRE), "--set", "tau_cap=8", "--json"])
    out = json.loads(capsys.readouterr().out)
    verdicts = [c["verdict"] for c in out["checks"]]
    assert FAILS not in verdicts and DEPENDS in verdicts and rc == 0  # violations, none recurrent below the cap
    for c in out["checks"]:
        assert c["verdict"] == verdict_of(c)  # the printed verdict is the rule applied to the printed numbers


def test_verify_table_prints_depends_and_the_rule(capsys):
    rc = main(["verify", str(PRE), "--set", "tau_cap=8"])
    text = capsys.readouterr().out
    assert rc == 0
    line = next(l for l in text.splitlines() if l.startswith("consistency"))
    assert line.split()[1] == DEPENDS
    assert "verdicts: HOLDS: no violation; FAILS:" in text


# ============================================================================ the switching-curve check
def _planted(mdp, sol, pattern):
    """A context whose policy in the Fig. 11 configuration (process 2 in service, process 1 arrived)
    is ``pattern(t1, t2) -> bool`` (True: preempt with process 1), strictly preferred by 10."""
    ctx = policy_context(mdp, sol)
    sp = mdp.states
    c = sp.config_id(sp.model.serving_config(2, (1, 0)))
    feas = np.flatnonzero(ctx.offsets[c] >= 0)
    labels = {tuple(ctx.action(a)): int(a) for a in feas}
    keep, start1 = labels[(0,)], labels[(1,)]
    q, act, q_pi = ctx.q.copy(), ctx.act.copy(), ctx.q_pi.copy()
    grid = sp.lookup_grid(c)
    for (i, j), s in np.ndenumerate(grid):
        if s < 0:
            continue
        a = start1 if pattern(i + 1, j + 1) else keep
        other = keep if a == start1 else start1
        base = mdp.pair_ptr[s]
        q[base + ctx.offsets[c, a]] = 0.0
        q[base + ctx.offsets[c, other]] = 10.0
        act[s], q_pi[s] = a, 0.0
    return dataclasses.replace(ctx, q=q, act=act, q_pi=q_pi), c, grid, act


def _reference(grid, act):
    """Plain walk over the lines: (axis gaps, axis reversals, diagonal gaps) for the two actions."""
    caps = grid.shape
    gaps = revs = dgaps = 0

    def line_cells(start, d):
        out, (i, j) = [], start
        while i < caps[0] and j < caps[1]:
            if grid[i, j] >= 0:
                out.append(int(act[grid[i, j]]))
            i, j = i + d[0], j + d[1]
        return out

    def n_gaps(seq):
        n = 0
        for a in set(seq):
            pos = [k for k, x in enumerate(seq) if x == a]
            n += any(seq[k] != a for k in range(pos[0], pos[-1] + 1))
        return n

    for d in ((1, 0), (0, 1)):
        starts = [(0, j) for j in range(caps[1])] if d == (1, 0) else [(i, 0) for i in range(caps[0])]
        orders = []
        for st in starts:
            seq = line_cells(st, d)
            if len(seq) >= 3:
                gaps += n_gaps(seq)
            acts = sorted(set(seq))
            if len(acts) == 2:
                a, b = acts
                pa = [k for k, x in enumerate(seq) if x == a]
                pb = [k for k, x in enumerate(seq) if x == b]
                if pa[-1] < pb[0]:
                    orders.append(1)
                elif pb[-1] < pa[0]:
                    orders.append(-1)
        if orders.count(1) and orders.count(-1):
            revs += min(orders.count(1), orders.count(-1))
    for st in [(i, 0) for i in range(caps[0])] + [(0, j) for j in range(1, caps[1])]:
        seq = line_cells(st, (1, 1))
        if len(seq) >= 3:
            dgaps += n_gaps(seq)
    return gaps, revs, dgaps


def test_monotone_staircase_passes_though_diagonals_switch_twice(pre8):
    _, mdp, sol = pre8
    # preempt iff tau_1 >= f(tau_2), f nondecreasing with a jump of 4: a monotone switching curve
    ctx, c, grid, act = _planted(mdp, sol, lambda t1, t2: t1 >= (2 if t2 <= 3 else 6))
    rep = check_threshold(mdp, sol, ctx=ctx, configs=[c])
    gaps, revs, dgaps = _reference(grid, act)
    assert (gaps, revs) == (0, 0) and dgaps > 0
    assert rep.holds and rep.violations == 0 and rep.verdict == HOLDS
    assert rep.details["diagonal_gaps"]["count"] == dgaps  # described, not counted


def test_reversed_switching_order_is_caught(pre8):
    _, mdp, sol = pre8
    # every row switches once (an interval along tau_1), but odd rows keep-then-preempt and even rows
    # preempt-then-keep: no monotone curve
    ctx, c, grid, act = _planted(mdp, sol, lambda t1, t2: (t1 >= 4) if t2 % 2 else (t1 <= 3))
    rep = check_threshold(mdp, sol, ctx=ctx, configs=[c])
    gaps, revs, dgaps = _reference(grid, act)
    assert revs > 0 and gaps > 0
    assert rep.details["reversals"]["count"] == revs
    assert rep.details["gaps"]["count"] == gaps
    assert rep.violations == gaps + revs and not rep.holds
    assert {e.kind for e in rep.examples} <= {"line-gap", "order-reversal"}
    kinds = {v["kind"] for v in [e.to_json() for e in rep.examples]}
    assert "order-reversal" in kinds or len(rep.examples) == 10
    assert rep.verdict == structural_verdict(False, rep.split["recurrent_below_cap"])


def test_one_row_reversed_is_one_reversal(pre8):
    _, mdp, sol = pre8
    # a monotone curve except one row (tau_2 = 5) that switches the other way round
    ctx, c, grid, act = _planted(mdp, sol, lambda t1, t2: (t1 <= 3) if t2 == 5 else (t1 >= 4))
    rep = check_threshold(mdp, sol, ctx=ctx, configs=[c])
    gaps, revs, _ = _reference(grid, act)
    assert revs == 1 == rep.details["reversals"]["count"]
    rev = next(e for e in rep.examples if e.kind == "order-reversal")
    taus = [tuple(int(x) for x in mdp.states.tau[s]) for s in rev.states]
    assert taus[0][1] == taus[1][1] == 5  # the reversed row's own switch
    assert abs(taus[2][1] - 5) == 1  # against the nearest row of the majority order
    assert rev.size == pytest.approx(10.0)


# ============================================================================ witnesses and weights
def _gap_witnesses(grid, act, tau, cap):
    """Plain walk over the axis lines: for each (line, action) with a gap, whether some witness
    (i < g < j, the action at i and j, another at g) has no state with an AoI at the cap."""
    out = []
    for axis in (0, 1):
        for fixed in range(grid.shape[1 - axis]):
            cells = [grid[(k, fixed) if axis == 0 else (fixed, k)] for k in range(grid.shape[axis])]
            cells = [int(s) for s in cells if s >= 0]
            seq = [int(act[s]) for s in cells]
            for a in sorted(set(seq)):
                pos = [k for k, x in enumerate(seq) if x == a]
                if not any(seq[k] != a for k in range(pos[0], pos[-1] + 1)):
                    continue
                below = any(seq[g] != a and all(tau[cells[t]].max() < cap for t in (i, g, j))
                            for i in pos for j in pos for g in range(i + 1, j))
                out.append(below)
    return out


def test_a_gap_with_a_witness_below_the_cap_is_filed_below_it(pre8):
    _, mdp, sol = pre8
    cap = 8
    # rows tau_2 != 5 keep going, then preempt from tau_1 = 6 (a monotone curve); the row tau_2 = 5
    # keeps going at tau_1 = 1, 2, preempts at 3, 4 and keeps going again from 5 to the cap: its last
    # keep-going state is at the cap, but (2, 3, 5) witnesses the gap well below it
    ctx, c, grid, act = _planted(mdp, sol, lambda t1, t2: (3 <= t1 <= 4) if t2 == 5 else t1 >= 6)
    n = mdp.n_states
    ctx = dataclasses.replace(ctx, recurrent=np.ones(n, bool), stationary=np.full(n, 1.0 / n))  # every state observable
    tau = mdp.states.tau
    row5 = [int(grid[i, 4]) for i in range(cap) if grid[i, 4] >= 0]
    assert tau[row5[-1]][0] == cap and act[row5[-1]] == act[row5[0]]  # the old rule's "last state": at the cap
    rep = check_threshold(mdp, sol, ctx=ctx, configs=[c])
    below = _gap_witnesses(grid, act, tau, cap)
    assert len(below) == rep.details["gaps"]["count"] > 0 and rep.details["reversals"]["count"] == 0
    assert rep.split["recurrent_below_cap"] == sum(below) > 0
    assert rep.split["recurrent_at_cap"] == len(below) - sum(below)
    assert rep.verdict == FAILS
    # the reported witness of the row tau_2 = 5 is the one below the cap, its outer states next to the gap
    ex = [e for e in rep.examples if all(tau[s][1] == 5 for s in e.states)]
    assert ex and [tuple(int(x) for x in tau[s]) for s in ex[0].states] == [(2, 5), (3, 5), (5, 5)]
    assert not ex[0].at_cap


def test_the_weight_is_the_stationary_probability_of_the_witness_states(pre8):
    _, mdp, sol = pre8
    ctx, c, grid, act = _planted(mdp, sol, lambda t1, t2: (3 <= t1 <= 4) if t2 == 5 else t1 >= 6)
    n = mdp.n_states
    law = np.zeros(n)
    row5 = [int(s) for s in grid[:, 4] if s >= 0]
    law[row5] = 1.0 / len(row5)  # a made-up law on the row tau_2 = 5 only
    ctx = dataclasses.replace(ctx, recurrent=np.ones(n, bool), stationary=law)
    rep = check_threshold(mdp, sol, ctx=ctx, configs=[c])
    # the witnesses touching the row: its own gap (2, 3, 5), and the gaps across it at tau_1 = 3, 4, 6, 7, 8,
    # whose middle state lies on the row: 1 + 5 states of the row carry weight, each 1 / len(row5)
    tau = mdp.states.tau
    on_row = {(2, 5), (3, 5), (5, 5)} | {(t1, 5) for t1 in (3, 4, 6, 7, 8)}
    assert rep.weight["mass"] == pytest.approx(len(on_row) / len(row5))
    assert rep.weight["states"] >= len(on_row)
    assert rep.to_json()["weight"]["mass"] == pytest.approx(rep.weight["mass"])
    assert {tuple(int(x) for x in tau[s]) for s in row5} >= on_row  # the whole row is reachable


# ============================================================================ the rules of sub-claims
def test_a_bump_inside_the_certificates_is_not_a_violation():
    from wncs_lp.verify.verdict import nonincreasing

    gaps = [0.0500, 0.0501, 0.0400]  # a bump of 1e-4 from p_1 to p_2
    assert not nonincreasing(gaps)  # exact numbers: a bump
    assert nonincreasing(gaps, lower=[0.0499, 0.0500, 0.0399], upper=[0.0502, 0.0502, 0.0401])  # inside: overlap
    assert not nonincreasing(gaps, lower=[0.04995, 0.05005, 0.0399], upper=[0.05004, 0.0502, 0.0401])  # beyond
    assert nonincreasing([0.05, 0.05 + 1e-9])  # round-off of "equal"
    assert nonincreasing([]) and nonincreasing([0.3])


def test_destinations_fixed_but_another_order():
    from wncs_lp.verify.verdict import (FIXED_DESTINATIONS_ONLY, NOT_STATIC, STATIC_RULE, destinations,
                                        destinations_fixed, static_reading)

    # processes 1 and 3 alternate on the remote server (0), 2 always to the edge (1): fixed destinations
    cycle = [(1, 2), (0, 0), (3, 2), (0, 0), (1, 0), (3, 2)]
    counts = destinations(cycle, 3)
    assert counts == [{0: 2}, {1: 3}, {0: 2}] and destinations_fixed(counts)
    assert static_reading(counts, 0.096) == FIXED_DESTINATIONS_ONLY  # every static rule costs 9.6% more
    assert static_reading(counts, 1e-12) == STATIC_RULE
    # process 1 goes to the edge once in twelve slots: not static, whatever the costs
    p14 = [(1, 2)] * 11 + [(2, 1)]
    counts = destinations(p14, 2)
    assert counts == [{0: 11, 1: 1}, {1: 11, 0: 1}] and not destinations_fixed(counts)
    assert static_reading(counts, 0.0) == NOT_STATIC


def test_magnitude_and_compound_rules():
    from wncs_lp.verify.verdict import MUCH, across, subclaims_verdict

    # "vastly improved" read with the bar of "much better": 1.94% at best fails at every cap
    vast = {cap: gap >= MUCH for cap, gap in ((12, 0.0), (20, 0.0003), (30, 0.0194))}
    assert subclaims_verdict({"vastly": vast, "equal at p = 1": {12: True, 20: True, 30: True}}) == FAILS
    assert across([HOLDS, FAILS]) == DEPENDS and across([FAILS, FAILS]) == FAILS


# ============================================================================ where a verdict is decided
def test_a_sub_claim_false_only_at_the_most_truncated_cap_is_a_caveat():
    from wncs_lp.verify.verdict import subclaim_caveats, subclaims_verdict

    only12 = {"gap shrinks": {12: False, 20: True, 30: True}, "equal at p = 1": {12: True, 20: True, 30: True}}
    assert subclaims_verdict(only12) == HOLDS  # cap 30 decides; cap 12 only adds a caveat
    assert subclaim_caveats(only12) == ["'gap shrinks' fails at cap 12 (holds at cap 30, which decides)"]
    # the converse: true at the small caps, false at the least truncated one
    only30 = {"vastly": {12: True, 20: True, 30: False}}
    assert subclaims_verdict(only30) == FAILS
    assert subclaim_caveats(only30) == ["'vastly' holds at cap 12, 20 (fails at cap 30, which decides)"]
    # not checked at the largest cap: the largest cap where it is checked decides
    assert subclaims_verdict({"a": {12: False, 20: True, 30: None}}) == HOLDS
    assert subclaims_verdict({"a": {12: None, 30: None}}) == DEPENDS  # decided nowhere


def test_a_structural_violation_only_at_the_most_truncated_cap_is_a_caveat():
    from wncs_lp.verify.verdict import decide

    # C1's shape: a recurrent violation below the cap at cap 12 only
    d = decide([("p14", 12, FAILS), ("p14", 20, HOLDS), ("p14", 30, HOLDS)])
    assert d.verdict == HOLDS and d.deciding == (2,) and d.caveats == (0,)
    # the least truncated instance of each scenario decides; one FAILS among them decides the claim
    d = decide([("p12", 12, HOLDS), ("p12", 30, FAILS), ("p14", 12, FAILS), ("p14", 30, DEPENDS)])
    assert d.verdict == FAILS and d.deciding == (1, 3) and d.caveats == (0, 2)
    assert decide([("p12", 30, HOLDS), ("p14", 30, DEPENDS)]).verdict == DEPENDS
    # descriptive claims: the deciding instances (e.g. planes at the largest cap) must agree
    d = decide([(18, 16, HOLDS), (18, 20, HOLDS), (45, 20, FAILS)], how="descriptive")
    assert d.verdict == DEPENDS and d.deciding == (1, 2) and d.caveats == ()
    assert decide([]).verdict == ERROR and decide([("a", 12, ERROR), ("a", 20, HOLDS)]).verdict == ERROR


def test_a_violation_of_negligible_weight_is_a_caveat_not_a_counterexample(pre8):
    from wncs_lp.verify.verdict import NEGLIGIBLE

    _, mdp, sol = pre8
    # one gap, on the row tau_2 = 5 (witness (2, 5), (3, 5), (5, 5), below the cap); every state recurrent
    ctx, c, grid, act = _planted(mdp, sol, lambda t1, t2: (3 <= t1 <= 4) if t2 == 5 else t1 >= 6)
    n = mdp.n_states
    row5 = [int(s) for s in grid[:, 4] if s >= 0]
    for weight, want in ((NEGLIGIBLE / 100, DEPENDS), (NEGLIGIBLE * 100, FAILS)):
        law = np.full(n, (1.0 - weight * len(row5)) / (n - len(row5)))
        law[row5] = weight  # the row visited `weight` of the time per state
        rep = check_threshold(mdp, sol, ctx=dataclasses.replace(ctx, recurrent=np.ones(n, bool), stationary=law),
                              configs=[c])
        assert rep.split["recurrent_below_cap"] > 0  # recurrent and below the cap either way ...
        assert (rep.split["observable_below_cap"] > 0) == (want == FAILS)  # ... of weight only above the bar
        assert rep.verdict == want == verdict_of(rep.to_json())
        row_ex = [e for e in rep.examples if all(mdp.states.tau[s][1] == 5 for s in e.states)]
        assert row_ex and row_ex[0].observable == (want == FAILS)


def test_the_witness_shown_first_is_the_farthest_from_the_cap(pre8):
    from wncs_lp.verify.report import pick_examples

    # hand-made: both recurrent and below the cap; the bigger one hugs the cap (distance 1), the other lies 6 away
    rec, cap = np.array([True, True]), np.array([False, False])
    assert list(pick_examples(rec, cap, np.array([20.0, 10.0]), 2, dist=np.array([1, 6]))) == [1, 0]
    assert list(pick_examples(rec, cap, np.array([20.0, 10.0]), 2)) == [0, 1]  # without distances: by size
    # an observable witness beats a heavier-sized one of negligible weight, whatever the distance
    assert list(pick_examples(rec, cap, np.array([20.0, 10.0]), 2, obs=np.array([False, True]),
                              dist=np.array([6, 1]))) == [1, 0]
    # planted: a gap on the row tau_2 = 2 (far from the cap 8) and one on the row tau_2 = 7 (next to it)
    _, mdp, sol = pre8
    ctx, c, grid, act = _planted(mdp, sol, lambda t1, t2: (3 <= t1 <= 4) if t2 in (2, 7) else t1 >= 6)
    n = mdp.n_states
    rep = check_threshold(mdp, sol, ctx=dataclasses.replace(ctx, recurrent=np.ones(n, bool),
                                                            stationary=np.full(n, 1.0 / n)), configs=[c])
    first = rep.examples[0]
    tau = mdp.states.tau
    assert {int(tau[s][1]) for s in first.states} == {2} and first.cap_distance == 8 - 5
    dists = [e.cap_distance for e in rep.examples]
    assert dists == sorted(dists, reverse=True)
    assert first.to_json()["cap_distance"] == first.cap_distance
