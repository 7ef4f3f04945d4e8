"""The performance part's figures (bench/results.json: ``netsetest bench --only performance``) as typed data.

Field names are the JSON's keys; a figure a run did not measure is None (older files lack some).  The run
builds its figures as a dict and writes them (netsetest_bench/run.py); every renderer reads them through
:func:`load`, once.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from netsetest_bench.render import FiguresError, typed


@dataclass(frozen=True)
class Config:
    """What the run was configured to do (run.QUICK / run.FULL; the report names a few)."""

    flood_rate: int | None = None  # msg/s of the flood at node 2


@dataclass(frozen=True)
class Meta:
    quick: bool
    date: str
    cpus: int
    python: str
    load_before: str
    duration_s: float
    config: Config = field(default_factory=Config)
    load_after: str | None = None
    machine: str = ""
    only: str | None = None  # the part a run measured alone (None: the whole benchmark)


@dataclass(frozen=True)
class Stat:
    """Times of one kind over node-steps [ms]."""

    median: float | None
    p95: float | None = None
    n: int = 0
    mean: float | None = None


@dataclass(frozen=True)
class Yardstick(Stat):
    """A reference formulation on the same steps: its times, how many times slower, its fault width against the fast path's."""

    ratio: float = 0.0
    width_rel_diff_min: float | None = None
    width_rel_diff_max: float | None = None
    fast_median_same_steps: float | None = None  # the fast path's median on the same node-steps (the ratio's denominator)
    uncertified: int = 0  # node-steps the yardstick's answer failed the certificate


@dataclass(frozen=True)
class RunCheck:
    """The captured run's verdict beside its times."""

    violations_total: int
    fallbacks: int
    fault_bound_mean_width: list[float | None]


YARDSTICKS = ("prev", "straightforward", "naive")  # the reference formulations, in the report's order


@dataclass(frozen=True)
class PaperCase:
    """One case/variant of the paper scenario, per node-step."""

    fast_ms: Stat
    fast_solve_ms: Stat
    fast_cpu_ms: Stat
    iterations_median: float | None
    fallbacks: int
    prev: Yardstick | None = None
    straightforward: Yardstick | None = None
    naive: Yardstick | None = None
    variant: str = ""
    case: str = ""
    node_steps: int = 0
    iterations_max: float | None = None
    in_run_fast_ms: Stat | None = None  # the same steps as the run timed them
    degree_of_nodes: dict[int, int] = field(default_factory=dict)
    run_summary: RunCheck | None = None

    def yardsticks(self) -> list[tuple[str, Yardstick]]:
        return [(name, y) for name in YARDSTICKS if (y := getattr(self, name)) is not None]


@dataclass(frozen=True)
class Coordinates:
    f: float | None
    r: float | None
    beta: float | None


@dataclass(frozen=True)
class Tightness:
    """Published width over the exact limit's, one case."""

    fault_bounds: str
    width_ratio: Coordinates
    rms_radius_rel: Coordinates
    narrower: int
    intervals: int
    exact_s: float | None
    steps: int
    bounded_nodes: list[int] = field(default_factory=list)
    fault_width_ratio_by_node: dict[int, float | None] = field(default_factory=dict)


@dataclass(frozen=True)
class ScalingRow:
    nodes: int
    ms_per_node_step: float | None
    estimator_ms_median: float | None = None
    estimator_ms_median_by_degree: dict[int, float] = field(default_factory=dict)
    node_steps: int = 0
    estimator_ms_mean: float | None = None
    fallbacks: int = 0
    violations: int = 0


@dataclass(frozen=True)
class Scaling:
    rows: list[ScalingRow]
    spread_vs_smallest: list[float]


@dataclass(frozen=True)
class CpuFloor:
    """Why the lockstep ratio is what it is: the CPU one step costs in the run's processes."""

    steps: int
    zenoh_cpu_ms_per_step: float
    cpu_ms_per_step_by_role: dict[str, tuple[float, int]]  # role → (ms per step, processes)
    inmemory_ms_per_step: float
    zenoh_stepping_ms_per_step: float
    cores: int
    ratio_floor: float


@dataclass(frozen=True)
class EndToEnd:
    zenoh_s: float | None
    inmemory_s: float | None
    ratio: float | None
    zenoh_exit: int | None = None
    inmemory_exit: int | None = None


@dataclass(frozen=True)
class Zenoh:
    zenoh_stepping_s: list[float | None]  # None: a run whose stepping was not timed
    inmemory_s: list[float]
    ratio: float | None
    zenoh_startup_s: float | None
    cli_end_to_end: EndToEnd
    node_peak_rss_mb_in_run: list[float]
    zenoh_insecure_stepping_s: list[float | None] = field(default_factory=list)
    ratio_insecure: float | None = None
    cpu_floor: CpuFloor | None = None
    zenoh_exit_codes: dict[str, int | None] | None = None  # role → exit code, the last secured run
    zenoh_insecure_exit_codes: dict[str, int | None] | None = None
    zenoh_violations: int | None = None


@dataclass(frozen=True)
class LaunchRep:
    launch_to_step0_s: float | None
    load_before: float
    exit_code: int | None = None


@dataclass(frozen=True)
class Launch:
    reps: list[LaunchRep]
    median_s: float | None
    steps: int = 0


@dataclass(frozen=True)
class NodeRep:
    first_state_s: float | None
    first_estimate_s: float | None
    peak_rss_mb: float | None
    exit_code: int | None = None


@dataclass(frozen=True)
class Stage:
    stage: str
    rss_mb: float | None = None
    added_mb: float | None = None
    ms: float | None = None


@dataclass(frozen=True)
class NodeStartup:
    reps: list[NodeRep]
    memory_by_stage: list[Stage] = field(default_factory=list)


@dataclass(frozen=True)
class Processes:
    """CPU of a real-time run's processes [% of one core]."""

    role_cpu_pct: dict[str, float] = field(default_factory=dict)
    node_cpu_pct_median: float | None = None
    nodes_cpu_pct_total: float | None = None
    other_work_pct: float | None = None
    node_peak_rss_mb_median: float | None = None
    window_s: float | None = None
    machine_busy_pct: float | None = None


@dataclass(frozen=True)
class RealtimeRun:
    nodes: int
    attempt: int
    exit_code: int | None
    deadline_misses: int
    nodes_missing: list[int]
    wall_s: float | None
    load_before: str | None = None
    late_steps: int | None = None
    first_late_step: int | None = None
    node_cpu_ms_per_step: float | None = None
    demand_cores: float | None = None
    processes: Processes = field(default_factory=Processes)
    fallbacks: int | None = None
    violations: int | None = None

    def fits(self) -> bool:
        """Every deadline kept and every node there."""
        return self.deadline_misses == 0 and not self.nodes_missing


def fit_cpu(runs: list[RealtimeRun], nodes: int | None) -> float | None:
    """A node's CPU ms per step in the run of ``nodes`` nodes that kept every deadline (None: there is none)."""
    return next((r.node_cpu_ms_per_step for r in runs if r.nodes == nodes and r.fits()), None)


@dataclass(frozen=True)
class Variant:
    """The largest real-time ring with one variant, walking down from the plain ladder's."""

    max_nodes: int | None
    ratio_to_plain: float | None
    runs: list[RealtimeRun]


@dataclass(frozen=True)
class Realtime:
    steps: int
    max_nodes: int | None
    runs: list[RealtimeRun]
    variants: dict[str, Variant] = field(default_factory=dict)


@dataclass(frozen=True)
class Phase:
    ms_per_step: float
    calls_per_step: float


@dataclass(frozen=True)
class NodeProfile:
    """A node's CPU per step by phase (``run --profile``); ``phases`` None: the run gave no report."""

    exit_code: int | None = None
    phases: dict[str, Phase] | None = None
    nodes: int = 0
    steps: int = 0
    objective: str = ""
    load_before: str = ""
    deadline_misses: int = 0
    process_ms_per_step: float | None = None
    profiled_nodes: int | None = None
    processes: Processes | None = None
    node_cpu_ms_per_step: float | None = None
    demand_cores: float | None = None
    thread_ms_per_step: float | None = None

    def process_ms(self) -> float:
        """The node's whole CPU per step [ms]; a report (its phases) always has it."""
        if self.process_ms_per_step is None:
            raise FiguresError("a node profile with phases but no process_ms_per_step")
        return self.process_ms_per_step


@dataclass(frozen=True)
class Flood:
    sent_per_s: float | None
    ratio: float | None
    nodes_lost: int
    exit_code: int | None
    target: str = ""  # node 2's input or state key
    secured: bool = True
    rate: int | None = None  # msg/s asked
    steps: int | None = None
    base_exit_code: int | None = None  # the run without the flood
    drops: dict[str, dict[str, int]] = field(default_factory=dict)  # role → reason → messages dropped


@dataclass(frozen=True)
class Crash:
    roles_lost: int | None
    exit_code: int | None
    nodes_missing: list[int]
    secured: bool = True
    sent: int | None = None
    drops: dict[str, dict[str, int]] = field(default_factory=dict)


@dataclass(frozen=True)
class Soak:
    steps: int
    rss_start_mb: float | None
    rss_end_mb: float | None
    slope_mb_per_10k_steps: float | None
    steps_per_s: float | None
    wall_s: float | None = None
    rss_mb: list[tuple[int, float]] = field(default_factory=list)  # (step, MB) samples
    violations: int | None = None


@dataclass(frozen=True)
class Defences:
    flood_input_secured: Flood
    flood_state_secured: Flood
    flood_input_insecure: Flood
    flood_state_insecure: Flood
    crash_secured: Crash
    crash_insecure: Crash
    soak: Soak

    def flood(self, target: str, mode: str) -> Flood:
        """``target``: input or state (node 2's key); ``mode``: secured or insecure."""
        return {
            ("input", "secured"): self.flood_input_secured,
            ("state", "secured"): self.flood_state_secured,
            ("input", "insecure"): self.flood_input_insecure,
            ("state", "insecure"): self.flood_state_insecure,
        }[target, mode]

    def crash(self, mode: str) -> Crash:
        return self.crash_secured if mode == "secured" else self.crash_insecure


@dataclass(frozen=True)
class ScalingPoint:
    nodes: int
    ms_per_node_step: float | None


@dataclass(frozen=True)
class Performance:
    """A performance run's figures (bench/results.json): each measurement, then the headline (run.headline)."""

    meta: Meta
    paper: dict[str, PaperCase]
    tightness: dict[str, Tightness]
    inmemory_scaling: Scaling
    zenoh: Zenoh
    launch: Launch
    node: NodeStartup
    realtime: Realtime
    defences: Defences
    scaling: list[ScalingPoint] = field(default_factory=list)  # the headline's (run.headline): none before the run computes it
    node_profile: NodeProfile = field(default_factory=NodeProfile)
    node_profile_trace: NodeProfile = field(default_factory=NodeProfile)
    # the headline (run.headline; run.TARGETS names them)
    solve_ms_median: float | None = None
    solve_ms_median_saim: float | None = None
    straightforward_ratio: float | None = None
    naive_ratio: float | None = None
    previous_default_ratio: float | None = None
    zenoh_overhead_ratio: float | None = None
    zenoh_overhead_ratio_cpu_floor: float | None = None
    fault_width_ratio_exact_nsnim: float | None = None
    fault_width_ratio_exact_saim: float | None = None
    node_rss_mb: float | None = None
    node_startup_s: float | None = None
    node_first_estimate_s: float | None = None
    launch_to_step0_s: float | None = None
    realtime_max_nodes: int | None = None
    realtime_max_nodes_reference_ratio: float | None = None
    realtime_max_nodes_max_faulty_ratio: float | None = None
    realtime_max_nodes_car_ratio: float | None = None
    flood_step_rate_ratio: float | None = None
    flood_nodes_lost: int | None = None
    crash_roles_lost: int | None = None
    soak_rss_slope_mb_per_10k_steps: float | None = None
    solve_ms_p95: float | None = None
    solve_ms_p95_saim: float | None = None
    solve_ms_median_per_rule: float | None = None
    solve_ms_median_saim_per_rule: float | None = None
    zenoh_overhead_ratio_insecure: float | None = None
    realtime_node_cpu_ms_per_step: float | None = None
    realtime_node_cpu_ms_per_step_trace: float | None = None
    flood_step_rate_ratio_insecure_input: float | None = None
    flood_step_rate_ratio_insecure_state: float | None = None


def load(doc: dict, what: str = "the performance figures") -> Performance:
    """``doc`` (bench/results.json as loaded, or a run's figures) as :class:`Performance`."""
    return typed(Performance, doc, what)
