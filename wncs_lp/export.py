"""The files (npz, Storm's DRN, PRISM's explicit files) moved to :mod:`wncs_lp.io`, one module a format:
every public name of this module is still found here for one release, with a
:class:`DeprecationWarning` naming the new path (:mod:`wncs_lp.moved`)."""
from __future__ import annotations

from typing import Any

from . import moved


def __getattr__(name: str) -> Any:
    return moved.old_name(__name__, name)
