"""No solver status becomes "yes": a solve that did not close its certificate is said in the report.

The status under test is planted (a wrapped solver, hand-made sweep rows); the expectations are
that very status, read back from every place the report shows the row or the claim.
"""
from __future__ import annotations

import dataclasses
import json
import math

import pytest

import wncs_lp.reproduce as rep
from wncs_lp.cli import main
from wncs_lp.reproduce import context, performance
from wncs_lp.reproduce.context import PROFILES, Context
from wncs_lp.reproduce.report import md_table
from wncs_lp.studies.sweep import SweepRow

PRECISION = "error: solver status inaccurate:precision"


def test_the_monte_carlo_table_shows_a_row_status_that_is_not_ok():
    exact = {0.9: {"optimal": 907.647708415537}, 1.0: {"optimal": 586.7527477593271}}
    rows = {("optimal", 0.9): SweepRow("p", 0.9, "optimal", 907.647708415537, 905.65, 2.58, status=PRECISION),
            ("optimal", 1.0): SweepRow("p", 1.0, "optimal", 586.7527477593271, 586.7527, 0.0, status="ok")}
    table, recs, ok_all = performance._mc_table(rows, [0.9, 1.0], ["optimal"], exact, 30, {})
    assert ok_all  # the Monte Carlo means agree ...
    assert table.header[-1] == "status"
    assert table.rows[0][-2] == "yes" and PRECISION in table.rows[0][-1]  # ... and the status is beside it
    assert table.rows[1][-1] == "ok"
    assert [r["status"] for r in recs] == [PRECISION, "ok"]
    assert PRECISION in md_table(table.header, table.rows).splitlines()[2]


@pytest.fixture()
def inaccurate(monkeypatch):
    """Every solve of the reproduction ends "inaccurate:precision" (the numbers of the real solve)."""
    real = context.run_scenario

    def solve(*a, **k):
        run = real(*a, **k)
        return dataclasses.replace(run, solution=dataclasses.replace(run.solution, status="inaccurate:precision"))

    monkeypatch.setattr(context, "run_scenario", solve)


def test_a_solve_that_did_not_close_keeps_its_status_and_is_noted(tmp_path, inaccurate):
    ctx = Context(tmp_path, PROFILES["quick"])
    sc = ctx.scenario("paper_p12.toml", ["tau_cap=7", "p=0.9"])
    solved = ctx.solve(sc)
    assert solved.status == "inaccurate:precision" and solved.as_solution().status == "inaccurate:precision"
    (note,) = ctx.status_notes
    assert "paper_p12.toml" in note and note.endswith(": inaccurate:precision")
    again = Context(tmp_path, PROFILES["quick"]).solve(sc)  # from the disk cache: the status too
    assert again.status == "inaccurate:precision" and math.isclose(again.gain, solved.gain)


def test_the_claim_says_which_solves_did_not_close(tmp_path, inaccurate, monkeypatch, capsys):
    def claim(ctx):
        s = ctx.solve(ctx.scenario("paper_p12.toml", ["tau_cap=7", "p=0.9"]))
        return rep.ClaimResult("C3", "Fig. 5", "", "HOLDS", f"g* = {s.gain:.6g}")

    monkeypatch.setattr(rep, "_claims", lambda: {"C3": claim})
    out = tmp_path / "r"
    assert main(["reproduce", "--out", str(out), "--profile", "quick", "--claims", "C3"]) == 0
    cap = capsys.readouterr()
    assert "not optimal:" in cap.out and "inaccurate:precision" in cap.out
    assert "C3 HOLDS (1 solve(s) not optimal)" in cap.err
    (c3,) = json.loads((out / "report.json").read_text())["claims"]
    assert len(c3["solver_notes"]) == 1 and c3["solver_notes"][0].endswith("inaccurate:precision")
    md = (out / "report.md").read_text()
    contents, sections = md.split('<a id="c3"></a>', 1)
    assert "⚠ 1 solve(s) not optimal" in contents
    assert "Not every solve of this section closed its certificate" in sections
    assert "inaccurate:precision" in sections.split("## Where the exact model")[0]
    page = (out / "report.html").read_text()
    assert 'class="notes"' in page and "inaccurate:precision" in page


def test_the_exact_table_shows_the_status_beside_an_optimal_gain_that_did_not_close():
    assert performance.optimal_cell({"optimal": 907.647708415537, "optimal_status": "optimal"}) == 907.647708415537
    cell = performance.optimal_cell({"optimal": 907.647708415537, "optimal_status": "inaccurate:precision"})
    assert cell == "907.6477084 (**inaccurate:precision**)"


def test_c3_shows_every_planted_status_in_its_tables_and_section(tmp_path, inaccurate, monkeypatch):
    """The issue's case end to end on a tiny profile: every solve of C3 (its exact grid and its
    Monte Carlo sweep) ends "inaccurate:precision"; no row of its tables may read as if it closed."""
    import wncs_lp.studies.sweep as sweep_mod

    real = sweep_mod.run_scenario

    def solve(*a, **k):
        run = real(*a, **k)
        return dataclasses.replace(run, solution=dataclasses.replace(run.solution, status="inaccurate:precision"))

    monkeypatch.setattr(sweep_mod, "run_scenario", solve)
    prof = dataclasses.replace(PROFILES["quick"], name="tiny-status", caps_2p=(7,), p_grid=(0.9, 1.0),
                               sweep_cap_2p=7, mc_slots=200, mc_reps=2)
    ctx = Context(tmp_path, prof)
    ctx.workers = 1  # every solve in this process, where the planted status is (workers would solve afresh)
    res = performance.claim_c3(ctx)
    exact_tab, mc_tab = res.shown[1], res.shown[2]
    assert all("inaccurate:precision" in str(row[2]) for row in exact_tab.rows)  # the optimal column
    opt_rows = [row for row in mc_tab.rows if row[0] == "optimal"]
    assert len(opt_rows) == 2 and all(PRECISION in row[-1] for row in opt_rows)
    assert all(row[-1].startswith("ok") for row in mc_tab.rows if row[0] != "optimal")
    assert len(ctx.status_notes) == 4  # two exact solves, two Monte Carlo rows


def test_b1_says_when_a_point_did_not_close():
    from wncs_lp.reproduce import beyond
    from wncs_lp.studies.tradeoff import TradeoffPoint, TradeoffResult

    def curve(status):
        pts = tuple(TradeoffPoint(bound=b, gain=g, gain_lower=g, gain_upper=g, multiplier=lam,
                                  randomized_states=1 if 0 < b < 0.3 else 0, status=s, method="lagrangian")
                    for (b, g, lam), s in zip([(0.0, 170.0, 400.0), (0.1, 130.0, 400.0), (0.3, 100.0, 0.0)],
                                              ["optimal", status, "optimal"]))
        return TradeoffResult("send_rate[remote]", "send_rate", 0, "max", pts, 100.0, 100.0, 100.0, 0.3, 0.0)

    for status, said in (("optimal", False), ("inaccurate:precision", True)):
        c = curve(status)
        text = beyond._text({12: c}, {12: beyond.tradeoff_findings(c)})
        assert ("NOT every point closed its certificate" in text) is said, status
