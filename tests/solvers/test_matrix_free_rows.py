"""The matrix-free kernels' row paths: a row on which one action is computed (an evaluation row
whose states all take one action, the first action of a minimum) is summed straight into the
row's result; a row of several actions is summed per action and selected. Both must give the same
values: a fixed-policy pass of a policy mixing actions within rows equals, state by state, the
passes of the constant policies of those actions, and the Bellman pass equals their minimum with
the first minimiser, on both model kinds. (The gains these passes converge to are checked against
the stored-matrix solvers in test_matrix_free.py.)
"""
from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("numba")

import wncs_lp  # noqa: E402
from wncs_lp.models.system import System  # noqa: E402
from wncs_lp.solvers.matrix_free import BoxLayout  # noqa: E402
from wncs_lp.solvers.matrix_free.operator import Operator, Reduce, Write  # noqa: E402
from wncs_lp.solvers.matrix_free.sweeper import Sweeper  # noqa: E402


@pytest.fixture(scope="module", params=[("paper_p1234", 6), ("paper_preemption_p12", 8)], ids=["wncs", "preemption"])
def passes(request):
    name, cap = request.param
    system = System.from_scenario(wncs_lp.load_scenario(wncs_lp.scenario_path(name), [f"tau_cap={cap}"]))
    layout = BoxLayout.from_system(system)
    sw = Sweeper(Operator.build(system, layout), 1, None)
    rng = np.random.default_rng(7)
    h = rng.normal(scale=100.0, size=layout.n_states)
    nact = np.repeat(np.asarray(system.n_actions), np.diff(layout.off))
    # per action j, the pass of the policy "j where the configuration has it, else 0" (every row one action)
    values = []
    for j in range(int(nact.max())):
        out = np.empty_like(h)
        sw.fixed(h, out, np.where(j < nact, j, 0).astype(np.uint8), Write.OUT, 1.0, 0.0)
        values.append(np.where(j < nact, out, np.inf))
    return sw, h, nact, np.array(values), rng


def test_a_policy_mixing_actions_in_a_row_takes_each_states_own_action(passes):
    sw, h, nact, values, rng = passes
    pol = np.floor(rng.random(h.size) * nact).astype(np.uint8)  # a random action a state: mixed rows
    out = np.empty_like(h)
    sw.fixed(h, out, pol, Write.OUT, 1.0, 0.0)
    assert np.array_equal(out, values[pol, np.arange(h.size)])


def test_the_bellman_pass_is_the_minimum_over_the_actions_passes(passes):
    sw, h, _, values, _ = passes
    out, pol = np.empty_like(h), np.zeros(h.size, np.uint8)
    sw.all_actions(h, out, pol, None, Reduce.MIN, Write.OUT, True, 1.0, 0.0)
    assert np.array_equal(out, values.min(axis=0))
    assert np.array_equal(pol, values.argmin(axis=0))
