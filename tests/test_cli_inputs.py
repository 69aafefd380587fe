"""Bad or surprising input on the command line (issue 16): checked before any work, warned in words,
answered in the command line's own terms."""
from __future__ import annotations

import json
import warnings

import pytest

import wncs_lp
from wncs_lp.cli import main
from wncs_lp.errors import ScenarioWarning

P12 = str(wncs_lp.scenario_path("paper_p12"))


def test_map_with_an_unknown_image_format_fails_before_the_solve(tmp_path, monkeypatch, capsys):
    import wncs_lp.models.guard as guard

    def no_build(*a, **k):
        raise AssertionError("the MDP was built before --out was checked")

    monkeypatch.setattr(guard, "build_checked", no_build)
    rc = main(["map", P12, "--servers", "idle", "--out", str(tmp_path / "x.xyz"), "--json"])
    cap = capsys.readouterr()
    assert rc == 2 and "Traceback" not in cap.err
    out = json.loads(cap.out)
    assert "x.xyz" in out["error"] and ".png" in out["error"] and ".svg" in out["error"]
    rc = main(["map", P12, "--servers", "idle", "--out", str(tmp_path / "missing" / "x.png")])
    assert rc == 2 and "does not exist" in capsys.readouterr().err
    assert not (tmp_path / "missing").exists()


@pytest.mark.parametrize("sets, words", [
    (["p=0"], "no update is ever delivered"),
    (["server.edge.p_down=0", "tau_cap=12"], "server 'edge' never delivers"),
    (["tau_cap=5"], "tau_cap = 5 is at most the shortest loop"),
])
def test_degenerate_inputs_warn_in_words_on_stderr(sets, words, capsys):
    rc = main(["solve", P12, *[a for s in sets for a in ("--set", s)], "--method", "vi", "--json"])
    cap = capsys.readouterr()
    assert rc == 0  # a warning, not an error
    json.loads(cap.out)
    lines = [ln for ln in cap.err.splitlines() if ln.startswith("warning: ")]
    assert any(words in ln for ln in lines), cap.err
    assert "ScenarioWarning" not in cap.err  # words, not a Python warning
    sc = wncs_lp.load_scenario(P12, sets)
    with pytest.warns(ScenarioWarning, match=words.split("'")[0]):
        wncs_lp.build(sc)


def test_a_sound_scenario_warns_nothing(capsys):
    sc = wncs_lp.load_scenario(P12, ["tau_cap=9"])
    assert sc.degenerate_warnings() == []
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        wncs_lp.build(sc)


def test_messages_speak_the_command_line(capsys):
    assert main(["solve", P12, "--set", "tau_cap"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: --set: override 'tau_cap': expected KEY=VALUE") and "<command line>" not in err
    # a multichain policy: the way out is the command's option, not the library keyword
    assert main(["evaluate", P12, "--set", "tau_cap=7", "--set", "p=1", "--policy", "static"]) == 2
    err = capsys.readouterr().err
    assert "multichain" in err and "--from-initial" in err and "multichain=" not in err
    assert main(["evaluate", P12, "--set", "tau_cap=7", "--set", "p=1", "--policy", "static", "--from-initial"]) == 0
    capsys.readouterr()
    # a 1-based option answers in 1-based terms
    assert main(["evaluate", P12, "--set", "tau_cap=7", "--policy", "static", "--assignment", "remote"]) == 2
    err = capsys.readouterr().err
    assert "one server per process (2 processes" in err and "0.." not in err


def test_docs_scenarios_page_names_every_field_and_its_examples_load():
    import re
    import tomllib
    from pathlib import Path

    from wncs_lp import scenario as S

    page = (Path(__file__).resolve().parent.parent / "docs" / "scenarios.md").read_text()
    fields = (S._MODEL_FIELDS | S._CHANNEL_FIELDS | S._PROCESS_FIELDS | S._SERVER_FIELDS | S._CONSTRAINT_FIELDS
              | set(S.QUANTITIES) | set(S.KINDS))
    missing = sorted(f for f in fields if f"`{f}`" not in page and f'"{f}"' not in page)
    assert not missing, f"docs/scenarios.md does not describe {missing}"
    base = Path(P12).read_text().replace("allow_idle = false", "allow_idle = true")
    blocks = re.findall(r"```toml\n(.*?)```", page, flags=re.S)
    assert len(blocks) >= 4
    for block in blocks:
        raw = tomllib.loads(block if "[model]" in block else base + "\n" + block)
        sc = wncs_lp.scenario_from_dict(raw, source="docs/scenarios.md")
        assert sc.n_processes >= 1
