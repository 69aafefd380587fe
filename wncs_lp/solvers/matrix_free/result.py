"""The results of the matrix-free solver: a solution over a :class:`~.layout.BoxLayout`
(:class:`MatrixFreeSolution`, stored by :meth:`~MatrixFreeSolution.save` and read back by
:func:`load_solution`) and the certified evaluation of a fixed policy (:class:`MatrixFreeEvaluation`)."""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ...errors import PolicyError, SolverError
from ...models.system import System
from ...scenario import Scenario
from ..result import Solution
from .layout import BoxLayout

__all__ = ["MatrixFreeSolution", "MatrixFreeEvaluation", "load_solution", "as_system"]


def as_system(obj: Any) -> System:
    if isinstance(obj, System):
        return obj
    if isinstance(obj, Scenario):
        return System.from_scenario(obj)
    raise SolverError(f"expected a Scenario or a System, got {type(obj).__name__}")



@dataclass(frozen=True, eq=False)
class MatrixFreeSolution(Solution):
    """A :class:`Solution` of the matrix-free solver, over a :class:`BoxLayout`.

    Differences from the stored-matrix solvers' ``Solution`` (everything else is the same:
    ``gain`` is the midpoint of the certificate ``gain_lower <= g* <= gain_upper``):

    * ``bias`` is h over the *layout* states (normalised so that the first state, tau = 1 in
      the first initial configuration, is 0);
    * ``policy`` is one ``uint8`` per layout state: the **local action index** j of the greedy
      policy of ``bias`` (first minimiser), i.e. ``system.automaton.actions[c][j]``;
    * ``layout`` and ``system`` say what the states are; ``mask`` is the exact reachable set
      when the solve used one (``domain="reachable"``), else None.

    :meth:`on_mdp` gives the ordinary pair-index ``Solution`` on an enumerated MDP;
    :class:`wncs_lp.policies.MatrixFreePolicy` wraps it as a policy.
    """

    layout: BoxLayout | None = None
    system: System | None = None
    mask: np.ndarray | None = None

    def act(self, tau: np.ndarray, config_ids: np.ndarray) -> np.ndarray:
        """Local action indices at R states ((R, N) AoI values, (R,) configuration ids)."""
        idx = self.layout.index(tau, config_ids)
        if np.any(idx < 0):
            r = int(np.flatnonzero(idx < 0)[0])
            raise PolicyError(f"state tau={np.asarray(tau)[r].tolist()}, configuration {int(np.asarray(config_ids)[r])} "
                              "is outside the solved layout")
        return self.policy[idx].astype(np.int64)


    def layout_index_of(self, mdp) -> np.ndarray:
        """Layout index of every state of an enumerated MDP of the same scenario."""
        self.system.check_mdp(mdp)
        idx = self.layout.index(np.asarray(mdp.states.tau, np.int64), np.asarray(mdp.states.config, np.int64))
        if np.any(idx < 0):  # pragma: no cover - the layout contains the reachable set
            raise SolverError("internal error: a state of the MDP is outside the matrix-free layout")
        return idx

    def on_mdp(self, mdp) -> Solution:
        """The same solution on an enumerated MDP: ``policy`` as pair indices, ``bias`` on its
        states (h[0] = 0), the certificate unchanged (it holds for the MDP's reachable set)."""
        idx = self.layout_index_of(mdp)
        pol = mdp.pair_ptr[:-1] + self.policy[idx].astype(np.int64)
        h = self.bias[idx]
        return Solution(method=self.method, status=self.status, gain=self.gain, gain_lower=self.gain_lower,
                        gain_upper=self.gain_upper, bias=h - h[0], policy=pol, occupation=None,
                        iterations=self.iterations, seconds=self.seconds, stats=dict(self.stats))

    def actions(self, mdp) -> np.ndarray:
        return self.on_mdp(mdp).actions(mdp)

    def save(self, path, *, bias: bool = False) -> None:
        """Store the policy (and the bias with ``bias=True``: 8 bytes a state) as ``.npz``,
        atomically, readable by others (the umask's mode); :func:`load_solution` reads it back."""
        arrays = dict(policy=self.policy, lo=self.layout.lo, dims=self.layout.dims, caps=self.layout.caps)
        if bias:
            arrays["bias"] = self.bias
        meta = dict(method=self.method, status=self.status, gain=self.gain, gain_lower=self.gain_lower,
                    gain_upper=self.gain_upper, iterations=self.iterations, seconds=self.seconds,
                    domain=self.layout.domain, fingerprint=self.system.scenario.fingerprint())
        import io

        from ...files import atomic_write_bytes

        buf = io.BytesIO()  # written whole or not at all (an interrupt leaves no half file)
        np.savez(buf, meta=np.array(json.dumps(meta)), **arrays)
        atomic_write_bytes(path, buf.getvalue())


def load_solution(path, system_or_scenario: System | Scenario) -> MatrixFreeSolution:
    """Read a :meth:`MatrixFreeSolution.save` file back (checked against the scenario)."""
    system = as_system(system_or_scenario)
    with np.load(path, allow_pickle=False) as z:
        meta = json.loads(str(z["meta"]))
        if meta["fingerprint"] != system.scenario.fingerprint():
            raise PolicyError(f"{path}: saved for another scenario (fingerprint {meta['fingerprint']})")
        layout = BoxLayout.from_system(system, meta["domain"])
        if not (np.array_equal(layout.lo, z["lo"]) and np.array_equal(layout.dims, z["dims"])):
            raise PolicyError(f"{path}: the saved layout differs from this scenario's")
        bias = z["bias"] if "bias" in z.files else np.zeros(0)
        policy = z["policy"]
    return MatrixFreeSolution(method=meta["method"], status=meta["status"], gain=meta["gain"],
                              gain_lower=meta["gain_lower"], gain_upper=meta["gain_upper"], bias=bias,
                              policy=policy, iterations=meta["iterations"], seconds=meta["seconds"],
                              stats={"loaded_from": str(path)}, layout=layout, system=system)


@dataclass(frozen=True, eq=False)
class MatrixFreeEvaluation:
    """Exact (certified) average cost of a fixed policy, from :func:`matrix_free_evaluate`.

    ``gain_lower <= g_pi <= gain_upper`` for the long-run average cost g_pi of the policy from
    every state (the bracket min / max of T_pi h - h over the layout); ``gain`` is the midpoint.
    """

    policy: str
    status: str
    gain: float
    gain_lower: float
    gain_upper: float
    bias: np.ndarray
    iterations: int
    seconds: float
    stats: dict[str, Any] = field(default_factory=dict)

    @property
    def gap(self) -> float:
        return (self.gain_upper - self.gain_lower) / max(abs(self.gain), 1e-300)

    def summary(self) -> dict[str, Any]:
        out = {"policy": self.policy, "status": self.status, "gain": float(self.gain),
               "gain_lower": float(self.gain_lower), "gain_upper": float(self.gain_upper),
               "certificate_gap": float(self.gap), "iterations": int(self.iterations),
               "seconds": float(self.seconds)}
        for k, v in self.stats.items():
            if isinstance(v, (int, float, str, bool, np.integer, np.floating)) or v is None:
                out[k] = v.item() if isinstance(v, np.generic) else v
        return out

