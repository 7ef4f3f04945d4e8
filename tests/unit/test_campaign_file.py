"""A campaign file (netsetest/campaign/spec.py): bad files are one line and exit 2 before any run starts; the
grid's runs and their keys (a changed parameter changes only the keys of the runs it touches); a run that
fails its verdict is rows with its cause; ``--fault-scale`` scales each fault to a fraction of its bound."""

from __future__ import annotations

from pathlib import Path

import pytest

from netsetest.campaign.rows import COLUMNS, ERROR, rows_of
from netsetest.campaign.spec import CampaignError, load_campaign
from netsetest.campaign.worker import RunOutcome
from netsetest.cli.main import main
from netsetest.config.schema import ConfigError, load_topology
from netsetest.records.summary import NodeSummary, RunSummary

GRID = """
[grid]
topology = "paper6"
estimator = ["sdp", "interval"]
case = ["nsnim", "saim"]
seeds = "0-2,7"
steps = 5
"""


def _file(tmp_path: Path, text: str, name: str = "c.toml") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


BAD = [
    ("[grid]\ntopology = 'paper6'\nseed = 3\n", "grid: Object contains unknown field `seed`"),
    ("[grid]\ntopology = 'paper6'\nestimator = 'kalman'\n", "grid.estimator = 'kalman': unknown estimator"),
    ("[grid]\ntopology = 'paper6'\nseeds = '5-2'\n", "grid.seeds = '5-2': seed range"),
    ("[grid]\ntopology = 'paper6'\nsteps = 0\n", "grid.steps = 0: must be ≥ 1"),
    ("[grid]\ntopology = 'paper6'\nfault_scale = [0.5, 11.0]\n", "grid.fault_scale = 11.0: a fault scale must be between 0 and 10"),
    ("[grid]\ntopology = 'paper6'\nmanoeuvre = 'slalom'\n", "grid.manoeuvre = 'slalom': unknown manoeuvre"),
    ("[grid]\ntopology = 'paper6'\ncase = []\n", "grid.case: an empty list"),
    ("[grid]\ntopology = 'no_such_topology'\n", "no_such_topology: file not found"),
    ("[grid]\ntopology = 'paper6'\nspeed = 60.0\n", "paper6 --speed 60.0"),  # the sine leaves the model's 80-120 km/h
    ("[[runs]]\ntopology = 'paper6'\n[[runs]]\ntopology = 'paper6'\nsignals = 'calm'\n", "runs[1].signals = 'calm': unknown signal kind"),
    ("name = 'x'\n", "no [grid] and no [[runs]]"),
    ("[grid\n", "not TOML"),
    ("[grid]\ntopology = 'paper6'\n[compute]\nfigures = ['exact', 'speed']\n", "compute.figures[1]"),
]


@pytest.mark.parametrize(("text", "says"), BAD, ids=[s for _, s in BAD])
def test_a_bad_campaign_file_is_one_line_and_exit_2_before_any_run(tmp_path: Path, capsys: pytest.CaptureFixture[str], text: str, says: str) -> None:
    out = tmp_path / "out"
    assert main(["campaign", str(_file(tmp_path, text)), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("netsetest campaign: ") and err.count("\n") == 1 and says in err, err
    assert not out.exists(), "nothing was started"


def test_workers_and_cluster_do_not_go_together(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["campaign", str(_file(tmp_path, GRID)), "--workers", "2", "--cluster", "tcp://127.0.0.1:1"]) == 2
    assert "--workers is the local pool's" in capsys.readouterr().err


def test_the_grid_is_every_combination_each_run_once(tmp_path: Path) -> None:
    c = load_campaign(_file(tmp_path, GRID + "[[runs]]\ntopology = 'paper6'\nestimator = 'sdp'\ncase = 'nsnim'\nseeds = [2, 9]\nsteps = 5\n"))
    assert len(c.runs) == 2 * 2 * 4 + 1  # the list's seed 2 is a run of the grid already
    assert len({p.key for p in c.runs}) == len(c.runs)
    assert c.runs[0].spec.command() == "netsetest run paper6 --case nsnim --steps 5 --estimator sdp --mode inmemory --seed 0"


def test_a_changed_parameter_changes_only_the_keys_of_the_runs_it_touches(tmp_path: Path) -> None:
    def keys(scales: str, topology: str = "paper6") -> dict[tuple, str]:
        c = load_campaign(_file(tmp_path, f"[grid]\ntopology = '{topology}'\nseeds = '0-1'\nsteps = 4\nfault_scale = {scales}\n"))
        return {(p.spec.scenario.fault_scale, p.spec.seed): p.key for p in c.runs}

    before, after = keys("[0.5, 1.0]"), keys("[0.5, 0.75]")
    assert {k: v for k, v in before.items() if k[0] == 0.5} == {k: v for k, v in after.items() if k[0] == 0.5}
    assert not set(before.values()) & {v for k, v in after.items() if k[0] == 0.75}
    bundled = Path(load_topology("paper6").path)
    assert keys("[0.5, 1.0]", str(bundled)) == before, "a key rests on the files' values, not on how the topology is named"


def test_a_run_that_fails_its_verdict_is_rows_with_its_cause(tmp_path: Path) -> None:
    c = load_campaign(_file(tmp_path, "[grid]\ntopology = 'paper6'\nsteps = 4\n"))
    p = c.runs[0]
    nodes = [NodeSummary(id=i, violations=int(i == 2), steps_evaluated=5, steps_covered=5, steps_contained=5 - int(i == 2)) for i in p.info.node_ids]
    summary = RunSummary(violations_total=1, node_steps_evaluated=30, node_steps_covered=30, node_steps_contained=29, nodes=nodes)
    rows = rows_of(c, p, RunOutcome(p.key, summary, None, None, None, 1.0, 1.0, "host:1"))
    assert len(rows) == 6 and all(set(r) == {col.name for col in COLUMNS} for r in rows)
    assert {(r["verdict"], r["exit_code"]) for r in rows} == {("FAIL", 1)}
    assert all("CONTAINMENT VIOLATED 1 time(s)" in r["cause"] and r["replay"] == p.spec.command() for r in rows)
    assert [r["violations"] for r in rows] == [int(i == 2) for i in p.info.node_ids]
    error = rows_of(c, p, RunOutcome(p.key, None, None, "ValueError: boom (at x.py:1)", None, 0.1, 0.1, "host:1"))
    assert {(r["verdict"], r["exit_code"], r["cause"], r["violations"]) for r in error} == {(ERROR, None, "ValueError: boom (at x.py:1)", None)}


def test_fault_scale_sets_each_fault_to_a_fraction_of_its_declared_bound() -> None:
    base, half = load_topology("paper6", steps=80), load_topology("paper6", steps=80, fault_scale=0.5)
    for n, h in zip(base.nodes, half.nodes):
        peak, half_peak = (max(abs(x.fault(k)) for k in range(81)) for x in (n, h))
        assert half_peak == pytest.approx(0.5 * n.fault_size if peak else 0.0, rel=1e-12), n.id
        if peak:  # the shape kept: the same steps nonzero, the same signs
            assert [(n.fault(k) > 0) - (n.fault(k) < 0) for k in range(81)] == [(h.fault(k) > 0) - (h.fault(k) < 0) for k in range(81)]
    assert half.settings_digest != base.settings_digest
    assert load_topology("paper6_reference", fault_scale=1.0).node(3).fault(40) == 0.0  # the reference stays fault-free


def test_fault_scale_needs_a_declared_size_to_scale_to(tmp_path: Path) -> None:
    nodes = Path(load_topology("paper6").path).parent.parent / "nodes"  # the bundled profiles
    (tmp_path / "nodes").mkdir()
    text = (nodes / "yaw1.toml").read_text()
    (tmp_path / "nodes" / "yaw1.toml").write_text(text.replace("rate = 0.2\nsize = 0.2", "rate = 0.2"))
    topo = "name = 't'\nnode_dir = 'nodes'\nsteps = 3\n[[nodes]]\nid = 1\nprofile = 'yaw1'\n[[edges]]\nto = 1\nfrom = 1\n"
    path = _file(tmp_path, topo, "t.toml")
    load_topology(path)
    with pytest.raises(ConfigError, match="a fault scale needs \\[fault_bound\\] size > 0"):
        load_topology(path, fault_scale=0.5)


def test_the_docs_name_every_column() -> None:
    doc = (Path(__file__).resolve().parents[2] / "docs" / "campaign.md").read_text(encoding="utf-8")
    missing = [c.name for c in COLUMNS if f"`{c.name}`" not in doc]
    assert not missing, f"docs/campaign.md does not name the columns {missing}"


def test_a_cluster_address_that_is_not_one_is_one_line_and_exit_2_before_anything_is_written(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "out"
    assert main(["campaign", str(_file(tmp_path, GRID)), "--out", str(out), "--cluster", "notanaddress"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("netsetest campaign: ") and err.count("\n") == 1 and "expected a Dask scheduler's address" in err, err
    assert not out.exists()


def test_dry_run_counts_the_runs_and_writes_nothing(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "out"
    assert main(["campaign", str(_file(tmp_path, GRID)), "--out", str(out), "--dry-run"]) == 0
    assert "16 runs, 0 already in" in capsys.readouterr().out and not out.exists()


def test_a_recorded_drive_is_an_axis_its_bytes_in_the_key(tmp_path: Path) -> None:
    logs = Path(__file__).resolve().parents[2] / "examples" / "logs"
    drive = tmp_path / "drive.csv"
    drive.write_bytes((logs / "drive.csv").read_bytes())
    text = f"[grid]\ntopology = '{logs / 'car_log.toml'}'\nsteps = 4\nlog = ['drive.csv']\nmap = '{logs / 'drive_csv.map.toml'}'\n"
    c = load_campaign(_file(tmp_path, text))
    (p,) = c.runs
    assert p.spec.command().endswith(f"--log {drive} --map {logs / 'drive_csv.map.toml'} --mode inmemory --seed 0") and p.info.drive_digest
    drive.write_bytes(drive.read_bytes().replace(b"\n", b"\n", 1) + b"\n")  # the same name, other bytes: another run
    assert load_campaign(_file(tmp_path, text)).runs[0].key != p.key
    with pytest.raises(CampaignError, match="grid.log = 'nowhere.csv'"):
        load_campaign(_file(tmp_path, text.replace("drive.csv", "nowhere.csv")))


def test_a_damaged_results_file_is_one_line_and_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("pyarrow")
    bad = tmp_path / "out" / "runs" / "estimator=sdp" / "case=nsnim" / "part-0.parquet"
    bad.parent.mkdir(parents=True)
    bad.write_bytes(b"PAR1 not a parquet file")
    assert main(["campaign", str(_file(tmp_path, GRID)), "--out", str(tmp_path / "out"), "--dry-run"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("netsetest campaign: ") and err.count("\n") == 1 and "a damaged results file" in err, err


def test_the_docs_start_a_dask_cluster_with_the_environment_the_benchmark_measured() -> None:
    """docs/campaign.md's start lines set every variable of ``engines.DASK_ENV`` (the benchmark's cluster and
    the cluster test start with it) and preload the run's code (``worker.dask_setup``)."""
    from netsetest.campaign.engines import DASK_ENV

    text = (Path(__file__).parents[2] / "docs" / "campaign.md").read_text()
    start = text[text.index("## Where the runs go") : text.index("### Why Dask distributed, not Ray")]
    assert [f"{k}={v}" for k, v in DASK_ENV.items() if f"{k}={v}" not in start] == []
    assert "dask worker tcp://HOST:8786 --nthreads 1 --nworkers N --preload netsetest.campaign.worker" in start
