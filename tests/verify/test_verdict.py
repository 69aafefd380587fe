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
from wncs_lp.solvers import solve
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
