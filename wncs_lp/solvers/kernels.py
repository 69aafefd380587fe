"""Fused Bellman sweeps over the state-action-pair CSR layout, with numba or scipy.

One Bellman sweep reads P (data, indices, indptr), the costs and the pair pointer once and
the bias vector h at random. The scipy path does that in several passes (a CSR mat-vec into
a length-L temporary, the minimum over each state's pairs, the span, the update); the numba kernels do it
in one pass per state:

    q_l = c_l + sum_k P_lk h(j_k)   for the pairs l of s,   (T h)(s) = min_l q_l,
    d(s) = (T h)(s) - h(s),  lo = min d,  hi = max d,  h'(s) = h(s) + tau (d(s) - shift).

and they read fewer bytes: the probabilities of these models take a handful of distinct
values, so P's data is stored as uint8/uint16 codes into a small table (exact: the table
holds the very same doubles), the cost as one number per state when it does not depend on
the action, and the pointers as int32 when they fit.

numba is optional (the ``fast`` extra): :func:`get_kernel` returns the numba kernel when it
imports and the MDP is large enough for its load to pay (:data:`NUMBA_MIN_STATES`), and the
scipy kernel otherwise; both give the same sweeps up to summation order
(``tests/solvers/test_perf_dp.py``). The numba kernels also offer in-place (Gauss-Seidel) sweeps and
fixed-policy sweeps for modified policy iteration, which the scipy kernel emulates with
Jacobi sweeps.
"""
from __future__ import annotations

import os
import weakref
from dataclasses import dataclass

import numpy as np

from ..errors import SolverError
from ..mdp import MDP
from .threads import resolve_threads, run_twins

__all__ = ["SweepData", "prepare", "code_table", "get_kernel", "numba_available", "ScipyKernel", "KERNELS",
           "NUMBA_MIN_STATES"]

#: kernel names accepted by :func:`get_kernel`
KERNELS = ("auto", "numba", "scipy")

_CACHE: "weakref.WeakKeyDictionary[MDP, SweepData]" = weakref.WeakKeyDictionary()


@dataclass(frozen=True, eq=False)
class SweepData:
    """The arrays a sweep reads, in their most compact exact form.

    Attributes
    ----------
    indptr, indices : P's CSR row pointer (L + 1) and column indices (int32 when they fit;
        P's own arrays, not copies, when they already are)
    codes : (nnz,) uint8/uint16 index into ``table`` (:func:`code_table`; or int32/int64
        0..nnz-1 when P has more than 65536 distinct values, ``table`` then being P.data itself)
    table : float64 distinct probability values
    cost : per-state cost (n,) when ``cost_per_state`` else per-pair cost (L,)
    cost_per_state : bool
    pair_ptr : (n + 1,) pairs of state s are pair_ptr[s]:pair_ptr[s+1]
    bytes_per_sweep : int
        Bytes a Jacobi sweep streams: the arrays above plus three length-n vectors
        (h read, h written, h gathered at least once).
    """

    n: int
    L: int
    indptr: np.ndarray
    indices: np.ndarray
    codes: np.ndarray
    table: np.ndarray
    cost: np.ndarray
    cost_per_state: bool
    pair_ptr: np.ndarray
    bytes_per_sweep: int
    bytes_per_sweep_plain: int


def _small_int(a: np.ndarray, limit: int) -> np.ndarray:
    """``a`` as int32 when ``limit`` fits, else int64 -- without a copy when it already has that dtype
    (so the sweep arrays share the MDP's CSR pointers and indices instead of doubling them)."""
    dtype = np.int32 if limit < np.iinfo(np.int32).max else np.int64
    return np.ascontiguousarray(a, dtype=dtype)


#: Probabilities coded per chunk of this many entries: bounds the temporaries of
#: :func:`code_table` (an int64 position and a bool per entry of the chunk, ~40 MB) whatever nnz is.
CODE_CHUNK = 1 << 22
#: Largest code table; beyond it the probabilities are kept uncoded (``table`` = P.data itself).
MAX_CODES = 1 << 16


def code_table(data: np.ndarray, *, chunk: int = CODE_CHUNK, max_codes: int = MAX_CODES):
    """Code an array of doubles exactly as ``table[codes]``, chunk by chunk, without sorting it.

    ``np.unique(data, return_inverse=True)`` would sort a copy of all of ``data`` and allocate an
    int64 inverse and an int64 permutation: 24 bytes per entry of temporaries and ~36 s at 2.3e8
    entries (processes 1-4, cap 18). The probabilities of these models take a handful of distinct
    values, so each chunk is looked up in the (sorted view of the) table found so far,
    ``np.searchsorted`` being O(log |table|) per entry, and only the entries that miss -- the
    first occurrences of a new value, rare after the first chunk -- are ``np.unique``'d and
    appended to the table. Codes are assigned in order of first appearance, so earlier codes
    never change; they start as uint8 and widen to uint16 once the table passes 256 values.

    Every chunk is verified after coding: ``table[codes] == data`` elementwise, so the coded
    probabilities are the very same doubles (nothing is rounded to a nearby table value).

    Parameters
    ----------
    data : (nnz,) float64 array
    chunk : int
        Entries coded per step.
    max_codes : int
        Table size beyond which coding gives up (at most 65536: uint16 codes).

    Returns
    -------
    table : float64 array or None
        The distinct values in order of first appearance; None when there are more than
        ``max_codes`` of them (the caller then keeps ``data`` uncoded).
    codes : uint8/uint16 array of len(data), or None with ``table``

    Raises
    ------
    SolverError
        ``data`` holds a NaN (which equals no table entry, so it cannot be coded exactly), or a
        coded chunk does not reproduce its doubles exactly (an internal error: never silent).
    """
    data = np.asarray(data, dtype=np.float64)
    max_codes = min(int(max_codes), 1 << 16)
    chunk = max(int(chunk), 1)
    nnz = data.size
    codes = np.empty(nnz, dtype=np.uint8)
    table = np.empty(0)
    srt = np.empty(0)  # the table sorted ...
    srt_code = np.empty(0, dtype=np.int64)  # ... and the code of each sorted value
    for a in range(0, nnz, chunk):
        x = data[a:a + chunk]
        pos = np.searchsorted(srt, x)
        if srt.size:
            np.minimum(pos, srt.size - 1, out=pos)
            miss = srt[pos] != x
        else:
            miss = np.ones(x.size, dtype=bool)
        if miss.any():
            new = np.unique(x[miss])
            if np.isnan(new).any():
                raise SolverError("transition probabilities contain NaN: they cannot be coded exactly "
                                  "(expected finite probabilities; validate the MDP)")
            if table.size + new.size > max_codes:
                return None, None
            table = np.concatenate([table, new])
            if table.size > 256 and codes.dtype == np.uint8:
                codes = codes.astype(np.uint16)
            order = np.argsort(table, kind="stable")
            srt, srt_code = table[order], order
            pos = np.searchsorted(srt, x)
        codes[a:a + x.size] = srt_code[pos]
        if not np.array_equal(table[codes[a:a + x.size]], x):
            raise SolverError(f"internal error: the probability code table does not reproduce entries "
                              f"{a}..{a + x.size - 1} exactly")
    return table, codes


def prepare(mdp: MDP) -> SweepData:
    """The compact sweep arrays of an MDP (cached per MDP object).

    Memory: the codes take one byte per transition (:func:`code_table`, no sort of all the
    entries), and the row pointer and column indices are P's own arrays when they are already
    int32 (no copy), so the compact form adds ~1 byte per transition to the MDP instead of the
    5 bytes of copies plus the 24 bytes per transition of ``np.unique`` temporaries it took
    before (``benchmarks/dp_memory.py``).
    """
    hit = _CACHE.get(mdp)
    if hit is not None:
        return hit
    P = mdp.P
    n, L = mdp.n_states, mdp.n_pairs
    table, codes = code_table(P.data)
    if table is None:  # too many distinct values: P's data itself, entry k coded k
        table, codes = np.asarray(P.data, float), np.arange(P.nnz, dtype=np.int32 if P.nnz < 2**31 else np.int64)
    sc = mdp.cost[mdp.pair_ptr[:-1]]
    per_state = bool(np.array_equal(mdp.cost, np.repeat(sc, mdp.n_actions)))
    cost = np.ascontiguousarray(sc if per_state else mdp.cost, dtype=float)
    indptr = _small_int(P.indptr, P.nnz)
    indices = _small_int(P.indices, n)
    pair_ptr = _small_int(mdp.pair_ptr, L)
    vec = 3 * 8 * n
    nbytes = indptr.nbytes + indices.nbytes + codes.nbytes + table.nbytes + cost.nbytes + pair_ptr.nbytes + vec
    plain = P.indptr.nbytes + P.indices.nbytes + P.data.nbytes + mdp.cost.nbytes + mdp.pair_ptr.nbytes + vec
    data = SweepData(n, L, indptr, indices, codes, np.ascontiguousarray(table, float), cost, per_state, pair_ptr,
                     int(nbytes), int(plain))
    _CACHE[mdp] = data
    return data


# ----------------------------------------------------------------------------- numba
_NUMBA = None


def numba_available() -> bool:
    """Whether the numba kernels can be used (numba importable, not disabled by WNCS_LP_NO_NUMBA)."""
    return _load_numba() is not None


def _load_numba():
    global _NUMBA
    if _NUMBA is not None:
        return _NUMBA or None
    if os.environ.get("WNCS_LP_NO_NUMBA"):
        _NUMBA = False
        return None
    try:
        from . import _numba_kernels as mod
    except Exception:  # numba missing or broken: the scipy kernel is used
        _NUMBA = False
        return None
    _NUMBA = mod
    return mod


class NumbaKernel:
    """Sweeps compiled with numba (see :mod:`wncs_lp.solvers._numba_kernels`)."""

    name = "numba"
    supports_gauss_seidel = True

    def __init__(self, mdp: MDP, threads: int | None = None):
        self.mod = _load_numba()
        self.d = prepare(mdp)
        # the usable cores on large MDPs, one in a fork of a process that ran OpenMP (.threads)
        self.threads = resolve_threads(threads, self.d.n)
        self.nchunk = max(1, min(8 * self.threads, self.d.n)) if self.threads > 1 else 1
        self._lo = np.empty(self.nchunk)
        self._hi = np.empty(self.nchunk)

    def jacobi(self, h: np.ndarray, h_out: np.ndarray, tau: float, shift: float) -> tuple[float, float]:
        """d = T h - h; h_out = h + tau (d - shift); returns (min d, max d)."""
        d = self.d
        args = (d.indptr, d.indices, d.codes, d.table, d.cost, d.cost_per_state, d.pair_ptr, h, h_out,
                float(tau), float(shift), self.nchunk, self._lo, self._hi)
        run_twins(self.mod.jacobi_sweep, self.mod.jacobi_sweep_serial, self.threads, *args)
        return float(self._lo.min()), float(self._hi.max())

    def gauss_seidel(self, h: np.ndarray, tau: float, shift: float, pol: np.ndarray) -> None:
        """In place, states in order: h(s) += tau ((T h)(s) - h(s) - shift); pol(s) = argmin pair."""
        d = self.d
        self.mod.gs_sweep(d.indptr, d.indices, d.codes, d.table, d.cost, d.cost_per_state, d.pair_ptr, h,
                          float(tau), float(shift), pol)

    def evaluate(self, h: np.ndarray, tau: float, shift: float, pol: np.ndarray) -> None:
        """In place, fixed policy: h(s) += tau (c_pol + P_pol h - h - shift)(s)."""
        d = self.d
        self.mod.eval_sweep(d.indptr, d.indices, d.codes, d.table, d.cost, d.cost_per_state, d.pair_ptr, h,
                            float(tau), float(shift), pol)


#: :func:`_later_pairs` gives up (``np.minimum.reduceat`` is used) beyond this many pairs in a state
#: (p123 has up to 6; on p1234's 12 the two were measured alike).
LATER_PAIRS_MAX = 6


def _later_pairs(pair_ptr: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]] | None:
    """For j = 1, 2, ...: the states with more than j pairs and their j-th pair, or None when a
    state has more than :data:`LATER_PAIRS_MAX` pairs.

    ``min_l q_l`` over the pairs of each state is then ``q`` at the first pairs, lowered by
    ``np.minimum`` at each j: the same doubles as ``np.minimum.reduceat(q, pair_ptr[:-1])`` (a
    minimum is exact in any order), with the in-place update 1.1-2.9x faster a sweep on p12, p123
    and p14 at 10k-110k states, where most states have one pair and reduceat pays per segment.
    """
    counts = np.diff(pair_ptr)
    top = int(counts.max(initial=1))
    if top > LATER_PAIRS_MAX:
        return None
    starts = pair_ptr[:-1]
    more = []
    for j in range(1, top):
        states = np.flatnonzero(counts > j)
        more.append((states, starts[states] + j))
    return more


class ScipyKernel:
    """The same sweeps with scipy's CSR mat-vec (always available; Jacobi only)."""

    name = "scipy"
    supports_gauss_seidel = False

    def __init__(self, mdp: MDP, threads: int | None = None):
        self.mdp = mdp
        self.d = prepare(mdp)
        self.starts = mdp.pair_ptr[:-1]
        self._more = _later_pairs(mdp.pair_ptr)
        if self._more is not None:  # the buffers of the state minimum, reused by every sweep
            self._Th = np.empty(mdp.n_states)
            self._bufs = [(np.empty(st.size), np.empty(st.size)) for st, _ in self._more]
        self.threads = 1
        self._pol_key = None
        self._Pd = None

    def jacobi(self, h, h_out, tau, shift):
        mdp = self.mdp
        q = mdp.P @ h
        q += mdp.cost
        if self._more is None:
            Th = np.minimum.reduceat(q, self.starts)
        else:  # the same minima: the first pair of every state, then the j-th pair of the states that have one
            Th = np.take(q, self.starts, out=self._Th)
            for (states, pairs), (mine, other) in zip(self._more, self._bufs):
                np.take(Th, states, out=mine)
                np.take(q, pairs, out=other)
                Th[states] = np.minimum(mine, other, out=mine)
        dd = np.subtract(Th, h, out=Th)  # in place: fresh large temporaries cost page faults every sweep
        np.subtract(dd, shift, out=h_out)
        h_out *= tau
        h_out += h
        return float(dd.min()), float(dd.max())

    def gauss_seidel(self, h, tau, shift, pol):  # pragma: no cover - guarded by supports_gauss_seidel
        raise NotImplementedError("the scipy kernel has no Gauss-Seidel sweep")

    def evaluate(self, h, tau, shift, pol):
        """Jacobi fixed-policy sweep (P_pol is extracted once per policy)."""
        key = pol.tobytes()
        if key != self._pol_key:
            self._Pd = self.mdp.P[pol].tocsr()
            self._cd = self.mdp.cost[pol]
            self._pol_key = key
        v = self._cd + self._Pd @ h - h
        h += tau * (v - shift)


#: ``kernel="auto"`` takes numba from this many states on, scipy below: where numba's fixed cost in
#: a fresh process (importing it, ~0.3-0.5 s, and loading its compiled kernels from the cache)
#: pays. In a fresh process the whole ``wncs-lp solve --json`` would break even near 100k states on
#: p123 and 200k on p12 (``benchmarks/fixed_costs.py --crossover``), but in a long run that has
#: loaded numba already (a reproduction, a sweep, a notebook) the scipy Jacobi sweeps cost 2.6-3.2x
#: numba's at 110k states (p12 cap 30, idling allowed: 1.9-2.4 s against 0.74 s, 393 against 157
#: sweeps), so the threshold stays where numba's sweeps win as soon as they are loaded.
NUMBA_MIN_STATES = 50_000


def get_kernel(mdp: MDP, kernel: str = "auto", threads: int | None = None, *, in_place: bool = False):
    """A sweep kernel for ``mdp``: ``"numba"``, ``"scipy"`` or ``"auto"`` (numba when importable
    and the MDP has at least :data:`NUMBA_MIN_STATES` states, where its load pays, or when the
    caller needs ``in_place`` sweeps, which only numba has).

    ``threads`` (numba only): None for the default of :func:`wncs_lp.solvers.threads.resolve_threads`
    (the usable cores from 1M states on, one below), else an integer >= 1.

    Raises
    ------
    ValueError
        Unknown name, a bad ``threads``, or ``"numba"`` requested but numba is not importable.
    """
    if kernel not in KERNELS:
        raise ValueError(f"unknown kernel {kernel!r}; expected one of {', '.join(KERNELS)}")
    if threads is not None and (isinstance(threads, bool) or not isinstance(threads, (int, np.integer)) or threads < 1):
        raise ValueError(f"threads must be an integer >= 1 (or None: the default), got {threads!r}")
    small = mdp.n_states < NUMBA_MIN_STATES and not in_place
    if kernel == "scipy" or (kernel == "auto" and (small or not numba_available())):
        return ScipyKernel(mdp, threads)
    if not numba_available():
        raise ValueError("kernel 'numba' requested but numba is not importable (pip install 'wncs_lp[fast]')")
    return NumbaKernel(mdp, threads)


def stream_bandwidth(nbytes: int = 400_000_000, repeats: int = 5) -> float:
    """Measured streaming read bandwidth in bytes/s: the best of ``repeats`` sums of a large array."""
    import time

    a = np.ones(nbytes // 8)
    a.sum()
    best = np.inf
    for _ in range(repeats):
        t = time.perf_counter()
        a.sum()
        best = min(best, time.perf_counter() - t)
    return a.nbytes / best

