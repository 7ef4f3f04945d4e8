"""The run record: one JSON file (optionally gzip-compressed, by a ``.gz`` suffix) per run, or the same
content as MCAP (``.mcap``, :mod:`netsetest.records.mcap_io`, for Foxglove).

Layout (``format = "netsetest-record"``, ``version = 1``)::

    meta     run settings: topology, case, signals, variant, seed, steps, tau_s, mode, clock,
             node ids, in-neighbour weights {i: {j: a_ij}}, run id
    truth    one entry per step k: x = [β, r], faults {i: f_i}, u, w, vx, noise {i}, gamma {i}, y {i},
             y_nofault {i}, sector_ok {i}, noise_ok {i}, dist_ok, lost [[j, i]], alive [i]
    nodes    {i: [one entry per published step: step, xhat [3], P [9, row-major], rho, status,
             rho_cert, solve_ms, used, missing, late, E = eᵀP⁻¹e, contained (E ≤ rho),
             assumptions_ok (every assumption in the step's dependency cone held)]}
    summary  the per-node table and totals (the same object ``--summary-json`` writes)

:func:`load_record` returns it as numpy arrays; :meth:`Record.fault_rows` gives the fault bounds.
"""

from __future__ import annotations

import gzip
import json
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from netsetest.extras import require

FORMAT = "netsetest-record"
VERSION = 1
MCAP_SUFFIX = ".mcap"  # save_record/load_record dispatch on it (netsetest.records.mcap_io)


class RecordError(Exception):
    """A record file that cannot be read; the message names the file and the reason."""


@dataclass
class NodeTrack:
    """One node's published ellipsoids, aligned by ``steps``."""

    id: int
    steps: np.ndarray  # (K,)
    xhat: np.ndarray  # (K, 3)
    P: np.ndarray  # (K, 3, 3)
    rho: np.ndarray  # (K,)
    E: np.ndarray  # (K,) eᵀP⁻¹e, NaN where the truth of that step is unknown
    contained: np.ndarray  # (K,) bool
    assumptions_ok: np.ndarray  # (K,) bool
    status: list[str]
    solve_ms: np.ndarray  # (K,)

    def bounds(self, index: int) -> tuple[np.ndarray, np.ndarray]:
        """Lower/upper bound of component ``index`` (0 β, 1 r, 2 f): x̂ ∓ √(ρ P_ii)."""
        half = np.sqrt(self.rho * self.P[:, index, index])
        return self.xhat[:, index] - half, self.xhat[:, index] + half


@dataclass
class Record:
    path: str
    meta: dict
    truth: list[dict]
    nodes: dict[int, NodeTrack]
    summary: dict
    raw_nodes: dict[str, list[dict]]

    def truth_at(self, step: int) -> dict | None:
        return self._truth_by_step.get(step)

    def __post_init__(self) -> None:
        self._truth_by_step = {t["step"]: t for t in self.truth}

    def fault_rows(self, node: int) -> list[dict]:
        """Per step: fault estimate and bounds of node ``node``, with the true fault."""
        tr = self.nodes[node]
        lo, hi = tr.bounds(2)
        rows = []
        for n, k in enumerate(tr.steps):
            t = self.truth_at(int(k))
            rows.append(
                {
                    "step": int(k),
                    "fault_estimate": float(tr.xhat[n, 2]),
                    "fault_lower": float(lo[n]),
                    "fault_upper": float(hi[n]),
                    "fault_true": None if t is None or str(node) not in t["faults"] else float(t["faults"][str(node)]),
                    "E": None if np.isnan(tr.E[n]) else float(tr.E[n]),
                    "contained": bool(tr.contained[n]),
                    "status": tr.status[n],
                }
            )
        return rows

    def state_rows(self, node: int) -> list[dict]:
        """Per step: fault rows plus the state estimates, bounds and true values."""
        tr = self.nodes[node]
        rows = self.fault_rows(node)
        for comp, name in ((0, "beta"), (1, "r")):
            lo, hi = tr.bounds(comp)
            for n, row in enumerate(rows):
                t = self.truth_at(row["step"])
                row[f"{name}_estimate"] = float(tr.xhat[n, comp])
                row[f"{name}_lower"] = float(lo[n])
                row[f"{name}_upper"] = float(hi[n])
                row[f"{name}_true"] = None if t is None else float(t["x"][comp])
        return rows


def check_record_path(path: str | Path | None) -> None:
    """Before a run: raise :class:`~netsetest.extras.MissingExtra` if the record's format cannot be written."""
    if path is not None and Path(path).suffix == MCAP_SUFFIX:
        require("mcap", "an MCAP record")


def save_record(path: str | Path, meta: dict, truth: list[dict], nodes: dict[str, list[dict]], summary: dict) -> None:
    if Path(path).suffix == MCAP_SUFFIX:
        require("mcap", "an MCAP record")
        from netsetest.records.mcap_io import save_mcap

        save_mcap(path, meta, truth, nodes, summary)
        return
    doc = {"format": FORMAT, "version": VERSION, "meta": meta, "truth": truth, "nodes": nodes, "summary": summary}
    data = json.dumps(doc, separators=(",", ":"), allow_nan=True).encode()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".part")
    tmp.write_bytes(gzip.compress(data) if path.suffix == ".gz" else data)
    tmp.replace(path)  # never leave a half-written record behind


def _read_json(path: Path) -> object:
    data = path.read_bytes()
    if data[:2] == b"\x1f\x8b":
        data = gzip.decompress(data)
    return json.loads(data)


def _read_mcap(path: Path) -> dict:
    require("mcap", "an MCAP record")
    from netsetest.records.mcap_io import McapReadError, read_mcap

    try:
        return {"format": FORMAT, "version": VERSION, **read_mcap(path)}
    except McapReadError as exc:
        raise RecordError(f"{path}: {exc}") from None


def load_record(path: str | Path) -> Record:
    path = Path(path)
    try:
        doc = _read_mcap(path) if path.suffix == MCAP_SUFFIX else _read_json(path)
    except FileNotFoundError:
        raise RecordError(f"{path}: file not found") from None
    except (OSError, ValueError, EOFError, zlib.error) as exc:
        raise RecordError(f"{path}: not a readable record ({exc})") from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise RecordError(f"{path}: not a netsetest record (format field missing or wrong)")
    if doc.get("version") != VERSION:
        raise RecordError(f"{path}: record version {doc.get('version')!r}, this netsetest reads {VERSION}")
    for name, kind in (("meta", dict), ("truth", list), ("nodes", dict), ("summary", dict)):
        if not isinstance(doc.get(name), kind):
            raise RecordError(f"{path}: malformed record ({name} must be a {kind.__name__})")
    try:
        return record_from_parts(doc["meta"], doc["truth"], doc["nodes"], doc["summary"], str(path))
    except (KeyError, TypeError, ValueError) as exc:
        raise RecordError(f"{path}: malformed record ({type(exc).__name__}: {exc})") from None


def record_from_parts(meta: dict, truth: list[dict], nodes: dict[str, list[dict]], summary: dict, path: str = "") -> Record:
    """A :class:`Record` from the parts a run returns (or a file holds); raises KeyError/TypeError/ValueError
    on malformed entries."""
    tracks = {}
    for key, entries in nodes.items():
        tracks[int(key)] = NodeTrack(
            id=int(key),
            steps=np.array([e["step"] for e in entries], dtype=int),
            xhat=np.array([e["xhat"] for e in entries], dtype=float).reshape(-1, 3),
            P=np.array([e["P"] for e in entries], dtype=float).reshape(-1, 3, 3),
            rho=np.array([e["rho"] for e in entries], dtype=float),
            E=np.array([np.nan if e["E"] is None else e["E"] for e in entries], dtype=float),
            contained=np.array([bool(e["contained"]) for e in entries], dtype=bool),
            assumptions_ok=np.array([bool(e["assumptions_ok"]) for e in entries], dtype=bool),
            status=[e["status"] for e in entries],
            solve_ms=np.array([e["solve_ms"] for e in entries], dtype=float),
        )
    return Record(path, meta, truth, tracks, summary, nodes)
