"""The toolkit's own files: a built MDP, a policy and a solution as self-describing ``.npz``
files (and read back).

``wncs-lp export SCENARIO [--set k=v ...] --out FILE.npz`` and :func:`save_npz` write, and
:func:`load_npz` reads, this format (``numpy.load(FILE, allow_pickle=False)`` reads it too:
every entry is a plain numeric or unicode array).

Format ``wncs_lp.mdp-npz``, version 1
-------------------------------------
An average-cost MDP in state-action-pair form (one row per feasible pair, pairs sorted by
state; see :class:`wncs_lp.mdp.MDP`). With n states, L pairs, nnz transitions, N processes,
M servers (action components) and C configurations:

==========================  =================  ==================================================
key                         shape, dtype       meaning
==========================  =================  ==================================================
``format``                  (), str            ``"wncs_lp.mdp-npz"``
``format_version``          (), int64          ``1``
``n_states``                (), int64          n
``s_indices``               (L,), int64        state of pair l (nondecreasing)
``a_indices``               (L,), int64        action of pair l: a row of ``action_table``
``cost``                    (L,), float64      one-slot cost c(s, a)
``pair_ptr``                (n+1,), int64      pairs of state s are ``pair_ptr[s]:pair_ptr[s+1]``
``P_data``                  (nnz,), float64    transition matrix P (L x n) in CSR:
``P_indices``               (nnz,), int32/64   row l = P(. | s_l, a_l), entries
``P_indptr``                (L+1,), int32/64   ``P_indptr[l]:P_indptr[l+1]``, sorted columns
``action_table``            (A, M), int64      decoded actions; wncs: (a_1..a_M), 0 = nothing
                                               sent, k = process k; preemption: (a,) 0 = keep
                                               going, k = start process k. (0, 0) when absent
``tau``                     (n, N), int32      AoI of every process in every state (1..cap)
``config``                  (n,), int32        configuration id of every state
``config_descriptions``     (C,), unicode      readable description of each configuration
``caps``                    (N,), int64        the AoI caps tau_hat_k
``process_names``           (N,), unicode      process names ("" when unknown)
``scenario_fingerprint``    (), str            :meth:`Scenario.fingerprint` of the source
``scenario_source``         (), str            scenario file (or "<dict>")
``name``                    (), str            the MDP's name
``meta_json``               (), str            JSON of the MDP's scalar metadata
``policy`` (optional)       (L,), float64      pair probabilities pi(a_l | s_l) of a stationary
                                               policy (``save_npz(..., policy=...)``; absent
                                               otherwise; read by :func:`load_policy_npz`)
==========================  =================  ==================================================

The state numbering is the builder's: configuration by configuration, within one in C order
of the tau box; so state ``s`` is ``(tau[s], config[s])``. A state of an MDP without a decoded
state space (``mdp.states is None``) gets ``tau`` of shape (n, 0) and ``config`` all zero.

To build P with scipy: ``scipy.sparse.csr_matrix((P_data, P_indices, P_indptr), shape=(L, n))``.
The optimal gain g* solves ``g + h(s) = min_{l: s_l = s} [cost_l + (P h)_l]``.

Format ``wncs_lp.policy-npz``, version 1
----------------------------------------
A stationary policy, deterministic or randomised (e.g. a constrained solve's), on an MDP exported
as above or rebuilt from its scenario; :func:`save_policy_npz` writes it and
:func:`load_policy_npz` reads it (and also the optional ``policy`` entry of an MDP file). The
pair layout is stored so a reader can check the policy belongs to its MDP:

==========================  =================  ==================================================
key                         shape, dtype       meaning
==========================  =================  ==================================================
``format``                  (), str            ``"wncs_lp.policy-npz"``
``format_version``          (), int64          ``1``
``n_states``                (), int64          n
``pair_ptr``                (n+1,), int64      as in the MDP file
``a_indices``               (L,), int64        as in the MDP file
``policy``                  (L,), float64      pair probabilities pi(a_l | s_l): >= 0, sum 1 over
                                               ``pair_ptr[s]:pair_ptr[s+1]``; a deterministic
                                               policy is one-hot
``randomized_states``       (r,), int64        states with two or more pairs of positive
                                               probability
``scenario_fingerprint``    (), str            :meth:`Scenario.fingerprint` of the source
``name``                    (), str            the policy's name
``meta_json``               (), str            JSON of scalar metadata (``mdp_name``, ``source``,
                                               and what the caller passes in ``meta``)
==========================  =================  ==================================================

Solutions (``wncs-lp solve --out FILE.npz``)
--------------------------------------------
:func:`save_solution_npz` writes a solve's optimal policy *and* its bias as a
``wncs_lp.policy-npz`` file (so :func:`load_policy_npz` reads its policy) with these entries
added:

==========================  =================  ==================================================
key                         shape, dtype       meaning
==========================  =================  ==================================================
``bias``                    (n,), float64      the relative value function h (h[0] = 0) of the
                                               certificate; absent for a constrained solve
``sigma``                   (n,), int64        the action of every state (a row of
                                               ``action_table``; QuantEcon's ``sigma``); -1 in a
                                               state where a randomised policy mixes
``action_table``            (A, M), int64      as in the MDP file
``tau``, ``config``         (n, N), (n,)       as in the MDP file: state s is (tau[s], config[s])
``config_descriptions``     (C,), unicode      as in the MDP file
``gain``                    (), float64        the optimal average cost
``gain_lower``,             (), float64        the certificate gain_lower <= g* <= gain_upper
``gain_upper``
``status``, ``method``      (), str            the solve's status and method
==========================  =================  ==================================================

Read it with ``numpy.load(FILE)``: e.g. ``z["bias"][s]`` and ``z["action_table"][z["sigma"][s]]``
for state s.

Every file is written atomically (:func:`wncs_lp.files.atomic_write_bytes`): a reader sees the old
complete file or the new one, never a partial one.
"""
from __future__ import annotations

import io
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import scipy.sparse as sp

from ..errors import ExportError, ModelError, PolicyError
from ..files import atomic_write_bytes, json_ready, npz_array, npz_json, read_npz
from ..mdp import MAX_COST, MDP
from ..models.statespace import StateSpace
from ..policies.base import Policy, TablePolicy, system_of
from ..policies.mixed import MixedPolicy, pair_probabilities, randomised_states

__all__ = [
    "FORMAT",
    "FORMAT_VERSION",
    "POLICY_FORMAT",
    "POLICY_FORMAT_VERSION",
    "save_npz",
    "load_npz",
    "save_policy_npz",
    "load_policy_npz",
    "policy_from_file",
    "save_solution_npz",
    "ExportError",
]

FORMAT = "wncs_lp.mdp-npz"
FORMAT_VERSION = 1
POLICY_FORMAT = "wncs_lp.policy-npz"
POLICY_FORMAT_VERSION = 1


def _scalar_meta(meta: dict) -> dict:
    """The scalar entries of the MDP's metadata, JSON-ready."""
    return {k: v for k, v in json_ready(meta).items() if isinstance(v, (bool, int, float, str)) or v is None}


def _npz_path(path: str | Path) -> Path:
    path = Path(path)
    return path if path.suffix == ".npz" else path.with_name(path.name + ".npz")


def _write_npz(path: Path, arrays: dict[str, np.ndarray], compress: bool) -> Path:
    """``np.savez[_compressed]`` into memory, then one atomic write."""
    buf = io.BytesIO()
    (np.savez_compressed if compress else np.savez)(buf, **arrays)
    atomic_write_bytes(path, buf.getvalue())
    return path


def _probs_for(mdp: MDP, policy: Any) -> np.ndarray:
    try:
        return pair_probabilities(mdp, policy)
    except PolicyError as exc:
        raise ExportError(f"cannot export the policy: {exc}") from None


def save_npz(mdp: MDP, path: str | Path, *, scenario: Any = None, compress: bool = False,
             policy: Any = None) -> Path:
    """Write ``mdp`` in the ``wncs_lp.mdp-npz`` format (see the module docstring).

    Parameters
    ----------
    mdp : MDP
    path : file name (``.npz`` is appended when missing)
    scenario : Scenario, optional
        Source of the fingerprint and process names (else taken from ``mdp.meta``).
    compress : bool
        ``np.savez_compressed`` (smaller, slower) instead of ``np.savez``.
    policy : optional
        A stationary policy to store with the MDP as the ``policy`` entry (pair
        probabilities): (L,) float probabilities, (n,) int pair indices, a Solution or
        ConstrainedSolution, or a Policy (mapped with ``on_mdp``).

    Returns
    -------
    Path of the written file (written atomically).

    Raises
    ------
    ExportError
        ``policy`` is not a valid policy on ``mdp``.
    """
    path = _npz_path(path)
    probs = None if policy is None else _probs_for(mdp, policy)
    n = mdp.n_states
    st = mdp.states
    if st is not None and hasattr(st, "tau") and hasattr(st, "config"):
        tau = np.asarray(st.tau, dtype=np.int32)
        config = np.asarray(st.config, dtype=np.int32)
        describe = getattr(st, "describe_config", repr)
        descriptions = np.array([str(describe(c)) for c in st.configs], dtype=np.str_)
        caps = np.asarray(st.caps, dtype=np.int64)
    else:
        tau = np.zeros((n, 0), np.int32)
        config = np.zeros(n, np.int32)
        descriptions = np.array([""], dtype=np.str_)
        caps = np.zeros(0, np.int64)
    if scenario is not None:
        fingerprint = scenario.fingerprint()
        source = str(scenario.source)
        names = [p.name for p in scenario.processes]
    else:
        fingerprint = str(mdp.meta.get("fingerprint", ""))
        source = str(mdp.meta.get("source", ""))
        names = [""] * tau.shape[1]
    at = mdp.action_table
    action_table = np.zeros((0, 0), np.int64) if at is None else np.asarray(at, dtype=np.int64).reshape(len(at), -1)
    P = mdp.P.tocsr()
    arrays = dict(
        format=np.array(FORMAT),
        format_version=np.array(FORMAT_VERSION, dtype=np.int64),
        n_states=np.array(n, dtype=np.int64),
        s_indices=np.asarray(mdp.s_indices, dtype=np.int64),
        a_indices=np.asarray(mdp.a_indices, dtype=np.int64),
        cost=np.asarray(mdp.cost, dtype=np.float64),
        pair_ptr=np.asarray(mdp.pair_ptr, dtype=np.int64),
        P_data=np.asarray(P.data, dtype=np.float64),
        P_indices=P.indices,
        P_indptr=P.indptr,
        action_table=action_table,
        tau=tau,
        config=config,
        config_descriptions=descriptions,
        caps=caps,
        process_names=np.array(names, dtype=np.str_),
        scenario_fingerprint=np.array(fingerprint),
        scenario_source=np.array(source),
        name=np.array(str(mdp.name)),
        meta_json=np.array(json.dumps(_scalar_meta(mdp.meta), sort_keys=True)),
    )
    if probs is not None:
        arrays["policy"] = probs
    return _write_npz(path, arrays, compress)


def load_npz(path: str | Path, *, validate: bool = True) -> MDP:
    """Read a ``wncs_lp.mdp-npz`` file back into an :class:`MDP`.

    The returned MDP's ``states`` is a :class:`~wncs_lp.models.statespace.StateSpace` whose
    configurations are the stored description strings (so ``label``, ``find(tau, config_id)``
    and ``lookup_grid`` work); ``meta`` holds the stored metadata plus ``fingerprint``,
    ``source`` and ``format_version``.

    Every entry is checked against the layout of the module docstring (dtype, shape, range,
    finiteness: a column index is a state, a pair's state and action exist, the AoI lies in
    1..cap...), always; ``validate`` adds the MDP's own checks (rows of P summing to one, no
    state without an action).

    Raises
    ------
    ExportError
        Not a readable export of this format (missing, empty, truncated or corrupted, an
        unsupported version, a missing or malformed entry); the message names the file.
    """
    path = Path(path)
    d, n, meta = _read_mdp_arrays(path)
    version = int(d["format_version"])
    L = int(d["s_indices"].size)
    P = sp.csr_matrix((d["P_data"], d["P_indices"], d["P_indptr"]), shape=(L, n))
    meta.update(fingerprint=str(d["scenario_fingerprint"]), source=str(d["scenario_source"]),
                format_version=version, loaded_from=str(path))
    at = d["action_table"]
    action_table = None if at.size == 0 else at
    states = _state_space(path, d, n) if d["tau"].shape[1] > 0 else None
    try:
        return MDP.from_arrays(d["s_indices"], d["a_indices"], d["cost"], P, n, action_table=action_table,
                               states=states, name=str(d["name"]), meta=meta, check=validate)
    except ModelError as exc:  # the MDP's own checks (rows summing to one...): name the file
        raise ExportError(f"{path}: {exc}") from None


_MDP_KEYS = ("format", "format_version", "n_states", "s_indices", "a_indices", "cost", "pair_ptr", "P_data",
             "P_indices", "P_indptr", "action_table", "tau", "config", "config_descriptions", "caps",
             "process_names", "scenario_fingerprint", "scenario_source", "name", "meta_json")


def _format_of(path: Path, d: dict, formats: tuple[str, ...]) -> tuple[str, int]:
    """The file's ``format`` (one of ``formats``) and ``format_version``, checked."""
    fmt = str(d["format"]) if "format" in d and np.issubdtype(d["format"].dtype, np.str_) and d["format"].ndim == 0 \
        else None
    if fmt not in formats:
        raise ExportError(f"{path}: not a {' (or '.join(formats)}{')' if len(formats) > 1 else ''} file "
                          f"(keys: {', '.join(sorted(d)[:8])} ...)")
    if "format_version" not in d:
        raise ExportError(f"{path}: {fmt} file without a format_version entry")
    version = npz_array(d, "format_version", path, expect="i", shape=(), error=ExportError)
    known = POLICY_FORMAT_VERSION if fmt == POLICY_FORMAT else FORMAT_VERSION
    if int(version) != known:
        raise ExportError(f"{path}: {fmt} version {int(version)} is not supported (this reader knows {known})")
    return fmt, int(version)


def _pair_layout(path: Path, d: dict, n: int, L: int) -> None:
    """``pair_ptr`` (n + 1,) nondecreasing from 0 to L; ``a_indices`` (L,) integers >= 0."""
    ptr = npz_array(d, "pair_ptr", path, expect="i", shape=(n + 1,), lo=0, hi=L, error=ExportError)
    if ptr[0] != 0 or ptr[-1] != L or np.any(np.diff(ptr) < 0):
        raise ExportError(f"{path}: entry 'pair_ptr': expected a nondecreasing pointer from 0 to {L} (the pairs)")
    if np.any(np.diff(ptr) == 0):
        raise ExportError(f"{path}: entry 'pair_ptr': state {int(np.flatnonzero(np.diff(ptr) == 0)[0])} has no pair")
    npz_array(d, "a_indices", path, expect="i", shape=(L,), lo=0, error=ExportError)


def _read_mdp_arrays(path: Path) -> tuple[dict, int, dict]:
    """The arrays of a ``wncs_lp.mdp-npz`` file, every one checked; (arrays, n, meta)."""
    d = read_npz(path, what=f"a {FORMAT} file", error=ExportError)
    _format_of(path, d, (FORMAT,))
    missing = [k for k in _MDP_KEYS if k not in d]
    if missing:
        raise ExportError(f"{path}: {FORMAT} file without the entr{'ies' if len(missing) > 1 else 'y'} "
                          f"{', '.join(missing)}")
    n = int(npz_array(d, "n_states", path, expect="i", shape=(), lo=1, error=ExportError))
    s = npz_array(d, "s_indices", path, expect="i", ndim=1, lo=0, hi=n - 1, error=ExportError)
    L = s.size
    if np.any(np.diff(s) < 0):
        raise ExportError(f"{path}: entry 's_indices': expected pairs sorted by state (nondecreasing)")
    _pair_layout(path, d, n, L)
    if not np.array_equal(d["pair_ptr"], np.searchsorted(s, np.arange(n + 1))):
        raise ExportError(f"{path}: entries 'pair_ptr' and 's_indices' disagree on the pairs of each state")
    npz_array(d, "cost", path, expect="f", shape=(L,), lo=-MAX_COST, hi=MAX_COST, error=ExportError)
    indptr = npz_array(d, "P_indptr", path, expect="i", shape=(L + 1,), lo=0, error=ExportError)
    nnz = int(indptr[-1])
    if indptr[0] != 0 or np.any(np.diff(indptr) < 0):
        raise ExportError(f"{path}: entry 'P_indptr': expected a nondecreasing row pointer from 0")
    npz_array(d, "P_indices", path, expect="i", shape=(nnz,), lo=0, hi=n - 1, error=ExportError)
    npz_array(d, "P_data", path, expect="f", shape=(nnz,), lo=0.0, hi=1.0, error=ExportError)
    at = npz_array(d, "action_table", path, expect="i", ndim=2, error=ExportError)
    if at.size and int(d["a_indices"].max(initial=0)) >= at.shape[0]:
        raise ExportError(f"{path}: entry 'a_indices': action {int(d['a_indices'].max())} is not a row of "
                          f"'action_table' ({at.shape[0]} rows)")
    for key in ("scenario_fingerprint", "scenario_source", "name"):
        npz_array(d, key, path, expect="U", shape=(), error=ExportError)
    npz_array(d, "tau", path, expect="i", ndim=2, error=ExportError)
    meta = npz_json(d, "meta_json", path, error=ExportError)
    return d, n, meta


def _state_space(path: Path, d: dict, n: int) -> StateSpace:
    """The decoded states (tau, configuration) of an MDP file, checked."""
    tau = npz_array(d, "tau", path, expect="i", ndim=2, error=ExportError)
    N = tau.shape[1]
    caps_arr = npz_array(d, "caps", path, expect="i", shape=(N,), lo=1, error=ExportError)
    npz_array(d, "tau", path, expect="i", shape=(n, N), lo=1, error=ExportError)
    if np.any(tau > caps_arr[None, :]):
        raise ExportError(f"{path}: entry 'tau': an AoI beyond its cap (caps {caps_arr.tolist()})")
    configs = [str(x) for x in npz_array(d, "config_descriptions", path, expect="U", ndim=1, error=ExportError)]
    config = npz_array(d, "config", path, expect="i", shape=(n,), lo=0, hi=len(configs) - 1,
                       error=ExportError).astype(np.int32)
    npz_array(d, "process_names", path, expect="U", shape=(N,), error=ExportError)
    caps = tuple(int(c) for c in caps_arr)
    box = math.prod(caps)
    from ..models.guard import available_memory

    if len(configs) * box * 8 > available_memory() // 2:
        raise ExportError(f"{path}: its state decoding needs a lookup table of {len(configs):,} configurations x "
                          f"{box:,} AoI vectors, more than half the memory available")
    lookup = np.full((len(configs), box), -1, dtype=np.int64)
    flat = np.ravel_multi_index(tuple((tau - 1).T.astype(np.int64)), caps)
    lookup[config, flat] = np.arange(n, dtype=np.int64)
    if np.count_nonzero(lookup >= 0) != n:
        raise ExportError(f"{path}: entries 'tau' and 'config': two states share an AoI vector and configuration")
    tau = tau.astype(np.int32)
    tau.setflags(write=False)
    return StateSpace(tau, config, configs, caps, str, lookup)


def save_policy_npz(path: str | Path, mdp: MDP, policy: Any, *, name: str | None = None, scenario: Any = None,
                    meta: dict | None = None, compress: bool = False, _extra: dict | None = None) -> Path:
    """Write a stationary policy on ``mdp`` in the ``wncs_lp.policy-npz`` format (module docstring).

    Parameters
    ----------
    path : file name (``.npz`` is appended when missing)
    mdp : MDP
        The MDP the policy lives on.
    policy
        (L,) float pair probabilities, (n,) int pair indices (stored one-hot), a Solution or
        ConstrainedSolution (its ``.policy``), or a Policy such as
        :class:`~wncs_lp.policies.MixedPolicy` (mapped with ``on_mdp``).
    name : str, optional
        Default: the policy's ``name``, else its ``method``, else ``"policy"``.
    scenario : Scenario, optional
        Source of the fingerprint (else ``mdp.meta["fingerprint"]``).
    meta : dict, optional
        Extra scalar metadata (stored as JSON).

    Returns
    -------
    Path of the written file (written atomically).

    Raises
    ------
    ExportError
        ``policy`` is not a valid policy on ``mdp`` (the message names the bad state).
    """
    path = _npz_path(path)
    probs = _probs_for(mdp, policy)
    if name is None:
        name = getattr(policy, "name", None) or getattr(policy, "method", None) or "policy"
    fingerprint = scenario.fingerprint() if scenario is not None else str(mdp.meta.get("fingerprint", ""))
    info = {"mdp_name": str(mdp.name), "source": str(scenario.source if scenario is not None
                                                      else mdp.meta.get("source", ""))}
    info.update(_scalar_meta(meta or {}))
    arrays = dict(
        format=np.array(POLICY_FORMAT),
        format_version=np.array(POLICY_FORMAT_VERSION, dtype=np.int64),
        n_states=np.array(mdp.n_states, dtype=np.int64),
        pair_ptr=np.asarray(mdp.pair_ptr, dtype=np.int64),
        a_indices=np.asarray(mdp.a_indices, dtype=np.int64),
        policy=probs,
        randomized_states=randomised_states(mdp, probs).astype(np.int64),
        scenario_fingerprint=np.array(fingerprint),
        name=np.array(str(name)),
        meta_json=np.array(json.dumps(info, sort_keys=True)),
    )
    arrays.update(_extra or {})
    return _write_npz(path, arrays, compress)


def _state_arrays(mdp: MDP) -> dict[str, np.ndarray]:
    """``tau``, ``config``, ``config_descriptions`` and ``action_table`` as in the MDP file."""
    st = mdp.states
    if st is not None and hasattr(st, "tau") and hasattr(st, "config"):
        describe = getattr(st, "describe_config", repr)
        out = dict(tau=np.asarray(st.tau, dtype=np.int32), config=np.asarray(st.config, dtype=np.int32),
                   config_descriptions=np.array([str(describe(c)) for c in st.configs], dtype=np.str_))
    else:
        out = dict(tau=np.zeros((mdp.n_states, 0), np.int32), config=np.zeros(mdp.n_states, np.int32),
                   config_descriptions=np.array([""], dtype=np.str_))
    at = mdp.action_table
    out["action_table"] = (np.zeros((0, 0), np.int64) if at is None
                           else np.asarray(at, dtype=np.int64).reshape(len(at), -1))
    return out


def save_solution_npz(path: str | Path, mdp: MDP, solution: Any, *, scenario: Any = None,
                      compress: bool = False) -> Path:
    """Write a solve's policy and bias (``wncs-lp solve --out``): a ``wncs_lp.policy-npz`` file with
    ``bias``, ``sigma``, the state decoding and the certificate added (module docstring).

    Parameters
    ----------
    path : file name (``.npz`` is appended when missing)
    mdp : MDP
    solution : Solution or ConstrainedSolution
    scenario : Scenario, optional
        Source of the fingerprint.

    Returns
    -------
    Path of the written file (written atomically).
    """
    path = _npz_path(path)
    probs = _probs_for(mdp, solution)
    n = mdp.n_states
    # the action of each state: its most probable pair (the only one of a deterministic policy); -1 where it mixes
    best = np.maximum.reduceat(probs, mdp.pair_ptr[:-1])
    first = np.where(probs >= best[mdp.s_indices], np.arange(mdp.n_pairs), mdp.n_pairs)
    pair = np.minimum.reduceat(first, mdp.pair_ptr[:-1])
    sigma = np.asarray(mdp.a_indices, dtype=np.int64)[pair]
    sigma[randomised_states(mdp, probs)] = -1
    extra = dict(_state_arrays(mdp), sigma=sigma,
                 gain=np.array(float(solution.gain)), gain_lower=np.array(float(solution.gain_lower)),
                 gain_upper=np.array(float(solution.gain_upper)), status=np.array(str(solution.status)),
                 method=np.array(str(solution.method)))
    bias = getattr(solution, "bias", None)
    if bias is not None and np.shape(bias) == (n,):
        extra["bias"] = np.asarray(bias, dtype=np.float64)
    return save_policy_npz(path, mdp, probs, name=str(solution.method), scenario=scenario,
                           meta={"status": str(solution.status), "gain": float(solution.gain)},
                           compress=compress, _extra=extra)


def load_policy_npz(path: str | Path, mdp: MDP | None = None) -> np.ndarray:
    """Read the (L,) pair probabilities of a ``wncs_lp.policy-npz`` file, or the optional
    ``policy`` entry of a ``wncs_lp.mdp-npz`` file.

    Parameters
    ----------
    path : file name
    mdp : MDP, optional
        When given, the stored pair layout (``pair_ptr``, ``a_indices``) and, when both are
        known, the scenario fingerprint must match it, and the probabilities are validated on it.

    Returns
    -------
    (L,) float64 array
        Usable by :class:`~wncs_lp.policies.MixedPolicy`, :func:`wncs_lp.evaluate.evaluate`
        and the maps.

    Raises
    ------
    ExportError
        Not such a file (missing, empty, truncated, corrupted), an unsupported version, an MDP
        file without a policy, an entry of the wrong dtype, shape or range (probabilities in
        [0, 1] summing to one per state), or a policy that does not belong to ``mdp``.
    """
    path = Path(path)
    d = read_npz(path, what=f"a {POLICY_FORMAT} file", error=ExportError)
    fmt, _ = _format_of(path, d, (POLICY_FORMAT, FORMAT))
    if "policy" not in d:
        raise ExportError(f"{path}: this {fmt} file holds no policy (write one with save_npz(..., policy=...))")
    missing = [k for k in ("pair_ptr", "a_indices", "scenario_fingerprint", "n_states") if k not in d]
    if missing:
        raise ExportError(f"{path}: {fmt} file without the entr{'ies' if len(missing) > 1 else 'y'} "
                          f"{', '.join(missing)}")
    n = int(npz_array(d, "n_states", path, expect="i", shape=(), lo=1, error=ExportError))
    probs = npz_array(d, "policy", path, expect="f", ndim=1, lo=0.0, hi=1.0, error=ExportError).astype(np.float64)
    _pair_layout(path, d, n, probs.size)
    npz_array(d, "scenario_fingerprint", path, expect="U", shape=(), error=ExportError)
    sums = np.add.reduceat(probs, d["pair_ptr"][:-1])
    if np.any(np.abs(sums - 1.0) > 1e-6):
        s_bad = int(np.flatnonzero(np.abs(sums - 1.0) > 1e-6)[0])
        raise ExportError(f"{path}: entry 'policy': the probabilities of state {s_bad} sum to {sums[s_bad]:.6g}, "
                          "expected 1")
    if mdp is not None:
        if not (np.array_equal(d["pair_ptr"], mdp.pair_ptr) and np.array_equal(d["a_indices"], mdp.a_indices)):
            raise ExportError(f"{path}: the policy's pairs ({n} states, {probs.size} pairs) "
                              f"are not those of {mdp.name} ({mdp.n_states} states, {mdp.n_pairs} pairs)")
        fp, mine = str(d["scenario_fingerprint"]), str(mdp.meta.get("fingerprint", ""))
        if fp and mine and fp != mine:
            raise ExportError(f"{path}: the policy was saved for scenario {fp[:12]}..., not {mine[:12]}... "
                              f"({mdp.name})")
        probs = _probs_for(mdp, probs)
    return probs


def policy_from_file(path: Any, mdp: MDP, *, name: str | None = None) -> Policy:
    """The policy saved in a ``.npz`` file (``wncs-lp solve --out``, :func:`wncs_lp.export.save_policy_npz`),
    on the MDP it was saved for.

    Parameters
    ----------
    path : file name
    mdp : MDP
        The MDP of the scenario the policy was solved on (its pairs and fingerprint must match).
    name : str, optional
        Default: the file's stem.

    Returns
    -------
    Policy
        A deterministic :class:`TablePolicy` when every state has one pair of probability 1,
        else a :class:`MixedPolicy`.

    Raises
    ------
    ExportError
        Not such a file, or a policy of another MDP (the message says which).
    """
    probs = load_policy_npz(path, mdp)
    name = name or Path(path).stem
    pairs = np.flatnonzero(probs == 1.0)
    if pairs.size == mdp.n_states and np.array_equal(np.asarray(mdp.s_indices)[pairs], np.arange(mdp.n_states)):
        return TablePolicy(system_of(mdp), mdp, pairs, name=name)
    return MixedPolicy(system_of(mdp), mdp, probs, name=name)
