"""``wncs-lp reproduce --threads N``: no solve of the run uses more than N threads (default: the
machine's cores), in this process and in the worker processes it starts."""
from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

import wncs_lp.reproduce as rep
from wncs_lp.cli import main
from wncs_lp.errors import SolverError
from wncs_lp.solvers.threads import LIMIT_ENV, resolve_threads, thread_limit, usable_cores


def test_thread_limit_caps_default_and_explicit_counts_and_is_restored(monkeypatch):
    monkeypatch.delenv(LIMIT_ENV, raising=False)
    big = 10**9  # states: above the parallel threshold, so the default is every usable core
    assert resolve_threads(None, big) == min(usable_cores(), resolve_threads(usable_cores()))
    with thread_limit(1):
        assert resolve_threads(None, big) == 1 and resolve_threads(8) == 1
        with thread_limit(None):  # no cap given: the outer one stays
            assert resolve_threads(8) == 1
    assert LIMIT_ENV not in os.environ
    for bad in (0, -1, 1.5, True):
        with pytest.raises(SolverError, match="threads"):
            with thread_limit(bad):
                pass


def test_a_worker_process_inherits_the_cap(monkeypatch):
    monkeypatch.delenv(LIMIT_ENV, raising=False)
    code = "from wncs_lp.solvers.threads import resolve_threads; print(resolve_threads(8))"
    with thread_limit(1):
        child = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert child.returncode == 0, child.stderr
    assert child.stdout.strip() == "1"


@pytest.mark.parametrize("given", [None, 1])
def test_reproduce_threads_reach_every_solve_and_the_provenance(tmp_path, monkeypatch, capsys, given):
    monkeypatch.delenv(LIMIT_ENV, raising=False)
    seen = []

    def claim(ctx):
        seen.append((resolve_threads(None, 10**9), resolve_threads(64)))
        return rep.ClaimResult("C1", "Fig. 3", "", "HOLDS", "ok")

    monkeypatch.setattr(rep, "_claims", lambda: {"C1": claim})
    out = tmp_path / "r"
    args = ["reproduce", "--out", str(out), "--profile", "quick", "--claims", "C1"]
    assert main(args + ([] if given is None else ["--threads", str(given)])) == 0
    cores = usable_cores()
    want = cores if given is None else given
    assert seen[0][0] == min(want, resolve_threads(cores))
    if given is not None:
        assert seen[0][1] == given
    prov = json.loads((out / "report.json").read_text())["provenance"]
    assert prov["threads"] == {"at most": want, "cores": cores}
    err = capsys.readouterr().err
    # the opening line: the threads and the estimate
    assert f"solves on up to {want} thread(s) of {cores} core(s)" in err.splitlines()[0]
    assert "estimate about" in err.splitlines()[0]
    assert LIMIT_ENV not in os.environ


def test_reproduce_refuses_a_bad_thread_count(tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["reproduce", "--out", str(tmp_path / "r"), "--threads", "0"])
    assert exc.value.code == 2 and "--threads" in capsys.readouterr().err and not (tmp_path / "r").exists()
