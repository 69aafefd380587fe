"""Parameter sweeps: several policies over a grid of one scenario parameter (usually p).

For every grid value v the scenario is ``scenario.with_overrides({param: v})``; for every
requested policy one row is produced:

=========== ==============================================================================
column      meaning
=========== ==============================================================================
param       the swept parameter (e.g. ``p``)
value       its value
policy      ``optimal``, ``suboptimal``, ``static``, ``best_static``, ``greedy``, ``random``
gain        exact average cost (stationary distribution of the enumerated MDP), or empty
sim_mean    Monte Carlo mean average cost (when simulating), or empty
sim_stderr  its standard error across replications, or empty
seconds     wall time of this row (policy construction, solve, evaluation, simulation)
states      number of MDP states (empty without enumeration)
warm_start  whether the optimal solve was warm-started from the previous grid value
status      ``ok`` or ``error: <message>`` (e.g. a multichain policy)
=========== ==============================================================================

Output folder: ``sweep.csv`` and ``sweep.json`` (the same rows plus the settings), rewritten
after every finished row through a temporary file and :func:`os.replace` (so a reader or an
interrupted run never sees a half-written file), ``sweep_meta.json`` (the settings a resumed
run must match) and the figure ``sweep.png`` / ``sweep.svg``.

Resume: rows already in ``sweep.csv`` (complete and parseable) are kept and not recomputed; a
deleted or truncated row is recomputed.

Warm start: with one worker the grid is walked in order and the optimal solve of value v_i
starts from the solution at v_{i-1} when the state space is the same (``auto``, ``vi``, ``rvi``:
``h0`` = previous bias; ``pi``: ``policy0`` = previous policy; ``lp``: none). With several workers (a
``concurrent.futures`` process pool, or Dask when installed and asked for) the grid values are
independent tasks and are not warm-started.
"""
from __future__ import annotations

import csv
import hashlib
import io
import json
import math
import time
from concurrent.futures import Executor, ProcessPoolExecutor, as_completed
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from .files import atomic_write_text, csv_records
from .errors import WncsError
from .methods import DEFAULT_METHOD, LP_METHODS, check_method
from .models.system import System
from .policies import POLICY_NAMES, make_policy, parse_policy_names
from .scenario import Scenario

__all__ = ["SweepRow", "SweepResult", "run_sweep", "parse_values", "read_rows", "COLUMNS"]

COLUMNS = ("param", "value", "policy", "gain", "sim_mean", "sim_stderr", "seconds", "states", "warm_start", "status")
_INT_PARAMS = ("tau_cap", "uplink_delay", "downlink_delay", "slots_per_dimension")


@dataclass(frozen=True)
class SweepRow:
    """One (value, policy) row of a sweep table; NaN marks a quantity not computed."""

    param: str
    value: float
    policy: str
    gain: float = math.nan
    sim_mean: float = math.nan
    sim_stderr: float = math.nan
    seconds: float = 0.0
    states: int = 0
    warm_start: bool = False
    status: str = "ok"

    @property
    def key(self) -> tuple[str, str]:
        return (_value_key(self.value), self.policy)

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        for k in ("gain", "sim_mean", "sim_stderr"):
            if not math.isfinite(d[k]):
                d[k] = None
        return d

    def to_csv(self) -> list[str]:
        def num(x: float) -> str:
            return "" if not math.isfinite(x) else repr(float(x))

        return [self.param, repr(float(self.value)), self.policy, num(self.gain), num(self.sim_mean),
                num(self.sim_stderr), repr(float(self.seconds)), str(int(self.states)),
                "true" if self.warm_start else "false", self.status]

    @classmethod
    def from_csv(cls, rec: dict[str, str]) -> "SweepRow":
        def num(s: str) -> float:
            return float(s) if s not in ("", None) else math.nan

        return cls(
            param=rec["param"],
            value=float(rec["value"]),
            policy=rec["policy"],
            gain=num(rec["gain"]),
            sim_mean=num(rec["sim_mean"]),
            sim_stderr=num(rec["sim_stderr"]),
            seconds=float(rec["seconds"]),
            states=int(rec["states"]),
            warm_start=rec["warm_start"] == "true",
            status=rec["status"],
        )


@dataclass(frozen=True)
class SweepResult:
    """A finished sweep.

    Attributes
    ----------
    rows : tuple of SweepRow
        The requested (value, policy) rows, grid order then policy order.
    out_dir : Path or None
    files : dict
        ``csv``, ``json``, ``meta``, ``png``, ``svg`` paths (those written).
    computed, reused : int
        Rows computed in this run / taken from the output folder.
    seconds : float
    """

    rows: tuple[SweepRow, ...]
    out_dir: Path | None
    files: dict[str, str] = field(default_factory=dict)
    computed: int = 0
    reused: int = 0
    seconds: float = 0.0

    def table(self) -> list[dict[str, Any]]:
        """The rows as JSON-ready dictionaries."""
        return [r.to_dict() for r in self.rows]

    def column(self, policy: str, name: str = "gain") -> np.ndarray:
        """One column for one policy, in grid order."""
        return np.array([getattr(r, name) for r in self.rows if r.policy == policy], dtype=float)


# ----------------------------------------------------------------------------- helpers
def _value_key(v: float) -> str:
    return format(round(float(v), 12), ".12g")


def parse_values(text: str | Sequence[float]) -> list[float]:
    """Grid values from ``"0.8:1.0:0.05"`` (start:stop:step, stop included) or ``"0.8,0.9,1"``.

    Values are rounded to 12 decimals so that 0.8 + 4 * 0.05 is exactly 1.0.

    Raises
    ------
    WncsError
        Malformed text, a step <= 0, or an empty grid.
    """
    if not isinstance(text, str):
        vals = [float(v) for v in text]
    elif ":" in text:
        parts = text.split(":")
        try:
            if len(parts) != 3:
                raise ValueError
            a, b, s = (float(x) for x in parts)
        except ValueError:
            raise WncsError(f"--values {text!r}: expected START:STOP:STEP (e.g. 0.8:1.0:0.05) or a comma list") from None
        if not s > 0:
            raise WncsError(f"--values {text!r}: the step must be > 0")
        n = int(math.floor((b - a) / s + 1e-9)) + 1
        vals = [round(a + i * s, 12) for i in range(max(n, 0))]
    else:
        try:
            vals = [float(x) for x in text.split(",") if x.strip()]
        except ValueError:
            raise WncsError(f"--values {text!r}: expected numbers separated by commas, or START:STOP:STEP") from None
    if not vals:
        raise WncsError(f"--values {text!r}: empty grid")
    return vals


def _override_value(param: str, value: float) -> Any:
    if param.split(".")[-1] in _INT_PARAMS and float(value).is_integer():
        return int(value)
    return float(value)


def read_rows(path: str | Path) -> list[SweepRow]:
    """Complete rows of a sweep CSV (a truncated or malformed line is skipped)."""
    rows = []
    for rec in csv_records(path, COLUMNS):
        try:
            row = SweepRow.from_csv(rec)
        except (ValueError, KeyError):
            continue
        if row.policy in POLICY_NAMES:
            rows.append(row)
    return rows


# ----------------------------------------------------------------------------- one grid point
def _same_space(mdp: Any, warm: dict | None) -> bool:
    return bool(warm) and warm.get("n_pairs") == mdp.n_pairs and warm.get("space") == _space_key(mdp)


def _space_key(mdp: Any) -> str:
    """A digest of the state numbering (configurations and the (C, tau) -> state lookup)."""
    h = hashlib.sha1(repr(list(mdp.states.configs)).encode())
    h.update(np.ascontiguousarray(mdp.states.lookup).tobytes())
    return h.hexdigest()


def compute_point(
    scenario: Scenario,
    param: str,
    value: float,
    policies: Sequence[str],
    opts: dict[str, Any],
    warm: dict | None = None,
    on_row: Callable[[SweepRow], None] | None = None,
) -> dict[str, Any]:
    """All requested rows of one grid value (a picklable unit of work for the executors).

    Returns ``{"rows": [SweepRow...], "warm": {...}}``; ``warm`` carries the optimal solution
    (bias, policy) for the next grid value.
    """
    from .evaluate import evaluate
    from .models import build
    from .simulate import simulate
    from .solvers import solve

    sc = scenario.with_overrides({param: _override_value(param, value)})
    system = System.from_scenario(sc)
    exact = opts.get("exact", True)
    method = opts.get("method", DEFAULT_METHOD)
    need_mdp = exact or any(p in ("optimal", "best_static") for p in policies)
    need_lp = "optimal" in policies and method in LP_METHODS
    mdp = build(sc, force=bool(opts.get("force", False)), need_lp=need_lp) if need_mdp else None
    rows: list[SweepRow] = []
    new_warm: dict | None = None
    for name in policies:
        t0 = time.perf_counter()
        gain = sim_mean = sim_err = math.nan
        status = "ok"
        warm_used = False
        try:
            solution = None
            if name == "optimal":
                kw: dict[str, Any] = {}
                if _same_space(mdp, warm):  # pi starts from the previous policy, the others from its bias
                    if method == "pi":
                        kw["policy0"] = warm["policy"]
                    elif method in ("rvi", "vi", "auto"):
                        kw["h0"] = warm["bias"]
                    warm_used = method in ("pi", "rvi", "vi", "auto")
                solution = solve(mdp, method=method, **kw)
                new_warm = {"n_pairs": mdp.n_pairs, "space": _space_key(mdp),
                            "bias": solution.bias, "policy": solution.policy}
                if not solution.ok:
                    status = f"error: solver status {solution.status}"
            pol = make_policy(name, system, mdp, method=method, solution=solution)
            if exact:
                ev = evaluate(mdp, pol, multichain="initial")
                gain = ev.gain
                if ev.recurrent_classes > 1 and status == "ok":
                    status = f"ok (multichain: {ev.recurrent_classes} recurrent classes; gain from the initial state)"
            slots = int(opts.get("simulate_slots", 0) or 0)
            if slots > 0:
                res = simulate(pol, slots=slots, reps=int(opts.get("reps", 20)), seed=opts.get("seed", 0),
                               burn_in=int(opts.get("burn_in", 1000)), progress=opts.get("progress", False))
                sim_mean, sim_err = res.mean, res.stderr
        except WncsError as exc:
            status = f"error: {exc}".replace("\n", " ")
        row = SweepRow(param=param, value=float(value), policy=name, gain=gain, sim_mean=sim_mean,
                       sim_stderr=sim_err, seconds=time.perf_counter() - t0,
                       states=int(mdp.n_states) if mdp is not None else 0, warm_start=warm_used, status=status)
        rows.append(row)
        if on_row is not None:
            on_row(row)
    return {"rows": rows, "warm": new_warm}


# ----------------------------------------------------------------------------- the sweep
def _meta(scenario: Scenario, param: str, opts: dict[str, Any]) -> dict[str, Any]:
    return {
        "scenario": scenario.source,
        "fingerprint": scenario.fingerprint(),
        "param": param,
        "method": opts["method"],
        "exact": bool(opts["exact"]),
        "simulate_slots": int(opts["simulate_slots"]),
        "reps": int(opts["reps"]),
        "seed": opts["seed"],
        "burn_in": int(opts["burn_in"]),
    }


#: executors accepted by :func:`run_sweep`
EXECUTORS = ("process", "dask")


def _make_executor(kind: str, max_workers: int) -> Executor:
    if kind == "process":
        return ProcessPoolExecutor(max_workers=max_workers)
    if kind == "dask":
        try:
            from dask.distributed import Client  # type: ignore
        except ImportError:
            raise WncsError("executor 'dask' needs dask.distributed: pip install 'wncs_lp[dask]'") from None
        client = Client(n_workers=max_workers, threads_per_worker=1, processes=True)
        ex = client.get_executor()
        ex._wncs_client = client  # closed with the executor below
        return ex
    raise WncsError(f"unknown executor {kind!r}; expected one of {', '.join(map(repr, EXECUTORS))}")


def run_sweep(
    scenario: Scenario,
    param: str,
    values: Sequence[float] | str,
    policies: Sequence[str] | str = ("optimal", "suboptimal", "static", "greedy"),
    out_dir: str | Path | None = None,
    *,
    method: str = DEFAULT_METHOD,
    force: bool = False,
    exact: bool = True,
    simulate_slots: int = 0,
    reps: int = 20,
    seed: int | None = 0,
    burn_in: int = 1000,
    max_workers: int = 1,
    executor: str = "process",
    plot: bool = True,
    progress: bool = False,
    log: Callable[[str], None] | None = None,
) -> SweepResult:
    """Sweep one parameter for several policies; write (and resume) a tidy table.

    Parameters
    ----------
    scenario : Scenario
        The base scenario.
    param : str
        An override key (``p``, ``tau_cap``, ``process.2.weight``, ...).
    values : sequence of float or str
        The grid (see :func:`parse_values`).
    policies : sequence of str or str
        Names from :data:`wncs_lp.policies.POLICY_NAMES`.
    out_dir : path, optional
        Output folder (created). Without it nothing is written and nothing is resumed.
    method : str
        Solver of the optimal policy (:data:`wncs_lp.methods.METHODS`, default ``"auto"``); every
        grid value after the first starts from the previous one's answer (``pi``: its policy;
        ``auto``, ``vi``, ``rvi``: its bias).
    force : bool
        Build past the size guard (:func:`wncs_lp.build`).
    exact : bool
        Evaluate every policy exactly on the enumerated MDP (default). With False only
        simulation is done (for scenarios too large to enumerate; ``optimal`` and
        ``best_static`` still enumerate).
    simulate_slots, reps, seed, burn_in : int
        Monte Carlo settings; ``simulate_slots = 0`` (default) skips simulation.
    max_workers : int
        Grid values computed in parallel (default 1: sequential with warm start).
    executor : {"process", "dask"}
        Parallel backend when ``max_workers > 1``.
    plot : bool
        Save ``sweep.png`` and ``sweep.svg`` (needs ``out_dir``).
    progress : bool
        Progress bars of the simulations.
    log : callable, optional
        Receives one line per finished row (e.g. ``print`` to stderr).

    Returns
    -------
    SweepResult

    Raises
    ------
    WncsError
        Bad grid or policy names, an unknown executor, or an output folder holding a sweep
        with other settings (another scenario, parameter, method or simulation setting).
    """
    t_start = time.perf_counter()
    grid = parse_values(values)
    names = parse_policy_names(policies)
    if max_workers < 1:
        raise WncsError(f"max_workers must be >= 1, got {max_workers}")
    if executor not in EXECUTORS:  # up front: a one-point sweep never builds the executor
        raise WncsError(f"unknown executor {executor!r}; expected one of {', '.join(map(repr, EXECUTORS))}")
    check_method(method)
    opts = {"method": method, "exact": exact, "simulate_slots": simulate_slots, "reps": reps, "seed": seed,
            "burn_in": burn_in, "progress": progress, "force": force}
    meta = _meta(scenario, param, opts)
    files: dict[str, str] = {}
    done: dict[tuple[str, str], SweepRow] = {}
    out = Path(out_dir) if out_dir is not None else None
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        meta_path = out / "sweep_meta.json"
        if meta_path.exists():
            try:
                old = json.loads(meta_path.read_text())
            except (OSError, ValueError):
                old = None
            if old is not None and old != json.loads(json.dumps(meta)):
                diff = sorted(k for k in set(old) | set(meta) if old.get(k) != json.loads(json.dumps(meta)).get(k))
                raise WncsError(
                    f"{out} holds a sweep with other settings ({', '.join(diff)} differ); "
                    "use another --out folder or delete it"
                )
        atomic_write_text(meta_path, json.dumps(meta, indent=2) + "\n")
        files["meta"] = str(meta_path)
        for row in read_rows(out / "sweep.csv"):
            done[row.key] = row
    reused_keys = {(_value_key(v), p) for v in grid for p in names if (_value_key(v), p) in done}

    def save() -> None:
        if out is None:
            return
        order_v = {_value_key(v): i for i, v in enumerate(grid)}
        order_p = {p: i for i, p in enumerate(POLICY_NAMES)}
        rows = sorted(done.values(), key=lambda r: (order_v.get(_value_key(r.value), len(grid)), r.value,
                                                     order_p.get(r.policy, 99)))
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(COLUMNS)
        for r in rows:
            w.writerow(r.to_csv())
        atomic_write_text(out / "sweep.csv", buf.getvalue())
        payload = {"settings": meta, "columns": list(COLUMNS), "rows": [r.to_dict() for r in rows]}
        atomic_write_text(out / "sweep.json", json.dumps(payload, indent=2) + "\n")
        files["csv"] = str(out / "sweep.csv")
        files["json"] = str(out / "sweep.json")

    computed = 0

    def record(row: SweepRow) -> None:
        nonlocal computed
        done[row.key] = row
        computed += 1
        save()
        if log is not None:
            g = "-" if not math.isfinite(row.gain) else f"{row.gain:.6g}"
            s = "" if not math.isfinite(row.sim_mean) else f", sim {row.sim_mean:.6g} +- {row.sim_stderr:.2g}"
            log(f"{param}={row.value:g} {row.policy}: gain {g}{s} ({row.seconds:.2f} s) {row.status}")

    todo = [(v, [p for p in names if (_value_key(v), p) not in done]) for v in grid]
    todo = [(v, ps) for v, ps in todo if ps]
    if max_workers == 1 or len(todo) <= 1:
        warm = None
        for v, ps in todo:
            res = compute_point(scenario, param, v, ps, opts, warm, on_row=record)
            warm = res["warm"]
    else:
        ex = _make_executor(executor, max_workers)
        try:
            futs = [ex.submit(compute_point, scenario, param, v, ps, opts, None) for v, ps in todo]
            for fut in as_completed(futs):
                for row in fut.result()["rows"]:
                    record(row)
        finally:
            ex.shutdown(wait=True)
            client = getattr(ex, "_wncs_client", None)
            if client is not None:
                client.close()
    save()

    rows = tuple(done[(_value_key(v), p)] for v in grid for p in names)
    if out is not None and plot:
        from .viz import save_sweep_figure

        paths = save_sweep_figure(rows, out / "sweep", title=f"{Path(scenario.source).stem}: {param} sweep")
        files.update(paths)
    return SweepResult(rows=rows, out_dir=out, files=files, computed=computed, reused=len(reused_keys),
                       seconds=time.perf_counter() - t_start)
