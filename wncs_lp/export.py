"""Export a built MDP to a self-describing ``.npz`` file, and read it back.

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
==========================  =================  ==================================================

The state numbering is the builder's: configuration by configuration, within one in C order
of the tau box; so state ``s`` is ``(tau[s], config[s])``. A state of an MDP without a decoded
state space (``mdp.states is None``) gets ``tau`` of shape (n, 0) and ``config`` all zero.

To build P with scipy: ``scipy.sparse.csr_matrix((P_data, P_indices, P_indptr), shape=(L, n))``.
The optimal gain g* solves ``g + h(s) = min_{l: s_l = s} [cost_l + (P h)_l]``.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import scipy.sparse as sp

from .errors import WncsError
from .files import json_ready
from .mdp import MDP
from .models.statespace import StateSpace

__all__ = ["FORMAT", "FORMAT_VERSION", "save_npz", "load_npz", "ExportError"]

FORMAT = "wncs_lp.mdp-npz"
FORMAT_VERSION = 1


class ExportError(WncsError):
    """A file is not a readable ``wncs_lp.mdp-npz`` export."""


def _scalar_meta(meta: dict) -> dict:
    """The scalar entries of the MDP's metadata, JSON-ready."""
    return {k: v for k, v in json_ready(meta).items() if isinstance(v, (bool, int, float, str)) or v is None}


def save_npz(mdp: MDP, path: str | Path, *, scenario: Any = None, compress: bool = False) -> Path:
    """Write ``mdp`` in the ``wncs_lp.mdp-npz`` format (see the module docstring).

    Parameters
    ----------
    mdp : MDP
    path : file name (``.npz`` is appended by numpy when missing)
    scenario : Scenario, optional
        Source of the fingerprint and process names (else taken from ``mdp.meta``).
    compress : bool
        ``np.savez_compressed`` (smaller, slower) instead of ``np.savez``.

    Returns
    -------
    Path of the written file.
    """
    path = Path(path)
    if path.suffix != ".npz":
        path = path.with_name(path.name + ".npz")
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
    path.parent.mkdir(parents=True, exist_ok=True)
    (np.savez_compressed if compress else np.savez)(path, **arrays)
    return path


def load_npz(path: str | Path, *, validate: bool = True) -> MDP:
    """Read a ``wncs_lp.mdp-npz`` file back into an :class:`MDP`.

    The returned MDP's ``states`` is a :class:`~wncs_lp.models.statespace.StateSpace` whose
    configurations are the stored description strings (so ``label``, ``find(tau, config_id)``
    and ``lookup_grid`` work); ``meta`` holds the stored metadata plus ``fingerprint``,
    ``source`` and ``format_version``.

    Raises
    ------
    ExportError
        Not an export of this format, or an unsupported version.
    """
    path = Path(path)
    try:
        z = np.load(path, allow_pickle=False)
    except (OSError, ValueError) as exc:
        raise ExportError(f"{path}: not a readable .npz file ({exc})") from exc
    with z:
        if "format" not in z.files or str(z["format"]) != FORMAT:
            raise ExportError(f"{path}: not a {FORMAT} file (keys: {', '.join(sorted(z.files)[:8])} ...)")
        version = int(z["format_version"])
        if version != FORMAT_VERSION:
            raise ExportError(f"{path}: format version {version} is not supported (this reader knows {FORMAT_VERSION})")
        d = {k: z[k] for k in z.files}
    n = int(d["n_states"])
    L = int(d["s_indices"].size)
    P = sp.csr_matrix((d["P_data"], d["P_indices"], d["P_indptr"]), shape=(L, n))
    meta = json.loads(str(d["meta_json"]))
    meta.update(fingerprint=str(d["scenario_fingerprint"]), source=str(d["scenario_source"]),
                format_version=version, loaded_from=str(path))
    at = d["action_table"]
    action_table = None if at.size == 0 else at
    states = None
    tau = d["tau"]
    if tau.shape[1] > 0:
        caps = tuple(int(c) for c in d["caps"])
        configs = [str(x) for x in d["config_descriptions"]]
        config = d["config"].astype(np.int32)
        box = int(np.prod(caps))
        lookup = np.full((len(configs), box), -1, dtype=np.int64)
        flat = np.ravel_multi_index(tuple((tau - 1).T.astype(np.int64)), caps)
        lookup[config, flat] = np.arange(n, dtype=np.int64)
        tau = tau.astype(np.int32)
        tau.setflags(write=False)
        states = StateSpace(tau, config, configs, caps, str, lookup)
    return MDP.from_arrays(d["s_indices"], d["a_indices"], d["cost"], P, n, action_table=action_table,
                           states=states, name=str(d["name"]), meta=meta, check=validate)
