"""Bad command-line values and hostile files: exit 2 with one clear line, before anything runs; no hang,
no traceback.  ``inspect … | head`` exits quietly."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from netsetest.cli.main import main

ROOT = Path(__file__).resolve().parents[2]
TOPOLOGY = str(ROOT / "topologies" / "paper6.toml")


def _copy(tmp_path: Path) -> Path:
    shutil.copytree(ROOT / "nodes", tmp_path / "nodes")
    (tmp_path / "topologies").mkdir()
    shutil.copy(TOPOLOGY, tmp_path / "topologies" / "paper6.toml")
    return tmp_path / "topologies" / "paper6.toml"


def _one_clear_line(err: str, *must: str) -> None:
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert "Traceback" not in err, err
    assert len(lines) == 1, err
    for m in must:
        assert m in lines[0], (m, err)


def _run(*args: str) -> list[str]:
    return ["run", TOPOLOGY, "--mode", "inmemory", "--steps", "2", "--quiet", *args]


@pytest.mark.parametrize("mode", ["inmemory", "zenoh"])
def test_negative_seed(mode: str, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["run", TOPOLOGY, "--mode", mode, "--steps", "2", "--seed", "-1"])
    assert exc.value.code == 2
    _one_clear_line(capsys.readouterr().err.splitlines()[-1], "--seed", "-1")


@pytest.mark.parametrize("option", ["--record", "--summary-json"])
@pytest.mark.parametrize("mode", ["inmemory", "zenoh"])
def test_output_is_a_directory_or_unwritable(option: str, mode: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Checked before the run starts (the run would otherwise be lost at its end)."""
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    try:
        cases = {"directory": str(tmp_path), "unwritable": str(locked / "out.json"), "parent-is-file": str(Path(TOPOLOGY) / "x.json")}
        if os.geteuid() == 0:  # root writes anywhere: the permission case cannot fail
            cases.pop("unwritable")
        for what, path in cases.items():
            t0 = time.monotonic()
            code = main(["run", TOPOLOGY, "--mode", mode, "--steps", "2000", "--quiet", option, path])
            assert code == 2, what
            assert time.monotonic() - t0 < 5, f"{what}: found only after the run"
            _one_clear_line(capsys.readouterr().err, option, path)
    finally:
        locked.chmod(0o700)


def test_plot_out_is_a_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rec = tmp_path / "r.jsonl"
    assert main([*_run("--record", str(rec))]) == 0
    capsys.readouterr()
    a_file = tmp_path / "file"
    a_file.write_text("x")
    assert main(["plot", str(rec), "--out", str(a_file)]) == 2
    _one_clear_line(capsys.readouterr().err, "--out", "not a directory")
    assert main(["plot", str(rec), "--out", str(a_file / "sub")]) == 2
    _one_clear_line(capsys.readouterr().err, "--out")


def test_deeply_nested_toml(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    topo = _copy(tmp_path)
    topo.write_text(topo.read_text() + "\ndeep = " + "[" * 100_000 + "]" * 100_000 + "\n")
    assert main(["run", str(topo), "--mode", "inmemory", "--steps", "1", "--quiet"]) == 2
    _one_clear_line(capsys.readouterr().err, "paper6.toml", "nested too deeply")


def test_symlink_loop_in_node_dir(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    topo = _copy(tmp_path)
    (tmp_path / "loop_a").symlink_to(tmp_path / "loop_b")
    (tmp_path / "loop_b").symlink_to(tmp_path / "loop_a")
    topo.write_text(topo.read_text().replace('node_dir = "../nodes"', 'node_dir = "../loop_a"'))
    assert main(["run", str(topo), "--mode", "inmemory", "--steps", "1", "--quiet"]) == 2
    err = capsys.readouterr().err
    _one_clear_line(err, "paper6.toml")
    assert "loop" in err.lower() or "symbolic" in err.lower(), err


def test_nul_byte_in_profile_name(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    topo = _copy(tmp_path)
    topo.write_text(topo.read_text().replace('profile = "yaw3"', 'profile = "yaw\\u00003"'))
    assert main(["run", str(topo), "--mode", "inmemory", "--steps", "1", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and "profile" in err and "paper6.toml" in err, err


def test_fifo_in_node_dir_does_not_hang(tmp_path: Path) -> None:
    topo = _copy(tmp_path)
    (tmp_path / "nodes" / "yaw3.toml").unlink()
    os.mkfifo(tmp_path / "nodes" / "yaw3.toml")
    r = subprocess.run([sys.executable, "-m", "netsetest.cli.main", *_run()[:1], str(topo), *_run()[2:]], capture_output=True, text=True, timeout=60)
    assert r.returncode == 2
    _one_clear_line(r.stderr, "yaw3.toml", "FIFO")


def test_inspect_into_a_closed_pipe_exits_quietly(tmp_path: Path) -> None:
    rec = tmp_path / "r.jsonl"
    assert main(["run", TOPOLOGY, "--mode", "inmemory", "--steps", "60", "--quiet", "--record", str(rec)]) == 0
    # --json: ~0.5 MB, far more than a pipe buffer, so the writer meets the closed pipe
    cmd = f"{sys.executable} -m netsetest.cli.main inspect --json {rec} | head -n 2"
    r = subprocess.run(["bash", "-o", "pipefail", "-c", cmd], capture_output=True, text=True, timeout=60, cwd=ROOT)
    assert r.returncode == 0, r.stderr
    assert r.stderr == "" and len(r.stdout.splitlines()) == 2


def test_kill_in_memory_is_refused(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(_run("--kill", "3@1")) == 2
    _one_clear_line(capsys.readouterr().err, "--kill", "--mode zenoh")


# ---------------------------------------------------------------- bad options: exit 2, one line, no traceback


@pytest.mark.parametrize(
    "argv,says",
    [
        (["echo", "--run-id", "a/**", "--duration", "1"], "--run-id: 'a/**': only letters"),
        (["watch", "--run-id", "a*", "--duration", "1"], "--run-id: 'a*': only letters"),
        (["echo", "--connect", "tcp/1.2.3.4:99999", "--duration", "1"], "port ≤ 65535"),
        (["credentials", "/proc/netsetest-x", "paper6"], "/proc/netsetest-x: cannot write the credentials there"),
        (["run", "paper6", "--mode", "inmemory", "--record", "/proc/netsetest-x.json"], "--record /proc/netsetest-x.json: cannot be written"),
        (["run", "paper6", "--mode", "inmemory", "--summary-json", "/proc/netsetest-x.json"], "--summary-json /proc/netsetest-x.json: cannot be written"),
    ],
)
def test_bad_outputs_and_observer_options_exit_2_before_anything(argv: list[str], says: str) -> None:
    """These printed tracebacks, exited 0 silently, or (--record under /proc) let the run start and the
    collector crash after it."""
    import subprocess
    import sys as _sys

    p = subprocess.run([_sys.executable, "-m", "netsetest", *argv], capture_output=True, text=True, timeout=60)
    assert p.returncode == 2, (p.returncode, p.stdout, p.stderr)
    assert says in p.stderr and "Traceback" not in p.stderr, p.stderr
    assert not Path("/proc/netsetest-x").exists()


# ---------------------------------------------------------------- the truth is not computable from `ps`


def test_each_run_draws_its_own_seed_and_prints_it(tmp_path: Path) -> None:
    """The default seed was 0 for every run, so anyone could recompute the truth the access control hides
    from the nodes; now each run draws one, prints and records it, and --seed replays it."""
    import json

    def run(*extra: str) -> tuple[int, str, dict]:
        summ = tmp_path / f"s{len(list(tmp_path.iterdir()))}.json"
        p = subprocess.run(
            [sys.executable, "-m", "netsetest", "run", TOPOLOGY, "--mode", "inmemory", "--steps", "3", "--summary-json", str(summ), *extra],
            capture_output=True,
            text=True,
            timeout=120,
        )
        assert p.returncode == 0, p.stderr
        return json.loads(summ.read_text())["seed"], p.stdout, json.loads(summ.read_text())

    (a, out_a, _), (b, _, _) = run(), run()
    assert a != b and f"seed {a}," in out_a.splitlines()[-1]
    rec1, rec2 = tmp_path / "r1.json", tmp_path / "r2.json"
    run("--seed", str(a), "--record", str(rec1))
    run("--seed", str(a), "--record", str(rec2))
    t1 = [json.loads(x) for x in rec1.read_text().splitlines() if '"truth"' in x]
    t2 = [json.loads(x) for x in rec2.read_text().splitlines() if '"truth"' in x]
    assert t1 == t2 and t1


@pytest.mark.zenoh
def test_no_process_of_a_run_shows_its_seed_or_a_guessable_run_id(tmp_path: Path) -> None:
    import json

    summ = tmp_path / "summary.json"
    parent = subprocess.Popen(
        [sys.executable, "-m", "netsetest", "run", TOPOLOGY, "--steps", "20", "--pace", "0.1", "--quiet", "--summary-json", str(summ)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    seen: set[str] = set()
    try:
        deadline = time.monotonic() + 120
        while parent.poll() is None and time.monotonic() < deadline:
            for d in Path("/proc").iterdir():
                if d.name.isdigit():
                    try:
                        seen.add((d / "cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace"))
                    except OSError:
                        pass
            time.sleep(0.2)
        out, err = parent.communicate(timeout=30)
    finally:
        if parent.poll() is None:
            parent.kill()
    assert parent.returncode == 0, err
    assert err == "", err  # --quiet: no line on stderr on success (it printed the security and ready lines)
    seed = json.loads(summ.read_text())["seed"]
    roles = [c for c in seen if "netsetest" in c]
    assert roles and not any(f" {seed} " in f" {c} " for c in roles), roles
    assert not any(f"run{parent.pid}" in c for c in roles), "the run id must not be derivable from the parent's pid"


def test_the_first_word_and_the_exit_code_agree() -> None:
    """Issue 29: ``run paper6 --kill 3@20`` printed PASS (partial coverage) and exited 3; a collector that
    gave up on the vehicle printed PASS (partial coverage) and exited 1.  One decision gives both."""
    from dataclasses import replace

    from netsetest.records.summary import NodeSummary, RunSummary
    from netsetest.runtime.report import EXIT_INTERRUPTED, EXIT_NODE_LOST, EXIT_OK, EXIT_VIOLATION, exit_code, format_table, outcome

    nodes = [NodeSummary(id=1), NodeSummary(id=2, missing_from=21)]
    full = RunSummary(steps_completed=3, node_steps_evaluated=8, node_steps_covered=8, node_steps_contained=8, nodes=nodes, mode="zenoh")
    cases = {
        "NODE LOST": (replace(full, nodes_missing=[2]), EXIT_NODE_LOST),
        "FAIL (vehicle gone)": (replace(full, stopped="vehicle gone"), EXIT_VIOLATION),
        "INTERRUPTED": (replace(full, stopped="interrupted"), EXIT_INTERRUPTED),
        "FAIL": (replace(full, violations_total=1, nodes_missing=[2], stopped="vehicle gone"), EXIT_VIOLATION),
        "PASS (partial coverage)": (replace(full, steps_overloaded=2, node_steps_evaluated=6, node_steps_covered=6), EXIT_OK),
        "PASS": (full, EXIT_OK),
    }
    for word, (summary, code) in cases.items():
        assert outcome(summary) == (word, code) and exit_code(summary) == code
        assert format_table(summary).splitlines()[-1].startswith(f"{word}: zenoh run")
    lost = format_table(cases["NODE LOST"][0]).splitlines()[-1]
    assert "lost for good: node 2 from step 21" in lost
    behind = replace(cases["PASS (partial coverage)"][0], collector_budget=70, node_steps_overloaded=12)
    past_budget = format_table(replace(behind, collector_peak=77)).splitlines()[-1]
    assert "collector overloaded on 2 step(s) (past its budget of 70 open node-steps): 12 node-step(s) not judged (collector overloaded)" in past_budget
    assert "collector overloaded on 2 step(s) (its inbox full)" in format_table(replace(behind, collector_peak=40)).splitlines()[-1]


def test_verdict_line_starts_with_the_outcome_and_names_the_step_range() -> None:
    """It had no pass/fail word and said "80 steps" next to 486 node-steps (6 × 81)."""
    from dataclasses import replace

    from netsetest.records.summary import NodeSummary, RunSummary
    from netsetest.runtime.report import LEGEND_WIDTH, format_table, outcome

    nodes = [NodeSummary(id=i) for i in (1, 2)]
    full = RunSummary(steps_completed=3, node_steps_evaluated=8, node_steps_covered=8, node_steps_contained=8, nodes=nodes)
    assert outcome(full) == ("PASS", 0)
    assert outcome(replace(full, node_steps_covered=7, node_steps_not_covered={"noise": 1})) == ("PASS (partial coverage)", 0)
    assert outcome(replace(full, node_steps_evaluated=7, node_steps_covered=7)) == ("PASS (partial coverage)", 0)
    assert outcome(replace(full, violations_total=1)) == ("FAIL", 1)
    text = format_table(replace(full, mode="inmemory", case="nsnim", signals="paper", variant="scheduled", seed=4))
    last = text.splitlines()[-1]
    assert last.startswith("PASS: inmemory run") and "steps 0–3:" in last
    assert "viol.: misses where every assumption held" in text
    assert all(len(ln) <= LEGEND_WIDTH for ln in text.splitlines()[:-1])
    mixed = format_table(replace(full, nodes=[NodeSummary(id=1, estimator="sdp"), NodeSummary(id=2, estimator="zonotope")]))
    assert "estimator" in mixed.splitlines()[0] and "zonotope" in mixed


@pytest.mark.parametrize(
    "option",
    [["--pace", "0.1"], ["--insecure"], ["--node-timeout", "3"], ["--neighbour-timeout", "1"], ["--run-id", "x1"], ["--rejoin", "2@3"]],
)
def test_zenoh_only_options_are_refused_in_memory(option: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    """They were accepted and silently ignored with --mode inmemory (only --kill was refused)."""
    assert main(["run", TOPOLOGY, "--mode", "inmemory", "--steps", "1", *option]) == 2
    err = capsys.readouterr().err
    assert f"{option[0]}: only a Zenoh run has it" in err and "Traceback" not in err


@pytest.mark.parametrize(
    "name,says",
    [("out.csv", "the name must end in .json, .jsonl"), ("r.mcap.gz", "the name must end in"), ("nonexistent-dir/r.json", "does not exist")],
)
def test_record_names_are_not_taken_literally(name: str, says: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """out.csv got JSON Lines, r.mcap.gz gzipped JSON, a missing directory was created silently."""
    assert main(["run", TOPOLOGY, "--mode", "inmemory", "--steps", "1", "--record", str(tmp_path / name)]) == 2
    err = capsys.readouterr().err
    assert says in err and "Traceback" not in err
    assert list(tmp_path.iterdir()) == []


def test_exact_table_mean_row_lines_up_and_progress_is_shown(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The mean row put its numbers under the wrong columns; exact ran 14 s on SAIM without progress."""
    rec = tmp_path / "r.json"
    assert main(["run", TOPOLOGY, "--mode", "inmemory", "--steps", "12", "--seed", "1", "--record", str(rec), "--quiet"]) == 0
    capsys.readouterr()
    assert main(["exact", str(rec)]) == 0
    out, err = capsys.readouterr()
    rows = [ln for ln in out.splitlines() if ln[:4].strip().isdigit() or ln.startswith("mean")]
    bars = {tuple(i for i, ch in enumerate(ln) if ch == "|") for ln in rows}
    assert len(rows) == 7 and len(bars) == 1 and len(next(iter(bars))) == 3, rows
    assert len({len(ln) for ln in rows}) == 1, rows
    assert "exact: step 12/13" in err or "exact: step" in err


def test_compare_table_folds_to_the_terminal_and_reports_progress() -> None:
    """compare printed a 220-character table after 26-90 s of silence."""
    from netsetest.analysis.compare import TABLE_HEADER, compare, table_rows
    from netsetest.cli.compare import TERMINAL_WIDTH, folded_table

    calls: list[tuple[int, int, str]] = []
    c = compare(TOPOLOGY, ("sdp", "interval"), steps=3, progress=lambda d, t, w: calls.append((d, t, w)))
    assert [d for d, _, _ in calls] == [1, 2, 3] and {t for _, t, _ in calls} == {3}
    rows = [TABLE_HEADER, *table_rows(c)]
    lines = folded_table(rows, TERMINAL_WIDTH)
    assert all(len(ln) <= TERMINAL_WIDTH for ln in lines)
    text = "\n".join(lines)
    assert all(h in text for h in TABLE_HEADER) and sum(len("  ".join(r)) for r in rows[:1]) > TERMINAL_WIDTH


def test_a_record_is_never_written_by_two_runs(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Two runs writing the same --record both exited 0 and interleaved their lines."""
    from netsetest.records.errors import RecordError
    from netsetest.records.files import open_locked
    from netsetest.records.record import load_record

    rec = tmp_path / "r.json"
    run = ["run", TOPOLOGY, "--mode", "inmemory", "--steps", "2", "--quiet", "--record", str(rec)]
    assert main(run) == 0
    before = rec.read_bytes()
    assert main(run) == 2 and "the file exists; give --overwrite" in capsys.readouterr().err
    assert rec.read_bytes() == before
    assert main([*run, "--overwrite", "--seed", "5"]) == 0 and load_record(rec).meta.seed == 5
    held = open_locked(rec)  # a run writing it: another writer fails at once and empties nothing
    try:
        with pytest.raises(RecordError, match="another run is writing this record"):
            open_locked(rec)
        # a second run is refused before any role starts: one line, exit 2 (a Zenoh run once started its
        # seven roles, then stopped them with exit 1 when its collector found the lock)
        for mode in ("zenoh", "inmemory"):
            assert main([*run, "--overwrite", "--mode", mode]) == 2
            err = capsys.readouterr().err
            assert err == f"netsetest run: --record {rec}: another run is writing this record\n", err
    finally:
        held.close()
