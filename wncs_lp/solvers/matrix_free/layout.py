"""The states of a matrix-free solve: one dense AoI sub-box per configuration (:class:`BoxLayout`),
the per-axis interval hull that bounds the reachable set, and the test on the automaton that says
whether the hull's certificate closes on the reachable MDP's gain (:func:`drains_to_initial`)."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ...errors import PolicyError, SizeLimitError, SolverError
from ...models.automaton import approx_count
from ...models.system import System

__all__ = ["BoxLayout", "box_count", "layout_states", "drains_to_initial", "resolve_domain", "saturation", "check_local_actions", "DOMAINS",
           "DOMAINS_OF_LAYOUT"]

#: ``domain`` values of the solvers (see :mod:`wncs_lp.solvers.matrix_free`).
DOMAINS = ("auto", "hull", "reachable")
#: ``domain`` values of a :class:`BoxLayout`.
DOMAINS_OF_LAYOUT = ("hull", "box")


def drains_to_initial(system: System) -> bool:
    """Whether every configuration reaches an initial one with positive probability under
    every action choice (a fixed point on the automaton; see the module docstring).

    When true, every state of the hull outside the reachable set is transient under every
    policy, so the hull's certificate closes on the reachable MDP's gain.
    """
    flat = system.automaton.flat(system.n_processes)
    nC = system.n_configs
    good = np.zeros(nC, dtype=bool)
    good[list(system.automaton.initial)] = True
    a_start = flat.act_ptr[:-1]
    o_start = flat.out_ptr[:-1]
    while True:
        ok_out = good[flat.out_nxt]
        ok_act = np.logical_or.reduceat(ok_out, o_start) if ok_out.size else np.zeros(0, bool)
        ok_cfg = np.logical_and.reduceat(ok_act, a_start) if ok_act.size else np.zeros(0, bool)
        new = good | ok_cfg
        if np.array_equal(new, good):
            return bool(good.all())
        good = new


@dataclass(frozen=True, eq=False)
class BoxLayout:
    """The states of a matrix-free solve: one dense AoI sub-box per configuration.

    Attributes
    ----------
    caps : (N,) int array
    lo, dims : (|C|, N) int arrays
        Configuration c covers the 0-based AoI indices ``lo[c, k] .. lo[c, k] + dims[c, k] - 1``
        (tau_k = index + 1).
    strides : (|C|, N) int array
        C-order strides of each sub-box (the last axis contiguous).
    off : (|C| + 1,) int array
        The states of configuration c are ``off[c]:off[c+1]``.
    domain : str
        ``"hull"`` (per-axis interval hull, the default) or ``"box"`` (the whole box).
    """

    caps: np.ndarray
    lo: np.ndarray
    dims: np.ndarray
    strides: np.ndarray
    off: np.ndarray
    domain: str = "hull"

    @property
    def n_states(self) -> int:
        return int(self.off[-1])

    @property
    def n_configs(self) -> int:
        return int(self.lo.shape[0])

    @property
    def n_processes(self) -> int:
        return int(self.caps.size)

    @classmethod
    def from_system(cls, system: System, domain: str = "hull") -> "BoxLayout":
        """The per-axis interval hull of the reachable set (``domain="hull"``) or the full box."""
        if system.is_lazy:
            layout_states(system)  # refuses with the reason
        caps = np.asarray(system.caps, dtype=np.int64)
        N, nC = caps.size, system.n_configs
        if domain == "box":
            lo = np.zeros((nC, N), np.int64)
            hi = np.tile(caps - 1, (nC, 1))
        elif domain == "hull":
            lo, hi = interval_hull(system)
        else:
            raise SolverError(f"unknown layout domain {domain!r}; expected 'hull' or 'box'")
        dims = hi - lo + 1
        n = box_count(dims)
        if n >= 2**62:  # int64 offsets would wrap (the paper's four processes four times at cap 40: 10^24 states)
            raise SizeLimitError(f"the matrix-free layout would have {approx_count(n)} states, beyond what int64 indices "
                                 "address (and any memory); simulate instead (Monte Carlo)")
        strides = np.ones((nC, N), np.int64)
        for k in range(N - 2, -1, -1):
            strides[:, k] = strides[:, k + 1] * dims[:, k + 1]
        sizes = np.prod(dims, axis=1)
        off = np.r_[0, np.cumsum(sizes)].astype(np.int64)
        return cls(caps, lo, dims, strides, off, domain)

    def index(self, tau: np.ndarray, config_ids: np.ndarray) -> np.ndarray:
        """Layout indices of R states ((R, N) AoI values 1..tau_hat, (R,) configuration ids); -1
        for a state outside the layout."""
        t = np.asarray(tau, dtype=np.int64) - 1
        c = np.asarray(config_ids, dtype=np.int64)
        if t.ndim != 2 or t.shape[1] != self.n_processes or c.shape != (t.shape[0],):
            raise PolicyError(f"expected tau of shape (R, {self.n_processes}) and config_ids of shape (R,)")
        rel = t - self.lo[c]
        inside = np.all((rel >= 0) & (rel < self.dims[c]), axis=1)
        idx = self.off[c] + np.einsum("rk,rk->r", np.where(rel >= 0, rel, 0), self.strides[c])
        return np.where(inside, idx, -1)

    def config_taus(self, c: int) -> np.ndarray:
        """(n_c, N) AoI vectors (1-based) of configuration c, in layout order."""
        grids = np.indices(tuple(int(d) for d in self.dims[c]), dtype=np.int64).reshape(self.n_processes, -1).T
        return grids + self.lo[c][None, :] + 1

    def config_of(self, s: np.ndarray) -> np.ndarray:
        """Configuration id of layout states."""
        return np.searchsorted(self.off, np.asarray(s, dtype=np.int64), side="right") - 1

    def tau_of(self, s: np.ndarray) -> np.ndarray:
        """(R, N) AoI vectors (1-based) of layout states."""
        s = np.asarray(s, dtype=np.int64)
        c = self.config_of(s)
        rem = s - self.off[c]
        out = np.empty((s.size, self.n_processes), np.int64)
        for k in range(self.n_processes):
            out[:, k] = rem // self.strides[c, k]
            rem = rem - out[:, k] * self.strides[c, k]
        return out + self.lo[c] + 1

    def arrays(self) -> dict[str, np.ndarray]:
        return {"caps": self.caps, "lo": self.lo, "dims": self.dims}


def box_count(dims: np.ndarray) -> int:
    """sum over configurations of prod_k dims[c, k] as a Python integer (no int64 overflow)."""
    return sum(math.prod(int(d) for d in row) for row in np.asarray(dims).tolist())


def layout_states(system: System, domain: str = "hull") -> int:
    """The number of states of :meth:`BoxLayout.from_system` (a Python integer, however large),
    without building the layout.

    Raises
    ------
    SizeLimitError
        A lazily explored system (:attr:`System.is_lazy`): its configurations are not all known."""
    if system.is_lazy:
        raise SizeLimitError(f"{system.scenario.source}: the configuration automaton is explored lazily (too large "
                             "to enumerate), so no matrix-free layout exists; simulate instead (Monte Carlo)")
    if domain == "box":
        return system.n_configs * math.prod(int(c) for c in system.caps)
    lo, hi = interval_hull(system)
    return box_count(hi - lo + 1)


def interval_hull(system: System) -> tuple[np.ndarray, np.ndarray]:
    """Per configuration and process, the smallest interval [lo, hi] (0-based) of reachable
    tau_k: the fixed point of the interval images f([a, b]) = [f(a), f(b)],
    f(t) = min(t + 1, delta - 1, cap - 1), over every edge, from the initial configurations'
    full boxes. (The product of these intervals is closed under every transition.)"""
    caps = np.asarray(system.caps, dtype=np.int64)
    N, nC = caps.size, system.n_configs
    flat = system.automaton.flat(N)
    src = np.repeat(np.arange(nC, dtype=np.int64), np.diff(flat.out_ptr[flat.act_ptr]))
    nxt = flat.out_nxt.astype(np.int64)
    m = saturation(flat.deltas, caps)[flat.out_delta] if flat.deltas.shape[0] else np.tile(caps - 1, (nxt.size, 1))
    big = np.iinfo(np.int64).max
    lo = np.full((nC, N), big, np.int64)
    hi = np.full((nC, N), -1, np.int64)
    init = np.asarray(sorted(set(int(i) for i in system.automaton.initial)), dtype=np.int64)
    lo[init] = 0
    hi[init] = caps - 1
    while True:
        live = hi[src, 0] >= 0
        s, n_, mm = src[live], nxt[live], m[live]
        new_lo = np.minimum(lo[s] + 1, mm)
        new_hi = np.minimum(hi[s] + 1, mm)
        lo2, hi2 = lo.copy(), hi.copy()
        np.minimum.at(lo2, n_, new_lo)
        np.maximum.at(hi2, n_, new_hi)
        if np.array_equal(lo2, lo) and np.array_equal(hi2, hi):
            break
        lo, hi = lo2, hi2
    if np.any(hi < 0):  # pragma: no cover - explore_configs only keeps reachable configurations
        raise SolverError("internal error: a configuration of the automaton is not reachable")
    return lo, hi


def saturation(deltas: np.ndarray, caps: np.ndarray) -> np.ndarray:
    """(nD, N) 0-based saturation index of each delivery vector: min(cap - 1, delta - 1 if > 0)."""
    d = np.asarray(deltas, dtype=np.int64)
    return np.where(d > 0, np.minimum(d - 1, caps[None, :] - 1), caps[None, :] - 1)




def resolve_domain(system: System, domain: str) -> tuple[bool, bool]:
    """(use an exact reachability mask, the hull's bracket closes)."""
    if domain not in DOMAINS:
        raise SolverError(f"unknown domain {domain!r}; expected one of {', '.join(DOMAINS)}")
    drains = drains_to_initial(system)
    if domain == "reachable":
        return True, drains
    if domain == "hull":
        return False, drains
    return (not drains), drains



def check_local_actions(table: Any, layout: BoxLayout, n_actions: np.ndarray, what: str) -> np.ndarray:
    """``table`` as the (n,) uint8 local actions of a layout, after checking it.

    One integer per layout state, and at a state of configuration c an index
    ``0 <= j < n_actions[c]``: a kernel reads the outcome tables of action j of c without bounds
    checks, so an index out of range would read another configuration's tables and give a wrong
    (certified!) number. Raises one :class:`PolicyError` naming ``what`` and the first bad state.
    """
    a = np.asarray(table)
    n = layout.n_states
    if a.shape != (n,):
        raise PolicyError(f"{what}: expected one local action index per layout state ({n:,}), got shape {a.shape}")
    if not np.issubdtype(a.dtype, np.integer):
        raise PolicyError(f"{what}: local action indices must be integers, got dtype {a.dtype}")
    nact = np.asarray(n_actions, dtype=np.int64)
    starts = layout.off[:-1]
    lo_c, hi_c = np.minimum.reduceat(a, starts), np.maximum.reduceat(a, starts)
    bad = np.flatnonzero((lo_c < 0) | (hi_c >= nact))
    if bad.size:
        c = int(bad[0])
        seg = a[layout.off[c]:layout.off[c + 1]].astype(np.int64)
        i = int(np.flatnonzero((seg < 0) | (seg >= nact[c]))[0])
        s = int(layout.off[c]) + i
        tau = tuple(int(t) for t in layout.tau_of(np.array([s]))[0])
        raise PolicyError(f"{what}: state {s:,} (configuration {c}, tau = {tau}) has local action {int(seg[i])}, "
                          f"but configuration {c} has {int(nact[c])} action(s) (0..{int(nact[c]) - 1})")
    if int(nact.max(initial=1)) > 256:  # pragma: no cover - the paper's models have <= 12
        raise PolicyError(f"{what}: a configuration has more than 256 actions; a uint8 table cannot hold them")
    return a if a.dtype == np.uint8 else a.astype(np.uint8)
