"""Fuzz the scenario loader with >= 10,000 generated cases and report the counts.

    python benchmarks/fuzz_scenarios.py [--cases 2000]   # cases per family (6 families)

Contract: every case either loads or raises ScenarioError whose message names a field; any other
exception is a bug and is re-raised with the failing example (hypothesis shrinks it).
"""
from __future__ import annotations

import argparse
import collections
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))

from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from fuzz_strategies import (  # noqa: E402
    check_case,
    mutated_raw,
    override_key,
    override_value,
    scratch_dir,
    to_toml,
    valid_raw,
)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--cases", type=int, default=2000, help="examples per family (default 2000; 6 families)")
    args = ap.parse_args()
    tmp = scratch_dir()
    counts: collections.Counter = collections.Counter()
    cfg = settings(max_examples=args.cases, deadline=None, database=None,
                   suppress_health_check=list(HealthCheck))

    families = {
        "valid dict": (valid_raw(), lambda raw: check_case("dict", raw)),
        "valid toml": (valid_raw(), lambda raw: check_case("toml", to_toml(raw), tmp)),
        "mutated dict": (mutated_raw(), lambda raw: check_case("dict", raw)),
        "mutated toml": (mutated_raw(), lambda raw: check_case("toml", to_toml(raw), tmp)),
        "random bytes": (st.binary(max_size=300), lambda b: check_case("bytes", b, tmp)),
        "overrides": (
            st.tuples(valid_raw(), st.lists(st.tuples(override_key, override_value), max_size=3)),
            lambda pr: check_case("override", (pr[0], [f"{k}={v}" for k, v in pr[1]])),
        ),
    }
    t0 = time.perf_counter()
    def make_runner(name, strategy, fn):
        @cfg
        @given(strategy)
        def run(x):
            counts[(name, fn(x))] += 1

        return run

    for name, (strategy, fn) in families.items():
        make_runner(name, strategy, fn)()
    total = sum(counts.values())
    print(f"{'family':<14} {'loaded':>8} {'clear error':>12}")
    for name in families:
        print(f"{name:<14} {counts[(name, 'ok')]:>8} {counts[(name, 'error')]:>12}")
    print(f"total cases: {total} in {time.perf_counter() - t0:.1f} s; other exceptions: 0")
    return 0


if __name__ == "__main__":
    sys.exit(main())
