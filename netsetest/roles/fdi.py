"""Guaranteed fault detection and isolation from a published set (docs/fdi.md).

A node-step's status follows from the published fault interval [lo, hi] alone, with the declared
tolerance τ ≥ 0 (``[network] fault_tolerance``: a fault with |f| ≤ τ counts as no fault):

- ``detected``: the interval excludes [−τ, τ]. Wherever the step's assumptions held the truth is in the set,
  so the sensor has a real fault: a detection on a healthy sensor is a containment miss;
- ``healthy``: the interval lies inside [−τ, τ]: the sensor is proved fault-free at that step;
- ``undecided``: neither.
"""

from __future__ import annotations

from dataclasses import dataclass

from netsetest.records.record import FdiStatus  # the statuses, spelled once (the record checks them on load)


def classify(lo: float, hi: float, tolerance: float = 0.0) -> FdiStatus:
    """The status of a fault interval [lo, hi] (module doc)."""
    if lo > tolerance or hi < -tolerance:
        return "detected"
    if lo >= -tolerance and hi <= tolerance:
        return "healthy"
    return "undecided"


@dataclass
class FdiTotals:
    """One node's detection figures over a run (steps are node-steps judged against the truth)."""

    fault_onset: int | None = None  # first step whose true |f| exceeds the tolerance
    first_detection: int | None = None  # first detected step (a false detection included)
    first_true_detection: int | None = None  # first detected step with a real fault
    detected_steps: int = 0
    healthy_steps: int = 0
    false_detections: int = 0  # detected while the true |f| ≤ tolerance
    false_detections_covered: int = 0  # of them, where every assumption held (each is also a violation)

    def truth(self, k: int, true_fault: float, tolerance: float) -> None:
        """Step k's true fault (called for every step whose truth is known, reported or not)."""
        if self.fault_onset is None and abs(true_fault) > tolerance:
            self.fault_onset = k

    def add(self, k: int, status: FdiStatus, true_fault: float, tolerance: float, covered: bool) -> None:
        """Judged node-step k's status (never a contested or truth-unknown one: a forged copy of a node's
        state must not count as its detection)."""
        faulty = abs(true_fault) > tolerance
        if status == "detected":
            self.detected_steps += 1
            if self.first_detection is None:
                self.first_detection = k
            if faulty and self.first_true_detection is None:
                self.first_true_detection = k
            if not faulty:
                self.false_detections += 1
                self.false_detections_covered += covered
        elif status == "healthy":
            self.healthy_steps += 1

    @property
    def detection_delay(self) -> int | None:
        """Steps from the true fault's onset to its first detection (None: no fault, or never detected)."""
        if self.fault_onset is None or self.first_true_detection is None:
            return None
        return self.first_true_detection - self.fault_onset


__all__ = ["FdiStatus", "FdiTotals", "classify"]
