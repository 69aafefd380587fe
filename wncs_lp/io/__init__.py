"""Files, and the forms other tools take: every reader and writer of the toolkit, one module a format.

* :mod:`~wncs_lp.io.npz` -- the toolkit's own ``.npz`` files: a built MDP (``wncs_lp.mdp-npz``:
  :func:`save_npz`, :func:`load_npz`), a policy (``wncs_lp.policy-npz``: :func:`save_policy_npz`,
  :func:`load_policy_npz`), a solve's policy with its bias and certificate
  (:func:`save_solution_npz`), a saved policy read back as a
  :class:`~wncs_lp.policies.Policy` (:func:`policy_from_file`);
* :mod:`~wncs_lp.io.drn` -- Storm's explicit DRN (:func:`save_drn`);
* :mod:`~wncs_lp.io.prism` -- PRISM's explicit files (:func:`save_prism`);
* :mod:`~wncs_lp.io.rewards` -- what the DRN and PRISM files carry beside the chain: the reward
  models (:func:`reward_models`, :func:`constraint_reward_names`), Storm's multi-objective query
  of a constrained scenario (:func:`multi_objective_property`), the initial state
  (:func:`initial_state`);
* :mod:`~wncs_lp.io.toolkits` -- QuantEcon's ``DiscreteDP`` (:func:`to_quantecon`) and
  pymdptoolbox's ``(P, R)`` (:func:`to_mdptoolbox`, :func:`from_mdptoolbox_policy`);
  :func:`require_package`, the one clear error for a missing optional package.

The modules ``wncs_lp.export`` and ``wncs_lp.interop`` were these; their names are still found
there for one release, with a :class:`DeprecationWarning` naming this package
(:mod:`wncs_lp.moved`). Every file is written atomically
(:func:`wncs_lp.files.atomic_write_bytes`).
"""
from __future__ import annotations

from ..errors import ExportError
from .drn import save_drn
from .npz import (FORMAT, FORMAT_VERSION, POLICY_FORMAT, POLICY_FORMAT_VERSION, load_npz, load_policy_npz,
                  policy_from_file, save_npz, save_policy_npz, save_solution_npz)
from .prism import save_prism
from .rewards import constraint_reward_names, initial_state, multi_objective_property, reward_models
from .toolkits import (InteropError, from_mdptoolbox_policy, n_action_labels, require_package, to_mdptoolbox,
                       to_quantecon)

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
    "InteropError",
    "to_quantecon",
    "to_mdptoolbox",
    "from_mdptoolbox_policy",
    "n_action_labels",
    "require_package",
]
