"""Shared by the whole suite: the quick reproduction, computed once per run; no files left in
the repository.

``wncs-lp reproduce --profile quick`` is the suite's most expensive step (here with its sections
beyond the paper on small settings, :data:`SMALL_SECTIONS`). One run serves both the
interruption test (Ctrl-C after three cached steps, then a resumed run) and the report's tests
(they read the resumed run's report, which must be the whole report). Under pytest-xdist every
test that uses it is kept on one worker (``xdist_group``), so it is computed once.
"""
from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import pytest
from hypothesis import settings
from hypothesis.configuration import set_hypothesis_home_dir

# numba's parallel kernels run on GNU OpenMP, whose idle threads spin (not sleep) while they wait
# at a loop's end. Under ``-n 2`` the other worker holds a core, so a kernel's two threads take
# turns on one: a spinning thread burns the slice its partner needs (the threads test took 30 s
# beside two busy processes, 10 s with passive waiting). Inherited by every subprocess the tests
# start; set before any parallel kernel loads the OpenMP runtime. Results do not depend on it.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

# Hypothesis would keep its example database and its cache of constants in .hypothesis/ of the
# working folder (the repository): no database (the fuzz tests print any falsifying example),
# the rest in a temporary folder removed at the end of the run
settings.register_profile("wncs_lp", database=None)
settings.load_profile("wncs_lp")
_HYPOTHESIS_HOME = tempfile.mkdtemp(prefix="wncs_lp-hypothesis-")
set_hypothesis_home_dir(_HYPOTHESIS_HOME)


def pytest_unconfigure(config):
    shutil.rmtree(_HYPOTHESIS_HOME, ignore_errors=True)


QUICK_GROUP = "quick_reproduction"


def _shares_a_module_fixture(item) -> bool:
    """Whether ``item`` uses a module- or class-scoped fixture of the suite (computed once per
    module on each worker that runs one of the module's tests)."""
    defs = getattr(getattr(item, "_fixtureinfo", None), "name2fixturedefs", {})
    return any(d[-1].scope in ("module", "class", "package") and d[-1].baseid for d in defs.values() if d)


@pytest.hookimpl(tryfirst=True)  # before xdist's worker reads the groups
def pytest_collection_modifyitems(config, items):
    """Under pytest-xdist (``-n 2``, loadgroup scheduling, see below) the tests that share an
    expensive fixture stay on one worker, so it is computed once: the quick reproduction's tests
    in one group, run first (the longest unit of work, started while the other worker takes the
    rest), and the tests of a module with a module-scoped fixture in one group per module. The
    tests marked ``slow`` (and their module's group) come next: the workers take units in this
    order, so the longest ones start early and none is left running alone at the end."""
    quick = [i for i in items if "quick_reproduction" in getattr(i, "fixturenames", ())]
    for item in quick:
        item.add_marker(pytest.mark.xdist_group(QUICK_GROUP))
    for item in items:
        if item not in quick and _shares_a_module_fixture(item):
            item.add_marker(pytest.mark.xdist_group(item.nodeid.split("::")[0]))
    first = {id(i) for i in quick}
    slow = [i for i in items if id(i) not in first and i.get_closest_marker("slow") is not None]
    first |= {id(i) for i in slow}
    items[:] = quick + slow + [i for i in items if id(i) not in first]


class _GroupNames:
    """pytest-xdist's worker marks a grouped test by appending ``@group`` to its node id, but
    pytest 9.2 keeps the id in ``_id`` where xdist (3.8) writes ``_nodeid``: here it is done for
    any grouped test still unnamed, so the groups hold on either."""

    @pytest.hookimpl(trylast=True)
    def pytest_collection_modifyitems(self, config, items):
        for item in items:
            groups = sorted({str(m.args[0]) for m in item.iter_markers("xdist_group") if m.args})
            if groups and "@" not in item.nodeid.rsplit("::", 1)[-1]:
                new = f"{item.nodeid}@{'_'.join(groups)}"
                if hasattr(item, "_id"):
                    from _pytest.nodeid import coerce_node_id

                    item._id = coerce_node_id(new)
                else:
                    item._nodeid = new


def ctrl_c_default() -> None:
    """In the child before exec: Ctrl-C's default action. A test run started in the background by
    a non-interactive shell (``cmd &``) inherits SIGINT ignored, and Python then installs no
    KeyboardInterrupt handler: the child would never see the Ctrl-C these tests send."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


@dataclass(frozen=True)
class QuickReproduction:
    """What the interrupted-then-resumed quick reproduction left: ``out`` its folder; the
    interrupted run's exit code and the cache entries it kept (name -> text); the resumed run's
    exit code, stderr, printed JSON and its ``report.json`` as written (later tests may rerun
    into ``out``)."""

    out: Path
    interrupted_code: int | None
    kept: dict
    code: int
    stderr: str
    printed: dict | None
    report: dict | None


#: ``wncs-lp reproduce`` (the CLI's own ``main``: its exit codes, Ctrl-C and ``--json``) with the
#: quick profile's claims as they are and its sections beyond the paper (B1-B3, more than half of
#: the quick run's time) on the small settings their own tests check against independent routes
#: (tests/reproduce/test_beyond.py, test_fullscale.py, test_beyond_exact.py): here they need only
#: be computed and rendered into the whole report.
SMALL_SECTIONS = """
import sys
from wncs_lp.reproduce import beyond, beyondexact, fullscale
beyond.SETTINGS["quick"] = beyond.BeyondSettings(caps=(5, 6), values=(0.0, 0.05, 0.1, 0.15, 0.2, 0.25, 0.3))
fullscale.SETTINGS["quick"] = fullscale.FullScaleSettings(caps=(6,), sweep_cap=6, p_grid=(0.8, 0.9))
beyondexact.SETTINGS["quick"] = beyondexact.BeyondExactSettings(
    (beyondexact.Instance(beyondexact.FOUR, 6, True), beyondexact.Instance("bounds_mix6.toml", 3, False)),
    slots=3_000, reps=4, burn_in=200, steps=3)
from wncs_lp.cli import main
sys.exit(main(sys.argv[1:]))
"""


@pytest.fixture(scope="session")
def quick_reproduction(tmp_path_factory) -> QuickReproduction:
    out = tmp_path_factory.mktemp("quick") / "repro"
    cmd = [sys.executable, "-c", SMALL_SECTIONS, "reproduce", "--out", str(out), "--profile", "quick"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, preexec_fn=ctrl_c_default)
    cache = out / "cache"
    deadline = time.time() + 600  # generous: guards a hang, not a speed (a loaded 2-core machine is slow)
    while (not cache.exists() or len(list(cache.glob("*.json"))) < 3) and time.time() < deadline:
        time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    try:
        proc.communicate(timeout=120)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.communicate()
    kept = {p.name: p.read_text() for p in cache.glob("*.json")}
    done = subprocess.run(cmd + ["--json"], capture_output=True, text=True, timeout=1800)
    printed = report = None
    if done.returncode == 0:
        printed = json.loads(done.stdout)
        report = json.loads((out / "report.json").read_text())
    return QuickReproduction(out, proc.returncode, kept, done.returncode, done.stderr, printed, report)


def pytest_configure(config):
    """``-n 2`` schedules by ``xdist_group`` (``--dist loadgroup``): the groups made in
    :func:`pytest_collection_modifyitems` are kept on one worker, the other tests go one by one.
    A worker parses the command line again, so it learns of the switch from its controller
    (:func:`pytest_configure_node`)."""
    if getattr(config.option, "dist", "no") == "load" and getattr(config.option, "tx", None):
        config.option.dist = "loadgroup"
        config.option.loadscopereorder = False  # the collection's order: the quick group first
    if getattr(config, "workerinput", {}).get("wncs_loadgroup"):
        config.option.loadgroup = True  # xdist's worker then names each grouped test's group
        config.pluginmanager.register(_GroupNames(), "wncs_lp_group_names")


@pytest.hookimpl(optionalhook=True)
def pytest_configure_node(node):
    node.workerinput["wncs_loadgroup"] = node.config.option.dist == "loadgroup"


def pytest_sessionstart(session):
    """On a cold numba cache (a fresh clone) and before xdist starts its workers (its own
    ``pytest_sessionstart`` runs last): compile the kernels once, in two processes side by side
    (tests/prewarm_kernels.py), instead of in every worker and subprocess that reaches them first.
    A failure here only costs the time: the tests then compile what they need themselves."""
    if hasattr(session.config, "workerinput") or getattr(session.config.option, "numprocesses", None) in (None, 0):
        return
    import wncs_lp

    package = Path(wncs_lp.__file__).parent
    if sum(1 for _ in package.rglob("*.nbi")) >= PREWARMED_INDEXES:
        return
    script = Path(__file__).with_name("prewarm_kernels.py")
    procs = [subprocess.Popen([sys.executable, str(script), part], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
             for part in ("solvers", "bounds")]
    for proc in procs:
        try:
            proc.wait(timeout=300)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


#: Cache index files (one per compiled kernel) the prewarm leaves; with as many, it is skipped.
PREWARMED_INDEXES = 20
