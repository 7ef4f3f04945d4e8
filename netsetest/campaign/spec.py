"""A campaign file (TOML) → the validated list of runs, each a :class:`~netsetest.runtime.runspec.RunSpec` and its key.

    name = "fault sweep"              # optional, a column of every row
    [grid]                            # every combination of the values given (a value or a list of values)
    topology = "paper6"               # a file (relative to the campaign file) or a bundled name
    estimator = ["sdp", "zonotope"]   # every node's (``run --estimator``); "file": the topology's own
    case = ["nsnim", "saim"]
    signals = ["paper", "worst"]
    seeds = "0-49"                    # a seed, a list, or ranges as ``--seeds`` takes them
    fault_scale = [0.5, 0.75, 1.0]    # the fault at that fraction of its declared bound (``run --fault-scale``)
    # log = ["a.mcap", "b.mf4"]       # recorded drives as the world (``run --log``), map = "car.map.toml" (``--map``)
    [[runs]]                          # and/or runs listed one by one (each table may hold lists too: a small grid)
    topology = "paper6_reference"
    seeds = 3
    [compute]
    figures = ["verdict", "widths", "detection", "exact"]   # "exact": width over the exact limit (costs a solve)
    records = false                   # keep each run's record (DIR/records/<key>.json.gz)

Every axis value is checked by the parser ``netsetest run`` uses for its option (runtime/argtypes.py), and
every scenario is loaded, before any run starts: a bad file is one :class:`CampaignError` line.  A run's key
is the digest of what it rests on (:func:`run_key`): the files' values (the scenario's ``settings_digest``,
which covers the overrides; a recorded drive's bytes), the run's settings, the seed and the figures asked for; not the file names.

A new way to vary a run's scenario (as ``log``/``map`` were: ``run --log``/``--map``) is one field of
``rolespec.ScenarioSpec`` (the option every role and ``run`` take, and its ``load``), one of :class:`Axes`
and its line in :func:`_expand`: the key follows from the scenario's settings digest, the row from the spec.
"""

from __future__ import annotations

import argparse
import itertools
import json
import tomllib
from dataclasses import dataclass
from hashlib import sha256
from pathlib import Path
from typing import Literal

import msgspec

from netsetest.config.schema import MAX_CONFIG_BYTES, ConfigError, Scenario
from netsetest.estimator.names import NODE_ESTIMATOR_NAMES
from netsetest.logs.readers import LogError
from netsetest.estimator.objective import DEFAULT_OBJECTIVE, OBJECTIVES
from netsetest.models.signals import SIGNAL_KINDS
from netsetest.runtime import argtypes
from netsetest.runtime.rolespec import ScenarioSpec
from netsetest.runtime.runspec import RunSpec
from netsetest.validation import split_error

Figure = Literal["verdict", "widths", "detection", "exact"]
FIGURES: tuple[Figure, ...] = ("verdict", "widths", "detection", "exact")
DEFAULT_FIGURES: tuple[Figure, ...] = ("verdict", "widths", "detection")
FILE_ESTIMATORS = "file"  # estimator axis value: each node keeps the topology's own (no --estimator)
FaultBounds = Literal["used", "all", "none"]
KEY_VERSION = 1  # bump when a row's figures change meaning: every run's key changes, so every run is re-run
KEY_HEX = 20  # 80 bits of sha256: a run key names one run among millions, never a security property
MAX_RUNS = 1_000_000  # a campaign larger than this is a typo in a range, not a request


class CampaignError(Exception):
    """A bad campaign file or option: one line naming the file, the place and why (exit 2)."""


class _Table(msgspec.Struct, frozen=True, forbid_unknown_fields=True, kw_only=True):
    """A table of the campaign file: unknown keys are errors (a typo must not be silently ignored)."""


class Axes(_Table, frozen=True):
    """One grid: each field a value or a list of values; the runs are every combination."""

    topology: str | list[str]
    estimator: str | list[str] = FILE_ESTIMATORS
    case: str | list[str] | None = None
    signals: str | list[str] = "paper"
    seeds: int | str | list[int] = 0
    steps: int | list[int] | None = None
    manoeuvre: str | list[str] | None = None
    speed: float | list[float] | None = None
    fault_scale: float | list[float] | None = None
    log: str | list[str] | None = None  # a recorded drive as the world (run --log; docs/your-log.md)
    map: str | None = None  # its mapping (run --map)
    variant: str | list[str] = "scheduled"
    objective: str | list[str] = DEFAULT_OBJECTIVE


class Compute(_Table, frozen=True):
    """What each run computes beyond its verdict, and what is kept."""

    figures: list[Figure] = msgspec.field(default_factory=lambda: list(DEFAULT_FIGURES))
    exact_fault_bounds: FaultBounds = "used"  # the exact limit's declared fault bounds (``netsetest exact --fault-bounds``)
    records: bool = False


class CampaignFile(_Table, frozen=True):
    name: str = ""
    grid: Axes | None = None
    runs: list[Axes] = msgspec.field(default_factory=list)
    compute: Compute = msgspec.field(default_factory=Compute)


@dataclass(frozen=True)
class ScenarioInfo:
    """What a row says of the scenario beside the run's figures, from the scenario loaded once per campaign."""

    name: str
    settings_digest: str
    case: str
    steps: int
    node_ids: tuple[int, ...]
    node_estimators: tuple[str, ...]
    fault_declared: tuple[float | None, ...]  # per node: its declared [fault_bound] size
    fault_peak: tuple[float, ...]  # per node: the largest |f_k| of its true fault over the run's steps
    drive_digest: str | None = None  # a recorded drive's: its log's and mapping's bytes (None: the model drives)


@dataclass(frozen=True)
class Planned:
    """One run of the campaign: its key, its spec, the campaign's axis values that made it, and its scenario."""

    key: str
    spec: RunSpec
    estimator: str  # the axis value (FILE_ESTIMATORS: the topology's own)
    info: ScenarioInfo


@dataclass(frozen=True)
class Campaign:
    path: str
    name: str
    runs: tuple[Planned, ...]  # in the file's order, each key once
    figures: tuple[Figure, ...]
    exact_fault_bounds: FaultBounds
    records: bool


def _values(v: object) -> list:
    return list(v) if isinstance(v, list) else [v]


def _checked(where: str, field: str, parse, values: list) -> list:
    """Each value through ``parse`` (the option's parser of ``netsetest run``), CampaignError naming it."""
    out = []
    for v in values:
        try:
            out.append(parse(v))
        except argparse.ArgumentTypeError as exc:
            raise CampaignError(f"{where}.{field} = {v!r}: {exc}") from None
    if not out:
        raise CampaignError(f"{where}.{field}: an empty list (no run)")
    return out


def _choice(choices: tuple[str, ...], what: str):
    def parse(v: str) -> str:
        if v not in choices:
            raise argparse.ArgumentTypeError(f"unknown {what}; choose from {', '.join(choices)}")
        return v

    return parse


def _seeds(v: int | str | list[int]) -> list[int]:
    if isinstance(v, list):
        return [argtypes.seed(str(s)) for s in v]
    return list(argtypes.seed_list(str(v)))


def _file_path(base: Path):
    def parse(v: str) -> str:
        """A file or directory relative to the campaign file, written absolute (the replay command works from anywhere)."""
        path = (base / v).resolve()
        if not path.exists():
            raise argparse.ArgumentTypeError(f"{path}: not found")
        return str(path)

    return parse


def _topology(base: Path):
    def parse(v: str) -> str:
        """A file relative to the campaign file (written absolute: the replay command works from anywhere), or a bundled name."""
        path = base / v
        return str(path.resolve()) if path.is_file() else v

    return parse


def _expand(where: str, axes: Axes, base: Path) -> list[tuple[RunSpec, str]]:
    """Every combination of one grid, as (spec, estimator axis value)."""
    num = lambda parse: lambda v: parse(repr(float(v)))  # noqa: E731  # a TOML number through the option's text parser
    opt = lambda parse: lambda v: None if v is None else parse(v)  # noqa: E731  # an axis left out: the file's
    axes_values = {
        "topology": _checked(where, "topology", _topology(base), _values(axes.topology)),
        "estimator": _checked(where, "estimator", _choice((FILE_ESTIMATORS, *NODE_ESTIMATOR_NAMES), "estimator"), _values(axes.estimator)),
        "case": _checked(where, "case", opt(_choice(("nsnim", "saim"), "case")), _values(axes.case)),
        "signals": _checked(where, "signals", _choice(SIGNAL_KINDS, "signal kind"), _values(axes.signals)),
        "steps": _checked(where, "steps", opt(lambda v: argtypes.positive_int(str(v))), _values(axes.steps)),
        "manoeuvre": _checked(where, "manoeuvre", opt(argtypes.drive), _values(axes.manoeuvre)),
        "speed": _checked(where, "speed", opt(num(argtypes.speed_kmh)), _values(axes.speed)),
        "fault_scale": _checked(where, "fault_scale", opt(num(argtypes.fault_scale)), _values(axes.fault_scale)),
        "log": _checked(where, "log", opt(_file_path(base)), _values(axes.log)),
        "map": _checked(where, "map", opt(_file_path(base)), _values(axes.map)),
        "variant": _checked(where, "variant", _choice(("scheduled", "per-rule"), "variant"), _values(axes.variant)),
        "objective": _checked(where, "objective", _choice(tuple(OBJECTIVES), "objective"), _values(axes.objective)),
    }
    try:
        seeds = _seeds(axes.seeds)
    except argparse.ArgumentTypeError as exc:
        raise CampaignError(f"{where}.seeds = {axes.seeds!r}: {exc}") from None
    names = list(axes_values)
    total = len(seeds)
    for vs in axes_values.values():
        total *= len(vs)
    if total > MAX_RUNS:
        raise CampaignError(f"{where}: {total} runs, more than {MAX_RUNS} (a range too wide?)")
    out = []
    for combo in itertools.product(*axes_values.values()):
        a = dict(zip(names, combo))
        est = a["estimator"]
        scenario = ScenarioSpec(
            a["topology"],
            a["case"],
            a["steps"],
            None if est == FILE_ESTIMATORS else est,
            log=a["log"],
            mapping=a["map"],
            manoeuvre=a["manoeuvre"],
            speed=a["speed"],
            fault_scale=a["fault_scale"],
        )
        out += [(RunSpec(scenario, a["signals"], a["variant"], a["objective"], s), est) for s in seeds]
    return out


def scenario_info(sc: Scenario) -> ScenarioInfo:
    """A loaded scenario's facts that every row of its runs carries."""
    peak = tuple(max((abs(n.fault(k)) for k in range(sc.steps + 1)), default=0.0) for n in sc.nodes)
    return ScenarioInfo(
        name=sc.name,
        settings_digest=sc.settings_digest or "",
        case=sc.case,
        steps=sc.steps,
        node_ids=tuple(sc.ids),
        node_estimators=tuple(n.estimator for n in sc.nodes),
        fault_declared=tuple(n.fault_size for n in sc.nodes),
        fault_peak=peak,
        drive_digest=None if sc.log is None else _drive_digest(Path(sc.log.path), Path(sc.log.mapping.path)),
    )


def _drive_digest(log: Path, mapping: Path) -> str:
    """The bytes a recorded drive's run rests on: its log (a file, or a bag's directory, every file in it) and its mapping."""
    h = sha256()
    for path in [*(sorted(p for p in log.rglob("*") if p.is_file()) if log.is_dir() else [log]), mapping]:
        h.update(path.name.encode() + b"\0")
        with open(path, "rb") as fh:
            for chunk in iter(lambda: fh.read(1 << 20), b""):
                h.update(chunk)
    return h.hexdigest()[:KEY_HEX]


def run_key(spec: RunSpec, info: ScenarioInfo, figures: tuple[Figure, ...], exact_fault_bounds: FaultBounds) -> str:
    """The digest of a run's inputs: what its figures rest on (module doc), never a path or a name."""
    body = {
        "v": KEY_VERSION,
        "settings": info.settings_digest,
        "case": info.case,
        "steps": info.steps,
        "nodes": list(zip(info.node_ids, info.node_estimators)),
        "drive": info.drive_digest,
        "signals": spec.signals,
        "variant": spec.variant,
        "objective": spec.objective,
        "seed": spec.seed,
        "figures": sorted(figures),
        "exact": exact_fault_bounds if "exact" in figures else None,
    }
    return sha256(json.dumps(body, sort_keys=True).encode()).hexdigest()[:KEY_HEX]


def _read(path: Path) -> CampaignFile:
    try:
        if not path.is_file():
            raise CampaignError(f"{path}: not a file")
        if path.stat().st_size > MAX_CONFIG_BYTES:
            raise CampaignError(f"{path}: too large for a campaign file ({path.stat().st_size} bytes)")
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as exc:
        raise CampaignError(f"{path}: cannot read: {exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise CampaignError(f"{path}: not TOML: {exc}") from None
    try:
        return msgspec.convert(data, CampaignFile, strict=True)
    except msgspec.ValidationError as exc:
        what, where = split_error(exc)
        raise CampaignError(f"{path}: {where + ': ' if where else ''}{what}") from None


def load_campaign(path: str | Path) -> Campaign:
    """Read, expand and check a campaign file: every run's scenario loaded once (CampaignError on anything wrong)."""
    p = Path(path)
    f = _read(p)
    if f.grid is None and not f.runs:
        raise CampaignError(f"{p}: no [grid] and no [[runs]]: nothing to run")
    figures = tuple(dict.fromkeys(("verdict", *f.compute.figures)))  # the verdict always; each figure once
    expanded = [
        *(_expand(f"{p}: grid", f.grid, p.parent) if f.grid is not None else []),
        *(x for n, r in enumerate(f.runs) for x in _expand(f"{p}: runs[{n}]", r, p.parent)),
    ]
    infos: dict[ScenarioSpec, ScenarioInfo] = {}
    runs: dict[str, Planned] = {}
    for spec, est in expanded:
        info = infos.get(spec.scenario)
        if info is None:
            try:
                info = infos[spec.scenario] = scenario_info(spec.load())
            except (ConfigError, LogError) as exc:
                raise CampaignError(f"{p}: {' '.join(spec.scenario.to_argv())}: {exc}") from None
        key = run_key(spec, info, figures, f.compute.exact_fault_bounds)
        runs.setdefault(key, Planned(key, spec, est, info))  # the same run named twice is run once
    return Campaign(str(p), f.name or p.stem, tuple(runs.values()), figures, f.compute.exact_fault_bounds, f.compute.records)
