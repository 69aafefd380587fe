"""Scenario files (TOML) -> validated, frozen :class:`Scenario` objects.

The format (the model it describes: ``docs/model.md``)::

    [model]     kind, allow_idle, distinct, preemptive, tau_cap
    [channel]   success_probability
    [[process]] name, A, R, weight, tau_cap, cost, arrival_probability
    [[server]]  name, uplink_delay, downlink_delay,
                slots_per_dimension | processing_time, p_up, p_down (a number, or one per process)
    [[constraint]] quantity, server, process, max, min   (constrained scheduling;
                docs/constraints.md)

Loading goes raw TOML -> plain dict -> overrides -> validation -> frozen dataclasses, so an
override is validated exactly like a field written in the file, and every error is one
:class:`~wncs_lp.errors.ScenarioError` naming the source, the field and the expectation.
"""
from __future__ import annotations

import copy
import hashlib
import json
import math
import re
import sys
from dataclasses import KW_ONLY, InitVar, dataclass, field
from pathlib import Path
from typing import Any, Iterable, Mapping

import numpy as np

from .errors import ScenarioError, printable
from .files import read_regular

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

__all__ = [
    "ModelOptions",
    "CostSpec",
    "ProcessSpec",
    "ServerSpec",
    "ConstraintSpec",
    "QUANTITIES",
    "Scenario",
    "load_scenario",
    "scenario_from_dict",
    "parse_overrides",
    "apply_overrides",
]

KINDS = ("wncs", "preemption")
_MODEL_FIELDS = {"kind", "allow_idle", "distinct", "preemptive", "tau_cap"}
_CHANNEL_FIELDS = {"success_probability"}
_PROCESS_FIELDS = {"name", "A", "R", "weight", "tau_cap", "cost", "arrival_probability"}
_SERVER_FIELDS = {
    "name",
    "uplink_delay",
    "downlink_delay",
    "slots_per_dimension",
    "processing_time",
    "p_up",
    "p_down",
}
_CONSTRAINT_FIELDS = {"quantity", "server", "process", "max", "min"}
_TOP_FIELDS = {"model", "channel", "process", "server", "constraint"}
#: The long-run averages a ``[[constraint]]`` can bound, and what each needs:
#: ``cost`` the total MSE; ``process_cost`` / ``aoi`` one process's weighted MSE / capped AoI
#: (need ``process``); ``send_rate`` the fraction of slots in which a server is sent an update
#: (needs ``server``; ``process`` optionally restricts it to that process's updates).
QUANTITIES = ("cost", "process_cost", "aoi", "send_rate")
#: Largest AoI cap accepted on load; far beyond anything enumerable, it only stops absurd input.
MAX_TAU_CAP = 100_000
#: Deepest nesting of lists and tables accepted (a scenario needs 5: top table, [[process]] list,
#: its table, the matrix A, a row); deeper input is refused before anything recurses into it.
MAX_DEPTH = 16
#: Largest scenario file read (bytes): a scenario is a few kilobytes, explicit cost tables up to
#: the largest cap a few megabytes; a larger file is refused by its size before it is read.
MAX_SCENARIO_BYTES = 64 << 20
#: A process or server selector of an override made of ASCII digits only is a 1-based index.
_INDEX = re.compile(r"[0-9]+")
#: One part of an override key: a "quoted" literal or bare text up to the next dot.
_PART = re.compile(r'"([^"]*)"|([^."]+)')


# ----------------------------------------------------------------------------- dataclasses
def _frozen_array(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


@dataclass(frozen=True)
class ModelOptions:
    """The ``[model]`` table: which MDP to build and its options."""

    kind: str = "wncs"
    allow_idle: bool = False
    distinct: bool = True
    preemptive: bool = True


@dataclass(frozen=True)
class CostSpec:
    """The cost family of one process: q(tau) = weight * f(tau), tau = 1..tau_hat.

    Attributes
    ----------
    family : {"mse", "aoi", "power", "table"}
        ``"mse"``: f(tau) = trace(sum_{i<tau} A^i R A^iT) (the default, ``docs/model.md``
        section 1); ``"aoi"``: f(tau) = tau; ``"power"``: f(tau) = tau ** power; ``"table"``:
        f(tau) = table[tau - 1].
    power : float
        The exponent of ``"power"`` (> 0; 1.0 otherwise).
    table : tuple of float
        The values of ``"table"``, at least tau_hat of them, finite, >= 0 and nondecreasing
        (empty otherwise).
    """

    family: str = "mse"
    power: float = 1.0
    table: tuple[float, ...] = ()

    def __str__(self) -> str:
        if self.family == "power":
            return f"aoi^{self.power:g}"
        if self.family == "table":
            return f"table[{len(self.table)}]"
        return self.family

    def to_raw(self) -> Any:
        """The scenario-file value of this cost (``"aoi"``, ``{"power": 2.0}``, a list)."""
        if self.family == "power":
            return {"power": self.power}
        if self.family == "table":
            return list(self.table)
        return self.family


#: The default cost: the MSE of the paper.
MSE_COST = CostSpec()


@dataclass(frozen=True, eq=False)
class ProcessSpec:
    """One LTI process x(t+1) = A x + B u + z, z ~ N(0, R), with weight, AoI cap, cost family and
    arrivals.

    Attributes
    ----------
    cost : CostSpec
        The cost family (default: the MSE).
    arrival_probability : float
        lambda_k in (0, 1]: the probability that the sensor generates an update in a slot; 1.0
        (the default) is the paper's sampling at will (``docs/model.md``, "Random arrivals").
    """

    name: str
    A: np.ndarray
    R: np.ndarray
    weight: float
    tau_cap: int
    cost: CostSpec = MSE_COST
    arrival_probability: float = 1.0

    @property
    def dim(self) -> int:
        """n_k, the dimension of the process state."""
        return int(self.A.shape[0])

    @property
    def has_arrivals(self) -> bool:
        """Whether updates arrive at random (lambda_k < 1) rather than at will."""
        return self.arrival_probability < 1.0

    def __eq__(self, other: object) -> bool:
        return (
            isinstance(other, ProcessSpec)
            and self.name == other.name
            and self.weight == other.weight
            and self.tau_cap == other.tau_cap
            and self.cost == other.cost
            and self.arrival_probability == other.arrival_probability
            and np.array_equal(self.A, other.A)
            and np.array_equal(self.R, other.R)
        )

    def __hash__(self) -> int:
        return hash((self.name, self.weight, self.tau_cap, self.cost, self.arrival_probability,
                     self.A.tobytes(), self.R.tobytes()))


@dataclass(frozen=True)
class ServerSpec:
    """One server m: delays U, D, processing times T_{m,k}, link success probabilities.

    Attributes
    ----------
    processing_time : tuple of int
        T_{m,k}, one per process.
    p_up, p_down : tuple of float
        pu_{m,k} and pd_{m,k}: the success probability of process k's uplink to this server and
        of its downlink from it, one per process (``docs/model.md``, "Per-link success
        probabilities"); all equal unless the scenario gives a list.
    """

    name: str
    uplink_delay: int
    downlink_delay: int
    processing_time: tuple[int, ...]
    p_up: tuple[float, ...]
    p_down: tuple[float, ...]

    @property
    def loop(self) -> tuple[int, ...]:
        """U + T_k + D for every process k: the age a delivered command carries."""
        return tuple(self.uplink_delay + t + self.downlink_delay for t in self.processing_time)


@dataclass(frozen=True)
class ConstraintSpec:
    """One ``[[constraint]]`` table: a bound on a long-run average per slot.

    Attributes
    ----------
    quantity : str
        One of :data:`QUANTITIES`.
    server : int or None
        0-based server index (``send_rate``), else None.
    process : int or None
        0-based process index (``process_cost``, ``aoi``; an optional filter of ``send_rate``).
    max, min : float or None
        The bounds; at least one is set, and ``min <= max``.
    label : str
        A readable name, e.g. ``"send_rate[remote] <= 0.2"``.
    """

    quantity: str
    server: int | None = None
    process: int | None = None
    max: float | None = None
    min: float | None = None
    label: str = ""

    def __str__(self) -> str:
        return self.label or self.quantity


@dataclass(frozen=True)
class Scenario:
    """A validated scenario. Build it with :func:`load_scenario` or :func:`scenario_from_dict`.

    Attributes
    ----------
    model : ModelOptions
    p : float
        The channel's success probability (default for every link).
    processes, servers : tuple
        The processes and servers, in file order (process k of the paper is ``processes[k-1]``).
    constraints : tuple of ConstraintSpec
        The ``[[constraint]]`` tables in file order (empty for an unconstrained scenario).
        They do not change the MDP, only what a constrained solve asks of it, so they are
        not part of :meth:`fingerprint`.
    source : str
        Where it came from (file path or ``<dict>``), for messages.
    raw : mapping
        The raw dictionary the fields were validated from (overrides applied): the source of
        every other field. :meth:`replace` / :meth:`with_overrides` edit it and validate again.

    Notes
    -----
    The fields are derived from ``raw`` (a server's ``p_up`` from the channel's ``p`` when it sets
    none, ``T_k`` from ``slots_per_dimension`` and the dimension of A...), so
    ``dataclasses.replace(scenario, p=0.5)`` cannot know what else must follow: it is refused
    with a :class:`ScenarioError` naming the field (a scenario whose fields disagree with its
    ``raw`` is never built). Use ``scenario.replace(p=0.5)``, which edits ``raw`` and validates.
    """

    model: ModelOptions
    p: float
    processes: tuple[ProcessSpec, ...]
    servers: tuple[ServerSpec, ...]
    constraints: tuple[ConstraintSpec, ...] = ()
    source: str = field(default="<dict>", compare=False)
    raw: Mapping[str, Any] = field(default_factory=dict, compare=False, repr=False)
    _: KW_ONLY
    #: True when the fields were just validated from ``raw`` (set by :func:`scenario_from_dict`).
    validated: InitVar[bool] = False

    def __post_init__(self, validated: bool) -> None:
        if validated or not self.raw:
            return
        # built another way (dataclasses.replace, the constructor): the fields must be raw's
        truth = scenario_from_dict(self.raw, source=self.source)
        for name in ("model", "p", "processes", "servers", "constraints"):
            mine, theirs = getattr(self, name), getattr(truth, name)
            both_nan = name == "p" and isinstance(mine, float) and math.isnan(mine) and math.isnan(theirs)
            if not both_nan and mine != theirs:
                raise ScenarioError(
                    self.source, name,
                    f"disagrees with the scenario's raw dictionary, from which the other fields are derived "
                    f"(dataclasses.replace changes one field and leaves e.g. every server's p_up/p_down and "
                    f"processing times as they were); use scenario.replace({name}=...) with a key of "
                    f"docs/scenarios.md, e.g. scenario.replace(p=0.5) or scenario.replace(**{{'process.1.weight': 2}})",
                    what="Scenario field")

    @property
    def n_processes(self) -> int:
        return len(self.processes)

    @property
    def n_servers(self) -> int:
        return len(self.servers)

    @property
    def tau_caps(self) -> tuple[int, ...]:
        return tuple(pr.tau_cap for pr in self.processes)

    def to_dict(self) -> dict[str, Any]:
        """The raw (pre-validation) dictionary this scenario was built from, overrides applied."""
        return copy.deepcopy(dict(self.raw))

    def with_overrides(self, overrides: Mapping[str, Any] | Iterable[str] | str) -> "Scenario":
        """A new scenario with overrides applied (``{"p": 0.8}``, ``["p=0.8", ...]`` or ``"p=0.8"``),
        validated like a file (the keys of :func:`apply_overrides`)."""
        raw = apply_overrides(self.to_dict(), _as_overrides(overrides, self.source), self.source)
        return scenario_from_dict(raw, source=self.source)

    def replace(self, **fields: Any) -> "Scenario":
        """A new, validated scenario with some fields changed: ``scenario.replace(p=0.5, tau_cap=10)``.

        The keys are those of an override (:func:`apply_overrides`: ``p``, ``tau_cap``,
        ``model.FIELD``...; dotted ones as ``replace(**{"process.1.weight": 2})``), so every
        derived field follows (each server's ``p_up``/``p_down`` from ``p`` when it sets none).
        The same as :meth:`with_overrides`; prefer it to ``dataclasses.replace``, which is refused.
        """
        return self.with_overrides(fields)

    def fingerprint(self) -> str:
        """A stable hash of the validated content (for caches keyed by scenario).

        A field at its default (the MSE cost, sampling at will, one link probability for every
        process of a server) hashes as it did before the field existed, so the caches of the
        scenarios that do not use it stay valid.
        """
        def process(pr: ProcessSpec) -> list:
            row = [pr.name, pr.A.tolist(), pr.R.tolist(), pr.weight, pr.tau_cap]
            if pr.cost != MSE_COST:
                row.append({"cost": pr.cost.to_raw()})
            if pr.has_arrivals:
                row.append({"arrival_probability": pr.arrival_probability})
            return row

        def server(sv: ServerSpec) -> dict:
            out = dict(vars(sv))
            for key in ("p_up", "p_down"):
                out[key] = _uniform(out[key])
            return out

        content = {
            "model": vars(self.model),
            "p": None if math.isnan(self.p) else self.p,
            "processes": [process(pr) for pr in self.processes],
            "servers": [server(s) for s in self.servers],
        }
        payload = json.dumps(_canonical(content), sort_keys=True)
        return hashlib.sha256(payload.encode()).hexdigest()[:16]

    @property
    def has_arrivals(self) -> bool:
        """Whether some process has random arrivals (``arrival_probability < 1``)."""
        return any(pr.has_arrivals for pr in self.processes)

    def degenerate_warnings(self) -> list[str]:
        """Warnings, in words, about a valid scenario that describes a degenerate problem.

        * a server whose every link fails (``p_up = 0`` or ``p_down = 0`` for every process, e.g.
          from ``channel.success_probability = 0``) never delivers: it is useless, and when every
          server is so, every AoI climbs to its cap and stays there (every policy costs the same);
        * a process none of whose links to a working server succeeds is never delivered;
        * a process whose ``tau_cap`` is at most the shortest loop ``U + T + D`` of every server:
          a delivered update is never fresher than the cap, so its AoI stays at the cap and
          scheduling it changes nothing.

        The command line prints them on stderr (``warning: ...``); :func:`wncs_lp.build` issues
        them as :class:`~wncs_lp.errors.ScenarioWarning`. They are not errors: such scenarios
        solve, with a result that says little.
        """
        out = []

        def works(sv: ServerSpec, k: int) -> bool:
            return sv.p_up[k] > 0 and sv.p_down[k] > 0

        N = self.n_processes
        dead = [sv for sv in self.servers if not any(works(sv, k) for k in range(N))]
        why = " (the channel's success_probability is 0)" if self.p == 0 else ""
        if dead and len(dead) == len(self.servers):
            out.append(f"{self.source}: no update is ever delivered: every server has p_up = 0 or p_down = 0{why}; "
                       "every AoI climbs to its cap and stays there, so every policy costs the same")
        else:
            for sv in dead:
                if _uniform(sv.p_up) == 0 or _uniform(sv.p_down) == 0:
                    link = "uplink (p_up = 0)" if _uniform(sv.p_up) == 0 else "downlink (p_down = 0)"
                else:
                    link = "link of every process (p_up = 0 or p_down = 0)"
                out.append(f"{self.source}: server '{sv.name}' never delivers: its {link} always fails, "
                           "so sending it updates is never useful")
            for k, pr in enumerate(self.processes):
                if not any(works(sv, k) for sv in self.servers if sv not in dead):
                    out.append(f"{self.source}: process '{pr.name}' is never delivered: its link to every server has "
                               "p_up = 0 or p_down = 0, so its AoI climbs to its cap and stays there")
        for k, pr in enumerate(self.processes):
            loops = [(sv.loop[k], sv.name) for sv in self.servers]
            shortest, name = min(loops)
            if pr.tau_cap <= shortest:
                out.append(f"{self.source}: process '{pr.name}': tau_cap = {pr.tau_cap} is at most the shortest loop "
                           f"U + T + D of any server ({shortest} slots, server '{name}'): a delivered update is never "
                           f"fresher than the cap, so its AoI stays at the cap and scheduling it changes nothing; "
                           f"raise tau_cap above {shortest}")
        return out

    def describe(self) -> str:
        """A one-paragraph human summary."""
        def extra(pr: ProcessSpec) -> str:
            text = f", cost={pr.cost}" if pr.cost != MSE_COST else ""
            return text + (f", lambda={pr.arrival_probability:g}" if pr.has_arrivals else "")

        procs = ", ".join(f"{printable(pr.name)} (n={pr.dim}, cap={pr.tau_cap}, w={pr.weight:g}{extra(pr)})"
                          for pr in self.processes)
        servs = ", ".join(
            f"{printable(s.name)} (U={s.uplink_delay}, D={s.downlink_delay}, T={list(s.processing_time)}, "
            f"pu={_show_links(s.p_up)}, pd={_show_links(s.p_down)})"
            for s in self.servers
        )
        text = f"kind={self.model.kind}; processes: {procs}; servers: {servs}"
        if self.constraints:
            text += "; constraints: " + ", ".join(c.label for c in self.constraints)
        return text


def _uniform(values: tuple[float, ...]) -> float | list[float]:
    """One number when every process's link has it (the form of a scenario without per-link
    values), else the list."""
    values = tuple(values)
    return float(values[0]) if values and all(v == values[0] for v in values) else [float(v) for v in values]


def _show_links(values: tuple[float, ...]) -> str:
    one = _uniform(values)
    return f"{one:g}" if isinstance(one, float) else "[" + ", ".join(f"{v:g}" for v in one) + "]"


def _canonical(obj: Any) -> Any:
    if isinstance(obj, Mapping):
        return {str(k): _canonical(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_canonical(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _canonical(obj.tolist())
    return obj


# ----------------------------------------------------------------------------- loading
def load_scenario(path: str | Path, overrides: Mapping[str, Any] | Iterable[str] | str | None = None) -> Scenario:
    """Load and validate a TOML scenario file, applying overrides on top.

    Parameters
    ----------
    path : str or Path
        The TOML file.
    overrides : mapping, iterable of ``"key=value"`` strings, or one such string, optional
        Applied before validation: ``p`` (channel success probability), ``tau_cap`` (every
        process's cap), or a dotted path such as ``process.2.weight`` / ``server.edge.p_up``
        (processes and servers addressed by 1-based index or by name; see :func:`apply_overrides`).

    Raises
    ------
    ScenarioError
        The file cannot be read or parsed, or a field or override is invalid.
    """
    if not isinstance(path, (str, Path)):
        raise ScenarioError("<argument>", "path", f"expected a file name (str or Path), found {_show(path)}",
                            what="argument")
    path = Path(path)
    source = str(path)
    try:
        text = read_regular(path, MAX_SCENARIO_BYTES)  # a pipe, a device, a folder: refused at once
    except OSError as exc:
        raise ScenarioError(source, "<file>", f"cannot be read ({exc.strerror or exc})") from None
    raw = _parse_toml(text, source)
    items = _as_overrides(overrides, source)
    if items:
        raw = apply_overrides(raw, items, source)
    return scenario_from_dict(raw, source=source)


def _parse_toml(text: bytes, source: str) -> dict[str, Any]:
    """The TOML document of a file, or one ScenarioError naming the file."""
    try:
        return tomllib.loads(text.decode("utf-8"))
    except UnicodeDecodeError:
        raise ScenarioError(source, "<file>", "expected UTF-8 TOML text, found undecodable bytes") from None
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(source, "<file>", f"malformed TOML: {exc}") from None
    except RecursionError:
        raise ScenarioError(source, "<file>", f"arrays or tables nested too deeply (a scenario needs at most "
                                              f"{MAX_DEPTH} levels)") from None
    except ValueError:  # an integer of more digits than Python converts
        raise ScenarioError(source, "<file>", f"expected values Python can read, found {_too_long()}") from None


def _too_long() -> str:
    limit = sys.get_int_max_str_digits() if hasattr(sys, "get_int_max_str_digits") else 4300
    return f"an integer of more than {limit} digits"


def _as_overrides(overrides: Any, source: str) -> dict[str, Any]:
    """Overrides given as a mapping, an iterable of ``"KEY=VALUE"`` strings or one such string,
    as a ``{key: value}`` dict whose keys are strings."""
    if overrides is None:
        return {}
    if isinstance(overrides, str):
        return parse_overrides([overrides])
    if isinstance(overrides, Mapping):
        for key in overrides:
            if not isinstance(key, str) or not key.strip():
                raise ScenarioError(source, _show(key) if key else "<empty key>", "expected a string key such as "
                                    "'p', 'tau_cap' or 'process.1.weight'", what="override")
        return {key.strip(): value for key, value in overrides.items()}
    try:
        items = list(overrides)
    except TypeError:
        raise ScenarioError(source, "<overrides>", f"expected a mapping, a list of 'KEY=VALUE' strings or one "
                            f"such string, found {_show(overrides)}", what="override") from None
    return parse_overrides(items)


def parse_overrides(items: Iterable[str] | str) -> dict[str, Any]:
    """Parse ``["p=0.8", "process.1.A=[[1.1]]"]`` (or one string ``"p=0.8"``) into ``{"p": 0.8, ...}``.

    Values are read as TOML values (numbers, booleans, arrays, quoted strings); a bare word
    that is not valid TOML is taken as a string (``--set model.kind=preemption``).
    """
    if isinstance(items, str):
        items = [items]
    out: dict[str, Any] = {}
    for item in items:
        if not isinstance(item, str) or "=" not in item:
            shown = item if isinstance(item, str) else _show(item)
            raise ScenarioError("--set", shown, "expected KEY=VALUE, e.g. --set p=0.8", what="override")
        key, value = item.split("=", 1)
        key, value = key.strip(), value.strip()
        if not key:
            raise ScenarioError("--set", item, "expected a non-empty KEY in KEY=VALUE, e.g. --set p=0.8",
                                what="override")
        try:
            parsed = tomllib.loads(f"v = {value}")["v"]
        except tomllib.TOMLDecodeError:
            parsed = value
        except RecursionError:
            raise ScenarioError("--set", key, f"expected a value nested at most {MAX_DEPTH} levels deep",
                                what="override") from None
        except ValueError:  # an integer of more digits than Python converts
            raise ScenarioError("--set", key, f"expected a value Python can read, found {_too_long()}",
                                what="override") from None
        out[key] = parsed
    return out


def _key_parts(key: str, source: str) -> list[tuple[str, bool]]:
    """The dot-separated parts of an override key, each ``(text, quoted)``.

    A part in double quotes is taken literally (it may hold dots) and, as a process or server
    selector, is always a name: ``process."2".weight`` is the process *named* "2".
    """
    parts: list[tuple[str, bool]] = []
    i = 0
    while True:
        m = _PART.match(key, i)
        if m is None:
            raise ScenarioError(source, key, 'malformed key: expected dot-separated parts such as process.1.weight '
                                             '(a name in double quotes may hold dots or be all digits)', what="override")
        parts.append((m.group(1), True) if m.group(1) is not None else (m.group(2), False))
        i = m.end()
        if i == len(key):
            return parts
        if key[i] != "." or i + 1 == len(key):
            raise ScenarioError(source, key, "malformed key: expected a '.' between parts and none at the end",
                                what="override")
        i += 1


def _find_entry(entries: list, selector: str, quoted: bool, kind: str, source: str, key: str) -> dict:
    if not quoted and _INDEX.fullmatch(selector):
        i = int(selector) if len(selector) < 10 else 0
        if not 1 <= i <= len(entries):
            raise ScenarioError(
                source, key, f"{kind} index {selector} out of range: expected 1..{len(entries)} (a selector of "
                f"digits is an index; quote a name made of digits: {kind}.\"{selector}\")", what="override"
            )
        entry = entries[i - 1]
    else:
        matches = [e for e in entries if isinstance(e, dict) and e.get("name") == selector]
        if not matches:
            names = [e.get("name") for e in entries if isinstance(e, dict)]
            raise ScenarioError(
                source, key, f"no {kind} named '{selector}': expected a 1-based index or one of {names}", what="override"
            )
        entry = matches[0]
    if not isinstance(entry, dict):
        raise ScenarioError(source, f"{kind}[{selector}]", "expected a table")
    return entry


def _table_of(out: dict, name: str, source: str) -> dict:
    """``out[name]``, created empty when missing; one error when it is not a table."""
    out.setdefault(name, {})
    if not isinstance(out[name], dict):
        raise ScenarioError(source, name, f"expected a table, found {type(out[name]).__name__}")
    return out[name]


def apply_overrides(raw: Mapping[str, Any], overrides: Mapping[str, Any], source: str = "<dict>") -> dict[str, Any]:
    """Apply overrides to a raw scenario dictionary (returns a new dict; input untouched).

    Keys: ``p`` (alias ``success_probability``), ``tau_cap`` (the model default *and* every
    process), ``model.FIELD``, ``channel.FIELD``, ``process.K.FIELD``, ``server.M.FIELD``
    (K, M a 1-based index or a name), ``constraint.J.FIELD`` (J a 1-based index; setting
    ``max`` or ``min`` to ``"none"`` removes that bound). A selector of ASCII digits only is an
    index; a name made of digits, or holding a dot, is written in double quotes
    (``process."2".weight``). Unknown keys raise :class:`ScenarioError`.
    """
    _check_depth(raw, source, "<top>")
    out = copy.deepcopy(dict(raw))
    for key, value in _as_overrides(overrides, source).items():
        _check_depth(value, source, key, start=3)
        parts = _key_parts(key, source)
        names = [text for text, _ in parts]
        if len(parts) == 1 and names[0] in ("p", "success_probability"):
            _table_of(out, "channel", source)["success_probability"] = value
        elif len(parts) == 1 and names[0] == "tau_cap":
            _table_of(out, "model", source)["tau_cap"] = value
            procs = out.get("process")
            for entry in procs if isinstance(procs, list) else []:
                if isinstance(entry, dict):
                    entry["tau_cap"] = value
        elif len(parts) == 2 and names[0] in ("model", "channel"):
            allowed = _MODEL_FIELDS if names[0] == "model" else _CHANNEL_FIELDS
            if names[1] not in allowed:
                raise ScenarioError(
                    source, key, f"unknown key: expected one of {sorted(allowed)}", what="override"
                )
            _table_of(out, names[0], source)[names[1]] = value
        elif len(parts) == 3 and names[0] in ("process", "server", "constraint"):
            _set_entry_field(out, parts, value, source, key)
        else:
            raise ScenarioError(
                source,
                key,
                "unknown key: expected p, tau_cap, model.FIELD, channel.FIELD, process.K.FIELD, server.M.FIELD "
                "or constraint.J.FIELD",
                what="override",
            )
    return out


def _set_entry_field(out: dict, parts: list[tuple[str, bool]], value: Any, source: str, key: str) -> None:
    """``process.K.FIELD``, ``server.M.FIELD`` or ``constraint.J.FIELD`` = value."""
    (kind, _), (selector, quoted), (fld, _) = parts
    allowed = {"process": _PROCESS_FIELDS, "server": _SERVER_FIELDS, "constraint": _CONSTRAINT_FIELDS}[kind]
    if fld not in allowed:
        raise ScenarioError(source, key, f"unknown key: expected one of {sorted(allowed)}", what="override")
    entries = out.get(kind)
    if not isinstance(entries, list) or not entries:
        what = "[[constraint]] tables" if kind == "constraint" else f"[[{kind}]] entries"
        raise ScenarioError(source, key, f"the scenario has no {what}", what="override")
    if kind == "constraint" and (quoted or not _INDEX.fullmatch(selector)):
        raise ScenarioError(source, key, f"expected a 1-based constraint index, found {selector!r}", what="override")
    entry = _find_entry(entries, selector, quoted, kind, source, key)
    if kind == "constraint" and fld in ("max", "min") and isinstance(value, str) and value.lower() == "none":
        entry.pop(fld, None)
        return
    entry[fld] = value
    if kind == "server" and fld in ("slots_per_dimension", "processing_time"):
        # the two ways of giving T are exclusive: an override of one replaces the other
        entry.pop("processing_time" if fld == "slots_per_dimension" else "slots_per_dimension", None)


def _check_depth(obj: Any, source: str, fld: str, start: int = 0) -> None:
    """Refuse lists / tables nested deeper than :data:`MAX_DEPTH` (before anything recurses)."""
    stack = [(obj, start)]
    while stack:
        item, depth = stack.pop()
        if isinstance(item, (list, tuple, dict)):
            if depth >= MAX_DEPTH:
                raise ScenarioError(source, fld, f"expected lists and tables nested at most {MAX_DEPTH} levels deep "
                                                 "(a matrix is a list of rows)")
            stack.extend((v, depth + 1) for v in (item.values() if isinstance(item, dict) else item))


def _show(obj: Any, width: int = 60) -> str:
    """A short repr of user input for a message (never raises: huge integers and deep nests too)."""
    if isinstance(obj, int) and not isinstance(obj, bool) and obj.bit_length() > 200:
        return f"an integer of {int(obj.bit_length() * math.log10(2)) + 1} digits"
    try:
        text = repr(obj)
    except (ValueError, RecursionError):  # an integer too long to print; a deep nest
        return f"a {type(obj).__name__} that cannot be shown"
    return text if len(text) <= width else text[: width - 3] + "..."


# ----------------------------------------------------------------------------- validation
class _V:
    """Field validators bound to a source name, so every message names the file."""

    def __init__(self, source: str):
        self.source = source

    def err(self, fld: str, expected: str) -> ScenarioError:
        return ScenarioError(self.source, fld, expected)

    def table(self, obj: Any, fld: str, allowed: set[str]) -> dict:
        if not isinstance(obj, dict):
            raise self.err(fld, f"expected a table, found {type(obj).__name__}")
        unknown = sorted((k for k in obj if k not in allowed), key=str)
        if unknown:
            raise self.err(f"{fld}.{unknown[0]}", f"unknown field: expected one of {sorted(allowed)}")
        return obj

    def boolean(self, obj: Any, fld: str) -> bool:
        if not isinstance(obj, bool):
            raise self.err(fld, f"expected true or false, found {_show(obj)}")
        return obj

    def integer(self, obj: Any, fld: str, lo: int, hi: int | None = None) -> int:
        if isinstance(obj, bool) or not isinstance(obj, (int, np.integer)):
            if isinstance(obj, float) and math.isfinite(obj) and obj.is_integer():
                obj = int(obj)
            else:
                raise self.err(fld, f"expected an integer >= {lo}, found {_show(obj)}")
        obj = int(obj)
        if obj < lo:
            raise self.err(fld, f"expected an integer >= {lo}, found {_show(obj)}")
        if hi is not None and obj > hi:
            raise self.err(fld, f"expected an integer <= {hi} (a sanity bound), found {_show(obj)}")
        return obj

    def real(self, obj: Any, fld: str) -> float:
        if isinstance(obj, bool) or not isinstance(obj, (int, float, np.integer, np.floating)):
            raise self.err(fld, f"expected a number, found {_show(obj)}")
        try:
            val = float(obj)
        except OverflowError:  # an integer beyond the float range
            raise self.err(fld, f"expected a finite number, found {_show(obj)} (beyond the float range)") from None
        if not math.isfinite(val):
            raise self.err(fld, f"expected a finite number, found {_show(obj)}")
        return val

    def probability(self, obj: Any, fld: str) -> float:
        val = self.real(obj, fld)
        if not 0.0 <= val <= 1.0:
            raise self.err(fld, f"expected a probability in [0, 1], found {val:g}")
        return val

    def string(self, obj: Any, fld: str) -> str:
        if not isinstance(obj, str) or not obj.strip():
            raise self.err(fld, f"expected a non-empty string, found {_show(obj)}")
        return obj

    def matrix(self, obj: Any, fld: str) -> np.ndarray:
        if not isinstance(obj, list) or not obj:
            raise self.err(fld, f"expected a non-empty square matrix (list of rows), found {_show(obj)}")
        rows = []
        for i, row in enumerate(obj):
            if not isinstance(row, list):
                raise self.err(fld, f"row {i + 1}: expected a list of numbers, found {_show(row, 40)}")
            rows.append([self.real(x, f"{fld}[{i + 1}]") for x in row])
        n = len(rows)
        if any(len(r) != n for r in rows):
            shape = f"{n} rows of lengths {[len(r) for r in rows]}"
            raise self.err(fld, f"expected a square matrix, found {_show(shape, 120)}")
        return np.array(rows, dtype=float)


def scenario_from_dict(raw: Mapping[str, Any], source: str = "<dict>") -> Scenario:
    """Validate a raw scenario dictionary (the TOML structure) into a :class:`Scenario`.

    Phases: the structure (tables, nesting depth), ``[model]``, ``[channel]``, the
    ``[[process]]`` tables, the ``[[server]]`` tables, the ``[[constraint]]`` tables; each
    raises one :class:`ScenarioError` naming the source and the field.
    """
    v = _V(source)
    raw = v.table(dict(raw) if isinstance(raw, Mapping) else raw, "<top>", _TOP_FIELDS)
    _check_depth(raw, source, "<top>")
    model, default_cap = _model_table(raw, v)
    p = _channel_table(raw, v)
    processes = _process_tables(raw, v, default_cap)
    servers = _server_tables(raw, v, processes, p)
    if model.kind == "preemption" and len(servers) != 1:
        raise v.err("server", f"a preemption scenario has exactly one server, found {len(servers)}")
    constraints = _constraints(raw.get("constraint", []), processes, servers, v)
    return Scenario(
        model=model,
        p=p if p is not None else float("nan"),
        processes=tuple(processes),
        servers=tuple(servers),
        constraints=constraints,
        source=source,
        raw=copy.deepcopy(dict(raw)),
        validated=True,
    )


def _model_table(raw: dict, v: _V) -> tuple[ModelOptions, int | None]:
    """``[model]``: the options and the default AoI cap (None when not set)."""
    if "model" not in raw:
        raise v.err("model", "missing table [model] (with at least kind = \"wncs\" or \"preemption\")")
    mt = v.table(raw["model"], "model", _MODEL_FIELDS)
    if "kind" not in mt:
        raise v.err("model.kind", f"missing: expected one of {list(KINDS)}")
    kind = mt["kind"]
    if not isinstance(kind, str) or kind not in KINDS:
        raise v.err("model.kind", f"expected one of {list(KINDS)}, found {_show(kind)}")
    model = ModelOptions(
        kind=kind,
        allow_idle=v.boolean(mt.get("allow_idle", False), "model.allow_idle"),
        distinct=v.boolean(mt.get("distinct", True), "model.distinct"),
        preemptive=v.boolean(mt.get("preemptive", True), "model.preemptive"),
    )
    default_cap = v.integer(mt["tau_cap"], "model.tau_cap", 1, MAX_TAU_CAP) if "tau_cap" in mt else None
    return model, default_cap


def _channel_table(raw: dict, v: _V) -> float | None:
    """``[channel]``: the success probability of every link (None when not set)."""
    ct = v.table(raw.get("channel", {}), "channel", _CHANNEL_FIELDS)
    if "success_probability" not in ct:
        return None
    return v.probability(ct["success_probability"], "channel.success_probability")


def _process_tables(raw: dict, v: _V, default_cap: int | None) -> list[ProcessSpec]:
    """The ``[[process]]`` tables, in file order, with unique names."""
    plist = raw.get("process")
    if not isinstance(plist, list) or not plist:
        raise v.err("process", "expected at least one [[process]] table")
    processes = [_process_table(entry, i, v, default_cap) for i, entry in enumerate(plist, start=1)]
    _unique([pr.name for pr in processes], "process", v)
    return processes


def _process_table(entry: Any, i: int, v: _V, default_cap: int | None) -> ProcessSpec:
    f = f"process[{i}]"
    entry = v.table(entry, f, _PROCESS_FIELDS)
    name = v.string(entry.get("name", f"process-{i}"), f"{f}.name")
    if "A" not in entry:
        raise v.err(f"{f}.A", "missing: expected a square matrix")
    A = v.matrix(entry["A"], f"{f}.A")
    R = _noise_covariance(entry.get("R", "identity"), A.shape[0], f"{f}.R", v)
    weight = v.real(entry.get("weight", 1.0), f"{f}.weight")
    if weight <= 0:
        raise v.err(f"{f}.weight", f"expected a number > 0, found {weight:g}")
    if "tau_cap" in entry:
        cap = v.integer(entry["tau_cap"], f"{f}.tau_cap", 1, MAX_TAU_CAP)
    elif default_cap is not None:
        cap = default_cap
    else:
        raise v.err(f"{f}.tau_cap", "missing: set it here or as [model].tau_cap")
    cost = _cost_spec(entry.get("cost", "mse"), cap, f"{f}.cost", v)
    lam = 1.0
    if "arrival_probability" in entry:
        lam = v.real(entry["arrival_probability"], f"{f}.arrival_probability")
        if not 0.0 < lam <= 1.0:
            raise v.err(f"{f}.arrival_probability", f"expected a probability in (0, 1] (1: an update every slot, the "
                                                   f"paper's sampling at will), found {lam:g}")
    return ProcessSpec(name, _frozen_array(A), _frozen_array(R), weight, cap, cost, lam)


def _cost_spec(obj: Any, cap: int, fld: str, v: _V) -> CostSpec:
    """``cost``: ``"mse"``, ``"aoi"``, ``{ power = x }`` (x > 0) or a table of at least ``cap``
    finite, nonnegative, nondecreasing numbers (q(1), q(2), ...)."""
    expected = 'expected "mse", "aoi", { power = x } (x > 0) or a list q(1), q(2), ... of at least tau_cap numbers'
    if isinstance(obj, str):
        if obj not in ("mse", "aoi"):
            raise v.err(fld, f"{expected}, found {_show(obj)}")
        return CostSpec(obj)
    if isinstance(obj, dict):
        v.table(obj, fld, {"power"})
        if "power" not in obj:
            raise v.err(f"{fld}.power", "missing: expected a number > 0 (q(tau) = weight * tau ** power)")
        x = v.real(obj["power"], f"{fld}.power")
        if not x > 0:
            raise v.err(f"{fld}.power", f"expected a number > 0 (a nondecreasing cost), found {x:g}")
        return CostSpec("power", power=x)
    if isinstance(obj, list):
        values = [v.real(x, f"{fld}[{i + 1}]") for i, x in enumerate(obj)]
        if len(values) < cap:
            raise v.err(fld, f"expected at least tau_cap = {cap} values q(1..{cap}), found {len(values)}")
        for i, x in enumerate(values):
            if x < 0:
                raise v.err(f"{fld}[{i + 1}]", f"expected a cost >= 0, found {x:g}")
            if i and x < values[i - 1]:
                raise v.err(f"{fld}[{i + 1}]", f"expected a nondecreasing table (q(tau) >= q(tau - 1)), found "
                                               f"{x:g} after {values[i - 1]:g}")
        return CostSpec("table", table=tuple(values))
    raise v.err(fld, f"{expected}, found {_show(obj)}")


def _noise_covariance(r_raw: Any, n: int, fld: str, v: _V) -> np.ndarray:
    """R: ``"identity"`` or an n x n symmetric positive semi-definite matrix."""
    if isinstance(r_raw, str):
        if r_raw != "identity":
            raise v.err(fld, f"expected \"identity\" or a {n}x{n} matrix, found {_show(r_raw)}")
        return np.eye(n)
    R = v.matrix(r_raw, fld)
    if R.shape != (n, n):
        raise v.err(fld, f"expected a {n}x{n} matrix (A is {n}x{n}), found {R.shape[0]}x{R.shape[1]}")
    scale = max(1.0, float(np.abs(R).max()))
    if not math.isfinite(scale):
        raise v.err(fld, "expected entries whose magnitude fits a float")
    if not np.allclose(R, R.T, rtol=0, atol=1e-12 * scale):
        raise v.err(fld, "expected a symmetric matrix")
    lam = float(np.linalg.eigvalsh(R).min())
    if lam < -1e-10 * scale:
        raise v.err(fld, f"expected positive semi-definite, found eigenvalue {lam:.3g}")
    return R


def _server_tables(raw: dict, v: _V, processes: list[ProcessSpec], p: float | None) -> list[ServerSpec]:
    """The ``[[server]]`` tables, in file order, with unique names."""
    slist = raw.get("server")
    if not isinstance(slist, list) or not slist:
        raise v.err("server", "expected at least one [[server]] table")
    servers = [_server_table(entry, m, v, processes, p) for m, entry in enumerate(slist, start=1)]
    _unique([s.name for s in servers], "server", v)
    return servers


def _server_table(entry: Any, m: int, v: _V, processes: list[ProcessSpec], p: float | None) -> ServerSpec:
    f = f"server[{m}]"
    entry = v.table(entry, f, _SERVER_FIELDS)
    name = v.string(entry.get("name", f"server-{m}"), f"{f}.name")
    for key in ("uplink_delay", "downlink_delay"):
        if key not in entry:
            raise v.err(f"{f}.{key}", "missing: expected an integer >= 0 (whole slots)")
    U = v.integer(entry["uplink_delay"], f"{f}.uplink_delay", 0, 10_000)
    D = v.integer(entry["downlink_delay"], f"{f}.downlink_delay", 0, 10_000)
    T = _processing_times(entry, f, v, processes)
    links = []
    for key in ("p_up", "p_down"):
        if key in entry:
            links.append(_link_probabilities(entry[key], f"{f}.{key}", len(processes), v))
        elif p is None:
            raise v.err(
                "channel.success_probability",
                f"missing: needed by {f} (which sets no own p_up/p_down); expected a probability in [0, 1]",
            )
        else:
            links.append((p,) * len(processes))
    return ServerSpec(name, U, D, T, links[0], links[1])


def _link_probabilities(obj: Any, fld: str, n: int, v: _V) -> tuple[float, ...]:
    """``p_up`` / ``p_down`` of a server: one probability for every process's link, or a list of
    one per process (in process order)."""
    if isinstance(obj, list):
        if len(obj) != n:
            raise v.err(fld, f"expected a probability in [0, 1] or a list of {n} (one per process), found a list "
                             f"of {len(obj)}")
        return tuple(v.probability(x, f"{fld}[{k + 1}]") for k, x in enumerate(obj))
    return (v.probability(obj, fld),) * n


def _processing_times(entry: dict, f: str, v: _V, processes: list[ProcessSpec]) -> tuple[int, ...]:
    """T_{m,k} of every process: ``slots_per_dimension`` x n_k, or ``processing_time`` as given."""
    has_spd, has_pt = "slots_per_dimension" in entry, "processing_time" in entry
    if has_spd == has_pt:
        raise v.err(
            f"{f}.processing_time",
            "expected exactly one of slots_per_dimension (integer >= 1) or processing_time (one integer >= 1 per process)",
        )
    if has_spd:
        spd = v.integer(entry["slots_per_dimension"], f"{f}.slots_per_dimension", 1, 10_000)
        return tuple(spd * pr.dim for pr in processes)
    pt, N = entry["processing_time"], len(processes)
    if not isinstance(pt, list) or len(pt) != N:
        raise v.err(f"{f}.processing_time", f"expected a list of {N} integers >= 1 (one per process), found {_show(pt)}")
    return tuple(v.integer(x, f"{f}.processing_time[{k + 1}]", 1, 100_000) for k, x in enumerate(pt))


def _unique(names: list[str], kind: str, v: _V) -> None:
    seen: set[str] = set()
    for i, name in enumerate(names, start=1):
        if name in seen:
            raise v.err(f"{kind}[{i}].name", f"expected a unique name, '{name}' is used twice")
        seen.add(name)


def _pick(obj: Any, names: list[str], kind: str, fld: str, v: _V) -> int:
    """A 0-based index from a 1-based index or a name."""
    if isinstance(obj, bool):
        raise v.err(fld, f"expected a {kind} name or 1-based index, found {_show(obj)}")
    if isinstance(obj, (int, np.integer)) or (isinstance(obj, float) and math.isfinite(obj) and obj.is_integer()):
        i = int(obj)
        if not 1 <= i <= len(names):
            raise v.err(fld, f"{kind} index {_show(i)} out of range: expected 1..{len(names)} or one of {names}")
        return i - 1
    if isinstance(obj, str):
        if obj in names:
            return names.index(obj)
        raise v.err(fld, f"no {kind} named {_show(obj)}: expected a 1-based index or one of {names}")
    raise v.err(fld, f"expected a {kind} name or 1-based index, found {_show(obj)}")


def _constraints(clist: Any, processes: list, servers: list, v: _V) -> tuple[ConstraintSpec, ...]:
    """Validate the ``[[constraint]]`` tables (see :data:`QUANTITIES`)."""
    if not isinstance(clist, list):
        raise v.err("constraint", f"expected [[constraint]] tables, found {type(clist).__name__}")
    pnames, snames = [p.name for p in processes], [s.name for s in servers]
    out = []
    for j, entry in enumerate(clist, start=1):
        f = f"constraint[{j}]"
        entry = v.table(entry, f, _CONSTRAINT_FIELDS)
        if "quantity" not in entry:
            raise v.err(f"{f}.quantity", f"missing: expected one of {list(QUANTITIES)}")
        qty = entry["quantity"]
        if not isinstance(qty, str) or qty not in QUANTITIES:
            raise v.err(f"{f}.quantity", f"unknown quantity {_show(qty)}: expected one of {list(QUANTITIES)}")
        server = process = None
        if qty == "send_rate":
            if "server" not in entry:
                raise v.err(f"{f}.server", f"missing: send_rate needs a server (one of {snames} or 1..{len(snames)})")
            server = _pick(entry["server"], snames, "server", f"{f}.server", v)
        elif "server" in entry:
            raise v.err(f"{f}.server", f"not used by quantity {qty!r}: only send_rate takes a server")
        if qty in ("process_cost", "aoi"):
            if "process" not in entry:
                raise v.err(f"{f}.process", f"missing: {qty} needs a process (one of {pnames} or 1..{len(pnames)})")
        elif qty == "cost" and "process" in entry:
            raise v.err(f"{f}.process", "not used by quantity 'cost' (use process_cost for one process)")
        if "process" in entry:
            process = _pick(entry["process"], pnames, "process", f"{f}.process", v)
        hi = v.real(entry["max"], f"{f}.max") if "max" in entry else None
        lo = v.real(entry["min"], f"{f}.min") if "min" in entry else None
        if hi is None and lo is None:
            raise v.err(f"{f}.max", "missing: expected a bound max = ... and/or min = ...")
        if hi is not None and lo is not None and lo > hi:
            raise v.err(f"{f}.min", f"expected min <= max, found min = {lo:g} > max = {hi:g}")
        what = qty
        if server is not None:
            what += f"[{snames[server]}" + (f", {pnames[process]}]" if process is not None else "]")
        elif process is not None:
            what += f"[{pnames[process]}]"
        bounds = [f"{lo:g} <= " if lo is not None else "", what, f" <= {hi:g}" if hi is not None else ""]
        out.append(ConstraintSpec(qty, server, process, hi, lo, "".join(bounds)))
    return tuple(out)
