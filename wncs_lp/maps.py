"""The policy maps as data moved to :mod:`wncs_lp.policy_grids` (so that this name is not read as the
drawing, :mod:`wncs_lp.viz.maps`): every public name of it is still found here for one release, with
a :class:`DeprecationWarning` naming the new path (:mod:`wncs_lp.moved`)."""
from __future__ import annotations

from . import moved


#: Names that moved or were replaced: found here for one release, with a warning (:mod:`wncs_lp.moved`).
__getattr__ = moved.old_names(__name__)
