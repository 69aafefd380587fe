"""The HTML and pandas views of the sweep's and the bound's results, and the sweep's value column
named by the swept parameter."""
from __future__ import annotations

import pytest

from wncs_lp import load_scenario, scenario_path


@pytest.fixture(scope="module")
def sweep():
    from wncs_lp.studies import run_sweep

    sc = load_scenario(scenario_path("paper_p12"), ["tau_cap=7"])
    return run_sweep(sc, "p", [0.8, 0.9], ["greedy", "round_robin"], plot=False)


def test_sweep_rows_name_the_parameter(sweep):
    rows = sweep.table()
    assert [r["p"] for r in rows] == [0.8, 0.8, 0.9, 0.9] and "value" not in rows[0] and rows[0]["param"] == "p"
    assert list(sweep.column("round_robin", "p")) == [0.8, 0.9]
    html = sweep._repr_html_()
    assert "SweepResult: 4 rows, p over 2 values" in html and "<th>p</th>" in html and "round_robin" in html
    assert "computed" in repr(sweep)


def test_sweep_frame_names_the_parameter(sweep):
    df = sweep.to_frame()
    assert list(df.columns[:2]) == ["p", "policy"] and len(df) == 4
    assert df["gain"].notna().all()


def test_a_clashing_parameter_keeps_value():
    from wncs_lp.studies.sweep import value_column

    assert value_column("p") == "p" and value_column("tau_cap") == "tau_cap" and value_column("status") == "value"


def test_bound_result_html_and_frame():
    from wncs_lp.bounds import lower_bound
    from wncs_lp.models.system import System

    sc = load_scenario(scenario_path("paper_p12"), ["tau_cap=8"])
    res = lower_bound(System.from_scenario(sc), 1)
    html = res._repr_html_()
    assert "BoundResult: g* &gt;= " in html and "certified_by" in html
    df = res.to_frame()
    assert list(df["processes"]) == ["1", "2"]
    assert df["part_of_bound"].sum() == pytest.approx(res.process_gains.sum())
    assert repr(res).startswith("BoundResult(private-servers: g* >= ")
