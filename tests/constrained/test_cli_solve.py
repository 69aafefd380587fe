"""``wncs-lp solve`` on a scenario with [[constraint]] tables: the JSON keys, the words, exit codes."""
from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

import wncs_lp
from wncs_lp.constrained import with_cost
from wncs_lp.models.quantities import pair_values
from wncs_lp.scenario import ConstraintSpec

TABLES = """
[[constraint]]
quantity = "send_rate"
server = "remote"
max = 0.2

[[constraint]]
quantity = "aoi"
process = "process-2"
max = 6
"""


def run(*args: str):
    return subprocess.run([sys.executable, "-m", "wncs_lp", "solve", *args], capture_output=True, text=True, timeout=300)


@pytest.fixture(scope="module")
def scenario_file(tmp_path_factory):
    p = tmp_path_factory.mktemp("c") / "p12c.toml"
    p.write_text(wncs_lp.scenario_path("paper_p12.toml").read_text() + TABLES)
    return p


def test_json_carries_the_constrained_result(scenario_file):
    proc = run(str(scenario_file), "--set", "model.allow_idle=true", "--set", "tau_cap=6", "--method", "lp", "--json")
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    assert out["status"] == "optimal" and out["method"] == "lp"
    assert out["gain_lower"] <= out["gain"] <= out["gain_upper"] + 1e-9 * out["gain"]
    assert isinstance(out["randomized_states"], int) and len(out["mixes"]) == out["randomized_states"]
    cons = out["constraints"]
    assert [c["quantity"] for c in cons] == ["send_rate", "aoi"]
    assert [(c["max"], c["min"]) for c in cons] == [(0.2, None), (6.0, None)]
    for c in cons:
        assert set(c) >= {"quantity", "max", "min", "value", "active", "multiplier"}
        assert c["value"] <= c["max"] + 1e-9 and c["multiplier"] >= 0
    # the bound on the remote send rate binds (the unconstrained optimum sends more, independent solve)
    sc = wncs_lp.load_scenario(scenario_file, ["model.allow_idle=true", "tau_cap=6"])
    mdp = wncs_lp.build(sc)
    opt = wncs_lp.solve(mdp, "vi")
    assert out["gain"] > opt.gain_upper and cons[0]["active"] and cons[0]["multiplier"] > 0
    assert 0 <= out["cap_mass"]["total"] <= 1 and len(out["cap_mass"]["per_process"]) == 2
    # --ignore-constraints solves the plain problem
    plain = json.loads(run(str(scenario_file), "--set", "model.allow_idle=true", "--set", "tau_cap=6",
                           "--ignore-constraints", "--json").stdout)
    assert opt.gain_lower - 1e-6 <= plain["gain"] <= opt.gain_upper + 1e-6


def test_human_output_says_it_in_words(scenario_file):
    proc = run(str(scenario_file), "--set", "model.allow_idle=true", "--set", "tau_cap=6", "--method", "lp")
    assert proc.returncode == 0, proc.stderr
    assert "optimal average cost under the constraints" in proc.stdout
    assert "send_rate[remote] <= 0.2: value" in proc.stdout and "multiplier" in proc.stdout


def test_infeasible_bound_is_one_line_and_exit_2(scenario_file):
    proc = run(str(scenario_file), "--set", "tau_cap=6", "--set", "constraint.1.max=0.01", "--method", "lp")
    assert proc.returncode == 2 and proc.stdout == ""
    # (tau_cap = 6 is at most process 1's shortest loop: that is a "warning: ..." line of its own)
    lines = [ln for ln in proc.stderr.strip().splitlines() if not ln.startswith("warning: ")]
    assert len(lines) == 1 and "send_rate[remote] <= 0.01" in lines[0] and "least value" in lines[0]
    sc = wncs_lp.load_scenario(scenario_file, ["tau_cap=6"])
    mdp = wncs_lp.build(sc)
    least = wncs_lp.solve(with_cost(mdp, pair_values(mdp, ConstraintSpec("send_rate", server=0))), "lp").gain
    shown = float(lines[0].rsplit(" ", 1)[1])
    assert shown == pytest.approx(least, rel=1e-8)


def test_methods_that_cannot_constrain_are_refused(scenario_file):
    proc = run(str(scenario_file), "--set", "tau_cap=6", "--method", "rvi")
    assert proc.returncode == 2 and "does not solve a scenario with [[constraint]] tables" in proc.stderr
