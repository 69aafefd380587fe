"""The forms of other toolkits (QuantEcon, pymdptoolbox) moved to :mod:`wncs_lp.io`, one module a format:
every public name of this module is still found here for one release, with a
:class:`DeprecationWarning` naming the new path (:mod:`wncs_lp.moved`)."""
from __future__ import annotations

from . import moved


#: Names that moved or were replaced: found here for one release, with a warning (:mod:`wncs_lp.moved`).
__getattr__ = moved.old_names(__name__)
