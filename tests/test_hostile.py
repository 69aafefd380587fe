"""Hostile input (issue 27): every case is one clear error naming what is wrong, never a traceback,
a hang or a silently wrong answer. The hostile inputs are built here."""
from __future__ import annotations

import dataclasses
import json
import os
import signal
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

import wncs_lp
from wncs_lp.cli import main
from wncs_lp.errors import ModelError, ScenarioError, WncsError
from wncs_lp.mdp import MDP
from wncs_lp.scenario import load_scenario, scenario_from_dict

ROOT = Path(__file__).resolve().parent.parent
P12 = str(wncs_lp.scenario_path("paper_p12"))
BUDGET = str(wncs_lp.scenario_path("paper_p12_cloud_budget"))
#: A folder nobody may create files in, root included (sysfs has no regular files to create).
UNWRITABLE = Path("/sys")


def _one_error(capsys, code: int) -> str:
    cap = capsys.readouterr()
    assert code == 2, cap.err[-2000:]
    assert "Traceback" not in cap.err
    lines = [ln for ln in cap.err.splitlines() if ln.startswith("error: ")]
    assert len(lines) == 1, cap.err
    return lines[0]


# ----------------------------------------------------------------------------- §3, §10, §19: costs
@pytest.mark.parametrize("method", ["vi", "rvi", "lp"])
def test_an_overflowing_cost_is_an_error_naming_the_process_and_the_aoi(method, capsys):
    # q(tau) of A = [[3.0]] is (9^tau - 1) / 8: past 1e100 at tau = 106 (9^105 / 8 = 1.76e100)
    code = main(["solve", P12, "--set", "process.2.A=[[3.0]]", "--set", "process.2.tau_cap=700",
                 "--set", "process.1.tau_cap=8", "--method", method])
    line = _one_error(capsys, code)
    assert "process 'process-2'" in line and "AoI tau = 106" in line and "tau_cap" in line


@pytest.mark.parametrize("method", ["vi", "rvi", "lp"])
def test_a_cost_that_overflows_float64_is_named_and_nothing_leaks(method, capsys):
    # A = 1e300: A R A^T = 1e600 overflows at tau = 2 (the LP used to loop forever on the inf costs)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no numpy RuntimeWarning may leak
        code = main(["solve", P12, "--set", "process.1.A=[[1e300]]", "--set", "tau_cap=8", "--method", method,
                     "--json"])
    line = _one_error(capsys, code)
    assert "process 'process-1'" in line and "AoI tau = 2" in line and "overflows" in line


def test_mdp_arrays_refuse_overflowing_and_non_numeric_costs():
    P = np.ones((1, 1, 1))
    with pytest.raises(ModelError, match="cost of pair 0 .*1.7e\\+308.*at most 1e\\+100"):
        MDP.from_dense(P, 1.7e308 * np.ones((1, 1)))
    with pytest.raises(ModelError, match="finite"):
        MDP.from_arrays([0], [0], [np.nan], [[1.0]])
    with pytest.raises(ModelError, match="cost must be an array of numbers, found dtype <U1"):
        MDP.from_arrays([0], [0], ["a"], [[1.0]])
    with pytest.raises(ModelError, match="cost must be an array of numbers"):
        MDP.from_arrays([0], [0], ["1.5"], [[1.0]])  # a number written as text is not silently read
    with pytest.raises(ModelError, match="P must be an array of numbers"):
        MDP.from_arrays([0], [0], [1.0], [["1"]])
    with pytest.raises(ModelError, match="integers"):
        MDP.from_arrays(["0"], [0], [1.0], [[1.0]])


def test_a_csr_with_a_column_beyond_the_states_is_refused():
    import scipy.sparse as sp

    P = sp.csr_matrix((np.array([1.0]), np.array([0]), np.array([0, 1])), shape=(1, 1))
    P.indices[0] = 5  # a hand-made CSR pointing outside the matrix
    with pytest.raises(ModelError, match="column index 5 out of range 0..0 in pair 0"):
        MDP.from_arrays([0], [0], [1.0], P, 1)


# ----------------------------------------------------------------------------- §16: the parser
@pytest.mark.parametrize("override, field, words", [
    ("process.1.A=" + "[" * 2000 + "]" * 2000, "process.1.A", "nested"),
    ("process.1.A=[[" + "9" * 400 + "]]", "process[1].A[1]", "beyond the float range"),
    ("process.1.weight=" + "9" * 400, "process[1].weight", "beyond the float range"),
    ("p=" + "9" * 400, "channel.success_probability", "beyond the float range"),
    ("process.1.weight=" + "9" * 5000, "process.1.weight", "more than 4300 digits"),
    ("process.².weight=1", "process.².weight", "no process named '²'"),
    ("process.١.weight=1", "process.١.weight", "no process named '١'"),
])
def test_parser_extremes_are_one_line_naming_the_field(override, field, words, capsys):
    with pytest.raises(ScenarioError) as info:
        load_scenario(P12, [override])
    msg = str(info.value)
    assert f"'{field}'" in msg and words in msg and "\n" not in msg, msg[:300]
    assert main(["solve", P12, "--set", override]) == 2  # the command line: one line, exit 2
    _one_error(capsys, 2)


def test_a_bound_of_400_digits_and_hostile_dicts(tmp_path):
    text = Path(BUDGET).read_text().replace("max = 0.2", "max = " + "9" * 400)
    f = tmp_path / "big.toml"
    f.write_text(text)
    with pytest.raises(ScenarioError, match="constraint\\[1\\].max.*beyond the float range"):
        load_scenario(f)
    f.write_text(Path(P12).read_text().replace("A = [[1, 1, 0]", "A = " + "[" * 2000 + "]" * 2000 + "\nB = [[1, 1, 0]"))
    with pytest.raises(ScenarioError, match="nested too deeply"):
        load_scenario(f)
    f.write_text(Path(P12).read_text().replace("tau_cap = 12", "tau_cap = " + "9" * 5000))
    with pytest.raises(ScenarioError, match="more than 4300 digits"):
        load_scenario(f)
    raw = load_scenario(P12).to_dict()
    deep: list = []
    for _ in range(2000):
        deep = [deep]
    for key, value, words in (("A", deep, "nested"), ("weight", 10**5000, "beyond the float range"),
                              ("tau_cap", 10**5000, "an integer of 5001 digits")):
        bad = json.loads(json.dumps(load_scenario(P12).to_dict()))
        bad["process"][0][key] = value
        with pytest.raises(ScenarioError, match=words):
            scenario_from_dict(bad)
    raw[1] = 2  # a non-string key in a table
    with pytest.raises(ScenarioError, match="unknown field"):
        scenario_from_dict(raw)


# ----------------------------------------------------------------------------- §17, §19: the library
@pytest.mark.parametrize("thing", ["path", "dict", "mdp"])
def test_build_refuses_what_is_not_a_scenario(thing):
    sc = load_scenario(P12, ["tau_cap=7"])
    arg = {"path": P12, "dict": sc.to_dict(), "mdp": None}[thing]
    if thing == "mdp":
        arg = wncs_lp.build(sc)
    with pytest.raises(ModelError, match="expected a Scenario, got"):
        wncs_lp.build(arg)


def test_overrides_in_every_shape():
    with pytest.raises(ScenarioError, match="override '1': expected a string key"):
        load_scenario(P12, {1: 2})
    with pytest.raises(ScenarioError, match="expected a mapping, a list"):
        load_scenario(P12, 5)
    # one string is one override, not a list of characters
    assert load_scenario(P12, "p=0.5").servers[0].p_up == (0.5, 0.5)
    assert load_scenario(P12, ["p=0.5"]) == load_scenario(P12, "p=0.5") == load_scenario(P12, {"p": 0.5})


def test_a_process_named_with_digits_is_addressed_in_quotes(tmp_path):
    f = tmp_path / "digits.toml"
    f.write_text(Path(P12).read_text().replace('name = "process-1"', 'name = "2"')
                 .replace('name = "process-2"', 'name = "v.1"'))
    sc = load_scenario(f, ['process."2".weight=3', "process.2.weight=5", 'process."v.1".tau_cap=9'])
    by_name = {p.name: p for p in sc.processes}
    assert by_name["2"].weight == 3  # the process named "2" (the first table)
    assert by_name["v.1"].weight == 5  # index 2: the second table
    assert by_name["v.1"].tau_cap == 9
    with pytest.raises(ScenarioError, match="process index 3 out of range.*quote a name"):
        load_scenario(f, ["process.3.weight=1"])
    with pytest.raises(ScenarioError, match="malformed key"):
        load_scenario(f, ['process."2.weight=1'])


# ----------------------------------------------------------------------------- §18: replace
def test_dataclasses_replace_cannot_leave_derived_fields_stale(tmp_path):
    sc = load_scenario(P12, ["tau_cap=8"])
    with pytest.raises(ScenarioError, match="field 'p'.*scenario.replace"):
        dataclasses.replace(sc, p=0.5)
    fixed = sc.replace(p=0.5)
    assert [s.p_up for s in fixed.servers] == [(0.5, 0.5)] * 2 and [s.p_down for s in fixed.servers] == [(0.5, 0.5)] * 2
    # the same scenario written as a file with p = 0.5: an independent path to the expected one
    f = tmp_path / "half.toml"
    f.write_text(Path(P12).read_text().replace("success_probability = 0.9", "success_probability = 0.5"))
    assert fixed == load_scenario(f, ["tau_cap=8"])
    assert sc.replace(**{"process.1.weight": 2}).processes[0].weight == 2
    with pytest.raises(ScenarioError, match="unknown key"):
        sc.replace(processes=())
    # harmless uses stay allowed: the same fields, another source name
    assert dataclasses.replace(sc, source="elsewhere").source == "elsewhere"


# ----------------------------------------------------------------------------- §6, §15: outputs
@pytest.fixture
def no_work(monkeypatch):
    """Fail when a command starts working before it checked its output."""
    import wncs_lp.policy_grids  # noqa: F401 - imported before the patch, so it binds the real load_scenario
    import wncs_lp.models.guard as guard
    import wncs_lp.workflow as route

    def refuse(*a, **k):
        raise AssertionError("work started before the output was checked")

    monkeypatch.setattr(route, "run_scenario", refuse)
    monkeypatch.setattr(route, "build_scenario", refuse)
    monkeypatch.setattr(guard, "build_checked", refuse)
    monkeypatch.setattr("wncs_lp.scenario.load_scenario", refuse)


@pytest.mark.parametrize("argv, words", [
    (["solve", P12, "--out", str(UNWRITABLE / "x.npz")], "cannot write in the folder /sys"),
    (["export", P12, "--out", str(UNWRITABLE / "x.npz")], "cannot write in the folder /sys"),
    (["map", P12, "--servers", "idle", "--out", str(UNWRITABLE / "x.png")], "cannot write in the folder /sys"),
    (["sweep", P12, "--values", "0.8,0.9", "--out", str(UNWRITABLE / "sw")], "cannot write in /sys"),
    (["tradeoff", BUDGET, "--constraint", "1", "--values", "0.1,0.2", "--out", str(UNWRITABLE / "t")],
     "cannot write in /sys"),
    (["reproduce", "--out", str(UNWRITABLE / "r"), "--profile", "quick"], "cannot write in /sys"),
])
def test_unwritable_outputs_are_refused_before_any_work(argv, words, no_work, capsys):
    line = _one_error(capsys, main(argv))
    assert words in line and "--out" in line


@pytest.mark.parametrize("command", ["sweep", "tradeoff", "reproduce", "solve", "export", "map"])
def test_outputs_of_the_wrong_type_are_refused_before_any_work(command, tmp_path, no_work, capsys):
    a_file = tmp_path / "file.txt"
    a_file.write_text("not a folder")
    folder_cmds = {
        "sweep": ["sweep", P12, "--values", "0.8,0.9", "--out"],
        "tradeoff": ["tradeoff", BUDGET, "--constraint", "1", "--values", "0.1", "--out"],
        "reproduce": ["reproduce", "--profile", "quick", "--out"],
    }
    if command in folder_cmds:
        cases = [(a_file, "exists and is not a folder"), (a_file / "sub", "is not a folder")]
        argv = folder_cmds[command]
    else:
        (tmp_path / "d.png").mkdir()
        cases = [(tmp_path / "d.png", "is a folder"), (a_file / "x.png", "is not a folder")]
        argv = {"solve": ["solve", P12, "--out"], "export": ["export", P12, "--out"],
                "map": ["map", P12, "--servers", "idle", "--out"]}[command]
    for out, words in cases:
        line = _one_error(capsys, main(argv + [str(out)]))
        assert words in line, line
    assert a_file.read_text() == "not a folder"


def test_a_failed_write_after_the_solve_keeps_the_result(tmp_path, monkeypatch, capsys):
    import wncs_lp.io as export

    def full_disk(*a, **k):
        raise OSError(28, "No space left on device", str(tmp_path / "x.npz"))

    monkeypatch.setattr(export, "save_solution_npz", full_disk)
    code = main(["solve", P12, "--set", "tau_cap=7", "--method", "vi", "--out", str(tmp_path / "x.npz"), "--json"])
    cap = capsys.readouterr()
    assert code == 2 and "Traceback" not in cap.err
    out = json.loads(cap.out)
    assert out["status"] == "optimal" and out["gain"] > 0  # the finished result is printed
    assert "No space left on device" in out["out_error"]
    assert "error: --out" in cap.err and "could not be written" in cap.err
    code = main(["solve", P12, "--set", "tau_cap=7", "--method", "vi", "--out", str(tmp_path / "x.npz")])
    cap = capsys.readouterr()
    assert code == 2 and "optimal average cost (gain)" in cap.out and "could not be written" in cap.err


# ----------------------------------------------------------------------------- §19: files and signals
def test_temporaries_of_killed_writers_are_cleaned_on_the_next_write(tmp_path):
    from wncs_lp.files import STALE_TMP_SECONDS, atomic_write_text

    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True,
                          text=True).stdout.strip()
    left = tmp_path / f".out.csv.{dead}.k3j2.tmp"  # what a SIGKILLed writer leaves (40 MB in the issue)
    live = tmp_path / f".out.csv.{os.getpid()}.a1b2.tmp"  # a writer still running: kept
    old = tmp_path / ".out.csv.zz9x.tmp"  # an old-style name without a pid, two hours old
    other = tmp_path / f".other.csv.{dead}.q.tmp"  # another target's: not this write's business
    for f in (left, live, old, other):
        f.write_bytes(b"x" * 100)
    os.utime(old, (time.time() - 2 * STALE_TMP_SECONDS,) * 2)
    atomic_write_text(tmp_path / "out.csv", "a,b\n")
    assert not left.exists() and not old.exists()
    assert live.exists() and other.exists()
    assert (tmp_path / "out.csv").read_text() == "a,b\n"


def test_a_csv_table_is_written_whole_with_its_header(tmp_path):
    from wncs_lp.files import atomic_write_csv

    out = tmp_path / "t.csv"
    atomic_write_csv(out, [{"a": 1, "b": 2.5}, {"a": 3}], ["a", "b"])
    assert out.read_text().splitlines() == ["a,b", "1,2.5", "3,"]  # a missing key: an empty cell
    with pytest.raises(ValueError, match="'c'"):
        atomic_write_csv(out, [{"a": 1, "c": 2}], ["a", "b"])
    assert out.read_text().splitlines()[1] == "1,2.5"  # a failed write leaves the file as it was
    atomic_write_csv(out, [{"a": 1, "c": 2}], ["a", "b"], extras="ignore")
    assert out.read_text().splitlines() == ["a,b", "1,"]


def test_sigterm_says_so_and_exits_143(tmp_path):
    """SIGTERM once the sweep has written its first row (its line on stderr is the readiness signal:
    no fixed sleep, so a loaded machine only makes it wait longer); 501 points, so it cannot end first."""
    import threading

    out = tmp_path / "sw"
    proc = subprocess.Popen([sys.executable, "-m", "wncs_lp", "sweep", P12, "--set", "tau_cap=8",
                             "--values", "0.5:1.0:0.001", "--policies", "optimal", "--no-plot", "--out", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    err: list[bytes] = []
    row_written = threading.Event()

    def read_err() -> None:
        for line in proc.stderr:
            err.append(line)
            if b"optimal: gain" in line:  # printed after the row was saved to sweep.csv
                row_written.set()

    reader = threading.Thread(target=read_err, daemon=True)
    reader.start()
    deadline = time.monotonic() + 300
    while not row_written.wait(0.05) and proc.poll() is None and time.monotonic() < deadline:
        pass
    assert row_written.is_set() and proc.poll() is None, b"".join(err).decode()[-2000:]
    proc.send_signal(signal.SIGTERM)
    proc.stdout.read()
    proc.wait(timeout=120)
    reader.join(timeout=10)
    text = b"".join(err).decode()
    assert proc.returncode == 143, text[-2000:]
    assert "terminated (SIGTERM)" in text and "Traceback" not in text
    assert not list(out.glob(".*.tmp"))
    assert (out / "sweep.csv").read_text().count("optimal") >= 1  # the rows written are kept


@pytest.mark.parametrize("damage", [b"param,value\xb3,policy\n", b"param,value\x00,policy\n", "folder"])
def test_a_damaged_table_gives_no_records(tmp_path, damage):
    from wncs_lp.files import csv_records

    f = tmp_path / "sweep.csv"
    if damage == "folder":
        f.mkdir()
    else:
        f.write_bytes(damage)
    assert csv_records(f, ("param", "value", "policy")) == []
