"""The collector role: checks every published ellipsoid against the truth and writes the record.

For node i at step k it computes E_i,k = e_i,kᵀ P_i,k⁻¹ e_i,k with e = x̄_i,k − x̂_i,k and declares
containment when E_i,k ≤ ρ_i.  A miss is attributed by the step's *dependency cone*: the estimate of
(i, k) relies on its own sector condition and noise bound at k, the disturbance bound at k−1, and on
every (j, k−1) with j ∈ N_i ∪ {i}; step 0 relies on the initial ellipsoid containing x̄_0
(Assumption 1).  A miss inside an intact cone is an estimator failure (``violations``); a miss after a
broken assumption is reported separately (``misses_assumption_broken``).
"""

from __future__ import annotations

import statistics
from collections import Counter

import numpy as np

from netsetest.bus import keys
from netsetest.bus.base import Bus
from netsetest.config.schema import Scenario
from netsetest.messages import End, Message, NodeState, Truth


class Collector:
    def __init__(self, scenario: Scenario, bus: Bus, run_id: str) -> None:
        self.sc, self.bus, self.run = scenario, bus, run_id
        self.truth: dict[int, Truth] = {}
        self.states: dict[int, dict[int, NodeState]] = {i: {} for i in scenario.ids}
        self.evaluated: dict[tuple[int, int], tuple[float, bool]] = {}
        self.ended: End | None = None
        bus.subscribe(keys.truth(run_id), self.on_message)
        bus.subscribe(keys.node_state(run_id, "*"), self.on_message)
        bus.subscribe(keys.end(run_id), self.on_message)

    def on_message(self, key: str, msg: Message) -> None:
        if isinstance(msg, Truth):
            self.truth[msg.step] = msg
            for i in self.sc.ids:
                self._evaluate(i, msg.step)
        elif isinstance(msg, NodeState):
            if msg.node not in self.states or key != keys.node_state(self.run, msg.node):
                self.bus.drop("unknown-node")
                return
            self.states[msg.node][msg.step] = msg
            self._evaluate(msg.node, msg.step)
        elif isinstance(msg, End):
            self.ended = msg

    def _evaluate(self, i: int, k: int) -> None:
        st, tr = self.states[i].get(k), self.truth.get(k)
        if st is None or tr is None or (i, k) in self.evaluated:
            return
        xbar = np.r_[tr.x, tr.faults[str(i)]]
        e = xbar - np.asarray(st.xhat)
        E = float(e @ np.linalg.solve(st.P_matrix(), e))
        self.evaluated[(i, k)] = (E, E <= st.rho)

    @property
    def progress(self) -> int:
        """Last step for which every alive node's ellipsoid has been checked."""
        k = max(self.truth, default=-1)
        while k >= 0:
            alive = set(self.truth[k].alive) if k > 0 else set(self.sc.ids)
            if all((i, k) in self.evaluated for i in alive):
                return k
            k -= 1
        return -1

    # ------------------------------------------------------------------ attribution and summary

    def _cones(self) -> dict[tuple[int, int], bool]:
        ok: dict[tuple[int, int], bool] = {}
        for k in sorted(self.truth):
            tr = self.truth[k]
            for n in self.sc.nodes:
                i, s = n.id, str(n.id)
                own = tr.sector_ok[s] and tr.noise_ok[s]
                if k == 0:
                    ev = self.evaluated.get((i, 0))
                    own = own and (ev is None or ev[1])  # Assumption 1: x̄_0 in the initial ellipsoid
                else:
                    prev = self.truth.get(k - 1)
                    own = own and prev is not None and prev.dist_ok
                    deps = set(n.in_weights) | {i}
                    own = own and all(ok.get((j, k - 1), True) for j in deps)
                ok[(i, k)] = bool(own)
        return ok

    def finish(self, meta: dict, deadline_misses: dict[int, int] | None = None) -> tuple[dict, dict]:
        """Return (summary, record document parts) once the run is over."""
        cones = self._cones()
        last = max(self.truth, default=-1)
        node_rows, record_nodes = [], {}
        losses: Counter[str] = Counter()
        for k, tr in self.truth.items():
            for j, i in tr.lost:
                losses[f"{j}->{i}"] += 1
        for n in self.sc.nodes:
            i = n.id
            entries, E_all, misses, broken_misses, solve, fallbacks, widths = [], [], 0, 0, [], 0, []
            late = missing_msgs = dropped = 0
            for k in sorted(self.states[i]):
                st = self.states[i][k]
                ev = self.evaluated.get((i, k))
                cone = cones.get((i, k), True)
                E, contained = (ev if ev is not None else (None, True))
                if E is not None:
                    E_all.append(E)
                    if not contained:
                        if cone:
                            misses += 1
                        else:
                            broken_misses += 1
                if st.status in ("ok", "fallback") and k > 0:
                    solve.append(st.solve_ms)
                fallbacks += st.status == "fallback"
                late += st.late
                missing_msgs += len(st.missing)
                dropped = max(dropped, st.dropped)
                P = st.P_matrix()
                widths.append(2.0 * np.sqrt(st.rho * P[2, 2]))
                entries.append(
                    {
                        "step": k, "xhat": list(st.xhat), "P": list(st.P), "rho": st.rho, "status": st.status,
                        "rho_cert": st.rho_cert, "solve_ms": st.solve_ms, "used": st.used, "missing": st.missing,
                        "late": st.late, "E": E, "contained": bool(contained), "assumptions_ok": bool(cone),
                    }
                )  # fmt: skip
            reported = sorted(self.states[i])
            gone = [k for k in range(last + 1) if k not in self.states[i]]
            node_rows.append(
                {
                    "id": i,
                    "max_E": max(E_all) if E_all else None,
                    "violations": misses,
                    "misses_assumption_broken": broken_misses,
                    "assumption_violations": sum(1 for k in range(last + 1) if not cones.get((i, k), True)),
                    "sector_breaks": sum(1 for t in self.truth.values() if not t.sector_ok[str(i)]),
                    "first_sector_break": min((k for k, t in self.truth.items() if not t.sector_ok[str(i)]), default=None),
                    "fault_bound_mean_width": float(np.mean(widths)) if widths else None,
                    "solve_ms_median": statistics.median(solve) if solve else None,
                    "fallbacks": fallbacks,
                    "steps_reported": len(reported),
                    "missing_steps": len(gone),
                    "missing_from": gone[0] if gone else None,
                    "neighbour_messages_missing": missing_msgs,
                    "dropped_messages": dropped,
                    "deadline_misses": (deadline_misses or {}).get(i, late),
                }
            )
            record_nodes[str(i)] = entries
        summary = {
            **{k: meta[k] for k in ("mode", "variant", "case", "signals", "steps", "seed", "clock") if k in meta},
            "violations_total": sum(r["violations"] for r in node_rows),
            "misses_assumption_broken_total": sum(r["misses_assumption_broken"] for r in node_rows),
            "steps_completed": last,
            "nodes_missing": [r["id"] for r in node_rows if r["missing_steps"]],
            "losses": dict(sorted(losses.items())),
            "losses_total": sum(losses.values()),
            "dropped_messages": dict(self.bus.dropped),  # by the collector; per node in nodes[*]
            "nodes": node_rows,
        }
        truth = [self._truth_entry(self.truth[k]) for k in sorted(self.truth)]
        return summary, {"truth": truth, "nodes": record_nodes}

    @staticmethod
    def _truth_entry(t: Truth) -> dict:
        d = t.model_dump(mode="json")
        for f in ("v", "type"):
            d.pop(f, None)
        return d
