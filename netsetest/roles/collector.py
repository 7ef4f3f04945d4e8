"""The collector role: checks every published ellipsoid against the truth and writes the record.

For node i at step k it computes E_i,k = e_i,kᵀ P_i,k⁻¹ e_i,k with e = x̄_i,k − x̂_i,k and declares
containment when E_i,k ≤ ρ_i.  A miss is attributed by the step's *dependency cone*: the estimate of
(i, k) relies on its own sector condition and noise bound at k, the disturbance bound at k−1, and on
every (j, k−1) with j ∈ N_i ∪ {i}; step 0 relies on the initial ellipsoid containing x̄_0
(Assumption 1).  A miss inside an intact cone is an estimator failure (``violations``); a miss after a
broken assumption is reported separately (``misses_assumption_broken``).  A saturating node's sector
premise is what its published sector rests on (``sector_basis``): the noise bound only, the declared
fault bound, or — for an assumed sector — the sector itself checked against the truth's C̄ x̄.  A derived
sector that misses the truth inside an intact cone is counted as a ``sector_failure`` (an estimator bug).
"""

from __future__ import annotations

import statistics
from collections import Counter

import numpy as np

from netsetest.bus import keys
from netsetest.bus.base import Bus
from netsetest.config.schema import NodeConfig, Scenario
from netsetest.estimator.sector import Sector, sector_ok
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

    def _published_sector(self, n: NodeConfig, k: int) -> Sector | None:
        st = self.states[n.id].get(k)
        if st is None or st.sector is None:
            return None
        return Sector(st.sector[0], st.sector[1], st.sector_basis)

    def _sector_premise(self, n: NodeConfig, k: int, tr: Truth) -> bool:
        """What the node's step-k sector rests on held: nothing more than the noise bound (measurement),
        the declared fault bound (fault-bound), or the sector itself against the truth (assumed)."""
        s = str(n.id)
        st = self.states[n.id].get(k)
        if not n.sensor.saturated:
            return True
        if st is None:
            return tr.sector_ok[s]
        if st.sector_basis == "assumed":
            return sector_ok(n.sensor, self._published_sector(n, k), tr.r[s])
        if st.sector_basis == "fault-bound":
            return tr.fault_ok[s]
        return True

    def _sector_failures(self, n: NodeConfig, cones: dict[tuple[int, int], bool]) -> int:
        """Steps whose derived sector misses the truth's r although its premises held: an estimator bug."""
        out = 0
        for k, st in self.states[n.id].items():
            tr = self.truth.get(k)
            if tr is None or not n.sensor.saturated or st.sector_basis in ("none", "assumed") or not cones.get((n.id, k), True):
                continue
            out += not sector_ok(n.sensor, self._published_sector(n, k), tr.r[str(n.id)])
        return out

    def _cones(self) -> dict[tuple[int, int], bool]:
        ok: dict[tuple[int, int], bool] = {}
        for k in sorted(self.truth):
            tr = self.truth[k]
            for n in self.sc.nodes:
                i, s = n.id, str(n.id)
                own = tr.noise_ok[s] and self._sector_premise(n, k, tr)
                if k == 0:
                    e = np.r_[tr.x, tr.faults[s]] - n.x0_hat  # Assumption 1: x̄_0 in the prior ellipsoid
                    own = own and float(e @ np.linalg.solve(n.P0, e)) <= n.rho
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
            reported = sorted(self.states[i])
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
                        "sector": list(st.sector) if st.sector is not None else None, "sector_basis": st.sector_basis,
                    }
                )  # fmt: skip
            gone = [k for k in range(last + 1) if k not in self.states[i]]
            node_rows.append(
                {
                    "id": i,
                    "max_E": max(E_all) if E_all else None,
                    "violations": misses,
                    "misses_assumption_broken": broken_misses,
                    "assumption_violations": sum(1 for k in range(last + 1) if not cones.get((i, k), True)),
                    "guaranteed_steps": sum(1 for k in reported if cones.get((i, k), True)),
                    "sector_failures": self._sector_failures(n, cones),
                    "sectors_assumed": sum(1 for st in self.states[i].values() if st.sector_basis == "assumed"),
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
            **{k: meta[k] for k in ("mode", "variant", "objective", "case", "signals", "steps", "seed", "clock") if k in meta},
            "violations_total": sum(r["violations"] for r in node_rows),
            "misses_assumption_broken_total": sum(r["misses_assumption_broken"] for r in node_rows),
            "guaranteed_steps_total": sum(r["guaranteed_steps"] for r in node_rows),
            "node_steps_total": sum(r["steps_reported"] for r in node_rows),
            "sector_failures_total": sum(r["sector_failures"] for r in node_rows),
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
