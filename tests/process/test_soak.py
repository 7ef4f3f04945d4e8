"""Bounded memory: a long in-memory run keeps its resident memory flat (the full 20 000-step figure is
in the benchmark, ``netsetest bench``).  Before the vehicle and the collector pruned their per-step maps this grew by
about 20 MB per 1000 steps."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
STEPS = 1200
MAX_SLOPE_MB_PER_10K = 5.0  # the bound


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_rss_stays_flat() -> None:
    out = subprocess.run(
        [sys.executable, "-m", "netsetest_bench.soak", "--steps", str(STEPS)], cwd=ROOT, capture_output=True, text=True, timeout=560, check=True
    ).stdout
    d = json.loads(out)
    assert d["violations"] == 0
    assert d["slope_mb_per_10k_steps"] < MAX_SLOPE_MB_PER_10K, d
    assert d["rss_end_mb"] - d["rss_start_mb"] < MAX_SLOPE_MB_PER_10K * STEPS / 10_000 + 1.0, d
