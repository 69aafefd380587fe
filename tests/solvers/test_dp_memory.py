"""The compact sweep arrays built without ``np.unique`` over all transitions (issue 18): exact
codes, shared CSR pointers, the same sweeps and gains as the plain CSR (scipy) path and the LP,
and a coding that raises or falls back instead of rounding. No memory or time is asserted here:
peak bytes per transition live in ``benchmarks/dp_memory.py``."""
from __future__ import annotations

import numpy as np
import pytest

from wncs_lp import scenario_path
from wncs_lp.errors import SolverError
from wncs_lp.mdp import MDP
from wncs_lp.models import build
from wncs_lp.scenario import load_scenario
from wncs_lp.solvers import value_iteration
from wncs_lp import solve
from wncs_lp.solvers.certify import greedy_first, q_values
from wncs_lp.solvers.dp import greedy_policy
from wncs_lp.solvers.kernels import code_table, get_kernel, numba_available, prepare

needs_numba = pytest.mark.skipif(not numba_available(), reason="numba not installed (the 'fast'/'test' extra)")

SMALL = [("paper_p12.toml", ["tau_cap=8"]), ("paper_p123.toml", ["tau_cap=7"]),
         ("paper_preemption_p12.toml", ["tau_cap=8"])]


def random_mdp(seed: int, n: int = 30, distinct: bool = True) -> MDP:
    """Random rows: all-distinct probabilities (``distinct``) or multiples of 1/8 (few values)."""
    rng = np.random.default_rng(seed)
    s_idx, a_idx, rows, cost = [], [], [], []
    for s in range(n):
        for a in range(int(rng.integers(1, 4))):
            row = np.zeros(n)
            k = int(rng.integers(1, 5))
            if distinct:
                row[rng.choice(n, size=k, replace=False)] = rng.random(k) + 0.1
                row[(s + 1) % n] += 0.05  # irreducible under every policy
            else:
                row[rng.choice(n, size=k, replace=False)] = 1.0
                row[(s + 1) % n] += 1.0
            rows.append(row / row.sum())
            s_idx.append(s)
            a_idx.append(a)
            cost.append(float(rng.integers(0, 5)))  # integer costs: ties between actions
    return MDP.from_arrays(s_idx, a_idx, cost, np.array(rows), n)


@pytest.fixture(scope="module", params=SMALL, ids=[f"{n}-{s[0]}" for n, s in SMALL])
def model(request):
    name, sets = request.param
    return build(load_scenario(scenario_path(name), sets))


# ----------------------------------------------------------------------------- the coding
@pytest.mark.parametrize("chunk", [1, 7, 1000, 1 << 22])
def test_code_table_reproduces_every_double(model, chunk):
    data = model.P.data
    table, codes = code_table(data, chunk=chunk)
    assert codes.dtype == np.uint8 and codes.shape == data.shape
    np.testing.assert_array_equal(table[codes], data)  # the very same doubles, bit for bit
    assert np.unique(table).size == table.size  # no value twice
    # against np.unique (the old coding): the same partition of the entries into values
    ref_table, ref_inv = np.unique(data, return_inverse=True)
    assert table.size == ref_table.size
    np.testing.assert_array_equal(np.sort(table), ref_table)
    pairs = np.unique(np.stack([codes.astype(np.int64), ref_inv.ravel()]), axis=1)
    assert pairs.shape[1] == table.size  # code <-> value is one-to-one


def test_code_table_widens_to_uint16_and_gives_up_past_the_limit():
    rng = np.random.default_rng(0)
    values = rng.random(300)
    data = values[rng.integers(0, 300, size=5000)]
    data[:300] = values  # every value occurs, the 257th after the first chunk
    table, codes = code_table(data[::-1].copy(), chunk=64)
    assert codes.dtype == np.uint16 and table.size == 300
    np.testing.assert_array_equal(table[codes], data[::-1])
    assert code_table(data, chunk=64, max_codes=299) == (None, None)  # too many values: not coded


def test_a_nan_cannot_be_coded_and_raises():
    data = np.array([0.5, 0.25, np.nan, 0.25])
    with pytest.raises(SolverError, match="NaN"):
        code_table(data, chunk=2)


def test_prepare_shares_the_csr_and_adds_one_byte_per_transition(model):
    d = prepare(model)
    P = model.P
    assert P.indices.dtype == np.int32 and P.indptr.dtype == np.int32
    assert d.indices is P.indices and d.indptr is P.indptr  # no copies
    assert d.codes.dtype == np.uint8 and d.codes.nbytes == P.nnz
    np.testing.assert_array_equal(d.table[d.codes], P.data)


def test_prepare_falls_back_to_the_doubles_when_there_are_too_many_values():
    mdp = random_mdp(1)
    assert np.unique(mdp.P.data).size <= 65536  # small: coded
    d = prepare(mdp)
    np.testing.assert_array_equal(d.table[d.codes], mdp.P.data)
    n = 140_000  # > 65536 distinct probabilities: kept as they are, entry k coded k
    rng = np.random.default_rng(2)
    P = np.zeros((n, 2))
    P[:, 0] = rng.random(n) * 0.5 + 0.25
    P[:, 1] = 1.0 - P[:, 0]
    big = MDP.from_arrays(np.repeat([0, 1], n // 2), np.tile(np.arange(n // 2), 2), np.ones(n), P, 2)
    d = prepare(big)
    assert d.table is big.P.data or np.shares_memory(d.table, big.P.data)
    np.testing.assert_array_equal(d.codes, np.arange(big.P.nnz))
    np.testing.assert_array_equal(d.table[d.codes], big.P.data)


# ----------------------------------------------------------------------------- the same sweeps
@needs_numba
@pytest.mark.parametrize("seed", [3, 4])
def test_numba_sweeps_on_the_new_codes_match_the_plain_csr(model, seed):
    rng = np.random.default_rng(seed)
    h = rng.normal(size=model.n_states) * 100
    out_n, out_s = np.empty_like(h), np.empty_like(h)
    lo_s, hi_s = get_kernel(model, "scipy").jacobi(h, out_s, 0.5, 1.0)  # scipy: P's float64 data
    lo_n, hi_n = get_kernel(model, "numba").jacobi(h, out_n, 0.5, 1.0)  # numba: table[codes]
    scale = float(np.abs(h).max() + np.abs(model.cost).max())
    np.testing.assert_allclose(out_n, out_s, rtol=0, atol=1e-13 * scale)
    assert abs(lo_n - lo_s) <= 1e-13 * scale and abs(hi_n - hi_s) <= 1e-13 * scale


def test_value_iteration_gains_agree_with_the_lp_and_the_scipy_path(model):
    lp = solve(model, "lp")
    ref = value_iteration(model, kernel="scipy", tol=1e-10)
    vi = value_iteration(model, tol=1e-10)
    for sol in (vi, ref):
        assert sol.status == "optimal"
        slack = 1e-7 * abs(lp.gain)  # the LP's own accuracy
        assert sol.gain_lower - slack <= lp.gain <= sol.gain_upper + slack
    assert vi.gain == pytest.approx(ref.gain, rel=2e-10)


# ----------------------------------------------------------------------------- greedy policy by blocks
@pytest.mark.parametrize("block", [1, 5, 1 << 20])
def test_blocked_greedy_policy_is_greedy_first_bit_for_bit(model, block):
    rng = np.random.default_rng(block)
    for h in (np.zeros(model.n_states), rng.normal(size=model.n_states) * 10,
              np.round(rng.normal(size=model.n_states)) * 4):  # zeros and integers: many exact ties
        ref = greedy_first(model, q_values(model, h))
        np.testing.assert_array_equal(greedy_policy(model, h, block=block), ref)


def test_blocked_greedy_policy_on_random_models_with_ties():
    for seed in range(4):
        mdp = random_mdp(seed, distinct=False)
        h = np.zeros(mdp.n_states)
        np.testing.assert_array_equal(greedy_policy(mdp, h, block=3), greedy_first(mdp, q_values(mdp, h)))
