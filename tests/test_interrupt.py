"""Interruption and concurrency: Ctrl-C keeps what was written, a resumed run completes the same
table; two runs into one folder do not corrupt it."""
from __future__ import annotations

import csv
import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
SWEEP = [sys.executable, "-m", "wncs_lp", "sweep", str(ROOT / "formulations" / "paper_p12.toml"),
         "--set", "tau_cap=8", "--param", "p", "--values", "0.60:1.0:0.02",
         "--policies", "optimal,static,greedy", "--no-plot"]



def _ctrl_c_default() -> None:
    """In the child before exec: Ctrl-C's default action. A test run started in the background by
    a non-interactive shell (``cmd &``) inherits SIGINT ignored, and Python then installs no
    KeyboardInterrupt handler: the child would never see the Ctrl-C these tests send."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def rows(folder: Path) -> dict[tuple[str, str], float]:
    with open(folder / "sweep.csv", newline="") as f:
        return {(r["value"], r["policy"]): float(r["gain"]) for r in csv.DictReader(f)}


def data_rows(path: Path) -> int:
    try:
        return max(0, len(path.read_text().splitlines()) - 1)
    except OSError:
        return 0


@pytest.mark.slow
def test_interrupted_sweep_resumes_to_the_same_table(tmp_path):
    full, cut = tmp_path / "full", tmp_path / "cut"
    subprocess.run(SWEEP + ["--out", str(full)], check=True, capture_output=True, timeout=600)
    reference = rows(full)
    assert len(reference) == 21 * 3

    proc = subprocess.Popen(SWEEP + ["--out", str(cut)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            preexec_fn=_ctrl_c_default)
    deadline = time.time() + 300
    while data_rows(cut / "sweep.csv") < 6 and time.time() < deadline and proc.poll() is None:
        time.sleep(0.05)
    assert proc.poll() is None, "the sweep finished before it could be interrupted"
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err.decode()[-2000:]
    assert b"interrupted" in err
    partial = rows(cut)  # still a complete, parseable CSV
    assert 6 <= len(partial) < len(reference)
    for key, gain in partial.items():
        assert gain == pytest.approx(reference[key], rel=1e-9)

    out = subprocess.run(SWEEP + ["--out", str(cut), "--json"], check=True, capture_output=True, timeout=600)
    summary = json.loads(out.stdout)
    assert summary["reused"] >= len(partial) and summary["computed"] == len(reference) - summary["reused"]
    resumed = rows(cut)
    assert resumed.keys() == reference.keys()
    for key, gain in resumed.items():
        assert gain == pytest.approx(reference[key], rel=1e-9), key


@pytest.mark.slow
def test_two_sweeps_into_one_folder(tmp_path):
    out = tmp_path / "shared"
    args = SWEEP + ["--out", str(out)]
    procs = [subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE) for _ in range(2)]
    for p in procs:
        p.wait(timeout=600)
    assert all(p.returncode == 0 for p in procs), [p.stderr.read().decode()[-1000:] for p in procs]
    table = rows(out)
    assert len(table) == 21 * 3
    json.loads((out / "sweep.json").read_text())  # parseable, not interleaved


def test_interrupted_reproduction_resumes(quick_reproduction):
    # the run itself (Ctrl-C after three cached steps, then the same command again) is the
    # session's quick reproduction (tests/conftest.py), whose report the reproduction's tests read
    run = quick_reproduction
    assert run.interrupted_code == 130
    assert len(run.kept) >= 3
    for text in run.kept.values():
        json.loads(text)  # every cache entry complete
    assert run.code == 0, run.stderr[-2000:]
    from wncs_lp.reproduce import CLAIMS

    assert [c["id"] for c in run.report["claims"]] == list(CLAIMS)  # every claim, none lost to the interrupt
    assert len(CLAIMS) == 16
    assert run.report["provenance"]["cache"]["hits"] >= 1  # the steps finished before Ctrl-C were reused


def test_a_signal_inside_the_kernel_compiler_waits_for_the_compilation_to_end():
    """An exception raised inside numba's compiler can leave it holding its lock (the command then
    hangs): the command line's handler, finding a numba or llvmlite frame on the stack, returns
    and the signal is sent again once the main thread has left the compiler."""
    from wncs_lp import stopping

    got: list[tuple[int, bool]] = []

    def handler(signum, frame):
        got.append((signum, stopping.in_compiler(frame)))

    compiling = {"__name__": "numba.core.fake_compiler", "time": time, "stopping": stopping, "got": got,
                 "USR1": signal.SIGUSR1}
    exec("def compile_for(seconds):\n"
         "    stopping.deliver_later(USR1)  # as the handler does for a signal arriving here\n"
         "    t = time.monotonic()\n"
         "    while time.monotonic() - t < seconds:\n"
         "        pass\n"
         "    return list(got)\n", compiling)
    assert not stopping.in_compiler(sys._getframe())
    old = signal.signal(signal.SIGUSR1, handler)
    try:
        assert compiling["compile_for"](0.3) == []  # nothing sent while the compiler runs
        ended = time.monotonic()
        while not got and time.monotonic() - ended < 5:
            time.sleep(0.01)
        assert got == [(signal.SIGUSR1, False)]  # sent once, handled outside the compiler
    finally:
        signal.signal(signal.SIGUSR1, old)
        stopping.clear()
