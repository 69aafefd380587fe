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

__all__ = ["CapMass", "cap_mass", "policy_cap_mass", "CAP_MASS_WARN"]

#: Above this stationary mass at the cap a result warns that it leans on the truncation.
CAP_MASS_WARN = 0.01


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
