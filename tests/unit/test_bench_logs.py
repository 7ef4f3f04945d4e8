"""The logs part's report (netsetest_bench/logs.py): issue 42's targets are read from the right figures (the bag's row,
wall time for the replay, the exact and the INS runs of the held-out drive), and a target missed is said to be."""

from __future__ import annotations

import copy

from netsetest_bench.logs import logs_markdown, logs_summary_markdown, targets


def _run(contained: int, missed: int, undecided: int, acc: list[float]) -> dict:
    inside = {"inside": 590, "overlap": 0, "disjoint": 0}
    return {
        "accuracy": acc,
        "held_out": {"inside": inside, "outside": {"inside": 9, "overlap": 0, "disjoint": 0}, "noise": {"1": inside}},
        "evaluated": 600,
        "contained": contained,
        "missed": missed,
        "undecided": undecided,
        "covered": 598,
        "not_covered": {"noise": 2},
        "violations": 0,
    }


def _row(fmt: str, import_s: float, peak: float) -> dict:
    return {
        "format": fmt,
        "size_mb": 500.0,
        "write_s": 100.0,
        "load": "3.00 3.00 3.00",
        "steps": 18000,
        "import_s": import_s,
        "import_cpu_s": import_s / 2,
        "stream_s": 20.0,
        "stream_cpu_s": 10.0,
        "rss_before_mb": 30.0,
        "rss_mb": [60.0, 61.0, 61.5],
        "peak_mb": peak,
    }


RES = {
    "import": {"minutes": 30.0, "hz": 100.0, "channels": 9, "samples": 1_620_000, "rows": [_row("rosbag-mcap", 8.0, 120.0), _row("csv", 30.0, 900.0)]},
    "replay": {
        "steps": 300,
        "drive_s": 30.0,
        "reps": 3,
        "log_wall_s": 1.2,
        "log_cpu_s": 1.0,
        "model_wall_s": 1.3,
        "model_cpu_s": 1.1,
        "realtime_wall": 25.0,
        "realtime_cpu": 30.0,
        "same_verdict": True,
        "load": "3.00 3.00 3.00",
    },
    "calibration": {
        "train_seeds": [1, 2, 3],
        "train_s": 30.0,
        "held_s": 30.0,
        "held_seed": 100,
        "held_steer": 0.009,
        "transitions": 900,
        "box": [0.003, 0.04],
        "envelope": {"ay_max": 5.0, "speed_kmh": [82.0, 118.0]},
        "R": {"1": 1.5},
        "runs": {"exact": _run(600, 0, 0, [0.0, 0.0]), "ins": _run(560, 0, 40, [0.0026, 0.0017])},
        "load": "3.00 3.00 3.00",
    },
    "load": "3 before, 3 after",
}


def test_every_target_met_is_said_so() -> None:
    met = [ok for _, _, _, ok in targets(RES)]
    assert met == [True, True, True, True, True]
    text = logs_markdown(RES)
    assert "| rosbag-mcap | 500 | 8.0 (4.0) | 20.0 | 120 | 60 | +2 | 3.00 3.00 3.00 |" in text
    assert "missed 0, undecided 40 of 600 (6.7 %)" in logs_summary_markdown(RES)


def test_the_bag_s_floor_is_said_where_measured() -> None:
    """rosbags' own reading of the bag (nothing decoded), measured beside its import, in the table's note and the target."""
    res = copy.deepcopy(RES)
    res["import"]["rows"][0]["rosbags_cpu_s"] = 3.25
    assert "took 3.2 s of CPU, against the whole import's 4.0 s" in logs_markdown(res) and "rosbags' own `messages()`" not in logs_markdown(RES)
    assert targets(res)[0][2] == "8.0 s (4.0 s CPU; rosbags' own `messages()` alone 3.2 s; load 3.00 3.00 3.00)"


def test_the_estimators_share_of_the_replay_is_said_where_measured() -> None:
    """The nodes' estimator steps' time beside the whole replay's, and the time 20x real time allows, once measured."""
    res = copy.deepcopy(RES)
    res["replay"]["estimator_s"] = 0.75 * res["replay"]["log_wall_s"]
    text = logs_markdown(res)
    assert "the nodes' estimator steps took" in text and "(75 %;" in text
    assert f"20× real time needs the whole replay in {res['replay']['drive_s'] / 20:.2f} s" in text
    assert "the nodes' estimator steps took" not in logs_markdown(RES)


def test_a_target_missed_is_said_so() -> None:
    res = copy.deepcopy(RES)
    res["import"]["rows"][0] |= {"import_s": 40.0, "peak_mb": 400.0}  # the bag's row decides, not the CSV's
    res["replay"]["realtime_wall"] = 12.0  # wall time decides, not CPU
    res["calibration"]["runs"]["exact"] |= {"contained": 599, "missed": 1}
    res["calibration"]["runs"]["ins"] |= {"missed": 2}
    assert [ok for _, _, _, ok in targets(res)] == [False, False, False, False, False]
    assert logs_summary_markdown(res).count("| no |") == 5
