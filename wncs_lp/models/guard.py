"""Size guard: estimate an MDP's size and memory from its scenario, before building it.

The configuration automaton of a model (server pipelines, jobs, arrivals) is small and cheap to
explore; the state space is that automaton times the AoI box. The estimate runs the reachability
fixed point of :mod:`wncs_lp.models.assemble` on *per-axis* masks (for each configuration and each
process, the set of reachable tau_k values) instead of full boxes. The product of the per-axis
sets contains the true reachable set, so

    states_est = sum_c prod_k |T_k(c)|  >=  true number of states,

an upper bound that costs O(configs x sum_k tau_hat_k) instead of O(configs x prod_k tau_hat_k).
Pairs and transition nonzeros follow by weighting each configuration's count with its number of
actions and outcomes (upper bounds too: merging of equal successors only lowers the truth).

The matrix-free solver (:mod:`wncs_lp.solvers.matrix_free`) stores no matrix: it sweeps, per
configuration, the box spanned by the per-axis sets' intervals (their hull), keeping one float64
value vector, one byte of policy and (only when its bracket needs it) one byte of reachability
mask per box state: ``matrix_free_bytes``.
"""
from __future__ import annotations

import os
from collections import deque
from dataclasses import asdict, dataclass

import numpy as np

from ..errors import WncsError
from ..scenario import Scenario

__all__ = ["SizeEstimate", "SizeLimitError", "estimate_size", "check_size", "build_checked", "available_memory"]

#: Bytes per stored transition nonzero at the peak of a build followed by a stored-matrix value
#: iteration: P's float64 data and int32 indices (12) and the sweeps' uint8 probability code (1),
#: plus slack. Measured peaks (``benchmarks/dp_memory.py``, issue 18), processes 1-4 at caps 16
#: and 18: 32.6 and 31.4 bytes per transition in all (pairs and states included; 66.4 and 65.5
#: before the compact sweep arrays stopped copying P and sorting its data); with the three
#: constants here the estimate is ~7.8 GiB at cap 18 against 6.6 GiB measured.
BUILD_BYTES_PER_NNZ = 16
#: Bytes per pair (state, action, cost, row pointer, the build's row lengths) and per state (AoI
#: vector, configuration, numbering, state cost, pointers; the iteration's value vectors, policy
#: and bias) at that peak.
BYTES_PER_PAIR = 40
BYTES_PER_STATE = 100
#: Extra factor for an interior-point LP (KKT matrix and its sparse factorisation), measured on
#: the paper's instances to be 10-40x the MDP's own size.
LP_FACTOR = 40.0
#: Fraction of the available memory a build may use before it is refused.
MEMORY_FRACTION = 0.5
#: Bytes per state of the matrix-free solver: the float64 value vector, the uint8 policy and the
#: uint8 reachability mask (used only when the hull's bracket needs it; counted always).
MATRIX_FREE_BYTES_PER_STATE = 10
#: Fixed extra of the matrix-free solver (interpreter, numba, tables), measured ~0.3 GB.
MATRIX_FREE_OVERHEAD = 400 << 20


class SizeLimitError(WncsError):
    """The MDP a scenario would build exceeds the memory limit (use ``force`` to build anyway)."""

    def __init__(self, message: str, estimate: "SizeEstimate"):
        self.estimate = estimate
        super().__init__(message)


@dataclass(frozen=True)
class SizeEstimate:
    """Upper-bound estimate of an MDP's size, from its scenario.

    Attributes
    ----------
    configs : int
        Configurations of the automaton (exact).
    box : int
        prod_k tau_hat_k.
    states, pairs, nnz : int
        Upper bounds on states, state-action pairs and transition nonzeros.
    build_bytes : int
        Estimated peak memory of the build.
    lp_bytes : int
        Estimated peak memory of an interior-point LP solve.
    matrix_free_states : int
        States of the matrix-free solver's layout (the per-axis interval hull; exact).
    matrix_free_bytes : int
        Peak memory of a matrix-free solve (no matrix: see the module docstring).
    """

    configs: int
    box: int
    states: int
    pairs: int
    nnz: int
    build_bytes: int
    lp_bytes: int
    matrix_free_states: int = 0
    matrix_free_bytes: int = 0

    def to_dict(self) -> dict:
        return asdict(self)


def available_memory() -> int:
    """Bytes of memory available now (``MemAvailable`` of /proc/meminfo; 8 GiB if unknown)."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return 8 << 30


def estimate_size(scenario: Scenario, model=None) -> SizeEstimate:
    """Estimate (upper bounds) the size of the MDP of a scenario without building it.

    ``model`` (a :class:`~wncs_lp.models.base.Model` of the scenario) lends its explored
    automaton, which a following ``model.build()`` then reuses.
    """
    if model is None:
        from . import model_for

        model = model_for(scenario)
    auto = model.automaton
    caps = scenario.tau_caps
    N = len(caps)
    nC = len(auto.configs)
    # per-axis reachable masks: masks[k][c, i] = tau_k = i + 1 reachable with configuration c
    masks = [np.zeros((nC, cap), dtype=bool) for cap in caps]
    work: deque[int] = deque()
    queued = np.zeros(nC, dtype=bool)
    for c in auto.initial:
        for k in range(N):
            masks[k][c] = True
        if not queued[c]:
            work.append(c)
            queued[c] = True
    idx = [np.arange(cap) for cap in caps]
    while work:
        c = work.popleft()
        queued[c] = False
        for outs in auto.outcomes[c]:
            for nxt, delta, _ in outs:
                grew = False
                for k in range(N):
                    src = idx[k][masks[k][c]]
                    img = np.minimum(src + 1, caps[k] - 1)
                    if delta[k] > 0:
                        img = np.minimum(img, delta[k] - 1)
                    row = masks[k][nxt]
                    if not row[img].all():
                        row[img] = True
                        grew = True
                if grew and not queued[nxt]:
                    work.append(nxt)
                    queued[nxt] = True
    per_cfg = np.ones(nC, dtype=np.float64)
    for k in range(N):
        per_cfg *= masks[k].sum(axis=1)
    n_act = np.array([len(a) for a in auto.actions], dtype=np.float64)
    n_out = np.array([sum(len(o) for o in outs) for outs in auto.outcomes], dtype=np.float64)
    states = int(per_cfg.sum())
    pairs = int((per_cfg * n_act).sum())
    nnz = int((per_cfg * n_out).sum())
    build = nnz * BUILD_BYTES_PER_NNZ + pairs * BYTES_PER_PAIR + states * BYTES_PER_STATE + nC * int(np.prod(caps))
    lp = int(LP_FACTOR * (nnz * 16 + pairs * 8))
    hull = np.ones(nC, dtype=np.int64)
    for k in range(N):
        first = masks[k].argmax(axis=1)
        last = caps[k] - 1 - masks[k][:, ::-1].argmax(axis=1)
        hull *= last - first + 1
    mf_states = int(hull.sum())
    mf = mf_states * MATRIX_FREE_BYTES_PER_STATE + MATRIX_FREE_OVERHEAD
    return SizeEstimate(nC, int(np.prod(caps)), states, pairs, nnz, int(build), lp, mf_states, int(mf))


def _gib(b: float) -> str:
    return f"{b / 2**30:.1f} GiB"


def check_size(
    scenario: Scenario,
    *,
    force: bool = False,
    need_lp: bool = False,
    limit_bytes: int | None = None,
    model=None,
    method: str | None = None,
    offer: tuple | None = None,
) -> SizeEstimate:
    """Refuse (raise :class:`SizeLimitError`) a build whose estimate exceeds the memory limit.

    The limit is ``MEMORY_FRACTION`` of :func:`available_memory` unless ``limit_bytes`` is given.
    With ``need_lp`` the LP's memory counts too. ``force=True`` only returns the estimate.
    The message gives the estimate and the cheaper routes that exist.
    With a method whose memory model is the AoI box (:data:`wncs_lp.methods.BOX`: the
    matrix-free solver) the need is that solver's (``matrix_free_bytes``: nothing is built),
    against the whole available memory (the estimate is exact up to the fixed overhead, not an
    upper bound with slack). ``offer``: the methods (:class:`wncs_lp.methods.Method` rows) the
    caller takes, of which the message suggests those that fit (default: the unconstrained ones).
    """
    from ..methods import BOX, STORED, TABLE, memory_of

    if model is None:
        from . import model_for

        model = model_for(scenario)
    est = estimate_size(scenario, model)
    if force:
        return est
    if memory_of(method) == BOX:
        limit = int(0.9 * available_memory()) if limit_bytes is None else int(limit_bytes)
        if est.matrix_free_bytes <= limit:
            return est
        raise SizeLimitError(
            f"{scenario.source}: the matrix-free solver would sweep {est.matrix_free_states:,} states "
            f"(one float64 value, one policy byte and one mask byte each), needing about "
            f"{_gib(est.matrix_free_bytes)}, over the limit of {_gib(limit)} (90% of the memory available now). "
            f"Cheaper routes: a smaller cap (--set tau_cap=...); "
            + "; ".join(model.cheaper_routes() or ["none"]) + ". Use --force (force=True) to run anyway.",
            est,
        )
    limit = int(MEMORY_FRACTION * available_memory()) if limit_bytes is None else int(limit_bytes)
    need = est.build_bytes + (est.lp_bytes if need_lp else 0)
    if need <= limit:
        return est
    routes = []
    rows = tuple(TABLE.values()) if offer is None else tuple(offer)
    lean = next((m for m in rows if m.hint and m.memory == STORED), None)
    if need_lp and est.build_bytes <= limit and lean is not None:
        routes.append(f"{lean.hint} (--method {lean.name}) instead of the LP, which fits")
    box = next((m for m in rows if m.hint and m.memory == BOX), None)
    if est.matrix_free_bytes <= limit and box is not None:
        routes.append(f"{box.hint} (--method {box.name}, about {_gib(est.matrix_free_bytes)}: "
                      "no matrix is built), which fits")
    routes += model.cheaper_routes()
    routes.append(f"a smaller cap (--set tau_cap=...; the box is {est.box:,} AoI vectors per configuration)")
    raise SizeLimitError(
        f"{scenario.source}: the MDP would have up to {est.states:,} states, {est.pairs:,} state-action pairs "
        f"and {est.nnz:,} transition nonzeros, needing about {_gib(need)}"
        f"{' (LP included)' if need_lp else ''}, over the limit of {_gib(limit)} "
        f"({MEMORY_FRACTION:.0%} of the memory available now). Cheaper routes: "
        + "; ".join(routes)
        + ". Use --force (force=True) to build anyway.",
        est,
    )


def build_checked(scenario: Scenario, *, force: bool = False, need_lp: bool = False,
                  limit_bytes: int | None = None, offer: tuple | None = None):
    """Build a scenario's MDP after the size guard (:func:`check_size`), exploring its automaton once.

    Raises
    ------
    SizeLimitError
        The estimate exceeds the limit and ``force`` is False (the message gives the estimate
        and cheaper routes).
    """
    from . import model_for

    model = model_for(scenario)
    check_size(scenario, force=force, need_lp=need_lp, limit_bytes=limit_bytes, model=model, offer=offer)
    return model.build()
