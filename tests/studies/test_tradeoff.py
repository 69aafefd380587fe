"""Trade-off curves (docs/constraints.md section 6): wncs_lp.studies.tradeoff, its figure and CLI.

Expectations come from elsewhere than the numbers under test: the multiplier of a point against
the finite-difference slope of the curve built from *other* solves; convexity and monotonicity
of the curve from the theory of the LP in its right-hand side; the flat part against certified
value iteration (``wncs_lp.solve(mdp, "vi")``) on the unconstrained MDP; the least send rate 0
from the model (with ``allow_idle`` the remote server can be left unused forever).
"""
from __future__ import annotations

import csv
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import wncs_lp
import wncs_lp.constrained.registry as registry
from wncs_lp.studies.tradeoff import TradeoffResult, read_points, tradeoff
from wncs_lp.errors import WncsError
from wncs_lp.scenario import ConstraintSpec

ROOT = Path(__file__).resolve().parents[2]
P12 = wncs_lp.scenario_path("paper_p12.toml")
REMOTE = ConstraintSpec("send_rate", server=0, max=0.2, label="send_rate[remote] <= 0.2")


def paper(cap: int):
    sc = wncs_lp.load_scenario(P12, ["model.allow_idle=true", f"tau_cap={cap}"])
    return wncs_lp.build(sc)


@pytest.fixture(scope="module")
def p6():
    return paper(6)


@pytest.fixture(scope="module")
def curve6(p6):
    """Remote send rate <= b at cap 6, b = -0.05 .. 0.45: an infeasible bound, kinks at 0 and ~0.357."""
    return tradeoff(p6, [REMOTE], 0, "-0.05:0.45:0.025", method="lp")


@pytest.fixture(scope="module")
def curve8():
    """Cap 8 around its two kinks (about 0.27 and 0.297)."""
    return tradeoff(paper(8), [REMOTE], 0, "0.2:0.32:0.02", method="lp")


def test_points_in_order_with_certificates(curve6):
    b = curve6.bounds
    assert np.all(np.diff(b) > 0) and b[0] == -0.05 and b[-1] == 0.45
    for p in curve6.feasible_points:
        assert p.ok, p
        assert p.gain_lower <= p.gain * (1 + 1e-12) and p.gain <= p.gain_upper * (1 + 1e-12)
        assert p.gain_upper - p.gain_lower <= 1e-6 * p.gain
        assert p.value <= p.bound + 1e-7
        assert p.randomized_states <= 1  # one active bound: at most one randomised state (basic solution)


def test_infeasible_bound_is_a_row_with_the_reachable_value(curve6):
    p = curve6.point(-0.05)
    assert p.status == "infeasible" and not p.feasible
    assert p.reachable == pytest.approx(0.0, abs=1e-9)  # allow_idle: the remote can stay unused
    assert np.isnan(p.gain)
    assert curve6.reachable == pytest.approx(0.0, abs=1e-9)
    assert curve6.point(0.0).feasible


@pytest.mark.parametrize("b", [0.2, 0.1])
def test_multiplier_is_the_finite_difference_slope(p6, curve6, b):
    e = 0.01
    side = tradeoff(p6, [REMOTE], 0, [b - e, b + e], method="lp")
    slope = -(side.point(b + e).gain - side.point(b - e).gain) / (2 * e)
    lam = curve6.point(b).multiplier
    assert lam > 0
    assert lam == pytest.approx(slope, rel=1e-6)


def _check_convex_nonincreasing(res: TradeoffResult):
    pts = res.feasible_points
    b = np.array([p.bound for p in pts])
    g = np.array([p.gain for p in pts])
    scale = 1e-7 * np.max(np.abs(g))
    assert np.all(np.diff(g) <= scale), g  # non-increasing in a max bound
    slopes = np.diff(g) / np.diff(b)
    assert np.all(np.diff(slopes) >= -scale / np.min(np.diff(b))), slopes  # convex: slopes nondecreasing
    # and every chord's slope lies between the (sub)gradients -lambda of its two ends
    lam = np.array([p.multiplier for p in pts])
    for i, s in enumerate(slopes):
        assert -lam[i] - 1e-6 * max(1, lam[i]) <= s <= -lam[i + 1] + 1e-6 * max(1, lam[i]), (i, s, lam[i:i + 2])


def test_curve_is_convex_and_nonincreasing(curve6, curve8):
    _check_convex_nonincreasing(curve6)
    _check_convex_nonincreasing(curve8)
    # cap 8 really has kinks inside the grid (otherwise convexity would be a weak check)
    _, slopes = curve8.slopes()
    assert len({round(s, 3) for s in slopes}) >= 3


def test_flat_beyond_the_threshold_at_the_unconstrained_optimum(p6, curve6, curve8):
    vi = wncs_lp.solve(p6, "vi")
    assert curve6.unconstrained_gain == pytest.approx(vi.gain, rel=1e-9)
    assert 0 < curve6.threshold < 0.45
    beyond = [p for p in curve6.feasible_points if p.bound >= curve6.threshold]
    assert len(beyond) >= 3
    for p in beyond:
        assert vi.gain_lower - 1e-9 * vi.gain <= p.gain <= vi.gain_upper + 1e-9 * vi.gain, p
        assert p.multiplier == pytest.approx(0.0, abs=1e-6)
    below = [p for p in curve6.feasible_points if p.bound < curve6.threshold - 0.01]
    assert all(p.gain > vi.gain_upper for p in below)  # and it binds below
    vi8 = wncs_lp.solve(paper(8), "vi")
    for p in curve8.feasible_points:
        if p.bound >= curve8.threshold:
            assert p.gain == pytest.approx(vi8.gain, rel=1e-8)


class _Counting:
    """Wraps the constrained step (run_constrained): counts calls and raises KeyboardInterrupt at call
    number ``stop``."""

    def __init__(self, real, stop=None):
        self.real, self.stop, self.calls, self.bounds = real, stop, 0, []

    def __call__(self, mdp, cons, method="auto", **kw):
        self.calls += 1
        if self.stop is not None and self.calls == self.stop:
            raise KeyboardInterrupt
        self.bounds.append(cons[0].max)
        return self.real(mdp, cons, method, **kw)


def test_resume_after_interrupt_solves_only_the_missing_bounds(p6, tmp_path, monkeypatch):
    # cold points (warm=False): each is one run_constrained call to count; the warm sweep's
    # resume is in test_tradeoff_warm.py
    real = registry.run_constrained
    grid = [0.05, 0.1, 0.15, 0.2, 0.25]
    first = _Counting(real, stop=3)
    monkeypatch.setattr(registry, "run_constrained", first)
    with pytest.raises(KeyboardInterrupt):
        tradeoff(p6, [REMOTE], 0, grid, method="lp", out=tmp_path / "t", plot=False, warm=False)
    done = read_points(tmp_path / "t" / "tradeoff.csv")
    assert [p.bound for p in done] == [0.05, 0.1]  # written after each point
    second = _Counting(real)
    monkeypatch.setattr(registry, "run_constrained", second)
    res = tradeoff(p6, [REMOTE], 0, grid, method="lp", out=tmp_path / "t", plot=False, warm=False)
    assert second.calls == 3 and sorted(second.bounds) == [0.15, 0.2, 0.25]
    assert res.computed == 3 and res.reused == 2
    assert [p.bound for p in res.points] == grid
    # the same numbers as an uninterrupted run
    fresh = tradeoff(p6, [REMOTE], 0, grid, method="lp")
    np.testing.assert_allclose(res.gains, fresh.gains, rtol=1e-10)
    # a third run solves nothing; a wider grid only the new bound
    third = _Counting(real)
    monkeypatch.setattr(registry, "run_constrained", third)
    res3 = tradeoff(p6, [REMOTE], 0, grid + [0.3], method="lp", out=tmp_path / "t", plot=False, warm=False)
    assert third.calls == 1 and res3.reused == 5 and len(res3.points) == 6
    with open(tmp_path / "t" / "tradeoff.csv", newline="") as fh:
        assert len(list(csv.DictReader(fh))) == 6


def test_resume_refuses_another_problem(p6, tmp_path):
    tradeoff(p6, [REMOTE], 0, [0.1], method="lp", out=tmp_path / "t", plot=False)
    with pytest.raises(WncsError, match="other settings.*(mdp|states)"):
        tradeoff(paper(5), [REMOTE], 0, [0.1], method="lp", out=tmp_path / "t", plot=False)
    with pytest.raises(WncsError, match="other settings.*method"):
        tradeoff(p6, [REMOTE], 0, [0.1], method="lp-cvxpy", out=tmp_path / "t", plot=False)


def test_other_constraints_stay_fixed(p6):
    edge = ConstraintSpec("send_rate", server=1, max=0.3, label="send_rate[edge] <= 0.3")
    res = tradeoff(p6, [edge, REMOTE], 1, [0.1, 0.2], method="lp")
    assert res.others == ("send_rate[edge] <= 0.3",) and res.index == 1
    for p in res.points:
        direct = wncs_lp.solve(p6, "lp", constraints=[edge, ConstraintSpec("send_rate", server=0, max=p.bound)])
        assert p.gain == pytest.approx(direct.gain, rel=1e-8)


def test_bad_index_and_side(p6):
    with pytest.raises(WncsError, match="no constraint at index 3"):
        tradeoff(p6, [REMOTE], 3, [0.1])
    with pytest.raises(WncsError, match="side"):
        tradeoff(p6, [REMOTE], 0, [0.1], side="both")


def test_summary_round_trip_and_repr(curve6):
    back = TradeoffResult.from_summary(json.loads(json.dumps(curve6.summary())))
    np.testing.assert_array_equal(back.bounds, curve6.bounds)
    np.testing.assert_allclose(back.gains, curve6.gains, equal_nan=True)
    assert back.threshold == curve6.threshold
    text = repr(curve6)
    assert "send_rate[remote] <= b" in text and "no longer binds at" in text
    assert "bracket=[" in repr(curve6.point(0.2)) and "infeasible" in repr(curve6.point(-0.05))


def test_plot_tradeoff_returns_axes_with_reference_lines(curve6):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from wncs_lp.viz import plot_tradeoff

    fig, ax = plt.subplots()
    assert plot_tradeoff(curve6, ax=ax) is ax
    ys = [tuple(ln.get_ydata()) for ln in ax.get_lines()]
    xs = [tuple(ln.get_xdata()) for ln in ax.get_lines()]
    assert (curve6.unconstrained_gain, curve6.unconstrained_gain) in ys  # horizontal: the unconstrained optimum
    assert (curve6.threshold, curve6.threshold) in xs  # vertical: where it stops binding
    assert "updates per slot" in ax.get_xlabel() and "MSE" in ax.get_ylabel()
    plt.close(fig)


# ----------------------------------------------------------------------------- CLI
def _scenario_with_constraint(tmp_path: Path) -> Path:
    text = Path(P12).read_text().replace("allow_idle = false", "allow_idle = true")
    text += '\n[[constraint]]\nquantity = "send_rate"\nserver = "remote"\nmax = 0.2\n'
    path = tmp_path / "p12_remote.toml"
    path.write_text(text)
    return path


def _cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "wncs_lp", "tradeoff", *args], capture_output=True, text=True,
                          cwd=ROOT, timeout=300)


def test_cli_writes_csv_png_json_and_resumes(tmp_path):
    sc = _scenario_with_constraint(tmp_path)
    out = tmp_path / "out"
    proc = _cli(str(sc), "--constraint", "1", "--values", "0.1:0.3:0.1", "--set", "tau_cap=6", "--method", "lp",
                "--out", str(out), "--json")
    assert proc.returncode == 0, proc.stderr
    data = json.loads(proc.stdout)
    assert data["computed"] == 3 and [p["bound"] for p in data["points"]] == [0.1, 0.2, 0.3]
    assert data["constraint"] == "send_rate[remote]" and data["threshold"] > 0.3
    assert (out / "tradeoff.png").read_bytes().startswith(b"\x89PNG")
    assert len(read_points(out / "tradeoff.csv")) == 3
    assert json.loads((out / "tradeoff.json").read_text())["points"][0]["bound"] == 0.1
    again = _cli(str(sc), "--constraint", "1", "--values", "0.1:0.4:0.1", "--set", "tau_cap=6", "--method", "lp",
                 "--out", str(out), "--json")
    assert again.returncode == 0, again.stderr
    data = json.loads(again.stdout)
    assert data["computed"] == 1 and data["reused"] == 3


def test_cli_unknown_constraint_number_is_one_line_exit_2(tmp_path):
    sc = _scenario_with_constraint(tmp_path)
    proc = _cli(str(sc), "--constraint", "5", "--values", "0.1:0.2:0.1", "--out", str(tmp_path / "o"))
    assert proc.returncode == 2
    assert proc.stdout == ""
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "no constraint number 5" in lines[0] and "1 [[constraint]] table" in lines[0]
    assert not (tmp_path / "o" / "tradeoff.csv").exists()
