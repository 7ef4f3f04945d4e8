"""Memory soak: a long in-memory run must keep its resident memory flat (vehicle and collector prune
their per-step maps, the record streams to disk).  ``python -m netsetest_bench.soak --steps N`` prints JSON:
RSS samples and the least-squares slope in MB per 10 000 steps after a warm-up.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

SAMPLE_EVERY = 250  # steps between RSS samples
WARMUP_FRACTION = 0.25  # the first quarter (imports, caches, allocator pools) is not part of the slope


def rss_mb() -> float:
    """Resident set size of this process now (Linux /proc), in MB."""
    pages = int(Path("/proc/self/statm").read_text().split()[1])
    return pages * os.sysconf("SC_PAGE_SIZE") / 2**20


def soak(steps: int, topology: str = "paper6") -> dict:
    from netsetest.config.schema import load_topology
    from netsetest.runtime.inmemory import run_inmemory

    sc = load_topology(topology, None, steps)  # a path or a bundled name
    samples: list[tuple[int, float]] = []

    def on_step(k: int) -> None:
        if k % SAMPLE_EVERY == 0:
            samples.append((k, rss_mb()))

    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:  # the record streams to disk, as with --record
        res = run_inmemory(sc, record=str(Path(tmp) / "soak.jsonl"), keep=False, on_step=on_step)
    wall = time.perf_counter() - t0
    ks = np.array([k for k, _ in samples], dtype=float)
    mb = np.array([m for _, m in samples])
    tail = ks >= WARMUP_FRACTION * steps
    slope = float(np.polyfit(ks[tail], mb[tail], 1)[0] * 10_000) if tail.sum() >= 3 else float("nan")
    return {
        "steps": steps,
        "wall_s": wall,
        "steps_per_s": steps / wall,
        "rss_mb": samples,
        "rss_start_mb": float(mb[tail][0]) if tail.any() else None,
        "rss_end_mb": float(mb[-1]) if len(mb) else None,
        "slope_mb_per_10k_steps": slope,
        "violations": res.summary.violations_total,
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--steps", type=int, default=20_000)
    a = ap.parse_args(argv)
    json.dump(soak(a.steps), sys.stdout)
    sys.stdout.write("\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
