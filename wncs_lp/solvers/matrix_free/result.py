"""The results of the matrix-free solver: a solution over a :class:`~.layout.BoxLayout`
(:class:`MatrixFreeSolution`, stored by :meth:`~MatrixFreeSolution.save` and read back, checked,
by :func:`load_solution`) and the certified evaluation of a fixed policy (:class:`MatrixFreeEvaluation`).

Both carry the certificate, status and ``summary()`` of :class:`~wncs_lp.solvers.result.Solution`
(:class:`~wncs_lp.solvers.result.Certified`); neither is a ``Solution``, whose ``policy`` holds
pair indices of an enumerated MDP: :meth:`MatrixFreeSolution.on_mdp` gives that form.
"""
from __future__ import annotations

import io
import json
import math
import zipfile
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ...errors import PolicyError, SolverError
from ...models.system import System
from ...scenario import Scenario
from ...status import INACCURATE, UNVERIFIED, Status, of
from ..result import Certificate, Certified, Solution, certificate_rows, describe_array, stats_row, takes_bounds
from .layout import DOMAINS_OF_LAYOUT, BoxLayout, check_local_actions

__all__ = ["MatrixFreeSolution", "MatrixFreeEvaluation", "load_solution", "as_system"]


def as_system(obj: Any) -> System:
    """The :class:`~wncs_lp.models.system.System` of a scenario (or the system itself)."""
    if isinstance(obj, System):
        return obj
    if isinstance(obj, Scenario):
        return System.from_scenario(obj)
    raise SolverError(f"expected a Scenario or a System, got {type(obj).__name__}")


@takes_bounds
@dataclass(frozen=True, eq=False, repr=False)
class MatrixFreeSolution(Certified):
    """A certified solution of the matrix-free solver, over the states of a :class:`BoxLayout`.

    Printing one shows its scalars, scipy ``OptimizeResult`` style; :meth:`to_frame` gives the
    policy state by state.

    Attributes
    ----------
    method : str
        ``"matrix-free"``.
    status : Status
        As :attr:`Solution.status <wncs_lp.solvers.result.Solution.status>` (``status_code``,
        ``status_reason``, ``message``, ``ok`` likewise).
    gain : float
        The midpoint of the certificate.
    certificate : Certificate
        ``gain_lower <= g* <= gain_upper`` (min / max of T h - h over the layout, or over its
        reachable states); :attr:`gain_lower` / :attr:`gain_upper` read its ends.
    bias : (n,) float array
        h over the *layout* states, the one the certificate was computed on (h = 0 at the first
        state: tau = 1 in the first initial configuration). Empty for a solution loaded without it.
    local_actions : (n,) uint8 array
        The greedy policy of ``bias`` (first minimiser) as the **local action index** j of every
        layout state: ``system.automaton.actions[c][j]``, c the state's configuration (the MDP's
        action order within c).
    iterations : int
        Sweeps made (improvement and certificate sweeps).
    seconds : float
    stats : dict
        ``n_states``, ``threads``, ``domain``, ``history`` ... (:func:`matrix_free_value_iteration`).
    layout : BoxLayout
    system : System
        What the states are.
    mask : (n,) uint8 array or None
        The exact reachable set, when the solve used one (``domain="reachable"``).
    """

    method: str
    status: Status
    gain: float
    certificate: Certificate
    bias: np.ndarray
    local_actions: np.ndarray
    iterations: int
    seconds: float
    stats: dict[str, Any]
    layout: BoxLayout
    system: System
    mask: np.ndarray | None = None

    def act(self, tau: np.ndarray, config_ids: np.ndarray) -> np.ndarray:
        """Local action indices at states given as (R, N) AoI values and (R,) configuration ids."""
        idx = self.layout.index(tau, config_ids)
        if np.any(idx < 0):
            r = int(np.flatnonzero(idx < 0)[0])
            raise PolicyError(f"state tau={np.asarray(tau)[r].tolist()}, configuration {int(np.asarray(config_ids)[r])} "
                              "is outside the solved layout")
        return self.local_actions[idx].astype(np.int64)

    def layout_index_of(self, mdp) -> np.ndarray:
        """Layout index of every state of an enumerated MDP of the same scenario."""
        self.system.check_mdp(mdp)
        idx = self.layout.index(np.asarray(mdp.states.tau, np.int64), np.asarray(mdp.states.config, np.int64))
        if np.any(idx < 0):  # pragma: no cover - the layout contains the reachable set
            raise SolverError("internal error: a state of the MDP is outside the matrix-free layout")
        return idx

    def on_mdp(self, mdp) -> Solution:
        """The same solution on an enumerated MDP of the same scenario, as a :class:`Solution`:
        ``policy`` as pair indices, ``bias`` on its states (h[0] = 0), the certificate unchanged
        (it holds for the MDP's reachable set)."""
        idx = self.layout_index_of(mdp)
        pol = mdp.pair_ptr[:-1] + self.local_actions[idx].astype(np.int64)
        h = self.bias[idx] if self.bias.size else np.zeros(idx.size)
        return Solution(method=self.method, status=self.status, gain=self.gain, gain_lower=self.gain_lower,
                        gain_upper=self.gain_upper, bias=h - h[0], policy=pol, occupation=None,
                        iterations=self.iterations, seconds=self.seconds, stats=dict(self.stats),
                        pair_actions=mdp.a_indices)

    def save(self, path, *, bias: bool = False) -> None:
        """Store the policy (and the bias with ``bias=True``: 8 bytes a state) as ``.npz``,
        atomically, readable by others (the umask's mode); :func:`load_solution` reads it back."""
        from ...files import atomic_write_bytes

        arrays = dict(policy=self.local_actions, lo=self.layout.lo, dims=self.layout.dims, caps=self.layout.caps)
        if bias:
            arrays["bias"] = self.bias
        meta = dict(method=self.method, status=str(self.status), gain=self.gain, gain_lower=self.gain_lower,
                    gain_upper=self.gain_upper, iterations=self.iterations, seconds=self.seconds,
                    domain=self.layout.domain, fingerprint=self.system.scenario.fingerprint())
        meta["digest"] = solution_digest(meta, arrays)
        buf = io.BytesIO()  # written whole or not at all (an interrupt leaves no half file)
        np.savez(buf, meta=np.array(json.dumps(meta)), **arrays)
        atomic_write_bytes(path, buf.getvalue())

    def _display_head(self) -> str:
        return f"{type(self).__name__} of {self.local_actions.size:,} layout states by {self.method}"

    def _display_rows(self) -> list[tuple[str, str]]:
        return certificate_rows(self) + [
            ("bias", describe_array(self.bias, "floats") + " over the layout"),
            ("local_actions", describe_array(self.local_actions, "local action indices") + ", one per layout state"),
            ("layout", f"{self.layout.n_configs:,} configurations x AoI boxes ({self.layout.domain})"),
            ("mask", "None" if self.mask is None else f"{int(self.mask.sum()):,} reachable states"),
            stats_row(self.stats),
        ]

    def _frame_records(self):
        from ...tables import layout_columns

        return layout_columns(self.system, self.layout, self.local_actions, self.bias, self.mask)

    def to_frame(self):
        """The policy state by state over the layout, as a :class:`pandas.DataFrame`: ``state``,
        ``tau_1`` ... ``tau_N``, ``configuration``, ``action`` (its name), ``local_action``,
        ``bias`` (when kept) and ``reachable`` (when the solve knew the reachable set); at most
        :data:`wncs_lp.tables.MAX_TABLE_ROWS` rows (a layout at the paper's full scale is larger:
        :meth:`on_mdp` on a smaller cap, or the policy maps)."""
        return super().to_frame()


# ----------------------------------------------------------------------------- load
#: The arrays a saved solution must hold (``bias`` is optional).
SAVED_ARRAYS = ("meta", "policy", "lo", "dims", "caps")
#: The entries of a saved solution's ``meta``, with their types.
SAVED_META = {"method": str, "status": str, "gain": float, "gain_lower": float, "gain_upper": float,
              "iterations": int, "seconds": float, "domain": str, "fingerprint": str}
#: What a saved solution's digest binds together: the certificate and what it was computed for.
DIGEST_META = ("method", "status", "gain", "gain_lower", "gain_upper", "domain", "fingerprint")


def solution_digest(meta: dict[str, Any], arrays: dict[str, np.ndarray]) -> str:
    """sha256 of a saved solution's certificate (:data:`DIGEST_META`) and of every array (the
    policy, the layout, the bias when kept): :func:`load_solution` trusts the certificate only
    for the policy it was saved with."""
    import hashlib

    h = hashlib.sha256(json.dumps({k: meta[k] for k in DIGEST_META}, sort_keys=True).encode())
    for name in sorted(k for k in arrays if k != "meta"):
        a = np.ascontiguousarray(arrays[name])
        h.update(f"|{name}|{a.dtype.str}|{a.shape}|".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def load_solution(path, system_or_scenario: System | Scenario) -> MatrixFreeSolution:
    """Read a :meth:`MatrixFreeSolution.save` file back, checked against the scenario.

    Every array is checked before it is used: the layout (``lo``, ``dims``, ``caps``) must be
    the scenario's, the policy one integer per layout state within its configuration's actions,
    the bias (if stored) one finite float per layout state, and ``meta`` a well-formed record
    whose certificate is ordered. A file that fails any check -- truncated, not a zip, a key
    missing, a policy entry out of range -- is one :class:`~wncs_lp.errors.PolicyError` naming
    the file and what is wrong, never a solution (a policy read outside its tables would give a
    wrong certified gain).

    The certificate is bound to the policy (and bias) it was computed for by a digest written
    with them (:func:`solution_digest`): a file whose policy, bias or certificate was changed
    after it was saved -- even to other valid actions -- is refused. A file without a digest
    (saved before it was written) loads with the status ``inaccurate:unverified``: its numbers
    are shown, never trusted as a certificate.
    """
    system = as_system(system_or_scenario)
    arrays, meta = _read_npz(path)
    digest = meta.pop("digest", None)
    if meta["fingerprint"] != system.scenario.fingerprint():
        raise PolicyError(f"{path}: saved for another scenario (fingerprint {meta['fingerprint']})")
    if meta["domain"] not in DOMAINS_OF_LAYOUT:
        raise PolicyError(f"{path}: meta 'domain' must be one of {', '.join(DOMAINS_OF_LAYOUT)}, got {meta['domain']!r}")
    layout = BoxLayout.from_system(system, meta["domain"])
    for key in ("lo", "dims", "caps"):
        if not np.array_equal(getattr(layout, key), arrays[key]):
            raise PolicyError(f"{path}: the saved layout ({key}) differs from this scenario's")
    policy = check_local_actions(arrays["policy"], layout, system.n_actions, f"{path}: policy")
    bias = arrays.get("bias", np.zeros(0))
    if "bias" in arrays:
        if bias.shape != (layout.n_states,) or not np.issubdtype(bias.dtype, np.floating) or not np.all(np.isfinite(bias)):
            raise PolicyError(f"{path}: bias must be {layout.n_states:,} finite floats, one per layout state; "
                              f"got shape {bias.shape}, dtype {bias.dtype}")
    if digest is not None and digest != solution_digest(meta, arrays):  # after the checks that name an entry
        raise PolicyError(f"{path}: its policy, bias or certificate is not what was saved together (the digest "
                          "written with them does not match): the file was edited, and its certificate holds for "
                          "no policy in it; solve again, or evaluate this policy (matrix_free_evaluate)")
    status = meta["status"] if digest is not None else of(INACCURATE, UNVERIFIED)
    return MatrixFreeSolution(method=meta["method"], status=status, gain=meta["gain"],
                              gain_lower=meta["gain_lower"], gain_upper=meta["gain_upper"], bias=bias,
                              local_actions=policy, iterations=meta["iterations"], seconds=meta["seconds"],
                              stats={"loaded_from": str(path)}, layout=layout, system=system)


def _read_npz(path) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """The arrays and the checked ``meta`` of a saved solution; PolicyError if unreadable."""
    try:
        with np.load(path, allow_pickle=False) as z:
            missing = [k for k in SAVED_ARRAYS if k not in z.files]
            if missing:
                raise PolicyError(f"{path}: not a matrix-free solution file: no {', '.join(missing)} "
                                  f"(expected the arrays {', '.join(SAVED_ARRAYS)}, as MatrixFreeSolution.save writes)")
            arrays = {k: z[k] for k in z.files}
    except PolicyError:
        raise
    except (OSError, EOFError, ValueError, KeyError, zipfile.BadZipFile) as exc:
        raise PolicyError(f"{path}: cannot read it as a matrix-free solution file (.npz): "
                          f"{type(exc).__name__}: {exc}") from None
    return arrays, _check_meta(path, arrays["meta"])


def _check_meta(path, raw: np.ndarray) -> dict[str, Any]:
    try:
        meta = json.loads(str(raw))
    except (TypeError, ValueError) as exc:
        raise PolicyError(f"{path}: its meta record is not valid JSON ({exc})") from None
    if not isinstance(meta, dict):
        raise PolicyError(f"{path}: its meta record must be a JSON object, got {type(meta).__name__}")
    for key, kind in SAVED_META.items():
        v = meta.get(key)
        ok = (isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)) if kind is float else \
             (isinstance(v, int) and not isinstance(v, bool) and v >= 0) if kind is int else isinstance(v, str)
        if not ok:
            raise PolicyError(f"{path}: meta {key!r} must be {'a finite number' if kind is float else kind.__name__}"
                              f"{' >= 0' if kind is int else ''}, got {v!r}")
    if not meta["gain_lower"] <= meta["gain"] <= meta["gain_upper"]:
        raise PolicyError(f"{path}: meta gain {meta['gain']!r} is outside its certificate "
                          f"[{meta['gain_lower']!r}, {meta['gain_upper']!r}]")
    out = {k: (float(meta[k]) if kind is float else meta[k]) for k, kind in SAVED_META.items()}
    if "digest" in meta:
        if not isinstance(meta["digest"], str):
            raise PolicyError(f"{path}: meta 'digest' must be a string, got {meta['digest']!r}")
        out["digest"] = meta["digest"]
    return out


# ----------------------------------------------------------------------------- evaluation
@takes_bounds
@dataclass(frozen=True, eq=False, repr=False)
class MatrixFreeEvaluation(Certified):
    """Exact (certified) average cost of a fixed policy, from :func:`matrix_free_evaluate`.

    ``gain_lower <= g_pi <= gain_upper`` for the long-run average cost g_pi of the policy from
    every state (the bracket min / max of T_pi h - h over the layout); ``gain`` is the midpoint.
    Status, ``summary()`` and printout as :class:`MatrixFreeSolution`.

    Attributes
    ----------
    policy : str
        The name of the policy evaluated (``summary()["policy"]``).
    certificate : Certificate
        ``gain_lower <= g_pi <= gain_upper``.
    method : str
        ``"matrix-free-evaluate"``.
    """

    policy: str
    status: Status
    gain: float
    certificate: Certificate
    bias: np.ndarray
    iterations: int
    seconds: float
    stats: dict[str, Any] = field(default_factory=dict)
    method: str = "matrix-free-evaluate"

    def summary(self) -> dict[str, Any]:
        """JSON-ready scalars: the policy's name, then as :meth:`Certified.summary`."""
        return {"policy": self.policy, **super().summary()}

    def _display_head(self) -> str:
        return f"{type(self).__name__} of {self.bias.size:,} layout states by {self.method}"

    def _display_rows(self) -> list[tuple[str, str]]:
        return certificate_rows(self) + [("policy", self.policy),
                                         ("bias", describe_array(self.bias, "floats") + " over the layout"),
                                         stats_row(self.stats)]

    def _frame_records(self):
        """One row: the policy, its certified gain and certificate."""
        cols = ["policy", "gain", "gain_lower", "gain_upper", "gap", "status", "iterations", "seconds"]
        return cols, [{"policy": self.policy, "gain": self.gain, "gain_lower": self.gain_lower,
                       "gain_upper": self.gain_upper, "gap": self.gap, "status": str(self.status),
                       "iterations": int(self.iterations), "seconds": float(self.seconds)}]
