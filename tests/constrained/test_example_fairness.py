"""examples/05_fairness_minmax.py runs and prints numbers that are consistent with each other."""
from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
NUM = r"(-?\d+\.\d+)"


def run(*args: str) -> str:
    proc = subprocess.run([sys.executable, str(ROOT / "examples" / "05_fairness_minmax.py"), *args], cwd=ROOT,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return proc.stdout


def row(out: str, label: str) -> tuple[list[float], float, float, int]:
    """(per-process MSE, total, max, randomised states) of one table row."""
    line = next(l for l in out.splitlines() if l.startswith(label))
    *per, total, worst, rnd = line[len(label):].split()
    return [float(v) for v in per], float(total), float(worst), int(rnd)


def bracket(out: str, label: str) -> tuple[float, float, str]:
    line = next(l for l in out.splitlines() if l.startswith(f"certificate, {label}:"))
    lo, hi, status = re.search(rf"in \[{NUM}, {NUM}\], (\S+) \(", line).groups()
    return float(lo), float(hi), status


@pytest.mark.parametrize("cap", [None, "6"])
def test_fairness_example_prints_consistent_numbers(cap):
    out = run(*([cap] if cap else []))
    assert f"tau_cap = {cap or 8}" in out
    rows = {k: row(out, k) for k in ("unconstrained optimum", "min-max (Clarabel)", "min-max, least total")}
    for per, total, worst, _ in rows.values():
        assert len(per) == 2
        assert total == pytest.approx(sum(per), abs=2e-6) and worst == pytest.approx(max(per), abs=1e-6)
    opt, fair, best = rows["unconstrained optimum"], rows["min-max (Clarabel)"], rows["min-max, least total"]
    tol = 1e-6
    # min-max is at most the unconstrained optimum's max MSE, and the refinement keeps that max
    assert fair[2] <= opt[2] + tol and best[2] <= fair[2] * (1 + 1e-8) + tol
    # the unconstrained optimum has the least total; the refinement does not raise the min-max policy's total
    assert opt[1] <= best[1] + tol and best[1] <= fair[1] + tol
    assert opt[3] == 0 and best[3] <= 2  # deterministic; a basic solution with two bounds
    lower = float(re.search(rf"any policy: {NUM}", out).group(1))
    assert lower <= fair[2] + tol
    for label, value, which in (("unconstrained optimum", opt[1], "total"), ("min-max", fair[2], "max"),
                                ("min-max least total", best[1], "total")):
        lo, hi, status = bracket(out, label)
        assert status == "optimal", (label, status)
        assert abs(hi - lo) <= 1e-6 * abs(value) and min(lo, hi) - tol <= value <= max(lo, hi) + tol
    if cap is None:  # at cap 8 fairness has a price: process 1 gains, the total grows
        assert fair[2] < opt[2] - 1.0 and best[1] > opt[1] + 0.1
