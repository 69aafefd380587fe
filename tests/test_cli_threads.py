"""``--threads N`` on every solving command reaches the solvers that take it (issue 28)."""
from __future__ import annotations

import functools
from dataclasses import replace

import pytest

import wncs_lp
from wncs_lp.cli import build_parser, main
from wncs_lp.solvers import dp
from wncs_lp.solvers import matrix_free as mf
from wncs_lp.solvers.registry import AVERAGE

P12 = str(wncs_lp.scenario_path("paper_p12"))
SOLVING = ["solve", "evaluate", "simulate", "sweep", "verify", "map", "capstudy", "tradeoff", "reproduce"]


def _record(monkeypatch, module, name):
    seen = []
    real = getattr(module, name)

    @functools.wraps(real)  # the same signature: the route passes threads only to a solver that takes them
    def spy(*a, **kw):
        seen.append(kw.get("threads"))
        return real(*a, **kw)

    monkeypatch.setattr(module, name, spy)
    for key, entry in AVERAGE.items():  # the registry holds the function itself: its entries call the spy too
        if entry.run is real:
            monkeypatch.setitem(AVERAGE, key, replace(entry, run=spy))
    return seen


def test_every_solving_command_has_the_option():
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command").choices
    for command in SOLVING:
        opt = next((a for a in sub[command]._actions if a.dest == "threads"), None)
        assert opt is not None and opt.default is None, command  # default: the solvers' (the machine's cores)


@pytest.mark.parametrize("argv", [
    ["solve", P12, "--set", "tau_cap=7", "--method", "vi"],
    ["solve", P12, "--set", "tau_cap=7"],  # auto: value iteration runs (the cross-check)
    ["evaluate", P12, "--set", "tau_cap=7", "--policy", "optimal", "--method", "vi"],
    ["verify", P12, "--set", "tau_cap=7", "--method", "vi"],
    ["capstudy", P12, "--caps", "9,10", "--method", "vi"],
    ["sweep", P12, "--set", "tau_cap=7", "--values", "0.9", "--policies", "optimal", "--method", "vi", "--no-plot"],
    ["map", P12, "--set", "tau_cap=7", "--servers", "idle", "--method", "vi"],
])
def test_threads_reach_value_iteration(argv, monkeypatch, tmp_path, capsys):
    seen = _record(monkeypatch, dp, "value_iteration")
    out = ["--out", str(tmp_path / ("m.png" if argv[0] == "map" else "o"))] if argv[0] in ("sweep", "map") else []
    assert main([*argv, *out, "--threads", "2", "--json"]) in (0, 1)
    capsys.readouterr()
    assert seen and all(t == 2 for t in seen), seen


def test_threads_reach_the_matrix_free_solver_and_skip_those_without(monkeypatch, capsys):
    seen = _record(monkeypatch, mf, "matrix_free_value_iteration")
    assert main(["solve", P12, "--set", "tau_cap=7", "--method", "matrix-free", "--threads", "3", "--json"]) == 0
    assert seen == [3]
    seen = _record(monkeypatch, dp, "policy_iteration")  # takes no threads: not passed, no error
    assert main(["solve", P12, "--set", "tau_cap=7", "--method", "pi", "--threads", "3", "--json"]) == 0
    capsys.readouterr()
    assert seen == [None]


@pytest.mark.parametrize("bad", ["0", "-2", "two"])
def test_a_bad_count_is_refused_by_the_parser(bad, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["solve", P12, "--threads", bad])
    assert exc.value.code == 2 and "--threads" in capsys.readouterr().err
