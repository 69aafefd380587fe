"""An MDP in PRISM's explicit format (``wncs-lp export --format prism``).

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

Every file is written atomically (:func:`wncs_lp.files.atomic_write_bytes`): a reader sees the
old complete file or the new one, never a partial one.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import scipy.sparse as sp

from ..files import atomic_write_bytes
from ..mdp import MDP
from .rewards import reward_models, state_labels

__all__ = ["save_prism"]


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
    init, at_cap = state_labels(mdp)
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
