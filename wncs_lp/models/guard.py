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
mask per box state: ``matrix_free_bytes``, the floor of a solve. A second float64 vector (the
extrapolation's and the Jacobi fallback's) is taken only when it fits when the solve starts:
``matrix_free_full_bytes``.

Before exploring, :func:`check_size` looks at what the scenario alone tells
(:meth:`~wncs_lp.models.base.Model.automaton_bounds`): every initial configuration carries the
whole AoI box, so ``initial x prod_k tau_hat_k`` states is a lower bound, and the automaton's
exploration is bounded (:data:`~wncs_lp.models.automaton.MAX_CONFIGS`, ``MAX_EDGES``). A
scenario whose lower bounds already exceed the limit is refused at once. All the arithmetic is in
Python integers and floats: a box of 8^21 vectors does not wrap around int64.

The limit is the smallest of the memory limits that apply to this process
(:func:`memory_limits`): the machine's available memory, the container's cgroup limit and the
process's own ``RLIMIT_AS`` / ``RLIMIT_DATA`` (``prlimit --as=8G``), each less what is in use.
"""
from __future__ import annotations

import math
import os
import re
from collections import deque
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from ..errors import SizeLimitError
from ..scenario import Scenario
from .automaton import MAX_CONFIGS, MAX_EDGES, MAX_WORK, approx_count as _count, exploration_limit

__all__ = ["SizeEstimate", "SizeLimitError", "estimate_size", "check_size", "build_checked", "available_memory",
           "memory_budget", "require_memory", "memory_limits", "matrix_free_fit"]

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
#: Extra factor for an interior-point LP (KKT matrix and its sparse factorisation) on small
#: instances: 10-40x the MDP's own size. The floor of :func:`lp_bytes`.
LP_FACTOR = 40.0
#: The LP's peak grows faster than its size: the fill of the interior point's factor. Peak resident
#: memory of ``wncs-lp solve --method lp`` (Clarabel) on processes 1-3 of the paper: 0.23 GB at cap 8,
#: over 1.0 GB at cap 10, 3.78 GB at cap 12; the 3-process preemption scenario at cap 7: 2.35 GB
#: (``/usr/bin/time -v``). In x = sqrt(transition nonzeros x pairs) these lie on
#: ``LP_BYTES_REF * (x / LP_SIZE_REF) ** LP_EXPONENT`` (the size alone would put the preemption LP, with
#: 9 nonzeros a pair, at 3x its peak; the pairs alone at 0.4x); :data:`LP_SLACK` above it.
LP_BYTES_REF = 120e6
LP_SIZE_REF = 92_000
LP_EXPONENT = 1.85
LP_SLACK = 1.25
#: Each LP backend's peak against Clarabel's (processes 1-3 at cap 8: HiGHS 146 MB and cvxpy with
#: Clarabel 306 MB against Clarabel's 231 MB, of which ~100 MB is the interpreter's), rounded up.
LP_BACKEND_SHARE = {"clarabel": 1.0, "highs": 0.6, "cvxpy": 1.5}
#: Fraction of the available memory a build may use before it is refused.
MEMORY_FRACTION = 0.5
#: Bytes per state of the matrix-free solver at its floor: the float64 value vector, the uint8
#: policy and the uint8 reachability mask (used only when the hull's bracket needs it; counted
#: always).
MATRIX_FREE_BYTES_PER_STATE = 10
#: Bytes per state of the second float64 vector (extrapolation, Jacobi fallback), when it fits.
MATRIX_FREE_SECOND_VECTOR = 8
#: Fixed extra of the matrix-free solver (interpreter, numba, tables), measured ~0.3 GB.
MATRIX_FREE_OVERHEAD = 400 << 20


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
        Estimated peak memory of the LP on Clarabel (:func:`lp_bytes`).
    matrix_free_states : int
        States of the matrix-free solver's layout (the per-axis interval hull; exact).
    matrix_free_bytes : int
        Peak memory of a matrix-free solve at its floor, one value vector (no matrix: see the
        module docstring).
    matrix_free_full_bytes : int
        The same with the second value vector (extrapolation, Jacobi fallback), which a solve
        takes when it fits.
    configs_bound : int or None
        The model's upper bound on the configurations, from the scenario alone.
    complete : bool
        False for a refusal before exploring: then ``configs`` is the number of initial
        configurations and the sizes are lower bounds from their AoI boxes alone.
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
    matrix_free_full_bytes: int = 0
    configs_bound: int | None = None
    complete: bool = True
    lp_backend_bytes: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        return asdict(self)

    def lp_need(self, backend: str | bool = True) -> int:
        """The LP's estimated peak on ``backend`` (``clarabel``, ``highs``, ``cvxpy``; True: Clarabel's)."""
        if backend is True or backend not in self.lp_backend_bytes:
            return self.lp_bytes
        return int(self.lp_backend_bytes[backend])


def _meminfo() -> dict[str, int]:
    """/proc/meminfo and /proc/self/status lines of interest, in bytes."""
    out = {}
    for path, keys in (("/proc/meminfo", ("MemAvailable",)), ("/proc/self/status", ("VmSize", "VmData"))):
        try:
            for line in Path(path).read_text().splitlines():
                key, _, rest = line.partition(":")
                if key in keys and rest.split():
                    out[key] = int(rest.split()[0]) * 1024
        except (OSError, ValueError):
            pass
    return out


def _read_int(path: Path) -> int | None:
    try:
        text = path.read_text().strip()
    except OSError:
        return None
    return int(text) if text.isdigit() else None  # "max" (cgroup v2): no limit


def _inactive_file(folder: Path, key: str) -> int:
    try:
        for line in (folder / "memory.stat").read_text().splitlines():
            name, _, value = line.partition(" ")
            if name == key and value.strip().isdigit():
                return int(value)
    except OSError:
        pass
    return 0


def _cgroup_headroom(root: Path = Path("/")) -> int | None:
    """The least (limit - usage) over this process's memory cgroup and its ancestors (v1 or v2;
    reclaimable page cache counted free), or None without a limit. ``root``: the file system root."""
    try:
        lines = (root / "proc/self/cgroup").read_text().splitlines()
    except OSError:
        return None
    best = None
    for line in lines:
        parts = line.split(":", 2)
        if len(parts) != 3:
            continue
        if parts[0] == "0" and parts[1] == "":
            base, files = root / "sys/fs/cgroup", ("memory.max", "memory.current", "inactive_file")
        elif "memory" in parts[1].split(","):
            base, files = root / "sys/fs/cgroup/memory", ("memory.limit_in_bytes", "memory.usage_in_bytes",
                                                          "total_inactive_file")
        else:
            continue
        rel = Path(parts[2].lstrip("/"))
        for folder in {base / rel, *(base / q for q in rel.parents)}:
            limit, usage = _read_int(folder / files[0]), _read_int(folder / files[1])
            if limit is None or usage is None or limit >= 1 << 60:
                continue
            room = max(limit - usage + _inactive_file(folder, files[2]), 0)
            best = room if best is None else min(best, room)
    return best


def memory_limits() -> dict[str, int]:
    """Bytes this process may still allocate, by the limit that applies.

    ``"available memory"`` (``MemAvailable`` of /proc/meminfo), ``"cgroup limit"`` (the
    container's memory limit less its usage), ``"RLIMIT_AS"`` and ``"RLIMIT_DATA"`` (the
    process's address-space and data limits, e.g. ``prlimit --as=8G``, less what it maps now).
    Limits that do not apply (or cannot be read) are absent.
    """
    info = _meminfo()
    out = {}
    if "MemAvailable" in info:
        out["available memory"] = info["MemAvailable"]
    else:
        try:
            out["available memory"] = int(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
        except (ValueError, OSError, AttributeError):
            pass
    room = _cgroup_headroom()
    if room is not None:
        out["cgroup limit"] = room
    try:
        import resource
    except ImportError:  # pragma: no cover - not on POSIX
        return out
    for name, used in (("RLIMIT_AS", "VmSize"), ("RLIMIT_DATA", "VmData")):
        soft = resource.getrlimit(getattr(resource, name))[0]
        if soft != resource.RLIM_INFINITY and soft > 0:
            out[name] = max(int(soft) - info.get(used, 0), 0)
    return out


def available_memory() -> int:
    """Bytes this process may allocate now: the smallest of :func:`memory_limits` (8 GiB if none
    can be read)."""
    limits = memory_limits()
    return min(limits.values()) if limits else 8 << 30


def _limit_words(available: int) -> str:
    """Which limit set ``available`` (for messages): the smallest one, when it is that one."""
    limits = memory_limits()
    if limits:
        name = min(limits, key=limits.get)
        if name != "available memory" and abs(limits[name] - available) <= 0.1 * max(available, 1):
            return f"the memory this process may still use under its {name}"
    return "the memory available now"


def estimate_size(scenario: Scenario, model=None) -> SizeEstimate:
    """Estimate (upper bounds) the size of the MDP of a scenario without building it.

    ``model`` (a :class:`~wncs_lp.models.base.Model` of the scenario) lends its explored
    automaton, which a following ``model.build()`` then reuses. The automaton is explored within
    the budget of :func:`~wncs_lp.models.automaton.exploration_limit`.
    """
    if model is None:
        from . import model_for

        model = model_for(scenario)
    auto = model.automaton
    caps = scenario.tau_caps
    masks = _axis_masks(auto, caps)
    nC = len(auto.configs)
    # float64 products: sizes beyond 2^53 lose digits, never wrap around (int64 would at 8^21)
    per_cfg = np.ones(nC, dtype=np.float64)
    hull = np.ones(nC, dtype=np.float64)
    for k, cap in enumerate(caps):
        per_cfg *= masks[k].sum(axis=1)
        first = masks[k].argmax(axis=1)
        last = cap - 1 - masks[k][:, ::-1].argmax(axis=1)
        hull *= last - first + 1
    n_act = np.array([len(a) for a in auto.actions], dtype=np.float64)
    n_out = np.array([sum(len(o) for o in outs) for outs in auto.outcomes], dtype=np.float64)
    states = int(per_cfg.sum())
    pairs = int((per_cfg * n_act).sum())
    nnz = int((per_cfg * n_out).sum())
    box = math.prod(caps)
    build = nnz * BUILD_BYTES_PER_NNZ + pairs * BYTES_PER_PAIR + states * BYTES_PER_STATE + nC * box
    mf_states = int(hull.sum())
    mf = mf_states * MATRIX_FREE_BYTES_PER_STATE + MATRIX_FREE_OVERHEAD
    by_backend = {b: lp_bytes(nnz, pairs, b) for b in LP_BACKEND_SHARE}
    return SizeEstimate(nC, box, states, pairs, nnz, int(build), by_backend["clarabel"], mf_states, int(mf),
                        int(mf + mf_states * MATRIX_FREE_SECOND_VECTOR), model.automaton_bounds().configs,
                        lp_backend_bytes=by_backend)


def matrix_free_fit(est: SizeEstimate, available: int) -> str:
    """What a matrix-free solve of ``est`` would hold in ``available`` bytes, in words: its floor
    (one value vector) against 90% of them (the size guard's limit for the method), then whether
    the second value vector fits beside it (the solver takes it when ``1.25 x`` its size is still
    free once the floor is allocated)."""
    floor, full = est.matrix_free_bytes, est.matrix_free_full_bytes
    words = (f"about {_gib(floor)} with one value vector (the floor: value, policy and mask bytes), "
             f"{_gib(full)} with the second vector of the extrapolation and the Jacobi fallback")
    if floor > 0.9 * available:
        return words + f": does not fit in {_gib(available)} available now (a solve is refused: a smaller cap)"
    second = 1.25 * (full - floor)
    if second <= available - floor:
        return words + ": fits with both vectors"
    return words + (": fits with one vector only (a solve then runs without the extrapolation and the Jacobi "
                    "fallback)")


def lp_bytes(nnz: int, pairs: int, backend: str = "clarabel") -> int:
    """Estimated peak memory of the occupation-measure LP of an MDP with ``nnz`` transition
    nonzeros and ``pairs`` state-action pairs, solved on ``backend`` (``clarabel``, ``highs``,
    ``cvxpy``): the larger of the linear floor (:data:`LP_FACTOR`) and the measured power law of
    the factor's fill (:data:`LP_EXPONENT`), times :data:`LP_SLACK` and the backend's share."""
    linear = LP_FACTOR * (nnz * 16 + pairs * 8)
    fill = LP_BYTES_REF * (math.sqrt(float(nnz) * float(pairs)) / LP_SIZE_REF) ** LP_EXPONENT
    return int(LP_SLACK * LP_BACKEND_SHARE.get(backend, max(LP_BACKEND_SHARE.values())) * max(linear, fill))


def _axis_masks(auto, caps: tuple[int, ...]) -> list[np.ndarray]:
    """Per-axis reachable masks: ``masks[k][c, i]``: tau_k = i + 1 is reachable with configuration c
    (the reachability fixed point of :mod:`wncs_lp.models.assemble` on per-axis sets)."""
    N, nC = len(caps), len(auto.configs)
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
    return masks


def _gib(b: float) -> str:
    return f"{_count(int(b) >> 30)} GiB" if b >= 2**50 else f"{b / 2**30:.1f} GiB"


def _lower_bounds(scenario: Scenario, model) -> SizeEstimate:
    """What the scenario alone guarantees, before exploring: every initial configuration carries
    the whole AoI box as states, each state has an action and a transition."""
    bounds = model.automaton_bounds()
    box = math.prod(scenario.tau_caps)
    states = bounds.initial * box
    build = states * (BUILD_BYTES_PER_NNZ + BYTES_PER_PAIR + BYTES_PER_STATE)
    lp = states * 24 * int(LP_FACTOR)
    mf = states * MATRIX_FREE_BYTES_PER_STATE + MATRIX_FREE_OVERHEAD
    return SizeEstimate(bounds.initial, box, states, states, states, build, lp, states, mf,
                        mf + states * MATRIX_FREE_SECOND_VECTOR, bounds.configs, complete=False)


def _refuse_before_exploring(scenario: Scenario, model, limit: int, words: str, *, need_lp: bool,
                             matrix_free: bool) -> None:
    """Raise :class:`SizeLimitError` when the lower bounds alone exceed the limit or the budget."""
    low = _lower_bounds(scenario, model)
    bounds = model.automaton_bounds()
    head = f"{scenario.source}: "
    need = low.matrix_free_bytes if matrix_free else low.build_bytes + (low.lp_bytes if need_lp else 0)
    if need > limit:
        what = "the matrix-free solver's value vector" if matrix_free else "the MDP"
        raise SizeLimitError(
            head + f"{what} would need at least {_gib(need)} before its automaton is even explored: the AoI box "
            f"(prod tau_hat = {_count(low.box)} vectors) of each of its {_count(bounds.initial)} initial "
            f"configuration(s) is a set of states, {_count(low.states)} in all; over the limit of {_gib(limit)} "
            f"({words}). Cheaper routes: a smaller cap (--set tau_cap=...) or fewer processes; "
            + "; ".join(model.cheaper_routes() or ["none"]) + ". Use --force (force=True) to run anyway.", low)
    edges = bounds.initial * bounds.edges_initial
    if bounds.initial > MAX_CONFIGS or edges > MAX_EDGES or edges * scenario.n_processes > MAX_WORK:
        raise SizeLimitError(
            head + f"the configuration automaton has {_count(bounds.initial)} initial configuration(s) with at least "
            f"{_count(edges)} edges (actions x outcomes, each with a delivery vector of {scenario.n_processes:,} "
            f"entries) among them, beyond the exploration budget ({MAX_CONFIGS:,} configurations, {MAX_EDGES:,} "
            f"edges, {MAX_WORK:,} work units: wncs_lp.models.automaton); fewer processes or servers make it "
            "smaller. Use --force (force=True) to explore it anyway.", low)


def check_size(
    scenario: Scenario,
    *,
    force: bool = False,
    need_lp: bool | str = False,
    limit_bytes: int | None = None,
    model=None,
    method: str | None = None,
    offer: tuple | None = None,
) -> SizeEstimate:
    """Refuse (raise :class:`SizeLimitError`) a build whose estimate exceeds the memory limit.

    The limit is ``MEMORY_FRACTION`` of :func:`available_memory` (the smallest of the limits
    that apply: :func:`memory_limits`) unless ``limit_bytes`` is given. With ``need_lp`` the LP's
    memory counts too: on the backend it names (``"clarabel"``, ``"highs"``, ``"cvxpy"``; True:
    Clarabel's, :func:`lp_bytes`). ``force=True`` only returns the estimate (and lifts the exploration budget).
    The message gives the estimate and the cheaper routes that exist.
    With a method whose memory model is the AoI box (:data:`wncs_lp.methods.BOX`: the
    matrix-free solver) the need is that solver's (``matrix_free_bytes``: nothing is built),
    against 90% of the available memory (the estimate is exact up to the fixed overhead, not an
    upper bound with slack). ``offer``: the methods (:class:`wncs_lp.methods.Method` rows) the
    caller takes, of which the message suggests those that fit (default: the unconstrained ones).

    In order: the cost tables (an overflowing one is a :class:`~wncs_lp.errors.ModelError`
    naming the process and the AoI), the lower bounds the scenario alone gives (refused before
    exploring), the automaton explored within its budget, the estimate.
    """
    from ..methods import BOX, STORED, STORED_LP, TABLE, memory_of
    from .cost import cost_tables

    if model is None:
        from . import model_for

        model = model_for(scenario)
    cost_tables(scenario)  # cheap, and an overflowing cost is the first thing to say
    matrix_free = memory_of(method) == BOX
    avail = available_memory() if limit_bytes is None else None
    if limit_bytes is not None:
        limit, words = int(limit_bytes), "the limit given"
    else:
        share = 0.9 if matrix_free else MEMORY_FRACTION
        limit, words = int(share * avail), f"{share:.0%} of {_limit_words(avail)}"
    if force:
        with exploration_limit(None):
            return estimate_size(scenario, model)
    _refuse_before_exploring(scenario, model, limit, words, need_lp=need_lp, matrix_free=matrix_free)
    est = estimate_size(scenario, model)
    if matrix_free:
        if est.matrix_free_bytes <= limit:
            return est
        raise SizeLimitError(
            f"{scenario.source}: the matrix-free solver would sweep {_count(est.matrix_free_states)} states "
            f"(one float64 value, one policy byte and one mask byte each), needing about "
            f"{_gib(est.matrix_free_bytes)}, over the limit of {_gib(limit)} ({words}). "
            f"Cheaper routes: a smaller cap (--set tau_cap=...); "
            + "; ".join(model.cheaper_routes() or ["none"]) + ". Use --force (force=True) to run anyway.",
            est,
        )
    need = est.build_bytes + (est.lp_need(need_lp) if need_lp else 0)
    if need <= limit:
        return est
    routes = []
    rows = tuple(TABLE.values()) if offer is None else tuple(offer)
    lean = next((m for m in rows if m.hint and m.memory == STORED), None)
    if need_lp and est.build_bytes <= limit and lean is not None:
        routes.append(f"{lean.hint} (--method {lean.name}) instead of the LP, which fits")
    if need_lp:  # the same LP on a backend that needs less
        for m in rows:
            other = dict(m.preset).get("backend")
            if m.memory == STORED_LP and other not in (None, need_lp) and \
                    est.build_bytes + est.lp_need(other) <= limit < need:
                routes.append(f"the LP on {other} (--method {m.name}, about "
                              f"{_gib(est.build_bytes + est.lp_need(other))}), which fits")
    box = next((m for m in rows if m.hint and m.memory == BOX), None)
    if est.matrix_free_bytes <= limit and box is not None:
        routes.append(f"{box.hint} (--method {box.name}, about {_gib(est.matrix_free_bytes)}: "
                      "no matrix is built), which fits")
    routes += model.cheaper_routes()
    routes.append(f"a smaller cap (--set tau_cap=...; the box is {_count(est.box)} AoI vectors per configuration)")
    raise SizeLimitError(
        f"{scenario.source}: the MDP would have up to {_count(est.states)} states, {_count(est.pairs)} "
        f"state-action pairs and {_count(est.nnz)} transition nonzeros, needing about {_gib(need)}"
        f"{' (LP included)' if need_lp else ''}, over the limit of {_gib(limit)} "
        f"({words}). Cheaper routes: "
        + "; ".join(routes)
        + ". Use --force (force=True) to build anyway.",
        est,
    )


def build_checked(scenario: Scenario, *, force: bool = False, need_lp: bool | str = False,
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


def memory_budget(fraction: float = MEMORY_FRACTION) -> int:
    """Bytes one large allocation may take now: ``fraction`` of :func:`available_memory` (the
    smallest of the limits that apply to this process)."""
    return int(fraction * available_memory())


def require_memory(need: int, what: str, routes: list[str] | tuple[str, ...] = (), *,
                   fraction: float = MEMORY_FRACTION, limit_bytes: int | None = None) -> None:
    """Raise :class:`SizeLimitError` when ``need`` bytes (a Python integer: no overflow) exceed the
    budget (``limit_bytes``, else ``fraction`` of the memory this process may still use), before
    anything is allocated: one sentence naming ``what``, the need, the limit and the cheaper
    ``routes``."""
    need = int(need)
    if limit_bytes is not None:
        limit, words = int(limit_bytes), "the limit given"
    else:
        avail = available_memory()
        limit, words = int(fraction * avail), f"{fraction:.0%} of {_limit_words(avail)}"
    if need <= limit:
        return
    tail = f" Cheaper routes: {'; '.join(routes)}." if routes else ""
    raise SizeLimitError(f"{what} would need about {_gib(need)}, over the limit of {_gib(limit)} ({words})." + tail)
