"""examples/06_notebook.py (the walk-through of docs/notebook.md) runs and keeps its promises:
the converters agree with the solution, the policy of one's own simulates to its exact value,
every discounted solve closes its certificate and approaches the average cost."""
from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


@pytest.mark.slow
def test_the_walk_through_runs(tmp_path):
    png = tmp_path / "maps.png"
    proc = subprocess.run([sys.executable, str(ROOT / "examples" / "06_notebook.py"), "7", str(png)], cwd=ROOT,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = proc.stdout
    assert "status: optimal" in out and "stalest to edge" in out
    apart = float(re.search(r"([\d.]+) standard errors apart", out).group(1))
    assert apart < 4  # Monte Carlo against the exact evaluation
    rows = [line.split() for line in out.splitlines() if re.match(r"\s+0\.9+ ", line)]
    assert len(rows) == 4 and all(r[1] == "optimal" for r in rows)
    gain_errors = [float(r[6]) for r in rows]  # |(1 - beta) v - g| shrinks tenfold with 1 - beta
    assert all(0.05 < b / a < 0.2 for a, b in zip(gain_errors, gain_errors[1:]))
    assert png.read_bytes().startswith(b"\x89PNG")
