"""Starting values of the matrix-free solver (wncs_lp.solvers.matrix_free.start).

The certificate min / max (T h - h) holds for any h, so a warm start may only change how many
sweeps a solve takes, never its certified gain: warm (the bounds' separable tables), random and
cold starts must close on the same gain, on both model kinds, for value iteration and for policy
evaluation. The start vector itself is checked against the tables' own evaluation
(``ValueTables.value`` at the layout's AoI vectors), which does not go through the solver.
"""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

pytest.importorskip("numba")

import wncs_lp  # noqa: E402
from wncs_lp.bounds import lower_bound  # noqa: E402
from wncs_lp.errors import SolverError  # noqa: E402
from wncs_lp.models.system import System  # noqa: E402
from wncs_lp.workflow import make_policy  # noqa: E402
from wncs_lp.solvers.matrix_free import (  # noqa: E402
    BoxLayout,
    matrix_free_evaluate,
    matrix_free_value_iteration,
)
from wncs_lp.solvers.matrix_free.start import separable_values, start_vector  # noqa: E402


def paper(name, cap):
    return wncs_lp.load_scenario(wncs_lp.scenario_path(name), [f"tau_cap={cap}"])


def agree(a, b, rel=1e-9):
    """Each gain inside the other's certificate (widened by rel)."""
    s = rel * abs(a.gain)
    return a.gain_lower - s <= b.gain <= a.gain_upper + s and b.gain_lower - s <= a.gain <= b.gain_upper + s


@pytest.fixture(scope="module")
def wncs():
    system = System.from_scenario(paper("paper_p1234", 7))
    return system, matrix_free_value_iteration(system), lower_bound(system, 1)


@pytest.fixture(scope="module")
def preemption():
    system = System.from_scenario(paper("paper_preemption_p12", 8))
    return system, matrix_free_value_iteration(system)


def cost_to_go_tables(system):
    """A separable start any model has: h_k(tau) = q_k(1) + ... + q_k(tau), the same for every
    configuration (one column)."""
    caps = system.caps
    return SimpleNamespace(h=tuple(np.cumsum(np.asarray(system.q[k][: caps[k]], float))[None, :]
                                   for k in range(len(caps))),
                           column=tuple(np.zeros(system.n_configs, np.int64) for _ in caps))


def test_the_start_vector_is_the_tables_value_at_every_state(wncs):
    system, _, bound = wncs
    layout = BoxLayout.from_system(system)
    h = start_vector(bound, layout)
    s = np.arange(layout.n_states)
    ref = bound.tables.value(layout.tau_of(s), layout.config_of(s))
    assert np.allclose(h, ref - ref[0], rtol=0, atol=1e-9 * np.abs(ref).max())
    # the same value function as per-group tables (processes 1 and 2 together): the same vector
    T = bound.tables
    c = np.arange(system.n_configs)
    pair = T.h[0][T.column[0][c]][:, :, None] + T.h[1][T.column[1][c]][:, None, :]  # one table per configuration
    grouped = SimpleNamespace(groups=((0, 1), (2,), (3,)), h=(pair, T.h[2], T.h[3]), column=(c, T.column[2], T.column[3]))
    assert np.allclose(separable_values(layout, grouped) - separable_values(layout, grouped)[0], h, rtol=0,
                       atol=1e-9 * np.abs(ref).max())


def test_warm_and_cold_starts_give_the_same_certified_gain(wncs, preemption):
    system, cold, bound = wncs
    warm = matrix_free_value_iteration(system, h0=bound)
    assert warm.status == cold.status == "optimal" and agree(warm, cold)
    assert matrix_free_value_iteration(system, h0=bound.tables).stats["sweeps"] == warm.stats["sweeps"]
    system, cold = preemption
    warm = matrix_free_value_iteration(system, h0=cost_to_go_tables(system))
    assert warm.status == cold.status == "optimal" and agree(warm, cold)


@pytest.mark.parametrize("kind", ["wncs", "preemption"])
def test_the_certificate_holds_from_a_random_start(kind, wncs, preemption):
    system, cold = (wncs[0], wncs[1]) if kind == "wncs" else preemption
    n = BoxLayout.from_system(system).n_states
    h0 = np.random.default_rng(7).normal(scale=10 * cold.gain, size=n)
    sol = matrix_free_value_iteration(system, h0=h0)
    assert sol.status == "optimal" and agree(sol, cold)
    # a random start is far from the bias: the first certificate is wide, yet it brackets g*
    lo, hi = sol.stats["history"][0][3:5]
    assert hi - lo > 1e3 * (sol.gain_upper - sol.gain_lower) and lo <= cold.gain <= hi


def test_policy_evaluation_from_a_warm_start(wncs):
    system, _, bound = wncs
    pol = make_policy("suboptimal", system)
    cold = matrix_free_evaluate(system, pol)
    warm = matrix_free_evaluate(system, pol, h0=bound)
    assert cold.status == warm.status == "optimal" and agree(cold, warm, rel=1e-8)


def test_bad_start_tables_are_one_error(wncs):
    system, _, bound = wncs
    T = bound.tables
    with pytest.raises(SolverError, match="one table per process"):
        matrix_free_value_iteration(system, h0=SimpleNamespace(h=T.h[:3], column=T.column[:3]))
    short = SimpleNamespace(h=(T.h[0][:, :3],) + T.h[1:], column=T.column)
    with pytest.raises(SolverError, match="part 0"):
        matrix_free_value_iteration(system, h0=short)
    bad = SimpleNamespace(h=(np.full_like(T.h[0], np.nan),) + T.h[1:], column=T.column)
    with pytest.raises(SolverError, match="non-finite"):
        matrix_free_value_iteration(system, h0=bad)
