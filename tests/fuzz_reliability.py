"""Hostile cases at the toolkit's edges (issue 39), shared by ``benchmarks/fuzz_scenarios.py``
(which counts their outcomes by family) and the tests.

Each case is run whole -- most as a ``wncs-lp`` command in a child process, under a memory
limit (``RLIMIT_AS``) and a timeout, some as a library call in a forked child -- and its outcome
is one of :data:`OUTCOMES`:

``ok``           the command did its work (or, for a signal, stopped as the contract says);
``clear error``  one error that names what was wrong (exit status 2 and ``error:`` / argparse's
                 usage error, or a ``WncsError`` naming the argument), within the time limit;
``traceback``    a Python traceback, or an exception other than the toolkit's;
``hang``         no answer within the time limit (killed by the harness);
``kill``         ended by a signal it did not handle (the kernel's OOM killer, an abort);
``wrong``        the contract broken without a crash: bad input accepted, an exit status other
                 than the one promised, two JSON objects, a label or a result that is not earned.

The families (:data:`FAMILIES`): special files, memory limits, signals, JSON contract, CLI
options, API arguments, edited files, edited systems, labels, caches, messages. The cases are
fixed lists, not random draws: each one is a defect found once, and its count before and after
a change is comparable.
"""
from __future__ import annotations

import dataclasses
import json
import os
import re
import resource
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any, Callable

ROOT = Path(__file__).resolve().parent.parent
OUTCOMES = ("ok", "clear error", "traceback", "hang", "kill", "wrong")
GiB = 1 << 30


# ----------------------------------------------------------------------------- running a command
@dataclasses.dataclass
class Run:
    """What a child command did."""

    code: int | None
    out: str
    err: str
    seconds: float
    hung: bool = False
    signalled: float | None = None  # seconds after the start the signal was sent
    stopped_in: float | None = None  # seconds from the signal to the exit


def _child_setup(mem: int | None) -> Callable[[], None]:
    def setup() -> None:
        os.setsid()  # its own process group: the harness can end it and its workers together
        signal.signal(signal.SIGINT, signal.SIG_DFL)  # a shell's background job inherits SIGINT ignored
        if mem is not None:
            resource.setrlimit(resource.RLIMIT_AS, (mem, mem))

    return setup


def child_env(extra: dict[str, str] | None = None) -> dict[str, str]:
    """The environment of a child command: this one, the code under test first on the path
    (``WNCS_FUZZ_CODE``: another checkout's root, to measure a "before")."""
    env = dict(os.environ)
    code = os.environ.get("WNCS_FUZZ_CODE")
    if code:
        env["PYTHONPATH"] = code + os.pathsep + env.get("PYTHONPATH", "")
    env.setdefault("NUMBA_NUM_THREADS", "2")
    env.update(extra or {})
    return env


def code_under_test() -> str:
    """The folder of the ``wncs_lp`` package the child commands import."""
    return subprocess.run([sys.executable, "-P", "-c", "import wncs_lp; print(wncs_lp.__file__)"], env=child_env(),
                          capture_output=True, text=True, check=True).stdout.strip()


def cli(argv: list[str], *, timeout: float = 60, mem: int | None = 3 * GiB, stop: tuple | None = None,
        head: int | None = None, cwd: Path | None = None, stdin: Any = subprocess.DEVNULL) -> Run:
    """Run ``wncs-lp argv`` in a child process.

    ``stop = (pattern, delay, signum)``: send ``signum`` ``delay`` seconds after a line of
    stderr matches ``pattern`` (give ``--progress``), then wait at most 10 s for the exit.
    ``head``: read that many bytes of stdout, then close it (``| head -c N``).
    """
    # -P: the working directory is not put first on the path, so WNCS_FUZZ_CODE's package is the one run
    cmd = [sys.executable, "-P", "-m", "wncs_lp", *argv]
    t0 = time.monotonic()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, stdin=stdin, cwd=cwd,
                            env=child_env(), preexec_fn=_child_setup(mem))
    err_chunks: list[bytes] = []
    out_chunks: list[bytes] = []
    matched = threading.Event()
    pattern = re.compile(stop[0]) if stop and stop[0] else None
    if stop and not stop[0]:  # no pattern: the delay counts from the start
        matched.set()

    def read_err() -> None:  # by chunks: a progress bar redraws its line with \r, never ending it
        tail = b""
        while chunk := proc.stderr.read1(1 << 16):
            err_chunks.append(chunk)
            if pattern is not None and not matched.is_set():
                tail = (tail + chunk)[-4096:]
                if any(pattern.search(part) for part in re.split(r"[\r\n]", tail.decode("utf-8", "replace"))):
                    matched.set()

    def read_out() -> None:
        if head is not None:
            out_chunks.append(proc.stdout.read(head))
            proc.stdout.close()
            return
        out_chunks.append(proc.stdout.read())

    readers = [threading.Thread(target=read_err, daemon=True), threading.Thread(target=read_out, daemon=True)]
    for r in readers:
        r.start()
    run = Run(None, "", "", 0.0)
    deadline = t0 + timeout
    try:
        if stop is not None:
            while not matched.is_set() and proc.poll() is None and time.monotonic() < deadline:
                time.sleep(0.05)
            if matched.is_set() and proc.poll() is None:
                time.sleep(stop[1])
                if proc.poll() is None:
                    run.signalled = time.monotonic() - t0
                    proc.send_signal(stop[2])
                    deadline = time.monotonic() + 10
        proc.wait(timeout=max(deadline - time.monotonic(), 0.1))
    except subprocess.TimeoutExpired:
        run.hung = True
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        proc.wait()
    finally:
        try:  # workers left behind by the command
            os.killpg(proc.pid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            pass
    for r in readers:
        r.join(timeout=5)
    run.code = proc.returncode
    run.seconds = time.monotonic() - t0
    if run.signalled is not None:
        run.stopped_in = run.seconds - run.signalled
    run.out = b"".join(c for c in out_chunks if c).decode("utf-8", "replace")
    run.err = b"".join(err_chunks).decode("utf-8", "replace")
    return run


TRACEBACK = "Traceback (most recent call last)"


def crash_of(run: Run) -> tuple[str, str] | None:
    """("hang" | "kill" | "traceback", detail) when the command crashed or hung, else None."""
    if run.hung:
        return "hang", f"no answer in {run.seconds:.0f} s"
    if run.code is not None and run.code < 0:
        return "kill", f"killed by signal {-run.code} ({signal.Signals(-run.code).name}); " + last_line(run.err)
    if TRACEBACK in run.err or "MemoryError" in run.err:
        return "traceback", last_line(run.err)
    return None


def last_line(text: str) -> str:
    lines = [ln for ln in text.strip().splitlines() if ln.strip()]
    return lines[-1][:160] if lines else ""


def error_lines(err: str) -> list[str]:
    """The ``error:`` lines of stderr (argparse's ``prog: error:`` too)."""
    return [ln for ln in err.splitlines() if re.match(r"^(error:|wncs-lp[\w -]*: error:)", ln)]


def expect_error(run: Run, words: str | None = None, usage: bool = False) -> tuple[str, str]:
    """The outcome of a case whose contract is one clear error (exit 2, one ``error:`` line;
    with ``usage`` argparse's usage error; ``words`` in it)."""
    crash = crash_of(run)
    if crash:
        return crash
    lines = error_lines(run.err)
    if run.code != 2 or len(lines) != 1:
        return "wrong", f"exit {run.code} with {len(lines)} error line(s), expected one error and exit 2: " \
            + last_line(run.err)
    if usage and "usage:" not in run.err:
        return "wrong", "not the parser's usage error: " + lines[0][:160]
    if words and not re.search(words, lines[0], re.I):
        return "wrong", f"the error does not say {words!r}: {lines[0][:160]}"
    return "clear error", lines[0][:160]


def expect_ok_or_error(run: Run, ok_codes=(0, 1)) -> tuple[str, str]:
    """A case that may run (exit 0 / 1) or be refused with one clear error."""
    crash = crash_of(run)
    if crash:
        return crash
    if run.code == 2:
        return expect_error(run)
    if run.code in ok_codes:
        return "ok", f"exit {run.code}"
    return "wrong", f"exit {run.code}: {last_line(run.err)}"


def json_objects(text: str) -> list[Any]:
    """The JSON values printed one after another on stdout."""
    dec, i, out = json.JSONDecoder(), 0, []
    text = text.strip()
    while i < len(text):
        try:
            obj, j = dec.raw_decode(text, i)
        except ValueError:
            out.append(None)
            break
        out.append(obj)
        i = j
        while i < len(text) and text[i].isspace():
            i += 1
    return out


def first_object(run: Run) -> dict:
    """The first JSON object the command printed ({} when none)."""
    objs = json_objects(run.out)
    return objs[0] if objs and isinstance(objs[0], dict) else {}


# ----------------------------------------------------------------------------- a library call in a child
def in_child(fn: Callable[[], Any], *, timeout: float = 60, mem: int | None = 3 * GiB) -> tuple[str, Any]:
    """``fn()`` in a forked child under ``RLIMIT_AS``: ("return", its repr) | ("raise", (type names of
    its MRO, message)) | ("hang", None) | ("kill", signal)."""
    import multiprocessing as mp

    ctx = mp.get_context("fork")
    parent, child = ctx.Pipe(duplex=False)

    def target() -> None:
        if mem is not None:
            resource.setrlimit(resource.RLIMIT_AS, (mem, mem))
        try:
            value = fn()
            child.send(("return", repr(value)[:300]))
        except BaseException as exc:  # noqa: BLE001 - the harness reports every kind
            child.send(("raise", ([c.__name__ for c in type(exc).__mro__], str(exc)[:500])))

    p = ctx.Process(target=target, daemon=True)
    p.start()
    got = parent.poll(timeout)
    if got:
        result = parent.recv()
        p.join(10)
        return result
    if p.is_alive():
        p.kill()
        p.join()
        return "hang", None
    p.join()
    return "kill", p.exitcode


def expect_api_error(result: tuple[str, Any], argument: str) -> tuple[str, str]:
    """A library call whose contract is a WncsError naming ``argument``."""
    kind, value = result
    if kind == "hang":
        return "hang", "no answer"
    if kind == "kill":
        return "kill", f"exit {value}"
    if kind == "return":
        return "wrong", f"accepted: returned {value[:100]}"
    mro, message = value
    if "WncsError" not in mro:
        return "traceback", f"{mro[0]}: {message[:140]}"
    if argument not in message:
        return "wrong", f"{mro[0]} does not name {argument!r}: {message[:140]}"
    return "clear error", f"{mro[0]}: {message[:140]}"


# ----------------------------------------------------------------------------- the cases
@dataclasses.dataclass(frozen=True)
class Case:
    family: str
    name: str
    run: Callable[[Path], tuple[str, str]]


def scenario(name: str) -> str:
    return str(ROOT / "formulations" / f"{name}.toml")


P12 = scenario("paper_p12")
SMALL = [P12, "--set", "tau_cap=6"]


def _special_files(tmp: Path) -> dict[str, Path]:
    """A FIFO without a writer, devices, a folder, a 6 GB sparse file, an unreadable file."""
    files = {}
    fifo = tmp / "pipe.toml"
    if not fifo.exists():
        os.mkfifo(fifo)
    files["fifo"] = fifo
    npz_fifo = tmp / "pipe.npz"
    if not npz_fifo.exists():
        os.mkfifo(npz_fifo)
    files["fifo .npz"] = npz_fifo
    files["/dev/zero"] = Path("/dev/zero")
    files["/dev/urandom"] = Path("/dev/urandom")
    files["/dev/null"] = Path("/dev/null")
    folder = tmp / "folder.toml"
    folder.mkdir(exist_ok=True)
    files["folder"] = folder
    sparse = tmp / "sparse.toml"
    if not sparse.exists():
        with open(sparse, "wb") as f:
            f.truncate(6 * 10**9)
    files["6 GB sparse file"] = sparse
    zero_npz = tmp / "zero.npz"
    if not zero_npz.exists():
        zero_npz.symlink_to("/dev/zero")
    files["/dev/zero .npz"] = zero_npz
    return files


def special_file_cases() -> list[Case]:
    commands = {
        "validate": lambda f: ["validate", str(f)],
        "solve": lambda f: ["solve", str(f)],
        "bound": lambda f: ["bound", str(f)],
        "simulate": lambda f: ["simulate", str(f), "--policy", "greedy"],
    }
    cases = []
    for what in ("fifo", "/dev/zero", "/dev/urandom", "/dev/null", "folder", "6 GB sparse file"):
        for cname, argv in commands.items():
            cases.append(Case("special files", f"{cname} on {what}", lambda tmp, argv=argv, what=what: expect_error(
                cli(argv(_special_files(tmp)[what]), timeout=30, mem=2 * GiB))))
    for what in ("fifo .npz", "/dev/zero .npz"):
        for cname in ("evaluate", "simulate"):
            cases.append(Case("special files", f"{cname} --policy {what}", lambda tmp, what=what, cname=cname: expect_error(
                cli([cname, *SMALL, "--policy", str(_special_files(tmp)[what])], timeout=30, mem=2 * GiB))))
    return cases


# memory limits: the LP of processes 1-3 at cap 12 (paper_p123) peaks at ~3.8 GB on Clarabel; under an
# address-space limit of 2.2 GB the guard must refuse it (or pick a route that fits), never abort
LP_INSTANCE = [scenario("paper_p123"), "--set", "tau_cap=12"]
LP_LIMIT = int(2.2 * GiB)


def memory_limit_cases() -> list[Case]:
    cases = []
    for m in ("lp", "lp-highs", "lp-cvxpy", "auto"):
        cases.append(Case("memory limits", f"solve --method {m} under {LP_LIMIT / GiB:.1f} GB",
                          lambda tmp, m=m: expect_ok_or_error(cli(["solve", *LP_INSTANCE, "--method", m],
                                                                  timeout=600, mem=LP_LIMIT))))
    cases.append(Case("memory limits", f"evaluate --policy optimal --method lp under {LP_LIMIT / GiB:.1f} GB",
                      lambda tmp: expect_ok_or_error(cli(["evaluate", *LP_INSTANCE, "--policy", "optimal",
                                                          "--method", "lp"], timeout=600, mem=LP_LIMIT))))
    for reps in (10**9, 10**12):
        cases.append(Case("memory limits", f"simulate --reps {reps}", lambda tmp, reps=reps: expect_error(
            cli(["simulate", *SMALL, "--policy", "greedy", "--reps", str(reps), "--slots", "100"], timeout=60,
                mem=2 * GiB))))
    for slots in (10**13, 10**18):
        cases.append(Case("memory limits", f"simulate --slots {slots}", lambda tmp, slots=slots: expect_error(
            cli(["simulate", *SMALL, "--policy", "greedy", "--slots", str(slots)], timeout=60, mem=2 * GiB))))
    cases.append(Case("memory limits", "bound --untruncated --reps 10**12", lambda tmp: expect_error(
        cli(["bound", *SMALL, "--untruncated", "--reps", str(10**12)], timeout=60, mem=2 * GiB))))
    return cases


#: Long commands, the progress line after which they are stopped (1.5 s later; ``--progress`` is
#: given) or None, and then the seconds after the start they are stopped at (no ``--progress``: the
#: LP backends, which a progress callback would make interruptible where a plain run is not).
LONG_COMMANDS = {
    "solve --method lp": (["solve", scenario("preemption_p123_u0d0"), "--set", "tau_cap=6", "--method", "lp"],
                          None, 20),
    "solve --method lp-highs": (["solve", scenario("preemption_p123_u0d0"), "--set", "tau_cap=6", "--method",
                                 "lp-highs"], None, 20),
    "solve --method lp-cvxpy": (["solve", scenario("preemption_p123_u0d0"), "--set", "tau_cap=6", "--method",
                                 "lp-cvxpy"], None, 20),
    "solve --method vi": (["solve", scenario("paper_p123"), "--set", "tau_cap=22", "--method", "vi"], r"sweep", 1.5),
    "solve --method matrix-free": (["solve", scenario("paper_p1234"), "--set", "tau_cap=14", "--method",
                                    "matrix-free"], r"\[matrix-free\] [\d,]+ states", 1.5),
    "bound --relaxation 2": (["bound", scenario("bounds_mix6"), "--relaxation", "2"], r"bundle 1:", 1.5),
    "bound --policy": (["bound", scenario("lab_5sensors"), "--set", "tau_cap=10", "--policy", "--relaxation", "1"],
                       r"evaluat", 1.5),
    "evaluate --policy suboptimal --certify": (["evaluate", scenario("paper_p123"), "--set", "tau_cap=22",
                                                "--policy", "suboptimal", "--certify"], r"evaluating", 1.5),
    "simulate": (["simulate", P12, "--policy", "greedy", "--slots", "100000000"], r"simulat", 1.5),
    "sweep": (["sweep", P12, "--set", "tau_cap=9", "--values", "0.5:1:0.01", "--out", "sweep_stop", "--no-plot",
               "--policies", "optimal,suboptimal"], r"\d+/\d+", 1.5),
    # tolerances it cannot meet before cap 160: it would stop at the cap where it converges
    "capstudy": (["capstudy", P12, "--caps", "10:160:2", "--method", "vi", "--gain-rtol", "1e-15", "--mass-tol",
                  "1e-15"], None, 8),
}


def signal_cases(variants: tuple[tuple[int, bool], ...] | None = None) -> list[Case]:
    variants = variants or ((signal.SIGINT, False), (signal.SIGTERM, False), (signal.SIGINT, True),
                            (signal.SIGTERM, True))
    cases = []
    for name, (argv, pattern, delay) in LONG_COMMANDS.items():
        for signum, as_json in variants:
            label = f"{signal.Signals(signum).name} during {name}{' --json' if as_json else ''}"
            cases.append(Case("signals", label, lambda tmp, argv=argv, pattern=pattern, delay=delay, signum=signum,
                              as_json=as_json: expect_stop(argv, pattern, delay, signum, as_json, tmp)))
    return cases


def expect_stop(argv: list[str], pattern: str | None, delay: float, signum: int, as_json: bool,
                tmp: Path) -> tuple[str, str]:
    """SIGINT / SIGTERM stop the command within 10 s: exit 130 / 143, the one line saying so
    (besides the progress lines), with --json one object ``"interrupted": true``."""
    work = tmp / f"stop_{abs(hash((tuple(argv), signum, as_json)))}"
    work.mkdir(exist_ok=True)
    stop = (pattern, delay, signum)
    run = cli([*argv, *(["--progress"] if pattern else []), *(["--json"] if as_json else [])], timeout=240,
              mem=3 * GiB, stop=stop, cwd=work)
    want = 130 if signum == signal.SIGINT else 143
    if run.signalled is None:
        crash = crash_of(run)
        return crash if crash else ("wrong", f"finished (exit {run.code}) before the signal: a longer instance "
                                              "is needed")
    crash = crash_of(run)
    if crash:
        return crash[0], f"{crash[1]} ({run.stopped_in:.1f} s after the signal)"
    if run.code != want:
        return "wrong", f"exit {run.code} (expected {want}) {run.stopped_in:.1f} s after the signal: " \
            + last_line(run.err)
    said = [ln for ln in run.err.splitlines() if re.search(r"interrupted|terminated", ln)]
    if len(said) != 1:
        return "wrong", f"{len(said)} lines say it stopped"
    if as_json:
        objs = json_objects(run.out)
        if len(objs) != 1 or not isinstance(objs[0], dict) or objs[0].get("interrupted") is not True:
            return "wrong", f"stdout holds {len(objs)} JSON value(s), not one object with interrupted: true"
    return "ok", f"exit {run.code} {run.stopped_in:.1f} s after the signal"


def json_contract_cases() -> list[Case]:
    cases = []
    for name, argv in {
        "validate": ["validate", P12],
        "solve": ["solve", *SMALL],
        "bound": ["bound", *SMALL],
        "simulate": ["simulate", *SMALL, "--policy", "greedy", "--slots", "2000"],
        "evaluate": ["evaluate", *SMALL, "--policy", "static"],
    }.items():
        # the reader closes stdout before the command writes (a reader that takes 10 bytes of a
        # short output may close after the one write: nothing would be tested)
        cases.append(Case("JSON contract", f"{name} --json | head -c 0", lambda tmp, argv=argv: expect_quiet_pipe(
            cli([*argv, "--json"], head=0, timeout=120))))
    return cases


def expect_quiet_pipe(run: Run) -> tuple[str, str]:
    """The reader went away: the command ends without a word about it (the scenario's warnings,
    printed before the output, may stand)."""
    crash = crash_of(run)
    if crash:
        return crash
    said = [ln for ln in run.err.splitlines() if ln.strip() and not ln.startswith("warning: ")]
    if said:
        return "wrong", "stderr: " + said[-1][:160]
    return "ok", f"exit {run.code}, nothing on stderr but the scenario's warnings"


#: Numeric options out of range or not finite: each must be argparse's usage error (exit 2).
BAD_OPTIONS = [
    ["bound", *SMALL, "--tol", "-1"], ["bound", *SMALL, "--tol", "nan"], ["bound", *SMALL, "--tol", "inf"],
    ["bound", *SMALL, "--tol", "0"],
    ["bound", *SMALL, "--time-limit", "-1"], ["bound", *SMALL, "--time-limit", "nan"],
    ["bound", *SMALL, "--max-steps", "0"], ["bound", *SMALL, "--exact-max-states", "-1"],
    ["bound", *SMALL, "--slots", "-1"], ["bound", *SMALL, "--reps", "0"], ["bound", *SMALL, "--burn-in", "-1"],
    ["simulate", *SMALL, "--policy", "greedy", "--slots", "-1"],
    ["simulate", *SMALL, "--policy", "greedy", "--slots", "0"],
    ["simulate", *SMALL, "--policy", "greedy", "--reps", "-5"],
    ["simulate", *SMALL, "--policy", "greedy", "--seed", "-1"],
    ["simulate", *SMALL, "--policy", "greedy", "--burn-in", "-1"],
    ["solve", *SMALL, "--untruncated", "--slots", "-1"], ["solve", *SMALL, "--discount", "nan"],
    ["solve", *SMALL, "--discount", "1"], ["solve", *SMALL, "--discount", "-0.5"],
    ["map", *SMALL, "--servers", "idle", "--out", "m.png", "--dpi", "0"],
    ["map", *SMALL, "--servers", "idle", "--out", "m.png", "--dpi", "100000"],
    ["map", *SMALL, "--servers", "idle", "--out", "m.png", "--slice", "-3"],
    ["capstudy", *SMALL, "--mass-tol", "nan"], ["capstudy", *SMALL, "--mass-tol", "-1"],
    ["capstudy", *SMALL, "--gain-rtol", "inf"],
    ["evaluate", *SMALL, "--policy", "static", "--horizon", "-1"],
    ["sweep", *SMALL, "--values", "0.8", "--out", "sw", "--simulate-slots", "-1"],
    ["sweep", *SMALL, "--values", "0.8", "--out", "sw", "--max-workers", "0"],
    ["sweep", *SMALL, "--values", "0.8", "--out", "sw", "--reps", "0", "--simulate-slots", "100"],
    ["verify", *SMALL, "--atol", "nan"], ["verify", *SMALL, "--examples", "-1"],
    ["tradeoff", scenario("paper_p12_cloud_budget"), "--set", "tau_cap=6", "--max-workers", "-2"],
]


def cli_option_cases() -> list[Case]:
    return [Case("CLI options", " ".join(a for a in argv if a not in SMALL), lambda tmp, argv=argv: expect_error(
        cli(argv, timeout=60, cwd=tmp), usage=True)) for argv in BAD_OPTIONS]


def _system_of(name: str, overrides: list[str]):
    from wncs_lp import load_scenario
    from wncs_lp.models.system import System

    return System.from_scenario(load_scenario(scenario(name), overrides))


def _system():
    return _system_of("paper_p12", ["tau_cap=6"])


def policy_factory():
    """``make_policy`` where the code under test keeps it (``wncs_lp.workflow``; before it moved,
    ``wncs_lp.policies``)."""
    try:
        from wncs_lp.workflow import make_policy
    except ImportError:
        from wncs_lp.policies import make_policy
    return make_policy


def _greedy():
    make_policy = policy_factory()

    return make_policy("greedy", _system())


#: Library calls with one bad argument: (the argument the error must name, the call).
BAD_CALLS: list[tuple[str, str, Callable[[], Any]]] = []


def _bad(argument: str, label: str):
    def register(fn):
        BAD_CALLS.append((argument, label, fn))
        return fn

    return register


def _sim(**kw):
    from wncs_lp.simulate import simulate

    return simulate(_greedy(), **{"slots": 50, "reps": 2, **kw})


for _kw, _arg in (({"slots": 2.5}, "slots"), ({"slots": "100"}, "slots"), ({"slots": -1}, "slots"),
                  ({"slots": float("nan")}, "slots"), ({"reps": 0}, "reps"), ({"reps": 10**12}, "reps"),
                  ({"reps": 1.5}, "reps"), ({"seed": "x"}, "seed"), ({"seed": -1}, "seed"),
                  ({"seed": 2.5}, "seed"), ({"burn_in": -1}, "burn_in"), ({"burn_in": None}, "burn_in"),
                  ({"slots": 10**15}, "slots"), ({"initial_tau": "abc"}, "initial_tau")):
    _bad(_arg, f"simulate({', '.join(f'{k}={v!r}' for k, v in _kw.items())})")(lambda kw=_kw: _sim(**kw))


@_bad("foo", "lower_bound(system, 1, foo=1)")
def _lb_foo():
    from wncs_lp.bounds import lower_bound

    return lower_bound(_system(), 1, foo=1)


@_bad("tol", "lower_bound(system, 1, tol=-1)")
def _lb_tol():
    from wncs_lp.bounds import lower_bound

    return lower_bound(_system(), 1, tol=-1.0)


@_bad("tol", "lower_bound(system, 1, tol=nan)")
def _lb_tol_nan():
    from wncs_lp.bounds import lower_bound

    return lower_bound(_system(), 1, tol=float("nan"))


@_bad("relaxation", "lower_bound(system, 7)")
def _lb_relax():
    from wncs_lp.bounds import lower_bound

    return lower_bound(_system(), 7)


@_bad("system", "lower_bound(42)")
def _lb_system():
    from wncs_lp.bounds import lower_bound

    return lower_bound(42)


@_bad("system", "make_policy('greedy', None)")
def _mp_none():
    make_policy = policy_factory()

    return make_policy("greedy", None)


@_bad("system", "make_policy('suboptimal', 'paper_p12')")
def _mp_str():
    make_policy = policy_factory()

    return make_policy("suboptimal", "paper_p12")


@_bad("name", "make_policy(3, system)")
def _mp_name():
    make_policy = policy_factory()

    return make_policy(3, _system())


@_bad("method", "wncs_lp.solve(scenario, method=5)")
def _solve_method():
    import wncs_lp

    return wncs_lp.solve(wncs_lp.load_scenario(P12, ["tau_cap=5"]), method=5)


@_bad("tol", "wncs_lp.solve(mdp, method='vi', tol=-1)")
def _solve_tol():
    import wncs_lp

    mdp = wncs_lp.build(wncs_lp.load_scenario(P12, ["tau_cap=5"]))
    return wncs_lp.solve(mdp, method="vi", tol=-1.0)


@_bad("caps", "cap_study(scenario, caps=[0, 5])")
def _capstudy():
    import wncs_lp
    from wncs_lp.studies import cap_study

    return cap_study(wncs_lp.load_scenario(P12), [0, 5])


@_bad("mass_tol", "cap_study(scenario, [10, 12], mass_tol=nan)")
def _capstudy_tol():
    import wncs_lp
    from wncs_lp.studies import cap_study

    return cap_study(wncs_lp.load_scenario(P12), [10, 12], mass_tol=float("nan"))


@_bad("slots", "policy_gaps(bound, system, slots=-5)")
def _gaps_slots():
    from wncs_lp.bounds import lower_bound, policy_gaps

    sysm = _system()
    return policy_gaps(lower_bound(sysm, 1), sysm, ["bound"], exact=False, slots=-5, reps=2)


def api_cases() -> list[Case]:
    return [Case("API arguments", label, lambda tmp, arg=arg, fn=fn: expect_api_error(in_child(fn, timeout=60), arg))
            for arg, label, fn in BAD_CALLS]


# ----------------------------------------------------------------------------- edited files
def _mf_saved(tmp: Path):
    """A matrix-free solve of paper_p12 at cap 8 saved with its bias, and the system."""
    from wncs_lp import load_scenario
    from wncs_lp.models.system import System
    from wncs_lp.solvers.matrix_free import matrix_free_value_iteration

    sysm = System.from_scenario(load_scenario(P12, ["tau_cap=8"]))
    path = tmp / "mf_solution.npz"
    if not path.exists():
        matrix_free_value_iteration(sysm, threads=1).save(path, bias=True)
    return path, sysm


def _edit_npz(src: Path, dst: Path, edit: Callable[[dict], None]) -> None:
    import io

    import numpy as np

    with np.load(src, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    edit(arrays)
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    dst.write_bytes(buf.getvalue())


def _other_valid_actions(arrays: dict, fraction: float, seed: int) -> None:
    """Replace a fraction of the policy's entries by another valid action of the same state."""
    import numpy as np

    pol = arrays["policy"].copy()
    rng = np.random.default_rng(seed)
    alt = (pol + 1) % 2  # every configuration of paper_p12 with more than one action takes 0 or 1 at least
    pick = rng.random(pol.size) < fraction
    pol[pick] = alt[pick]
    arrays["policy"] = pol


EDITS = {
    "policy: 5% of states to another action": lambda a: _other_valid_actions(a, 0.05, 1),
    "policy: 50% of states to another action": lambda a: _other_valid_actions(a, 0.5, 2),
    "policy: every entry 0": lambda a: a.__setitem__("policy", a["policy"] * 0),
    "bias scaled by 2": lambda a: a.__setitem__("bias", a["bias"] * 2),
    "bias shifted in one state": lambda a: a["bias"].__setitem__(5, a["bias"][5] + 100.0),
    "meta: certificate narrowed to the gain": lambda a: a.__setitem__("meta", _meta_edit(a["meta"], narrow=True)),
    "meta: gain moved inside the certificate": lambda a: a.__setitem__("meta", _meta_edit(a["meta"], shift=True)),
    "meta: status optimal with a wide certificate": lambda a: a.__setitem__("meta", _meta_edit(a["meta"], wide=True)),
    "policy to another action, the digest removed": lambda a: (_other_valid_actions(a, 0.2, 3),
                                                                a.__setitem__("meta", _meta_edit(a["meta"], drop=True))),
}


def _meta_edit(raw, narrow=False, shift=False, wide=False, drop=False):
    import numpy as np

    meta = json.loads(str(raw))
    if drop:
        meta.pop("digest", None)
    if narrow:
        meta["gain_lower"] = meta["gain_upper"] = meta["gain"]
    if shift:
        meta["gain"] = meta["gain_lower"]
    if wide:
        meta["gain_lower"], meta["gain_upper"], meta["status"] = meta["gain"] - 50, meta["gain"] + 50, "optimal"
    return np.array(json.dumps(meta))


def check_edited_solution(tmp: Path, edit: str) -> tuple[str, str]:
    """A saved matrix-free solution edited: refused, or loaded with a certificate that holds for
    its policy (its gain, evaluated independently on the enumerated MDP, inside [lower, upper])
    and a status "optimal" only when the interval is closed around g*."""
    def body():
        import numpy as np

        import wncs_lp
        from wncs_lp.errors import WncsError
        from wncs_lp.evaluate import evaluate
        from wncs_lp.solvers.matrix_free import load_solution

        path, sysm = _mf_saved(tmp)
        bad = tmp / "mf_edited.npz"
        _edit_npz(path, bad, EDITS[edit])
        try:
            back = load_solution(bad, sysm)
        except WncsError as exc:
            return "clear error", str(exc)[:160]
        mdp = wncs_lp.build(sysm.scenario)
        ref = wncs_lp.solve(mdp, method="pi")
        true = evaluate(mdp, back.on_mdp(mdp).policy).gain
        tol = 1e-7 * abs(true)
        if back.status.ok and not (back.gain_lower - tol <= true <= back.gain_upper + tol
                                   and back.gain_lower - tol <= ref.gain <= back.gain_upper + tol
                                   and back.gain_upper - back.gain_lower <= 1e-5 * abs(true)):
            return "wrong", (f"loaded as {back.status} with [{back.gain_lower:.7g}, {back.gain_upper:.7g}] "
                             f"while its policy's gain is {true:.7g} (g* {ref.gain:.7g})")
        if not back.status.ok and not np.isfinite(back.gain):
            return "wrong", "not finite"
        return "ok", f"loaded as {back.status}, policy gain {true:.7g} in its certificate"

    return _outcome_of(in_child(body, timeout=240))


def _outcome_of(result) -> tuple[str, str]:
    kind, value = result
    if kind == "return":
        label, detail = eval(value)  # noqa: S307 - the repr of a (str, str) tuple from our own child
        return label, detail
    if kind == "raise":
        return "traceback", f"{value[0][0]}: {value[1][:140]}"
    return kind, str(value)


def edited_file_cases() -> list[Case]:
    return [Case("edited files", name, lambda tmp, name=name: check_edited_solution(tmp, name)) for name in EDITS]


# ----------------------------------------------------------------------------- edited systems
def check_edited_system(what: str) -> tuple[str, str]:
    """A System edited by hand (``dataclasses.replace``) given to the bounds and the policies:
    its edit honoured (the same result as the scenario that says the same) or refused by name."""
    def body():
        import dataclasses as dc

        import numpy as np

        import wncs_lp
        from wncs_lp.bounds import lower_bound
        from wncs_lp.errors import WncsError
        from wncs_lp.models.system import System
        make_policy = policy_factory()
        from wncs_lp.simulate import simulate

        sc = wncs_lp.load_scenario(P12, ["tau_cap=7"])
        sysm = System.from_scenario(sc)
        table = [list(np.asarray(q, float) * 3.0) for q in sysm.q]
        edited_sc = wncs_lp.load_scenario(P12, ["tau_cap=7", *(f"process.{k + 1}.cost={json.dumps(t)}"
                                                               for k, t in enumerate(table))])
        try:
            edited = dc.replace(sysm, q=tuple(np.asarray(t) for t in table))
        except WncsError as exc:
            return "clear error", str(exc)[:160]
        truth_sys = System.from_scenario(edited_sc)
        try:
            if what.startswith("lower_bound"):
                rel = int(what[-1])
                got, want = lower_bound(edited, rel).lower_bound, lower_bound(truth_sys, rel).lower_bound
            elif what == "simulate greedy":
                got = simulate(make_policy("greedy", edited), slots=3000, reps=4, seed=1).mean
                want = simulate(make_policy("greedy", truth_sys), slots=3000, reps=4, seed=1).mean
            else:
                got = simulate(make_policy("suboptimal", edited), slots=3000, reps=4, seed=1).mean
                want = simulate(make_policy("suboptimal", truth_sys), slots=3000, reps=4, seed=1).mean
        except WncsError as exc:
            return "clear error", str(exc)[:160]
        if abs(got - want) > 1e-6 * abs(want):
            return "wrong", f"{got:.8g} where the scenario with those costs gives {want:.8g}"
        return "ok", f"{got:.8g} (honoured)"

    return _outcome_of(in_child(body, timeout=240))


def edited_system_cases() -> list[Case]:
    return [Case("edited systems", f"costs x3 by dataclasses.replace: {w}", lambda tmp, w=w: check_edited_system(w))
            for w in ("lower_bound 1", "lower_bound 3", "simulate greedy", "simulate suboptimal")]


# ----------------------------------------------------------------------------- labels
#: paper_p12 with reliable links and a cost of 1e13 at AoI 16 of process 1: value iteration stops
#: at the round-off band at cap 16 (status inaccurate:precision), not at cap 15
HUGE_AT_16 = ["--set", "p=0.99", "--set", "process.1.cost=[1,2,3,4,5,6,7,8,9,10,11,12,13,14,15,1e13]"]
VI_INACCURATE = [P12, "--set", "tau_cap=16", *HUGE_AT_16]


def label_cases() -> list[Case]:
    def solve_status(tmp):
        run = cli(["solve", *VI_INACCURATE, "--method", "vi", "--json"], timeout=600, cwd=tmp)
        objs = json_objects(run.out)
        return run, (objs[0].get("status") if objs and isinstance(objs[0], dict) else None)

    def evaluate_case(tmp):
        ref, status = solve_status(tmp)
        run = cli(["evaluate", *VI_INACCURATE, "--policy", "optimal", "--method", "vi", "--json"], timeout=600,
                  cwd=tmp)
        crash = crash_of(run)
        if crash:
            return crash
        doc = first_object(run)
        if status == "optimal":
            return "ok", "the solve certified (no inaccurate solve to label)"
        label = json.dumps(doc.get("policy_info", {})) + json.dumps(doc.get("policy_status"))
        if run.code == 0 or status not in label:
            return "wrong", f"evaluate exit {run.code}, no {status!r} said, where solve says {status} (exit {ref.code})"
        return "ok", f"evaluate says {status}, exit {run.code}"

    def capstudy_case(tmp):
        run = cli(["capstudy", P12, *HUGE_AT_16, "--caps", "15,16", "--method", "vi", "--json"], timeout=900,
                  cwd=tmp)
        crash = crash_of(run)
        if crash:
            return crash
        doc = first_object(run)
        rows = doc.get("rows", [])
        if not rows or any("status" not in r for r in rows):
            return "wrong", f"rows without the status of their solve (cap 16's is not certified), exit {run.code}"
        uncertified = [r for r in rows if str(r.get("status")) != "optimal"]
        if doc.get("converged") and uncertified:
            return "wrong", "converged although a cap's solve is not certified"
        return "ok", f"converged={doc.get('converged')}, statuses {[r['status'] for r in rows]}, exit {run.code}"

    def sweep_case(tmp):
        out = tmp / "sweep_labels"
        run = cli(["sweep", *VI_INACCURATE, "--values", "0.99", "--policies", "optimal", "--method",
                   "vi", "--out", str(out), "--no-plot", "--json"], timeout=900, cwd=tmp)
        crash = crash_of(run)
        if crash:
            return crash
        objs = json_objects(run.out)
        rows = (objs[0] or {}).get("rows", []) if objs and isinstance(objs[0], dict) else []
        bad = [r for r in rows if r.get("policy") == "optimal" and str(r.get("status")) == "ok"
               and run.code == 0 and not r.get("certified", True)]
        statuses = {str(r.get("status")) for r in rows}
        if run.code == 0 and statuses <= {"ok", "optimal"} and rows:
            return "wrong", f"sweep rows {sorted(statuses)} with exit 0 where the solve is not certified"
        return "ok", f"rows {sorted(statuses)}, exit {run.code}" + (" (labelled rows)" if not bad else "")

    return [Case("labels", "evaluate --policy optimal --method vi (inaccurate solve)", evaluate_case),
            Case("labels", "capstudy --method vi (inaccurate solves)", capstudy_case),
            Case("labels", "sweep --method vi (inaccurate solve)", sweep_case)]


# ----------------------------------------------------------------------------- caches
def check_cache(kind: str) -> tuple[str, str]:
    def body():
        import shutil

        import numpy as np

        from wncs_lp.reproduce.cache import StepCache

        folder = Path(tempfile.mkdtemp(prefix="cache_case_"))
        cache = StepCache(folder)
        truth = ({"gain": 1.5, "mse": [1.0, 0.5]}, {"x": np.arange(3.0)})
        other = ({"gain": 9.5, "mse": [4.0, 5.5]}, {"x": np.arange(4.0)})
        params, foreign = {"fingerprint": "A", "policy": "static"}, {"fingerprint": "B", "policy": "static"}
        jpath, npath = cache._paths(cache.key("evaluate", params))
        fj, fn = cache._paths(cache.key("evaluate", foreign))
        if kind.startswith("replaced by a folder"):
            target = jpath if "json" in kind else npath
            cache.store("evaluate", params, *truth)
            target.unlink()
            target.mkdir()
            (target / "x").write_text("x")
        elif kind == "re-keyed from another scenario (files renamed)":
            cache.store("evaluate", foreign, *other)
            shutil.copy(fj, jpath)
            shutil.copy(fn, npath)
        elif kind == "re-keyed from another scenario (key and checksum rewritten)":
            cache.store("evaluate", foreign, *other)
            doc = json.loads(fj.read_text())
            key = cache.key("evaluate", params)
            doc["key"] = key
            doc["checksum"] = StepCache.checksum(key, doc["result"], {"x": np.arange(4.0)})
            jpath.write_text(json.dumps(doc))
            shutil.copy(fn, npath)
        calls = []

        def compute():
            calls.append(1)
            return truth

        try:
            res, arrays = cache.get_or_compute("evaluate", params, compute)
        except Exception as exc:  # noqa: BLE001
            return "traceback", f"{type(exc).__name__}: {exc}"[:160]
        if res != truth[0] or not np.array_equal(arrays["x"], truth[1]["x"]):
            return "wrong", f"another scenario's result trusted: {res}"
        # and the next run reads a good entry (or recomputes again), never fails
        try:
            res2, _ = StepCache(folder).get_or_compute("evaluate", params, compute)
        except Exception as exc:  # noqa: BLE001
            return "traceback", f"second run: {type(exc).__name__}: {exc}"[:160]
        return ("ok", f"recomputed ({len(calls)} computes)") if res2 == truth[0] else ("wrong", f"{res2}")

    return _outcome_of(in_child(body, timeout=60))


def cache_cases() -> list[Case]:
    return [Case("caches", k, lambda tmp, k=k: check_cache(k)) for k in (
        "replaced by a folder (json)", "replaced by a folder (npz)", "re-keyed from another scenario (files renamed)",
        "re-keyed from another scenario (key and checksum rewritten)")]


# ----------------------------------------------------------------------------- messages
def message_cases() -> list[Case]:
    def auto_reason(tmp):
        def body():
            from wncs_lp.bounds import joint

            joint.REACH_MAX_NNZ = 1_000  # the 6-process mix's LP is larger: the rule must say so
            return joint.joint_reach(_system_of("bounds_mix6", []))

        kind, value = in_child(body, timeout=120)
        if kind != "return":
            return _outcome_of((kind, value))
        m = re.search(r"([\d,]+) *(<=|>|<|>=) *([\d,]+)", value)
        if m and (int(m.group(1).replace(",", "")) > int(m.group(3).replace(",", ""))) == (m.group(2) in ("<=", "<")):
            return "wrong", f"says {m.group(0)}"
        return "ok", value[:160]

    def control_name(tmp):
        path = tmp / "ctl.toml"
        text = (ROOT / "formulations" / "paper_p12.toml").read_text()
        path.write_text(text.replace('name = "process-1"', 'name = "a\\nb\\u001b[31m"', 1))
        outcomes = []
        for extra in ([], ["--set", "process.1.weight=-2"]):  # warnings naming it; an error naming it
            run = cli(["validate", str(path), "--set", "tau_cap=5", *extra], timeout=60, cwd=tmp)
            crash = crash_of(run)
            if crash:
                return crash
            stray = [ln for ln in run.err.splitlines() if not re.match(r"^(warning|error): ", ln)]
            if stray or "\x1b" in run.err + run.out:
                return "wrong", f"{len(stray)} stderr line(s) that are not a warning or an error" + \
                    (", an escape sequence printed raw" if "\x1b" in run.err + run.out else "")
            outcomes.append(run.code)
        return "ok", f"exits {outcomes}, every line whole, no escape sequence printed"

    def map_npz(tmp):
        sol = tmp / "sol.npz"
        cli(["solve", *SMALL, "--out", str(sol)], timeout=120, cwd=tmp)
        run = cli(["map", *SMALL, "--servers", "idle", "--policy", str(sol), "--out", str(tmp / "m.png")],
                  timeout=120, cwd=tmp)
        crash = crash_of(run)
        if crash:
            return crash
        if run.code != 0:
            return "wrong", f"exit {run.code}: {last_line(run.err)}"
        return "ok", "map draws the saved policy"

    return [Case("messages", "auto's reason when the LP's nonzeros exceed the limit", auto_reason),
            Case("messages", "a process name with a newline and an escape sequence", control_name),
            Case("messages", "map --policy FILE.npz", map_npz)]


FAMILIES: dict[str, Callable[[], list[Case]]] = {
    "special files": special_file_cases,
    "memory limits": memory_limit_cases,
    "signals": signal_cases,
    "JSON contract": json_contract_cases,
    "CLI options": cli_option_cases,
    "API arguments": api_cases,
    "edited files": edited_file_cases,
    "edited systems": edited_system_cases,
    "labels": label_cases,
    "caches": cache_cases,
    "messages": message_cases,
}
