"""Export a built MDP to a self-describing ``.npz`` file (and read it back), to Storm's DRN and to
PRISM's explicit format.

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

Storm's explicit format (``wncs-lp export --format drn``)
---------------------------------------------------------
:func:`save_drn` writes the MDP in Storm's DiRect eNcoding (DRN), which ``storm --explicit-drn
FILE`` and ``stormpy.build_model_from_drn(FILE)`` load. The file holds

* a header: ``@type: MDP``, an empty ``@parameters`` line, ``@reward_models`` with the names of
  the reward models (:func:`reward_models`: ``cost``, then one per ``[[constraint]]`` table of
  the scenario), ``@nr_states`` n and ``@nr_choices`` L; before it, comment lines (``//``)
  naming the scenario, each reward model and what each action name means;
* ``@model``: every state as ``state <s> <labels>`` in the toolkit's numbering (the same as the
  ``.npz`` export's, so ``tau[s]``, ``config[s]`` of that file decode it), then each of its pairs
  as ``action a<k> [<cost>, <reward 2>, ...]`` (``k`` the row of the action table; the one-slot
  cost and the other reward models' values as the choice rewards, in the header's order)
  followed by one line ``<target> : <probability>`` per successor, in increasing target order.

Labels: ``init`` on the initial state (every AoI at its cap in the first initial configuration,
where the paper's chain starts; state 0 for an MDP without decoded states) and ``at_cap`` on the
states where some AoI is at its cap. The optimal average cost is the minimal long-run average
reward ``R{"cost"}min=? [LRA]``: ``storm --explicit-drn model.drn --prop 'R{"cost"}min=? [LRA]'``,
or in Python::

    model = stormpy.build_model_from_drn("model.drn")
    prop = stormpy.parse_properties('R{"cost"}min=? [LRA]')[0]
    g = stormpy.model_checking(model, prop).get_value(model.initial_states[0])

A constrained scenario's optimum is Storm's multi-objective query
(:func:`multi_objective_property`), e.g. ``multi(R{"cost"}min=? [LRA], R{"send_rate_remote"}<=0.2
[LRA])``. Storm's long-run-average solvers stop at their own precision (1e-6 relative by
default) and give no certificate. Numbers are written as Python's shortest round-trip decimals
(the exact doubles).

PRISM's explicit format (``wncs-lp export --format prism``)
-----------------------------------------------------------
:func:`save_prism` writes the files of PRISM's explicit model import (the PRISM manual, appendix
"Explicit Model Files"), for ``prism -importmodel NAME.all -mdp`` (or ``-importtrans NAME.tra
-importstates NAME.sta -importlabels NAME.lab -importstaterewards NAME.srew ...``):

===============  ================================================================================
file             content
===============  ================================================================================
``NAME.tra``     ``n L nnz``, then ``s k j p a<action>`` per transition: state s, its k-th choice
                 (pair ``pair_ptr[s] + k``), target j, probability p, action name as in the DRN
``NAME.sta``     ``(config,tau1,...,tauN)``, then ``s:(c,t1,...,tN)`` per state (the same
                 numbering, which is lexicographic in these values); ``(s)`` for an MDP without
                 decoded states
``NAME.lab``     ``0="init" 1="deadlock" 2="at_cap"``, then ``s: i j`` per labelled state
``NAME.srew``    one reward structure: ``# Reward structure "cost"``, ``# State rewards``, ``n m``,
                 then ``s r`` per nonzero state reward
``NAME.trew``    only when some reward depends on the action: ``# Reward structure "..."``,
                 ``# Transition rewards``, ``n L m``, then ``s k j r`` on every transition of a
                 choice with reward r (PRISM reads it as the reward of the choice)
===============  ================================================================================

With several reward models (a constrained scenario) they are ``NAME1.srew``, ``NAME2.srew``, ...
(and ``NAME1.trew``, ...), numbered in the order of :func:`reward_models` as PRISM's own export
does; a reward that is the same for all pairs of a state is a state reward, any other a choice
reward, and when any reward needs a ``.trew`` every reward structure gets both files (one of
them empty) so that PRISM pairs them by number with matching names.

What reads it: PRISM (its parser; note that PRISM does not compute long-run average rewards
of MDPs -- ``R{"cost"}min=? [ S ]`` is refused for MDPs -- so the average-cost optimum itself is
Storm's job, through the DRN). Storm's own "explicit" input (``storm --explicit``,
``stormpy.build_model_from_explicit``) is a different dialect (a model-type line in place of the
size line, ``#DECLARATION`` label files, one unnamed reward model) and does not read PRISM's
``.tra``; the tests read these files with a parser written from PRISM's manual and check them in
Storm through stormpy's sparse-model builder.

Every file is written atomically (:func:`wncs_lp.files.atomic_write_bytes`): a reader sees the old
complete file or the new one, never a partial one.
"""

from __future__ import annotations

import io
import json
import math
import re
from pathlib import Path
from typing import Any

import numpy as np
import scipy.sparse as sp

from .errors import ModelError, PolicyError, WncsError
from .files import atomic_write_bytes, json_ready, npz_array, npz_json, read_npz
from .mdp import MAX_COST, MDP
from .models.statespace import StateSpace
from .policies.base import Policy, TablePolicy, system_of
from .policies.mixed import MixedPolicy, pair_probabilities, randomised_states

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
    "save_drn",
    "save_prism",
    "reward_models",
    "constraint_reward_names",
    "multi_objective_property",
    "initial_state",
    "ExportError",
]

FORMAT = "wncs_lp.mdp-npz"
FORMAT_VERSION = 1
POLICY_FORMAT = "wncs_lp.policy-npz"
POLICY_FORMAT_VERSION = 1


class ExportError(WncsError):
    """A file is not a readable ``wncs_lp.mdp-npz`` export."""


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
    from .models.guard import available_memory

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


def initial_state(mdp: MDP) -> int:
    """The state a run of the system starts in: every AoI at its cap in the first initial
    configuration (0 for an MDP without a decoded state space or model)."""
    st = mdp.states
    model = getattr(st, "model", None)
    if st is not None and model is not None and hasattr(st, "find"):
        try:
            s = st.find(tuple(int(c) for c in st.caps), int(model.automaton.initial[0]))
        except (AttributeError, IndexError, TypeError, ValueError):
            s = -1
        if s >= 0:
            return int(s)
    return 0


def _action_comments(mdp: MDP, scenario: Any) -> list[str]:
    """Comment lines saying what each action name ``a<k>`` means (the names of the policy maps)."""
    at = mdp.action_table
    if at is None:
        return ["// action a<k>: action index k of the MDP"]
    rows = np.asarray(at, dtype=np.int64).reshape(len(at), -1)
    out = []
    for k, row in enumerate(rows):
        what = str(tuple(int(v) for v in row))
        if mdp.states is not None and getattr(mdp.states, "configs", None) is not None:
            try:
                from .policy_grids import action_name

                what = f"{action_name(mdp, k, scenario=scenario)} {what}"
            except Exception:  # a name is a courtesy: the decoded tuple always stands
                pass
        out.append(f"// action a{k}: {what}")
    return out


_NAME_CHARS = re.compile(r"[^A-Za-z0-9_]+")


def _reward_name(text: str) -> str:
    """An identifier both Storm's properties and PRISM's reward headers accept ([A-Za-z_][A-Za-z0-9_]*)."""
    name = _NAME_CHARS.sub("_", text).strip("_") or "reward"
    return name if not name[0].isdigit() else f"r_{name}"


def constraint_reward_names(scenario: Any) -> tuple[str, ...]:
    """The reward-model name of each ``[[constraint]]`` table of ``scenario``, in file order.

    A constraint's name is its quantity followed by the server and / or process it is about
    (``send_rate_remote``, ``aoi_process_1``), with every character outside ``[A-Za-z0-9_]``
    replaced by ``_``; a name already taken (``cost``, or an earlier constraint's) gets the
    suffix ``_c<j>`` (j the constraint's 1-based position).
    """
    taken, out = {"cost"}, []
    for j, spec in enumerate(getattr(scenario, "constraints", ()) or (), start=1):
        parts = [spec.quantity]
        if spec.server is not None:
            parts.append(scenario.servers[spec.server].name)
        if spec.process is not None:
            parts.append(scenario.processes[spec.process].name)
        name = _reward_name("_".join(parts))
        if name in taken:
            name = f"{name}_c{j}"
        taken.add(name)
        out.append(name)
    return tuple(out)


def reward_models(mdp: MDP, scenario: Any = None, rewards: dict[str, Any] | None = None) -> dict[str, np.ndarray]:
    """The reward models a DRN or PRISM export carries, each an (L,) per-pair vector.

    ``cost`` (the MDP's one-slot cost) first; then, when ``scenario`` has ``[[constraint]]``
    tables, each constraint's quantity d_l (:func:`wncs_lp.models.quantities.pair_values`, the
    vector whose long-run average the constraint bounds) under the name of
    :func:`constraint_reward_names`; then ``rewards`` (name -> (L,) values) as given.

    Raises
    ------
    ExportError
        A name that is not an identifier or is used twice, or values of the wrong shape, not
        finite or negative (Storm's and PRISM's parsers take non-negative rewards).
    """
    out: dict[str, np.ndarray] = {"cost": np.asarray(mdp.cost, dtype=np.float64)}
    specs = getattr(scenario, "constraints", ()) or ()
    if specs:
        from .models.quantities import pair_values

        for name, spec in zip(constraint_reward_names(scenario), specs):
            out[name] = np.asarray(pair_values(mdp, spec), dtype=np.float64)
    for name, values in (rewards or {}).items():
        if not isinstance(name, str) or _reward_name(name) != name:
            raise ExportError(f"reward model name {name!r}: expected an identifier ([A-Za-z_][A-Za-z0-9_]*)")
        if name in out:
            raise ExportError(f"reward model {name!r} is given twice (names taken: {', '.join(out)})")
        out[name] = np.asarray(values, dtype=np.float64)
    for name, v in out.items():
        if v.shape != (mdp.n_pairs,):
            raise ExportError(f"reward model {name!r}: expected {mdp.n_pairs} values (one per pair), got shape {v.shape}")
        if not np.all(np.isfinite(v)) or np.any(v < 0):
            raise ExportError(f"reward model {name!r}: values must be finite and >= 0 (pair {int(np.flatnonzero(~(v >= 0) | ~np.isfinite(v))[0])})")
    return out


def multi_objective_property(scenario: Any, *, direction: str = "min") -> str:
    """Storm's multi-objective query of a constrained scenario: the least long-run average cost
    subject to each ``[[constraint]]`` bound on its reward model's long-run average, e.g.
    ``multi(R{"cost"}min=? [LRA], R{"send_rate_remote"}<=0.2 [LRA])``.

    Its value is the constrained optimum that :func:`wncs_lp.solve` (``constraints=``)
    certifies (Storm's multi-objective engine lets the scheduler randomise, as the constrained
    optimum does).

    Raises
    ------
    ExportError
        The scenario has no ``[[constraint]]`` table.
    """
    specs = getattr(scenario, "constraints", ()) or ()
    if not specs:
        raise ExportError("the scenario has no [[constraint]] table: its optimum is R{\"cost\"}min=? [LRA]")
    terms = [f'R{{"cost"}}{direction}=? [LRA]']
    for name, spec in zip(constraint_reward_names(scenario), specs):
        if spec.max is not None:
            terms.append(f'R{{"{name}"}}<={float(spec.max)!r} [LRA]')
        if spec.min is not None:
            terms.append(f'R{{"{name}"}}>={float(spec.min)!r} [LRA]')
    return f"multi({', '.join(terms)})"


def _export_header(mdp: MDP, scenario: Any, fmt: str, names: list[str]) -> list[str]:
    """Comment lines (without the comment marker) shared by the DRN and PRISM exports."""
    source = str(scenario.source) if scenario is not None else str(mdp.meta.get("source", ""))
    fingerprint = scenario.fingerprint() if scenario is not None else str(mdp.meta.get("fingerprint", ""))
    lines = [
        f"Exported by wncs_lp (wncs-lp export --format {fmt}): an average-cost MDP; its optimal average",
        'cost is the minimal long-run average of the reward model "cost": R{"cost"}min=? [LRA] in Storm',
        f"scenario {source} (fingerprint {fingerprint}): {mdp.n_states} states, {mdp.n_pairs} choices, "
        f"{int(mdp.P.nnz)} transitions",
        "states are numbered as in the .npz export (wncs-lp export --format npz): tau[s], config[s]",
        f"reward models: {', '.join(names)}",
    ]
    specs = getattr(scenario, "constraints", ()) or ()
    for name, spec in zip(constraint_reward_names(scenario) if specs else (), specs):
        lines.append(f'reward model "{name}": the quantity of the constraint {spec.label or spec.quantity}')
    if specs:
        lines.append(f"the constrained optimum (Storm): {multi_objective_property(scenario)}")
    return lines


def _state_labels(mdp: MDP) -> tuple[int, np.ndarray]:
    """The initial state and the states where some AoI is at its cap (the exports' labels)."""
    st = mdp.states
    if st is not None and hasattr(st, "tau") and len(getattr(st, "caps", ())) > 0:
        at_cap = np.any(np.asarray(st.tau) >= np.asarray(st.caps)[None, :], axis=1)
    else:
        at_cap = np.zeros(mdp.n_states, bool)
    return initial_state(mdp), at_cap


def save_drn(mdp: MDP, path: str | Path, *, scenario: Any = None, rewards: dict[str, Any] | None = None) -> Path:
    """Write ``mdp`` in Storm's explicit DRN format (module docstring), atomically.

    Parameters
    ----------
    mdp : MDP
    path : file name (written as given)
    scenario : Scenario, optional
        Named in the header comments (with its fingerprint); also used to describe the actions.
        Its ``[[constraint]]`` tables become extra reward models (:func:`reward_models`).
    rewards : dict, optional
        More reward models, name -> (L,) non-negative per-pair values.

    Returns
    -------
    Path of the written file.
    """
    path = Path(path)
    models = reward_models(mdp, scenario, rewards)
    P = mdp.P.tocsr()
    if not P.has_sorted_indices:
        P = P.copy()
        P.sort_indices()
    n = mdp.n_states
    init, at_cap = _state_labels(mdp)
    labels = np.where(at_cap, " at_cap", "").astype(object)
    labels[init] = " init" + labels[init]
    head = [f"// {line}" for line in _export_header(mdp, scenario, "drn", list(models))]
    head += [*_action_comments(mdp, scenario), "@type: MDP", "@parameters", "", "@reward_models", " ".join(models),
             "@nr_states", str(n), "@nr_choices", str(mdp.n_pairs), "@model", ""]
    values = np.column_stack(list(models.values())).tolist()
    action = [f"\taction a{a} [{', '.join(repr(x) for x in r)}]\n" for a, r in zip(mdp.a_indices.tolist(), values)]
    rows = [f"\t\t{j} : {x!r}\n" for j, x in zip(P.indices.tolist(), P.data.tolist())]
    indptr = P.indptr.tolist()
    pair_ptr = mdp.pair_ptr.tolist()
    out = ["\n".join(head)]
    push = out.append
    for s in range(n):
        push(f"state {s}{labels[s]}\n")
        for l in range(pair_ptr[s], pair_ptr[s + 1]):
            push(action[l])
            push("".join(rows[indptr[l]:indptr[l + 1]]))
    atomic_write_bytes(path, "".join(out).encode("utf-8"))
    return path


def _prism_prefix(path_prefix: str | Path) -> Path:
    """``DIR/NAME`` from ``DIR/NAME``, ``DIR/NAME.tra`` or ``DIR/NAME.all``."""
    prefix = Path(path_prefix)
    return prefix.with_suffix("") if prefix.suffix in (".tra", ".all") else prefix


def _prism_tra(mdp: MDP, P: sp.csr_matrix) -> str:
    """PRISM's ``.tra`` of an MDP: ``n c m``, then ``s k j p a<action>`` per transition."""
    local = (np.arange(mdp.n_pairs) - mdp.pair_ptr[mdp.s_indices]).tolist()
    head = [f"{mdp.n_states} {mdp.n_pairs} {int(P.nnz)}\n"]
    lead = [f"{s} {k} " for s, k in zip(mdp.s_indices.tolist(), local)]
    act = [f" a{a}\n" for a in mdp.a_indices.tolist()]
    indptr, cols, vals = P.indptr.tolist(), P.indices.tolist(), P.data.tolist()
    body = [f"{lead[l]}{cols[i]} {vals[i]!r}{act[l]}" for l in range(mdp.n_pairs) for i in range(indptr[l], indptr[l + 1])]
    return "".join(head + body)


def _prism_sta(mdp: MDP) -> str:
    """PRISM's ``.sta``: ``(config,tau1,...,tauN)`` and one ``s:(c,t1,...,tN)`` line per state
    (``(s)`` and the state's own number for an MDP without decoded states)."""
    st = mdp.states
    if st is None or not hasattr(st, "tau") or np.asarray(st.tau).ndim != 2 or np.asarray(st.tau).shape[1] == 0:
        return "(s)\n" + "".join(f"{s}:({s})\n" for s in range(mdp.n_states))
    tau = np.asarray(st.tau, dtype=np.int64)
    values = np.column_stack([np.asarray(st.config, dtype=np.int64), tau]).tolist()
    names = ",".join(["config", *(f"tau{k + 1}" for k in range(tau.shape[1]))])
    return f"({names})\n" + "".join(f"{s}:({','.join(map(str, v))})\n" for s, v in enumerate(values))


def _prism_lab(mdp: MDP) -> str:
    """PRISM's ``.lab``: ``0="init" 1="deadlock" 2="at_cap"``, then ``s: i j`` per labelled state."""
    init, at_cap = _state_labels(mdp)
    lines = ['0="init" 1="deadlock" 2="at_cap"\n']
    for s in sorted(set(np.flatnonzero(at_cap).tolist()) | {init}):
        labels = (["0"] if s == init else []) + (["2"] if at_cap[s] else [])
        lines.append(f"{s}: {' '.join(labels)}\n")
    return "".join(lines)


def _prism_rewards(mdp: MDP, P: sp.csr_matrix, name: str, values: np.ndarray, choices: bool) -> tuple[str, str | None]:
    """One reward structure: the ``.srew`` text and, when ``choices``, the ``.trew`` text.

    A reward that is the same for every pair of a state goes into ``.srew`` (state rewards);
    otherwise into ``.trew`` as a choice reward: the same value on every transition of the choice,
    which PRISM reads as the reward of the choice. The other file of the pair is empty.
    """
    n = mdp.n_states
    first = values[mdp.pair_ptr[:-1]]
    state_only = bool(np.array_equal(first[mdp.s_indices], values))
    head = f'# Reward structure "{name}"\n'
    if state_only:
        nz = np.flatnonzero(first)
        srew = head + f"# State rewards\n{n} {nz.size}\n" + "".join(f"{s} {v!r}\n" for s, v in zip(nz.tolist(), first[nz].tolist()))
    else:
        srew = head + f"# State rewards\n{n} 0\n"
    if not choices:
        return srew, None
    if state_only:
        return srew, head + f"# Transition rewards\n{n} {mdp.n_pairs} 0\n"
    local = np.arange(mdp.n_pairs) - mdp.pair_ptr[mdp.s_indices]
    lines = []
    for l in np.flatnonzero(values).tolist():
        lead, v = f"{int(mdp.s_indices[l])} {int(local[l])} ", repr(float(values[l]))
        lines += [f"{lead}{j} {v}\n" for j in P.indices[P.indptr[l]:P.indptr[l + 1]].tolist()]
    return srew, head + f"# Transition rewards\n{n} {mdp.n_pairs} {len(lines)}\n" + "".join(lines)


def save_prism(mdp: MDP, path_prefix: str | Path, *, scenario: Any = None,
               rewards: dict[str, Any] | None = None) -> dict[str, Path]:
    """Write ``mdp`` in PRISM's explicit format (``.tra``, ``.sta``, ``.lab``, ``.srew``, ``.trew``).

    See the module docstring ("PRISM's explicit format") for the files and what reads them.

    Parameters
    ----------
    mdp : MDP
    path_prefix : ``DIR/NAME`` (a trailing ``.tra`` or ``.all`` is dropped)
        The files are ``DIR/NAME.tra``, ``.sta``, ``.lab`` and the reward files: ``NAME.srew``
        (and ``NAME.trew``) for the one reward model ``cost``; ``NAME1.srew``, ``NAME2.srew``, ...
        (and ``NAME1.trew``, ...) for several, in the order of :func:`reward_models`.
    scenario : Scenario, optional
        Its ``[[constraint]]`` tables become extra reward models (:func:`reward_models`).
    rewards : dict, optional
        More reward models, name -> (L,) non-negative per-pair values.

    Returns
    -------
    dict
        Extension (``"tra"``, ``"sta"``, ``"lab"``, ``"srew"``, ``"srew2"``, ... ``"trew"``, ...)
        -> path of the written file (each written atomically).
    """
    prefix = _prism_prefix(path_prefix)
    models = reward_models(mdp, scenario, rewards)
    P = mdp.P.tocsr().copy()
    P.eliminate_zeros()
    P.sort_indices()
    texts = {"tra": _prism_tra(mdp, P), "sta": _prism_sta(mdp), "lab": _prism_lab(mdp)}
    choices = any(not np.array_equal(v[mdp.pair_ptr[:-1]][mdp.s_indices], v) for v in models.values())
    numbered = len(models) > 1
    for r, (name, values) in enumerate(models.items(), start=1):
        srew, trew = _prism_rewards(mdp, P, name, values, choices)
        key = "" if r == 1 else str(r)
        texts[f"srew{key}"] = srew
        if trew is not None:
            texts[f"trew{key}"] = trew
    out = {}
    for key, text in texts.items():
        ext = key.rstrip("0123456789")
        number = (key[len(ext):] or "1") if numbered and ext in ("srew", "trew") else ""
        path = prefix.with_name(f"{prefix.name}{number}.{ext}")
        atomic_write_bytes(path, text.encode("utf-8"))
        out[key] = path
    return out


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
