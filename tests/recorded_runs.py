"""Whole runs held to a committed record of their figures (tests/fixtures/recorded_runs.json) within stated
tolerances, where they were once held to digests, bit for bit.  Bit for bit depended on the CPU: OpenBLAS picks its
kernels by CPU (``OPENBLAS_CORETYPE``), one rounds a 2-vector product with a fused multiply-add (SkylakeX, on a CPU
with AVX-512; Haswell on AVX2) and another without (Sandybridge), so the data of every Clarabel solve differ in the
last bits; the solver stops within its tolerances (10⁻⁸), an iteration sooner or later, and a later step starts
from what it published.

What is recorded, per run (:data:`RUNS`: paper6, paper6_reference and paper6_max_faulty; NSNIM and SAIM; paper
and worst-case signals; the scheduled and the per-rule variant; seed 3, 30 steps) and node: the mean width of the
published set (ellipsoid ∩ region ∩ fault range, the bounds users read) per coordinate β, r, f over every step,
and each step's labels (status, sector basis, fault detection).  And the truth x_k of the T-S plant's paper6 runs
(tests/inmemory/test_plant.py).  Measured between the Haswell, SkylakeX and Sandybridge kernels (on 2026-12-07,
issue 40): the mean widths within 1.0·10⁻⁶ relative, every label the same, the truth within 5·10⁻¹⁶ (no solver
in its loop: stable dynamics keep a rounding a rounding).  So :data:`WIDTH_RTOL` is a hundred times the kernels'
largest difference and a hundred times below a 1 % change, and :data:`TRUTH_RTOL` far above a few ulps and far
below any change of the model or the signals.

Not recorded: the published ellipsoid alone (x̂, P, ρ), whose width differs between kernels by up to 1.4 % on single
steps (paper6_max_faulty SAIM, worst-case signals, per-rule: where the SDP's objective is nearly flat the solver's
stopping point moves; the published set, cut by the region and the fault range, does not), and the solver's
iteration counts (±3 on a step).

Re-record after a change by design, saying in tests/inmemory/test_recorded_runs.py's docstring what moved and why:
``python tests/recorded_runs.py`` in the checkout's root (its venv active), then ``git diff tests/fixtures``.
"""

from __future__ import annotations

import json
import math
import re
from itertools import groupby
from pathlib import Path
from typing import Any

import numpy as np

from netsetest.config.schema import Case, Variant, load_topology
from netsetest.models.drive import Drive, DriveStep
from netsetest.models.signals import SignalKind
from netsetest.runtime.inmemory import RunResult, run_inmemory

ROOT = Path(__file__).resolve().parents[1]
RECORD = ROOT / "tests" / "fixtures" / "recorded_runs.json"
STEPS = 30
SEED = 3
TOPOLOGIES = ("paper6", "paper6_reference", "paper6_max_faulty")
CASES: tuple[Case, ...] = ("nsnim", "saim")
SIGNALS: tuple[SignalKind, ...] = ("paper", "worst")
VARIANTS: tuple[Variant, ...] = ("scheduled", "per-rule")
RUNS = [(t, c, s, v) for t in TOPOLOGIES for c in CASES for s in SIGNALS for v in VARIANTS]
LABELS = ("status", "sector_basis", "fdi")
WIDTH_RTOL = 1e-4  # the mean widths (see above: kernels 10⁻⁶ apart)
WIDTH_ATOL = 1e-12  # a reference's fault, published [0, 0]: width 0
TRUTH_RTOL = 1e-12  # relative to the largest |x| of the track (kernels: 5·10⁻¹⁶ at 0.27)


def key(topology: str, case: str, signals: str, variant: str) -> str:
    return f"{topology} {case} {signals} {variant}"


def run(topology: str, case: Case, signals: SignalKind, variant: Variant) -> RunResult:
    return run_inmemory(load_topology(ROOT / "topologies" / f"{topology}.toml", case, STEPS), signals, variant, SEED)


def _runs_of(labels: list[str]) -> str:
    """A label sequence, run-length coded: ``ok*29,fallback*1``."""
    return ",".join(f"{v}*{len(list(g))}" for v, g in groupby(labels))


def figures(res: RunResult) -> dict[str, dict[str, Any]]:
    """Per node (id as a string): ``width`` (the published set's mean width per coordinate β, r, f over every
    step) and each of :data:`LABELS` step by step (run-length coded)."""
    out: dict[str, dict[str, Any]] = {}
    for i in sorted(res.parts["nodes"], key=int):
        entries = sorted(res.parts["nodes"][i], key=lambda e: e["step"])
        bounds = np.array([e["bounds"] for e in entries], dtype=float)  # (K, 3, 2)
        node: dict[str, Any] = {"width": [float(w) for w in (bounds[:, :, 1] - bounds[:, :, 0]).mean(axis=0)]}
        for label in LABELS:
            node[label] = _runs_of([str(e[label]) for e in entries])
        out[str(i)] = node
    return out


def drive(case: Case, signals: SignalKind) -> list[DriveStep]:
    """Steps 0 … STEPS of paper6's truth (the T-S plant) for seed SEED."""
    truth = Drive(load_topology(ROOT / "topologies" / "paper6.toml", case, STEPS), signals, SEED)
    return [truth.step(k) for k in range(STEPS + 1)]


def load() -> dict[str, Any]:
    return json.loads(RECORD.read_text())


def differences(name: str, got: dict[str, dict[str, Any]], want: dict[str, dict[str, Any]]) -> list[str]:
    """What of run ``name``'s figures ``got`` is not the record's ``want`` within the tolerances, one line each."""
    if sorted(got) != sorted(want):
        return [f"{name}: nodes {sorted(got)}, recorded {sorted(want)}"]
    out = []
    for i in sorted(got, key=int):
        g, w = got[i], want[i]
        for axis, a, b in zip(("beta", "r", "f"), g["width"], w["width"]):
            if not math.isclose(a, b, rel_tol=WIDTH_RTOL, abs_tol=WIDTH_ATOL):
                out.append(f"{name}: node {i} mean {axis} width {a:.9g}, recorded {b:.9g} ({(a - b) / b if b else math.inf:+.2e} relative)")
        out += [f"{name}: node {i} {label} {g[label]}, recorded {w[label]}" for label in LABELS if g[label] != w[label]]
    return out


def truth_differences(name: str, got: list[list[float]], want: list[list[float]]) -> list[str]:
    scale = max(abs(v) for x in want for v in x)
    if len(got) != len(want):
        return [f"{name}: {len(got)} truth steps, recorded {len(want)}"]
    return [f"{name}: x_{k} {a}, recorded {b}" for k, (a, b) in enumerate(zip(got, want)) if np.abs(np.subtract(a, b)).max() > TRUTH_RTOL * scale]


def write() -> None:
    """Run every recorded run and rewrite :data:`RECORD`."""
    record: dict[str, Any] = {
        "about": "tests/recorded_runs.py: what is recorded, its tolerances and how to re-record",
        "runs": {},
        "truth": {},
    }
    for t, c, s, v in RUNS:
        record["runs"][key(t, c, s, v)] = figures(run(t, c, s, v))
        print(key(t, c, s, v), flush=True)
    for c in CASES:
        for s in SIGNALS:
            record["truth"][f"paper6 {c} {s}"] = [step.x.tolist() for step in drive(c, s)]
    text = json.dumps(record, indent=1)
    RECORD.write_text(re.sub(r"\[\s+([^\[\]]+?)\s+\]", lambda m: "[" + " ".join(m.group(1).split()) + "]", text) + "\n")  # numbers on one line


if __name__ == "__main__":
    write()
