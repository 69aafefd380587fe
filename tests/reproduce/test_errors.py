"""A claim that cannot be computed is an ERROR (exit 1), never a FAILS; bad arguments create nothing."""
from __future__ import annotations

import json

import pytest

import wncs_lp.reproduce as rep
from wncs_lp.cli import main
from wncs_lp.errors import WncsError


def test_a_claim_that_raises_is_an_error_and_the_command_exits_1(tmp_path, monkeypatch, capsys):
    def broken(ctx):
        raise FileNotFoundError("scenario missing")

    monkeypatch.setattr(rep, "_claims", lambda: {"C1": broken})
    code = main(["reproduce", "--out", str(tmp_path / "r"), "--profile", "quick", "--claims", "C1"])
    assert code == 1
    err = capsys.readouterr().err
    assert "1 claim(s) could not be computed (C1)" in err
    claims = json.loads((tmp_path / "r" / "report.json").read_text())["claims"]
    (c1,) = [c for c in claims if c["id"] == "C1"]
    assert c1["verdict"] == "ERROR" and "could not be computed: FileNotFoundError" in c1["summary"]


def test_unknown_claim_is_refused_before_anything_is_written(tmp_path):
    out = tmp_path / "never"
    with pytest.raises(WncsError, match="unknown claim\\(s\\) C99"):
        rep.run_reproduction(out, "quick", claims=["C99"])
    assert not out.exists()
    assert main(["reproduce", "--out", str(out), "--claims", "C99"]) == 2 and not out.exists()


# ----------------------------------------------------------------------------- beyond the paper
def _beyond_fails(monkeypatch):
    """B2's matrix-free solver unavailable (as on an install without numba) and B1's trade-off failing."""
    import wncs_lp.solvers.matrix_free as mf
    from wncs_lp.errors import SolverError
    from wncs_lp.reproduce import beyond

    def no_solver(*a, **k):
        raise SolverError("the matrix-free solver needs numba")

    monkeypatch.setattr(mf, "matrix_free_value_iteration", no_solver)
    monkeypatch.setattr(beyond, "tradeoff", no_solver)


def test_a_section_beyond_the_paper_that_fails_is_an_error_listed_first_and_exits_1(tmp_path, monkeypatch, capsys):
    from wncs_lp.reproduce.beyond import TITLES

    _beyond_fails(monkeypatch)
    out = tmp_path / "r"
    code = main(["reproduce", "--out", str(out), "--profile", "quick", "--claims", "B1,B2"])
    assert code == 1
    cap = capsys.readouterr()
    assert "2 section(s) beyond the paper could not be computed (B1, B2)" in cap.err
    assert "[1/2] B1 ERROR" in cap.err and "[2/2] B2 ERROR" in cap.err  # one progress line per section
    assert "B2 ERROR" in cap.out and TITLES["B2"] in cap.out
    beyond = {e["id"]: e for e in json.loads((out / "report.json").read_text())["beyond"]}
    for sid in ("B1", "B2"):
        assert beyond[sid]["status"] == "ERROR"
        assert beyond[sid]["title"] == TITLES[sid]  # the title is kept, the error is in the summary
        assert beyond[sid]["summary"] == "could not be computed: SolverError: the matrix-free solver needs numba"
    md = (out / "report.md").read_text()
    first, contents = md.split("## Contents and verdicts", 1)
    assert "ERROR: 2 part(s) of this report could not be computed" in first
    assert first.index(TITLES["B1"]) < first.index(TITLES["B2"])
    assert md.count("could not be computed: SolverError: the matrix-free solver needs numba") >= 4
    assert f"### B2: {TITLES['B2']} (ERROR: could not be computed)" in contents
    page = (out / "report.html").read_text()
    assert page.index('class="errors"') < page.index('id="contents"') < page.index('id="b2"')


def test_b2_without_numba_is_an_error_and_exits_1(tmp_path, monkeypatch, capsys):
    """The real unavailability path: numba disabled, the matrix-free solver says so, B2 is an ERROR."""
    monkeypatch.setenv("WNCS_LP_NO_NUMBA", "1")
    out = tmp_path / "r"
    assert main(["reproduce", "--out", str(out), "--profile", "quick", "--claims", "B2", "--json"]) == 1
    printed = json.loads(capsys.readouterr().out)
    assert printed["errors"] == ["B2"]
    (b2,) = printed["beyond"]
    assert b2["status"] == "ERROR" and "needs numba" in b2["summary"]


def test_a_partial_run_keeps_an_earlier_error_first_and_exits_1(tmp_path, monkeypatch, capsys):
    """A later partial run that computes only C1 keeps the B2 error of the first in the same report:
    still listed first, still exit 1 (the exit status is the report's)."""
    monkeypatch.setenv("WNCS_LP_NO_NUMBA", "1")
    out = tmp_path / "r"
    assert main(["reproduce", "--out", str(out), "--profile", "quick", "--claims", "B2"]) == 1
    monkeypatch.setattr(rep, "_claims", lambda: {"C1": lambda ctx: rep.ClaimResult("C1", "Fig. 3", "", "HOLDS", "ok")})
    capsys.readouterr()
    assert main(["reproduce", "--out", str(out), "--profile", "quick", "--claims", "C1"]) == 1
    assert "1 section(s) beyond the paper could not be computed (B2)" in capsys.readouterr().err
    md = (out / "report.md").read_text()
    first = md.split("## Contents and verdicts")[0]
    assert "ERROR: 1 part(s) of this report could not be computed" in first and "[B2: " in first


def test_an_error_of_an_older_report_without_a_status_stays_an_error(tmp_path, monkeypatch):
    """A report.json written before sections had a status (its B2 titled "could not be computed")."""
    from wncs_lp.reproduce.beyond import TITLES

    out = tmp_path / "r"
    out.mkdir()
    old = {"id": "B2", "title": "could not be computed", "summary": "could not be computed: SolverError: no numba",
           "numbers": {}, "figures": [], "tables": [], "details": "", "seconds": 0.1}
    (out / "report.json").write_text(json.dumps({"claims": [], "beyond": [old], "provenance": {}}))
    monkeypatch.setattr(rep, "_claims", lambda: {"C1": lambda ctx: rep.ClaimResult("C1", "Fig. 3", "", "HOLDS", "ok")})
    assert main(["reproduce", "--out", str(out), "--profile", "quick", "--claims", "C1"]) == 1
    (b2,) = json.loads((out / "report.json").read_text())["beyond"]
    assert b2["status"] == "ERROR" and b2["title"] == TITLES["B2"]
