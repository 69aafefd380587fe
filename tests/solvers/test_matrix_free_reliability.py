"""The matrix-free solver under hostile input (issue 27): damaged policy files and tables, costs
that overflow, options out of range -- one clear error each, never a certified wrong number."""
from __future__ import annotations

import dataclasses
import io
import json

import numpy as np
import pytest

pytest.importorskip("numba")

import wncs_lp  # noqa: E402
from wncs_lp.errors import PolicyError, SolverError, WncsError  # noqa: E402
from wncs_lp.evaluate import evaluate  # noqa: E402
from wncs_lp.models.system import System  # noqa: E402
from wncs_lp.policies import MatrixFreePolicy  # noqa: E402
from wncs_lp.workflow import make_policy  # noqa: E402
from wncs_lp.solvers.matrix_free import (  # noqa: E402
    BoxLayout,
    MatrixFreeOptions,
    load_solution,
    matrix_free_evaluate,
    matrix_free_value_iteration,
)


def p12(*overrides):
    """Processes 1 (A = [[1.02, 1], [0, 1]]) and 2 (A = [[1.02]]), the paper's two servers."""
    return wncs_lp.load_scenario(wncs_lp.scenario_path("paper_p12"), ["tau_cap=8", *overrides])


@pytest.fixture(scope="module")
def saved(tmp_path_factory):
    sc = p12()
    sol = matrix_free_value_iteration(sc)
    path = tmp_path_factory.mktemp("mf") / "p12.npz"
    sol.save(path, bias=True)
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    return sc, sol, path, arrays


def _write(path, arrays):
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    path.write_bytes(buf.getvalue())
    return path


def test_a_policy_of_255s_is_refused_on_load_and_on_evaluation(saved, tmp_path):
    sc, sol, _, arrays = saved
    bad = _write(tmp_path / "bad.npz", {**arrays, "policy": np.full_like(arrays["policy"], 255)})
    with pytest.raises(PolicyError, match=r"bad\.npz: policy: state 0 \(configuration \d+, tau = \(1, 1\)\) has "
                                          r"local action 255, but configuration \d+ has \d+ action"):
        load_solution(bad, sc)
    # the same table handed to the evaluator directly (before: "optimal", gain 3.02 where the
    # true gain of any policy is above the optimum, read outside the kernel's tables)
    table = np.full(sol.local_actions.size, 255, np.uint8)
    for policy in (table, dataclasses.replace(sol, local_actions=table)):
        with pytest.raises(PolicyError, match="local action 255"):
            matrix_free_evaluate(sc, policy)
    with pytest.raises(PolicyError, match="local action 255"):
        MatrixFreePolicy(sol.system, sol.layout, table)


def test_one_entry_out_of_range_is_named(saved):
    sc, sol, _, _ = saved
    table = sol.local_actions.copy()
    layout, nact = sol.layout, sol.system.n_actions
    c = int(np.argmin(nact))  # a configuration with few actions
    s = int(layout.off[c]) + 3
    table[s] = nact[c]
    tau = tuple(int(t) for t in layout.tau_of(np.array([s]))[0])
    with pytest.raises(PolicyError, match=rf"state {s:,} \(configuration {c}, tau = \({tau[0]}, {tau[1]}\)\)"):
        matrix_free_evaluate(sc, table)


@pytest.mark.parametrize("damage", ["short policy", "float policy", "short bias", "nan bias", "no policy",
                                    "bad meta", "meta gain outside", "meta missing field", "other caps"])
def test_damaged_files_are_one_clear_error(saved, tmp_path, damage):
    sc, _, _, arrays = saved
    a = dict(arrays)
    meta = json.loads(str(a["meta"]))
    if damage == "short policy":
        a["policy"] = a["policy"][:-1]
    elif damage == "float policy":
        a["policy"] = a["policy"].astype(float)
    elif damage == "short bias":
        a["bias"] = a["bias"][:10]
    elif damage == "nan bias":
        a["bias"] = np.where(np.arange(a["bias"].size) == 5, np.nan, a["bias"])
    elif damage == "no policy":
        del a["policy"]
    elif damage == "bad meta":
        a["meta"] = np.array("{not json")
    elif damage == "meta gain outside":
        a["meta"] = np.array(json.dumps({**meta, "gain": meta["gain_upper"] + 1.0}))
    elif damage == "meta missing field":
        a["meta"] = np.array(json.dumps({k: v for k, v in meta.items() if k != "status"}))
    elif damage == "other caps":
        a["dims"] = a["dims"] + 1
    path = _write(tmp_path / "damaged.npz", a)
    with pytest.raises(PolicyError, match="damaged.npz"):
        load_solution(path, sc)


@pytest.mark.parametrize("cut", [0, 10, 200, -7])
def test_truncated_or_empty_files_are_one_clear_error(saved, tmp_path, cut):
    sc, _, path, _ = saved
    data = path.read_bytes()
    bad = tmp_path / "cut.npz"
    bad.write_bytes(data[:cut] if cut >= 0 else data[:cut] + b"garbage")
    with pytest.raises(PolicyError, match="cut.npz"):
        load_solution(bad, sc)


def test_the_saved_policy_still_loads_and_evaluates_to_its_gain(saved):
    sc, sol, path, _ = saved
    back = load_solution(path, sc)
    ev = matrix_free_evaluate(sc, back)
    # the greedy policy of the certified bias: its exact gain lies within the certificate
    assert ev.status == "optimal" and sol.gain_lower - 1e-9 <= ev.gain <= sol.gain_upper + 1e-9
    mdp = wncs_lp.build(sc)
    exact = evaluate(mdp, back.on_mdp(mdp).policy, system=back.system)
    assert ev.gain_lower - 1e-9 * ev.gain <= exact.gain <= ev.gain_upper + 1e-9 * ev.gain


# ----------------------------------------------------------------------------- overflow
def test_a_cost_that_overflows_is_named_before_any_sweep():
    """A = [[3.0]] at cap 700: q(tau) ~ 9^tau overflows float64 from tau ~ 323."""
    raw = {"model": {"kind": "wncs", "tau_cap": 700}, "channel": {"success_probability": 0.9},
           "process": [{"name": "fast", "A": [[3.0]]}],
           "server": [{"name": "s", "uplink_delay": 0, "downlink_delay": 0, "slots_per_dimension": 1}]}
    with pytest.raises(WncsError, match="overflow"):
        matrix_free_value_iteration(wncs_lp.scenario_from_dict(raw, source="<test>"), max_iter=50)


def test_values_that_overflow_stop_at_once():
    """Costs up to 1e308 a slot are finite, the values they sum to are not: one error, not sweeps
    to nan (before: 200 sweeps, then status "max_iter" with gain nan)."""
    sc = p12()
    pol = make_policy("greedy", System.from_scenario(sc))
    cost = 5e307 * np.tile(np.arange(1, 9) / 8.0, (2, 1))
    with pytest.raises(SolverError, match=r"values overflow .* the costs \(up to 1e\+308 a slot\)"):
        matrix_free_evaluate(sc, pol, cost=cost, max_iter=200)
    # the same costs scaled to 1e306 a slot are representable, and so is their evaluation
    ev = matrix_free_evaluate(sc, pol, cost=cost / 50.0)
    ref = matrix_free_evaluate(sc, pol, cost=cost / 5e307)
    assert ev.status == ref.status == "optimal" and ev.gain == pytest.approx(1e306 * ref.gain, rel=1e-8)


# ----------------------------------------------------------------------------- options
@pytest.mark.parametrize("bad", [dict(tol=-1.0), dict(tol=float("nan")), dict(tol=0.0), dict(tol=float("inf")),
                                 dict(atol=-1.0), dict(max_iter=0), dict(max_iter=2.5), dict(threads=0),
                                 dict(threads=True), dict(relax=0.0), dict(check_every=0), dict(eval_sweeps=-1),
                                 dict(warm_rel=float("nan")), dict(domain="box"), dict(on_interrupt="ignore")])
def test_options_out_of_range_are_refused_once(bad):
    (field, value), = bad.items()
    with pytest.raises(SolverError, match=field):
        MatrixFreeOptions(**bad)
    with pytest.raises(SolverError, match=field):
        matrix_free_value_iteration(p12(), **bad)


def test_an_unknown_keyword_names_the_options():
    with pytest.raises(SolverError, match=r"takes no option 'tolerance'; its options are tol, atol, max_iter"):
        matrix_free_value_iteration(p12(), tolerance=1e-9)
    with pytest.raises(SolverError, match="takes no option 'bogus'"):
        matrix_free_evaluate(p12(), np.zeros(3, np.uint8), bogus=1)


def test_options_as_a_dataclass_and_as_keywords_agree():
    sc = p12()
    a = matrix_free_value_iteration(sc, MatrixFreeOptions(tol=1e-10, extrapolate=False))
    b = matrix_free_value_iteration(sc, tol=1e-10, extrapolate=False)
    c = matrix_free_value_iteration(sc, MatrixFreeOptions(tol=1e-6), tol=1e-10, extrapolate=False)  # keywords win
    assert a.gain == b.gain == c.gain and a.iterations == b.iterations == c.iterations
    assert a.stats["tol"] == 1e-10


# ----------------------------------------------------------------------------- the result type
def test_the_result_is_its_own_type_with_a_readable_repr(saved):
    sc, sol, _, _ = saved
    assert not isinstance(sol, wncs_lp.Solution)
    assert not hasattr(sol, "sigma") and not hasattr(sol, "chain") and not hasattr(sol, "policy")
    text = repr(sol)
    assert len(text) < 2000 and text.startswith("MatrixFreeSolution of ")
    assert "local_actions: array of" in text and "status: optimal" in text
    # the same summary keys as a Solution of the enumerated MDP
    mdp = wncs_lp.build(sc)
    on = sol.on_mdp(mdp)
    assert isinstance(on, wncs_lp.Solution) and on.sigma is not None
    base = ["method", "status", "status_code", "message", "gain", "gain_lower", "gain_upper", "certificate_gap",
            "iterations", "seconds"]
    assert list(sol.summary())[:len(base)] == base == list(on.summary())[:len(base)]
    ev = matrix_free_evaluate(sc, sol)
    assert repr(ev).startswith("MatrixFreeEvaluation of ") and len(repr(ev)) < 2000
    assert ev.ok and ev.status_code == "optimal" and ev.summary()["policy"] == "optimal"


def test_layout_size_matches_the_policy(saved):
    sc, sol, _, _ = saved
    assert sol.local_actions.shape == (BoxLayout.from_system(System.from_scenario(sc)).n_states,)
