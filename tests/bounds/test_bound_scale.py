"""Bounds and their policies at scale: the projected lookahead against the joint tables, tables
numbered otherwise refused, box counts past int64, and sixteen to thirty-two processes run under a
memory limit set in a subprocess (or refused by a guard before they allocate)."""
from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest
from bounds_reference import shape

from wncs_lp import scenario_path
from wncs_lp.bounds import BoundPolicy, ValueTables, bound_policy, private_bound
from wncs_lp.bounds.grouped import grouped_bound
from wncs_lp.bounds.policy import GroupBoundPolicy
from wncs_lp.bounds.projected import ProjectedBoundPolicy
from wncs_lp.errors import PolicyError, SizeLimitError
from wncs_lp.models import build
from wncs_lp.models.system import System
from wncs_lp.scenario import scenario_from_dict
from wncs_lp.solvers.matrix_free.layout import BoxLayout, box_count, layout_states

pytestmark = pytest.mark.filterwarnings("ignore::wncs_lp.errors.ScenarioWarning")


@pytest.fixture(scope="module")
def three():
    """Three processes on three servers with U = 0, 1, 2 (the reference shape "3x3", cap 4), enumerated."""
    sc = shape("3x3").with_overrides(["tau_cap=4"])
    system = System.from_scenario(sc)
    return system, build(sc)


@pytest.mark.parametrize("groups", [None, [(0, 2), (1,)]])
def test_the_projected_lookahead_is_the_joint_tables_one(three, groups):
    """sum_G W_G over the private pairs, read through the projections, equals the joint tables'
    lookahead on every state (to rounding), and the actions tie with theirs."""
    system, mdp = three
    res = private_bound(system) if groups is None else grouped_bound(system, groups)
    joint = BoundPolicy(res, system) if groups is None else GroupBoundPolicy(res, system)
    pol = bound_policy(res, system)
    assert isinstance(pol, ProjectedBoundPolicy)
    tau, cfg = np.asarray(mdp.states.tau), np.asarray(mdp.states.config)
    a, b = pol.values(tau, cfg), joint.values(tau, cfg)
    np.testing.assert_array_equal(np.isfinite(a), np.isfinite(b))
    fin = np.isfinite(b)
    np.testing.assert_allclose(a[fin], b[fin], rtol=1e-13, atol=0)
    rows = np.arange(tau.shape[0])
    ja = pol.act(tau, cfg)
    assert np.all(b[rows, ja] <= b.min(axis=1) + 1e-11 * np.abs(b.min(axis=1)))


def test_tables_numbered_otherwise_are_refused(three):
    system, _ = three
    res = private_bound(system)
    h = tuple(hk[::-1] for hk in res.tables.h)  # rows reversed, the column maps reversed with them
    cols = tuple(hk.shape[0] - 1 - ck for hk, ck in zip(res.tables.h, res.tables.column))
    with pytest.raises(PolicyError, match="not the projection"):
        ProjectedBoundPolicy(replace(res, tables=ValueTables(h, cols)), system)


def test_box_counts_do_not_wrap_around():
    """Twelve scalar processes at cap 40 on one server: 40^12 AoI vectors a configuration, past int64
    once summed over the configurations; the count is exact and the layout refuses to index it."""
    proc = {"A": [[1.05]]}
    sc = scenario_from_dict({"model": {"kind": "wncs", "tau_cap": 40}, "channel": {"success_probability": 0.9},
                             "process": [proc] * 12,
                             "server": [{"name": "edge", "uplink_delay": 0, "downlink_delay": 0,
                                         "slots_per_dimension": 1}]}, source="<12 on one server>")
    system = System.from_scenario(sc)
    assert box_count(np.full((system.n_configs, 12), 40)) == system.n_configs * 40**12  # > 2^63
    assert layout_states(system, "box") == system.n_configs * 40**12
    assert 0 < layout_states(system, "hull") <= system.n_configs * 40**12
    with pytest.raises(SizeLimitError, match="int64"):
        BoxLayout.from_system(system, "box")


def _lab(n: int, cap: int) -> str:
    """The lab shape (bounds_lab16's sensors, A = 1.05 ... 1.3 in turn) with n sensors, as TOML."""
    text = scenario_path("bounds_lab16").read_text()
    head, _, rest = text.partition("[[process]]")
    servers = rest[rest.index("[[server]]"):]
    a = [1.05, 1.1, 1.15, 1.2, 1.3]
    procs = "".join(f'[[process]]\nname = "sensor-{i + 1:02d}"\nA = [[{a[i % 5]}]]\nR = "identity"\n\n'
                    for i in range(n))
    return head.replace("tau_cap = 20", f"tau_cap = {cap}") + procs + servers


def _limited(code: str, limit_gb: float, tmp_path) -> subprocess.CompletedProcess:
    """Run Python code in a subprocess whose address space is limited to ``limit_gb`` (setrlimit)."""
    pre = (f"import resource; resource.setrlimit(resource.RLIMIT_AS, ({int(limit_gb * 2**30)}, "
           f"{int(limit_gb * 2**30)}))\n")
    env = {**os.environ, "NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
    return subprocess.run([sys.executable, "-c", pre + code], capture_output=True, text=True, cwd=tmp_path,
                          env=env, timeout=600)


def test_twenty_processes_run_lazily_within_a_memory_limit(tmp_path):
    """Twenty sensors: relaxation 1, its policy and the greedy baseline simulated on the lazily explored
    system under a 3 GiB address-space limit; the suboptimal policy, which needs the whole automaton,
    is reported as not evaluated (with the reason), never a crash."""
    (tmp_path / "lab20.toml").write_text(_lab(20, 3))
    code = """
import json, wncs_lp
from wncs_lp.bounds import lower_bound, policy_gaps
from wncs_lp.models.system import System
system = System.from_scenario(wncs_lp.load_scenario("lab20.toml"), explore="lazy")
res = lower_bound(system, 1)
rep = policy_gaps(res, system, ["bound", "greedy", "suboptimal"], slots=300, reps=4, burn_in=10)
print(json.dumps({"lb": res.lower_bound, "sense": res.stats["capacity"], "expanded": system.n_expanded,
                  **rep.summary()}))
"""
    out = _limited(code, 3.0, tmp_path)
    assert out.returncode == 0, out.stderr[-2000:]
    got = json.loads(out.stdout.strip().splitlines()[-1])
    assert got["lb"] > 0 and got["sense"] == "inequality" and got["expanded"] > 1
    gains = {p["policy"]: p for p in got["policies"]}
    assert set(gains) == {"bound[private-servers]", "greedy"}
    assert all(p["gain_upper"] >= got["lb"] for p in gains.values())  # a policy never beats a certified bound
    assert [s["policy"] for s in got["skipped"]] == ["suboptimal"]
    assert "whole configuration automaton" in got["skipped"][0]["reason"]


def test_thirty_two_processes_by_the_command_line_within_a_memory_limit(tmp_path):
    """`wncs-lp bound --policy` on 32 sensors explores lazily at once (by the model's bounds on the
    automaton), prints the AoI box's size without wrapping around, and stays within 3 GiB."""
    (tmp_path / "lab32.toml").write_text(_lab(32, 3))
    code = """
import sys
from wncs_lp.cli import main
sys.exit(main(["bound", "lab32.toml", "--relaxation", "1", "--policy", "--compare", "suboptimal",
               "--slots", "100", "--reps", "2", "--burn-in", "10"]))
"""
    out = _limited(code, 3.0, tmp_path)
    assert out.returncode in (0, 1), out.stderr[-2000:]  # 1: the relaxation stopped short (still certified)
    text = out.stdout
    assert "explored lazily" in text and "Traceback" not in out.stderr
    assert f"{math.prod([3] * 32) / 10**15:.2f}e15 states" in text  # 3^32, not a wrapped int64
    assert "suboptimal: not evaluated" in text and "bound[private-servers]" in text


def test_every_guard_refuses_before_it_allocates_and_names_a_cheaper_route(three, monkeypatch):
    """With (almost) no memory left, each large allocation is refused in one sentence naming a cheaper
    route, and the greedy tables give way to the same lookahead computed state by state."""
    from wncs_lp.bounds import lower_bound
    from wncs_lp.models import guard
    from wncs_lp.policies.suboptimal import SeparableGreedyPolicy, SuboptimalPolicy
    from wncs_lp.simulate import simulate

    system, mdp = three
    res = private_bound(system)
    full = SeparableGreedyPolicy(system, res.tables)  # built with the memory there is
    monkeypatch.setattr(guard, "available_memory", lambda: 0)
    per_state = SeparableGreedyPolicy(system, res.tables)
    assert full.lookahead == "tables" and per_state.lookahead == "per-state" and per_state.tables is None
    tau, cfg = np.asarray(mdp.states.tau)[::7], np.asarray(mdp.states.config)[::7]
    a, b = full.values(tau, cfg), per_state.values(tau, cfg)
    np.testing.assert_array_equal(np.isfinite(a), np.isfinite(b))
    np.testing.assert_allclose(a[np.isfinite(a)], b[np.isfinite(b)], rtol=1e-12)
    cases = [(lambda: SeparableGreedyPolicy(system, res.tables, lookahead="tables"), "per-state"),
             (lambda: SuboptimalPolicy(system), "bound's policy"),
             (lambda: lower_bound(system, 2), "relaxation 3"),
             (lambda: simulate(full, slots=10, reps=1000, progress=False), "fewer replications"),
             (lambda: bound_policy(res, system), "relaxation 1")]
    for make, route in cases:
        with pytest.raises(SizeLimitError, match=f"would need about .* over the limit .*Cheaper routes: .*{route}"):
            make()
