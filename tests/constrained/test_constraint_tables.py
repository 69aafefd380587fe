"""``[[constraint]]`` tables: parsing, overrides, and one clear error per malformed table."""
from __future__ import annotations

import numpy as np
import pytest

import wncs_lp
from wncs_lp.errors import ScenarioError
from wncs_lp.scenario import ConstraintSpec, load_scenario

BASE = wncs_lp.scenario_path("paper_p12.toml").read_text()


def write(tmp_path, tables: str):
    p = tmp_path / "c.toml"
    p.write_text(BASE + "\n" + tables)
    return p


def test_tables_parse_in_file_order_with_names_and_indices(tmp_path):
    p = write(tmp_path, """
[[constraint]]
quantity = "send_rate"
server = "remote"
max = 0.2

[[constraint]]
quantity = "aoi"
process = 2
min = 1.5
max = 6

[[constraint]]
quantity = "send_rate"
server = 2
process = "process-1"
min = 0.05
""")
    sc = load_scenario(p)
    assert sc.constraints == (
        ConstraintSpec("send_rate", 0, None, 0.2, None, "send_rate[remote] <= 0.2"),
        ConstraintSpec("aoi", None, 1, 6.0, 1.5, "1.5 <= aoi[process-2] <= 6"),
        ConstraintSpec("send_rate", 1, 0, None, 0.05, "0.05 <= send_rate[edge, process-1]"),
    )
    # constraints do not change the MDP: the fingerprint is the unconstrained scenario's
    assert sc.fingerprint() == load_scenario(wncs_lp.scenario_path("paper_p12.toml")).fingerprint()


def test_overrides_address_constraints_by_index(tmp_path):
    p = write(tmp_path, '[[constraint]]\nquantity = "send_rate"\nserver = "remote"\nmax = 0.2\n')
    sc = load_scenario(p, ["constraint.1.max=0.15", "constraint.1.min=0.05"])
    assert (sc.constraints[0].max, sc.constraints[0].min) == (0.15, 0.05)
    assert load_scenario(p, ["constraint.1.max=none", "constraint.1.min=0.1"]).constraints[0].max is None
    with pytest.raises(ScenarioError, match=r"constraint index 2 out of range: expected 1..1"):
        load_scenario(p, ["constraint.2.max=0.1"])
    with pytest.raises(ScenarioError, match=r"unknown key"):
        load_scenario(p, ["constraint.1.bound=0.1"])
    with pytest.raises(ScenarioError, match=r"no \[\[constraint\]\] tables"):
        load_scenario(wncs_lp.scenario_path("paper_p12.toml"), ["constraint.1.max=0.1"])


@pytest.mark.parametrize("table, field, words", [
    ('quantity = "energy"\nmax = 1', "constraint[1].quantity", "unknown quantity 'energy'"),
    ('max = 1', "constraint[1].quantity", "missing"),
    ('quantity = "send_rate"\nmax = 0.2', "constraint[1].server", "send_rate needs a server"),
    ('quantity = "send_rate"\nserver = "cloud"\nmax = 0.2', "constraint[1].server", "no server named 'cloud'"),
    ('quantity = "send_rate"\nserver = 3\nmax = 0.2', "constraint[1].server", "server index 3 out of range"),
    ('quantity = "aoi"\nmax = 3', "constraint[1].process", "aoi needs a process"),
    ('quantity = "process_cost"\nprocess = "p9"\nmax = 3', "constraint[1].process", "no process named 'p9'"),
    ('quantity = "aoi"\nprocess = 1\nserver = 1\nmax = 3', "constraint[1].server", "only send_rate takes a server"),
    ('quantity = "cost"\nprocess = 1\nmax = 3', "constraint[1].process", "not used by quantity 'cost'"),
    ('quantity = "aoi"\nprocess = 1\nmin = 5\nmax = 3', "constraint[1].min", "min <= max"),
    ('quantity = "aoi"\nprocess = 1\nmax = nan', "constraint[1].max", "finite number"),
    ('quantity = "aoi"\nprocess = 1\nmax = inf', "constraint[1].max", "finite number"),
    ('quantity = "aoi"\nprocess = 1\nmax = "3"', "constraint[1].max", "expected a number"),
    ('quantity = "aoi"\nprocess = 1', "constraint[1].max", "max = ... and/or min"),
    ('quantity = "aoi"\nprocess = 1\nmax = 3\nweight = 2', "constraint[1].weight", "unknown field"),
])
def test_each_malformed_table_gives_one_clear_line(tmp_path, table, field, words):
    p = write(tmp_path, "[[constraint]]\n" + table + "\n")
    with pytest.raises(ScenarioError) as info:
        load_scenario(p)
    msg = str(info.value)
    assert "\n" not in msg and str(p) in msg and f"'{field}'" in msg and words in msg, msg
    assert isinstance(info.value, ValueError)


def test_second_table_is_named_by_its_index(tmp_path):
    p = write(tmp_path, '[[constraint]]\nquantity = "cost"\nmax = 900\n\n[[constraint]]\nquantity = "cst"\nmax = 1\n')
    with pytest.raises(ScenarioError, match=r"'constraint\[2\]\.quantity'"):
        load_scenario(p)
