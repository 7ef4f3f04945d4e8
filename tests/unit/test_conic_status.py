"""The clarabel backend's status map (netsetest/estimator/conic/solver.py) names every status Clarabel has, and
maps back exactly the answers cvxpy's Clarabel interface calls optimal or optimal_inaccurate."""

from __future__ import annotations

import clarabel

from netsetest.estimator.conic.solver import STATUS_MAP


def test_status_map_names_every_clarabel_status() -> None:
    statuses = {getattr(clarabel.SolverStatus, n) for n in dir(clarabel.SolverStatus) if not n.startswith("_")}
    assert set(STATUS_MAP) == statuses  # a new status in a Clarabel release must be placed here
    assert {s for s, answer in STATUS_MAP.items() if answer} == {clarabel.SolverStatus.Solved, clarabel.SolverStatus.AlmostSolved}
