"""What enters the bounds (``wncs_lp.bounds.inputs``): every per-process quantity read from the
system given -- per-link probabilities, cost families, random arrivals -- or the system refused
by name; Systems edited by hand checked where they enter.

Every relaxation below the exact optimum of a system with each field, and moved by it, is in
``tests/test_rooms_fields.py``'s table of rooms x fields.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import wncs_lp
from reference.own_systems import small_scenario
from wncs_lp.bounds import lower_bound
from wncs_lp.errors import WncsError
from wncs_lp.models.system import System

def test_replaced_cost_tables_are_honoured():
    """The issue's report: lower_bound(dataclasses.replace(system, q=...)) gave the bound of the
    original costs. Now every relaxation reads them: the bounds are those of the scenario that
    writes the same tables as its cost field."""
    plain = System.from_scenario(small_scenario("none"))
    costs_sc = small_scenario("costs")
    edited = dataclasses.replace(plain, q=tuple(System.from_scenario(costs_sc).q))
    for rel in (1, 2, 3):
        assert lower_bound(edited, rel).lower_bound == pytest.approx(lower_bound(costs_sc, rel).lower_bound,
                                                                     rel=1e-9, abs=1e-9)
    assert lower_bound(edited, 1).lower_bound != pytest.approx(lower_bound(plain, 1).lower_bound, rel=1e-3)


def test_replaced_cost_tables_checked():
    plain = System.from_scenario(small_scenario("none"))
    with pytest.raises(WncsError, match=r"System\.q\[0\]: .* nondecreasing table"):
        lower_bound(dataclasses.replace(plain, q=(np.array([1.0, 2, 1, 4, 5]), plain.q[1])), 1)
    with pytest.raises(WncsError, match=r"System\.q\[1\]: expected q_2\(1\.\.5\)"):
        lower_bound(dataclasses.replace(plain, q=(plain.q[0], plain.q[1][:3])), 1)
    with pytest.raises(WncsError, match=r"System\.q\[0\]: expected finite"):
        lower_bound(dataclasses.replace(plain, q=(plain.q[0] * np.inf, plain.q[1])), 2)


def test_edited_system_fields_refused_by_name():
    plain = System.from_scenario(small_scenario("none"))
    with pytest.raises(WncsError, match=r"System\.caps"):
        lower_bound(dataclasses.replace(plain, caps=plain.caps + 1), 1)
    other = System.from_scenario(small_scenario("links"))
    with pytest.raises(WncsError, match=r"System\.model"):
        lower_bound(dataclasses.replace(plain, model=other.model), 2)
    with pytest.raises(WncsError, match=r"System\.n_actions"):
        lower_bound(dataclasses.replace(plain, n_actions=plain.n_actions + 1), 3)


def test_automaton_edited_by_hand():
    """A per-link system made by swapping in another automaton (as a patched server step does):
    relaxations 1 and 3, which rebuild the private chains from the scenario's fields, refuse it by
    name; relaxation 2 reads the automaton, so it bounds the system the automaton describes."""
    plain = System.from_scenario(small_scenario("none"))
    links_sc = small_scenario("links")
    links_sol = wncs_lp.solve(links_sc, "lp")
    edited = dataclasses.replace(plain, automaton=System.from_scenario(links_sc).automaton)
    for rel in (1, 3):
        with pytest.raises(WncsError, match=r"System\.automaton: relaxation .* cannot honour this system: process"):
            lower_bound(edited, rel)
    assert lower_bound(edited, 2).lower_bound <= links_sol.gain_upper * (1 + 1e-12)
