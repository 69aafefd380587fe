"""The command line a researcher reaches for (issue 26): validate, shipped scenarios by name,
--policy FILE.npz, sweep --progress with an ETA, schema_version and nested stats under --json,
Ctrl-C under --json. Expectations come from the library run on its own (a solve's certificate,
the built MDP's size, the list of shipped files), never from the command's own output."""
from __future__ import annotations

import json

import numpy as np
import pytest

import wncs_lp
from wncs_lp.cli import main
from wncs_lp.models import build
from wncs_lp.progress import convergence_eta, duration, eta
from wncs_lp.scenario import load_scenario
from wncs_lp import solve

CAP = ["--set", "tau_cap=7"]


def run(capsys, *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def reference():
    """The paper's scenario solved by the library from its file path."""
    mdp = build(load_scenario(wncs_lp.scenario_path("paper_p12"), ["tau_cap=7"]))
    return mdp, solve(mdp, "pi")


def within(sol, g: float) -> bool:
    return sol.gain_lower - 1e-9 * sol.gain <= g <= sol.gain_upper + 1e-9 * sol.gain


# ----------------------------------------------------------------------------- validate, names
def test_validate_gives_the_size_without_solving(capsys, reference):
    mdp, _ = reference
    code, out, _ = run(capsys, "validate", "paper_p12", *CAP, "--json")
    d = json.loads(out)
    assert code == 0 and d["valid"] is True and d["would_build"] is True
    est = d["estimate"]
    assert est["states"] >= mdp.n_states and est["pairs"] >= mdp.n_pairs  # upper bounds
    assert est["configs"] == len(np.unique(mdp.states.config))  # every configuration has a state
    code, out, _ = run(capsys, "validate", "paper_p12", *CAP)
    assert code == 0 and f"{est['states']:,} states" in out and "a solve would build it" in out


def test_solve_dry_run_is_validate(capsys, monkeypatch):
    import wncs_lp.workflow as route

    monkeypatch.setattr(route, "run_scenario", lambda *a, **k: pytest.fail("a dry run solved"))
    code, out, _ = run(capsys, "solve", "paper_p12", *CAP, "--dry-run", "--json")
    d = json.loads(out)
    assert code == 0 and d["valid"] is True and "gain" not in d
    assert d["estimate"] == json.loads(run(capsys, "validate", "paper_p12", *CAP, "--json")[1])["estimate"]


def test_validate_names_the_bad_field(capsys):
    code, out, err = run(capsys, "validate", "paper_p12", "--set", "p=2")
    assert code == 2 and "channel.success_probability" in err and "expected a probability" in err


def test_validate_lists_the_shipped_scenarios(capsys):
    code, out, _ = run(capsys, "validate", "--list", "--json")
    assert code == 0
    assert json.loads(out)["scenarios"] == [n[:-len(".toml")] for n in wncs_lp.scenario_names()]
    assert "paper_p12" in json.loads(out)["scenarios"]


def test_a_shipped_scenario_by_name(capsys, reference):
    _, sol = reference
    code, out, _ = run(capsys, "solve", "paper_p12", *CAP, "--method", "vi", "--json")
    d = json.loads(out)
    assert code == 0 and d["scenario"] == str(wncs_lp.scenario_path("paper_p12"))
    assert within(sol, d["gain"])


def test_an_unknown_name_still_says_cannot_be_read(capsys):
    code, _, err = run(capsys, "validate", "no_such_scenario")
    assert code == 2 and "cannot be read" in err


# ----------------------------------------------------------------------------- --discount
def test_solve_discount(capsys, reference):
    _, sol = reference
    beta = 0.9
    d = {m: json.loads(run(capsys, "solve", "paper_p12", *CAP, "--discount", str(beta), "--method", m, "--json")[1])
         for m in ("pi", "lp")}
    assert all(x["status"] == "optimal" and x["criterion"] == "discounted" for x in d.values())
    assert d["lp"]["value_initial"] == pytest.approx(d["pi"]["value_initial"], rel=1e-9)  # two methods
    # for every beta, (1 - beta) min v* <= g* <= (1 - beta) max v*: pi* v* <= g* / (1 - beta) from
    # v* <= c_{d*} + beta P_{d*} v*, and g* <= g of the discounted-optimal policy = (1 - beta) pi v
    assert (1 - beta) * d["pi"]["value_min"] <= sol.gain <= (1 - beta) * d["pi"]["value_max"]


def test_solve_discount_refuses_what_it_cannot_do(capsys):
    with pytest.raises(SystemExit) as exc:  # refused by the parser, before any work
        run(capsys, "solve", "paper_p12", "--discount", "1")
    assert exc.value.code == 2 and "expected a finite number >= 0 and < 1, got '1'" in capsys.readouterr().err
    code, _, err = run(capsys, "solve", "paper_p12", "--discount", "0.9", "--method", "matrix-free")
    assert code == 2 and "the discounted criterion solves with lp, pi, vi" in err and "'matrix-free'" in err
    code, _, err = run(capsys, "solve", "paper_p12_cloud_budget", "--discount", "0.9")
    assert code == 2 and "--ignore-constraints" in err


# ----------------------------------------------------------------------------- --json layout
def test_json_has_a_schema_version_and_nested_stats(capsys):
    code, out, _ = run(capsys, "solve", "paper_p12", *CAP, "--method", "vi", "--json")
    d = json.loads(out)
    assert d["schema_version"] == 2 and d["version"] == wncs_lp.__version__
    # the method's statistics (value iteration: its sweeps, kernel, span) under "stats" only
    assert isinstance(d["stats"], dict) and "sweeps" in d["stats"] and "sweeps" not in d
    for key in ("gain", "gain_lower", "gain_upper", "status", "method", "iterations", "seconds"):
        assert key in d and key not in d["stats"]
    code, out, _ = run(capsys, "solve", "paper_p12", *CAP, "--method", "lp", "--json")
    d = json.loads(out)
    assert "lp_rows" in d["stats"] and "lp_rows" not in d


def test_errors_under_json_carry_the_schema_version(capsys):
    code, out, _ = run(capsys, "solve", "paper_p12", "--set", "p=2", "--json")
    d = json.loads(out)
    assert code == 2 and d["schema_version"] == 2 and d["type"] == "ScenarioError"


def test_ctrl_c_under_json_prints_one_object_saying_so(capsys, monkeypatch):
    import wncs_lp.workflow as route

    def interrupted(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(route, "run_scenario", interrupted)
    code, out, err = run(capsys, "solve", "paper_p12", *CAP, "--json")
    d = json.loads(out)
    assert code == 130 and d["interrupted"] is True and d["signal"] == "SIGINT" and d["exit_status"] == 130
    assert d["command"] == "solve" and "interrupted" in err
    code, out, _ = run(capsys, "solve", "paper_p12", *CAP)  # without --json: nothing on stdout
    assert code == 130 and out == ""


# ----------------------------------------------------------------------------- --policy FILE.npz
def test_a_saved_policy_is_evaluated_and_simulated(capsys, tmp_path, reference):
    _, sol = reference
    saved = tmp_path / "mine.npz"
    assert run(capsys, "solve", "paper_p12", *CAP, "--out", str(saved))[0] == 0
    code, out, _ = run(capsys, "evaluate", "paper_p12", *CAP, "--policy", str(saved), "--json")
    d = json.loads(out)
    assert code == 0 and d["policy"] == "mine" and d["randomised"] is False
    assert within(sol, d["gain"])  # the saved optimal policy, evaluated exactly
    code, out, _ = run(capsys, "simulate", "paper_p12", *CAP, "--policy", str(saved), "--slots", "4000",
                       "--reps", "8", "--json")
    d = json.loads(out)
    assert code == 0 and abs(d["mean"] - sol.gain) <= 4 * d["stderr"]


def test_a_policy_of_another_scenario_is_one_clear_error(capsys, tmp_path):
    saved = tmp_path / "cap7.npz"
    assert run(capsys, "solve", "paper_p12", *CAP, "--out", str(saved))[0] == 0
    code, _, err = run(capsys, "evaluate", "paper_p12", "--set", "tau_cap=8", "--policy", str(saved))
    assert code == 2 and "are not those of" in err and err.count("\n") == 1


# ----------------------------------------------------------------------------- sweep --progress
SWEEP = ("sweep", "paper_p12", "--set", "tau_cap=6", "--values", "0.8,0.9", "--policies", "static,greedy",
         "--no-plot")


def test_sweep_progress_counts_rows_with_an_eta(capsys, tmp_path):
    code, out, err = run(capsys, *SWEEP, "--out", str(tmp_path / "a"), "--json", "--progress")
    lines = [x for x in err.splitlines() if x.startswith("[")]
    assert code == 0 and json.loads(out)["computed"] == 4
    assert [x.split(",")[0] for x in lines] == ["[1/4", "[2/4", "[3/4", "[4/4"]
    assert all("ETA" in x for x in lines[:-1]) and "ETA" not in lines[-1]
    code, out, err = run(capsys, *SWEEP, "--out", str(tmp_path / "b"), "--no-progress")
    assert code == 0 and not [x for x in err.splitlines() if x.startswith("[")]


def test_eta_by_hand():
    # 1 of 4 steps in 10 s: 3 more steps of 10 s each
    assert eta(1, 4, 10.0) == "1/4, 10 s elapsed, ETA 30 s"
    assert eta(0, 4, 0.0) == "0/4, 0 s elapsed" and eta(4, 4, 50.0) == "4/4, 50 s elapsed"
    assert duration(200) == "3 min 20 s" and duration(7500) == "2 h 05 min"


def test_convergence_eta_by_hand():
    # a gap halving every second from 1e-2: at t = 10 it is 1e-2 / 1024; to reach 1e-9 it needs
    # log2(1e-2 / 1024 / 1e-9) = 13.25 more seconds
    points = [(float(t), 1e-2 * 0.5**t) for t in range(11)]
    assert convergence_eta(points, 1e-9) == ", ETA 13 s"
    assert convergence_eta(points[:1], 1e-9) == ""  # one point: no rate
    assert convergence_eta([(0.0, 1e-3), (1.0, 2e-3)], 1e-9) == ""  # not shrinking
    assert convergence_eta(points, 1.0) == ""  # already there


def test_value_iteration_progress_lines_carry_an_eta():
    import io

    from wncs_lp.progress import Progress
    from wncs_lp.solvers.dp import value_iteration

    mdp = build(load_scenario(wncs_lp.scenario_path("paper_p12"), ["tau_cap=10"]))
    buf = io.StringIO()
    value_iteration(mdp, progress=Progress(True, stream=buf, every=0.0), tol=1e-12)
    lines = [x for x in buf.getvalue().splitlines() if "<= g* <=" in x]
    assert len(lines) >= 3 and any("ETA" in x for x in lines)
