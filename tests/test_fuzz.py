"""Property-based fuzzing of scenario loading: succeed, or raise ScenarioError naming a field.

The regular suite runs a few hundred cases; ``python benchmarks/fuzz_scenarios.py`` runs 10,000+.
"""
from __future__ import annotations

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fuzz_strategies import (
    check_case,
    mutated_raw,
    override_key,
    override_value,
    scratch_dir,
    to_toml,
    valid_raw,
)

TMP = scratch_dir()
FAST = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@FAST
@given(valid_raw())
def test_valid_scenarios_load(raw):
    assert check_case("dict", raw) == "ok"
    # and the same through a TOML file
    assert check_case("toml", to_toml(raw), TMP) == "ok"


@FAST
@given(mutated_raw())
def test_mutated_scenarios_load_or_name_the_field(raw):
    check_case("dict", raw)


@FAST
@given(mutated_raw())
def test_mutated_toml_files(raw):
    check_case("toml", to_toml(raw), TMP)


@FAST
@given(st.binary(max_size=200))
def test_random_bytes(data):
    check_case("bytes", data, TMP)


@FAST
@given(st.text(max_size=200))
def test_random_text(text):
    check_case("toml", text, TMP)


@FAST
@given(valid_raw(), st.lists(st.tuples(override_key, override_value), max_size=3))
def test_overrides(raw, pairs):
    check_case("override", (raw, [f"{k}={v}" for k, v in pairs]))
