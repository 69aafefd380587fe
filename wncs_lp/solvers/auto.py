"""``method="auto"``: choose the LP or dynamic programming by size and need, and cross-check.

The rule (measured on the paper's instances, ``benchmarks/``):

* value iteration (:func:`~wncs_lp.solvers.dp.value_iteration`, certified to 1e-9) costs a
  few hundred sweeps of ~nnz(P) work: it is the default at every size;
* the occupation-measure LP (:func:`~wncs_lp.solvers.lp.solve_lp`) costs an interior-point
  factorisation per iteration; it is chosen when the caller needs what only it gives
  (``need="occupation"``: the LP's state-action frequencies, or ``need="lp"``) and the
  model is small enough (``lp_max_pairs``), or when the MDP is small enough that the LP is
  cheap anyway (``lp_small_pairs``) -- then its polished answer is an exactly evaluated
  policy whose gain is certified to round-off;
* whenever both are cheap (``cross_check_max_pairs``) the other method runs too and the
  two gains are compared: they agree when each lies in the other's certificate widened by
  ``cross_check_rtol`` (``stats["cross_check_agree"]``). A disagreement does not raise; the
  status becomes ``"inaccurate:cross_check"``.

The returned :class:`Solution` is the chosen method's, with ``method = "auto"``,
``stats["method_requested"] = "auto"``, ``stats["auto_choice"]`` (``"lp"`` or ``"vi"``: the
method whose answer it is) and ``stats["auto_reason"]``; ``seconds`` includes the cross-check (``stats["primary_seconds"]``
is the chosen method alone).
"""
from __future__ import annotations

from dataclasses import replace
from typing import Any, Callable

from ..errors import SolverError
from ..mdp import MDP
from ..progress import Progress, as_progress
from ..status import CROSS_CHECK, INACCURATE, of
from .result import Solution

__all__ = ["solve_auto", "LP_SMALL_PAIRS", "LP_MAX_PAIRS", "CROSS_CHECK_MAX_PAIRS"]

#: At or below this many pairs the LP is the primary method (fast and exactly polished).
LP_SMALL_PAIRS = 6_000
#: Above this many pairs the LP is not attempted even when asked for by ``need``.
LP_MAX_PAIRS = 250_000
#: At or below this many pairs both methods run and their gains are compared.
CROSS_CHECK_MAX_PAIRS = 30_000


def _agree(a: Solution, b: Solution, rtol: float) -> tuple[bool, float]:
    diff = abs(a.gain - b.gain)
    scale = max(abs(a.gain), abs(b.gain), 1e-300)
    slack = rtol * scale
    ok = (b.gain_lower - slack <= a.gain <= b.gain_upper + slack) and (a.gain_lower - slack <= b.gain <= a.gain_upper + slack)
    return bool(ok), diff / scale


def _choose(L: int, need: str | None, lp_small_pairs: int, lp_max_pairs: int) -> tuple[str, str]:
    """Which method answers (``"lp"`` or ``"vi"``) and why, by size and ``need``."""
    if need not in (None, "gain", "occupation", "lp"):
        raise SolverError(f"unknown need {need!r}; expected None, 'gain', 'occupation' or 'lp'")
    if need in ("occupation", "lp"):
        if L <= lp_max_pairs:
            return "lp", f"need={need} and {L} pairs <= {lp_max_pairs}"
        return "vi", f"need={need} but {L} pairs > {lp_max_pairs}: LP too large, value iteration instead"
    if L <= lp_small_pairs:
        return "lp", f"{L} pairs <= {lp_small_pairs}: the LP is cheap and its policy is exactly evaluated"
    return "vi", f"{L} pairs > {lp_small_pairs}: value iteration (certified) is faster than the LP"


def _options(lp_options: dict | None, vi_options: dict | None, h0: Any, tol: float | None, threads: int | None,
             prog: Progress) -> tuple[dict, dict]:
    """The keywords of the LP and of value iteration: the caller's, then auto's own where unset."""
    lp_kw = dict(lp_options or {})
    vi_kw = dict(vi_options or {})
    if h0 is not None:
        vi_kw.setdefault("h0", h0)
    if tol is not None:
        vi_kw.setdefault("tol", tol)
        lp_kw.setdefault("cert_rtol", tol)
    if threads is not None:
        vi_kw.setdefault("threads", threads)
    if prog.enabled:
        vi_kw.setdefault("progress", prog)
        lp_kw.setdefault("progress", prog)
    return lp_kw, vi_kw


def _cross_check(sol: Solution, run: Callable[[str], Solution], choice: str, rtol: float) -> dict[str, Any]:
    """Run the other method and compare the gains (a failure of the other one is reported, not raised)."""
    other = "vi" if choice == "lp" else "lp"
    try:
        o = run(other)
    except SolverError as exc:
        return dict(cross_check_method=other, cross_check_error=str(exc), cross_check_agree=None)
    ok, diff = _agree(sol, o, rtol)
    return dict(cross_check_method=other, cross_check_status=str(o.status), cross_check_gain=float(o.gain),
                cross_check_gain_lower=float(o.gain_lower), cross_check_gain_upper=float(o.gain_upper),
                cross_check_seconds=float(o.seconds), cross_check_rel_diff=float(diff), cross_check_agree=ok)


def _name(which: str) -> str:
    return "the LP" if which == "lp" else "value iteration"


def solve_auto(
    mdp: MDP,
    *,
    need: str | None = None,
    lp_small_pairs: int = LP_SMALL_PAIRS,
    lp_max_pairs: int = LP_MAX_PAIRS,
    cross_check_max_pairs: int = CROSS_CHECK_MAX_PAIRS,
    cross_check_rtol: float = 1e-8,
    lp_options: dict | None = None,
    vi_options: dict | None = None,
    h0: Any = None,
    tol: float | None = None,
    threads: int | None = None,
    progress: bool | Progress = False,
) -> Solution:
    """Solve with the LP or value iteration, chosen by size and ``need``; see the module doc.

    Parameters
    ----------
    mdp : MDP
    need : {None, "gain", "occupation", "lp"}
        ``None``/``"gain"``: the optimal gain and a policy (value iteration unless small);
        ``"occupation"`` or ``"lp"``: the LP's occupation measure is wanted (LP up to
        ``lp_max_pairs``, beyond that value iteration and a warning in ``auto_reason``).
    lp_small_pairs, lp_max_pairs, cross_check_max_pairs : int
        The size thresholds (in state-action pairs).
    cross_check_rtol : float
        Relative slack of the agreement test.
    lp_options, vi_options : dict, optional
        Keyword arguments of :func:`solve_lp` / :func:`value_iteration`.
    h0 : array, optional
        Warm start for value iteration.
    tol : float, optional
        The relative certificate width asked for: value iteration's ``tol`` and the LP's
        ``cert_rtol`` (unless ``vi_options`` / ``lp_options`` set them).
    threads : int, optional
        Value iteration's kernel threads (unless ``vi_options`` sets them; default: the solver's).
    progress : bool or Progress
        Show the choice, then the chosen method's progress and the cross-check's, on stderr.
    """
    import time

    from .dp import value_iteration
    from .lp import solve_lp

    t0 = time.perf_counter()
    L = mdp.n_pairs
    choice, reason = _choose(L, need, lp_small_pairs, lp_max_pairs)
    if choice == "lp":  # the route that fits: the LP only when its estimated peak does
        from ..models.guard import MEMORY_FRACTION, available_memory, lp_bytes

        need_bytes, room = lp_bytes(int(mdp.P.nnz), L), int(MEMORY_FRACTION * available_memory())
        if need_bytes > room:
            choice, reason = "vi", (f"{reason}; but the LP would need about {need_bytes / 2**30:.2f} GiB, over "
                                    f"{room / 2**30:.2f} GiB ({MEMORY_FRACTION:.0%} of the memory available): "
                                    "value iteration instead")
    prog = as_progress(progress)
    lp_kw, vi_kw = _options(lp_options, vi_options, h0, tol, threads, prog)

    def run(which: str) -> Solution:
        return solve_lp(mdp, **lp_kw) if which == "lp" else value_iteration(mdp, **vi_kw)

    prog.phase(f"[auto] {reason}: solving with {_name(choice)}")
    sol = run(choice)
    stats = dict(sol.stats)
    stats.update(method_requested="auto", auto_choice=choice, auto_reason=reason,
                 n_states=mdp.n_states, n_pairs=L)
    status = sol.status
    if L <= cross_check_max_pairs:
        prog.phase(f"[auto] {L} pairs <= {cross_check_max_pairs}: cross-checking with "
                   f"{_name('vi' if choice == 'lp' else 'lp')}")
        stats.update(_cross_check(sol, run, choice, cross_check_rtol))
        if stats["cross_check_agree"] is False and status.ok:
            status = of(INACCURATE, CROSS_CHECK)
    else:
        stats.update(cross_check_method=None, cross_check_agree=None,
                     cross_check_skipped=f"{L} pairs > {cross_check_max_pairs}")
    stats["primary_seconds"] = float(sol.seconds)
    return replace(sol, method="auto", status=status, stats=stats, seconds=time.perf_counter() - t0)
