"""Parameter sweeps: several policies over a grid of one scenario parameter (usually p).

For every grid value v the scenario is ``scenario.with_overrides({param: v})``; for every
requested policy one row is produced:

=========== ==============================================================================
column      meaning
=========== ==============================================================================
param       the swept parameter (e.g. ``p``)
value       its value; the rows of ``sweep.json``, :meth:`SweepResult.table`, ``to_frame()`` and the
            command's printout name this column by the parameter (``p``, ``tau_cap``), as
            :func:`value_column` says; ``sweep.csv``, the resumable store, keeps ``value``
policy      ``optimal``, ``suboptimal``, ``static``, ``best_static``, ``greedy``, ``random``
gain        exact average cost (stationary distribution of the enumerated MDP), or empty
sim_mean    Monte Carlo mean average cost (when simulating), or empty
sim_stderr  its standard error across replications, or empty
seconds     wall time of this row (policy construction, solve, evaluation, simulation)
states      number of MDP states (empty without enumeration)
warm_start  whether the optimal solve was warm-started from the previous grid value
status      ``ok`` or ``error: <message>`` (e.g. a multichain policy)
fingerprint the row's seal (:mod:`wncs_lp.studies.folder`)
=========== ==============================================================================

Output folder (:class:`~wncs_lp.studies.folder.StudyFolder`): ``sweep.csv`` and ``sweep.json``
(the same rows plus the settings), rewritten atomically after every finished row,
``sweep_meta.json`` (the settings a resumed run must match) and the figure ``sweep.png`` /
``sweep.svg``. One run writes a folder at a time (a second waits for it).

Resume: rows already in ``sweep.csv`` whose fingerprint checks out are kept and not recomputed;
a deleted, truncated, edited or foreign row is recomputed, and so is a row whose status is an
error (a solve that stopped short of its certificate, a failed evaluation): a later run, or a
fixed solver, may close it, and a kept error row would carry an older run's status for good.

Warm start: with one worker the grid is walked in order and the optimal solve of value v_i
starts from the solution at v_{i-1} when the state space is the same (the method's warm start
in the registry, :mod:`wncs_lp.methods`: ``auto``, ``vi``, ``rvi`` from the previous bias,
``pi`` from the previous policy, the LPs cold). With several workers (a process pool, or a Dask
cluster: :mod:`wncs_lp.studies.executors`) the grid values are independent tasks and are not
warm-started.
"""
from __future__ import annotations

import math
import time
from contextlib import nullcontext
from dataclasses import asdict, dataclass, field
from functools import partial
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from ..display import Display, fmt
from ..errors import WncsError
from ..methods import DEFAULT_METHOD, check_method
from ..models.system import System
from ..policies import POLICY_NAMES, parse_policy_names
from ..policies.factory import NEED_MDP, OPTIMAL
from ..progress import eta
from ..scenario import Scenario
from ..solvers.route import build_scenario
from ..workflow import make_policy, run_scenario
from .executors import check_executor
from .folder import FINGERPRINT, StudyFolder, read_table
from .grid import parse_values, value_key
from .runner import run_grid

__all__ = ["SweepRow", "SweepResult", "run_sweep", "parse_values", "read_rows", "COLUMNS", "compute_point",
           "value_column"]

#: The columns of ``sweep.csv`` (the fingerprint last).
COLUMNS = ("param", "value", "policy", "gain", "sim_mean", "sim_stderr", "seconds", "states", "warm_start", "status",
           FINGERPRINT)
_INT_PARAMS = ("tau_cap", "uplink_delay", "downlink_delay", "slots_per_dimension")


def value_column(param: str) -> str:
    """The column a sweep's table names its values by: the parameter itself (``p``, ``tau_cap``), or
    ``value`` for a parameter named like another column. ``sweep.csv`` keeps ``value``: it is the
    resumable store, read back by its fixed header."""
    return "value" if param in COLUMNS or not param else param


def _num(s: str) -> float:
    return float(s) if s not in ("", None) else math.nan


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
        return (value_key(self.value), self.policy)

    @property
    def value_column(self) -> str:
        """The name of the value's column in the row's table: the swept parameter's (``p``)."""
        return value_column(self.param)

    def to_dict(self) -> dict[str, Any]:
        """The row with its value under the parameter's name: ``{"param": "p", "p": 0.9, "policy": ...}``."""
        d = asdict(self)
        for k in ("gain", "sim_mean", "sim_stderr"):
            if not math.isfinite(d[k]):
                d[k] = None
        value = d.pop("value")
        return {"param": d.pop("param"), self.value_column: value, **d}

    def to_csv(self) -> list[str]:
        """The row's cells, without its fingerprint."""
        def num(x: float) -> str:
            return "" if not math.isfinite(x) else repr(float(x))

        return [self.param, repr(float(self.value)), self.policy, num(self.gain), num(self.sim_mean),
                num(self.sim_stderr), repr(float(self.seconds)), str(int(self.states)),
                "true" if self.warm_start else "false", self.status]

    @classmethod
    def from_csv(cls, rec: dict[str, str]) -> "SweepRow":
        """From a CSV record (ValueError for a value no sweep writes: a negative count, an unknown policy, ...)."""
        row = cls(param=rec["param"], value=float(rec["value"]), policy=rec["policy"], gain=_num(rec["gain"]),
                  sim_mean=_num(rec["sim_mean"]), sim_stderr=_num(rec["sim_stderr"]), seconds=float(rec["seconds"]),
                  states=int(rec["states"]), warm_start=rec["warm_start"] == "true", status=rec["status"])
        if (not row.param or not math.isfinite(row.value) or row.policy not in POLICY_NAMES or row.states < 0
                or not row.seconds >= 0 or rec["warm_start"] not in ("true", "false") or not row.status):
            raise ValueError(f"not a sweep row: {rec}")
        return row


@dataclass(frozen=True, repr=False)
class SweepResult(Display):
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
    dropped : int
        Rows of the output folder not reused because their fingerprint did not check out
        (another scenario's, edited by hand, duplicated): recomputed, or dropped from the table.
    seconds : float
    """

    rows: tuple[SweepRow, ...]
    out_dir: Path | None
    files: dict[str, str] = field(default_factory=dict)
    computed: int = 0
    reused: int = 0
    seconds: float = 0.0
    dropped: int = 0

    def table(self) -> list[dict[str, Any]]:
        """The rows as JSON-ready dictionaries."""
        return [r.to_dict() for r in self.rows]

    def column(self, policy: str, name: str = "gain") -> np.ndarray:
        """One column for one policy, in grid order (``name``: a field of :class:`SweepRow`, or the
        parameter's name for its values)."""
        return np.array([getattr(r, "value" if name == r.value_column else name) for r in self.rows
                         if r.policy == policy], dtype=float)

    # the printout, the HTML form in Jupyter and to_frame() (wncs_lp.display): one record per row
    def _display_head(self) -> str:
        params = sorted({r.param for r in self.rows})
        values = len({r.key[0] for r in self.rows})
        policies = list(dict.fromkeys(r.policy for r in self.rows))
        return (f"SweepResult: {len(self.rows)} rows, {', '.join(params) or 'no parameter'} over {values} values, "
                f"policies {', '.join(policies)}")

    def _display_rows(self) -> list[tuple[str, str]]:
        errors = sum(r.status.startswith("error") for r in self.rows)
        rows = [("computed", fmt(self.computed)), ("reused", fmt(self.reused)), ("errors", fmt(errors)),
                ("seconds", f"{self.seconds:.2f}")]
        if self.dropped:
            rows.append(("dropped", fmt(self.dropped)))
        rows += [(k, v) for k, v in self.files.items()]
        return rows

    def _frame_records(self):
        name = self.rows[0].value_column if self.rows else "value"
        cols = [name, "policy", "gain", "sim_mean", "sim_stderr", "seconds", "states", "warm_start", "status"]
        return cols, [{**r.to_dict(), name: r.value} for r in self.rows]


def _row_key(row: SweepRow) -> str:
    return "|".join(row.key)


def read_rows(path: str | Path) -> list[SweepRow]:
    """Complete, well-formed rows of a sweep CSV (a truncated or malformed line is skipped; the
    fingerprints are checked only by a resumed sweep, which knows its settings)."""
    return read_table(path, COLUMNS, SweepRow.from_csv)


# ----------------------------------------------------------------------------- one grid point
def _override_value(param: str, value: float) -> Any:
    if param.split(".")[-1] in _INT_PARAMS and float(value).is_integer():
        return int(value)
    return float(value)


def _policy_row(name: str, sc: Scenario, system: System, mdp: Any, opts: dict[str, Any], warm: Any
                ) -> tuple[dict[str, Any], Any]:
    """The numbers of one policy's row (status ``error: ...`` for a failure), and the warm start it hands on."""
    from ..evaluate import evaluate
    from ..simulate import simulate

    out: dict[str, Any] = {"status": "ok", "warm_start": False}
    new_warm = None
    try:
        solution = None
        if name == OPTIMAL:
            run = run_scenario(sc, opts["method"], constrained=False, mdp=mdp, warm=warm,
                                 threads=opts.get("threads"))
            solution, new_warm, out["warm_start"] = run.solution, run.warm(), run.warm_start
            if not solution.ok:
                out["status"] = f"error: solver status {solution.status}"
        pol = make_policy(name, system, mdp, method=opts["method"], solution=solution)
        if opts["exact"]:
            ev = evaluate(mdp, pol, multichain="initial")
            out["gain"] = ev.gain
            if ev.recurrent_classes > 1 and out["status"] == "ok":
                out["status"] = (f"ok (multichain: {ev.recurrent_classes} recurrent classes; "
                                 "gain from the initial state)")
        if opts["simulate_slots"] > 0:
            res = simulate(pol, slots=opts["simulate_slots"], reps=opts["reps"], seed=opts["seed"],
                           burn_in=opts["burn_in"], progress=opts.get("progress", False))
            out["sim_mean"], out["sim_stderr"] = res.mean, res.stderr
    except WncsError as exc:
        out["status"] = f"error: {exc}".replace("\n", " ")
    return out, new_warm


def compute_point(scenario: Scenario, param: str, opts: dict[str, Any], task: tuple[float, Sequence[str]],
                  warm: Any = None, emit: Callable[[SweepRow], None] | None = None) -> tuple[list[SweepRow], Any]:
    """All requested rows of one grid value (``task = (value, policies)``; a picklable unit of
    work for :func:`~wncs_lp.studies.runner.run_grid`).

    Returns the rows and the :class:`~wncs_lp.solvers.route.WarmStart` of the optimal solve
    for the next grid value (None without one).
    """
    value, policies = task
    sc = scenario.with_overrides({param: _override_value(param, value)})
    system = System.from_scenario(sc)
    need_mdp = opts["exact"] or any(p in NEED_MDP for p in policies)
    method = opts["method"] if OPTIMAL in policies else None  # what the guard counts
    mdp = build_scenario(sc, method, force=opts["force"])[0] if need_mdp else None
    rows: list[SweepRow] = []
    new_warm = None
    for name in policies:
        t0 = time.perf_counter()
        out, made = _policy_row(name, sc, system, mdp, opts, warm)
        new_warm = made or new_warm
        row = SweepRow(param=param, value=float(value), policy=name, seconds=time.perf_counter() - t0,
                       states=int(mdp.n_states) if mdp is not None else 0, **out)
        rows.append(row)
        if emit is not None:
            emit(row)
    return rows, new_warm


# ----------------------------------------------------------------------------- the sweep
def _settings(scenario: Scenario, param: str, opts: dict[str, Any]) -> dict[str, Any]:
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


class _Table:
    """The rows of a sweep run, in memory and (with a folder) on disk after each one."""

    def __init__(self, grid: list[float], names: list[str], folder: StudyFolder | None, settings: dict[str, Any],
                 log: Callable[[str], None] | None):
        self.grid, self.names, self.folder, self.settings, self.log = grid, names, folder, settings, log
        self.done: dict[str, SweepRow] = folder.rows(SweepRow.from_csv, _row_key) if folder is not None else {}
        errors = [k for k in self.keys() if k in self.done and self.done[k].status.startswith("error")]
        for k in errors:  # computed again (module docstring)
            del self.done[k]
        if errors and log is not None:
            log(f"{len(errors)} row(s) of the folder with an error status computed again")
        self.reused = sum(1 for k in self.keys() if k in self.done)
        self.computed = 0
        self.files: dict[str, str] = {}
        self.total = sum(len(ps) for _, ps in self.todo())  # rows this run computes (for the ETA)
        self.started = time.monotonic()

    def keys(self) -> list[str]:
        return [f"{value_key(v)}|{p}" for v in self.grid for p in self.names]

    def todo(self) -> list[tuple[float, list[str]]]:
        todo = [(v, [p for p in self.names if f"{value_key(v)}|{p}" not in self.done]) for v in self.grid]
        return [(v, ps) for v, ps in todo if ps]

    def record(self, row: SweepRow) -> None:
        self.done[_row_key(row)] = row
        self.computed += 1
        self.save()
        if self.log is not None:
            g = "-" if not math.isfinite(row.gain) else f"{row.gain:.6g}"
            s = "" if not math.isfinite(row.sim_mean) else f", sim {row.sim_mean:.6g} +- {row.sim_stderr:.2g}"
            where = eta(self.computed, self.total, time.monotonic() - self.started)
            self.log(f"[{where}] {row.param}={row.value:g} {row.policy}: gain {g}{s} ({row.seconds:.2f} s) "
                     f"{row.status}")

    def save(self) -> None:
        if self.folder is None:
            return
        order_v = {value_key(v): i for i, v in enumerate(self.grid)}
        order_p = {p: i for i, p in enumerate(POLICY_NAMES)}
        rows = sorted(self.done.values(), key=lambda r: (order_v.get(value_key(r.value), len(self.grid)), r.value,
                                                         order_p.get(r.policy, 99)))
        named = [value_column(self.settings["param"]) if c == "value" else c for c in COLUMNS[:-1]]
        payload = {"settings": self.settings, "columns": named, "rows": [r.to_dict() for r in rows]}
        self.files.update(self.folder.write(((_row_key(r), r.to_csv()) for r in rows), payload))

    def rows(self) -> tuple[SweepRow, ...]:
        return tuple(self.done[k] for k in self.keys())


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
    executor: Any = None,
    threads: int | None = None,
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
        Grid values computed in parallel worker processes (default 1: in order, with warm start).
    executor : None, "process", "dask", str, Client or Executor
        Where the grid values run (:mod:`wncs_lp.studies.executors`): worker processes (with
        ``max_workers > 1``), a local Dask cluster (``"dask"``), the Dask scheduler at an address
        (``"tcp://HOST:PORT"``), your own ``dask.distributed.Client`` or a
        ``concurrent.futures.Executor``.
    threads : int, optional
        Kernel threads of the optimal solve (default: the solver's).
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
    check_executor(executor)  # up front: a one-point sweep never builds the executor
    check_method(method)
    opts = {"method": method, "exact": exact, "simulate_slots": int(simulate_slots or 0), "reps": int(reps),
            "seed": seed, "burn_in": int(burn_in), "progress": progress, "force": force, "threads": threads}
    settings = _settings(scenario, param, opts)
    folder = StudyFolder(out_dir, "sweep", settings, COLUMNS, "a sweep") if out_dir is not None else None
    with folder if folder is not None else nullcontext():
        table = _Table(grid, names, folder, settings, log)
        if folder is not None and folder.dropped and log is not None:
            log(f"{folder.dropped} row(s) of {folder.csv} not reused: their fingerprint does not match this sweep "
                "(another scenario's, edited, or duplicated); recomputed where on the grid")
        run_grid(table.todo(), partial(compute_point, scenario, param, opts), table.record, executor=executor,
                 max_workers=max_workers)
        table.save()
        if folder is not None and plot:
            from ..viz import save_sweep_figure

            table.files.update(save_sweep_figure(table.rows(), folder.path / "sweep",
                                                 title=f"{Path(scenario.source).stem}: {param} sweep"))
    return SweepResult(rows=table.rows(), out_dir=folder.path if folder is not None else None, files=table.files,
                       computed=table.computed, reused=table.reused, seconds=time.perf_counter() - t_start,
                       dropped=folder.dropped if folder is not None else 0)

