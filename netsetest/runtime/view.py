"""The live view (``netsetest view``, ``netsetest run … --view``; extra ``view``): what an observer hears,
as a Rerun stream, shown by the web viewer of the installed package, both served from this machine to whoever
holds the address the view prints (:mod:`netsetest.runtime.view_server`; no internet needed).

It is one more subscribe-only session, like ``watch`` (:mod:`netsetest.runtime.live`): the nodes do no
work for it.  :class:`LiveView` turns each decoded message into Rerun entities, timed by the step
(timeline ``step``) and, when the sampling period is known, by t = k·τs (timeline ``t``):

``nodes/<i>/fault/{lower,upper,true}``    the published fault interval and the true fault (Fig. 7 live)
``nodes/<i>/yaw_rate/{lower,upper,true}`` the same for r
``sets/node<i>``, ``sets/truth``          the published set projected on (β, r) (the ellipse of ρP ∩ the region, or a set
                                          estimator's box) and the true (β, r), at the current step
``graph``                                 the topology: an edge j → i for every message node i used, each
                                          node coloured by its step (contained, missed, late, fault detected);
                                          drawn once a step, with its truth (and at the end)
``verdict``                               how many node-steps' published sets held the truth so far, of those whose
                                          truth was heard, by the collector's rule (roles/judge.py, as ``watch``
                                          shows it; the collector's verdict, with its coverage, is the run's word)
``plant/path``, ``plant/e/{beta,r}``, ``plant/mismatch_ok``   with a plant: the car's path (integrated
                                          from r, β and v_x) and its model mismatch e_k with the flag whether
                                          it stayed in its declared bound

A view that falls behind drops frames: while more than :data:`MAX_BACKLOG` messages wait, messages are
counted (the verdict stays exact) but not drawn, and the verdict says how many were left out.  The run
never waits for it.

Each step goes to the browsers as soon as its truth is drawn (Rerun's batcher would hold it up to 0.2 s): the
view's ``outlet`` (the server's :meth:`~netsetest.runtime.view_server.ViewerServer.send`; by default a flush of
the recording stream).  In a real-time run the view knows when the vehicle published step k (the deadline its
inputs carry, minus τs), so it measures its own lag (:class:`Lag`): the time step k's truth was handed to the
browsers' connections minus that, per drawn step; the verdict shows the last one, and with ``--lag-json PATH``
(the benchmark's) the view writes every one to PATH when it stops.

This module maps messages to Rerun; the server is runtime/view_server.py, the view's process (started beside a
run, its lag handed over) runtime/view_process.py.
"""

from __future__ import annotations

import math
import time
from array import array
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from netsetest.messages import End, Message, NodeInput, NodeState, Truth
from netsetest.polygon import Polygon
from netsetest.runtime.live import LiveTable

MAX_TIMELINE = 2**63 - 1  # Rerun's timelines are 64-bit: a sequence number, a duration in ns
MAX_BACKLOG = 200  # messages waiting: above this the view drops frames (about one step of a 24-node run and its truth ×4)
ELLIPSE_POINTS = 48  # vertices of a drawn (β, r) ellipse
APP_ID = "netsetest"
FLUSH_TIMEOUT_S = 1.0  # a step's truth not encoded for the browsers within this is not waited for (no lag for it)
LAG_PENDING_STEPS = 50  # a step's publish time waits this many steps for its truth to be drawn (and back)
BOUND_RGB = (31, 119, 180)
COLOURS = {  # a node's step in the graph (RGB)
    "contained": (44, 160, 44),
    "missed": (214, 39, 40),
    "undecided": (188, 189, 34),
    "late": (255, 127, 14),
    "fault detected": (148, 103, 189),
    "no truth yet": (127, 127, 127),
}


def ellipse(centre: np.ndarray, shape: np.ndarray, n: int = ELLIPSE_POINTS) -> np.ndarray:
    """(n + 1, 2) points of {x : (x − c)ᵀ shape⁻¹ (x − c) = 1}, closed."""
    w, v = np.linalg.eigh(0.5 * (shape + shape.T))
    a = np.linspace(0.0, 2 * math.pi, n + 1)
    return np.asarray(centre, dtype=float) + ((v * np.sqrt(np.maximum(w, 0.0))) @ np.vstack([np.cos(a), np.sin(a)])).T


def outline(centre: np.ndarray, shape: np.ndarray, region: Polygon | None, n: int = ELLIPSE_POINTS) -> np.ndarray:
    """Closed (m, 2) outline of {x : (x − c)ᵀ shape⁻¹ (x − c) ≤ 1} ∩ ``region`` (the published set's (β, r) part;
    the collector judges this intersection, so the view draws it, not the ellipse alone): the region cut by the
    ellipse's supporting slabs along n/2 directions, an outline holding the set; the ellipse where no region is kept."""
    if region is None:
        return ellipse(centre, shape, n)
    shape = 0.5 * (shape + shape.T)
    for a in np.linspace(0.0, math.pi, n // 2, endpoint=False):
        c = np.array([math.cos(a), math.sin(a)])
        mid, half = float(c @ centre), math.sqrt(max(float(c @ shape @ c), 0.0))  # the ellipse's extent along c
        cut = region.cut(c, mid - half, mid + half)
        if cut is None:  # no common point: a set no node publishes (decode refuses it); draw the ellipse
            return ellipse(centre, shape, n)
        region = cut
    v = region.vertices
    return np.vstack([v, v[:1]])


@dataclass
class Coverage:
    """Node-steps whose state and truth the view heard, and how many of their published sets held the truth."""

    judged: int = 0
    contained: int = 0
    missed: int = 0  # certainly (a point truth outside the set; a recorded drive's reference box disjoint from it)
    dropped_frames: int = 0


@dataclass
class Lag:
    """The view's lag behind a real-time run: per drawn step, when its truth was handed to the browsers'
    connections minus when the vehicle published the step (its inputs' deadline − τs; one machine, one clock).
    Steps whose truth was dropped (the view behind) or not sent within FLUSH_TIMEOUT_S have none."""

    started: dict[int, float] = field(default_factory=dict)  # step → published, until its truth is sent
    sent: dict[int, float] = field(default_factory=dict)  # step → its truth sent, until its publish time is known
    lags_s: array = field(default_factory=lambda: array("d"))  # one per step with both, in the order they completed
    unsent: int = 0  # truths drawn but not encoded for the browsers within FLUSH_TIMEOUT_S

    def started_at(self, step: int, t: float) -> None:
        self.started.setdefault(step, t)
        self._match(step)

    def sent_at(self, step: int, t: float) -> None:
        self.sent[step] = t
        self._match(step)

    def _match(self, step: int) -> None:
        if step in self.started and step in self.sent:
            self.lags_s.append(self.sent.pop(step) - self.started[step])
        for d in (self.started, self.sent):  # bounded memory: a step without its counterpart is given up
            for k in [k for k in d if k < step - LAG_PENDING_STEPS]:
                del d[k]

    def to_dict(self) -> dict:
        """The figures ``--lag-json`` gets (runtime/view_process.py): every lag (s) and the truths not sent in time."""
        return {"lags_s": list(self.lags_s), "unsent": self.unsent}


@dataclass
class LiveView:
    """Rerun entities from observed messages (module doc); ``rec`` is a ``rerun.RecordingStream``; ``outlet(pinned,
    timeout_s)`` hands what has been logged to the viewer now (``pinned``: the layout and styles, kept for every
    browser that connects later), RuntimeError if not within ``timeout_s``: by default a flush of ``rec``."""

    rec: Any
    tau_s: float | None = None
    outlet: Callable[[bool, float], None] | None = None
    table: LiveTable = field(default_factory=lambda: LiveTable(judged=[]))
    coverage: Coverage = field(default_factory=Coverage)
    node_colour: dict[int, tuple[int, int, int]] = field(default_factory=dict)
    edges: set[tuple[int, int]] = field(default_factory=set)
    path: list[tuple[float, float]] = field(default_factory=lambda: [(0.0, 0.0)])
    heading: float = 0.0
    styled: set[int] = field(default_factory=set)
    lag: Lag = field(default_factory=Lag)
    clock: Callable[[], float] = time.time  # wall clock (the inputs' deadlines are the vehicle's time.time())
    layout_due: bool = False  # nodes appeared since the layout was last sent (it goes with the next step's frame)

    def __post_init__(self) -> None:
        self.layout()  # Rerun's first blueprint takes a second or more to encode: here, before the run, not in its first step
        self._send(pinned=True)  # with the recording's start: every browser needs it

    def _send(self, pinned: bool) -> bool:
        """What has been logged, to the viewer now; False when it did not get there within FLUSH_TIMEOUT_S."""
        try:
            (self.outlet or self._flush)(pinned, FLUSH_TIMEOUT_S)
        except RuntimeError:  # Rerun's "flush timed out": the view goes on
            return False
        return True

    def _flush(self, pinned: bool, timeout_s: float) -> None:
        """The default outlet: the recording stream's own sink (a file, in the tests) gets everything now."""
        self.rec.flush(timeout_sec=timeout_s)

    def layout(self) -> None:
        """The viewer's layout for the nodes seen so far (sent again when a node appears): the graph, the
        verdict and the (β, r) sets on the left; per node its fault and its yaw rate against the truth."""
        import rerun.blueprint as rrb

        ids = sorted(self.table.rows)
        per_node = [
            rrb.Grid(*(rrb.TimeSeriesView(origin=f"nodes/{i}/{what}", name=f"node {i} {what}") for i in ids), name=what) for what in ("fault", "yaw_rate")
        ]
        plant = [
            rrb.Vertical(
                rrb.Spatial2DView(origin="plant/path", name="car path"),
                rrb.TimeSeriesView(origin="plant", contents=["plant/e/**", "plant/mismatch_ok"], name="e_k; 1 = in bound"),
                name="plant",
            )
        ]
        left = rrb.Vertical(
            rrb.GraphView(origin="graph", name="topology"),
            rrb.TextDocumentView(origin="verdict", name="verdict"),
            rrb.Spatial2DView(origin="sets", name="(β, r) sets and truth"),
        )
        self.rec.send_blueprint(
            rrb.Blueprint(
                rrb.Horizontal(left, rrb.Tabs(*per_node, *plant), column_shares=[1, 2]),
                rrb.TimePanel(state="collapsed", play_state="following"),  # a stream over HTTP would otherwise play from step 0
                collapse_panels=True,
            )
        )

    def _styles(self, ids: set[int]) -> None:
        """Once per node: the bounds blue, the truth black (as the report's figures draw them)."""
        import rerun as rr

        for i in ids - self.styled:
            for what in ("fault", "yaw_rate"):
                for part, colour in (("lower", BOUND_RGB), ("upper", BOUND_RGB), ("true", (0, 0, 0))):
                    self.rec.log(f"nodes/{i}/{what}/{part}", rr.SeriesLines(colors=[colour], names=[part]), static=True)
        self.styled |= ids

    def feed(self, msg: Message | None, backlog: int = 0) -> None:
        """Take one message; draw it unless ``backlog`` messages wait behind it (then count only)."""
        known = len(self.table.rows)
        self.table.update(msg)
        if isinstance(msg, NodeInput) and msg.deadline is not None and self.tau_s is not None:
            self.lag.started_at(msg.step, msg.deadline - self.tau_s)
        if len(self.table.rows) != known:
            self._styles(set(self.table.rows))
            self.layout_due = True
        judged = self.table.judged or []
        for node, _step, c in judged:  # judged by the collector's rule (LiveTable: Judge.containment)
            self.coverage.judged += 1
            self.coverage.contained += c.contained
            self.coverage.missed += c.missed
            self.node_colour[node] = COLOURS["contained" if c.contained else "missed" if c.missed else "undecided"]
        if judged:
            judged.clear()
        if backlog > MAX_BACKLOG:
            self.coverage.dropped_frames += 1
            return
        step = msg.steps if isinstance(msg, End) else getattr(msg, "step", 0)
        if not self._on_timeline(step):
            return  # no run has such a step: a forged message, counted above, not drawn
        if isinstance(msg, NodeState):
            self._state(msg)
        elif isinstance(msg, Truth):
            self._truth(msg)
        elif isinstance(msg, End):
            self._time(msg.steps)
            self._graph()
            self._verdict(msg.steps, ended=True)

    def _on_timeline(self, step: int) -> bool:
        """Rerun's timelines hold the step and its time (ns) as 64-bit integers (half their range: rounding's margin)."""
        return step <= MAX_TIMELINE // 2 and (self.tau_s is None or step * self.tau_s * 1e9 <= MAX_TIMELINE // 2)

    def _time(self, step: int) -> None:
        self.rec.set_time("step", sequence=step)
        if self.tau_s is not None:
            self.rec.set_time("t", duration=step * self.tau_s)

    def _state(self, m: NodeState) -> None:
        import rerun as rr

        self._time(m.step)
        pub = m.published
        lo, hi = pub.bounds()
        base = f"nodes/{m.node}"
        for name, idx in (("fault", 2), ("yaw_rate", 1)):
            self.rec.log(f"{base}/{name}/lower", rr.Scalars(float(lo[idx])))
            self.rec.log(f"{base}/{name}/upper", rr.Scalars(float(hi[idx])))
        if pub.set is None:  # the SDP's ellipsoid ∩ its region, projected on (β, r)
            pts = outline(pub.centre[:2], pub.rho * pub.P_matrix[:2, :2], pub.polygon)
        else:  # a set estimator's own set: its box in (β, r)
            pts = np.array([[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]], [lo[0], lo[1]]])
        colour = COLOURS["late"] if m.late else COLOURS["fault detected"] if self.table.rows[m.node].fdi == "detected" else None
        if colour is not None:
            self.node_colour[m.node] = colour
        self.rec.log(f"sets/node{m.node}", rr.LineStrips2D([pts], labels=[str(m.node)]))
        self.edges |= {(j, m.node) for j in m.used}

    def _graph(self) -> None:
        """The topology as heard so far, once a step (with the step's truth, and at the end), and the layout if nodes appeared."""
        import rerun as rr

        if self.layout_due:
            self.layout()
            self.layout_due = False
            self._send(pinned=True)  # the layout and the new nodes' styles: kept for every browser that connects later
        ids = sorted(self.table.rows)
        self.rec.log(
            "graph",
            rr.GraphNodes([str(i) for i in ids], labels=[str(i) for i in ids], colors=[self.node_colour.get(i, COLOURS["no truth yet"]) for i in ids]),
            rr.GraphEdges([(str(j), str(i)) for j, i in sorted(self.edges)], graph_type="directed"),
        )

    def _truth(self, t: Truth) -> None:
        import rerun as rr

        self._time(t.step)
        for i, f in t.faults.items():
            self.rec.log(f"nodes/{i}/fault/true", rr.Scalars(float(f)))
            self.rec.log(f"nodes/{i}/yaw_rate/true", rr.Scalars(float(t.x[1])))
        self.rec.log("sets/truth", rr.Points2D([t.x], radii=[0.002], colors=[(0, 0, 0)]))
        if t.e is not None and any(t.e):  # a plant other than the T-S model drives the truth
            self.rec.log("plant/e/beta", rr.Scalars(float(t.e[0])))
            self.rec.log("plant/e/r", rr.Scalars(float(t.e[1])))
            self.rec.log("plant/mismatch_ok", rr.Scalars(float(t.mismatch_ok)))
            if self.tau_s is not None:
                beta, r = float(t.x[0]), float(t.x[1])
                x, y = self.path[-1]
                self.path.append((x + t.vx * math.cos(self.heading + beta) * self.tau_s, y + t.vx * math.sin(self.heading + beta) * self.tau_s))
                self.heading += r * self.tau_s
                self.rec.log("plant/path", rr.LineStrips2D([self.path]))
        self._graph()
        self._verdict(t.step, ended=False)
        if not self._send(pinned=False):  # the step goes to the viewer now, not at the batcher's next tick
            self.lag.unsent += 1
            return
        self.lag.sent_at(t.step, self.clock())

    def _verdict(self, step: int, ended: bool) -> None:
        import rerun as rr

        c = self.coverage
        text = (
            f"## {'run ended after' if ended else 'step'} {step}\n\n"
            f"the published set held the truth on **{c.contained} of {c.judged}** node-steps heard with their truth"
            + (f" — **{c.missed} missed**" if c.missed else "")
            + (f", {c.judged - c.contained - c.missed} undecided (the reference's box overlaps the set)" if c.judged > c.contained + c.missed else "")
            + f"\n\nframes dropped (the view was behind): {c.dropped_frames}"
            + (f"; the view's lag behind the run: {self.lag.lags_s[-1]:.2f} s" if self.lag.lags_s else "")
            + "\n\n"
            "Judged by the collector's rule (the ellipsoid ∩ the region ∩ the fault range), as `watch` shows it; "
            "the run's verdict (coverage, assumptions) is the collector's."
        )
        self.rec.log("verdict", rr.TextDocument(text, media_type=rr.MediaType.MARKDOWN))
