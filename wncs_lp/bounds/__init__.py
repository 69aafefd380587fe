"""Certified lower bounds on the optimal gain g*, for any number of processes, and the policies
they give (relaxations of the joint MDP built on :class:`~wncs_lp.models.system.System`, never on
the enumerated MDP).

The result type of every relaxation is :class:`BoundResult`; its value tables
(:class:`ValueTables`) drive the greedy policy of the bound.
"""
from __future__ import annotations

from .result import BoundResult, ValueTables

__all__ = ["BoundResult", "ValueTables"]
