"""The k-of-N health assumption on one step's readings (``[network] max_faulty = m``, or per group of
sensors ``[[network.health_groups]]``; docs/network.md).  N and m below are the node's group's.

Every sensor j measures the same combination of the state, C_j = s_j uᵀ (checked when the topology is
loaded), so a healthy sensor's reading (fault 0) bounds t = uᵀx to an interval I_j.  At most m of the N
sensors are faulty at a step, so the truth's t lies in the intersection of the intervals of some N − m
sensors: equivalently, in at least N − m of the N intervals.  :func:`healthy_interval` returns the hull
of that set (a union of intervals, found by one sweep over the endpoints instead of the C(N, m)
hypotheses).  A sensor whose reading did not arrive has the interval (−∞, ∞): it may be the faulty one
or not, which is always sound.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from netsetest.estimator.sector import Interval
from netsetest.models.sensor import Sensor

if TYPE_CHECKING:
    from netsetest.config.schema import HealthGroup, Scenario

Span = tuple[float, float]
HEALTH_KEY = 0  # the k-of-N interval among a step's readings (node ids start at 1)


def healthy_interval(spans: Sequence[Span], need: int) -> Span | None:
    """The hull of {t : t lies in at least ``need`` of the closed intervals ``spans``}; None if no t does
    (the assumption broke).  Endpoints may be ±inf."""
    if need <= 0:
        return (-math.inf, math.inf)
    # opening events sort before closing ones at the same point: closed intervals that touch do overlap
    events = sorted([(lo, 0) for lo, _ in spans] + [(hi, 1) for _, hi in spans])
    count, lo_hull, hi_hull = 0, None, None
    for t, kind in events:
        if kind == 0:
            count += 1
            if count >= need and lo_hull is None:
                lo_hull = t
        else:
            if count >= need:
                hi_hull = t  # the last point where the count still reaches ``need``
            count -= 1
    if lo_hull is None or hi_hull is None:
        return None
    return (lo_hull, hi_hull)


@dataclass(frozen=True)
class Others:
    """What the other sensors' readings of one step prove if the node's own sensor is faulty: then the N − m healthy
    ones are among them, so t = uᵀx lies in at least ``need`` of their ``spans``."""

    u: np.ndarray  # (2,) the direction every sensor measures
    spans: tuple[Span, ...]  # per other sensor, its reading's interval of t as if healthy; (−∞, ∞) if not here
    need: int

    def agree(self, within: Span | None) -> Span | None:
        """The hull of the t in ``within`` that at least ``need`` of the spans hold; None if no t does (then the own
        sensor is healthy in every hypothesis the readings leave)."""
        return healthy_interval(_present(_clipped(list(self.spans), within)), self.need)


@dataclass(frozen=True)
class HealthAssessment:
    """One step under k-of-N: uᵀx's interval (None: unbounded or empty), whether the own fault is pinned (|f| ≤ τ in
    every consistent hypothesis), and what the other sensors' readings prove where the own sensor is faulty."""

    interval: Interval | None
    pinned: bool
    others: Others


@dataclass(frozen=True)
class HealthModel:
    """What a node needs for the k-of-N interval: every sensor, how many must be healthy (N − m), the
    tolerance below which a fault counts as none, and the direction u every sensor measures."""

    sensors: dict[int, Sensor]
    need: int
    tolerance: float
    u: np.ndarray  # (2,) unit vector: C_j = s_j uᵀ for every sensor (checked when the topology is loaded)

    @classmethod
    def of(cls, scenario: Scenario, node_id: int) -> HealthModel | None:
        """Node ``node_id``'s model: its k-of-N group's; None when it is in none (or the readings are off)."""
        group = scenario.health_group(node_id)
        return None if group is None else cls.of_group(scenario, group)

    @classmethod
    def of_group(cls, scenario: Scenario, group: HealthGroup) -> HealthModel | None:
        """The model of one group over the scenario's nodes (a subset of the topology's: at least
        |S| − m of the group's sensors in S are healthy wherever at least N − m of its N are); None if no
        sensor of the group is among them."""
        sensors = {n.id: n.sensor for n in scenario.nodes if n.id in group.nodes}
        if not sensors:
            return None
        return cls(sensors, len(sensors) - group.max_faulty, scenario.fault_tolerance, next(iter(sensors.values())).direction)

    def assess(
        self,
        own: int,
        measured: Mapping[int, tuple[float, float]],
        within: Span | None = None,
        pin: bool = False,
    ) -> HealthAssessment:
        """The step's assessment: the interval, whether the own fault is pinned, the other sensors' spans.

        ``measured``: each reading's measurement interval of C̄_j x̄_j (outward: Sensor.measured_interval), keyed by its
        sensor's id, the node's own (``own``) among them; a sensor of the group without one did not send a reading.
        The interval: uᵀx lies in it wherever at most m sensors are faulty and the readings' noise bounds
        held; None if it is unbounded or empty (an assumption broke: nothing is used).  ``within``: an
        interval known to hold uᵀx (the node's own prediction): hypotheses that agree only outside it are no
        hypotheses (this is what makes the assumption bite: faulty sensors that agree with each other usually
        do so far from the truth).  ``pin``: also tell whether the node's own sensor is healthy (|f| ≤ τ) in
        every consistent hypothesis: the others' readings alone cannot supply N − m agreeing sensors (inside
        ``within``), while with its own they can."""
        every = self._spans(measured)
        others = Others(self.u, tuple(sp for j, sp in zip(self.sensors, every) if j != own), self.need)
        hull = healthy_interval(_present(_clipped(every, within)), self.need)
        pinned = pin and hull is not None and others.agree(within) is None
        if hull is None or not (math.isfinite(hull[0]) and math.isfinite(hull[1])) or hull[1] <= hull[0]:
            return HealthAssessment(None, pinned, others)
        return HealthAssessment(Interval(*hull), pinned, others)

    def _spans(self, measured: Mapping[int, tuple[float, float]]) -> list[Span]:
        """Per sensor (in ``sensors`` order), the interval of uᵀx its reading gives if it is healthy: |f_j| ≤ τ,
        so C_j x lies within |Ds_j| τ of its measurement interval of C̄_j x̄_j; (−∞, ∞) if it did not arrive."""
        spans: list[Span] = []
        for j, sensor in self.sensors.items():
            iv = measured.get(j)
            if iv is None:  # not here: it may be healthy with any value
                spans.append((-math.inf, math.inf))
                continue
            slack = abs(sensor.Ds) * self.tolerance
            s = float(sensor.C @ self.u)  # C_j x = s_j uᵀx
            a, b = (iv[0] - slack) / s, (iv[1] + slack) / s
            spans.append((min(a, b), max(a, b)))
        return spans


def _clipped(spans: list[Span], within: Span | None) -> list[Span | None]:
    """Each span ∩ ``within``, in order; None where it misses it (it contains no admissible t)."""
    out: list[Span | None] = []
    for lo, hi in spans:
        a, b = (lo, hi) if within is None else (max(lo, within[0]), min(hi, within[1]))
        out.append((a, b) if a <= b else None)
    return out


def _present(spans: list[Span | None]) -> list[Span]:
    """The non-empty spans: an empty one counts for no t (a sensor that must then be a faulty one)."""
    return [sp for sp in spans if sp is not None]


__all__ = ["HEALTH_KEY", "HealthAssessment", "HealthModel", "Others", "Span", "healthy_interval"]
