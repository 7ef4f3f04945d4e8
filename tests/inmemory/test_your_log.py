"""docs/your-log.md runs as written: the repository's examples/ and nodes/ are copied into an empty directory and
every command of its ``bash`` blocks runs there in order (netsetest through ``main``), each exiting 0; the example
drive written again equals the committed one (to rounding: the car is integrated numerically); every run of the
synthetic held-out drive with its INS-grade reference misses nothing."""

from __future__ import annotations

import re
import shlex
import shutil
from pathlib import Path

import numpy as np
import pytest

from netsetest.cli.main import main

pytest.importorskip("vehiclemodels")
pytest.importorskip("rosbags")
pytest.importorskip("asammdf")
ROOT = Path(__file__).resolve().parents[2]
DOC = ROOT / "docs" / "your-log.md"
BASH_RE = re.compile(r"```bash\n(.*?)```", re.S)


def commands() -> list[str]:
    return [ln.strip() for block in BASH_RE.findall(DOC.read_text()) for ln in block.splitlines() if ln.strip() and not ln.startswith("#")]


def test_the_tutorial_runs_end_to_end(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    shutil.copytree(ROOT / "examples", tmp_path / "examples")
    shutil.copytree(ROOT / "nodes", tmp_path / "nodes")
    monkeypatch.chdir(tmp_path)
    cmds = commands()
    assert [c.split()[1] for c in cmds] == ["log-example", "run", "run", "run", "calibrate"]
    for command in cmds:
        assert command.startswith("netsetest "), command
        assert main(shlex.split(command)[1:]) == 0, command
        out = capsys.readouterr().out
        if " run " in f" {command} ":
            last = out.splitlines()[-1]
            assert last.startswith("PASS") and "missed on 0," in last and "a recorded drive; reference ± 0.00262 rad" in last, last
    again = np.loadtxt(tmp_path / "examples/logs/drive.csv", delimiter=",", skiprows=1)
    committed = np.loadtxt(ROOT / "examples/logs/drive.csv", delimiter=",", skiprows=1)
    assert again.shape == committed.shape and np.allclose(again, committed, rtol=1e-9, atol=1e-12)


def test_every_example_file_says_it_is_synthetic() -> None:
    logs = ROOT / "examples" / "logs"
    for mapping in logs.glob("*.map.toml"):
        assert mapping.read_text().startswith("# SYNTHETIC drive"), mapping
    for bag in ("drive_mcap", "drive_sqlite3"):
        assert (logs / bag / "README.txt").read_text().startswith("SYNTHETIC drive"), bag
    assert b"SYNTHETIC drive" in (logs / "drive.mf4").read_bytes() and b"SYNTHETIC drive" in (logs / "drive.parquet").read_bytes()
    assert "SYNTHETIC" in (logs / "README.md").read_text()
