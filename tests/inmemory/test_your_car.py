"""docs/your-car.md runs as written: its files are written into an empty directory and every command of
its ``bash`` blocks runs there in order (netsetest through ``main``, the shell's ``cat`` through a shell),
each exiting 0; then what the text says of the runs is checked against what they printed."""

from __future__ import annotations

import re
import shlex
import subprocess
from pathlib import Path

import pytest

from netsetest.cli.main import main

pytest.importorskip("vehiclemodels")
pytest.importorskip("matplotlib")
DOC = Path(__file__).resolve().parents[2] / "docs" / "your-car.md"
FILE_RE = re.compile(r"File `([^`]+)`:\n\n```toml\n(.*?)```", re.S)
BASH_RE = re.compile(r"```bash\n(.*?)```", re.S)


def tutorial() -> tuple[dict[str, str], list[str]]:
    """The files the tutorial shows (path → text) and its commands, in order."""
    text = DOC.read_text()
    files = {m[1]: m[2] for m in FILE_RE.finditer(text)}
    commands = [ln.strip() for block in BASH_RE.findall(text) for ln in block.splitlines() if ln.strip() and not ln.startswith("#")]
    return files, commands


def test_the_tutorial_shows_every_step() -> None:
    files, commands = tutorial()
    assert set(files) == {"nodes/vanagon_yaw.toml", "nodes/vanagon_yaw_drift.toml", "vanagon.toml"}
    verbs = [c.split()[1] for c in commands if c.startswith("netsetest ")]
    assert verbs == ["run", "calibrate", "run", "run", "inspect", "plot"]
    assert "--envelope" in commands[1] and "--strict" in commands[3]


def test_the_tutorial_runs_end_to_end(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    files, commands = tutorial()
    for name, text in files.items():
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text(text)
    monkeypatch.chdir(tmp_path)
    outputs = []
    for command in commands:
        if command.startswith("netsetest "):
            code = main(shlex.split(command)[1:])
        else:  # cat a >> b: the one shell step, appending the calibrated tables
            assert command.startswith("cat "), command
            code = subprocess.run(command, shell=True, cwd=tmp_path, check=False).returncode
        out, err = capsys.readouterr()
        assert code == 0, (command, out, err)
        outputs.append(out)
    first, _, _, heldout, other, inspect, plot = outputs
    # what the text says: without a bound only step 0 is covered, every other node-step by model mismatch
    assert "the guarantee applied on 3 (not covered 60: model mismatch 60)" in first.splitlines()[-1]
    topo = (tmp_path / "vanagon.toml").read_text()
    assert "[model_uncertainty]\nbox = [" in topo and "[envelope]\nay_max = 7.0\nspeed_kmh = [75.0, 85.0]" in topo
    for run in (heldout, other):  # the held-out drives: every node-step covered, e_k well inside the bound
        assert "contained on 243 of 243 node-steps; the guarantee applied on 243." in run.splitlines()[-1]
        assert "inside it on all 80 steps" in run.splitlines()[1] and run.splitlines()[2].endswith("; inside on every step")
    assert "detected" in inspect and "not covered" not in inspect
    assert any(line.endswith("mismatch.png") for line in plot.splitlines())
