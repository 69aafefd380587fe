"""numba kernels of :mod:`wncs_lp.solvers.matrix_free` (imported only when numba is available).

The state space is a union of dense sub-boxes, one per configuration c: axis k runs over the
0-based AoI indices ``lo[c, k] .. lo[c, k] + dims[c, k] - 1``, C order, the last axis
contiguous; the box of c starts at ``off[c]`` of every state vector. Outcome e (a global index
of :class:`~wncs_lp.models.automaton.FlatAutomaton`) of configuration c moves the state
(c, t) to (c', t') with t'_k = min(t_k + 1, m[e, k]) (``m`` folds in the delivery and the
cap), whose index is

    e_base[e] + sum_k e_stride[e, k] * t'_k        (e_stride[e, N-1] = 1).

Order of a sweep. The first N - 2 axes are *tiles* (absolute AoI indices, C order); a sweep
visits the tiles in turn and, in each, the *plane* (last two axes) of every configuration
whose box has that tile. The successors of a tile lie in a few neighbouring tiles (t + 1, or
the small AoI a delivery resets to), so a sweep streams the value vector about once instead
of once per predecessor configuration. Within a plane, rows (the last axis) are computed one
at a time: per row, the offset ``P[o]`` of every outcome's successor row; along the row the
successor index grows by one until the last axis saturates at ``m[e, N-1]`` (position
``split[o]``), then stays. So each outcome is two contiguous loops, vectorised by LLVM.

Two details make the loops fast (measured on processes 1-4, cap 20: 19 -> 11 ns a state):
indices into the value vector are **unsigned** (numba emits a negative-index wraparound for
signed ones, and LLVM then turned the contiguous loads into AVX-512 gathers), and the work of a
whole chunk of planes is one function (a call per plane passes ~30 arrays, and numba's atomic
reference counting of them cost ~10%). The same holds for the scratch rows: a loop
``range(sp, L)`` does not start at 0, so its index is not known to be non-negative, and a
signed index there made LLVM store the saturated part of a row with AVX-512 scatters; as
unsigned, plain stores (every pass kind 7-8% less CPU at cap 20, the same arithmetic).

Kernels (each a ``prange`` driver over chunks of work items, compiled for numba's threads and,
as ``*_serial``, for one: :func:`wncs_lp.solvers.threads.twins`):

* :func:`all_actions` -- every action's value on a row (``acc``), then the minimum over actions
  (``mode`` :attr:`Reduce.MIN <.operator.Reduce.MIN>`: the Bellman operator T, first minimiser
  kept, ``arg``) or the weighted sum with per-configuration action weights ``W[c, j]``
  (:attr:`Reduce.WEIGHTED <.operator.Reduce.WEIGHTED>`: a tau-independent randomised policy).
  ``write`` (:class:`.operator.Write`) ``NONE`` only computes min / max of (T h - h) (over the
  states with ``mask`` set when ``use_mask``), ``IN_PLACE`` updates h in place (Gauss-Seidel:
  ``h += relax (T h - h - shift)``; such a pass computes no bracket, as its d(s) are taken on a
  moving h: it returns (inf, -inf), and its update is one fused loop), ``OUT`` writes ``h_out``
  (Jacobi); ``write_pol`` stores the minimiser in ``pol`` (uint8). With ``use_cand`` only the
  actions whose bit is set in ``cand[c]`` (:data:`CAND_CONFIG`) or in ``cand[row]``
  (:data:`CAND_ROW`, rows numbered by ``row_off``) are tried (in-place improvement sweeps only: a
  certificate always takes the minimum over every action). With ``near >= 0`` (a certificate
  pass of the minimum) each row's bit set of the actions within ``near`` of the running minimum
  somewhere on the row goes into ``nbits[row]`` (a superset of those within ``near`` of the
  final minimum, the minimiser included; read only, the bracket is unchanged).
* :func:`fixed_policy` -- the same for one action per state (``pol``), which must be in range
  for its configuration (checked by the callers: :func:`.layout.check_local_actions`).
* :func:`used_actions` -- per configuration, the bit set of the actions a policy takes in its box
  (the candidates of the improvement sweeps, ``candidates="config"``).
* :func:`row_actions` -- the same per row.
* :func:`reach_all` -- marks the successors of the marked states to a fixed point.
* :func:`clamped` -- a coarse solution read at each state's AoI clamped into the smaller boxes
  (:func:`.start.clamped_values`), and :func:`value_range` -- min / max of a value vector in one
  pass (the loop's finiteness check and the round-off bound's max |h|): the parts of a solve
  outside its passes, on the solve's threads (as numpy, on one core, they were ~5% of the cap-30
  solve's wall clock while the other core waited).

With threads, a Gauss-Seidel sweep is asynchronous across the chunks (a plane may
read another's values before or after their update): still a valid value-iteration scheme,
but its iterates depend on timing. Chunks are contiguous ranges of tiles, so most reads
(t -> t + 1) stay in the reading thread's own range and follow the serial order; splitting the
configurations of every tile between the threads instead was measured to need 1.5x more
sweeps (evaluation of the suboptimal policy, processes 1-4, cap 16: 517 against 331 serial). Certificate passes (``write`` 0 or 2) read one fixed h and
are deterministic.
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange, uint64

from ..threads import twins
from .operator import Reduce, Write

#: ``use_cand`` of :func:`all_actions`: every action; the configuration's bit set ``cand[c]``; the
#: row's ``cand[row]`` (rows numbered by ``row_off``).
CAND_NONE, CAND_CONFIG, CAND_ROW = 0, 1, 2


# The plane setup is inlined into both chunk kernels by numba (``inline="always"``, at the level of
# numba's IR: no call, no reference counting of its arrays). The row loops are written out in each
# kernel on purpose: inlined helpers for them (the values of an action along a row, the end of a
# row) were measured 20-30% slower on processes 1-4 at cap 8 (the all-actions pass, CPU time per
# state, five alternating runs), so those kernels stay long.
@njit(inline="always")
def _plane(c, tc, N, lo_, dims, strides, off, act_ptr, out_ptr, e_m, e_base, e_stride, q, split, sat, A, rs, rm):
    """Set up the plane of configuration c in tile ``tc``: per outcome o, the last axis' split /
    saturation, the offset due to the tile's axes (A) and the stride / saturation of the row axis
    N - 2. Returns the row length L, the row's first AoI index loN, the first outcome o0, the
    plane's first state s0, the tile axes' cost qo0, and the rows (count, first AoI index)."""
    L = dims[c, N - 1]
    loN = lo_[c, N - 1]
    o0 = out_ptr[act_ptr[c]]
    nO = out_ptr[act_ptr[c + 1]] - o0
    for o in range(nO):
        e = o0 + o
        mN = e_m[e, N - 1]
        sat[o] = mN
        split[o] = min(max(mN - loN, 0), L)
        v = e_base[e]
        for k in range(N - 2):
            tk = tc[k] + 1
            mk = e_m[e, k]
            v += e_stride[e, k] * (tk if tk < mk else mk)
        A[o] = v
        if N >= 2:
            rs[o] = e_stride[e, N - 2]
            rm[o] = e_m[e, N - 2]
        else:
            rs[o] = 0
            rm[o] = 0
    s0 = off[c]
    qo0 = 0.0
    for k in range(N - 2):
        s0 += (tc[k] - lo_[c, k]) * strides[c, k]
        qo0 += q[k, tc[k]]
    nrows = 1
    tr = 0
    if N >= 2:
        nrows = dims[c, N - 2]
        tr = lo_[c, N - 2]
    return L, loN, o0, nO, s0, qo0, nrows, tr


@njit(cache=True, nogil=True, boundscheck=False, fastmath={"contract"})
def _all_chunk(ci, tc, tile_cfg, x0, x1, N, lo_, dims, strides, off, act_ptr, out_ptr, e_prob, e_m, e_base,
               e_stride, q, h, h_out, pol, W, mode, write, write_pol, relax, shift, mask, use_mask, cand, use_cand,
               row_off, near, nbits, iscr, fscr, los, his):
    P, split, sat, A, rs, rm, arg = iscr[0], iscr[1], iscr[2], iscr[3], iscr[4], iscr[5], iscr[6]
    acc, best, dd = fscr[0], fscr[1], fscr[2]
    lo = np.inf
    hi = -np.inf
    for x in range(x0, x1):
        c = tile_cfg[x]
        L, loN, o0, nO, s0, qo0, nrows, tr = _plane(c, tc, N, lo_, dims, strides, off, act_ptr, out_ptr, e_m,
                                                    e_base, e_stride, q, split, sat, A, rs, rm)
        a0 = act_ptr[c]
        na = act_ptr[c + 1] - a0
        qN = q[N - 1]
        qu = uint64(loN)
        # the global index of the plane's first row (per-row candidates: one bit set a row)
        row = row_off[c] + (s0 - off[c]) // L
        bits = cand[c] if use_cand == CAND_CONFIG else uint64(0)
        # ---- rows
        for r in range(nrows):
            qo = qo0
            if N >= 2:
                qo += q[N - 2, tr]
            t1 = tr + 1
            for o in range(nO):
                m = rm[o]
                P[o] = A[o] + rs[o] * (t1 if t1 < m else m)
            if use_cand == CAND_ROW:
                bits = cand[row]
            rid = row
            row += 1
            nb = uint64(0)  # the row's near-minimal actions (``near``)
            first = True
            for j in range(na):
                # an improvement sweep may try only the candidate actions of the configuration or
                # of the row (bit j of ``bits``; actions past 63 are always tried)
                if use_cand != CAND_NONE and j < 64 and (bits >> uint64(j)) & uint64(1) == uint64(0):
                    continue
                w = 1.0
                if mode == Reduce.WEIGHTED:
                    w = W[c, j]
                    if w == 0.0:
                        continue
                ob = out_ptr[a0 + j] - o0
                oe = out_ptr[a0 + j + 1] - o0
                # the minimum's first action is summed straight into best (no copy)
                direct = first and mode == Reduce.MIN
                tgt = best if direct else acc
                for oo in range(ob, oe):
                    p = e_prob[o0 + oo]
                    b = uint64(P[oo] + loN + 1)
                    sp = split[oo]
                    v = p * h[P[oo] + sat[oo]]
                    if oo == ob:
                        for i in range(sp):
                            tgt[i] = p * h[b + uint64(i)]
                        for i in range(sp, L):
                            tgt[uint64(i)] = v
                    else:
                        for i in range(sp):
                            tgt[i] += p * h[b + uint64(i)]
                        for i in range(sp, L):
                            tgt[uint64(i)] += v
                if mode == Reduce.MIN:
                    if first:
                        for i in range(L):
                            arg[i] = j
                        nb |= uint64(1) << uint64(min(j, 63))
                    elif near >= 0.0:
                        # the select, and whether the action is within ``near`` of the minimum so far
                        # somewhere on the row (a superset of those within ``near`` of the final one)
                        hit = 0
                        for i in range(L):
                            xa = acc[i]
                            yb = best[i]
                            hit += 1 if xa <= yb + near else 0
                            better = xa < yb
                            best[i] = xa if better else yb
                            arg[i] = j if better else arg[i]
                        if hit > 0:
                            nb |= uint64(1) << uint64(min(j, 63))
                    else:
                        for i in range(L):
                            xa = acc[i]
                            yb = best[i]
                            better = xa < yb
                            best[i] = xa if better else yb
                            arg[i] = j if better else arg[i]
                else:
                    if first:
                        for i in range(L):
                            best[i] = w * acc[i]
                    else:
                        for i in range(L):
                            best[i] += w * acc[i]
                first = False
            su = uint64(s0)
            if write == Write.IN_PLACE:
                # an improvement sweep: no bracket (only certificate passes give one), one loop
                for i in range(L):
                    hs = h[su + uint64(i)]
                    h[su + uint64(i)] = hs + relax * (((qo + qN[qu + uint64(i)] + best[i]) - hs) - shift)
                if write_pol:
                    for i in range(L):
                        pol[su + uint64(i)] = arg[i]
                s0 += L
                tr += 1
                continue
            for i in range(L):
                dd[i] = (qo + qN[qu + uint64(i)] + best[i]) - h[su + uint64(i)]
            if use_mask:
                for i in range(L):
                    if mask[su + uint64(i)] != 0:
                        lo = min(lo, dd[i])
                        hi = max(hi, dd[i])
            else:
                for i in range(L):
                    lo = min(lo, dd[i])
                    hi = max(hi, dd[i])
            if write == Write.IN_PLACE:
                for i in range(L):
                    h[su + uint64(i)] += relax * (dd[i] - shift)
            elif write == Write.OUT:
                for i in range(L):
                    h_out[su + uint64(i)] = h[su + uint64(i)] + relax * (dd[i] - shift)
            if write_pol:
                for i in range(L):
                    pol[su + uint64(i)] = arg[i]
            if near >= 0.0:
                nbits[rid] = nb
            s0 += L
            tr += 1
    if lo < los[ci]:
        los[ci] = lo
    if hi > his[ci]:
        his[ci] = hi


@njit(cache=True, nogil=True, boundscheck=False, fastmath={"contract"})
def _fixed_chunk(ci, tc, tile_cfg, x0, x1, N, lo_, dims, strides, off, act_ptr, out_ptr, e_prob, e_m, e_base,
                 e_stride, q, h, h_out, pol, write, relax, shift, mask, use_mask, iscr, fscr, los, his):
    split, sat, A, rs, rm, arg = iscr[1], iscr[2], iscr[3], iscr[4], iscr[5], iscr[6]
    acc, best, dd = fscr[0], fscr[1], fscr[2]
    lo = np.inf
    hi = -np.inf
    for x in range(x0, x1):
        c = tile_cfg[x]
        L, loN, o0, nO, s0, qo0, nrows, tr = _plane(c, tc, N, lo_, dims, strides, off, act_ptr, out_ptr, e_m,
                                                    e_base, e_stride, q, split, sat, A, rs, rm)
        a0 = act_ptr[c]
        na = act_ptr[c + 1] - a0
        qN = q[N - 1]
        qu = uint64(loN)
        for r in range(nrows):
            qo = qo0
            if N >= 2:
                qo += q[N - 2, tr]
            t1 = tr + 1
            su = uint64(s0)
            # the actions used on this row (a bit set; configurations have at most 64 actions
            # here, else every action is tried), each computed on the whole row as in the
            # improvement kernel and kept where the policy chose it
            used = uint64(0)
            for i in range(L):
                pol_i = pol[su + uint64(i)]
                arg[i] = pol_i
                used |= uint64(1) << uint64(pol_i & 63)
            # one action on the whole row (most rows): its values go straight into best, no select
            single = na <= 64 and (used & (used - uint64(1))) == uint64(0)
            tgt = best if single else acc
            for j in range(na):
                if na <= 64 and (used >> uint64(j)) & uint64(1) == uint64(0):
                    continue
                ob = out_ptr[a0 + j] - o0
                oe = out_ptr[a0 + j + 1] - o0
                for oo in range(ob, oe):
                    m = rm[oo]
                    Po = A[oo] + rs[oo] * (t1 if t1 < m else m)
                    p = e_prob[o0 + oo]
                    b = uint64(Po + loN + 1)
                    sp = split[oo]
                    v = p * h[Po + sat[oo]]
                    if oo == ob:
                        for i in range(sp):
                            tgt[i] = p * h[b + uint64(i)]
                        for i in range(sp, L):
                            tgt[uint64(i)] = v
                    else:
                        for i in range(sp):
                            tgt[i] += p * h[b + uint64(i)]
                        for i in range(sp, L):
                            tgt[uint64(i)] += v
                if not single:
                    for i in range(L):
                        best[i] = acc[i] if arg[i] == j else best[i]
            if write == Write.IN_PLACE:
                for i in range(L):
                    hs = h[su + uint64(i)]
                    h[su + uint64(i)] = hs + relax * (((qo + qN[qu + uint64(i)] + best[i]) - hs) - shift)
                s0 += L
                tr += 1
                continue
            for i in range(L):
                dd[i] = (qo + qN[qu + uint64(i)] + best[i]) - h[su + uint64(i)]
            if use_mask:
                for i in range(L):
                    if mask[su + uint64(i)] != 0:
                        lo = min(lo, dd[i])
                        hi = max(hi, dd[i])
            else:
                for i in range(L):
                    lo = min(lo, dd[i])
                    hi = max(hi, dd[i])
            if write == Write.IN_PLACE:
                for i in range(L):
                    h[su + uint64(i)] += relax * (dd[i] - shift)
            elif write == Write.OUT:
                for i in range(L):
                    h_out[su + uint64(i)] = h[su + uint64(i)] + relax * (dd[i] - shift)
            s0 += L
            tr += 1
    if lo < los[ci]:
        los[ci] = lo
    if hi > his[ci]:
        his[ci] = hi


# ----------------------------------------------------------------------------- drivers
# A sweep is a list of work items (tile, x0, x1): the planes of configurations
# tile_cfg[x0:x1] in that tile. Chunk ci does items[ip[ci]:ip[ci + 1]] in order, and the chunks
# run on numba's threads in one parallel region per sweep (a region per tile was measured 10x
# slower on a loaded machine: every region waits for both threads to be scheduled). The chunks
# are contiguous ranges of tiles (:func:`.operator.work_items`), so each thread's in-place sweep
# runs in the serial order over its part of the AoI box.


def _all_actions_body(items, ip, tile_tc, tile_cfg, N, lo_, dims, strides, off, act_ptr, out_ptr, e_prob, e_m,
                      e_base, e_stride, q, h, h_out, pol, W, mode, write, write_pol, relax, shift, mask, use_mask,
                      cand, use_cand, row_off, near, nbits, maxO, maxL, los, his):
    for ci in prange(ip.size - 1):
        los[ci] = np.inf
        his[ci] = -np.inf
        iscr = np.zeros((7, max(maxO, maxL)), np.int64)
        fscr = np.zeros((3, maxL))
        for it in range(ip[ci], ip[ci + 1]):
            _all_chunk(ci, tile_tc[items[it, 0]], tile_cfg, items[it, 1], items[it, 2], N, lo_, dims, strides,
                       off, act_ptr, out_ptr, e_prob, e_m, e_base, e_stride, q, h, h_out, pol, W, mode, write,
                       write_pol, relax, shift, mask, use_mask, cand, use_cand, row_off, near, nbits, iscr, fscr,
                       los, his)


def _fixed_policy_body(items, ip, tile_tc, tile_cfg, N, lo_, dims, strides, off, act_ptr, out_ptr, e_prob, e_m,
                       e_base, e_stride, q, h, h_out, pol, write, relax, shift, mask, use_mask, maxO, maxL, los, his):
    for ci in prange(ip.size - 1):
        los[ci] = np.inf
        his[ci] = -np.inf
        iscr = np.zeros((7, max(maxO, maxL)), np.int64)
        fscr = np.zeros((3, maxL))
        for it in range(ip[ci], ip[ci + 1]):
            _fixed_chunk(ci, tile_tc[items[it, 0]], tile_cfg, items[it, 1], items[it, 2], N, lo_, dims, strides,
                         off, act_ptr, out_ptr, e_prob, e_m, e_base, e_stride, q, h, h_out, pol, write, relax,
                         shift, mask, use_mask, iscr, fscr, los, his)


#: Every action's value on each state (the Bellman operator or a weighted policy), by chunks.
all_actions, all_actions_serial = twins(_all_actions_body, "all_actions")
#: One fixed action per state, by chunks.
fixed_policy, fixed_policy_serial = twins(_fixed_policy_body, "fixed_policy")


def _used_actions_body(pol, off, cand):
    for c in prange(off.size - 1):
        bits = uint64(0)
        for s in range(off[c], off[c + 1]):
            bits |= uint64(1) << uint64(min(pol[s], 63))
        cand[c] = bits


#: Per configuration, the bit set of the actions ``pol`` takes somewhere in its box.
used_actions, used_actions_serial = twins(_used_actions_body, "used_actions")


def _row_actions_body(pol, off, dims, row_off, cand):
    N = dims.shape[1]
    for c in prange(off.size - 1):
        L = dims[c, N - 1]
        r = row_off[c]
        for s0 in range(off[c], off[c + 1], L):
            bits = uint64(0)
            for i in range(L):
                bits |= uint64(1) << uint64(min(pol[s0 + i], 63))
            cand[r] = bits
            r += 1


#: Per row (the last AoI axis of a configuration's box), the bit set of the actions ``pol`` takes on it.
row_actions, row_actions_serial = twins(_row_actions_body, "row_actions")


# ----------------------------------------------------------------------------- starts and checks
def _clamped_body(N, s_off, s_lo, s_dims, s_strides, b_off, b_lo, b_dims, h_small, out):
    """out(c, t) = h_small(c, t clamped into the small box of c), per configuration (C order,
    a row of the last axis at a time)."""
    for c in prange(b_off.size - 1):
        t = np.zeros(max(N, 1), np.int64)  # the row's indices in the big box (first N - 1 axes)
        L = b_dims[c, N - 1]
        nrows = (b_off[c + 1] - b_off[c]) // L
        s = b_off[c]
        lN = s_lo[c, N - 1]
        hN = lN + s_dims[c, N - 1] - 1
        for r in range(nrows):
            base = s_off[c]
            for k in range(N - 1):
                a = min(max(b_lo[c, k] + t[k], s_lo[c, k]), s_lo[c, k] + s_dims[c, k] - 1) - s_lo[c, k]
                base += a * s_strides[c, k]
            for i in range(L):
                a = min(max(b_lo[c, N - 1] + i, lN), hN) - lN
                out[s + i] = h_small[base + a * s_strides[c, N - 1]]
            s += L
            k = N - 2
            while k >= 0:
                t[k] += 1
                if t[k] < b_dims[c, k]:
                    break
                t[k] = 0
                k -= 1


def _value_range_body(h, nchunk, los, his):
    """min and max of h (NaN if an entry is), in one pass by ``nchunk`` contiguous chunks."""
    n = h.size
    for ci in prange(nchunk):
        a = n * ci // nchunk
        b = n * (ci + 1) // nchunk
        lo = np.inf
        hi = -np.inf
        nan = False
        for i in range(a, b):
            x = h[i]
            lo = min(lo, x)
            hi = max(hi, x)
            nan |= x != x
        if nan:
            lo = np.nan
            hi = np.nan
        los[ci] = lo
        his[ci] = hi


#: A start at larger caps from a solution at smaller ones (:func:`.start.clamped_values`).
clamped, clamped_serial = twins(_clamped_body, "clamped")
#: min / max of a value vector by chunks (the loop's finiteness check, :meth:`.iterate.BoxSweeps.h_range`).
value_range, value_range_serial = twins(_value_range_body, "value_range")


# ----------------------------------------------------------------------------- reachability
@njit(inline="always")
def _row_offsets(t, N, e_base, e_stride, e_m, o0, nO, P):
    """Successor offsets (every axis but the last) of the outcomes o0 .. o0 + nO - 1 from the row
    at AoI indices t (the first N - 1 axes)."""
    for o in range(nO):
        e = o0 + o
        v = e_base[e]
        for k in range(N - 1):
            tk = t[k] + 1
            mk = e_m[e, k]
            v += e_stride[e, k] * (tk if tk < mk else mk)
        P[o] = v


@njit(inline="always")
def _next_row(t, c, N, lo_, dims):
    """The AoI indices of the next row of configuration c's box (C order)."""
    k = N - 2
    while k >= 0:
        t[k] += 1
        if t[k] < lo_[c, k] + dims[c, k]:
            break
        t[k] = lo_[c, k]
        k -= 1


@njit(cache=True, nogil=True, boundscheck=False)
def _reach_config(c, N, lo_, dims, off, act_ptr, out_ptr, e_m, e_base, e_stride, mask, t, P):
    """Mark the successors (under every action) of the marked states of configuration c;
    returns how many states were newly marked."""
    L = dims[c, N - 1]
    loN = lo_[c, N - 1]
    o0 = out_ptr[act_ptr[c]]
    nO = out_ptr[act_ptr[c + 1]] - o0
    nrows = 1
    for k in range(N - 1):
        nrows *= dims[c, k]
        t[k] = lo_[c, k]
    new = 0
    s0 = off[c]
    for r in range(nrows):
        _row_offsets(t, N, e_base, e_stride, e_m, o0, nO, P)
        for i in range(L):
            if mask[s0 + i] == 0:
                continue
            tN = loN + i + 1
            for o in range(nO):
                mN = e_m[o0 + o, N - 1]
                idx = P[o] + (tN if tN < mN else mN)
                if mask[idx] == 0:
                    mask[idx] = 1
                    new += 1
        s0 += L
        _next_row(t, c, N, lo_, dims)
    return new


@njit(cache=True, nogil=True)
def reach_all(N, lo_, dims, off, act_ptr, out_ptr, e_m, e_base, e_stride, mask, maxO, max_passes):
    """Passes over every configuration until no state is newly marked; returns the passes made
    (``max_passes + 1`` if it had not settled)."""
    nC = off.size - 1
    t = np.empty(max(N, 1), np.int64)
    P = np.empty(maxO, np.int64)
    for it in range(max_passes):
        new = 0
        for c in range(nC):
            new += _reach_config(c, N, lo_, dims, off, act_ptr, out_ptr, e_m, e_base, e_stride, mask, t, P)
        if new == 0:
            return it + 1
    return max_passes + 1


# ----------------------------------------------------------------------------- aggregation
def _agg_config_body(cp, N, lo_, dims, off, act_ptr, out_ptr, e_prob, e_m, e_base, e_stride, q, h, pol, counts, rsum,
                     maxO):
    """Per configuration c: how many of its states take each local action under ``pol``
    (``counts[c, j]``) and the sum of their residuals d = c + P_pol h - h (``rsum[c]``). A plain
    loop over each box (a row's successor offsets computed once): one pass a correction."""
    for ci in prange(cp.size - 1):
        t = np.empty(max(N, 1), np.int64)
        P = np.empty(maxO, np.int64)
        for c in range(cp[ci], cp[ci + 1]):
            L = dims[c, N - 1]
            loN = lo_[c, N - 1]
            a0 = act_ptr[c]
            o0 = out_ptr[a0]
            nO = out_ptr[act_ptr[c + 1]] - o0
            for j in range(counts.shape[1]):
                counts[c, j] = 0
            nrows = 1
            for k in range(N - 1):
                nrows *= dims[c, k]
                t[k] = lo_[c, k]
            s0 = off[c]
            acc = 0.0
            for r in range(nrows):
                _row_offsets(t, N, e_base, e_stride, e_m, o0, nO, P)
                qr = 0.0
                for k in range(N - 1):
                    qr += q[k, t[k]]
                for i in range(L):
                    s = s0 + i
                    j = pol[s]
                    counts[c, j] += 1
                    tN = loN + i + 1
                    v = qr + q[N - 1, loN + i]
                    for oo in range(out_ptr[a0 + j], out_ptr[a0 + j + 1]):
                        mN = e_m[oo, N - 1]
                        v += e_prob[oo] * h[P[oo - o0] + (tN if tN < mN else mN)]
                    acc += v - h[s]
                s0 += L
                _next_row(t, c, N, lo_, dims)
            rsum[c] = acc


def _agg_apply_body(off, h, y):
    """h[s] += y[c] over the states s of every configuration c."""
    for c in prange(off.size - 1):
        yc = y[c]
        for s in range(off[c], off[c + 1]):
            h[s] += yc


#: Per configuration, a fixed policy's action counts and residual sum (the aggregated problem).
agg_config, agg_config_serial = twins(_agg_config_body, "agg_config")
#: The correction of every state by its configuration's.
agg_apply, agg_apply_serial = twins(_agg_apply_body, "agg_apply")
