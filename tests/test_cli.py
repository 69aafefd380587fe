"""Command-line conventions: --version, JSON errors under --json, the library's default method."""
from __future__ import annotations

import json
import subprocess
import sys

import wncs_lp


def run(*args: str):
    return subprocess.run([sys.executable, "-m", "wncs_lp", *args], capture_output=True, text=True, timeout=120)


def test_version():
    proc = run("--version")
    assert proc.returncode == 0 and proc.stdout.strip() == f"wncs-lp {wncs_lp.__version__}"


def test_errors_under_json_are_one_json_object():
    proc = run("solve", str(wncs_lp.scenario_path("paper_p12")), "--set", "p=2", "--json")
    assert proc.returncode == 2
    out = json.loads(proc.stdout)
    assert out["type"] == "ScenarioError" and out["field"] == "channel.success_probability"
    assert "expected a probability" in out["error"]
    assert len(proc.stderr.strip().splitlines()) == 1  # and the one line on stderr as without --json


def test_library_default_is_auto_like_the_command_line():
    sc = wncs_lp.load_scenario(wncs_lp.scenario_path("paper_p12"), ["tau_cap=6"])
    sol = wncs_lp.solve(wncs_lp.build(sc))
    assert sol.method == "auto" and sol.stats["auto_choice"] in ("lp", "vi")
