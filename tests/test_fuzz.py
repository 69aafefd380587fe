"""Property-based fuzzing of scenario loading: succeed, or raise ScenarioError naming a field.

The regular suite runs a few hundred cases; ``python benchmarks/fuzz_scenarios.py`` runs 10,000+.
"""
from __future__ import annotations

from hypothesis import HealthCheck, example, given, settings
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


# ----------------------------------------------------------------------------- issue 27: hostile families
from fuzz_strategies import (  # noqa: E402
    apply_npz_mutation,
    cache_base,
    cache_mutation,
    check_cache_case,
    check_npz_case,
    check_override_forms,
    check_sweep_case,
    hostile_key,
    hostile_value,
    npz_bases,
    npz_mutation,
    sweep_base,
    sweep_mutation,
)

_BASES: dict = {}


def _base(name, make):
    if name not in _BASES:
        _BASES[name] = make(TMP)
    return _BASES[name]


@FAST
@given(valid_raw(), st.lists(st.tuples(hostile_key, hostile_value), min_size=1, max_size=3))
def test_hostile_overrides_in_every_form(raw, pairs):
    check_override_forms(raw, pairs, TMP)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(npz_mutation())
@example(("policy", ("bytes", [(790, 1)])))  # a header numpy re-tokenizes: tokenize.TokenError escaped (CI, 2026-12-06)
def test_mutated_npz_files_load_or_name_the_file(mutation):
    which, how = mutation
    path = apply_npz_mutation(_base("npz", npz_bases)[which], how, TMP / f"case_{which}.npz")
    check_npz_case("mdp" if which == "mdp" else "policy", path)


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(cache_mutation())
def test_mutated_cache_entries_are_never_trusted_wrong(mutation):
    check_cache_case(_base("cache", cache_base), mutation, TMP)


@settings(max_examples=5, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(sweep_mutation())
def test_mutated_sweep_folders_end_in_a_status(mutation):
    check_sweep_case(_base("sweep", sweep_base), mutation, TMP)
