r"""How much a result leans on the AoI cap: the stationary mass with some process at its cap.

The cap :math:`\hat\tau_k` is a truncation, not part of the paper's model: at the cap the AoI
stops growing and so does its cost. A policy whose chain spends a visible share of its time at
the cap is judged on a model that differs from the paper's where it matters. Every solve and
evaluation therefore reports, for the policy it returns,

.. math::

    m_k = \sum_s \pi(s)\,[\tau_k(s) = \hat\tau_k], \qquad
    m = \sum_s \pi(s)\,[\exists k:\ \tau_k(s) = \hat\tau_k],

and warns when :math:`m` exceeds :data:`CAP_MASS_WARN`. (Raising the cap is the remedy; while
every loop length :math:`U + T_k + D` fits under it, the optimal gain is non-decreasing in the
cap, so smaller caps give lower bounds on the untruncated optimum.)
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .errors import ModelError
from .mdp import MDP

__all__ = ["CapMass", "CapCount", "cap_mass", "policy_cap_mass", "CAP_MASS_WARN", "CAP_COUNT_ATOL"]

#: Above this stationary mass at the cap a result warns that it leans on the truncation.
CAP_MASS_WARN = 0.01

#: The certified width to which the commands and the cap study measure a :class:`CapCount`
#: (``atol`` of :func:`wncs_lp.solvers.matrix_free.matrix_free_cap_mass`). What reads it: the
#: shares printed to 0.01% (``solve``, ``evaluate``) or 0.001% (``capstudy``), the count to four
#: digits, and the comparison of the certified upper end with :data:`CAP_MASS_WARN` or a study's
#: ``mass_tol`` (so a wider bracket can only warn or go on sooner, never pass a mass wrongly).
#: 1e-6 is a tenth of the finest digit printed and 1e-4 of the threshold, so a finer certificate
#: changes nothing shown or decided, only costs passes (docs/matrix-free.md).
CAP_COUNT_ATOL = 1e-6


@dataclass(frozen=True)
class CapMass:
    """The stationary mass of a policy's chain with some AoI at its cap.

    Attributes
    ----------
    total : float
        Share of the long-run time with at least one process at its cap.
    per_process : tuple of float
        Share of the long-run time with process k at its cap.
    caps : tuple of int
    process_names : tuple of str
    threshold : float
        The warning threshold (:data:`CAP_MASS_WARN` by default).
    """

    total: float
    per_process: tuple[float, ...]
    caps: tuple[int, ...]
    process_names: tuple[str, ...]
    threshold: float = CAP_MASS_WARN

    @property
    def warn(self) -> bool:
        return self.total > self.threshold

    def message(self) -> str:
        """One sentence in words (a warning when above the threshold)."""
        per = ", ".join(f"{n} {m:.2%}" for n, m in zip(self.process_names, self.per_process))
        text = f"{self.total:.2%} of the long-run time has some AoI at its cap ({per}; caps {list(self.caps)})"
        if self.warn:
            text = (f"warning: {text}, above {self.threshold:.0%}: the result leans on the truncation; "
                    "raise tau_cap to see how it moves")
        return text

    def to_dict(self) -> dict[str, Any]:
        return {"total": float(self.total), "per_process": [float(m) for m in self.per_process],
                "caps": list(self.caps), "threshold": float(self.threshold), "warning": bool(self.warn)}


def cap_mass(mdp: MDP, law: np.ndarray, threshold: float = CAP_MASS_WARN) -> CapMass:
    """The mass at the cap of a state law (n,) or an occupation measure (L,).

    Raises
    ------
    ModelError
        The MDP has no decoded AoI states, or ``law`` has neither shape.
    """
    st = mdp.states
    if st is None or not hasattr(st, "tau"):
        raise ModelError("the mass at the cap needs an MDP with decoded AoI states (build it with wncs_lp.build)")
    w = np.asarray(law, dtype=float)
    if w.shape == (mdp.n_pairs,) and mdp.n_pairs != mdp.n_states:
        w = np.bincount(mdp.s_indices, weights=w, minlength=mdp.n_states)
    elif w.shape != (mdp.n_states,):
        raise ModelError(f"expected a state law of shape ({mdp.n_states},) or an occupation measure of shape "
                         f"({mdp.n_pairs},), got {w.shape}")
    tau = np.asarray(st.tau)
    caps = np.asarray(st.caps)
    at = tau == caps[None, :]
    per = tuple(float(w @ at[:, k]) for k in range(caps.size))
    model = getattr(st, "model", None)
    names = (tuple(p.name for p in model.scenario.processes) if model is not None
             else tuple(f"process-{k + 1}" for k in range(caps.size)))
    return CapMass(float(w @ at.any(axis=1)), per, tuple(int(c) for c in caps), names, threshold)


def policy_cap_mass(mdp: MDP, policy: np.ndarray, threshold: float = CAP_MASS_WARN) -> CapMass:
    """:func:`cap_mass` of the stationary law of a deterministic or randomised policy.

    A multichain policy gets the equal-weight mixture of its classes' laws
    (:class:`~wncs_lp.chain.PolicyChain`).
    """
    from .chain import PolicyChain

    return cap_mass(mdp, PolicyChain(mdp, policy).stationary, threshold)


@dataclass(frozen=True)
class CapCount:
    r"""How much a policy leans on the cap where its stationary law is out of reach (the
    matrix-free route): a certified bracket on the expected number of processes at their cap,
    :math:`E\#\{k: \tau_k = \hat\tau_k\} = \sum_k m_k`, from
    :func:`wncs_lp.solvers.matrix_free.matrix_free_cap_mass`.

    It brackets the share of time with *some* AoI at its cap, the :attr:`CapMass.total` of the
    enumerated route: :math:`\frac1N \sum_k m_k \le m \le \min(1, \sum_k m_k)`; the warning uses
    the upper end (:attr:`mass_upper`), so it never misses a mass above the threshold.

    Attributes
    ----------
    lower, upper : float
        Certified bracket on sum_k m_k.
    caps : tuple of int
    process_names : tuple of str
    threshold : float
    """

    lower: float
    upper: float
    caps: tuple[int, ...]
    process_names: tuple[str, ...]
    threshold: float = CAP_MASS_WARN

    @classmethod
    def of(cls, evaluation: Any, system: Any, threshold: float = CAP_MASS_WARN) -> "CapCount":
        """From a matrix-free evaluation under the cap cost and the system it ran on."""
        return cls(max(float(evaluation.gain_lower), 0.0), float(evaluation.gain_upper),
                   tuple(int(c) for c in system.caps), tuple(p.name for p in system.scenario.processes), threshold)

    @property
    def mass_lower(self) -> float:
        return self.lower / max(len(self.caps), 1)

    @property
    def mass_upper(self) -> float:
        return min(1.0, self.upper)

    @property
    def warn(self) -> bool:
        return self.mass_upper > self.threshold

    def message(self) -> str:
        """One sentence in words (a warning when the upper end is above the threshold)."""
        count = (f"{0.5 * (self.lower + self.upper):.4g}" if self.upper - self.lower <= 1e-4 * max(self.upper, 1e-300)
                 else f"{self.lower:.4g} to {self.upper:.4g}")
        text = (f"{self.mass_lower:.2%} to {self.mass_upper:.2%} of the long-run time has some AoI at its cap (the "
                f"expected number of processes at their caps is {count}, certified; caps {list(self.caps)})")
        if self.warn:
            text = (f"warning: {text}; possibly above {self.threshold:.0%}: the result may lean on the truncation; "
                    "raise tau_cap to see how it moves")
        return text

    @property
    def total(self) -> float:
        """The upper end of the mass with some AoI at its cap (what a study compares with its tolerance)."""
        return self.mass_upper

    def to_dict(self) -> dict[str, Any]:
        return {"expected_at_cap_lower": self.lower, "expected_at_cap_upper": self.upper,
                "total_lower": self.mass_lower, "total_upper": self.mass_upper, "caps": list(self.caps),
                "threshold": float(self.threshold), "warning": bool(self.warn)}
