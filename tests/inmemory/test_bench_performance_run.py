"""``netsetest bench --only performance`` end to end at a tiny size (netsetest_bench/run.py): the paper scenario's
side-by-side solves, the in-memory scaling and the lockstep CPU floor measured for real; the process-heavy
measurements (Zenoh runs, the real-time ladder, floods, the soak, the exact limit) faked with the committed figures.
Every measurement is built as its typed figures, the file written holds every key the committed one does, and the
report is what its renderers make of that file."""

from __future__ import annotations

import importlib
import json
from dataclasses import replace
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def test_the_performance_run_builds_typed_figures_and_reports_what_its_file_holds(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    run = importlib.import_module("netsetest_bench.run")  # (sys.modules' copies: test_bench_extras imports the benchmark again)
    zenoh_runs = importlib.import_module("netsetest_bench.zenoh_runs")
    attacks, soak = importlib.import_module("netsetest_bench.attacks"), importlib.import_module("netsetest_bench.soak")
    performance = importlib.import_module("netsetest_bench.figures.performance")
    committed = json.loads((ROOT / "bench" / "results.json").read_text())

    def lockstep(topology: object, steps: int | None = None, insecure: bool = False, **_: object) -> object:
        n = steps or 80  # a role's CPU grows with the steps: the floor is the difference of a long and a short run
        usage = {name: zenoh_runs.RoleUsage(0, 46.0, 0.5 + 0.002 * n) for name in ("collector", "vehicle", "run", *(f"node{i}" for i in range(1, 7)))}
        return zenoh_runs.Lockstep("insecure" if insecure else "mtls+acl", 6, n, 0.01 * n, 0.01 * n + 1.0, 0.6, usage, None)

    defences = committed["defences"]
    fakes = {
        (zenoh_runs, "observed_lockstep"): lockstep,
        (zenoh_runs, "cli_run"): lambda *a, **k: {"wall_s": 2.0, "exit_code": 0, "summary": None},
        (zenoh_runs, "launch_to_step0"): lambda *a, **k: committed["launch"],
        (zenoh_runs, "node_startup"): lambda *a, **k: {k: v for k, v in committed["node"].items() if k != "memory_by_stage"},
        (zenoh_runs, "node_memory_profile"): lambda: committed["node"]["memory_by_stage"],
        (zenoh_runs, "realtime_ladder"): lambda *a, **k: {k: v for k, v in committed["realtime"].items() if k != "variants"},
        (zenoh_runs, "realtime_fit"): lambda *a, **k: committed["realtime"]["variants"],
        (zenoh_runs, "realtime_node_profile"): lambda *a, objective=None: committed["node_profile_trace" if objective else "node_profile"],
        (attacks, "flood"): lambda topology, steps, rate, target, secured, **k: defences[f"flood_{target}_{'secured' if secured else 'insecure'}"],
        (attacks, "crash"): lambda topology, steps, secured, **k: defences[f"crash_{'secured' if secured else 'insecure'}"],
        (soak, "soak"): lambda steps: defences["soak"],
        (run, "tightness"): lambda tmp: {c: performance.load(committed).tightness[c] for c in ("nsnim", "saim")},  # the exact limit: minutes
    }
    for (module, name), fake in fakes.items():
        monkeypatch.setattr(module, name, fake)
    tiny = replace(run.QUICK, steps=3, ref_sched=2, ref_rule=1, naive=2, prev_sched=0, prev_rule=0, scaling_sizes=[6], scaling_steps=3, cpu_steps=100)
    monkeypatch.setattr(run, "QUICK", tiny)

    assert run.run_bench(True, str(tmp_path / "results.json"), str(tmp_path / "results.md"), "performance") == 0
    capsys.readouterr()
    written = json.loads((tmp_path / "results.json").read_text())
    p = performance.load(written)
    only_with_baseline = {"baseline"}  # the committed run's side by side with 16f81b4 (docs.py's command)
    assert set(committed) - set(written) <= {"plant", "network", "scenario", "exact", "widths"} | only_with_baseline  # every key of the part
    assert p.paper["nsnim/scheduled"].run_summary is not None and p.paper["saim/scheduled"].straightforward is not None
    assert p.zenoh.cpu_floor is not None and p.zenoh.cpu_floor.cores == zenoh_runs.MACHINE_CORES
    assert [r.nodes for r in p.inmemory_scaling.rows] == [6] and p.defences.flood("state", "insecure").ratio is not None
    assert p.realtime.variants and p.node_profile_trace.objective == "trace" and p.meta.config.flood_rate == tiny.flood_rate
    assert (tmp_path / "results.md").read_text() == run.markdown(written)  # the report: what the renderers make of the file
