"""The operating envelope (models/envelope.py): its check, its declaration, its flag on the wire, the judge's
attribution of a miss after a transition whose e_k left its bound, and what the verdict says (issue 29)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from netsetest.cli.main import main
from netsetest.config.schema import ConfigError, load_topology
from netsetest.messages import Truth, decode, encode
from netsetest.models.envelope import MODEL_MISMATCH, OUTSIDE_ENVELOPE, OperatingEnvelope
from netsetest.models.uncertainty import ModelUncertainty
from netsetest.models.vehicle import KMH
from netsetest.records.summary import CarSummary, NodeSummary, RunSummary
from netsetest.runtime.report import EXIT_NODE_LOST, EXIT_OK, EXIT_VIOLATION, Outcome, car_lines, exit_code, format_table, outcome, verdict

from message_helpers import truth

ROOT = Path(__file__).resolve().parents[2]
ENV = OperatingEnvelope(6.0, (70.0, 120.0))


def test_envelope_holds_inside_and_measures_its_margins() -> None:
    assert ENV.holds(5.9, 80 * KMH) and ENV.holds(-6.0, 70 * KMH) and ENV.holds(6.0, 120 * KMH)
    assert not ENV.holds(6.01, 80 * KMH) and not ENV.holds(-6.5, 80 * KMH)
    assert not ENV.holds(1.0, 69.9 * KMH) and not ENV.holds(1.0, 120.1 * KMH)
    assert not ENV.holds(float("nan"), 80 * KMH)
    assert ENV.ay_margin(-4.5) == pytest.approx(1.5) and ENV.ay_margin(7.0) == pytest.approx(-1.0)
    assert ENV.speed_margin(80 * KMH) == pytest.approx(10.0) and ENV.speed_margin(125 * KMH) == pytest.approx(-5.0)


def test_an_older_truth_without_the_envelope_decodes_as_inside_and_a_new_one_round_trips() -> None:
    old = truth()
    payload = encode(old)
    assert b"envelope_ok" not in payload and b"ay" not in payload  # omitted at their defaults
    assert decode(payload).envelope_ok is True
    new = truth(speed=22.2, ay=-6.5, envelope_ok=False, e=[1e-3, -2e-2], mismatch_ok=False)
    back = decode(encode(new))
    assert isinstance(back, Truth) and (back.speed, back.ay, back.envelope_ok) == (22.2, -6.5, False)


def _topology(tmp_path: Path, extra: str, plant: bool = True) -> Path:
    text = (ROOT / "topologies" / ("paper6_car.toml" if plant else "paper6.toml")).read_text()
    text = text.replace('node_dir = "../nodes"', f'node_dir = "{ROOT / "nodes"}"').replace("[[nodes]]", extra + "\n[[nodes]]", 1)
    path = tmp_path / "t.toml"
    path.write_text(text)
    return path


def test_the_topology_declares_an_envelope_beside_its_bound(tmp_path: Path) -> None:
    pytest.importorskip("vehiclemodels")
    sc = load_topology(_topology(tmp_path, "[envelope]\nay_max = 6\nspeed_kmh = [80, 120]\n"))  # paper6_car's model range: 80–120 km/h
    assert sc.envelope == OperatingEnvelope(6.0, (80.0, 120.0))
    assert load_topology("paper6_car").envelope is None  # optional


@pytest.mark.parametrize(
    ("extra", "plant", "says"),
    [
        ("[envelope]\nay_max = 6\nspeed_kmh = [120, 70]\n", True, "lo ≤ hi"),
        ("[envelope]\nay_max = 0\nspeed_kmh = [70, 120]\n", True, "ay_max"),
        ("[envelope]\nay_max = 6\n", True, "speed_kmh"),
        ("[envelope]\nay_max = 6\nspeed_kmh = [70, 120]\n", False, "nonlinear plant"),  # the T-S plant: e_k ≡ 0, no bound
        ("[envelope]\nay_max = 6\nspeed_kmh = [60, 130]\n", True, "leave the model's range 80–120 km/h"),  # issue 41 item 10
        ("[envelope]\nay_max = 6\nspeed_kmh = [80, 120.5]\n", True, "leave the model's range"),
    ],
)
def test_a_wrong_envelope_is_refused_in_one_line(tmp_path: Path, extra: str, plant: bool, says: str) -> None:
    if plant:
        pytest.importorskip("vehiclemodels")
    with pytest.raises(ConfigError, match=says):
        load_topology(_topology(tmp_path, extra, plant))


def test_run_and_calibrate_refuse_an_envelope_beyond_the_model_range_with_the_same_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Issue 41 item 10: one rule (config/schema.py, check_envelope_speeds) for the topology's [envelope], which
    `run` reads, and `calibrate --envelope --speed`; each refuses before any drive, exit 2, one line."""
    pytest.importorskip("vehiclemodels")
    topology = _topology(tmp_path, "[envelope]\nay_max = 6\nspeed_kmh = [60, 130]\n")
    assert main(["run", str(topology), "--mode", "inmemory", "--steps", "2", "--quiet"]) == 2
    run_err = capsys.readouterr().err
    bare = _topology(tmp_path, "")
    assert main(["calibrate", str(bare), "--envelope", "--ay-max", "6", "--speed", "60-130", "--steps", "2"]) == 2
    calibrate_err = capsys.readouterr().err
    for err in (run_err, calibrate_err):
        assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    why = "the envelope's speeds 60–130 km/h leave the model's range 80–120 km/h"
    assert why in run_err and why in calibrate_err
    assert run_err.split(why)[1] == calibrate_err.split(why)[1]  # the same rule's words


def test_the_judge_names_the_plants_transition_first_and_whether_the_car_left_its_envelope() -> None:
    pytest.importorskip("vehiclemodels")
    from netsetest.roles.judge import Judge

    sc = dataclasses.replace(load_topology("paper6_car"), envelope=ENV)
    judge, n = Judge(sc), sc.nodes[0]
    ids = dict.fromkeys(sc.ids, 0.0)
    flags = dict.fromkeys(sc.ids, True)
    base = dict(faults=ids, noise=ids, gamma={s: 1.0 for s in ids}, y=ids, y_nofault=ids, sector_ok=flags, noise_ok=flags, r=ids, fault_ok=flags)
    now = truth(step=5, **(base | {"noise_ok": {**flags, n.id: False}}))  # its own noise bound broke too
    for envelope_ok, cause in ((True, MODEL_MISMATCH), (False, OUTSIDE_ENVELOPE)):
        prev = truth(step=4, **base, e=[0.1, 0.1], mismatch_ok=False, envelope_ok=envelope_ok)
        assert judge.own_cause(n, None, now, prev, 5) == cause
    inside = truth(step=4, **base, e=[0.0, 0.0], envelope_ok=False)  # left the envelope, e_k inside its bound: the guarantee held
    assert judge.own_cause(n, None, now, inside, 5) == "noise"
    assert judge.own_cause(n, None, truth(step=5, **base), inside, 5) is None


def _summary(**kw: object) -> RunSummary:
    car = CarSummary(
        plant="single-track/3",
        car="CommonRoad vehicle 3, VW Vanagon",
        manoeuvre="double-lane-change at 80 km/h",
        bound="box [0.00263, 0.018]",
        transitions=80,
        e_max=[0.003, 0.029],
        e_max_ratio=1.61,
        e_outside=7,
        e_outside_first=8,
        envelope=ENV.text,
        ay_peak=7.8,
        speed_kmh=[79.7, 80.0],
        ay_margin=-1.8,
        speed_margin_kmh=9.7,
        envelope_left=12,
    )
    base: dict[str, object] = dict(
        steps_completed=80,
        node_steps_evaluated=486,
        node_steps_contained=480,
        node_steps_covered=438,
        node_steps_not_covered={"inherited": 6, MODEL_MISMATCH: 30, OUTSIDE_ENVELOPE: 12},
        misses_assumption_broken_total=6,
        misses_by_cause={"inherited": 6},
        car=car,
        nodes=[NodeSummary(id=i) for i in range(1, 7)],
    )
    base.update(kw)
    return RunSummary(**base)  # type: ignore[arg-type]  # the fields above, by name


def test_the_verdict_says_a_miss_outside_the_guarantee_in_words_with_its_cause() -> None:
    text = verdict(_summary())
    assert "6 set(s) missed the truth outside the guarantee (6 of them resting on an input that missed it): " in text
    assert "model mismatch exceeded its bound on 30 node-steps: the guarantee does not hold there; recalibrate (docs/plant.md)" in text
    assert "the car left its operating envelope and e_k its bound on 12 node-steps" in text
    assert "outside the guarantee" not in verdict(_summary(misses_assumption_broken_total=0))
    other = verdict(_summary(misses_by_cause={"noise": 2}, misses_assumption_broken_total=2))
    assert "2 set(s) missed the truth outside the guarantee: model mismatch" in other and other.endswith(
        "misses where an assumption of their own step broke: noise 2"
    )


def test_the_header_names_the_car_the_manoeuvre_its_mismatch_and_envelope_margin() -> None:
    head = "\n".join(car_lines(_summary()))
    for part in ("single-track/3 (CommonRoad vehicle 3, VW Vanagon)", "double-lane-change at 80 km/h", "largest e_k 1.61 × its bound"):
        assert part in head
    assert "e_k left it on 7 of 80 steps (first k = 8)" in head and "margin -1.80 m/s², 9.7 km/h; left on 12 of 80 steps" in head
    assert "node-steps after a step whose e_k left its bound: 42" in head
    assert car_lines(_summary(car=None)) == []  # the T-S plant: no car


def test_strict_fails_a_run_with_a_miss_outside_the_guarantee_in_its_one_verdict() -> None:
    s = _summary()
    assert outcome(s) == Outcome("PASS (partial coverage)", EXIT_OK) and exit_code(s) == EXIT_OK
    assert outcome(s, strict=True) == Outcome("FAIL (--strict)", EXIT_VIOLATION) and exit_code(s, strict=True) == EXIT_VIOLATION
    last = format_table(s, strict=True).splitlines()[-1]
    assert last.startswith("FAIL (--strict): ") and "6 set(s) missed the truth outside the guarantee" in last
    assert format_table(s).splitlines()[-1] == last.replace("FAIL (--strict)", "PASS (partial coverage)", 1)
    lost = dataclasses.replace(s, nodes_missing=[2])
    assert outcome(lost) == Outcome("NODE LOST", EXIT_NODE_LOST) and outcome(lost, strict=True) == Outcome("FAIL (--strict)", EXIT_VIOLATION)
    assert outcome(dataclasses.replace(s, stopped="interrupted"), strict=True).word == "INTERRUPTED"  # a stopped run stays stopped
    clean = _summary(misses_assumption_broken_total=0)
    assert outcome(clean, strict=True) == outcome(clean)


def test_the_car_summary_round_trips_and_a_ts_summary_has_none() -> None:
    s = _summary()
    assert RunSummary.from_dict(s.to_dict()) == s
    assert "car" not in _summary(car=None).to_dict()


def test_the_bound_measures_e_in_its_own_norm() -> None:
    box = ModelUncertainty.box((0.01, 0.02))
    assert box.ratio(np.array([0.005, -0.03])) == pytest.approx(1.5)
    ell = ModelUncertainty.ellipsoid(np.diag([1e-4, 4e-4]))
    assert ell.ratio(np.array([0.01, 0.0])) == pytest.approx(1.0)


def test_the_bench_table_says_per_car_and_drive_what_was_covered_and_attributed() -> None:
    from netsetest_bench.figures.plant import Envelopes
    from netsetest_bench.plant import envelope_markdown
    from netsetest_bench.render import typed

    row = dict(
        case="nsnim", kmh=70.0, steps=80, ay_peak=5.5, envelope_left=0, e_max_ratio=0.4, covered=486, evaluated=486, violations=0, misses=0, misses_attributed=0
    )
    outside = dict(row, kmh=120.0, ay_peak=9.1, envelope_left=12, e_max_ratio=1.7, covered=400, misses=9, misses_attributed=9, verdict_says=True)
    env = {
        "ay_max": 6.0,
        "speed_kmh": [70.0, 120.0],
        "seeds": [0, 1, 2, 3, 4],
        "held_out_seeds": [100, 101],
        "cars": [{"vehicle": 3, "box": [0.0037, 0.0199], "drives": {"double-lane-change": [row, row], "double-lane-change (outside)": [outside]}}],
    }
    lines = envelope_markdown(typed(Envelopes, env))
    assert "--ay-max 6 --speed 70-120 --seeds 0-4" in lines[0] and "a double lane change at 70 km/h;" in lines[0] and "lap" not in lines[0]
    env["cars"][0]["drives"]["lap"] = [dict(row, kmh=None, steps=300)]  # a lap measured: named with its length
    assert "the lap's first 300 steps (the first straight and into the first bend" in envelope_markdown(typed(Envelopes, env))[0]
    assert "a double lane change at 120 km/h, outside the envelope (seed 100 only)" in lines[0]
    assert "| 3 (VW Vanagon) | [0.0037, 0.0199] | double-lane-change | nsnim | 2 | 5.50 | 0 | 0.40 | 972 / 972 | 0 | 0 (0, yes) |" in lines
    assert "| 3 (VW Vanagon) | [0.0037, 0.0199] | double-lane-change (outside) | nsnim | 1 | 9.10 | 12 | 1.70 | 400 / 486 | 0 | 9 (9, yes) |" in lines


@pytest.mark.parametrize(("strict", "code", "word"), [(False, EXIT_OK, "PASS (partial coverage): "), (True, EXIT_VIOLATION, "FAIL (--strict): ")])
def test_a_zenoh_run_decides_strict_in_the_same_verdict(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], strict: bool, code: int, word: str
) -> None:
    """``run --mode zenoh --strict``: the launcher's summary (a collector that exited with its code) goes through
    the same outcome() as in memory: one verdict line, its word and the exit code together."""
    from netsetest.cli.main import main
    from netsetest.runtime import launcher

    monkeypatch.setattr(launcher, "plan_run", lambda opts: None)
    monkeypatch.setattr(launcher, "launch", lambda plan: launcher.RunOutcome(EXIT_OK, _summary(mode="zenoh")))
    assert main(["run", "paper6", "--quiet", *(["--strict"] if strict else [])]) == code
    out = capsys.readouterr().out.splitlines()
    assert out[-1].startswith(word + "zenoh run") and "6 set(s) missed the truth outside the guarantee" in out[-1]
