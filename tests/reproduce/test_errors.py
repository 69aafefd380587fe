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
