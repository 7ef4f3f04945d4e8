"""``netsetest calibrate TOPOLOGY --logs TRAIN… [--held-out TEST…]`` (analysis/calibrate.py, docs/your-log.md): the bounds
from recorded drives.  The drive is a simulated paper6 run written as a log (its truth the reference), so what the
calibration must find is known exactly: with the wind taken as 0, e_k = D̄_k w_k; each sensor's noise is the run's
own v (the worst signals: at its bound); the envelope is the drive's |v·r| and speeds.  A reference of some accuracy
a widens every e_k by a + |Ā_k| a (any pair of states in the two boxes gives an e_k inside the bound), and a held-out
drive whose e_k leave the bound is said to."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from run_helpers import shared_run

from netsetest.analysis.calibrate import calibrate_logs, check_held_out, log_recording, logged_mismatch
from netsetest.cli.main import main
from netsetest.config.schema import load_topology
from netsetest.logs.drive import with_log_steps
from netsetest.logs.write import DriveTable, from_truth, mapping_toml, write_log

STEPS = 12  # the replay tests' run (run_helpers.shared_run: made once per worker)
MARGIN = 0.1


@pytest.fixture(scope="module")
def run() -> tuple[list[dict], DriveTable]:
    res = shared_run("nsnim", "worst", 3, STEPS)
    assert res.parts is not None
    return res.parts["truth"], from_truth(res.parts["truth"], 0.1, "synthetic: the calibration test's simulated paper6 run")


def _log(d: DriveTable, tmp: Path, name: str, accuracy: tuple[float, float] | None, healthy: str = "") -> Path:
    tmp.mkdir(exist_ok=True)
    log = write_log(d, tmp / f"{name}.csv", "csv")
    text = mapping_toml(d, "csv", accuracy)
    if healthy:
        text = text.replace('channel = "yaw2"\nunit = "rad/s"', f'channel = "yaw2"\nunit = "rad/s"\nhealthy = {healthy}')
    (tmp / f"{name}.map.toml").write_text(text)  # the log's name with .map.toml: the default mapping
    return log


def _scenario(log: Path):
    return with_log_steps(load_topology("paper6", log=str(log)), whole=True)


def test_from_an_exact_reference_the_bounds_are_the_drive_s_own(run: tuple[list[dict], DriveTable], tmp_path: Path) -> None:
    truth, d = run
    sc = _scenario(_log(d, tmp_path, "train", (0.0, 0.0)))
    cal = calibrate_logs([sc], MARGIN)
    wind = np.array([sc.model.blend(sc.model.weights(t["vx"]))[2][:, 0] * t["w"] for t in truth[:-1]])  # D̄_k w_k
    np.testing.assert_allclose(np.diag(cal.box.G), (1 + MARGIN) * np.abs(wind).max(axis=0), rtol=1e-9)
    for i in sc.ids:  # y_nofault − C x = Dv v: the worst signals hold v at ±√R
        v = max(abs(t["noise"][str(i)]) for t in truth)
        assert cal.R[i] == pytest.approx(((1 + MARGIN) * v) ** 2, rel=1e-9) and cal.noise_steps[i] == STEPS + 1
    ay = [t["vx"] * t["x"][1] for t in truth[:-1]]
    assert cal.envelope.ay_max == pytest.approx(max(map(abs, ay)), rel=1e-12) and cal.transitions == STEPS
    assert all(cal.ellipsoid.holds(e) for e in wind)


def test_the_reference_s_accuracy_is_carried_through_the_model(run: tuple[list[dict], DriveTable], tmp_path: Path) -> None:
    """Every e_k any pair of states inside the reference's boxes gives lies inside both bounds; the box is the exact
    one's widened by a + |Ā_k| a at its worst transition; the noise bound by |C| a / |Dv|."""
    _, d = run
    acc = np.array([0.002, 0.003])
    exact, coarse = (calibrate_logs([_scenario(_log(d, tmp_path / n, "train", a))], MARGIN) for n, a in (("a", (0.0, 0.0)), ("b", tuple(acc))))
    sc = _scenario(tmp_path / "b" / "train.csv")
    rec = log_recording(sc)
    m = logged_mismatch(sc, rec)
    expect = (np.abs(m.centre) + m.half).max(axis=0) * (1 + MARGIN)
    np.testing.assert_allclose(np.diag(coarse.box.G), expect, rtol=1e-12)
    assert np.all(np.diag(coarse.box.G) > np.diag(exact.box.G) + acc)
    rng = np.random.default_rng(0)
    for k in range(STEPS):
        a, b, _ = sc.model.blend(sc.model.weights(rec.vx[k]))
        for _ in range(20):
            x0, x1 = (rec.x_ref[j] + rng.uniform(-1, 1, 2) * acc for j in (k, k + 1))  # states the reference allows
            e = x1 - a @ x0 - b[:, 0] * rec.u[k]
            assert coarse.box.holds(e) and coarse.ellipsoid.holds(e)
    for i in sc.ids:
        sen = sc.node(i).sensor
        grow = float(np.abs(sen.C) @ acc) / abs(sen.Dv)
        assert math.sqrt(coarse.R[i]) == pytest.approx(math.sqrt(exact.R[i]) + (1 + MARGIN) * grow, rel=1e-9)


def test_a_sensor_s_noise_bound_uses_its_healthy_stretches_only(run: tuple[list[dict], DriveTable], tmp_path: Path) -> None:
    """Node 2's logged sensor had a fault (+0.5) after t = 0.55 s: declared healthy only before, its bound is its noise's."""
    _, d = run
    yaw = dict(d.yaw)
    yaw[2] = np.where(d.t > 0.55, yaw[2] + 0.5, yaw[2])
    faulty = DriveTable(d.t, d.speed, d.steering, yaw, d.beta, d.r)
    plain = calibrate_logs([_scenario(_log(d, tmp_path, "plain", (0.0, 0.0)))], MARGIN)
    cal = calibrate_logs([_scenario(_log(faulty, tmp_path, "faulty", (0.0, 0.0), healthy="[[0.0, 0.55]]"))], MARGIN)
    assert cal.noise_steps[2] == 6 and cal.R[2] <= plain.R[2] and cal.R[1] == plain.R[1]
    assert (
        calibrate_logs([_scenario(_log(faulty, tmp_path, "all", (0.0, 0.0)))], MARGIN).R[2] > 10 * plain.R[2]
    )  # declared healthy throughout: the fault is noise


def test_held_out_drives_are_checked_against_the_calibration(run: tuple[list[dict], DriveTable], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The training drive itself holds out inside everything; one steered harder (e_k grows by B̄ Δu) is certainly
    outside the box on some transitions, and leaves the envelope; the command prints it all, ready to paste, and
    writes the box and the envelope with --toml."""
    _, d = run
    train = _log(d, tmp_path, "train", (0.0, 0.0))
    harder = _log(DriveTable(d.t, d.speed, d.steering * 3.0, d.yaw, d.beta, d.r), tmp_path, "harder", (0.0, 0.0))
    cal = calibrate_logs([_scenario(train)], MARGIN)
    same, hard = check_held_out(_scenario(train), cal), check_held_out(_scenario(harder), cal)
    assert same.inside == {"inside": STEPS, "overlap": 0, "disjoint": 0} and all(c["inside"] == STEPS + 1 for c in same.noise.values())
    assert hard.inside["disjoint"] + hard.outside["disjoint"] > 0
    toml = tmp_path / "bounds.toml"
    assert main(["calibrate", "paper6", "--logs", str(train), "--held-out", str(train), str(harder), "--toml", str(toml)]) == 0
    out = capsys.readouterr().out
    assert "[model_uncertainty]\nbox = [" in out and "[envelope]\nay_max = " in out and "R = " in out and out.count("held out ") == 2
    assert "[model_uncertainty]" in toml.read_text() and "[envelope]" in toml.read_text()


def test_each_log_carries_its_own_mapping(run: tuple[list[dict], DriveTable], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """``--logs DRIVE:MAP.toml``: each drive read with its own mapping (here the faulty drive's declares node 2 healthy
    only before its fault), the others with --map or their default; ``--held-out`` alike.  The same drives under one
    mapping calibrate differently: node 2's fault becomes noise."""
    _, d = run
    yaw = dict(d.yaw)
    yaw[2] = np.where(d.t > 0.55, yaw[2] + 0.5, yaw[2])
    faulty = DriveTable(d.t, d.speed, d.steering, yaw, d.beta, d.r)
    plain = _log(d, tmp_path, "plain", (0.0, 0.0))  # its default mapping: plain.map.toml
    log = _log(faulty, tmp_path, "faulty", (0.0, 0.0))
    own = tmp_path / "faulty_healthy_before.toml"
    own.write_text(
        (tmp_path / "faulty.map.toml").read_text().replace('channel = "yaw2"\nunit = "rad/s"', 'channel = "yaw2"\nunit = "rad/s"\nhealthy = [[0.0, 0.55]]')
    )
    expected = calibrate_logs([_scenario(plain), with_log_steps(load_topology("paper6", log=str(log), mapping=str(own)), whole=True)], MARGIN)
    js = tmp_path / "cal.json"
    argv = ["calibrate", "paper6", "--logs", str(plain), f"{log}:{own}", "--held-out", f"{log}:{own}", "--json", str(js)]
    assert main(argv) == 0
    out = capsys.readouterr().out
    doc = json.loads(js.read_text())
    assert doc["maps"] == [str(tmp_path / "plain.map.toml"), str(own)] and doc["R"] == {str(i): R for i, R in expected.R.items()}
    assert doc["noise_steps"]["2"] == STEPS + 1 + 6 and f"mapping {own}" in out and f"held out {log} (mapping {own})" in out
    assert main(["calibrate", "paper6", "--logs", str(plain), str(log), "--json", str(js)]) == 0  # faulty.map.toml: healthy throughout
    capsys.readouterr()
    assert json.loads(js.read_text())["R"]["2"] > 10 * expected.R[2]


@pytest.mark.parametrize(
    "args, expect",
    [
        (["--logs", "LOG:MISSING.toml"], "MISSING.toml: the log's mapping file not found"),
        (["--logs", "LOG", "--held-out", "LOG:BAD.toml"], "BAD.toml"),
    ],
)
def test_a_log_s_own_mapping_that_is_not_one_exits_2(
    run: tuple[list[dict], DriveTable], tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str], expect: str
) -> None:
    _, d = run
    (tmp_path / "BAD.toml").write_text("[log]\nformat = 'csv'\n[speed]\n")
    paths = {"LOG": str(_log(d, tmp_path, "train", (0.0, 0.0))), "MISSING.toml": str(tmp_path / "MISSING.toml"), "BAD.toml": str(tmp_path / "BAD.toml")}
    argv = [":".join(paths.get(p, p) for p in a.split(":")) for a in args]
    assert main(["calibrate", "paper6", *argv]) == 2
    err = capsys.readouterr().err
    assert expect in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err, err


@pytest.mark.parametrize(
    "arg, expect",
    [
        ("drive.map.toml", "'drive.map.toml' is a mapping, not a drive: give it with its drive as DRIVE:MAP.toml"),
        (":drive.map.toml", "expected DRIVE or DRIVE:MAP.toml, with both names given"),
        ("drive.csv:.toml", "expected DRIVE or DRIVE:MAP.toml, with both names given"),
    ],
)
def test_a_drive_and_mapping_pair_that_is_not_one_exits_2(arg: str, expect: str, capsys: pytest.CaptureFixture[str]) -> None:
    for option in ("--logs", "--held-out"):
        with pytest.raises(SystemExit) as exc:
            main(["calibrate", "paper6", "--logs", "x.csv", option, arg] if option == "--held-out" else ["calibrate", "paper6", option, arg])
        assert exc.value.code == 2
        err = capsys.readouterr().err
        assert f"argument {option}: " in err and expect in err, err


def test_a_drive_s_own_colon_stays_its_own() -> None:
    from netsetest.cli.checks import log_with_map

    assert log_with_map("run:3.mf4") == ("run:3.mf4", None) and log_with_map("run:3.mf4:m.toml") == ("run:3.mf4", "m.toml")
    assert log_with_map("bags/drive_mcap") == ("bags/drive_mcap", None)


@pytest.mark.parametrize(
    "args, expect",
    [
        (["--held-out", "x.csv"], "--held-out and --map go with --logs"),
        (["--logs", "LOG", "--manoeuvres", "paper"], "--logs chooses its own drives: leave out --manoeuvres"),
        (["--logs", "NOREF"], "no [reference]: calibrating from a log needs the reference"),
    ],
)
def test_calibrate_logs_bad_use_exits_2(
    run: tuple[list[dict], DriveTable], tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str], expect: str
) -> None:
    _, d = run
    paths = {"LOG": str(_log(d, tmp_path, "train", (0.0, 0.0))), "NOREF": str(_log(d, tmp_path, "noref", None))}
    assert main(["calibrate", "paper6", *(paths.get(a, a) for a in args)]) == 2
    err = capsys.readouterr().err
    assert expect in err and len(err.strip().splitlines()) == 1, err
