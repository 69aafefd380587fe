"""Fuzz the toolkit's inputs with generated hostile cases and report the counts.

    python benchmarks/fuzz_scenarios.py [--cases 2000] [--npz-cases 400] [--cache-cases 2000] [--system-cases 120]
                                        [--sweep-cases 60]

Families and their contracts (any other outcome is a bug, re-raised with the failing example,
which hypothesis shrinks):

* scenarios (valid / mutated dicts and TOML files, random bytes, overrides, hostile overrides in
  every form: list, one string, mapping): they load, or raise a ScenarioError naming a field;
* npz files (an exported MDP, policy and solution with flipped bytes, truncated, or with one
  entry replaced, shifted, permuted or deleted): they load, or raise one WncsError naming the
  file; a loaded MDP is solved by value iteration and the LP, which agree when both certify;
* reproduction cache entries (a number, key or value of the JSON edited, bytes flipped, the
  arrays truncated or missing): the cache returns the true result, reused or recomputed;
* edited systems (a ``System`` whose cost tables, caps, action counts, automaton or model were
  replaced by hand, given to ``lower_bound`` with relaxation 1, 2 or 3): refused with one
  WncsError naming the field, or bounded as the system the edit describes, never above its exact
  optimum (cost tables are honoured; an automaton of another system only by relaxation 2);
* sweep folders (``sweep.csv`` / ``sweep.json`` / ``sweep_meta.json`` deleted, truncated, edited,
  garbled, replaced by a folder; rerun with the same or another scenario): the command ends with
  an exit status and at most one ``error:`` line, never a traceback. Rows whose gain is not the
  true one (trusted from a damaged or foreign folder: the resume logic of ``wncs_lp.sweep``) are
  counted and reported.

The hostile families of issue 39 (``tests/fuzz_reliability.py``: special files, memory limits,
signals during every long command, the JSON contract, CLI options, API arguments, edited files,
edited systems, labels, caches, messages) are fixed lists of cases, each run whole in a child
process under a memory limit and a timeout. Each case ends in one of: ok, clear error,
traceback, hang, kill (a signal it did not handle: the OOM killer, an abort), wrong (the
contract broken without a crash). They are counted, never re-raised::

    python benchmarks/fuzz_scenarios.py --families hostile [--record counts.json]

``WNCS_FUZZ_CODE=/path/to/another/checkout`` runs the children on that checkout's code (a
"before" measurement).
"""
from __future__ import annotations

import argparse
import collections
import os
import re
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
if os.environ.get("WNCS_FUZZ_CODE"):  # measure another checkout's code (a "before"): its package first
    sys.path.insert(0, os.environ["WNCS_FUZZ_CODE"])

from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from fuzz_strategies import (  # noqa: E402
    apply_npz_mutation,
    cache_base,
    cache_mutation,
    check_cache_case,
    check_system_edit,
    check_case,
    check_npz_case,
    check_override_forms,
    check_sweep_case,
    hostile_key,
    hostile_value,
    mutated_raw,
    npz_bases,
    npz_mutation,
    override_key,
    override_value,
    scratch_dir,
    sweep_base,
    sweep_mutation,
    system_bases,
    system_edit,
    to_toml,
    valid_raw,
)


def families(tmp: Path, args) -> dict:
    """name -> (strategy, case function returning an outcome label, number of cases)."""
    npz = {}
    cache = {}
    sweep = {}

    def npz_case(m):
        npz.setdefault("b", npz_bases(tmp))
        which, how = m
        return check_npz_case("mdp" if which == "mdp" else "policy",
                              apply_npz_mutation(npz["b"][which], how, tmp / f"case_{which}.npz"))

    def cache_case(m):
        cache.setdefault("b", cache_base(tmp))
        return check_cache_case(cache["b"], m, tmp)

    systems = {}

    def system_case(m):
        systems.setdefault("b", system_bases())
        return check_system_edit(systems["b"], m)

    def sweep_case(m):
        sweep.setdefault("b", sweep_base(tmp))
        outcome, wrong = check_sweep_case(sweep["b"], m, tmp)
        sweep["wrong"] = sweep.get("wrong", 0) + wrong
        sweep["cases with wrong rows"] = sweep.get("cases with wrong rows", 0) + bool(wrong)
        return outcome

    n = args.cases
    return {
        "valid dict": (valid_raw(), lambda raw: check_case("dict", raw), n),
        "valid toml": (valid_raw(), lambda raw: check_case("toml", to_toml(raw), tmp), n),
        "mutated dict": (mutated_raw(), lambda raw: check_case("dict", raw), n),
        "mutated toml": (mutated_raw(), lambda raw: check_case("toml", to_toml(raw), tmp), n),
        "random bytes": (st.binary(max_size=300), lambda b: check_case("bytes", b, tmp), n),
        "overrides": (
            st.tuples(valid_raw(), st.lists(st.tuples(override_key, override_value), max_size=3)),
            lambda pr: check_case("override", (pr[0], [f"{k}={v}" for k, v in pr[1]])), n),
        "hostile overrides": (
            st.tuples(valid_raw(), st.lists(st.tuples(hostile_key, hostile_value), min_size=1, max_size=3)),
            lambda pr: check_override_forms(pr[0], pr[1], tmp), n),
        "npz files": (npz_mutation(), npz_case, args.npz_cases),
        "cache entries": (cache_mutation(), cache_case, args.cache_cases),
        "edited systems": (system_edit(), system_case, args.system_cases),
        "sweep folders": (sweep_mutation(), sweep_case, args.sweep_cases),
    }, sweep


def run_hostile(names: list[str], record: str | None, verbose: bool, only: str | None = None) -> int:
    """The hostile families: every case run, its outcome counted by family."""
    import json
    import tempfile

    import wncs_lp
    from fuzz_reliability import FAMILIES, OUTCOMES, code_under_test

    print(f"code under test: commands {code_under_test()}, library calls {wncs_lp.__file__}", flush=True)
    tmp = Path(tempfile.mkdtemp(prefix="wncs_lp-hostile-"))
    results = []
    t0 = time.perf_counter()
    for family in names:
        for case in FAMILIES[family]():
            if only and not re.search(only, case.name):
                continue
            t1 = time.perf_counter()
            try:
                label, detail = case.run(tmp)
            except Exception as exc:  # noqa: BLE001 - a harness failure is reported as such
                label, detail = "harness error", f"{type(exc).__name__}: {exc}"
            results.append({"family": family, "case": case.name, "outcome": label, "detail": detail,
                            "seconds": round(time.perf_counter() - t1, 1)})
            if record:  # as each case ends: a run stopped half-way keeps what it measured
                Path(record).write_text(json.dumps(results, indent=1))
            if verbose:
                print(f"  [{family}] {case.name}: {label} ({detail}) {results[-1]['seconds']} s", flush=True)
    cols = ["cases", *OUTCOMES]
    print(f"{'family':<16} " + " ".join(f"{c:>11}" for c in cols) + f" {'seconds':>8}")
    for family in names:
        rows = [r for r in results if r["family"] == family]
        n = collections.Counter(r["outcome"] for r in rows)
        secs = sum(r["seconds"] for r in rows)
        print(f"{family:<16} {len(rows):>11} " + " ".join(f"{n.get(o, 0):>11}" for o in OUTCOMES)
              + f" {secs:>8.0f}" + (f"  harness errors {n['harness error']}" if n.get("harness error") else ""))
    bad = [r for r in results if r["outcome"] not in ("ok", "clear error")]
    print(f"total: {len(results)} cases in {time.perf_counter() - t0:.0f} s; {len(bad)} not ok or a clear error")
    for r in bad:
        print(f"  [{r['family']}] {r['case']}: {r['outcome']}: {r['detail']}")
    if record:
        Path(record).write_text(json.dumps(results, indent=1))
    return 0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--families", default="all",
                    help="comma list of families, 'scenarios' (the hypothesis families), 'hostile' (issue 39's) or "
                         "'all' (default)")
    ap.add_argument("--record", default=None, metavar="FILE.json", help="write every hostile case's outcome here")
    ap.add_argument("--verbose", action="store_true", help="one line per hostile case as it ends")
    ap.add_argument("--only", default=None, metavar="REGEX", help="only the hostile cases whose name matches")
    ap.add_argument("--cases", type=int, default=2000, help="examples per scenario family (default 2000; 7 families)")
    ap.add_argument("--npz-cases", type=int, default=400, help="mutated .npz files (default 400; each MDP is solved twice)")
    ap.add_argument("--cache-cases", type=int, default=2000, help="mutated cache entries (default 2000)")
    ap.add_argument("--system-cases", type=int, default=120,
                    help="Systems edited by hand, given to the bounds (default 120; each computes a bound)")
    ap.add_argument("--sweep-cases", type=int, default=60, help="mutated sweep folders (default 60; each reruns a sweep)")
    args = ap.parse_args()
    from fuzz_reliability import FAMILIES

    wanted = [w.strip() for w in args.families.split(",") if w.strip()]
    hostile = [f for f in FAMILIES if "all" in wanted or "hostile" in wanted or f in wanted]
    unknown = [w for w in wanted if w not in ("all", "hostile", "scenarios") and w not in FAMILIES]
    if unknown:
        ap.error(f"unknown families {unknown}; expected 'all', 'hostile', 'scenarios' or some of {list(FAMILIES)}")
    if hostile:
        run_hostile(hostile, args.record, args.verbose, args.only)
    if not ("all" in wanted or "scenarios" in wanted):
        return 0
    tmp = scratch_dir()
    counts: collections.Counter = collections.Counter()
    fams, sweep = families(tmp, args)

    def make_runner(name, strategy, fn, cases):
        @settings(max_examples=cases, deadline=None, database=None, suppress_health_check=list(HealthCheck))
        @given(strategy)
        def run(x):
            counts[(name, fn(x))] += 1

        return run

    t0 = time.perf_counter()
    seconds = {}
    for name, (strategy, fn, cases) in fams.items():
        t1 = time.perf_counter()
        make_runner(name, strategy, fn, cases)()
        seconds[name] = time.perf_counter() - t1
    total = sum(counts.values())
    print(f"{'family':<18} {'cases':>7}  outcomes{'':<40} {'seconds':>8}")
    for name in fams:
        got = {o: c for (f, o), c in counts.items() if f == name}
        text = ", ".join(f"{o} {c}" for o, c in sorted(got.items()))
        print(f"{name:<18} {sum(got.values()):>7}  {text:<48} {seconds[name]:>8.1f}")
    print(f"total cases: {total} in {time.perf_counter() - t0:.1f} s; tracebacks, hangs and wrong answers "
          f"trusted by the loaders and the cache: 0")
    print(f"sweep folders: {sweep.get('wrong', 0)} rows with a gain other than the true one, in "
          f"{sweep.get('cases with wrong rows', 0)} cases (resume of wncs_lp.sweep)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
