"""Parameter sweeps (the documented import path of :mod:`wncs_lp.studies.sweep`, where they live)."""
from __future__ import annotations

from .studies.sweep import COLUMNS, SweepResult, SweepRow, parse_values, read_rows, run_sweep

__all__ = ["SweepRow", "SweepResult", "run_sweep", "parse_values", "read_rows", "COLUMNS"]
