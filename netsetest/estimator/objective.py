"""What each node's SDP minimises (no heavy imports: the CLI reads the choices from here).

``trace``: trace(P), the paper's objective (reproduces its numbers).  ``fault``: trace(D P) with
D = diag(1, 1, FAULT_WEIGHT): aimed at the fault bound users inspect, the state as a secondary term.
``bank``: the node recurs on the trace-optimal set (a good state set for the next step) and weights the fault by
BANK_FAULT_WEIGHT in what it reshapes for publishing (the size and readings' cuts).  Until issue
45 it also solved each step a second time for the trace(diag(1, 1, BANK_FAULT_WEIGHT)·P) set and published that
ellipsoid; with the region in the published set that bought nothing on any coordinate against the exact limit.
Measured in docs/estimator.md ("Objectives").
"""

from __future__ import annotations

from typing import Literal

Objective = Literal["trace", "fault", "bank"]
OBJECTIVES: tuple[Objective, ...] = ("trace", "fault", "bank")
DEFAULT_OBJECTIVE: Objective = "bank"
FAULT_WEIGHT = 10.0  # measured best single weight (1.26× exact on paper NSNIM; 100 gives 1.32×)
BANK_FAULT_WEIGHT = 30.0  # ``bank``'s weight of f in the cuts (its second solve's, until issue 45: 1.121× exact; 10: 1.139×, 100: 1.117×)
OBJECTIVE_HELP = (
    f"what each node's SDP minimises: trace = the paper's trace(P); fault = trace(diag(1, 1, {FAULT_WEIGHT:g})·P); "
    f"bank = the trace set, with the fault weighted by {BANK_FAULT_WEIGHT:g} in the cuts that reshape what is published"
)
