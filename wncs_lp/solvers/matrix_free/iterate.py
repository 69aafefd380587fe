"""Certified value iteration (:func:`matrix_free_value_iteration`) and exact policy evaluation
(:func:`matrix_free_evaluate`) over a :class:`~.layout.BoxLayout`, on the matrix-free kernels."""
from __future__ import annotations

import sys
import time
from typing import Any

import numpy as np

from ...errors import PolicyError, SolverError
from ...models.system import System
from ...scenario import Scenario
from ..certify import width_closed
from ..dp import VI_TOL, initial_bias
from .extrapolate import Extrapolator
from .layout import BoxLayout, resolve_domain
from .operator import Operator, with_cost
from .result import MatrixFreeEvaluation, MatrixFreeSolution, as_system
from .sweeper import Sweeper, load_kernels, reachable_mask

__all__ = ["matrix_free_value_iteration", "matrix_free_evaluate", "policy_table", "matrix_free_bytes", "SCHEMES",
           "BYTES_PER_STATE"]

#: ``scheme`` values of :func:`matrix_free_value_iteration`.
SCHEMES = ("auto", "mpi", "gs", "jacobi")

#: Bytes per state of a solve: one float64 value vector and the uint8 policy (a Jacobi
#: iteration, or the stall fallback, adds a second vector: 17 bytes).
BYTES_PER_STATE = 9


def matrix_free_bytes(n_states: int, *, vectors: int = 1, mask: bool = False) -> int:
    """Memory of a matrix-free solve over ``n_states`` layout states (value vectors, policy,
    optional reachability mask)."""
    return int(n_states) * (8 * int(vectors) + 1 + (1 if mask else 0))


def _initial_h(h0: Any, n: int) -> np.ndarray:
    """A warm start: a bias array or a matrix-free result's bias (checked by :func:`~wncs_lp.solvers.dp.initial_bias`)."""
    if isinstance(h0, (MatrixFreeSolution, MatrixFreeEvaluation)):
        h0 = h0.bias
    return initial_bias(h0, n, 0)


def _second_vector_fits(n: int) -> bool:
    """Whether a second value vector (the Jacobi fallback's) fits in the memory available now."""
    from ...models.guard import available_memory

    return 8 * n * 1.25 <= available_memory()


def _say(progress: bool, text: str) -> None:
    if progress:
        print(text, file=sys.stderr, flush=True)


def _mb(nbytes: float) -> str:
    return f"{nbytes / 2**20:,.0f} MiB"


# ============================================================================ the solver
def matrix_free_value_iteration(
    scenario_or_system: Scenario | System,
    *,
    tol: float = VI_TOL,
    atol: float = 0.0,
    max_iter: int = 100_000,
    scheme: str = "auto",
    relax: float = 0.8,
    eval_sweeps: int = 1,
    check_every: int = 5,
    h0: Any = None,
    threads: int | None = None,
    domain: str = "auto",
    stall_checks: int = 40,
    progress: bool = False,
    on_interrupt: str = "return",
    tile_order: str = "forward",
    extrapolate: bool = True,
    warm_start: bool = False,
    warm_rel: float = 0.05,
    warm_max: int = 100,
    force: bool = False,
) -> MatrixFreeSolution:
    """Certified average-cost value iteration without a transition matrix.

    The iteration is that of :func:`wncs_lp.solvers.dp.value_iteration` (modified policy
    iteration: relaxed Gauss-Seidel improvement sweeps, ``eval_sweeps`` sweeps of the policy
    they found, and every ``check_every`` improvement sweeps a certificate pass), on the
    matrix-free kernels. The certificate pass computes d = T h - h over **every** state of the
    layout (or of the exact reachable set, see ``domain``) on one fixed h and stops when
    ``hi - lo <= tol |(lo + hi)/2|`` (or ``<= atol``). It writes nothing but the greedy policy
    of that h, so the returned ``bias`` is exactly the h of the certificate and the returned
    policy its greedy policy (whose gain is <= ``gain_upper``).

    Parameters
    ----------
    scenario_or_system : Scenario or System
    tol, atol : float
        Relative (default 1e-9) and absolute certificate widths.
    max_iter : int
        Budget of improvement + certificate sweeps (evaluation sweeps not counted).
    scheme : {"auto", "mpi", "gs", "jacobi"}
        ``"auto"`` = ``"mpi"``; ``"jacobi"`` is relative value iteration with the aperiodicity
        transform (tau = 0.5), which needs a second value vector.
    relax : float
        Relaxation of the in-place sweeps, in (0, 1].
    eval_sweeps, check_every : int
    h0 : array or MatrixFreeSolution, optional
        Warm start, one value per layout state.
    threads : int, optional
        numba threads (default 1: numba's OpenMP layer does not survive a fork). With 2 or
        more, configurations are swept in parallel; the in-place sweeps are then asynchronous
        (iterates depend on timing; the certificate does not).
    domain : {"auto", "hull", "reachable"}
        Over which states the certificate is taken (module docstring): the interval hull
        (valid always, closes when :func:`drains_to_initial`), or the exact reachable set
        (a byte mask; ``"auto"`` uses it only when the hull's bracket might not close).
    stall_checks : int
        Switch to the Jacobi scheme when the width has not halved in this many checks.
    progress : bool
        One line on stderr per certificate pass (sweeps, bracket, relative width, time).
    on_interrupt : {"return", "raise"}
        On KeyboardInterrupt: certify the current h with one more pass and return it with
        status ``"interrupted"`` (default), or re-raise.
    tile_order : {"forward", "reverse"}
        Order of the in-place sweeps over the AoI tiles (forward, the default, needed 1.5x
        fewer sweeps than reverse on processes 1-4).
    extrapolate : bool
        One-mode extrapolation of the bias when the bracket shrinks at a steady rate
        (:class:`Extrapolator`; needs a second value vector, used only if it fits in memory).
    force : bool
        Skip the size guard (:func:`wncs_lp.models.guard.check_size` with
        ``method="matrix-free"``, which refuses a layout whose vectors would not fit).

    Returns
    -------
    MatrixFreeSolution
        ``method = "matrix-free"``; ``stats``: ``scheme``, ``threads``, ``domain``,
        ``n_states`` (layout), ``n_reachable`` (with a mask), ``sweeps``, ``eval_sweeps``,
        ``checks``, ``rel_gap``, ``bytes`` (the solve's arrays), ``seconds_setup``,
        ``fallback``, ``hull_closes`` and ``history``: one ``(sweeps, eval_sweeps, seconds, lo, hi)``
        per certificate pass.
    """
    t0 = time.perf_counter()
    if scheme not in SCHEMES:
        raise SolverError(f"unknown matrix-free scheme {scheme!r}; expected one of {', '.join(SCHEMES)}")
    if not (0.0 < relax <= 1.0):
        raise SolverError(f"relax must be in (0, 1], got {relax}")
    if max_iter < 1 or check_every < 1 or eval_sweeps < 0:
        raise SolverError("max_iter and check_every must be >= 1 and eval_sweeps >= 0")
    if on_interrupt not in ("return", "raise"):
        raise SolverError(f"on_interrupt must be 'return' or 'raise', got {on_interrupt!r}")
    load_kernels()
    system = as_system(scenario_or_system)
    if not force:
        from ...models.guard import check_size

        check_size(system.scenario, method="matrix-free", model=system.model)
    use_mask, closes = resolve_domain(system, domain)
    layout = BoxLayout.from_system(system, "hull")
    op = Operator.build(system, layout)
    n = layout.n_states
    mask = reachable_mask(system, layout) if use_mask else None
    sw = Sweeper(op, threads, mask, reverse=tile_order == "reverse")
    h = _initial_h(h0, n)
    pol = np.zeros(n, np.uint8)
    if int(system.n_actions.max()) > 255:  # pragma: no cover - the paper's models have <= 12
        raise SolverError("more than 255 actions in a configuration: the uint8 policy cannot hold them")
    if scheme == "auto":
        scheme = "mpi"
    cur = scheme
    h_out = np.empty(n) if cur == "jacobi" else None
    n_eval = eval_sweeps if scheme == "mpi" else 0
    t_setup = time.perf_counter() - t0
    _say(progress, f"[matrix-free] {n:,} states over {layout.n_configs} configurations"
         + (f" ({int(mask.sum()):,} reachable)" if mask is not None else "")
         + f", {_mb(matrix_free_bytes(n, vectors=2 if h_out is not None else 1, mask=mask is not None))}, "
         f"{sw.threads} thread(s), setup {t_setup:.2f}s")
    used = evals = checks = iters = 0
    shift = 0.0
    lo = hi = np.nan
    converged = False
    fallback = None
    interrupted = False
    history: list[tuple] = []
    ex = Extrapolator(n, extrapolate and scheme != "jacobi" and _second_vector_fits(n))
    vectors = 1 + (h_out is not None) + ex.enabled
    _say(progress, f"[matrix-free] {_mb(matrix_free_bytes(n, vectors=vectors, mask=mask is not None))} "
         f"with {vectors} value vector(s)")
    best_w, best_at = np.inf, 0
    tau_j = 0.5
    first = True
    warm = warm_start and ex.enabled
    try:
        while used < max_iter:
            if warm:
                # Jacobi sweeps until the bracket is within warm_rel (see matrix_free_evaluate)
                lo, hi = sw.all_actions(h, ex.prev, pol, None, 0, 2, True, tau_j, shift)
                used += 1
                checks += 1
                ex.prev -= ex.prev[0]
                h, ex.prev = ex.prev, h
                width, mid = hi - lo, 0.5 * (lo + hi)
                history.append((used, evals, time.perf_counter() - t0, lo, hi))
                shift = mid
                if width <= warm_rel * abs(mid) or used >= warm_max or used >= max_iter - 1:
                    warm = False
                    first = True
                    _say(progress, f"[matrix-free:jacobi] sweeps={used} lo={lo:.12g} hi={hi:.12g} "
                         f"rel={width / max(abs(mid), 1e-300):.3g} t={time.perf_counter() - t0:.1f}s (warm start)")
                continue
            if cur != "jacobi" and not first:
                todo = min(check_every, max(max_iter - used - 1, 0))
                for i in range(todo):
                    if i == todo - 1 and ex.want_save():
                        ex.save(h, iters)
                    sw.all_actions(h, None, pol, None, 0, 1, n_eval > 0, relax, shift)
                    used += 1
                    iters += 1
                    for _ in range(n_eval):
                        sw.fixed(h, None, pol, 1, relax, shift)
                        evals += 1
            first = False
            if cur == "jacobi":
                lo, hi = sw.all_actions(h, h_out, pol, None, 0, 2, True, tau_j, shift)
            else:
                lo, hi = sw.all_actions(h, None, pol, None, 0, 0, True, relax, shift)
            used += 1
            checks += 1
            width = hi - lo
            mid = 0.5 * (lo + hi)
            history.append((used, evals, time.perf_counter() - t0, lo, hi))
            _say(progress, f"[matrix-free:{cur}] sweeps={used} evals={evals} lo={lo:.12g} hi={hi:.12g} "
                 f"rel={width / max(abs(mid), 1e-300):.3g} t={time.perf_counter() - t0:.1f}s")
            if width_closed(lo, hi, 0.5 * (lo + hi), tol, atol=atol, cost_scale=op.cost_scale):
                converged = True
                break
            if cur != "jacobi":
                note = ex.step(h, iters, width)
                if note is not None:
                    _say(progress, f"[matrix-free] {note}")
                if ex.pending is not None or (note is not None and "undone" in note):
                    first = True  # certify the moved h before sweeping on
                    continue
            if width < 0.5 * best_w:
                best_w, best_at = width, checks
            elif cur != "jacobi" and checks - best_at >= stall_checks:
                fallback = f"{cur} stalled at relative width {width / max(abs(mid), 1e-300):.3g} after {used} sweeps"
                best_at = checks
                if _second_vector_fits(n):
                    cur = "jacobi"
                    h_out = np.empty(n)
                    vectors += 1
                    continue
                fallback += " (no memory for the Jacobi fallback's second vector: continuing)"
            shift = mid
            if cur == "jacobi" and used < max_iter:  # the budget's last pass keeps its (certified) h
                h_out -= h_out[0]
                h, h_out = h_out, h
    except KeyboardInterrupt:
        if on_interrupt == "raise":
            raise
        interrupted = True
        _say(progress, "[matrix-free] interrupted: certifying the current iterate")
        ex.pending = None
        lo, hi = sw.all_actions(h, None, pol, None, 0, 0, True, relax, shift)
        checks += 1
        converged = width_closed(lo, hi, 0.5 * (lo + hi), tol, atol=atol, cost_scale=op.cost_scale)
    ex.settle(h)
    h -= h[0]
    gain = 0.5 * (lo + hi)
    status = "optimal" if converged else ("interrupted" if interrupted else "max_iter")
    stats = {
        "scheme": scheme,
        "final_scheme": cur,
        "threads": sw.threads,
        "domain": "reachable" if mask is not None else "hull",
        "hull_closes": closes,
        "n_states": n,
        "n_reachable": int(mask.sum()) if mask is not None else None,
        "n_configs": layout.n_configs,
        "sweeps": used,
        "eval_sweeps": evals,
        "checks": checks,
        "relax": relax,
        "tol": tol,
        "span": hi - lo,
        "rel_gap": (hi - lo) / max(abs(gain), 1e-300),
        "converged": converged,
        "bytes": matrix_free_bytes(n, vectors=vectors, mask=mask is not None),
        "value_vectors": vectors,
        "seconds_setup": t_setup,
        "fallback": fallback,
        "history": history,
        "extrapolations": ex.count,
        "extrapolations_undone": ex.reverted,
    }
    return MatrixFreeSolution(method="matrix-free", status=status, gain=gain, gain_lower=lo, gain_upper=hi,
                              bias=h, policy=pol, occupation=None, iterations=used,
                              seconds=time.perf_counter() - t0, stats=stats, layout=layout, system=system,
                              mask=mask)


# ============================================================================ evaluation
def policy_table(system: System, layout: BoxLayout, policy: Any, *, batch: int = 1 << 21) -> np.ndarray:
    """(n,) uint8 local action of a deterministic ``policy`` at every layout state (``policy.act``
    called on batches of whole configurations)."""
    n = layout.n_states
    out = np.empty(n, np.uint8)
    nact = system.n_actions
    rng = np.random.default_rng(0)
    c = 0
    nC = layout.n_configs
    while c < nC:
        c1 = c + 1
        while c1 < nC and layout.off[c1 + 1] - layout.off[c] <= batch:
            c1 += 1
        taus = np.concatenate([layout.config_taus(i) for i in range(c, c1)])
        cfg = np.repeat(np.arange(c, c1, dtype=np.int64), np.diff(layout.off[c:c1 + 1]))
        j = np.asarray(policy.act(taus, cfg, rng), dtype=np.int64)
        if j.shape != cfg.shape or np.any(j < 0) or np.any(j >= nact[cfg]):
            raise PolicyError(f"policy {getattr(policy, 'name', policy)!r}: a local action index is out of range")
        out[layout.off[c]:layout.off[c1]] = j
        c = c1
    return out


def matrix_free_evaluate(
    scenario_or_system: Scenario | System,
    policy: Any,
    *,
    tol: float = VI_TOL,
    atol: float = 0.0,
    max_iter: int = 100_000,
    relax: float = 0.8,
    check_every: int = 5,
    h0: Any = None,
    threads: int | None = None,
    domain: str = "auto",
    stall_checks: int = 40,
    progress: bool = False,
    on_interrupt: str = "return",
    name: str | None = None,
    extrapolate: bool = True,
    warm_start: bool = True,
    warm_rel: float = 0.05,
    warm_max: int = 100,
    cost: Any = None,
) -> MatrixFreeEvaluation:
    """Exact average cost of a stationary policy, certified, without a transition matrix.

    Relaxed Gauss-Seidel sweeps of the fixed-policy operator
    (T_pi h)(s) = c(s) + sum_{s'} P_pi(s' | s) h(s'), and every ``check_every`` sweeps a pass
    computing ``lo = min (T_pi h - h) <= g_pi <= max (T_pi h - h) = hi`` on one fixed h over
    every layout state (or the exact reachable set, as in :func:`matrix_free_value_iteration`).
    If the width stalls, Jacobi sweeps with the aperiodicity transform take over.

    Parameters
    ----------
    policy : Policy, MatrixFreeSolution or array
        A deterministic :class:`~wncs_lp.policies.Policy` (``act`` is called once on every
        layout state), a tau-independent randomised one (anything with a ``probs`` table of
        action probabilities per configuration, e.g. the random policy: evaluated with those
        weights), a :class:`MatrixFreeSolution` (its policy), or an (n,) array of local
        action indices over the layout.
    cost : array, optional
        A separable per-slot cost c(s) = sum_k cost[k, tau_k - 1] instead of the MSE: an
        (N, max cap) table (entries past a process's cap are ignored). With
        :func:`cap_cost` it measures the time spent at the cap (:func:`matrix_free_cap_mass`).
    Other parameters as in :func:`matrix_free_value_iteration`.

    Returns
    -------
    MatrixFreeEvaluation
    """
    t0 = time.perf_counter()
    if not (0.0 < relax <= 1.0):
        raise SolverError(f"relax must be in (0, 1], got {relax}")
    if on_interrupt not in ("return", "raise"):
        raise SolverError(f"on_interrupt must be 'return' or 'raise', got {on_interrupt!r}")
    load_kernels()
    system = getattr(policy, "system", None)
    if not isinstance(system, System):
        system = as_system(scenario_or_system)
    use_mask, closes = resolve_domain(system, domain)
    layout = BoxLayout.from_system(system, "hull")
    n = layout.n_states
    W = None
    table = None
    if isinstance(policy, MatrixFreeSolution):
        table = policy.policy
        pname = name or "optimal"
    elif hasattr(policy, "table") and hasattr(policy, "layout"):  # a wncs_lp.policies.MatrixFreePolicy
        table = policy.table
        pname = name or policy.name
    elif hasattr(policy, "act"):  # any wncs_lp.policies.Policy (duck-typed: solvers sit below policies)
        pname = name or policy.name
        probs = getattr(policy, "probs", None)
        if probs is not None:
            W = np.ascontiguousarray(probs, dtype=float)
        elif policy.randomised:
            raise PolicyError(f"policy {pname}: matrix-free evaluation takes a deterministic policy or a "
                              "tau-independent randomised one (a probs table)")
        else:
            table = policy_table(system, layout, policy)
    else:
        pname = name or "array"
        table = np.asarray(policy)
        if table.shape != (n,) or not np.issubdtype(table.dtype, np.integer):
            raise PolicyError(f"a policy array must hold one local action index per layout state ({n})")
        cfg = np.repeat(np.arange(layout.n_configs), np.diff(layout.off))
        if np.any(table < 0) or np.any(table >= system.n_actions[cfg]):
            raise PolicyError("a local action index is out of range")
        table = table.astype(np.uint8)
    if table is not None and table.shape != (n,):
        raise PolicyError(f"the policy's table has {table.shape[0]} states, the layout {n}")
    op = Operator.build(system, layout)
    if cost is not None:
        op = with_cost(op, cost)
    mask = reachable_mask(system, layout) if use_mask else None
    sw = Sweeper(op, threads, mask)
    h = _initial_h(h0, n)
    t_setup = time.perf_counter() - t0
    _say(progress, f"[matrix-free eval {pname}] {n:,} states, setup (policy table) {t_setup:.2f}s")

    def sweep(h_, h_out_, write, rx, shift_):
        if table is None:
            return sw.all_actions(h_, h_out_, np.zeros(1, np.uint8), W, 1, write, False, rx, shift_)
        return sw.fixed(h_, h_out_, table, write, rx, shift_)

    used = checks = iters = 0
    shift = 0.0
    lo = hi = np.nan
    converged = interrupted = False
    history: list[tuple] = []
    ex = Extrapolator(n, extrapolate and _second_vector_fits(n))
    cur = "gs"
    fallback = None
    h_out = None
    best_w, best_at = np.inf, 0
    first = True
    warm = warm_start and ex.enabled
    try:
        while used < max_iter:
            if warm:
                # Jacobi sweeps (tau = 0.5) until the bracket is within warm_rel: their bounds
                # are monotone and a wrong shift only adds a constant, whereas in-place sweeps
                # started with the wide first bracket's midpoint as the gain distort h for
                # hundreds of sweeps (suboptimal policy, cap 12: 212 -> 173 sweeps)
                lo, hi = sweep(h, ex.prev, 2, 0.5, shift)
                used += 1
                checks += 1
                ex.prev -= ex.prev[0]
                h, ex.prev = ex.prev, h
                width, mid = hi - lo, 0.5 * (lo + hi)
                history.append((used, 0, time.perf_counter() - t0, lo, hi))
                shift = mid
                if width <= warm_rel * abs(mid) or used >= warm_max or used >= max_iter - 1:
                    warm = False
                    first = True
                    _say(progress, f"[matrix-free eval {pname}:jacobi] sweeps={used} lo={lo:.12g} hi={hi:.12g} "
                         f"rel={width / max(abs(mid), 1e-300):.3g} t={time.perf_counter() - t0:.1f}s (warm start)")
                continue
            if cur == "gs" and not first:
                todo = min(check_every, max(max_iter - used - 1, 0))
                for i in range(todo):
                    if i == todo - 1 and ex.want_save():
                        ex.save(h, iters)
                    sweep(h, None, 1, relax, shift)
                    used += 1
                    iters += 1
            first = False
            if cur == "jacobi":
                lo, hi = sweep(h, h_out, 2, 0.5, shift)
            else:
                lo, hi = sweep(h, None, 0, relax, shift)
            used += 1
            checks += 1
            width = hi - lo
            mid = 0.5 * (lo + hi)
            history.append((used, 0, time.perf_counter() - t0, lo, hi))
            _say(progress, f"[matrix-free eval {pname}:{cur}] sweeps={used} lo={lo:.12g} hi={hi:.12g} "
                 f"rel={width / max(abs(mid), 1e-300):.3g} t={time.perf_counter() - t0:.1f}s")
            if width_closed(lo, hi, 0.5 * (lo + hi), tol, atol=atol, cost_scale=op.cost_scale):
                converged = True
                break
            if cur == "gs":
                note = ex.step(h, iters, width)
                if note is not None:
                    _say(progress, f"[matrix-free eval {pname}] {note}")
                if ex.pending is not None:
                    first = True  # certify the extrapolated h before sweeping on
                    continue
                if note is not None and "undone" in note:
                    first = True
                    continue
            if width < 0.5 * best_w:
                best_w, best_at = width, checks
            elif cur == "gs" and checks - best_at >= stall_checks:
                fallback = f"gs stalled at relative width {width / max(abs(mid), 1e-300):.3g} after {used} sweeps"
                best_at = checks
                if _second_vector_fits(n):
                    cur = "jacobi"
                    h_out = np.empty(n)
                    continue
                fallback += " (no memory for the Jacobi fallback's second vector: continuing)"
            shift = mid
            if cur == "jacobi" and used < max_iter:  # the budget's last pass keeps its (certified) h
                h_out -= h_out[0]
                h, h_out = h_out, h
    except KeyboardInterrupt:
        if on_interrupt == "raise":
            raise
        interrupted = True
        ex.pending = None
        lo, hi = sweep(h, None, 0, relax, shift)
        converged = width_closed(lo, hi, 0.5 * (lo + hi), tol, atol=atol, cost_scale=op.cost_scale)
    ex.settle(h)
    h -= h[0]
    gain = 0.5 * (lo + hi)
    stats = {"threads": sw.threads, "domain": "reachable" if mask is not None else "hull", "hull_closes": closes,
             "n_states": n, "checks": checks, "relax": relax, "tol": tol, "rel_gap": (hi - lo) / max(abs(gain), 1e-300),
             "converged": converged, "seconds_setup": t_setup, "fallback": fallback,
             "randomised": W is not None, "history": history, "extrapolations": ex.count,
             "extrapolations_undone": ex.reverted}
    return MatrixFreeEvaluation(policy=pname,
                                status="optimal" if converged else ("interrupted" if interrupted else "max_iter"),
                                gain=gain, gain_lower=lo, gain_upper=hi, bias=h, iterations=used,
                                seconds=time.perf_counter() - t0, stats=stats)

