"""Adapters that hand one of our MDPs to peer solvers (the optional ``bench`` extra).

Every adapter takes an :class:`wncs_lp.mdp.MDP` and returns a dict with at least
``seconds`` (the solve only; model conversion is timed separately as ``convert_seconds``),
``gain`` and ``iterations`` where the peer reports them. A missing package raises
``ImportError``; the caller records the peer as unavailable.

* stormpy (Storm's Python bindings): ``R{"cost"}min=? [LRA]`` on a sparse MDP built from
  our CSR through ``SparseMatrixBuilder.add_next_values`` (row groups = states). Storm picks
  its long-run-average method itself (value iteration for MDPs, its default precision
  1e-6 relative, not settable from stormpy 2.0's environment bindings).
* pymdptoolbox ``RelativeValueIteration``: needs one n x n matrix per action index and every
  action in every state; a state with fewer actions repeats its first pair (a duplicate
  action changes no optimum); rewards are minus costs. It stops when span(V' - V) < epsilon;
  we pass epsilon = 1e-9 * |g| with g from our solution, so it aims at our tolerance.
  Compatibility shim (:func:`_patch_mdptoolbox`): its input check ``isNonNegative`` does
  ``(matrix >= 0).all()``, which old scipy refused for sparse matrices (so it fell back to
  ``matrix.data >= 0``) but scipy 1.17 evaluates -- as a sparse matrix that is True on every
  *zero* entry, i.e. n^2 entries (14 GB at 16k states); and ``isStochastic`` subtracts a
  length-n vector from the (n, 1) ``np.matrix`` of row sums, which broadcasts to a dense
  n x n array. The shim checks sparse input on ``.data`` and on the raveled row sums.
* HiGHS through ``scipy.optimize.linprog(method="highs")``: the plain occupation-measure LP
  with the normalisation sum x = n (sum x = 1 lost up to 2e-4 relative in the issue's runs).
* scipy RVI: our :func:`relative_value_iteration` with ``kernel="scipy"`` (a plain scipy
  CSR mat-vec + ``np.minimum.reduceat`` RVI, aperiodicity 0.5).
"""
from __future__ import annotations

import time
import warnings

import numpy as np
import scipy.sparse as sp

__all__ = ["storm_lra", "mdptoolbox_rvi", "highs_lp", "scipy_rvi", "available"]


def available(name: str) -> bool:
    try:
        __import__({"stormpy": "stormpy", "pymdptoolbox": "mdptoolbox", "highs": "scipy.optimize"}[name])
    except ImportError:
        return False
    return True


def storm_lra(mdp) -> dict:
    import stormpy
    from stormpy import datastructures as DS
    from stormpy import models as M

    t0 = time.perf_counter()
    P = mdp.P.tocsr()
    L, n = P.shape
    rows = np.repeat(np.arange(L), np.diff(P.indptr))
    b = DS.SparseMatrixBuilder(rows=L, columns=n, entries=P.nnz, force_dimensions=False,
                               has_custom_row_grouping=True, row_groups=n)
    b.add_next_values(rows.tolist(), P.indices.tolist(), P.data.tolist(), mdp.pair_ptr[:-1].tolist())
    mat = b.build()
    lab = M.StateLabeling(n)
    lab.add_label("init")
    lab.set_states("init", DS.BitVector(n, [0]))
    rew = M.SparseRewardModel(optional_state_action_reward_vector=mdp.cost.tolist())
    comp = M.SparseModelComponents(transition_matrix=mat, state_labeling=lab, reward_models={"cost": rew})
    model = M.SparseMdp(comp)
    prop = stormpy.parse_properties('R{"cost"}min=? [LRA]')[0]
    t1 = time.perf_counter()
    res = stormpy.model_checking(model, prop)
    t2 = time.perf_counter()
    return {"seconds": t2 - t1, "convert_seconds": t1 - t0, "gain": float(res.get_value(0)), "iterations": None}


def _per_action(mdp):
    n = mdp.n_states
    A = int(mdp.n_actions.max())
    Ps, R = [], np.zeros((n, A))
    for a in range(A):
        pair = np.where(mdp.n_actions > a, mdp.pair_ptr[:-1] + a, mdp.pair_ptr[:-1])
        Ps.append(mdp.P[pair].tocsr())
        R[:, a] = -mdp.cost[pair]
    return Ps, R


def _patch_mdptoolbox() -> None:
    import mdptoolbox.util as U

    if getattr(U, "_wncs_patched", False):
        return
    original = U.isNonNegative

    def is_non_negative(matrix):
        if sp.issparse(matrix):
            return bool((matrix.data >= 0).all())
        return original(matrix)

    def is_stochastic(matrix):
        if sp.issparse(matrix):
            rows = np.asarray(matrix.sum(axis=1)).ravel()
            return bool(np.abs(rows - 1.0).max() <= 10 * np.spacing(np.float64(1)))
        return original_stoch(matrix)

    original_stoch = U.isStochastic
    U.isNonNegative = is_non_negative
    U.isStochastic = is_stochastic
    U._wncs_patched = True


def mdptoolbox_rvi(mdp, gain_hint: float, rtol: float = 1e-9, max_iter: int = 20_000) -> dict:
    import mdptoolbox.mdp as M

    _patch_mdptoolbox()
    t0 = time.perf_counter()
    Ps, R = _per_action(mdp)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        solver = M.RelativeValueIteration(Ps, R, epsilon=rtol * abs(gain_hint), max_iter=max_iter)
        t1 = time.perf_counter()
        solver.run()
    t2 = time.perf_counter()
    return {"seconds": t2 - t1, "convert_seconds": t1 - t0, "gain": -float(solver.average_reward),
            "iterations": int(solver.iter), "converged": int(solver.iter) < max_iter}


def highs_lp(mdp) -> dict:
    from scipy.optimize import linprog

    t0 = time.perf_counter()
    n, L = mdp.n_states, mdp.n_pairs
    E = sp.csr_matrix((np.ones(L), (mdp.s_indices, np.arange(L))), shape=(n, L))
    B = (E - mdp.P.T.tocsr()).tocsr()
    A = sp.vstack([B[1:], sp.csr_matrix(np.ones((1, L)))], format="csr")
    b = np.zeros(n)
    b[-1] = float(n)
    t1 = time.perf_counter()
    res = linprog(mdp.cost, A_eq=A, b_eq=b, bounds=(0, None), method="highs")
    t2 = time.perf_counter()
    gain = float(res.fun) / n if res.x is not None else float("nan")
    return {"seconds": t2 - t1, "convert_seconds": t1 - t0, "gain": gain, "iterations": getattr(res, "nit", None),
            "status": str(res.message)[:60]}


def scipy_rvi(mdp, tol: float = 1e-9) -> dict:
    from wncs_lp.solvers import relative_value_iteration

    s = relative_value_iteration(mdp, tol=tol, kernel="scipy")
    return {"seconds": s.seconds, "gain": s.gain, "iterations": s.iterations, "gap": s.gap, "lo": s.gain_lower,
            "hi": s.gain_upper}
