"""One method vocabulary, one default, the same keywords, results in the conventions researchers know
(issue 16): every command and library entry point takes the same ``--method`` names with default
``auto``; ``tol``/``progress`` work for every method; ``Solution`` has ``sigma``, ``chain()``, a
readable repr, a closed status vocabulary with a message; progress shows on stderr only."""
from __future__ import annotations

import inspect
import io
import json

import numpy as np
import pytest

import wncs_lp
from wncs_lp import methods, status
from wncs_lp.chain import PolicyChain
from wncs_lp.cli import build_parser, main
from wncs_lp.errors import SolverError
from wncs_lp.progress import Progress, wanted

P12 = str(wncs_lp.scenario_path("paper_p12"))


@pytest.fixture(scope="module")
def small():
    sc = wncs_lp.load_scenario(P12, ["tau_cap=8"])
    return sc, wncs_lp.build(sc)


def _subparsers():
    parser = build_parser()
    action = next(a for a in parser._actions if a.dest == "command")
    return action.choices


@pytest.mark.parametrize("command", ["solve", "evaluate", "simulate", "sweep", "verify", "map", "capstudy"])
def test_every_command_has_the_same_methods_and_default_auto(command):
    sub = _subparsers()[command]
    opt = next(a for a in sub._actions if a.dest == "method")
    assert opt.default == "auto"
    assert set(methods.METHODS) <= set(opt.choices)
    extra = set(opt.choices) - set(methods.METHODS)
    assert extra <= {"lagrangian", "matrix-free"}  # solve also names the constrained route and the matrix-free solver


def test_library_defaults_are_auto_and_the_vocabulary_is_the_solvers():
    from wncs_lp import solvers
    from wncs_lp.constrained.registry import run_constrained
    from wncs_lp.solvers.registry import run_average
    from wncs_lp.studies import cap_study
    from wncs_lp.policies import OptimalPolicy
    from wncs_lp.workflow import make_policy, policy_for, run_scenario
    from wncs_lp.studies import run_sweep, tradeoff

    assert set(solvers.METHODS) == set(methods.METHODS)
    for fn in (wncs_lp.solve, make_policy, policy_for, OptimalPolicy.from_scenario, run_sweep, cap_study, tradeoff,
               run_average, run_constrained, run_scenario):
        assert inspect.signature(fn).parameters["method"].default == "auto", fn.__qualname__


def test_one_registry_feeds_every_list_of_methods():
    """The help, the parser's choices and the library's tuples all come from the registry's rows."""
    assert methods.METHODS == ("auto", "lp", "lp-highs", "lp-cvxpy", "vi", "rvi", "pi")
    assert methods.SCENARIO_METHODS == methods.METHODS + ("matrix-free",)
    assert methods.CONSTRAINED_METHODS == ("auto", "lp", "lp-highs", "lp-cvxpy", "lagrangian")
    assert methods.LP_METHODS == ("lp", "lp-highs", "lp-cvxpy")
    for m in methods.METHODS:
        assert f"{m} (" in methods.METHOD_HELP
    sub = _subparsers()
    assert set(next(a for a in sub["tradeoff"]._actions if a.dest == "method").choices) == \
        set(methods.CONSTRAINED_METHODS)
    assert set(next(a for a in sub["solve"]._actions if a.dest == "method").choices) == \
        set(methods.SCENARIO_METHODS) | set(methods.CONSTRAINED_METHODS)
    with pytest.raises(SolverError, match="unknown method 'simplex'; expected one of 'auto', 'lp'"):
        methods.method("simplex")
    with pytest.raises(SolverError, match="unknown constrained method 'vi'"):
        methods.method("vi", constrained=True)


@pytest.mark.parametrize("method", methods.METHODS)
def test_tol_and_progress_are_accepted_by_every_method(small, method, capsys):
    _, mdp = small
    sol = wncs_lp.solve(mdp, method, tol=1e-8, progress=True)
    assert sol.ok
    err = capsys.readouterr()
    assert err.out == ""  # progress never touches stdout
    assert err.err.strip(), "progress=True printed nothing"


def test_policy_iteration_takes_tol_and_h0(small):
    _, mdp = small
    ref = wncs_lp.solve(mdp, "vi")
    sol = wncs_lp.solve(mdp, "pi", tol=1e-10, h0=ref.bias)
    assert sol.ok and sol.stats["tol"] == 1e-10 and sol.iterations <= 2
    assert sol.gain == pytest.approx(ref.gain, rel=1e-9)
    with pytest.raises(SolverError, match="not both"):
        wncs_lp.solve(mdp, "pi", tol=1e-8, cert_rtol=1e-6)
    for method in ("auto", "vi", "rvi"):  # the same warm-start keyword
        assert wncs_lp.solve(mdp, method, h0=ref.bias).gain == pytest.approx(ref.gain, rel=1e-8)


def test_an_unknown_keyword_is_one_clear_solver_error(small):
    _, mdp = small
    with pytest.raises(SolverError, match=r"method 'pi' takes no keyword 'tolerance'; it takes .*tol"):
        wncs_lp.solve(mdp, "pi", tolerance=1e-8)


def test_solution_sigma_chain_and_repr(small):
    _, mdp = small
    sol = wncs_lp.solve(mdp, "pi")
    np.testing.assert_array_equal(sol.sigma, mdp.a_indices[sol.policy])
    np.testing.assert_array_equal(sol.sigma, sol.actions(mdp))
    chain = sol.chain(mdp)
    assert isinstance(chain, PolicyChain) and chain.is_unichain
    assert chain.stationary.sum() == pytest.approx(1.0)
    np.testing.assert_allclose(chain.stationary, np.add.reduceat(sol.occupation, mdp.pair_ptr[:-1]), atol=1e-12)
    text = repr(sol)
    lines = text.splitlines()
    assert len(lines) > 8 and lines[0].startswith("Solution of 2,703 states by pi")
    assert any(line.strip().startswith("gain:") for line in lines)
    assert "array(" not in text and "sigma: array of 2,703 action indices" in text
    for m in ("vi", "rvi", "lp", "auto"):
        assert wncs_lp.solve(mdp, m).sigma is not None


@pytest.mark.parametrize("text, code", [
    ("optimal", status.OPTIMAL), ("max_iter", status.MAX_ITER), ("inaccurate", status.INACCURATE),
    ("inaccurate:polish_max_iter", status.INACCURATE), ("inaccurate:AlmostSolved", status.INACCURATE),
    ("inaccurate:cross_check", status.INACCURATE), ("interrupted", status.INTERRUPTED),
    ("infeasible", status.INFEASIBLE), ("error: boom", status.FAILED),
])
def test_status_vocabulary(small, text, code):
    from dataclasses import replace

    _, mdp = small
    sol = replace(wncs_lp.solve(mdp, "vi"), status=text)
    assert sol.status == text  # the old strings stay as they were
    assert sol.status_code == code and code in status.STATUS_CODES
    assert sol.message and ":" not in sol.message.split(" ")[0]
    assert sol.summary()["status_code"] == code and sol.summary()["message"] == sol.message
    if text == "inaccurate:AlmostSolved":
        assert "'AlmostSolved'" in sol.message


def test_constrained_solution_follows_the_vocabulary():
    from wncs_lp import solve

    sc = wncs_lp.load_scenario(wncs_lp.scenario_path("paper_p12_cloud_budget"), ["tau_cap=8"])
    sol = solve(wncs_lp.build(sc), "lp", constraints=sc.constraints)
    assert sol.status_code == status.OPTIMAL and "certificate" in sol.message
    assert sol.summary()["status_code"] == status.OPTIMAL


# ----------------------------------------------------------------------------- progress
class _Tty(io.StringIO):
    def isatty(self):
        return True


def test_progress_rewrites_one_line_on_a_terminal_and_prints_lines_elsewhere():
    tty = _Tty()
    p = Progress(True, stream=tty, every=0.0)
    p.phase("phase")
    p.tick("a")
    p.tick("b")
    p.done("c")
    assert tty.getvalue() == "phase\n\r\x1b[Ka\r\x1b[Kb\r\x1b[Kc\n"
    log = io.StringIO()
    p = Progress(True, stream=log, every=0.0)
    p.tick("a")
    p.done("b")
    assert log.getvalue() == "a\nb\n"
    assert wanted(None, json=False, stream=tty) and not wanted(None, json=True, stream=tty)
    assert not wanted(None, json=False, stream=log) and wanted(True, json=True, stream=log)


def test_solve_shows_progress_with_the_flag_and_stays_clean_json(capsys):
    assert main(["solve", P12, "--set", "tau_cap=8", "--method", "lp", "--json", "--progress"]) == 0
    cap = capsys.readouterr()
    assert json.loads(cap.out)["status"] == "optimal"
    assert "building the MDP" in cap.err and "[lp] interior-point iteration" in cap.err and "[pi] iteration" in cap.err
    assert main(["solve", P12, "--set", "tau_cap=8", "--method", "vi", "--json"]) == 0
    cap = capsys.readouterr()
    json.loads(cap.out)
    assert "[vi" not in cap.err and "building" not in cap.err  # not a terminal, --json: quiet


def test_evaluate_and_map_show_progress(tmp_path, capsys):
    assert main(["evaluate", P12, "--set", "tau_cap=8", "--policy", "optimal", "--method", "vi", "--progress",
                 "--json"]) == 0
    cap = capsys.readouterr()
    json.loads(cap.out)
    assert "[vi:" in cap.err and "gap" in cap.err and "evaluating the optimal policy exactly" in cap.err
    out = tmp_path / "m.png"
    assert main(["map", P12, "--set", "tau_cap=8", "--servers", "idle", "--out", str(out), "--progress"]) == 0
    assert out.exists() and "drawing the map" in capsys.readouterr().err


def test_start_up_imports_only_what_the_command_needs():
    import subprocess
    import sys

    code = ("import sys\nimport wncs_lp.cli\nprint(sorted(m for m in ('numpy', 'scipy', 'numba', 'cvxpy', 'matplotlib', "
            "'clarabel') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"  # parsing the command line (and --help, --version, bad input) loads no numerics
    code = ("import contextlib, io, sys\nfrom wncs_lp.cli import main\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n"
            f"    assert main(['solve', {P12!r}, '--set', 'tau_cap=9', '--method', 'vi', '--json']) == 0\n"
            "print(sorted(m for m in ('cvxpy', 'matplotlib', 'clarabel', 'dask', 'tqdm') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"
