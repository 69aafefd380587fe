r"""Confidence intervals for a long-run average estimated by simulation.

A time average of a Markov chain's cost is autocorrelated, so the slots of one run are not
independent samples. Two standard ways give an interval that holds anyway:

* **Independent replications** (:func:`replication_interval`). R runs from independent
  random numbers give R independent time averages :math:`Y_1, \dots, Y_R`; with
  :math:`\bar Y` their mean and :math:`s` their sample standard deviation (ddof = 1),

  .. math:: \bar Y \pm t_{R-1} \, s / \sqrt{R}

  (Student t with R - 1 degrees of freedom, one-sided or two-sided). Valid when each
  :math:`Y_r` is close to normal: runs long against the chain's autocorrelation time.

* **Batch means** (:func:`batch_means_interval`). Each run is cut into B consecutive batches;
  batches long against the autocorrelation time have nearly independent means
  :math:`Y_{rb}`, whose pooled within-run variance

  .. math:: \hat\sigma^2 = \frac{1}{R(B-1)} \sum_{r,b} (Y_{rb} - \bar Y_r)^2

  gives :math:`\bar Y \pm t_{R(B-1)} \hat\sigma / \sqrt{RB}`. Whether the batches are long
  enough is tested on the data: while the pooled lag-1 autocorrelation of the batch means,
  :math:`\hat\rho_1 = \sum_{r,b} (Y_{rb} - \bar Y_r)(Y_{r,b+1} - \bar Y_r) / \sum_{r,b} (Y_{rb} -
  \bar Y_r)^2`, exceeds :math:`z_{0.9} / \sqrt{R(B-1)}` (a one-sided 10% test of
  independence, as in Fishman's LBATCH rule), adjacent batches are merged in pairs; below
  :data:`MIN_BATCHES` batches the test has no power left and the interval says so
  (``independent = False``). It serves one long run (R = 1), where replications give nothing.

Both are normal-theory intervals: stated at their level, never certified. Both assume the runs
estimate one number: :func:`replications_agree` tests it (the runs' means against the spread of
their own batches), which catches runs too short for the chain and policies whose chain has
several recurrent classes (a run's average then depends on where it settles).

Two policies simulated with one seed share their random numbers; :func:`difference_interval`
pairs their replications for the interval of the difference of their averages (common random
numbers).

References: A. M. Law, *Simulation Modeling and Analysis*, 5th ed., ch. 9 (replication /
deletion and batch means); G. S. Fishman, *Discrete-Event Simulation* (2001), sec. 6.6
(LBATCH).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import stats as sps

from .display import Display, fmt
from .errors import WncsError

__all__ = ["ConfidenceInterval", "replication_interval", "control_variate_interval", "batch_means_interval",
           "replications_agree", "difference_interval", "SIDES",
           "MIN_BATCHES", "INDEPENDENCE_LEVEL", "AGREEMENT_LEVEL"]

#: ``"upper"``: (-inf, upper]; ``"lower"``: [lower, inf); ``"two-sided"``: [lower, upper].
SIDES = ("upper", "lower", "two-sided")
#: Fewest batches per run the batch-means merging goes down to.
MIN_BATCHES = 4
#: Level of the one-sided test of the batch means' lag-1 autocorrelation.
INDEPENDENCE_LEVEL = 0.10
#: p-value of :func:`replications_agree` below which a simulation's result warns.
AGREEMENT_LEVEL = 0.001


@dataclass(frozen=True, repr=False)
class ConfidenceInterval(Display):
    """A confidence interval for a long-run average (module docstring).

    Attributes
    ----------
    estimate : float
    lower, upper : float
        The interval's ends (-inf / +inf on the open side of a one-sided interval).
    confidence : float
        Its level, e.g. 0.95.
    side : {"upper", "lower", "two-sided"}
        ``"upper"``: the one-sided upper confidence limit ``upper`` (the estimate is below it).
    method : {"replications", "batch-means"}
    stderr : float
        Standard error of ``estimate``.
    df : int
        Degrees of freedom of the t quantile.
    samples : int
        Independent means the variance came from (replications, or runs x batches).
    batches : int
        Batches per run (1 for replications).
    lag1 : float
        The batch means' pooled lag-1 autocorrelation at the batches used (NaN for replications).
    independent : bool
        False when the batch means failed the independence test even at :data:`MIN_BATCHES`
        batches per run: the interval is then too narrow, and longer runs are needed.
    """

    estimate: float
    lower: float
    upper: float
    confidence: float
    side: str
    method: str
    stderr: float
    df: int
    samples: int
    batches: int = 1
    lag1: float = float("nan")
    independent: bool = True

    @property
    def half_width(self) -> float:
        """Distance from the estimate to the interval's finite end (the larger one if two-sided)."""
        return float(max(d for d in (self.upper - self.estimate, self.estimate - self.lower) if math.isfinite(d)))

    def contains(self, x: float) -> bool:
        return bool(self.lower <= x <= self.upper)

    def _display_head(self) -> str:
        what = {"upper": "one-sided upper", "lower": "one-sided lower", "two-sided": "two-sided"}[self.side]
        return f"{100 * self.confidence:g}% {what} confidence interval ({self.method})"

    def _display_rows(self) -> list[tuple[str, str]]:
        rows = [("estimate", fmt(self.estimate)), ("lower", fmt(self.lower)), ("upper", fmt(self.upper)),
                ("stderr", fmt(self.stderr, 4)), ("df", fmt(self.df)), ("samples", fmt(self.samples))]
        if self.method == "batch-means":
            rows += [("batches", fmt(self.batches)), ("lag1", fmt(self.lag1, 3)),
                     ("independent", fmt(self.independent))]
        return rows

    def to_dict(self) -> dict[str, Any]:
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


def _check(confidence: float, side: str) -> None:
    if not 0.5 <= confidence < 1:
        raise WncsError(f"confidence must be in [0.5, 1), got {confidence}")
    if side not in SIDES:
        raise WncsError(f"side must be one of {', '.join(SIDES)}; got {side!r}")


def _t_interval(estimate: float, se: float, df: int, confidence: float, side: str, method: str, samples: int,
                **extra: Any) -> ConfidenceInterval:
    t = float(sps.t.ppf(confidence if side != "two-sided" else (1 + confidence) / 2, df))
    lo = estimate - t * se if side != "upper" else -math.inf
    hi = estimate + t * se if side != "lower" else math.inf
    return ConfidenceInterval(float(estimate), float(lo), float(hi), float(confidence), side, method, float(se),
                              int(df), int(samples), **extra)


def replication_interval(means: Any, confidence: float = 0.95, side: str = "upper") -> ConfidenceInterval:
    """The t interval from R >= 2 independent replications' averages (module docstring).

    Parameters
    ----------
    means : (R,) array
        One time average per independent replication.
    confidence : float
    side : {"upper", "lower", "two-sided"}
    """
    _check(confidence, side)
    y = np.asarray(means, dtype=float).ravel()
    if y.size < 2:
        raise WncsError(f"an interval from replications needs at least 2 of them, got {y.size}")
    return _t_interval(float(y.mean()), float(y.std(ddof=1) / math.sqrt(y.size)), y.size - 1, confidence, side,
                       "replications", y.size)


def control_variate_interval(means: Any, controls: Any, confidence: float = 0.95, side: str = "upper"
                             ) -> tuple[ConfidenceInterval, float]:
    r"""The regression control-variate interval from R >= 3 independent replications.

    Each replication gives its plain average :math:`Y_r` and its control's average :math:`C_r`, a
    quantity of mean zero. The estimate is the intercept of the least-squares line of Y on C, read
    at C = 0:

    .. math:: \hat g = \bar Y + \hat\beta \bar C, \qquad
              \hat\beta = -\frac{\sum_r (Y_r - \bar Y)(C_r - \bar C)}{\sum_r (C_r - \bar C)^2},

    with standard error :math:`s_e \sqrt{1/R + \bar C^2 / \sum_r (C_r - \bar C)^2}`, :math:`s_e^2`
    the residual sum of squares over R - 2, and Student t with R - 2 degrees of freedom: exact
    when (Y_r, C_r) are jointly normal (S. S. Lavenberg and P. D. Welch, "A perspective on the use
    of control variables to increase the efficiency of Monte Carlo simulations", Management Sci.
    27(3), 1981). The fitted coefficient makes the most of the control and turns it off where it
    carries nothing: beta is 1 when the control is exact, near 0 when it is unrelated.

    Returns
    -------
    (ConfidenceInterval, beta)
        The interval (method ``"control variate"``) and the fitted coefficient.
    """
    _check(confidence, side)
    y = np.asarray(means, dtype=float).ravel()
    c = np.asarray(controls, dtype=float).ravel()
    R = y.size
    if c.size != R or R < 3:
        raise WncsError(f"a fitted control variate needs at least 3 replications and one control per "
                        f"replication; got {R} and {c.size}")
    dc = c - c.mean()
    scc = float(dc @ dc)
    if scc <= 0:  # a constant control carries nothing
        ci = replication_interval(y, confidence, side)
        return ci, 0.0
    beta = -float(dc @ (y - y.mean())) / scc
    resid = y + beta * c - float(np.mean(y + beta * c))
    s2 = float(resid @ resid) / (R - 2)
    se = math.sqrt(s2 * (1.0 / R + float(c.mean()) ** 2 / scc))
    return _t_interval(float(y.mean() + beta * c.mean()), se, R - 2, confidence, side, "control variate", R), beta


def _lag1(y: np.ndarray) -> float:
    """Pooled lag-1 autocorrelation of the rows of y about their own means."""
    d = y - y.mean(axis=1, keepdims=True)
    den = float((d * d).sum())
    return float((d[:, :-1] * d[:, 1:]).sum() / den) if den > 0 else 0.0


def _merge_pairs(sums: np.ndarray, sizes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Adjacent batches merged in pairs (an odd last batch joins the pair before it)."""
    B = sums.shape[1]
    ends = np.arange(2, B + 1, 2)
    ends[-1] = B
    starts = np.r_[0, ends[:-1]]
    return np.add.reduceat(sums, starts, axis=1), np.add.reduceat(sizes, starts)


def _independent_batches(sums: np.ndarray, sizes: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, bool]:
    """Batches merged in pairs while their lag-1 autocorrelation fails the test (module docstring):
    (sums, sizes, lag-1 autocorrelation, passed)."""
    z = float(sps.norm.ppf(1 - INDEPENDENCE_LEVEL))
    while True:
        R, B = sums.shape
        rho = _lag1(sums / sizes)
        independent = bool(rho <= z / math.sqrt(R * (B - 1)))
        if independent or B < 2 * MIN_BATCHES:
            return sums, sizes, rho, independent
        sums, sizes = _merge_pairs(sums, sizes)


def _batches(batch_sums: Any, sizes: Any) -> tuple[np.ndarray, np.ndarray]:
    sums = np.atleast_2d(np.asarray(batch_sums, dtype=float))
    sizes = np.asarray(sizes, dtype=float).ravel()
    if sums.shape[1] != sizes.size or sizes.size < 2 or np.any(sizes <= 0):
        raise WncsError(f"batch means need >= 2 batches of positive size per run and one size per batch; got "
                        f"sums of shape {sums.shape} and {sizes.size} sizes")
    return sums, sizes


def batch_means_interval(batch_sums: Any, sizes: Any, confidence: float = 0.95, side: str = "upper"
                         ) -> ConfidenceInterval:
    """The batch-means t interval of R runs cut into B batches each (module docstring).

    Parameters
    ----------
    batch_sums : (R, B) or (B,) array
        Per run and batch, the sum of the quantity over the batch's slots.
    sizes : (B,) array of int
        Slots per batch (the same in every run).
    confidence : float
    side : {"upper", "lower", "two-sided"}

    Returns
    -------
    ConfidenceInterval
        With ``batches`` the batches per run finally used, ``lag1`` their autocorrelation and
        ``independent`` whether they passed the independence test.
    """
    _check(confidence, side)
    sums, sizes, rho, independent = _independent_batches(*_batches(batch_sums, sizes))
    R, B = sums.shape
    y = sums / sizes
    estimate = float(sums.sum() / (R * sizes.sum()))
    d = y - y.mean(axis=1, keepdims=True)
    df = R * (B - 1)
    se = math.sqrt(float((d * d).sum()) / df / (R * B))
    return _t_interval(estimate, se, df, confidence, side, "batch-means", R * B, batches=B, lag1=rho,
                       independent=independent)


def replications_agree(batch_sums: Any, sizes: Any) -> float:
    r"""The p-value of the replications' agreement with their own batches (one-way analysis of variance).

    With the batches merged until independent (module docstring), under "every run has the same
    mean and independent batches" the ratio of the between-run mean square to the within-run one,
    :math:`F = B \sum_r (\bar Y_r - \bar Y)^2 / (R - 1) \,\big/\, \hat\sigma^2`, follows
    F(R - 1, R(B - 1)). A tiny p-value says the runs disagree more than their batches allow: runs
    too short for the chain's autocorrelation, or a chain with several recurrent classes whose
    runs settle in different ones (the long-run average then depends on the start, and no
    interval over the runs means anything). NaN for fewer than 2 runs.
    """
    sums, sizes, _, _ = _independent_batches(*_batches(batch_sums, sizes))
    R, B = sums.shape
    if R < 2:
        return math.nan
    y = sums / sizes
    ybar = y.mean(axis=1)
    within = float(((y - ybar[:, None]) ** 2).sum()) / (R * (B - 1))
    between = B * float(((ybar - ybar.mean()) ** 2).sum()) / (R - 1)
    if within <= 0:
        return 1.0 if between <= 0 else 0.0
    return float(sps.f.sf(between / within, R - 1, R * (B - 1)))


def difference_interval(a: Any, b: Any, paired: bool, confidence: float = 0.95, side: str = "two-sided"
                        ) -> ConfidenceInterval:
    """An interval for mean(a) - mean(b) from two sets of independent replications.

    ``paired=True``: replication r of ``a`` and of ``b`` share their random numbers (common random
    numbers: simulations with one seed), so the differences a_r - b_r are R independent samples
    and the interval is :func:`replication_interval` of them -- narrower than the unpaired one by
    the positive correlation the shared channel outcomes induce. ``paired=False``: Welch's
    interval, df by the Welch-Satterthwaite formula.
    """
    _check(confidence, side)
    a = np.asarray(a, dtype=float).ravel()
    b = np.asarray(b, dtype=float).ravel()
    if paired:
        if a.size != b.size:
            raise WncsError(f"paired replications need as many of each, got {a.size} and {b.size}")
        ci = replication_interval(a - b, confidence, side)
        return _t_interval(ci.estimate, ci.stderr, ci.df, confidence, side, "paired replications", ci.samples)
    if a.size < 2 or b.size < 2:
        raise WncsError(f"an unpaired difference needs at least 2 replications of each, got {a.size} and {b.size}")
    va, vb = a.var(ddof=1) / a.size, b.var(ddof=1) / b.size
    se = math.sqrt(va + vb)
    df = (va + vb) ** 2 / (va ** 2 / (a.size - 1) + vb ** 2 / (b.size - 1)) if se > 0 else a.size + b.size - 2
    return _t_interval(float(a.mean() - b.mean()), se, int(math.floor(df)), confidence, side, "welch",
                       a.size + b.size)
