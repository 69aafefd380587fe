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


def test_a_signal_inside_a_finalizer_or_weakref_callback_is_delivered_after_it():
    """A KeyboardInterrupt raised inside ``__del__`` or a weak reference's callback is printed as
    "Exception ignored in ..." and lost (seen in CI: SIGTERM landing in a WeakKeyDictionary's
    callback): the handler finds such a frame, returns, and the signal comes again after it."""
    import gc
    import weakref

    from wncs_lp import stopping

    got: list[tuple[str, bool]] = []

    def handler(signum, frame):  # as the command line's handler does
        if stopping.not_raisable(frame):
            got.append(("later", True))
            stopping.deliver_later(signum)
            return
        got.append(("raised", False))

    class Dying:
        def __del__(self):
            signal.raise_signal(signal.SIGUSR1)  # the handler runs here, inside the finalizer

    class Target:
        pass

    weak = {"__name__": "weakref", "signal": signal}  # a callback of the standard library's weakref module
    exec("def remove(ref):\n    signal.raise_signal(signal.SIGUSR1)\n", weak)
    old = signal.signal(signal.SIGUSR1, handler)
    try:
        assert not stopping.in_finalizer(sys._getframe())
        for make in (lambda t: Dying(), lambda t: weakref.ref(t, weak["remove"])):
            got.clear()
            stopping.clear()
            target = Target()
            keep = make(target)
            del target, keep
            gc.collect()
            t = time.monotonic()
            while len(got) < 2 and time.monotonic() - t < 5:
                time.sleep(0.01)
            assert got == [("later", True), ("raised", False)]
    finally:
        signal.signal(signal.SIGUSR1, old)
        stopping.clear()


def test_an_interrupt_lost_in_an_unknown_callback_is_sent_again_without_a_traceback(capsys):
    """A callback the handler cannot recognise: the interrupt it raises there is lost to Python;
    redeliver_lost() prints nothing and sends the signal again, which then raises where it can."""
    import gc
    import weakref

    from wncs_lp import stopping

    def handler(signum, frame):
        stopping.request(signum)
        raise KeyboardInterrupt

    class Target:
        pass

    def callback(ref):
        signal.raise_signal(signal.SIGUSR1)

    old = signal.signal(signal.SIGUSR1, handler)
    stopping.clear()
    try:
        with pytest.raises(KeyboardInterrupt), stopping.redeliver_lost():
            target = Target()
            ref = weakref.ref(target, callback)
            del target  # the callback runs here; its KeyboardInterrupt is lost
            gc.collect()
            t = time.monotonic()
            while time.monotonic() - t < 5:  # the second delivery raises in this loop
                time.sleep(0.01)
        assert ref() is None
        assert "Exception ignored" not in capsys.readouterr().err
    finally:
        signal.signal(signal.SIGUSR1, old)
        stopping.clear()


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
