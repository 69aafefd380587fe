"""Plain readers of the model files other tools read, written from those tools' own format
descriptions (never from the toolkit's writers), and Storm models built from what they read.

* :func:`parse_prism` -- PRISM's explicit files (PRISM manual, appendix "Explicit Model Files"):
  ``.tra`` ("n c m", then "i k j x [a]"), ``.sta``, ``.lab``, ``.srew`` / ``.trew`` with the
  optional ``# Reward structure "name"`` header, found as PRISM's ``-importmodel NAME.all`` finds
  them (``NAME.srew``, else ``NAME1.srew``, ``NAME2.srew``, ...), paired by number.
* :func:`parse_drn` -- Storm's DRN for MDPs with any number of reward models.
* :func:`storm_mdp`, :func:`storm_dtmc` -- a stormpy sparse model from arrays, through stormpy's
  storage builders (``SparseMatrixBuilder``, ``SparseRewardModel``, ``SparseModelComponents``).
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import scipy.sparse as sp

__all__ = ["parse_prism", "parse_drn", "storm_mdp", "storm_dtmc"]


def _data_lines(text: str) -> list[str]:
    return [ln for ln in text.splitlines() if ln.strip() and not ln.startswith("#")]


def _reward_files(prefix: Path, ext: str) -> list[Path]:
    single = prefix.with_name(f"{prefix.name}.{ext}")
    if single.exists():
        return [single]
    out, i = [], 1
    while (f := prefix.with_name(f"{prefix.name}{i}.{ext}")).exists():
        out.append(f)
        i += 1
    return out


def _reward_name(text: str) -> str | None:
    for ln in text.splitlines():
        if not ln.startswith("#"):
            return None
        m = re.fullmatch(r'# Reward structure "([_a-zA-Z0-9]*)"', ln)
        if m:
            return m.group(1)
    return None


def _parse_tra(text: str) -> dict:
    lines = _data_lines(text)
    n, c, m = (int(x) for x in lines[0].split())
    s_of, actions, rows, cols, vals = [], [], [], [], []
    last = None
    for ln in lines[1:]:
        parts = ln.split()
        s, k, j, x = int(parts[0]), int(parts[1]), int(parts[2]), float(parts[3])
        if (s, k) != last:
            assert last is None or (s, k) > last, "states and choices must ascend"
            assert k == (last[1] + 1 if last and last[0] == s else 0), "choices of a state are numbered 0, 1, ..."
            s_of.append(s)
            actions.append(parts[4] if len(parts) > 4 else "")
            last = (s, k)
        else:
            assert actions[-1] == (parts[4] if len(parts) > 4 else ""), "one action label per choice"
        rows.append(len(s_of) - 1)
        cols.append(j)
        vals.append(x)
    assert len(s_of) == c and len(vals) == m and max(s_of) == n - 1
    P = sp.csr_matrix((vals, (rows, cols)), shape=(c, n))
    return dict(n=n, s_indices=np.array(s_of), actions=actions, P=P)


def _parse_rewards(prefix: Path, n: int, s_indices: np.ndarray, ptr: np.ndarray) -> dict[str, np.ndarray]:
    """name -> (L,) per-choice reward (state reward + choice reward), pairing srew i with trew i."""
    srews, trews = _reward_files(prefix, "srew"), _reward_files(prefix, "trew")
    out = {}
    for r in range(max(len(srews), len(trews))):
        total = np.zeros(s_indices.size)
        names = set()
        if r < len(srews):
            text = srews[r].read_text()
            names.add(_reward_name(text))
            lines = _data_lines(text)
            n_file, m = (int(x) for x in lines[0].split())
            assert n_file == n and len(lines) - 1 == m
            state = np.zeros(n)
            for ln in lines[1:]:
                s, v = ln.split()
                state[int(s)] = float(v)
            total += state[s_indices]
        if r < len(trews):
            text = trews[r].read_text()
            names.add(_reward_name(text))
            lines = _data_lines(text)
            n_file, c, m = (int(x) for x in lines[0].split())
            assert n_file == n and c == s_indices.size and len(lines) - 1 == m
            choice = {}
            for ln in lines[1:]:
                s, k, _, v = ln.split()
                key = ptr[int(s)] + int(k)
                assert choice.setdefault(key, float(v)) == float(v), "one reward per choice"
            for key, v in choice.items():
                total[key] += v
        assert len(names) == 1, f"reward structure {r + 1}: state and transition reward names differ: {names}"
        out[names.pop()] = total
    return out


def parse_prism(prefix: str | Path) -> dict:
    """Read ``prefix.tra``, ``.sta``, ``.lab`` and the reward files.

    Returns
    -------
    dict with ``n``, ``s_indices``, ``actions`` (label per choice), ``P`` (choices x n CSR),
    ``variables``, ``values`` (n, v) int array of the .sta, ``labels`` (name -> set of states)
    and ``rewards`` (name -> (choices,) reward per choice).
    """
    prefix = Path(prefix)
    d = _parse_tra(prefix.with_name(prefix.name + ".tra").read_text())
    n = d["n"]
    sta = prefix.with_name(prefix.name + ".sta").read_text().splitlines()
    d["variables"] = sta[0].strip("()").split(",")
    values = []
    for i, ln in enumerate(sta[1:]):
        idx, vals = ln.split(":")
        assert int(idx) == i
        values.append([int(v) for v in vals.strip("()").split(",")])
    d["values"] = np.array(values)
    assert d["values"].shape[0] == n
    lab = prefix.with_name(prefix.name + ".lab").read_text().splitlines()
    names = dict(re.fullmatch(r'(\d+)="([^"]*)"', tok).groups() for tok in lab[0].split())
    d["labels"] = {name: set() for name in names.values()}
    for ln in lab[1:]:
        s, idx = ln.split(":")
        for i in idx.split():
            d["labels"][names[i]].add(int(s))
    ptr = np.searchsorted(d["s_indices"], np.arange(n + 1))
    d["rewards"] = _parse_rewards(prefix, n, d["s_indices"], ptr)
    return d


def parse_drn(text: str) -> dict:
    """A plain reader of Storm's DRN for MDPs (header sections, ``state``/``action`` lines with
    one value per reward model, ``target : probability`` lines)."""
    lines = [ln for ln in text.splitlines() if ln.strip() and not ln.startswith("//")]
    head: dict[str, str] = {}
    i = 0
    while lines[i] != "@model":
        ln = lines[i]
        if ln.startswith("@type: "):
            head["type"] = ln[len("@type: "):]
        elif ln in ("@reward_models", "@nr_states", "@nr_choices"):
            i += 1
            head[ln[1:]] = lines[i]
        elif ln != "@parameters":
            raise AssertionError(f"unexpected header line {ln!r}")
        i += 1
    n, L = int(head["nr_states"]), int(head["nr_choices"])
    names = head["reward_models"].split()
    s_idx, actions, rewards, rows, cols, vals, labels = [], [], [], [], [], [], {}
    for ln in lines[i + 1:]:
        if ln.startswith("state "):
            parts = ln.split()
            assert int(parts[1]) == len(labels), "state ids must be consecutive from 0"
            labels[len(labels)] = parts[2:]
        elif ln.startswith("\taction "):
            m = re.fullmatch(r"\taction (\S+) \[([^\]]+)\]", ln)
            assert m, ln
            s_idx.append(len(labels) - 1)
            actions.append(m.group(1))
            rewards.append([float(v) for v in m.group(2).split(",")])
        else:
            m = re.fullmatch(r"\t\t(\d+) : (\S+)", ln)
            assert m, ln
            rows.append(len(s_idx) - 1)
            cols.append(int(m.group(1)))
            vals.append(float(m.group(2)))
    assert len(labels) == n and len(s_idx) == L
    R = np.array(rewards).reshape(L, len(names))
    return dict(head=head, s_indices=np.array(s_idx), actions=actions, P=sp.csr_matrix((vals, (rows, cols)), shape=(L, n)),
                labels=labels, rewards={name: R[:, r] for r, name in enumerate(names)})


def _matrix(P: sp.csr_matrix, groups: np.ndarray | None):
    from stormpy import datastructures as DS

    P = P.tocsr()
    rows = np.repeat(np.arange(P.shape[0]), np.diff(P.indptr))
    kw = dict(has_custom_row_grouping=True, row_groups=groups.size) if groups is not None else {}
    b = DS.SparseMatrixBuilder(rows=P.shape[0], columns=P.shape[1], entries=P.nnz, force_dimensions=True, **kw)
    if groups is not None:
        b.add_next_values(rows.tolist(), P.indices.tolist(), P.data.tolist(), groups.tolist())
    else:
        b.add_next_values(rows.tolist(), P.indices.tolist(), P.data.tolist())
    return b.build()


def _labeling(n: int, init: int):
    from stormpy import datastructures as DS
    from stormpy import models as M

    lab = M.StateLabeling(n)
    lab.add_label("init")
    lab.set_states("init", DS.BitVector(n, [init]))
    return lab


def storm_mdp(P: sp.csr_matrix, s_indices: np.ndarray, rewards: dict[str, np.ndarray], init: int):
    """A stormpy ``SparseMdp``: one row group per state, each reward as state-action rewards."""
    from stormpy import models as M

    n = P.shape[1]
    groups = np.searchsorted(s_indices, np.arange(n))
    rm = {k: M.SparseRewardModel(optional_state_action_reward_vector=np.asarray(v, float).tolist())
          for k, v in rewards.items()}
    comp = M.SparseModelComponents(transition_matrix=_matrix(P, groups), state_labeling=_labeling(n, init),
                                   reward_models=rm)
    return M.SparseMdp(comp)


def storm_dtmc(P: sp.csr_matrix, rewards: dict[str, np.ndarray], init: int):
    """A stormpy ``SparseDtmc`` with state rewards."""
    from stormpy import models as M

    n = P.shape[0]
    rm = {k: M.SparseRewardModel(optional_state_reward_vector=np.asarray(v, float).tolist()) for k, v in rewards.items()}
    comp = M.SparseModelComponents(transition_matrix=_matrix(P, None), state_labeling=_labeling(n, init),
                                   reward_models=rm)
    return M.SparseDtmc(comp)
