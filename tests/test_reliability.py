"""Reliability at the toolkit's edges (issue 39), one test per hostile family of
``fuzz_reliability.py`` (which ``benchmarks/fuzz_scenarios.py --families hostile`` counts in full):
special files, memory limits (set in a subprocess with ``resource.setrlimit``), signals, the JSON
contract, numeric options, the library's arguments, labels, caches and messages. The cases here
are the cheap ones of each family; edited systems are in ``tests/bounds/test_bound_inputs.py``,
edited solution files in ``tests/solvers/test_matrix_free.py``, sixteen to thirty-two processes
under a memory limit in ``tests/bounds/test_bound_scale.py``."""
from __future__ import annotations

import json
import os
import signal
import sys
from contextlib import contextmanager
from pathlib import Path

import pytest
from fuzz_reliability import (
    BAD_CALLS,
    BAD_OPTIONS,
    GiB,
    LP_INSTANCE,
    LP_LIMIT,
    P12,
    SMALL,
    check_cache,
    cli,
    error_lines,
    json_objects,
    scenario,
)

from wncs_lp.cli import main
from wncs_lp.errors import WncsError

pytestmark = pytest.mark.filterwarnings("ignore::wncs_lp.errors.ScenarioWarning")


@contextmanager
def at_most(seconds: int):
    """Fail, instead of hanging the suite, when the block takes longer (an open() on a FIFO
    without a writer blocks in the kernel; SIGALRM interrupts it)."""
    def alarm(signum, frame):
        raise TimeoutError(f"no answer within {seconds} s")

    old = signal.signal(signal.SIGALRM, alarm)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


def one_error(capsys, code: int) -> str:
    cap = capsys.readouterr()
    assert code == 2 and "Traceback" not in cap.err, cap.err[-2000:]
    lines = error_lines(cap.err)
    assert len(lines) == 1, cap.err[-2000:]
    return lines[0]


# ----------------------------------------------------------------------------- special files
def test_a_fifo_a_device_a_folder_and_a_huge_file_are_refused_at_once(tmp_path, capsys):
    fifo = tmp_path / "pipe.toml"
    os.mkfifo(fifo)  # no writer: opening it to read would block for ever
    npz_fifo = tmp_path / "pipe.npz"
    os.mkfifo(npz_fifo)
    (tmp_path / "folder.toml").mkdir()
    sparse = tmp_path / "sparse.toml"
    with open(sparse, "wb") as f:
        f.truncate(6 * 10**9)  # 6 GB of holes: nothing on disk, but no scenario either
    cases = [(["validate", str(fifo)], "named pipe"), (["solve", str(fifo)], "named pipe"),
             (["validate", "/dev/zero"], "character device"), (["bound", "/dev/urandom"], "character device"),
             (["validate", str(tmp_path / "folder.toml")], "folder"),
             (["validate", str(sparse)], "6,000,000,000 bytes, over the limit"),
             (["evaluate", *SMALL, "--policy", str(npz_fifo)], "pipe.npz")]
    for argv, words in cases:
        with at_most(20):
            line = one_error(capsys, main(argv))
        assert words in line, (argv, line)


# ----------------------------------------------------------------------------- memory limits
def test_under_an_address_space_limit_the_guard_refuses_before_the_backend_aborts(tmp_path):
    """The LP of processes 1-3 at cap 12 peaks near 3.8 GB on Clarabel: under a 2.2 GiB limit
    (resource.setrlimit in the subprocess) each LP route is refused in one line naming a cheaper
    one, and replications that do not fit are refused before numpy allocates them."""
    code = f"""
import resource, sys
resource.setrlimit(resource.RLIMIT_AS, ({LP_LIMIT}, {LP_LIMIT}))
from wncs_lp.cli import main
codes = [main(argv) for argv in {[["solve", *LP_INSTANCE, "--method", m] for m in ("lp", "lp-highs")]
                                  + [["simulate", *SMALL, "--policy", "greedy", "--reps", str(10**9), "--slots", "100"]]!r}]
print(codes)
"""
    import subprocess

    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path, timeout=300,
                         env={**os.environ, "NUMBA_NUM_THREADS": "1"})
    assert out.returncode == 0 and "Traceback" not in out.stderr and "MemoryError" not in out.stderr, out.stderr[-2000:]
    assert out.stdout.strip().splitlines()[-1] == "[2, 2, 2]", out.stdout
    lines = error_lines(out.stderr)
    assert len(lines) == 3, out.stderr
    assert all("over the limit" in ln for ln in lines), lines
    assert all("RLIMIT_AS" in ln for ln in lines[:2]), lines  # the limit is the one set here
    assert all("Cheaper routes" in ln and "--method matrix-free" in ln for ln in lines[:2]), lines
    assert "replications" in lines[2], lines[2]


# ----------------------------------------------------------------------------- signals and the JSON contract
def test_sigterm_stops_bound_policy_within_ten_seconds_with_one_json_object(tmp_path):
    """SIGTERM while ``bound --policy`` evaluates its first policy (three more to come) ends the
    whole command within 10 s: exit 143, one line saying so, one JSON object ``interrupted``."""
    run = cli(["bound", scenario("lab_5sensors"), "--set", "tau_cap=10", "--relaxation", "1", "--policy",
               "--compare", "greedy,static,max_weight", "--progress", "--json"],
              stop=(r"evaluat", 0.5, signal.SIGTERM), timeout=240, mem=3 * GiB, cwd=tmp_path)
    assert run.signalled is not None, f"ended (exit {run.code}) before the signal: {run.err[-1500:]}"
    assert run.code == 143 and run.stopped_in < 10, (run.code, run.stopped_in, run.err[-1500:])
    assert "Traceback" not in run.err
    said = [ln for ln in run.err.splitlines() if "terminated" in ln or "interrupted" in ln]
    assert said == ["terminated (SIGTERM): results already written are kept"], said
    objs = json_objects(run.out)
    assert len(objs) == 1 and objs[0]["interrupted"] is True and objs[0]["signal"] == "SIGTERM", run.out[:500]
    assert "evaluat" not in run.err.split("terminated")[1]  # no policy evaluated after the signal


def test_a_reader_closing_stdout_ends_the_command_quietly(tmp_path):
    run = cli(["simulate", P12, "--set", "tau_cap=7", "--policy", "greedy", "--slots", "2000", "--json"], head=0,
              timeout=120, cwd=tmp_path)  # stdout closed before the command writes
    assert run.code is not None and run.code >= 0 and not run.hung
    assert run.err.strip() == "", run.err[-1500:]  # no BrokenPipeError traceback, not even at exit


# ----------------------------------------------------------------------------- numeric options
@pytest.mark.parametrize("argv", BAD_OPTIONS, ids=[" ".join(a for a in argv if a not in SMALL) for argv in BAD_OPTIONS])
def test_numeric_options_out_of_range_are_the_parsers_usage_error(argv, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit) as info:
        main(argv)
    err = capsys.readouterr().err
    assert info.value.code == 2 and "usage:" in err and len(error_lines(err)) == 1, err[-1000:]


# ----------------------------------------------------------------------------- the library's arguments
@pytest.mark.parametrize("argument, label, call", BAD_CALLS, ids=[label for _, label, _ in BAD_CALLS])
def test_the_public_api_names_the_bad_argument(argument, label, call):
    with pytest.raises(WncsError, match=argument):
        call()


# ----------------------------------------------------------------------------- labels
@pytest.fixture
def vi_stops_short(monkeypatch):
    """Value iteration's default budget set to 3 passes: its solves end uncertified (``max_iter``).
    The default itself is changed, so every route that calls the function finds it."""
    from wncs_lp.solvers import dp

    monkeypatch.setitem(dp.value_iteration.__kwdefaults__, "max_iter", 3)


def test_an_uncertified_optimal_policy_is_not_labelled_optimal(vi_stops_short, capsys):
    """When the solve behind the "optimal" policy is not certified, evaluate says its status and
    exits 1, as solve does, and the cap study does not call itself converged."""
    argv = [P12, "--set", "tau_cap=8", "--method", "vi", "--json"]
    assert main(["solve", *argv]) == 1
    status = json.loads(capsys.readouterr().out)["status"]
    assert status != "optimal", status
    assert main(["evaluate", *argv, "--policy", "optimal"]) == 1
    doc = json.loads(capsys.readouterr().out)
    assert status in json.dumps(doc.get("policy_status")), doc
    main(["capstudy", P12, "--caps", "8,9", "--method", "vi", "--json"])
    doc = json.loads(capsys.readouterr().out)
    assert [r["status"] for r in doc["rows"]] == [status, status] and not doc["converged"], doc


# ----------------------------------------------------------------------------- caches
@pytest.mark.parametrize("kind", ["replaced by a folder (json)", "replaced by a folder (npz)",
                                  "re-keyed from another scenario (files renamed)",
                                  "re-keyed from another scenario (key and checksum rewritten)"])
def test_a_cache_entry_that_does_not_verify_is_recomputed(kind):
    label, detail = check_cache(kind)
    assert label == "ok", detail


# ----------------------------------------------------------------------------- messages
def test_a_name_with_control_characters_is_printed_on_one_line(tmp_path, capsys):
    path = tmp_path / "ctl.toml"
    path.write_text(Path(P12).read_text().replace('name = "process-1"', 'name = "a\\nb\\u001b[31m"', 1))
    for extra, want in (([], 0), (["--set", "process.1.weight=-2"], 2)):
        assert main(["validate", str(path), "--set", "tau_cap=5", *extra]) == want
        cap = capsys.readouterr()
        stray = [ln for ln in cap.err.splitlines() if not ln.startswith(("warning: ", "error: "))]
        assert not stray and "\x1b" not in cap.err + cap.out, cap.err
        if not extra:
            assert "'a\\nb\\x1b[31m'" in cap.err  # the name in the warnings, escaped


def test_map_draws_a_saved_policy_file(tmp_path, capsys):
    sol = tmp_path / "sol.npz"
    assert main(["solve", *SMALL, "--method", "vi", "--out", str(sol)]) == 0
    capsys.readouterr()
    assert main(["map", *SMALL, "--servers", "idle", "--policy", str(sol), "--out", str(tmp_path / "m.png")]) == 0
    assert (tmp_path / "m.png").stat().st_size > 0
