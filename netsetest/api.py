"""A Python API for notebooks: ``netsetest.simulate(...)`` runs a scenario and returns typed arrays.

    import netsetest
    res = netsetest.simulate("paper6", case="saim", steps=40)
    res.nodes[2].upper[:, 2]      # upper fault bound of node 2 per step
    res.violations                # misses on steps where every assumption held (must be 0)
    df = res.to_pandas()          # one row per node and step (pip install 'netsetest[export]')

``mode="inmemory"`` runs every role in this process (deterministic); ``mode="zenoh"`` runs
``netsetest run --mode zenoh`` (one process per role) and reads its record back.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Literal

import numpy as np

from netsetest.config.schema import Case, ConfigError, load_topology
from netsetest.estimator.sdp import Variant
from netsetest.extras import require
from netsetest.models.signals import SignalKind
from netsetest.proven import ProvenSet
from netsetest.records.export import node_table
from netsetest.records.record import Record, load_record, record_from_parts, save_record
from netsetest.records.summary import RunSummary

if TYPE_CHECKING:
    import pandas

Mode = Literal["inmemory", "zenoh"]
COMPONENT_NAMES = ("beta", "r", "fault")  # the columns of centre/lower/upper/truth: β [rad], r [rad/s], f [rad/s]


class SimulationError(RuntimeError):
    """A Zenoh run that ended without a record (the message carries its exit code and error output), or a
    verdict asked of a partial record."""


@dataclass(frozen=True)
class NodeSeries:
    """One node's published sets over the steps it reported (K of them), and their check.

    Columns of ``centre``, ``lower``, ``upper`` and ``truth``: β [rad], r [rad/s], f [rad/s]; the bounds are the
    published set's (``published``: the ellipsoid x̂, P, ρ ∩ its region ∩ its fault range, or a set estimator's
    set; ProvenSet.bounds)."""

    id: int
    steps: np.ndarray  # (K,) int
    t: np.ndarray  # (K,) k·τs [s]
    centre: np.ndarray  # (K, 3) x̂
    lower: np.ndarray  # (K, 3)
    upper: np.ndarray  # (K, 3)
    truth: np.ndarray  # (K, 3) true [β, r, f_i]; NaN where the truth of the step is unknown
    E: np.ndarray  # (K,) eᵀP⁻¹e; NaN where the truth is unknown
    rho: np.ndarray  # (K,) the radius: contained ⇔ E ≤ ρ
    contained: np.ndarray  # (K,) bool
    assumptions_ok: np.ndarray  # (K,) bool: every assumption in the step's dependency cone held
    status: tuple[str, ...]  # per step: init, init-prior, ok, fallback, rejoin, resume or no-reading
    published: tuple[ProvenSet, ...]  # per step: the set the node proved (contains(), bounds())
    continues: tuple[ProvenSet | None, ...]  # per step: the set it continued from (None: the published one)
    # per step, per coordinate β, r, f: the cuts that narrowed the published interval, as the node sent them
    # (docs/estimator.md, "One step"; empty: the solve's ellipsoid or the method's own set alone; None: an older record)
    cuts: tuple[tuple[tuple[str, ...], ...] | None, ...] = ()


@dataclass(frozen=True)
class SimulationResult:
    """Per-node arrays, the run's summary (the ``--summary-json`` object) and the full record."""

    nodes: dict[int, NodeSeries]
    summary: RunSummary | None  # None: a partial record (the run did not finish writing it)
    record: Record  # for plots (netsetest.records.plots), MCAP (netsetest.records.mcap_io), inspect

    @property
    def violations(self) -> int:
        """Misses on steps where every assumption held: the estimator's failures (must be 0)."""
        if self.summary is None:
            raise SimulationError(f"{self.record.path}: a partial record has no verdict")
        return self.summary.violations_total

    @property
    def covered_steps(self) -> dict[int, int]:
        """Per node: how many of its published steps were judged with every assumption held (the summary's
        ``steps_covered``: the truth known, one copy, the dependency cone intact)."""
        return {i: int((s.assumptions_ok & np.isfinite(s.E)).sum()) for i, s in self.nodes.items()}

    def save(self, path: str | Path) -> None:
        """Write the record (JSON, ``.gz`` compressed, or ``.mcap``)."""
        rec = self.record
        save_record(path, rec.meta, rec.truth, rec.raw_nodes, rec.summary)

    def to_pandas(self) -> pandas.DataFrame:
        """One row per node and published step: node, step, t, estimate/lower/upper/true of β, r, f, E,
        ρ, contained, assumptions_ok, status (the columns of ``netsetest export``)."""
        require("pandas", "SimulationResult.to_pandas()")
        import pandas as pd

        frames = [pd.DataFrame({"node": i, **node_table(self.record, i)}) for i in sorted(self.nodes)]
        return pd.concat(frames, ignore_index=True)


def simulate(
    topology: str | Path,
    case: Case | None = None,
    signals: SignalKind = "paper",
    seed: int = 0,
    variant: Variant = "scheduled",
    steps: int | None = None,
    mode: Mode = "inmemory",
    estimator: str | None = None,
) -> SimulationResult:
    """Run ``topology`` (a file, or a bundled name such as ``"paper6"``); ``case`` and ``steps`` override
    the file, ``estimator`` every node's (default: each node's in the file, else ``"sdp"``).  Raises :class:`~netsetest.config.schema.ConfigError` on a bad file or argument."""
    if mode == "inmemory":
        from netsetest.runtime.rolespec import ScenarioSpec
        from netsetest.runtime.runspec import RunSpec

        res = RunSpec(ScenarioSpec(str(topology), case, steps, estimator), signals, variant, seed=seed).execute()
        assert res.parts is not None  # kept in memory (run_inmemory's default)
        return result_of(record_from_parts(res.meta, res.parts["truth"], res.parts["nodes"], res.summary))
    if mode == "zenoh":
        return result_of(_run_zenoh(topology, case, signals, seed, variant, steps, estimator))
    raise ConfigError(f"mode must be 'inmemory' or 'zenoh', got {mode!r}")


def _run_zenoh(topology: str | Path, case: Case | None, signals: str, seed: int, variant: str, steps: int | None, estimator: str | None) -> Record:
    load_topology(topology, case, steps, estimator)  # bad input fails here, with the loader's message
    with tempfile.TemporaryDirectory(prefix="netsetest-") as tmp:
        rec = Path(tmp) / "run.json"
        argv = [
            sys.executable,
            "-m",
            "netsetest.cli.main",
            "run",
            str(topology),
            "--mode",
            "zenoh",
            "--quiet",
            "--signals",
            signals,
            "--seed",
            str(seed),
            "--variant",
            variant,
            "--record",
            str(rec),
        ]
        argv += ["--case", case] if case else []
        argv += ["--steps", str(steps)] if steps else []
        argv += ["--estimator", estimator] if estimator else []
        proc = subprocess.run(argv, capture_output=True, text=True)
        if not rec.exists():
            raise SimulationError(f"netsetest run --mode zenoh exited {proc.returncode} without a record: {proc.stderr.strip()[-2000:]}")
        return load_record(rec)


def result_of(rec: Record) -> SimulationResult:
    """The typed view of a record (from a run, or :func:`~netsetest.records.record.load_record`)."""
    nodes = {}
    for i, tr in rec.nodes.items():
        bounds = [tr.bounds(j) for j in range(3)]
        truth = np.full((len(tr.steps), 3), np.nan)
        for n, k in enumerate(tr.steps):
            t = rec.truth_at(int(k))
            if t is not None and i in t["faults"]:
                truth[n] = [t["x"][0], t["x"][1], t["faults"][i]]
        nodes[i] = NodeSeries(
            id=i,
            steps=tr.steps,
            t=tr.steps * rec.meta.tau_s,
            centre=tr.xhat,
            lower=np.column_stack([lo for lo, _ in bounds]),
            upper=np.column_stack([hi for _, hi in bounds]),
            truth=truth,
            E=tr.E,
            rho=tr.rho,
            contained=tr.contained,
            assumptions_ok=tr.assumptions_ok,
            status=tuple(tr.status),
            published=tuple(tr.published),
            continues=tuple(tr.continues),
            cuts=tuple(tr.cuts) if tr.cuts is not None else (None,) * len(tr.steps),
        )
    return SimulationResult(nodes, rec.summary, rec)
