"""One closed status vocabulary (issue 23 §3): a code and a reason, each backend's native statuses
mapped by a table of its own, "optimal" only when the Bellman certificate closed.

The expected code of every native status below is written from the backend's own documentation
(Clarabel's ``SolverStatus``, HiGHS's ``HighsModelStatus``, cvxpy's problem statuses), not read
from the toolkit's tables; every native status the installed backend knows is fed through.
"""
from __future__ import annotations

import pickle
from dataclasses import replace

import numpy as np
import pytest

from wncs_lp import status
from wncs_lp.mdp import MDP
from wncs_lp.solvers import policy_iteration, value_iteration
from wncs_lp.solvers.highs import HIGHS_STATUS, highs_status
from wncs_lp.solvers.lp import (CLARABEL_STATUS, CVXPY_STATUS, backend_status, clarabel_status, cvxpy_status,
                                solve_lp, status_from as lp_status_from, usable)
from wncs_lp.status import (CERTIFICATE, FAILED, INACCURATE, INFEASIBLE, INTERRUPTED, MAX_ITER, OPTIMAL, Code, Status,
                            of, parse, status_from)

# --------------------------------------------------------------------------- native statuses
#: Clarabel (docs: "SolverStatus"): only Solved is a solution to the tolerance; Almost* and the
#: numerical troubles leave a point worth certifying; the limits are budgets; infeasibility of our
#: LPs (a probability vector always exists) and an unbounded dual leave nothing usable.
CLARABEL_EXPECTED = {
    "Solved": OPTIMAL, "AlmostSolved": INACCURATE, "NumericalError": INACCURATE,
    "InsufficientProgress": INACCURATE, "MaxIterations": MAX_ITER, "MaxTime": MAX_ITER,
    "CallbackTerminated": INTERRUPTED, "PrimalInfeasible": INFEASIBLE, "AlmostPrimalInfeasible": INFEASIBLE,
    "DualInfeasible": FAILED, "AlmostDualInfeasible": FAILED, "Unsolved": FAILED,
}
#: HiGHS (docs: "HighsModelStatus").
HIGHS_EXPECTED = {
    "kOptimal": OPTIMAL, "kInfeasible": INFEASIBLE, "kUnboundedOrInfeasible": INFEASIBLE, "kUnbounded": FAILED,
    "kTimeLimit": MAX_ITER, "kIterationLimit": MAX_ITER, "kObjectiveBound": MAX_ITER, "kObjectiveTarget": MAX_ITER,
    "kSolutionLimit": MAX_ITER, "kInterrupt": INTERRUPTED, "kHighsInterrupt": INTERRUPTED, "kMemoryLimit": FAILED,
    "kNotset": FAILED, "kLoadError": FAILED, "kModelError": FAILED, "kPresolveError": FAILED, "kSolveError": FAILED,
    "kPostsolveError": FAILED, "kModelEmpty": FAILED, "kUnknown": FAILED,
}
#: cvxpy (docs: "Problem status"; user_limit is an iteration or time limit).
CVXPY_EXPECTED = {
    "optimal": OPTIMAL, "optimal_inaccurate": INACCURATE, "user_limit": MAX_ITER, "infeasible": INFEASIBLE,
    "infeasible_inaccurate": INFEASIBLE, "infeasible_or_unbounded": INFEASIBLE, "unbounded": FAILED,
    "unbounded_inaccurate": FAILED, "solver_error": FAILED,
}


def _clarabel_natives():
    import clarabel

    return [getattr(clarabel.SolverStatus, n) for n in dir(clarabel.SolverStatus) if n[0].isupper()]


def _highs_natives():
    import highspy

    return list(highspy.HighsModelStatus.__members__)


def _cvxpy_natives():
    import cvxpy.settings as s

    return [*s.SOLUTION_PRESENT, *s.INF_OR_UNB, *s.ERROR]


@pytest.mark.parametrize("natives, mapper, expected, table", [
    (_clarabel_natives, clarabel_status, CLARABEL_EXPECTED, CLARABEL_STATUS),
    (_highs_natives, highs_status, HIGHS_EXPECTED, HIGHS_STATUS),
    (_cvxpy_natives, cvxpy_status, CVXPY_EXPECTED, CVXPY_STATUS),
], ids=["clarabel", "highs", "cvxpy"])
def test_every_native_status_maps_into_the_closed_vocabulary(natives, mapper, expected, table):
    seen = set()
    for native in natives():  # the backend's own enum members / words, as it reports them
        word = str(native)
        seen.add(word)
        st = mapper(native)
        assert isinstance(st, Status) and st.code in status.STATUS_CODES
        assert st.code is expected[word], word
        if st.code is OPTIMAL:  # the one success: no reason, and "optimal" as text
            assert st == "optimal" and st.reason is None and st.ok
        else:  # the native word is kept verbatim as the reason, and the message names it
            assert st.reason == word and st == f"{st.code.value}:{word}" and not st.ok
            assert repr(word) in st.message
        assert usable(st) == (st.code not in (INFEASIBLE, FAILED))
    assert seen == set(expected) == set(table)  # no native status left to the default
    # a status the backend adds later is FAILED, its word kept: never silently optimal
    new = mapper("kSomethingNew" if mapper is highs_status else "SomethingNew")
    assert new.code is FAILED and "SomethingNew" in new


def test_backend_status_picks_each_backends_own_table():
    assert backend_status("clarabel", "MaxIterations") == "max_iter:MaxIterations"
    assert backend_status("highs", "kIterationLimit") == "max_iter:kIterationLimit"
    assert backend_status("cvxpy", "user_limit") == "max_iter:user_limit"
    # the same word means nothing to another backend: failed, not borrowed
    assert backend_status("highs", "Solved").code is FAILED
    assert backend_status("clarabel", "kOptimal").code is FAILED


# --------------------------------------------------------------------------- the vocabulary
def test_status_is_its_text_with_a_code_and_a_reason():
    st = of(INACCURATE, "precision")
    assert st == "inaccurate:precision" and st.code is INACCURATE and st.reason == "precision"
    assert isinstance(st, str) and "round-off" in st.message
    assert of(OPTIMAL) == "optimal" and of(OPTIMAL).reason is None and of(OPTIMAL).ok
    assert Code.MAX_ITER == "max_iter" and f"{Code.MAX_ITER}" == "max_iter" and str(Code.FAILED) == "failed"
    assert status.STATUS_CODES == (OPTIMAL, INACCURATE, MAX_ITER, INTERRUPTED, INFEASIBLE, FAILED)
    for code in status.STATUS_CODES:
        assert of(code).message and of(code).code is code
    with pytest.raises(ValueError, match="unknown status code"):
        of("solved")
    with pytest.raises(ValueError, match="no reason"):
        of(OPTIMAL, "certificate")
    with pytest.raises(ValueError, match="one line"):
        of(INACCURATE, "two\nlines")
    with pytest.raises(AttributeError):
        st.code = OPTIMAL
    assert pickle.loads(pickle.dumps(st)) == st and pickle.loads(pickle.dumps(st)).reason == "precision"


@pytest.mark.parametrize("text, code, reason", [
    ("optimal", OPTIMAL, None), ("max_iter", MAX_ITER, None), ("inaccurate:certificate", INACCURATE, "certificate"),
    ("max_iter:MaxIterations", MAX_ITER, "MaxIterations"), ("inaccurate:Time limit reached", INACCURATE,
                                                              "Time limit reached"),
    ("interrupted", INTERRUPTED, None), ("infeasible", INFEASIBLE, None), ("error: boom", FAILED, None),
    ("optimal:but not quite", FAILED, None), ("solved", FAILED, None), ("", FAILED, None),
])
def test_parse_reads_every_text_back(text, code, reason):
    st = parse(text)
    assert st == text and st.code is code and st.reason == reason  # the text is kept as written
    assert status.status_code(text) is code and status.status_reason(text) == reason
    assert status.status_message(text) == st.message


def test_status_from_takes_the_first_defect():
    assert status_from((None, None, None)) == "optimal"
    assert status_from((of(OPTIMAL), Code.OPTIMAL, None)) == "optimal"
    # a backend's own status stands as it is: an iteration limit stays MAX_ITER
    assert status_from((clarabel_status("MaxIterations"), "polish_max_iter", CERTIFICATE)) == "max_iter:MaxIterations"
    # a reason word is an INACCURATE status, in order of precedence
    assert status_from((clarabel_status("Solved"), "polish_max_iter", CERTIFICATE)) == "inaccurate:polish_max_iter"
    assert status_from((None, None, CERTIFICATE)) == "inaccurate:certificate"
    assert status_from(("Time limit  reached",)) == "inaccurate:Time limit reached"
    assert lp_status_from is status_from  # the LP module's public name still works


# --------------------------------------------------------------------------- on real solves
def _mdp(seed: int = 3) -> MDP:
    rng = np.random.default_rng(seed)
    n, m = 6, 3
    P = rng.random((n, m, n)) + 0.05
    P /= P.sum(axis=2, keepdims=True)
    return MDP.from_dense(P, rng.uniform(0.0, 10.0, size=(n, m)), np.ones((n, m), bool))


def _exact_gain(mdp: MDP) -> float:
    """The optimal gain by enumerating every deterministic policy (dense stationary laws)."""
    import itertools

    P = mdp.P.toarray()
    best = np.inf
    for pol in itertools.product(*[list(mdp.pairs_of(s)) for s in range(mdp.n_states)]):
        idx = np.array(pol)
        A = P[idx].T - np.eye(mdp.n_states)
        A[-1] = 1.0
        rhs = np.zeros(mdp.n_states)
        rhs[-1] = 1.0
        best = min(best, float(np.linalg.solve(A, rhs) @ mdp.cost[idx]))
    return best


@pytest.mark.parametrize("backend", ["clarabel", "highs", "cvxpy"])
def test_lp_is_optimal_exactly_when_the_backend_succeeded_and_the_certificate_closed(backend):
    from wncs_lp.solvers.certify import bracket, certificate_closed

    mdp = _mdp()
    g = _exact_gain(mdp)
    for kw in (dict(polish=False, cert_rtol=1e-15), dict()):
        sol = solve_lp(mdp, backend=backend, **kw)
        assert backend_status(backend, sol.stats["solver_status"]).ok
        # the rule, recomputed from the bias the solution carries
        lo, hi = bracket(mdp, sol.bias)
        closed = certificate_closed(mdp, lo, hi, sol.gain, kw.get("cert_rtol", 1e-6))
        assert sol.ok == sol.success == closed == sol.stats["certificate_closed"]
        assert sol.status == ("optimal" if closed else "inaccurate:certificate")
        assert sol.certificate.contains(g, rtol=1e-9)
    assert sol.ok and sol.gain == pytest.approx(g, rel=1e-9)  # polished: closed, optimal


@pytest.mark.parametrize("backend", ["clarabel", "cvxpy"])
def test_interior_point_success_is_not_optimal_without_a_closed_certificate(backend):
    # the backend reports success, but the unpolished interior-point dual bias gives a bracket far
    # wider than 1e-15 (and than its round-off floor): "certificate", never "optimal"
    mdp = _mdp()
    sol = solve_lp(mdp, backend=backend, polish=False, cert_rtol=1e-15)
    assert backend_status(backend, sol.stats["solver_status"]).ok
    assert sol.certificate.width > 1e-12 * abs(sol.gain)
    assert sol.status == "inaccurate:certificate" and not sol.ok and not sol.success
    assert "cert_rtol" in sol.message


def test_value_iteration_is_optimal_only_when_closed():
    mdp = _mdp(5)
    g = _exact_gain(mdp)
    short = value_iteration(mdp, max_iter=1)
    assert short.status == "max_iter" and short.status_code is MAX_ITER and not short.ok
    assert short.certificate.contains(g, rtol=1e-12)  # the bracket of the last iterate still holds
    full = value_iteration(mdp, tol=1e-9)
    assert full.ok and full.certificate.closed(1e-9, gain=full.gain) and full.certificate.contains(g, rtol=1e-12)
    pi = policy_iteration(mdp)
    assert pi.ok and pi.gain == pytest.approx(g, rel=1e-10)


def test_a_status_given_as_text_is_parsed_when_the_result_is_made():
    sol = value_iteration(_mdp(), tol=1e-9)
    back = replace(sol, status="max_iter:kTimeLimit")
    assert isinstance(back.status, Status) and back.status_code is MAX_ITER and back.status_reason == "kTimeLimit"
    assert back.summary()["status"] == "max_iter:kTimeLimit" and back.summary()["status_code"] == "max_iter"


def test_a_reproduction_solve_carries_its_status_into_as_solution():
    from wncs_lp.reproduce.context import Solved

    mdp = _mdp()
    sol = value_iteration(mdp, max_iter=2)
    assert not sol.ok
    solved = Solved(None, mdp, sol.gain, sol.gain_lower, sol.gain_upper, sol.policy, sol.bias,
                    np.full(mdp.n_states, 1.0 / mdp.n_states), sol.method, sol.seconds, str(sol.status))
    back = solved.as_solution()
    assert back.status == sol.status and back.status_code is sol.status_code and not back.ok
    assert back.certificate == sol.certificate


@pytest.mark.parametrize("method, native", [("lp", "MaxIterations"), ("lp-cvxpy", "user_limit")])
def test_the_constrained_lp_maps_its_backend_by_the_same_table(method, native):
    import warnings

    import wncs_lp
    from wncs_lp import solve

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sc = wncs_lp.load_scenario(wncs_lp.scenario_path("paper_p12_cloud_budget"), ["tau_cap=6"])
    mdp = wncs_lp.build(sc)
    short = solve(mdp, method, constraints=sc.constraints, max_iter=2)
    assert short.stats["solver_status"] == native
    assert short.status == f"max_iter:{native}" and short.status_code is MAX_ITER and not short.ok
    full = solve(mdp, method, constraints=sc.constraints)
    assert full.status == "optimal" and full.status_code is OPTIMAL
    assert full.gain_lower <= full.gain <= full.gain_upper + 1e-9 * abs(full.gain)
