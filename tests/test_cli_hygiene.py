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

ROOT = Path(__file__).resolve().parents[1]
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
    r = subprocess.run([sys.executable, "-m", "netsetest.cli.main", *_run()[:1], str(topo), *_run()[2:]], capture_output=True,
                       text=True, timeout=60)  # fmt: skip
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
