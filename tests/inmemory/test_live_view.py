"""The live view's stream (runtime/view.py): fed the messages of an in-memory run (the same the collector
sees), it writes Rerun's stream to a file, which a client reads back and decodes: every node's published
intervals and the truth per step, the graph's nodes and edges, the coverage, and frames dropped when
behind.  The viewer in a browser during a Zenoh run: tests/process/test_browser.py."""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path

import msgspec
import numpy as np
import pytest

from netsetest.bus.base import MemoryBus
from netsetest.messages import NodeInput, Truth
from netsetest.polygon import MARGIN, Polygon
from netsetest.config.schema import load_topology
from netsetest.records.record import record_from_parts
from netsetest.runtime.inmemory import run_inmemory
from netsetest.runtime.live import observed_key
from netsetest.runtime.view import APP_ID, ELLIPSE_POINTS, LAG_PENDING_STEPS, MAX_BACKLOG, Lag, LiveView

rr = pytest.importorskip("rerun")
from rerun.chunk import RrdReader  # noqa: E402  # after the skip: the extra may be missing

ROOT = Path(__file__).resolve().parents[2]
STEPS = 12
TAU_S = 0.1  # paper6's


def _decode(path: Path) -> dict[str, dict[int, dict]]:
    """Entity → step → {column: value} of every timed row in the stream file."""
    out: dict[str, dict[int, dict]] = defaultdict(dict)
    for chunk in RrdReader(path).stream():
        if chunk.is_static:
            continue
        batch = chunk.to_record_batch().to_pydict()
        if "step" not in batch:
            continue
        for n, k in enumerate(batch["step"]):
            out[str(chunk.entity_path)][k] = {c: v[n] for c, v in batch.items() if ":" in c}
    return out


def _run(tmp_path: Path, backlog_from: int | None = None) -> tuple[LiveView, dict, object]:
    rec = rr.RecordingStream(APP_ID)
    rec.save(tmp_path / "view.rrd")
    view = LiveView(rec, tau_s=0.1)
    bus = MemoryBus()

    def feed(key: str, msg: object) -> None:  # from step ``backlog_from`` on, as if the view were far behind
        behind = backlog_from is not None and getattr(msg, "step", -1) >= backlog_from
        view.feed(msg, MAX_BACKLOG + 1 if behind else 0)  # type: ignore[arg-type]  # a decoded message

    bus.subscribe(observed_key("mem", None), feed)
    res = run_inmemory(load_topology(ROOT / "topologies" / "paper6.toml", steps=STEPS), bus=bus)
    rec.flush()
    rec.disconnect()
    return view, _decode(tmp_path / "view.rrd"), res


def test_the_stream_decodes_to_every_nodes_intervals_truth_graph_and_verdict(tmp_path: Path) -> None:
    view, ents, res = _run(tmp_path)
    record = record_from_parts(res.meta, res.parts["truth"], res.parts["nodes"], res.summary)
    for i, track in record.nodes.items():
        for comp, name in ((2, "fault"), (1, "yaw_rate")):
            lo, hi = track.bounds(comp)
            for n, k in enumerate(track.steps):
                assert ents[f"/nodes/{i}/{name}/lower"][int(k)]["Scalars:scalars"] == pytest.approx([lo[n]], abs=1e-12)
                assert ents[f"/nodes/{i}/{name}/upper"][int(k)]["Scalars:scalars"] == pytest.approx([hi[n]], abs=1e-12)
        for t in record.truth:
            assert ents[f"/nodes/{i}/fault/true"][t["step"]]["Scalars:scalars"] == pytest.approx([t["faults"][i]])
            assert ents[f"/nodes/{i}/yaw_rate/true"][t["step"]]["Scalars:scalars"] == pytest.approx([t["x"][1]])
        ring = np.asarray(ents[f"/sets/node{i}"][STEPS]["LineStrips2D:strips"][0])
        assert len(ring) > 4 and np.allclose(ring[0], ring[-1])  # a closed outline
        # the ellipse ∩ the region the collector judged, not the ellipse alone: it holds the truth and lies within
        # the published set's (β, r) bounds (the region's are tighter than the ellipse's on paper6: the ellipse alone
        # overshoots them by about 1e-2), up to the outward margins of the outline's cuts (one per half-plane)
        assert Polygon(ring[:-1]).contains(np.asarray(record.truth[-1]["x"][:2]))
        pad = ELLIPSE_POINTS * 2 * MARGIN
        for comp in (0, 1):
            lo, hi = track.bounds(comp)
            assert lo[-1] - pad <= ring[:, comp].min() and ring[:, comp].max() <= hi[-1] + pad, (i, comp)
    assert ents["/sets/truth"][STEPS]["Points2D:positions"][0] == pytest.approx(record.truth[-1]["x"])
    graph = ents["/graph"][STEPS]
    assert sorted(graph["GraphNodes:node_ids"]) == [str(i) for i in sorted(record.nodes)]
    in_weights = res.meta.in_weights
    expected = {(str(j), str(i)) for i, row in in_weights.items() for j in row if j != i}
    assert {(e["first"], e["second"]) for e in graph["GraphEdges:edges"]} == expected  # lockstep, no loss: every message used
    # the coverage counts what the collector counted (every node-step judged, all inside here)
    assert view.coverage.judged == res.summary.node_steps_evaluated and view.coverage.contained == res.summary.node_steps_contained
    text = ents["/verdict"][STEPS]["TextDocument:text"]
    assert f"{res.summary.node_steps_contained} of {res.summary.node_steps_evaluated}" in str(text)


def test_a_view_behind_drops_frames_but_keeps_counting(tmp_path: Path) -> None:
    view, ents, res = _run(tmp_path, backlog_from=6)
    assert max(ents["/nodes/1/fault/lower"]) == 5  # nothing drawn from step 6 on
    assert view.coverage.dropped_frames > 0
    assert view.coverage.judged == res.summary.node_steps_evaluated  # the verdict still counts every node-step


PUBLISHED_AT = 1000.0  # the fake wall clock of step 0's publication
LAG_S = 0.03  # how long after its publication each step's truth leaves the view, on that clock


def test_the_view_measures_its_lag_behind_a_real_time_run(tmp_path: Path) -> None:
    """Inputs carrying the deadlines of a real-time run (step k published at PUBLISHED_AT + k·τs) and a clock
    that reads LAG_S later whenever the view sends a truth: one lag per step, each LAG_S, shown in the verdict."""
    rec = rr.RecordingStream(APP_ID)
    rec.save(tmp_path / "view.rrd")
    view = LiveView(rec, tau_s=TAU_S)
    now = [0.0]
    view.clock = lambda: now[0]

    def feed(key: str, msg: object) -> None:
        if isinstance(msg, NodeInput):
            msg = msgspec.structs.replace(msg, deadline=PUBLISHED_AT + (msg.step + 1) * TAU_S)
        if isinstance(msg, Truth):
            now[0] = PUBLISHED_AT + msg.step * TAU_S + LAG_S
        view.feed(msg, 0)  # type: ignore[arg-type]  # a decoded message

    bus = MemoryBus()
    bus.subscribe(observed_key("mem", None), feed)
    run_inmemory(load_topology(ROOT / "topologies" / "paper6.toml", steps=STEPS), bus=bus)
    rec.flush()
    rec.disconnect()
    assert list(view.lag.lags_s) == pytest.approx([LAG_S] * (STEPS + 1), abs=1e-9)
    assert view.lag.unsent == 0 and view.lag.sent == {}
    assert f"lag behind the run: {LAG_S:.2f} s" in str(_decode(tmp_path / "view.rrd")["/verdict"][STEPS]["TextDocument:text"])


def test_lag_waits_for_both_ends_and_gives_up_old_steps() -> None:
    lag = Lag()
    lag.sent_at(3, 10.5)  # the truth can be drawn before the step's input is heard
    assert list(lag.lags_s) == []
    lag.started_at(3, 10.0)
    assert list(lag.lags_s) == [0.5]
    for k in range(4, 4 + 3 * LAG_PENDING_STEPS):  # a lockstep run, or inputs the view never heard: no lag, bounded memory
        lag.sent_at(k, float(k))
    assert list(lag.lags_s) == [0.5] and len(lag.sent) <= LAG_PENDING_STEPS + 1
