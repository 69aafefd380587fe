"""The grid of a study is bounded and finite (issue 27, item 11), and the trade-off's size error names
only methods the command takes (item 19)."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

import wncs_lp
from wncs_lp.errors import WncsError
from wncs_lp.studies import MAX_GRID_VALUES, parse_values

ROOT = Path(__file__).resolve().parents[2]
P12 = str(wncs_lp.scenario_path("paper_p12"))


def test_ranges_and_lists():
    assert parse_values("0.8:1.0:0.05") == [0.8, 0.85, 0.9, 0.95, 1.0]
    assert parse_values("1:3:1") == [1.0, 2.0, 3.0]
    assert parse_values("0.8,0.9") == [0.8, 0.9]
    assert len(parse_values(f"0:{MAX_GRID_VALUES - 1}:1")) == MAX_GRID_VALUES  # the largest grid allowed


@pytest.mark.parametrize("text, words", [
    ("0:1:1e-12", "1,000,000,000,001 values, at most 10,000"),
    ("0:inf:0.1", "must be finite numbers"),
    ("0:1:nan", "must be finite numbers"),
    ("0:1e308:1e-308", r"more than 10\^308 values"),
    ("0.1,inf", "every value must be a finite number"),
    ("0.1,nan", "every value must be a finite number"),
    ("1:2:0", "the step must be > 0"),
    ("", "empty grid"),
])
def test_a_grid_too_fine_or_not_finite_is_one_clear_error(text, words):
    with pytest.raises(WncsError, match=words):
        parse_values(text)


def test_lists_are_bounded_too():
    with pytest.raises(WncsError, match="at most 10,000"):
        parse_values([0.5] * (MAX_GRID_VALUES + 1))
    with pytest.raises(WncsError, match="finite"):
        parse_values([0.5, float("inf")])


def _scenario_with_constraint(tmp_path: Path, base: str = P12) -> Path:
    text = Path(base).read_text().replace("allow_idle = false", "allow_idle = true")
    path = tmp_path / "with_bound.toml"
    path.write_text(text + '\n[[constraint]]\nquantity = "send_rate"\nserver = "remote"\nmax = 0.2\n')
    return path


@pytest.mark.parametrize("command", ["sweep", "tradeoff"])
@pytest.mark.parametrize("values", ["0:1:1e-12", "0:inf:0.1"])
def test_the_commands_answer_at_once_with_one_line(tmp_path, command, values):
    extra = ["--constraint", "1"] if command == "tradeoff" else ["--param", "p"]
    proc = subprocess.run([sys.executable, "-m", "wncs_lp", command, str(_scenario_with_constraint(tmp_path)),
                           "--set", "tau_cap=7", *extra, f"--values={values}", "--out", str(tmp_path / "o")],
                          capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: --values") and "Traceback" not in proc.stderr


def test_the_tradeoffs_size_error_suggests_only_what_tradeoff_takes(tmp_path, monkeypatch, capsys):
    """Processes 1-4 at cap 20 with a bound: the stored matrix does not fit in a 4 GiB machine, the
    matrix-free solver would (about 0.8 GiB), but ``tradeoff`` cannot run it."""
    import wncs_lp.models.guard as guard
    from wncs_lp.cli import main

    monkeypatch.setattr(guard, "available_memory", lambda: 4 << 30)
    path = _scenario_with_constraint(tmp_path, str(wncs_lp.scenario_path("paper_p1234")))
    args = ["--set", "tau_cap=20", "--constraint", "1", "--values", "0.1,0.2", "--out", str(tmp_path / "o")]
    assert main(["tradeoff", str(path), *args]) == 2
    err = capsys.readouterr().err
    assert "the MDP would have up to" in err and "matrix-free" not in err
    assert main(["tradeoff", str(path), *args, "--method", "lp"]) == 2
    assert "matrix-free" not in capsys.readouterr().err
    # the solve command, which takes it, still suggests it
    assert main(["solve", str(path), "--set", "tau_cap=20", "--method", "vi", "--ignore-constraints"]) == 2
    assert "--method matrix-free" in capsys.readouterr().err
