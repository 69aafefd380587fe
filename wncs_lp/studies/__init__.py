"""Studies: grids of solves, resumable, written as CSV + JSON (and a figure).

* :func:`run_sweep` -- several policies over a grid of one scenario parameter (:mod:`.sweep`);
* :func:`tradeoff` -- the constrained optimum against one constraint's bound (:mod:`.tradeoff`);
* :func:`cap_study` -- the optimum at increasing AoI caps until the truncation stops mattering
  (:mod:`.capstudy`).

They share one grid (:mod:`.grid`: bounded, finite values), one runner (:mod:`.runner`: in
order with a warm start, or in parallel on worker processes or a Dask cluster,
:mod:`.executors`) and one output folder (:mod:`.folder`: locked while a run writes it, its
settings checked, every row sealed by a fingerprint so no foreign or edited row is reused).
"""
from __future__ import annotations

from .capstudy import CapRow, CapStudy, cap_study
from .executors import EXECUTORS, parallel
from .folder import StudyFolder
from .grid import MAX_GRID_VALUES, parse_values, value_key
from .runner import run_grid
from .sweep import COLUMNS, SweepResult, SweepRow, read_rows, run_sweep
from .tradeoff import TradeoffPoint, TradeoffResult, quantity_unit, read_points, tradeoff

__all__ = [
    "run_sweep", "SweepRow", "SweepResult", "read_rows", "COLUMNS",
    "tradeoff", "TradeoffPoint", "TradeoffResult", "read_points", "quantity_unit",
    "cap_study", "CapRow", "CapStudy",
    "parse_values", "value_key", "MAX_GRID_VALUES", "run_grid", "parallel", "EXECUTORS", "StudyFolder",
]
