"""The benchmark's lockstep Zenoh runs go through the launcher ``netsetest run`` uses (defect 2 of issue 18):
the default row is the secured run (router star, forked roles), ``--insecure`` the second row; each role's
CPU and peak RSS come from its rusage, and the stepping phase from the collector's channel."""

from __future__ import annotations

from pathlib import Path

import pytest

from netsetest_bench.zenoh_runs import observed_lockstep
from zenoh_helpers import child_pids

pytestmark = pytest.mark.zenoh
ROOT = Path(__file__).resolve().parents[2]
ROLES = {"collector", "vehicle", "run", *(f"node{i}" for i in range(1, 7))}


@pytest.mark.parametrize("insecure", [False, True], ids=["secured", "insecure"])
@pytest.mark.timeout(180)
def test_the_lockstep_row_is_a_run_of_the_launcher(insecure: bool) -> None:
    before = child_pids()
    r = observed_lockstep(ROOT / "topologies" / "paper6.toml", steps=8, insecure=insecure)
    assert r.security == ("insecure" if insecure else "mtls+acl")
    assert r.summary is not None and r.summary.security == r.security and r.summary.violations_total == 0
    assert set(r.usage) == ROLES and all(code == 0 for code in r.exit_codes.values()), r.exit_codes
    assert all(u.cpu_s and u.cpu_s > 0 for u in r.usage.values())
    assert len(r.node_peak_rss_mb) == 6 and all(10 < x < 500 for x in r.node_peak_rss_mb)
    assert r.stepping_s is not None and r.startup_s is not None and 0 < r.stepping_s < r.total_s and 0 < r.startup_s < r.total_s
    assert child_pids() <= before, "the launcher left a child behind"
