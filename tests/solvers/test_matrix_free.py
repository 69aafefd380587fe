"""The matrix-free solver (wncs_lp.solvers.matrix_free) against the stored-matrix solvers.

On small instances of every shape the models take, the matrix-free certified value iteration
must agree with ``solve(build(sc), "vi")`` within both certificates, its exact reachable set
must be the state set that ``build`` enumerates, its policy (mapped onto the MDP) must have the
optimal gain, and its matrix-free policy evaluation must equal ``wncs_lp.evaluate.evaluate``.
"""
from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("numba")

import wncs_lp  # noqa: E402
from wncs_lp.errors import PolicyError, SolverError  # noqa: E402
from wncs_lp.evaluate import evaluate  # noqa: E402
from wncs_lp.models.system import System  # noqa: E402
from wncs_lp.workflow import make_policy  # noqa: E402
from wncs_lp.simulate import simulate  # noqa: E402
from wncs_lp.solvers import bracket  # noqa: E402
from wncs_lp.workflow import run_scenario  # noqa: E402
from wncs_lp.solvers.matrix_free import (  # noqa: E402
    BoxLayout,
    MatrixFreeSolution,
    drains_to_initial,
    load_solution,
    matrix_free_evaluate,
    matrix_free_value_iteration,
    reachable_mask,
)

A1 = [[1.02, 1, 0, 1], [0, 1, 0.2, 0], [0, 0, 1, 0], [0, 0, 0, 1.01]]
A2 = [[1, 1, 0], [0, 1.02, 0], [0, 0, 1]]
A3 = [[1.02, 1], [0, 1]]


def scenario(procs, servers, *, p=0.9, idle=False, distinct=True, cap=5, kind="wncs", preemptive=True):
    """A scenario from processes (A matrices, or dicts of process fields) and servers
    ((U, D, slots_per_dimension) or dicts of server fields)."""
    plist = []
    for k, pr in enumerate(procs):
        entry = {"name": f"p{k + 1}"}
        entry.update(pr if isinstance(pr, dict) else {"A": pr})
        plist.append(entry)
    slist = []
    for m, sv in enumerate(servers):
        entry = {"name": f"s{m + 1}"}
        if isinstance(sv, dict):
            entry.update(sv)
        else:
            entry.update(uplink_delay=sv[0], downlink_delay=sv[1], slots_per_dimension=sv[2])
        slist.append(entry)
    model = {"kind": kind, "tau_cap": cap}
    if kind == "wncs":
        model.update(allow_idle=idle, distinct=distinct)
    else:
        model.update(preemptive=preemptive)
    raw = {"model": model, "channel": {"success_probability": p}, "process": plist, "server": slist}
    return wncs_lp.scenario_from_dict(raw, source="<test>")


def paper(name, *overrides):
    return wncs_lp.load_scenario(wncs_lp.scenario_path(name), list(overrides))


_SOLVED: dict = {}
_BUILT: dict = {}


def solved(sc):
    """``matrix_free_value_iteration(sc)`` with its defaults, computed once per test process: the
    paper's instances at caps 7 and 8 are the reference of several tests (read, never changed)."""
    key = sc.fingerprint()
    if key not in _SOLVED:
        _SOLVED[key] = matrix_free_value_iteration(sc)
    return _SOLVED[key]


def built(sc):
    """``wncs_lp.build(sc)``, once per test process (read, never changed)."""
    key = sc.fingerprint()
    if key not in _BUILT:
        _BUILT[key] = wncs_lp.build(sc)
    return _BUILT[key]


# every shape: 1-4 processes, 1-3 servers, U and D from 0 to 2, idling allowed or not, p = 1,
# per-link probabilities, per-process caps and weights, both preemption variants
SHAPES = {
    "1p-1s-U0D0": lambda: scenario([[[1.1]]], [(0, 0, 1)], cap=10),
    "1p-1s-U2D2-T2": lambda: scenario([[[1.05]]], [(2, 2, 2)], cap=12),
    "1p-1s-U1D0-idle": lambda: scenario([A3], [(1, 0, 1)], idle=True, cap=10),
    "2p-2s-paper-cap8": lambda: paper("paper_p12", "tau_cap=8"),
    "2p-2s-U0D2-U2D0-idle": lambda: scenario([[[1.1]], [[1.05]]], [(0, 2, 1), (2, 0, 1)], idle=True, p=0.7),
    "2p-1s-U1D1": lambda: scenario([A3, [[1.1]]], [(1, 1, 1)], cap=7),
    "2p-2s-not-distinct": lambda: scenario([[[1.1]], [[1.02]]], [(0, 0, 1), (1, 1, 1)], distinct=False, cap=6),
    "2p-2s-p1-idle": lambda: paper("paper_p12", "tau_cap=8", "p=1", "model.allow_idle=true"),
    "2p-2s-p1": lambda: scenario([[[1.1]], [[1.05]]], [(0, 0, 1), (1, 1, 1)], p=1.0, cap=6),
    "2p-2s-links": lambda: scenario(
        [{"A": [[1.1]], "weight": 2.0, "tau_cap": 7}, {"A": A3, "tau_cap": 4}],
        [{"uplink_delay": 0, "downlink_delay": 1, "slots_per_dimension": 1, "p_up": 0.8, "p_down": 0.95},
         {"uplink_delay": 1, "downlink_delay": 0, "processing_time": [2, 1], "p_up": 0.6}],
    ),
    "2p-3s-mixed-idle": lambda: scenario([[[1.1]], [[1.05]]], [(0, 1, 1), (1, 0, 1), (2, 2, 1)], idle=True, cap=5),
    "3p-3s-mixed": lambda: scenario([[[1.1]], [[1.05]], [[1.02]]], [(0, 0, 1), (1, 1, 1), (0, 1, 1)], cap=4),
    "3p-2s-paper-cap7": lambda: paper("paper_p123", "tau_cap=7"),
    "3p-1s-U0D0": lambda: scenario([[[1.1]], [[1.05]], [[1.02]]], [(0, 0, 1)], cap=5),
    "4p-2s-paper-cap7": lambda: paper("paper_p1234", "tau_cap=7"),
    "4p-1s-U1D2": lambda: scenario([[[1.1]], [[1.05]], [[1.02]], [[1.01]]], [(1, 2, 1)], cap=5),
    "preemption-p12": lambda: paper("paper_preemption_p12", "tau_cap=8"),
    "preemption-non-preemptive": lambda: scenario([[[1.1]], A3], [(1, 1, 1)], kind="preemption",
                                                  preemptive=False, cap=6),
    "preemption-u0d0-p1": lambda: scenario([[[1.1]], [[1.05]]], [(0, 0, 1)], kind="preemption", p=1.0, cap=5),
}


def _within(g, lo, hi, rel=1e-9):
    slack = rel * max(abs(g), 1.0)
    return lo - slack <= g <= hi + slack


@pytest.fixture(scope="module", params=sorted(SHAPES))
def case(request):
    sc = SHAPES[request.param]()
    mdp = built(sc)
    vi = wncs_lp.solve(mdp, "vi")
    mf = solved(sc)
    return request.param, sc, mdp, vi, mf


def test_gain_equals_the_stored_matrix_solver(case):
    name, sc, mdp, vi, mf = case
    assert vi.status == "optimal" and mf.status == "optimal", (name, mf.stats)
    assert mf.gap <= 1e-9 or mf.gain_upper - mf.gain_lower <= 1e-12 * mf.stats["n_states"]
    assert _within(vi.gain, mf.gain_lower, mf.gain_upper), (name, vi.gain, mf.gain_lower, mf.gain_upper)
    assert _within(mf.gain, vi.gain_lower, vi.gain_upper), (name, mf.gain, vi.gain_lower, vi.gain_upper)


def test_layout_contains_the_reachable_set_and_the_mask_is_it(case):
    name, sc, mdp, vi, mf = case
    system = mf.system
    layout = mf.layout
    idx = layout.index(np.asarray(mdp.states.tau), np.asarray(mdp.states.config))
    assert np.all(idx >= 0) and np.unique(idx).size == mdp.n_states
    mask = reachable_mask(system, layout)
    assert int(mask.sum()) == mdp.n_states
    assert np.all(mask[idx] == 1)
    # the hull's bracket closes on R's gain unless some link never loses an update
    if not drains_to_initial(system):
        assert mf.stats["domain"] == "reachable" and mf.stats["n_reachable"] == mdp.n_states


def test_policy_and_bias_on_the_mdp(case):
    name, sc, mdp, vi, mf = case
    on = mf.on_mdp(mdp)
    assert on.policy.shape == (mdp.n_states,)
    assert np.all(mdp.s_indices[on.policy] == np.arange(mdp.n_states))
    assert on.bias[0] == 0.0
    # the certificate recomputed by the stored-matrix operator on the MDP is at least as tight
    lo, hi = bracket(mdp, on.bias)
    tol = 1e-9 * abs(mf.gain)
    assert mf.gain_lower - tol <= lo and hi <= mf.gain_upper + tol
    # the greedy policy of the certified bias is optimal (exact evaluation of the enumerated chain)
    ev = evaluate(mdp, on.policy, system=mf.system, multichain="initial")
    assert _within(ev.gain, vi.gain_lower, vi.gain_upper, rel=1e-8), (name, ev.gain, vi.gain)


def test_policy_evaluation_equals_the_exact_evaluation(case):
    name, sc, mdp, vi, mf = case
    system = mf.system
    names = ["greedy", "suboptimal"] + (["static"] if system.model.has_static_policy else [])
    if mdp.n_pairs <= 50_000:  # the randomised chain's exact evaluation is slow on larger MDPs
        names.append("random")
    for pname in names:
        try:
            ref = evaluate(mdp, make_policy(pname, system, mdp))
        except PolicyError:  # multichain (p = 1): no single gain to compare
            continue
        ev = matrix_free_evaluate(system, make_policy(pname, system, mdp))
        assert ev.status == "optimal", (name, pname, ev.stats)
        assert _within(ref.gain, ev.gain_lower, ev.gain_upper, rel=1e-8), (name, pname, ref.gain, ev.gain_lower,
                                                                           ev.gain_upper)
    # the solver's own policy evaluates to the optimal gain
    ev = matrix_free_evaluate(system, mf)
    if ev.status == "optimal":
        assert _within(ev.gain, vi.gain_lower, vi.gain_upper, rel=1e-8)


# ------------------------------------------------------------------------- API and properties
def test_solve_registers_the_method_on_a_built_mdp():
    sc = paper("paper_p12", "tau_cap=8")
    mdp = wncs_lp.build(sc)
    sol = wncs_lp.solve(mdp, "matrix-free")
    ref = wncs_lp.solve(mdp, "vi")
    assert sol.method == "matrix-free" and sol.status == "optimal"
    assert sol.policy.shape == (mdp.n_states,) and sol.bias.shape == (mdp.n_states,)
    assert _within(ref.gain, sol.gain_lower, sol.gain_upper)
    direct = run_scenario(sc, "matrix-free").solution
    assert isinstance(direct, MatrixFreeSolution) and direct.gain == pytest.approx(sol.gain, rel=1e-12)
    with pytest.raises(SolverError, match="matrix-free"):
        wncs_lp.solve(wncs_lp.MDP.from_dense(np.ones((1, 1, 1)), np.ones((1, 1))), "matrix-free")


@pytest.mark.slow
def test_threads_give_the_same_certified_gain():
    # cap 6: the same 486 configurations as cap 7 on 48k states instead of 128k (beside another
    # busy worker two threads share one core, at a pace set by the states they sweep)
    sc = paper("paper_p1234", "tau_cap=6")
    one = matrix_free_value_iteration(sc, threads=1)
    two = matrix_free_value_iteration(sc, threads=2)
    assert one.status == two.status == "optimal" and two.stats["threads"] == 2
    assert _within(one.gain, two.gain_lower, two.gain_upper) and _within(two.gain, one.gain_lower, one.gain_upper)
    ev = matrix_free_evaluate(sc, one, threads=2)
    assert _within(ev.gain, one.gain_lower, one.gain_upper, rel=1e-8)
    # two processes: one tile, so the threads split each tile's configurations instead
    sc = paper("paper_p12", "tau_cap=10")
    one = matrix_free_value_iteration(sc, threads=1)
    two = matrix_free_value_iteration(sc, threads=2)
    assert two.stats["threads"] == 2
    assert _within(one.gain, two.gain_lower, two.gain_upper) and _within(two.gain, one.gain_lower, one.gain_upper)


@pytest.mark.parametrize("options", [dict(warm_start=True), dict(extrapolate=False), dict(scheme="gs"),
                                     dict(scheme="jacobi"), dict(eval_sweeps=3, relax=1.0)])
def test_solver_options_reach_the_same_gain(options):
    sc = paper("paper_p1234", "tau_cap=7")
    ref = solved(sc)
    sol = matrix_free_value_iteration(sc, **options)
    assert sol.status == "optimal", sol.stats
    assert _within(ref.gain, sol.gain_lower, sol.gain_upper) and _within(sol.gain, ref.gain_lower, ref.gain_upper)


def test_gain_grows_with_the_cap():
    gains = [matrix_free_value_iteration(paper("paper_p12", f"tau_cap={c}"), tol=1e-10) for c in (7, 9, 11, 14)]
    for a, b in zip(gains, gains[1:]):
        assert a.gain_lower <= b.gain_upper and a.gain <= b.gain + 1e-9 * b.gain


def test_monte_carlo_of_the_policy_agrees_with_its_gain():
    sc = paper("paper_p1234", "tau_cap=7")
    sol = solved(sc)
    from wncs_lp.policies import MatrixFreePolicy

    pol = MatrixFreePolicy.from_solution(sol)
    assert isinstance(pol, MatrixFreePolicy)
    res = simulate(pol, slots=4000, reps=16, seed=3, burn_in=200, progress=False)
    assert abs(res.mean - sol.gain) <= 4 * res.stderr, (res.mean, res.stderr, sol.gain)


def test_save_and_load_round_trip(tmp_path):
    sc = paper("paper_p12", "tau_cap=8")
    sol = solved(sc)
    path = tmp_path / "p12.npz"
    sol.save(path, bias=True)
    back = load_solution(path, sc)
    assert back.gain == sol.gain and np.array_equal(back.local_actions, sol.local_actions) and np.array_equal(back.bias, sol.bias)
    tau = np.array([[3, 2], [6, 6]])
    assert np.array_equal(back.act(tau, np.array([0, 0])), sol.act(tau, np.array([0, 0])))
    with pytest.raises(PolicyError, match="another scenario"):
        load_solution(path, paper("paper_p12", "tau_cap=9"))


def test_an_edited_solution_file_is_refused_or_not_trusted(tmp_path):
    """The certificate is bound to the policy: a file whose policy was changed to other valid
    actions (its true gain 5% above the stored one in the issue) is refused; with the digest
    removed too it loads, but is not called optimal."""
    import io
    import json

    sc = paper("paper_p12", "tau_cap=8")
    path = tmp_path / "p12.npz"
    solved(sc).save(path, bias=True)
    with np.load(path, allow_pickle=False) as z:
        saved = {k: z[k] for k in z.files}
    pol = saved["policy"]
    layout = BoxLayout.from_system(System.from_scenario(sc))
    n_act = np.repeat(System.from_scenario(sc).n_actions, np.diff(layout.off))  # each state's action count
    other = (pol.astype(np.int64) + 1) % n_act  # another valid action where there is a choice
    flip = (np.random.default_rng(1).random(pol.size) < 0.2) & (n_act > 1)
    assert flip.sum() > 100
    meta = json.loads(str(saved["meta"]))
    widened = np.array(json.dumps({**meta, "gain_lower": meta["gain_lower"] - 1.0}))  # digest kept
    del meta["digest"]
    for edit, refused in (({"policy": np.where(flip, other, pol).astype(pol.dtype)}, True), ({"bias": saved["bias"] * 2}, True),
                          ({"meta": widened}, True),
                          ({"policy": np.where(flip, other, pol).astype(pol.dtype), "meta": np.array(json.dumps(meta))}, False)):
        buf = io.BytesIO()
        np.savez(buf, **{**saved, **edit})
        (tmp_path / "edited.npz").write_bytes(buf.getvalue())
        if refused:
            with pytest.raises(PolicyError, match="digest"):
                load_solution(tmp_path / "edited.npz", sc)
        else:
            back = load_solution(tmp_path / "edited.npz", sc)
            assert not back.status.ok and back.status == "inaccurate:unverified"


def test_interrupt_returns_a_certified_iterate(monkeypatch):
    from wncs_lp.solvers.matrix_free.sweeper import Sweeper

    sc = paper("paper_p12", "tau_cap=8")
    calls = {"n": 0}
    real = Sweeper.all_actions

    def flaky(self, *args):
        calls["n"] += 1
        if calls["n"] == 12:
            raise KeyboardInterrupt
        return real(self, *args)

    monkeypatch.setattr(Sweeper, "all_actions", flaky)
    sol = matrix_free_value_iteration(sc)
    assert sol.status == "interrupted" and sol.gain_lower <= sol.gain <= sol.gain_upper
    ref = wncs_lp.solve(wncs_lp.build(sc), "vi")
    assert sol.gain_lower - 1e-9 <= ref.gain <= sol.gain_upper + 1e-9
    calls["n"] = 0
    with pytest.raises(KeyboardInterrupt):
        matrix_free_value_iteration(sc, on_interrupt="raise")


def test_bad_input_and_missing_numba(monkeypatch):
    sc = paper("paper_p12", "tau_cap=7")
    with pytest.raises(SolverError, match="scheme"):
        matrix_free_value_iteration(sc, scheme="nope")
    with pytest.raises(SolverError, match="domain"):
        matrix_free_value_iteration(sc, domain="nope")
    with pytest.raises(SolverError, match="h0"):
        matrix_free_value_iteration(sc, h0=np.zeros(3))
    n = BoxLayout.from_system(System.from_scenario(sc)).n_states
    with pytest.raises(PolicyError, match="layout state"):
        matrix_free_evaluate(sc, np.zeros(n + 1, np.int64))
    monkeypatch.setenv("WNCS_LP_NO_NUMBA", "1")
    with pytest.raises(SolverError, match="numba"):
        matrix_free_value_iteration(sc)


def test_size_guard_knows_the_matrix_free_memory():
    from wncs_lp.models.guard import SizeLimitError, check_size, estimate_size

    sc = paper("paper_p1234", "tau_cap=8")
    est = estimate_size(sc)
    layout = BoxLayout.from_system(System.from_scenario(sc))
    assert est.matrix_free_states == layout.n_states
    assert est.matrix_free_bytes >= 10 * layout.n_states
    check_size(sc, method="matrix-free", limit_bytes=est.matrix_free_bytes)
    with pytest.raises(SizeLimitError, match="matrix-free"):
        check_size(sc, method="matrix-free", limit_bytes=est.matrix_free_bytes - 1)
    # a refused build names the matrix-free route when it fits
    big = paper("paper_p1234", "tau_cap=20")
    est = estimate_size(big)
    with pytest.raises(SizeLimitError, match="--method matrix-free"):
        check_size(big, limit_bytes=est.matrix_free_bytes)


@pytest.mark.parametrize("options", [dict(scheme="mpi"), dict(scheme="jacobi"), dict(scheme="mpi", warm_start=True)])
def test_an_unfinished_run_returns_the_iterate_of_its_certificate(options):
    sc = paper("paper_p1234", "tau_cap=7")
    mdp = built(sc)
    for budget in (1, 2, 7, 23, 41, 47):  # the default closes after 56
        sol = matrix_free_value_iteration(sc, max_iter=budget, **options)
        assert sol.status == "max_iter" and sol.iterations <= budget
        lo, hi = bracket(mdp, sol.on_mdp(mdp).bias)
        tol = 1e-9 * abs(sol.gain)
        assert sol.gain_lower - tol <= lo <= hi <= sol.gain_upper + tol, (budget, lo, hi, sol.gain_lower,
                                                                           sol.gain_upper)


def test_readable_repr_html_and_table_of_a_matrix_free_solution():
    # issue 23 §3 / 26: the printout is short (it was tens of thousands of characters), the table
    # names the same action in every state as the table of the same policy on the enumerated MDP
    sc = paper("paper_p12", "tau_cap=8")
    mf = solved(sc)
    mdp = built(sc)
    text = repr(mf)
    assert text.startswith(f"MatrixFreeSolution of {mf.local_actions.size:,} layout states") and len(text) < 2000
    assert "array(" not in text and "status: optimal" in text
    assert mf._repr_html_().count("<table>") == 2
    df = mf.to_frame()
    assert list(df.columns)[:4] == ["state", "tau_1", "tau_2", "configuration"] and len(df) == mf.layout.n_states
    np.testing.assert_array_equal(df["local_action"], mf.local_actions)
    idx = mf.layout_index_of(mdp)
    on = mf.on_mdp(mdp).to_frame(mdp)  # the enumerated MDP's path: pair indices, action table
    assert list(df["action"].to_numpy()[idx]) == list(on["action"])
    assert list(df["configuration"].to_numpy()[idx]) == list(on["configuration"])
    np.testing.assert_array_equal(df[["tau_1", "tau_2"]].to_numpy()[idx], mdp.states.tau)
    ev = matrix_free_evaluate(sc, mf)
    assert len(repr(ev)) < 2000 and list(ev.to_frame()["status"]) == [str(ev.status)]
